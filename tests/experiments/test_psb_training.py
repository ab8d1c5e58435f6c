"""experiments/psb_classification/psb_training.py: the training loop, averaged weights, augmented
copies, test-time augmentation, the optimiser options and the records of a run."""

from types import SimpleNamespace

import numpy as np
import pytest
import torch

from study import psb_data, psb_report, psb_training, variants
from study import run as command


class _MeanLinear(torch.nn.Module):
    """A stand-in model: a linear map of each mesh's mean feature, with dropout."""

    def __init__(self, c_in, c_out, log_features=False):
        super().__init__()
        self.linear, self.drop = torch.nn.Linear(c_in, c_out), torch.nn.Dropout(0.5)

    def forward(self, batch):
        return self.linear(self.drop(batch.features.mean(0, keepdim=True)))


class _ToyBatch(SimpleNamespace):
    def to(self, device):  # the features stay on the CPU
        return self


def _toy_batches(n=12, classes=3):
    g = torch.Generator().manual_seed(5)
    return [
        _ToyBatch(features=torch.randn(7, 4, generator=g) + i % classes, labels=torch.tensor(i % classes))
        for i in range(n)
    ]


def test_averaged_weights_are_the_mean_of_the_last_epochs(monkeypatch):
    monkeypatch.setitem(variants.MODELS, "toy", _MeanLinear)
    batches = _toy_batches()
    model, averaged, _ = psb_training.fit("toy", batches, seed=3, epochs=5, num_classes=3, average=3)
    finals = [
        psb_training.fit("toy", batches, seed=3, epochs=e, num_classes=3, average=0)[0] for e in (3, 4, 5)
    ]
    assert psb_training.fit("toy", batches, 3, 5, 3, average=0)[1] is None
    for name, p in model.named_parameters():  # averaging leaves the run's own weights as they were
        torch.testing.assert_close(p, dict(finals[-1].named_parameters())[name], rtol=0, atol=0)
    for name, p in averaged.module.named_parameters():
        mean = torch.stack([dict(m.named_parameters())[name] for m in finals]).mean(0)
        torch.testing.assert_close(p, mean)
    assert not torch.equal(averaged.module.linear.weight, model.linear.weight)


def test_run_records_and_table_rows_of_averaged_weights(monkeypatch):
    monkeypatch.setitem(variants.MODELS, "toy", _MeanLinear)
    batches = _toy_batches()
    r = psb_training.train("toy", batches[:9], batches[9:], seed=0, epochs=4, num_classes=3, average=10)
    assert r["average_epochs"] == 4 and 0 <= r["averaged_test_accuracy"] <= 1
    assert "average_epochs" not in psb_training.train("toy", batches[:9], batches[9:], 0, 2, 3, average=0)
    r.update(split="fixed", test_accuracy=0.25, averaged_test_accuracy=0.75)
    rows = psb_report.with_averaged([r])
    assert [psb_report.label(x) for x in rows] == ["toy", "toy, averaged last 4"]
    lines = psb_report.table(rows, [psb_report.label(x) for x in rows]).splitlines()
    assert lines[2].startswith("| toy | 0.250 ± 0.000 (n=1)")
    assert lines[3].startswith("| toy, averaged last 4 | 0.750 ± 0.000 (n=1)")


class _Logits(torch.nn.Module):
    """A stand-in model whose logits are each mesh's mean feature; it records its mode."""

    def __init__(self):
        super().__init__()
        self.modes = []

    def forward(self, batch):
        self.modes.append(self.training)
        return batch.features.mean(0, keepdim=True)


def _logits(values, label):
    return SimpleNamespace(features=torch.tensor([values]), labels=torch.tensor(label))


def test_runs_record_the_class_given_to_each_test_mesh(monkeypatch):
    model = _Logits()
    meshes = [_logits([0.0, 0.2], 0), _logits([0.0, 0.1], 1), _logits([1.0, 0.0], 0)]
    assert psb_training.predictions(model, meshes) == [1, 1, 0]
    assert psb_training.accuracy(model, meshes, [0, 1, 0]) == 1.0  # from the predictions given
    monkeypatch.setitem(variants.MODELS, "toy", _MeanLinear)
    batches = _toy_batches()
    r = psb_training.train("toy", batches[:9], batches[9:], 0, 4, 3, average=2)
    assert len(r["test_predictions"]) == len(r["averaged_test_predictions"]) == 3
    for key in ("test", "averaged_test"):
        right = [p == int(b.labels) for p, b in zip(r[f"{key}_predictions"], batches[9:])]
        assert r[f"{key}_accuracy"] == pytest.approx(sum(right) / 3)
    plain, averaged = psb_report.with_averaged([r])
    assert plain["test_predictions"] == r["test_predictions"]
    assert averaged["test_predictions"] == r["averaged_test_predictions"]


