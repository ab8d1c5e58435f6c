"""experiments/psb_classification/run.py: its quick run, its splits, its options and its argument errors."""

import json

import numpy as np
import pytest
import torch
import trimesh

from torch_edgevf.learning.cache import OperatorCache

from study import euler_of_closed, paired_rows, psb_data, psb_report, psb_training, variants
from study import run as command

#: the study's README: its tables, its reading and its report
README = "experiments/psb_classification/README.md"


@pytest.mark.slow
def test_quick_run_writes_every_field_and_a_table(psb, tmp_path, capsys):
    out = tmp_path / "runs.json"
    results = command.main(
        ["--quick", "--cache", str(tmp_path / "cache"), "--threads", "1", "--json", str(out)]
    )
    saved = json.loads(out.read_text())
    assert [r["model"] for r in saved] == list(psb_report.DEFAULT_MODELS) == [r["model"] for r in results]
    for r in saved:
        assert set(r) >= {"test_accuracy", "train_accuracy", "train_seconds", "parameters", "seed", "split"}
        assert 0 <= r["test_accuracy"] <= 1 and r["train_seconds"] > 0 and r["parameters"] > 10_000
    printed = capsys.readouterr().out
    assert "| edgefieldnet-nodiv-meanpool |" in printed and "| diffusionnet-nodropout |" in printed
    assert "operators: 32 meshes, 32 computed" in printed
    assert command.main(["--table", str(out)]) == saved
    # --device cpu (the default, named) trains the same networks to the same numbers
    named = command.main(["--quick", "--cache", str(tmp_path / "cache"), "--threads", "1", "--device", "cpu"])
    for r, s in zip(results, named):
        assert r["test_predictions"] == s["test_predictions"]
        assert r["train_accuracy"] == s["train_accuracy"]


@pytest.mark.slow
def test_profile_prints_the_operators_of_ten_training_steps(psb, tmp_path, capsys):
    argv = ["--quick", "--profile", "--models", "edgefieldnet-nodiv-meanpool", "--threads", "1"]
    command.main([*argv, "--cache", str(tmp_path / "cache")])
    printed = capsys.readouterr().out
    head, _, profile = printed.partition("one training step of edgefieldnet-nodiv-meanpool (10 steps):")
    assert profile and "| edgefieldnet-nodiv-meanpool |" in head
    assert "aten::mm" in profile and "Self CPU time total" in profile
    (adam,) = [line for line in profile.splitlines() if "Optimizer.step" in line]
    assert adam.split()[-1] == "10"  # one optimiser step per profiled training step


def test_folds_are_stratified_and_cover_every_mesh_once():
    labels = np.repeat(np.arange(5), 20)
    dataset = {"labels": labels, "split": np.zeros(100, dtype=int)}
    evaluations = psb_data.splits(dataset, 5, None)
    assert all((train == ~test).all() for _, train, test in evaluations)
    masks = [test for _, _, test in evaluations]
    assert (np.sum(masks, axis=0) == 1).all()
    for m in masks:
        assert (np.bincount(labels[m], minlength=5) == 4).all()
    assert len(psb_data.splits(dataset, 0, None)) == 1
    # another partition: other folds, as stratified; partition 0 is the default
    again = psb_data.splits(dataset, 5, None, partition=0)
    assert all((a[2] == b[2]).all() for a, b in zip(evaluations, again))
    other = [test for _, _, test in psb_data.splits(dataset, 5, None, partition=1)]
    assert (np.sum(other, axis=0) == 1).all()
    assert all((np.bincount(labels[m], minlength=5) == 4).all() for m in other)
    assert any((m != o).any() for m, o in zip(masks, other))


def test_split_file_is_checked(tmp_path):
    dataset = {"labels": np.zeros(10, dtype=int), "split": np.zeros(10, dtype=int)}
    good, bad = tmp_path / "good.npy", tmp_path / "bad.npy"
    np.save(good, np.array([0, 1, -1, 1, 0, 0, 1, 0, -1, 0]))
    np.save(bad, np.array([0, 2] * 5))
    ((name, train, test),) = psb_data.splits(dataset, 0, good)
    assert name == "split" and test.sum() == 3 and train.sum() == 5  # -1: in neither
    with pytest.raises(ValueError, match="0 \\(train\\), 1 \\(test\\) or -1 \\(left out\\)"):
        psb_data.splits(dataset, 0, bad)
    np.save(bad, np.array([0, -1] * 5))
    with pytest.raises(ValueError, match="at least one training"):
        psb_data.splits(dataset, 0, bad)


