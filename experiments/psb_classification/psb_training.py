"""The PSB study's training recipe and its timings: models by name, optimiser and schedule,
the training loop (with averaged weights and augmented copies), accuracies, and the step
and precompute times of ``--step-time`` and ``--precompute-time``."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import torch
from psb_data import HKS_SCALES, K_EDGE, operator_options, without_degenerate_faces
from variants import MODELS

from torch_edgevf.learning.precompute import compute_operators

#: the repository root (benchmarks/bench_peers.py rebuilds DiffusionNet's precompute)
ROOT = Path(__file__).resolve().parents[2]
#: epochs whose final weights are averaged (those after the learning rate is halved at 50)
AVERAGE_EPOCHS = 10
#: learning-rate schedules: halved every 50 epochs (DiffusionNet's), or a cosine decay to 0
SCHEDULES = ("step", "cosine")


def label_smoothing_loss(logits: torch.Tensor, label: int, smoothing: float = 0.2) -> torch.Tensor:
    """Cross-entropy against ``1 - s`` on the label and ``s / (C - 1)`` on every other class."""
    logp = torch.log_softmax(logits, dim=-1)
    target = torch.full_like(logp, smoothing / (logp.shape[-1] - 1))
    target[..., label] = 1.0 - smoothing
    return -(target * logp).sum(-1).mean()


def new_model(name: str, batch, num_classes: int, seed: int, weight_decay: float = 0.0):
    """Model ``name`` initialised from ``seed``, and its optimiser at the recipe's rate: Adam,
    or AdamW (decoupled weight decay) with ``weight_decay > 0``."""
    torch.manual_seed(seed)
    channels = batch.features.shape[1]
    # the channels after the HKS (the mean curvature) are signed: no logarithm of them
    model = MODELS[name](channels, num_classes, True if channels <= HKS_SCALES else HKS_SCALES)
    model = model.to(batch.features.device)  # where the batches are (--device)
    if weight_decay > 0:
        return model, torch.optim.AdamW(model.parameters(), lr=1e-3, weight_decay=weight_decay)
    return model, torch.optim.Adam(model.parameters(), lr=1e-3)


def new_schedule(opt, schedule: str, epochs: int):
    """The learning-rate schedule, stepped once per epoch: ``"step"`` halves the rate every
    50 epochs; ``"cosine"`` decays it along a half cosine to 0 after the last epoch."""
    if schedule == "step":
        return torch.optim.lr_scheduler.StepLR(opt, step_size=50, gamma=0.5)
    if schedule == "cosine":
        return torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=epochs)
    raise ValueError(f"schedule must be one of {SCHEDULES}, got {schedule!r}")


def train_step(model, opt, batch) -> None:
    """One optimiser step on one mesh: label-smoothed cross-entropy, backward, step."""
    opt.zero_grad()
    label_smoothing_loss(model(batch)[0], int(batch.labels)).backward()
    opt.step()


@torch.no_grad()
def predictions(model, batches) -> list[int]:
    """The class the model gives each batch (one mesh each)."""
    model.eval()
    out = [int(model(b).argmax(-1).item()) for b in batches]
    model.train()
    return out


def accuracy(model, batches, predicted: list[int] | None = None) -> float:
    """The fraction of ``batches`` classified right (from ``predicted`` if given)."""
    predicted = predictions(model, batches) if predicted is None else predicted
    correct = sum(int(p == int(b.labels)) for p, b in zip(predicted, batches))
    return correct / max(len(batches), 1)


@torch.no_grad()
def tta_accuracy(model, batches, copies) -> float:
    """Accuracy of the class probabilities averaged over each mesh and its ``copies``
    (test-time augmentation with the stretched copies of :func:`precompute_copies`)."""
    model.eval()
    correct = 0
    for b, others in zip(batches, copies):
        p = sum(torch.softmax(model(x)[0], dim=-1) for x in [b, *others])
        correct += int(p.argmax().item() == int(b.labels))
    model.train()
    return correct / max(len(batches), 1)


def fit(
    name: str,
    train_set,
    seed: int,
    epochs: int,
    num_classes: int,
    average: int = AVERAGE_EPOCHS,
    copies: list | None = None,
    weight_decay: float = 0.0,
    schedule: str = "step",
):
    """Train model ``name``: ``(model, averaged model or None, seconds)``.

    The averaged model holds the mean of the weights after each of the last ``average``
    epochs (stochastic weight averaging, :class:`torch.optim.swa_utils.AveragedModel`).
    Averaging draws no random numbers: the final weights are those of a run without it.
    ``copies[i]``: augmented copies of ``train_set[i]``; each step then takes the mesh or
    one of its copies, drawn uniformly (the same number of steps as without them).
    ``weight_decay`` and ``schedule``: see :func:`new_model` and :func:`new_schedule`.
    """
    model, opt = new_model(name, train_set[0], num_classes, seed, weight_decay)
    sched = new_schedule(opt, schedule, epochs)
    averaged = torch.optim.swa_utils.AveragedModel(model) if average > 0 else None
    order = torch.Generator().manual_seed(seed)
    pick = torch.Generator().manual_seed(seed)  # apart from the order: that stays as without copies
    start = time.perf_counter()
    for epoch in range(epochs):
        for i in torch.randperm(len(train_set), generator=order).tolist():
            batch = train_set[i]
            if copies and copies[i]:
                k = int(torch.randint(len(copies[i]) + 1, (1,), generator=pick))
                batch = copies[i][k - 1] if k else batch
            train_step(model, opt, batch)
        sched.step()
        if averaged is not None and epoch >= epochs - average:
            averaged.update_parameters(model)
    return model, averaged, time.perf_counter() - start


def train(
    name: str,
    train_set,
    test_set,
    seed: int,
    epochs: int,
    num_classes: int,
    average: int = AVERAGE_EPOCHS,
    copies: list | None = None,
    test_copies: list | None = None,
    weight_decay: float = 0.0,
    schedule: str = "step",
) -> dict:
    """The record of one run: accuracies after the final epoch and, with ``average``, those
    of the weights averaged over the last ``average`` epochs of the same run (see :func:`fit`).
    Training accuracy is that on ``train_set`` (without the copies). With ``test_copies``
    (per test mesh, its stretched copies), also the accuracies of the probabilities
    averaged over each test mesh and its copies (:func:`tta_accuracy`). ``test_predictions``
    (and ``averaged_test_predictions``): the class given to each test mesh, in the order
    of ``test_set``, for comparing models mesh by mesh."""
    model, averaged, seconds = fit(
        name, train_set, seed, epochs, num_classes, average, copies, weight_decay, schedule
    )
    predicted = predictions(model, test_set)
    out = {
        "model": name,
        "seed": seed,
        "test_accuracy": accuracy(model, test_set, predicted),
        "test_predictions": predicted,
        "train_accuracy": accuracy(model, train_set),
        "train_seconds": seconds,
        "seconds_per_step": seconds / max(epochs * len(train_set), 1),
        "parameters": sum(p.numel() for p in model.parameters()),
    }
    if averaged is not None:
        predicted = predictions(averaged.module, test_set)
        out.update(
            average_epochs=min(average, epochs),
            averaged_test_accuracy=accuracy(averaged.module, test_set, predicted),
            averaged_test_predictions=predicted,
            averaged_train_accuracy=accuracy(averaged.module, train_set),
        )
    if test_copies is not None:
        out["tta_test_accuracy"] = tta_accuracy(model, test_set, test_copies)
        if averaged is not None:
            out["averaged_tta_test_accuracy"] = tta_accuracy(averaged.module, test_set, test_copies)
    return out


def profile_step(name: str, batch, num_classes: int, rows: int = 12) -> str:
    """The operators that take the time of one training step (torch profiler, self CPU time)."""
    model, opt = new_model(name, batch, num_classes, 0)
    for _ in range(3):
        train_step(model, opt, batch)
    with torch.profiler.profile() as prof:
        for _ in range(10):
            train_step(model, opt, batch)
    return prof.key_averages().table(sort_by="self_cpu_time_total", row_limit=rows)


def step_times(names, batches, num_classes: int, rounds: int = 3, passes: int = 3) -> dict[str, list[float]]:
    """Seconds per training step of each model, the models alternated ``rounds`` times.

    Each round trains every model for ``passes`` passes over ``batches`` (forward,
    backward and Adam step, one mesh per step) after one untimed pass.
    """
    out: dict[str, list[float]] = {n: [] for n in names}
    for _ in range(rounds):
        for name in names:
            model, opt = new_model(name, batches[0], num_classes, 0)
            for p in range(passes + 1):
                if p == 1:
                    start = time.perf_counter()
                for b in batches:
                    train_step(model, opt, b)
            out[name].append((time.perf_counter() - start) / (passes * len(batches)))
    return out


def precompute_times(
    dataset: dict, rounds: int = 3, vertex_laplacian: str = "cotan", k_edge: int = K_EDGE
) -> dict[str, list[float]]:
    """Seconds per mesh of the operator precompute: DiffusionNet's against this library's.

    ``diffusionnet``: the steps of DiffusionNet's ``compute_operators`` (robust_laplacian's
    Laplacian, ARPACK ``eigsh`` with ``k = 128``, the least-squares vertex gradient), as
    ``bench_peers.py`` rebuilds them; ``edgefieldnet``: :func:`compute_operators` with the
    options of this benchmark (``k = 128`` vertex and ``k_edge`` edge eigenpairs, ``G``, ``L_c``,
    the vertex gradient). Alternated ``rounds`` times over the meshes; nothing cached.
    """
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import bench_peers

    if bench_peers._peer("robust_laplacian") is None:
        raise SystemExit("--precompute-time needs robust_laplacian (benchmarks/requirements-peers.txt)")
    meshes = []
    for v, f in dataset["meshes"]:
        v, f = without_degenerate_faces(v, f)
        meshes.append((np.ascontiguousarray(v, dtype=np.float64), np.ascontiguousarray(f, dtype=np.int64)))
    steps = {
        "diffusionnet": lambda v, f: bench_peers.diffusionnet_reference(v, f),
        "edgefieldnet": lambda v, f: compute_operators(v, f, **operator_options(vertex_laplacian, k_edge)),
    }
    out: dict[str, list[float]] = {n: [] for n in steps}
    for fn in steps.values():  # one untimed call each
        fn(*meshes[0])
    for _ in range(rounds):
        for name, fn in steps.items():
            start = time.perf_counter()
            for v, f in meshes:
                fn(v, f)
            out[name].append((time.perf_counter() - start) / len(meshes))
    return out