def test_test_time_augmentation_averages_the_probabilities_of_a_mesh_and_its_copies():
    model = _Logits()
    # mesh 0 (class 0) is misread alone, and read right with its two copies; mesh 1 is read
    # right alone and misread with its copies; mesh 2 has no copies
    meshes = [_logits([0.0, 0.2], 0), _logits([0.0, 0.1], 1), _logits([1.0, 0.0], 0)]
    copies = [
        [_logits([3.0, 0.0], 0), _logits([2.0, 0.0], 0)],
        [_logits([0.0, -2.0], 1), _logits([0.0, -2.0], 1)],
        [],
    ]
    assert psb_training.accuracy(model, meshes) == pytest.approx(2 / 3)
    assert psb_training.tta_accuracy(model, meshes, copies) == pytest.approx(2 / 3)
    assert psb_training.tta_accuracy(model, meshes, [copies[0], [], []]) == 1.0
    # probabilities are averaged, not logits: one confident copy does not outvote two others
    # (the mean logits would read mesh 0 right: 2.25 against 1.55)
    votes = [[_logits([9.0, 0.0], 0), _logits([0.0, 3.0], 0), _logits([0.0, 3.0], 0)], [], []]
    assert psb_training.tta_accuracy(model, meshes, votes) == pytest.approx(2 / 3)
    assert not any(model.modes) and model.training  # evaluated in eval mode, then back to training


def test_run_records_of_test_time_augmentation(monkeypatch):
    monkeypatch.setitem(variants.MODELS, "toy", _MeanLinear)
    batches = _toy_batches()
    test_copies = [[batches[j] for j in (0, 1)] for _ in batches[9:]]
    r = psb_training.train("toy", batches[:9], batches[9:], 0, 3, 3, average=2, test_copies=test_copies)
    assert 0 <= r["tta_test_accuracy"] <= 1 and 0 <= r["averaged_tta_test_accuracy"] <= 1
    plain = psb_training.train("toy", batches[:9], batches[9:], 0, 3, 3, average=2)
    assert "tta_test_accuracy" not in plain
    assert plain["test_accuracy"] == r["test_accuracy"]  # the run itself is the one it was
    same = psb_training.train("toy", batches[:9], batches[9:], 0, 3, 3, average=0, test_copies=[[]] * 3)
    assert same["tta_test_accuracy"] == same["test_accuracy"] and "averaged_tta_test_accuracy" not in same


def test_stretched_copies_are_reproducible_non_rigid_and_normalised():
    rng = np.random.default_rng(0)
    v = rng.standard_normal((50, 3)) * [2.0, 1.0, 0.5] + 3.0
    w = psb_data.stretched(v, index=7, copy=1)
    np.testing.assert_array_equal(w, psb_data.stretched(v, index=7, copy=1))
    assert not np.allclose(w, psb_data.stretched(v, index=7, copy=2))
    np.testing.assert_allclose(np.linalg.norm(w, axis=1).max(), 1.0)
    np.testing.assert_allclose((w.max(0) + w.min(0)) / 2, 0.0, atol=1e-12)
    # not a similarity: ratios of distances change, within the stretch's bounds
    d0 = np.linalg.norm(v[:, None] - v[None], axis=-1)[np.triu_indices(50, 1)]
    d1 = np.linalg.norm(w[:, None] - w[None], axis=-1)[np.triu_indices(50, 1)]
    ratio = d1 / d0
    assert ratio.max() / ratio.min() > 1.05
    assert ratio.max() / ratio.min() <= psb_data.STRETCH**2 + 1e-9