def test_validation_split_leaves_the_test_meshes_out():
    labels = np.repeat(np.arange(3), 20)
    split = np.tile(np.r_[np.zeros(16, int), np.ones(4, int)], 3)
    ids = np.arange(60)[::-1].copy()  # ids against the file's order
    ((name, train, test),) = psb_data.splits({"labels": labels, "split": split, "ids": ids}, 0, None, True)
    assert name == "validation"
    assert not (train & test).any() and not ((train | test) & (split == 1)).any()
    assert (np.bincount(labels[test]) == 4).all() and (np.bincount(labels[train]) == 12).all()
    for c in range(3):  # the validation meshes are the training meshes of largest id
        tr = (labels == c) & (split == 0)
        assert ids[test & (labels == c)].min() > ids[train & (labels == c)].max()
        assert (train | test)[tr].all()


def test_topology_shift_tests_each_class_on_topologies_its_training_meshes_lack():
    """Spheres train; a torus tests where its class has spheres; a class without spheres
    trains whole."""
    sphere = trimesh.creation.icosphere(1)
    torus = trimesh.creation.torus(1.0, 0.3, major_sections=12, minor_sections=6)
    meshes, labels = [], []
    for label, shapes in enumerate([[sphere, sphere, torus], [torus, torus], [sphere, torus, sphere]]):
        for m in shapes:
            meshes.append((np.asarray(m.vertices), np.asarray(m.faces)))
            labels.append(label)
    dataset = {"meshes": meshes, "labels": np.array(labels), "split": np.zeros(len(labels), int)}
    flags = psb_data.topology_shift_flags(dataset)
    np.testing.assert_array_equal(flags, [0, 0, 1, 0, 0, 0, 1, 0])
    ((name, train, test),) = psb_data.splits(dataset, 0, None, topology_shift=True)
    assert name == "topology"
    np.testing.assert_array_equal(test, flags == 1)
    np.testing.assert_array_equal(train, flags == 0)
    # within the fixed split's training meshes: its test meshes are left out
    dataset["split"] = np.array([0, 1, 0, 0, 0, 1, 0, 1])
    flags = psb_data.topology_shift_flags(dataset, validation=True)
    np.testing.assert_array_equal(flags, [0, -1, 1, 0, 0, -1, 1, -1])
    ((name, train, test),) = psb_data.splits(dataset, 0, None, validation=True, topology_shift=True)
    assert name == "topology validation"
    np.testing.assert_array_equal(test, flags == 1)
    np.testing.assert_array_equal(train, flags == 0)