def test_training_steps_draw_the_mesh_or_its_copies(monkeypatch):
    monkeypatch.setitem(variants.MODELS, "toy", _MeanLinear)
    batches = _toy_batches(6)
    copies = [
        [SimpleNamespace(features=b.features + 0.5, labels=b.labels) for _ in range(2)] for b in batches
    ]
    seen = []
    step = psb_training.train_step
    monkeypatch.setattr(psb_training, "train_step", lambda m, o, b: (seen.append(b), step(m, o, b)))
    psb_training.fit("toy", batches, seed=1, epochs=20, num_classes=3, average=0, copies=copies)
    originals = sum(any(b is x for x in batches) for b in seen)
    assert len(seen) == 120 and 25 <= originals <= 55  # a third of the steps, drawn uniformly
    assert {id(b) for b in seen} <= {id(x) for x in batches} | {id(c) for cs in copies for c in cs}
    # without copies (or empty ones) the run is the one it was
    seen.clear()
    plain = psb_training.fit("toy", batches, seed=1, epochs=3, num_classes=3, average=0)[0]
    empty = psb_training.fit("toy", batches, seed=1, epochs=3, num_classes=3, average=0, copies=[[]] * 6)[0]
    assert all(any(b is x for x in batches) for b in seen)
    torch.testing.assert_close(plain.linear.weight, empty.linear.weight, rtol=0, atol=0)


def test_copies_whose_operators_fail_are_left_out_and_reported(monkeypatch, capsys):
    v = np.random.default_rng(1).standard_normal((6, 3))
    dataset = {"meshes": [(v, None), (v + 1, None), (v, None)], "labels": np.array([0, 1, 2])}

    def fake_precompute(one, cache_dir, vertex_laplacian="cotan", k_edge=32, inputs="hks"):
        (w, _), label = one["meshes"][0], int(one["labels"][0])
        if label == 1 and np.allclose(w, psb_data.stretched(v + 1, 1, 0)):
            raise ValueError("eigsh: Lanczos did not converge")
        return [SimpleNamespace(labels=label)], []

    monkeypatch.setattr(psb_data, "precompute", fake_precompute)
    out = psb_data.precompute_copies(dataset, None, 2, np.array([True, True, False]))
    assert [len(c) for c in out] == [2, 1, 0] and all(b.labels == 1 for b in out[1])
    assert "left out 1 copies: mesh 1 copy 0: eigsh: Lanczos did not converge" in capsys.readouterr().out
    assert psb_data.precompute_copies(dataset, None, 0, np.ones(3, bool)) == [[], [], []]


def test_copies_take_the_stretch_asked_for_and_runs_name_it(monkeypatch):
    v = np.random.default_rng(2).standard_normal((40, 3))
    dataset = {"meshes": [(v, None)], "labels": np.array([0])}
    seen = []
    monkeypatch.setattr(
        psb_data, "precompute", lambda one, *a: (seen.append(one["meshes"][0][0]), ([None], []))[1]
    )
    psb_data.precompute_copies(dataset, None, 1, np.array([True]))
    psb_data.precompute_copies(dataset, None, 1, np.array([True]), spread=1.5)
    np.testing.assert_array_equal(seen[0], psb_data.stretched(v, 0, 0))
    np.testing.assert_array_equal(seen[1], psb_data.stretched(v, 0, 0, 1.5))
    assert not np.allclose(seen[0], seen[1])
    run = {"model": "edgefieldnet", "augment": 4}
    assert psb_report.label(run) == "edgefieldnet, 4 stretched copies"
    assert psb_report.label(dict(run, stretch=psb_data.STRETCH)) == "edgefieldnet, 4 stretched copies"
    assert psb_report.label(dict(run, stretch=1.5)) == "edgefieldnet, 4 stretched copies (up to 1.5)"


def test_warped_copies_keep_their_stretch_and_runs_name_the_warp(monkeypatch):
    v = np.random.default_rng(3).standard_normal((60, 3))
    dataset = {"meshes": [(v, None)], "labels": np.array([0])}
    seen = []
    monkeypatch.setattr(
        psb_data, "precompute", lambda one, *a: (seen.append(one["meshes"][0][0]), ([None], []))[1]
    )
    psb_data.precompute_copies(dataset, None, 2, np.array([True]), warp=0.3)
    stretched = [psb_data.stretched(v, 0, c) for c in range(2)]
    for c in range(2):
        np.testing.assert_array_equal(seen[c], psb_data.stretched(v, 0, c, warp=0.3))
        # the warp moves the stretched copy (by at most its amplitude, before rescaling)
        moved = np.linalg.norm(seen[c] - stretched[c], axis=1)
        assert 1e-3 < moved.max() < 0.3
    np.testing.assert_array_equal(psb_data.stretched(v, 0, 1, warp=0.0), stretched[1])
    run = {"model": "edgefieldnet", "augment": 4}
    assert psb_report.label(dict(run, warp=0.3)) == "edgefieldnet, 4 stretched copies, warped (strain 0.3)"
    assert psb_report.label(dict(run, warp=0.0)) == "edgefieldnet, 4 stretched copies"
    assert (
        psb_report.label({"model": "edgefieldnet", "tta": 8, "warp": 0.3})
        == "edgefieldnet, warped (strain 0.3)"
    )