def test_topology_shift_of_the_psb_file(psb):
    """On PSB: 39 test meshes in 9 classes (16 cups with a handle, 12 vases, the 3 bearings
    with holes, ...), each of a topology no training mesh of its class has."""
    dataset = psb_data.load_psb(psb)
    flags = psb_data.topology_shift_flags(dataset)
    labels = dataset["labels"]
    euler = euler_of_closed(dataset)
    assert flags.sum() == 39 and len(set(labels[flags == 1])) == 9
    for i in np.flatnonzero(flags):
        assert euler[i] not in euler[(labels == labels[i]) & (flags == 0)]
    classes = np.array(dataset["classes"])
    assert (classes[labels[flags == 1]] == "cup").sum() == 16
    assert sorted(euler[(classes[labels] == "bearing") & (flags == 1)]) == [-10, -6, -6]
    # for choosing a design: 31 of them are fixed-split training meshes, none of the bearings
    within = psb_data.topology_shift_flags(dataset, validation=True)
    assert (within == 1).sum() == 31 and (within == 0).sum() == 304 - 31
    assert not (within[dataset["split"] == 1] + 1).any()
    assert "bearing" not in classes[labels[within == 1]]


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--models", "resnet"], "unknown models"),
        (["--split", "s.npy", "--topology-shift"], "exclude each other"),
        (["--folds", "1"], "--folds"),
        (["--only-folds", "0"], "--only-folds needs --folds"),
        (["--folds", "5", "--only-folds", "5"], "0..K-1"),
        (["--folds", "5", "--only-folds", "a"], "comma-separated"),
        (["--rounds", "0"], "--rounds must be at least 1"),
        (["--average", "-1"], "--average must be 0"),
        (["--augment", "-1"], "--augment must be 0"),
        (["--tta", "-1"], "--tta must be 0"),
        (["--stretch", "0.8"], "--stretch must be at least 1"),
        (["--augment", "4", "--warp", "1"], "--warp must be in [0, 1)"),
        (["--augment", "4", "--warp", "nan"], "--warp must be in"),
        (["--warp", "0.3"], "--warp warps the copies of --augment or --tta"),
        (["--k-edge", "0"], "--k-edge must be at least 1"),
        (["--weight-decay", "-0.1"], "--weight-decay must be 0"),
        (["--weight-decay", "nan"], "--weight-decay must be 0"),
        (["--weight-decay", "inf"], "--weight-decay must be 0"),
        (["--validation", "--folds", "5"], "exclude each other"),
        (["--partition", "1"], "--partition needs --folds K"),
        (["--folds", "5", "--partition", "-1"], "--partition must be a seed"),
        (["--paired", "m"], "--paired compares saved runs"),
        (["--partitions", "0"], "--partitions selects saved runs"),
        (["--table", "{runs}", "--partitions", "a"], "--partitions takes comma-separated numbers"),
        ([], "TORCH_EDGEVF_PSB"),
        (["--device", "nonsense"], "'nonsense' is not a device"),
    ],
)
def test_argument_errors(argv, message, capsys, monkeypatch, tmp_path):
    monkeypatch.delenv("TORCH_EDGEVF_PSB", raising=False)
    data = [] if message == "TORCH_EDGEVF_PSB" else ["--data", str(tmp_path / "x.npz")]
    (tmp_path / "runs.json").write_text("[]")
    argv = [a.format(runs=tmp_path / "runs.json") for a in argv]
    with pytest.raises(SystemExit) as exc:
        command.main(data + argv)
    assert exc.value.code == 2 and message in capsys.readouterr().err


@pytest.mark.slow
def test_step_time_alternates_the_models_and_gives_ratios(psb, tmp_path, capsys):
    out = tmp_path / "steps.json"
    argv = ["--step-time", "2", "--cache", str(tmp_path / "cache"), "--threads", "1", "--json", str(out)]
    results = command.main(argv)
    assert [r["model"] for r in results] == ["edgefieldnet-nodiv-meanpool", "diffusionnet-nodropout"]
    for r in results:
        assert len(r["seconds_per_step"]) == 3 and all(0 < t < 60 for t in r["seconds_per_step"])
        assert r["meshes"] == 2 and r["threads"] == 1
    assert json.loads(out.read_text()) == results
    printed = capsys.readouterr().out
    assert "edgefieldnet-nodiv-meanpool:" in printed and "diffusionnet-nodropout: " in printed
    assert "mean vs diffusionnet-nodropout 1.00" in printed


def test_the_faithful_baseline_has_no_dropout_and_the_other_diffusionnet_has():
    """DiffusionNet's public classification script builds it without dropout: the default
    baseline; ``diffusionnet`` keeps the class's default, dropout 0.5 in every block's MLP.
    The ``-nodropout`` edge-field networks have none either."""
    assert psb_report.BASELINE == "diffusionnet-nodropout"
    assert psb_report.DEFAULT_MODELS == ("edgefieldnet-nodiv-meanpool", psb_report.BASELINE)

    def dropouts(name):
        return [m.p for m in variants.MODELS[name](16, 19, True).modules() if isinstance(m, torch.nn.Dropout)]

    assert dropouts(psb_report.BASELINE) == []
    assert dropouts("diffusionnet") == [0.5] * 8  # 4 blocks, 2 hidden layers each
    assert dropouts("edgefieldnet-nodropout") == dropouts("edgefieldnet-vec8-nodropout") == []
    assert dropouts("edgefieldnet") == [0.5] * 6  # 3 blocks, 2 hidden layers each
    baseline = psb_report.BASELINE
    assert psb_report.baseline_of({"edgefieldnet", "diffusionnet", baseline}) == baseline
    assert psb_report.baseline_of({"edgefieldnet", "diffusionnet"}) == "diffusionnet"


def test_the_spectrum_candidate_and_its_control_differ_from_their_bases_by_the_spectrum_only():
    """``edgefieldnet-spectrum`` is the recommended network and
    ``diffusionnet-nodropout-spectrum`` the faithful DiffusionNet, seed for seed, plus the
    same linear map of the ``K_EDGE`` eigenvalues of ``L_c``; ``-lbspectrum`` takes those
    of the vertex Laplacian."""
    for name, base in (
        ("edgefieldnet-spectrum", "edgefieldnet"),
        (psb_report.BASELINE + "-spectrum", psb_report.BASELINE),
        (psb_report.BASELINE + "-lbspectrum", psb_report.BASELINE),
    ):
        torch.manual_seed(0)
        net = variants.STUDY_MODELS[name](16, 19, True)
        torch.manual_seed(0)
        ref = variants.STUDY_MODELS[base](16, 19, True).state_dict()
        assert (net.spectrum.in_features, net.spectrum.out_features) == (variants.K_EDGE, 19)
        assert net.spectrum_of == ("laplacian" if "lbspectrum" in name else "connection")
        rest = {k: w for k, w in net.state_dict().items() if not k.startswith("spectrum.")}
        assert rest.keys() == ref.keys() and all(torch.equal(w, ref[k]) for k, w in rest.items())


@pytest.mark.parametrize(
    "base",
    [
        "edgefieldnet",
        "edgefieldnet-scalar",
        "edgefieldnet-vertexvec",
        "edgefieldnet-fixedtime",
        "edgefieldnet-local",
        "edgefieldnet-nodiv",
    ],
)
def test_the_readout_variants_differ_from_their_bases_by_the_readout_only(base):
    """``edgefieldnet-meanpool-X`` (``edgefieldnet-local-meanpool``,
    ``edgefieldnet-nodiv-meanpool``) is ``edgefieldnet-X`` (``edgefieldnet-local``,
    ``edgefieldnet-nodiv``) with ``pool="mean"``: the same layers, parameters and buffers,
    and a last layer on the last scalars alone, not on their mean and deviation."""
    name = {
        "edgefieldnet": "edgefieldnet-meanpool",
        "edgefieldnet-local": "edgefieldnet-local-meanpool",
        "edgefieldnet-nodiv": "edgefieldnet-nodiv-meanpool",
    }.get(base, base.replace("edgefieldnet-", "edgefieldnet-meanpool-"))
    net, ref = variants.STUDY_MODELS[name](16, 19, True), variants.STUDY_MODELS[base](16, 19, True)
    assert (net.pool, ref.pool) == ("mean", "mean_std")
    assert 2 * net.last.in_features == ref.last.in_features

    def layers(m):
        named = [*m.named_parameters(), *m.named_buffers()]
        kept = {k: (tuple(w.shape), w.requires_grad) for k, w in named if not k.startswith("last.")}
        return kept, [line for line in str(m).splitlines() if "(last)" not in line]

    assert layers(net) == layers(ref)


def test_the_frozen_time_ablation_differs_from_its_base_by_the_times_only():
    """``edgefieldnet-nodiv-meanpool-fixedtime`` is ``edgefieldnet-nodiv-meanpool`` with
    the diffusion times frozen: the same parameters, of which only the times stop
    learning, initialised alike from one seed."""
    torch.manual_seed(0)
    net = variants.STUDY_MODELS["edgefieldnet-nodiv-meanpool-fixedtime"](16, 19, True)
    torch.manual_seed(0)
    ref = variants.STUDY_MODELS["edgefieldnet-nodiv-meanpool"](16, 19, True)
    mine, theirs = dict(net.named_parameters()), dict(ref.named_parameters())
    assert mine.keys() == theirs.keys() and all(torch.equal(w, theirs[k]) for k, w in mine.items())
    frozen = {k for k, w in mine.items() if not w.requires_grad}
    assert frozen and all("times" in k for k in frozen)
    assert all(theirs[k].requires_grad for k in frozen)