def test_schedules_halve_or_decay_the_rate_along_a_cosine():
    def rates(schedule, epochs):
        opt = torch.optim.SGD([torch.nn.Parameter(torch.zeros(1))], lr=1e-3)
        sched, out = psb_training.new_schedule(opt, schedule, epochs), []
        for _ in range(epochs):
            out.append(opt.param_groups[0]["lr"])
            opt.step()
            sched.step()
        return np.array(out + [opt.param_groups[0]["lr"]])

    step = rates("step", 120)
    assert (step[:50] == 1e-3).all() and (step[50:100] == 5e-4).all() and (step[100:] == 2.5e-4).all()
    cosine = rates("cosine", 60)
    expected = 1e-3 * (1 + np.cos(np.pi * np.arange(61) / 60)) / 2
    np.testing.assert_allclose(cosine, expected, rtol=1e-9, atol=1e-15)
    assert cosine[-1] < 1e-12 and (np.diff(cosine) < 0).all()
    with pytest.raises(ValueError, match="schedule must be one of"):
        psb_training.new_schedule(torch.optim.SGD([torch.nn.Parameter(torch.zeros(1))], lr=1), "linear", 3)


def test_weight_decay_takes_adamw_and_shrinks_weights_without_gradients(monkeypatch):
    monkeypatch.setitem(variants.MODELS, "toy", _MeanLinear)
    batch = _toy_batches()[0]
    model, opt = psb_training.new_model("toy", batch, 3, seed=0)
    assert type(opt) is torch.optim.Adam and opt.param_groups[0]["weight_decay"] == 0
    model, opt = psb_training.new_model("toy", batch, 3, seed=0, weight_decay=0.5)
    assert type(opt) is torch.optim.AdamW and opt.param_groups[0]["weight_decay"] == 0.5
    before = model.linear.weight.detach().clone()
    for p in model.parameters():
        p.grad = torch.zeros_like(p)
    opt.step()  # a zero gradient moves nothing but the decay: w (1 - lr wd)
    torch.testing.assert_close(model.linear.weight, before * (1 - 1e-3 * 0.5))


def test_runs_record_and_name_their_optimiser_options(monkeypatch):
    monkeypatch.setitem(variants.MODELS, "toy", _MeanLinear)
    batches = _toy_batches()
    plain = psb_training.train("toy", batches[:9], batches[9:], 0, 3, 3, average=0)
    decayed = psb_training.train("toy", batches[:9], batches[9:], 0, 3, 3, average=0, weight_decay=0.5)
    cosine = psb_training.train("toy", batches[:9], batches[9:], 0, 3, 3, average=0, schedule="cosine")
    assert plain["parameters"] == decayed["parameters"] == cosine["parameters"]
    run = {"model": "edgefieldnet", "augment": 4}
    assert (
        psb_report.label(dict(run, weight_decay=0.05))
        == "edgefieldnet, 4 stretched copies, weight decay 0.05"
    )
    assert (
        psb_report.label(dict(run, schedule="cosine")) == "edgefieldnet, 4 stretched copies, cosine schedule"
    )
    assert psb_report.label(dict(run, schedule="step", weight_decay=0)) == "edgefieldnet, 4 stretched copies"
    fake = {
        "meshes": [None] * 12,
        "labels": np.repeat(np.arange(3), 4),
        "split": np.tile([0, 0, 0, 1], 3),
        "classes": ["a", "b", "c"],
    }
    record = dict(plain, test_accuracy=0.5, train_seconds=1.0, seconds_per_step=0.1)
    saved = []
    monkeypatch.setattr(command, "load_psb", lambda path: fake)
    monkeypatch.setattr(command, "precompute", lambda d, *a: (batches, []))
    monkeypatch.setattr(command, "train", lambda *a: saved.append(a) or dict(record))
    argv = ["--data", __file__, "--models", "edgefieldnet", "--seeds", "0", "--threads", "1"]
    out = command.main(argv + ["--weight-decay", "0.05", "--schedule", "cosine"])
    assert saved[0][-2:] == (0.05, "cosine")
    assert out[0]["weight_decay"] == 0.05 and out[0]["schedule"] == "cosine"
    assert {"weight_decay", "schedule"}.isdisjoint(command.main(argv)[0])  # the defaults: not recorded
    assert saved[1][-2:] == (0.0, "step")