@pytest.mark.slow
def test_precompute_time_alternates_diffusionnet_and_ours(psb, tmp_path, capsys):
    pytest.importorskip("robust_laplacian")
    results = command.main(["--precompute-time", "2", "--cache", str(tmp_path / "cache"), "--threads", "1"])
    assert [r["model"] for r in results] == ["diffusionnet", "edgefieldnet"]
    for r in results:
        assert len(r["seconds_per_mesh"]) == 3 and all(0 < t < 60 for t in r["seconds_per_mesh"])
    assert not (tmp_path / "cache").exists()  # nothing cached: every call computes
    printed = capsys.readouterr().out
    assert "edgefieldnet:" in printed and "mean vs diffusionnet" in printed


@pytest.mark.slow
def test_only_folds_runs_just_the_folds_asked_for(psb, tmp_path):
    argv = ["--quick", "--models", "edgefieldnet-scalar", "--folds", "4", "--only-folds", "3,1"]
    argv += ["--partition", "2"]
    results = command.main(argv + ["--cache", str(tmp_path / "cache"), "--threads", "1", "--epochs", "1"])
    assert [r["split"] for r in results] == ["fold1", "fold3"]
    assert [r["partition"] for r in results] == [2, 2]  # recorded, so --paired keeps it apart
    first, second = (set(r["test_meshes"]) for r in results)  # the meshes of test_predictions
    assert first and second and not first & second
    assert all(len(r["test_predictions"]) == len(r["test_meshes"]) for r in results)


def test_table_keeps_fixed_folds_and_validation_apart():
    def run(split, acc):
        return dict(
            model="m", split=split, test_accuracy=acc, train_seconds=1.0, seconds_per_step=0.1, parameters=7
        )

    rows = [run("fixed", 0.5), run("fold0", 0.75), run("fold1", 0.25), run("validation", 1.0)]
    lines = psb_report.table(rows, ["m"]).splitlines()
    assert "validation or own split" in lines[0]
    cells = [c.strip() for c in lines[2].strip("|").split("|")]
    assert cells[1:4] == ["0.500 ± 0.000 (n=1)", "0.500 ± 0.354 (n=2)", "1.000 ± 0.000 (n=1)"]
    assert "own split" not in psb_report.table(rows[:3], ["m"]).splitlines()[0]
    # the folds of another partition are reported apart, after those of partition 0
    rows += [dict(run("fold0", 1.0), partition=2), dict(run("fold1", 0.5), partition=2)]
    cells = [c.strip() for c in psb_report.table(rows, ["m"]).splitlines()[2].strip("|").split("|")]
    assert cells[2] == "0.500 ± 0.354 (n=2); partition 2: 0.750 ± 0.354 (n=2)"
    only = [dict(run("fold0", 1.0), partition=1)]
    assert (
        psb_report.table(only, ["m"]).splitlines()[2].split("|")[3].strip()
        == "partition 1: 1.000 ± 0.000 (n=1)"
    )


def test_table_time_is_a_dash_without_diffusionnet_runs():
    run = dict(model="edgefieldnet", seed=0, split="topology", test_accuracy=0.5, train_accuracy=1.0)
    run.update(train_seconds=10.0, seconds_per_step=0.02, parameters=1000)
    row = psb_report.table([run]).splitlines()[-1]
    assert "nan" not in row and row.split("|")[-3].strip() == "-"
    with_base = psb_report.table([run, dict(run, model="diffusionnet", seconds_per_step=0.04)]).splitlines()
    assert with_base[2].split("|")[-3].strip() == "0.50"


def test_table_partitions_keeps_the_folds_of_the_partitions_asked_for(tmp_path, capsys):
    """``--table RUNS --partitions 0`` leaves out the fold runs of other partitions (and
    keeps every other split), so each partition's comparison can be printed alone."""

    def run(split, acc, **extra):
        return dict(
            model="m",
            seed=0,
            split=split,
            test_accuracy=acc,
            train_seconds=1.0,
            seconds_per_step=0.1,
            parameters=7,
            **extra,
        )

    runs = [run("fixed", 0.5), run("fold0", 0.75), run("fold0", 1.0, partition=1)]
    (tmp_path / "runs.json").write_text(json.dumps(runs))
    assert command.main(["--table", str(tmp_path / "runs.json"), "--partitions", "0"]) == runs[:2]
    assert "partition 1" not in capsys.readouterr().out
    assert command.main(["--table", str(tmp_path / "runs.json"), "--partitions", "1,0"]) == runs
    assert "0.750 ± 0.000 (n=1); partition 1: 1.000 ± 0.000 (n=1)" in capsys.readouterr().out


def test_paired_table_pairs_the_folds_and_corrects_the_t_test():
    """Rows are paired with the reference by seed and fold; the p-value is that of the
    corrected resampled t test over the folds, here worked out by hand: differences 1..5
    points over 5 folds of K = 5 give t = 0.03 / sqrt((1/5 + 1/4) 2.5e-4) = 2.828 on 4
    degrees of freedom, p = 0.047 (the naive t test would give 0.016). Every seed has the
    same folds, so a second seed with the same differences is the same evidence: still
    0.047 (taken as 10 samples it would give 0.008)."""

    def run(model, seed, fold, acc, split=None):
        return dict(model=model, seed=seed, split=split or f"fold{fold}", test_accuracy=acc)

    ref = [run("ref", s, k, 0.9) for s in (0, 1) for k in range(5)]
    better = [run("b", 0, k, 0.9 - (k + 1) / 100) for k in range(5)]  # seed 0 only: 5 pairs
    level = [run("c", s, k, 0.9) for s in (0, 1) for k in range(5)]
    step = [run("d", s, k, 0.85) for s in (0, 1) for k in range(5)]  # the same difference everywhere
    lone = [run("e", s, 0, 0.5) for s in (0, 1)] + [run("e", 0, 0, 0.5, split="fixed")]  # one fold: left out
    twice = [run("f", s, k, 0.9 - (k + 1) / 100) for s in (0, 1) for k in range(5)]  # b's, on two seeds
    rows = paired_rows(psb_report.paired_table(ref + better + level + step + lone + twice, "ref"))
    assert set(rows) == {"b", "c", "d", "f"}
    assert rows["b"] == ["5 (5)", "+3.00", "5 / 0 / 0", "0.047"]
    assert rows["c"] == ["5 (10)", "+0.00", "0 / 10 / 0", "1.000"]
    assert rows["d"] == ["5 (10)", "+5.00", "10 / 0 / 0", "0.000"]
    assert rows["f"] == ["5 (10)", "+3.00", "10 / 0 / 0", "0.047"]
    # seeds that disagree on a fold: the fold's difference is their mean
    split = [run("g", 0, k, 0.9 - (k + 1) / 100) for k in range(5)] + [run("g", 1, k, 0.9) for k in range(5)]
    halves = paired_rows(psb_report.paired_table(ref + split, "ref"))["g"]
    assert halves == ["5 (10)", "+1.50", "5 / 5 / 0", "0.047"]
    # another partition's folds are other samples (repeated cross-validation): b's
    # differences on two partitions are 10 folds, t = 3.402 on 9 degrees of freedom
    repeated = [dict(r, partition=1) for r in ref + better]
    both = paired_rows(psb_report.paired_table(ref + better + repeated, "ref"))["b"]
    assert both == ["10 (10)", "+3.00", "10 / 0 / 0", "0.008"]
    # K from the argument: more folds, smaller correction, smaller p
    assert float(paired_rows(psb_report.paired_table(ref + better, "ref", folds=10))["b"][-1]) < 0.047
    with pytest.raises(ValueError, match="no cross-validation runs of 'x'"):
        psb_report.paired_table(ref, "x")
    with pytest.raises(ValueError, match="at least 2 folds"):
        psb_report.paired_table(ref, "ref", folds=1)


def test_vertex_laplacian_options_and_rows():
    assert psb_data.operator_options() == psb_data.OPERATOR_OPTIONS  # the cache keys of cotan runs unchanged
    assert psb_data.operator_options("robust")["vertex_laplacian"] == "robust"
    with pytest.raises(ValueError, match="vertex_laplacian"):
        psb_data.operator_options("edge")
    assert psb_report.label({"model": "m"}) == "m"
    assert psb_report.label({"model": "m", "vertex_laplacian": "robust"}) == "m (robust Laplacian)"


def test_edge_eigenpairs_reach_the_operators_and_the_run_label():
    assert psb_data.operator_options()["k_edge"] == variants.K_EDGE == 32
    assert psb_data.operator_options("robust", 48) == dict(
        psb_data.OPERATOR_OPTIONS, k_edge=48, vertex_laplacian="robust"
    )
    assert psb_data.operator_options() == psb_data.OPERATOR_OPTIONS  # the cache keys as before
    run = {"model": "edgefieldnet", "augment": 4}
    assert psb_report.label(dict(run, k_edge=48)) == "edgefieldnet (48 edge eigenpairs), 4 stretched copies"
    assert psb_report.label(dict(run, k_edge=32)) == "edgefieldnet, 4 stretched copies"


def test_curvature_input_follows_the_hks_and_only_the_hks_are_logged(tmp_path):
    import torch_edgevf as ev
    from torch_edgevf.learning.precompute import heat_kernel_signature, mean_curvature_signature

    v, f = ev.icosphere(3)
    v = v * torch.tensor([1.0, 0.7, 0.5], dtype=v.dtype)  # an ellipsoid: the curvature varies
    dataset = {"meshes": [(v.numpy(), f.numpy())], "labels": np.array([2])}
    (plain,), _ = psb_data.precompute(dataset, tmp_path)
    (both,), _ = psb_data.precompute(dataset, tmp_path, inputs="hks+curvature")
    assert plain.features.shape[1] == psb_data.HKS_SCALES == 16 and both.features.shape[1] == 16 + 9
    torch.testing.assert_close(both.features[:, :16], plain.features)
    ops = OperatorCache(tmp_path).get(v.numpy(), f.numpy(), **psb_data.OPERATOR_OPTIONS)
    h = mean_curvature_signature(ops.verts, ops.faces, ops.vertex_evals, ops.vertex_evecs, ops.vertex_mass)
    torch.testing.assert_close(both.features[:, 16:], h.float())
    assert float(both.features[:, 16:].min()) < 0.5 < float(both.features[:, 16:].max())
    torch.testing.assert_close(
        plain.features, heat_kernel_signature(ops.vertex_evals, ops.vertex_evecs, count=16).float()
    )
    edge, _ = psb_training.new_model("edgefieldnet", both, 3, seed=0)
    vertex, _ = psb_training.new_model("diffusionnet-nodropout", both, 3, seed=0)
    recommended, _ = psb_training.new_model(psb_report.RECOMMENDED_MODEL, both, 3, seed=0)
    assert edge.log_features == 16 and not hasattr(vertex, "log_features")  # the library's, raw input
    assert recommended.channels == 16  # the library's network on the logarithm of the HKS only
    assert psb_training.new_model("edgefieldnet", plain, 3, seed=0)[0].log_features is True
    assert psb_training.new_model(psb_report.RECOMMENDED_MODEL, plain, 3, seed=0)[0].channels is True
    assert all(torch.isfinite(m(both)).all() for m in (edge, vertex, recommended))
    run = {"model": "edgefieldnet", "augment": 4}
    assert (
        psb_report.label(dict(run, input="hks+curvature"))
        == "edgefieldnet, mean curvature input, 4 stretched copies"
    )
    assert psb_report.label(dict(run, input="hks")) == "edgefieldnet, 4 stretched copies"
    with pytest.raises(ValueError, match="inputs must be one of"):
        psb_data.precompute(dataset, tmp_path, inputs="xyz")


def test_precompute_refuses_signatures_that_vanish(monkeypatch, tmp_path):
    """Wrong eigenpairs (all eigenvalues large) make the signatures underflow to zero: the
    mesh is refused with a ValueError, which leaves a stretched copy out, instead of
    training on zeros."""
    import torch_edgevf as ev

    v, f = ev.icosphere(2)
    dataset = {"meshes": [(v.numpy(), f.numpy())], "labels": np.array([0])}
    assert len(psb_data.precompute(dataset, tmp_path)[0]) == 1
    real = psb_data.heat_kernel_signature
    monkeypatch.setattr(psb_data, "heat_kernel_signature", lambda *a, **k: real(*a, **k) * 0)
    with pytest.raises(ValueError, match="heat kernel signatures not all positive"):
        psb_data.precompute(dataset, tmp_path)


def test_precompute_times_only_the_meshes_it_computes(tmp_path):
    import torch_edgevf as ev

    v, f = ev.icosphere(2)
    dataset = {"meshes": [(v.numpy(), f.numpy())] * 2, "labels": np.array([0, 1])}
    batches, computed = psb_data.precompute(dataset, tmp_path)
    assert len(batches) == 2 and len(computed) == 1 and computed[0] > 0  # the second is cached
    assert psb_data.precompute(dataset, tmp_path)[1] == []
