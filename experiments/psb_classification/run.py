"""Shape classification on PSB: the edge-field network against a faithful DiffusionNet.

One command reproduces a table of this folder's README (run from the repository root)::

    python experiments/psb_classification/run.py --data psb_watertight_2k.npz           # fixed split, 3 seeds
    python experiments/psb_classification/run.py --data psb_watertight_2k.npz --augment 4 # recommended recipe
    python experiments/psb_classification/run.py --data psb_watertight_2k.npz --folds 5 # stratified 5-fold CV
    python experiments/psb_classification/run.py --data psb_watertight_2k.npz --folds 5 --only-folds 0,1 \\
        --json folds01.json                                                # part of one CV
    python experiments/psb_classification/run.py --table folds01.json folds234.json  # the table of saved runs
    python experiments/psb_classification/run.py --table runs.json --paired "edgefieldnet, averaged last 10"
                                                        # and every row against one, fold by fold
    python experiments/psb_classification/run.py --quick                             # a small smoke run

Without ``--models`` it trains the recommended network (``edgefieldnet-nodiv-meanpool``:
the library's ``EdgeFieldNet`` on the logarithm of the heat kernel signatures) and the
faithful DiffusionNet (``diffusionnet-nodropout``: the library's ``DiffusionNet`` without
dropout, on the signatures as they are); ``--models`` takes any of ``variants.MODELS``.

Every model is trained with the same recipe, on the same operators, inputs, seeds and
threads, one after the other in this process: the 16-scale heat kernel signature of the
vertex Laplacian as input (every model is invariant to rigid motions; ``--input
hks+curvature`` appends the signed mean curvature and its heat diffusion, extrinsic
features that the models' logarithm leaves out), one mesh per
optimiser step, Adam at ``1e-3`` halved every 50 epochs, label smoothing 0.2, dropout 0.5
in the per-vertex MLPs (none in the ``-nodropout`` models: the faithful DiffusionNet is
built without it, as its public classification script builds it). The accuracy reported
is the one after the final epoch (no model selection on the test set); each run also
reports that of its weights averaged over the last ``--average`` epochs (default 10, the
epochs after the rate is halved).

``--augment K`` gives every model in the run the same K stretched copies of each training
mesh (a random anisotropic stretch by factors up to 1.25, or ``--stretch S``, and with
``--warp S`` a smooth random warp of strain at most S, the copy re-centred and scaled to
the unit sphere as the dataset's meshes are; operators cached);
each step takes the mesh or one of its copies, so a run takes as many steps as without
them. ``--tta K`` also reports the accuracy of the class probabilities averaged over each
test mesh and K stretched copies of it.

``--weight-decay W`` trains every model with AdamW (decoupled weight decay ``W``) in place
of Adam; ``--schedule cosine`` decays the learning rate along a half cosine to 0 over the
run in place of halving it every 50 epochs.

``--data`` (or ``$TORCH_EDGEVF_PSB``) is the ``psb_watertight_2k.npz`` file (see the
README for how to build it); operators are cached on disk in ``--cache`` (default
``$TORCH_EDGEVF_CACHE`` or ``~/.cache/torch_edgevf/operators``). ``--split FILE`` takes a
``.npy`` of one flag per mesh in the file's order (0 train, 1 test, -1 left out);
``--validation`` trains on 12 of the 16 training meshes of each class and tests on the
other 4, leaving the test meshes out, for choosing a design without them.
``--topology-shift`` tests on the meshes that are not topological spheres in the classes
that have spheres, and trains on every other mesh (see :func:`topology_shift_flags`);
with ``--validation`` it does so within the fixed split's training meshes, leaving the
test meshes out: a split across topology for choosing a design.

``--vertex-laplacian`` chooses the vertex Laplacian of every model (its eigenbasis gives
the input signatures and the vertex diffusion): ``cotan`` (default) or ``robust``, the
intrinsic Delaunay Laplacian that DiffusionNet's own code computes with
``robust_laplacian`` (about one edge in eight of a decimated PSB mesh is not Delaunay, and
there the cotangent weight is negative).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import torch

from torch_edgevf.learning import resolve_device
from torch_edgevf.learning.augment import random_stretch, random_warp
from torch_edgevf.learning.batching import MeshBatch
from torch_edgevf.learning.cache import OperatorCache
from torch_edgevf.learning.datasets import psb_mesh, psb_path
from torch_edgevf.learning.precompute import (
    compute_operators,
    heat_kernel_signature,
    mean_curvature_signature,
)
from torch_edgevf.mesh.repair import find_degenerate_faces, repair_degenerate_faces
from torch_edgevf.mesh.topology import Topology

sys.path.insert(0, str(Path(__file__).resolve().parent))  # variants.py, beside this file
from variants import K_EDGE, MODELS  # noqa: E402

#: the repository root (benchmarks/bench_peers.py rebuilds DiffusionNet's precompute)
ROOT = Path(__file__).resolve().parents[2]

#: the faithful DiffusionNet: as its public classification script builds it (no dropout)
BASELINE = "diffusionnet-nodropout"
#: the recommended edge-field network: log-HKS in, no divergence and curl of the fields in
#: the blocks' MLPs, DiffusionNet's readout (the mean of per-vertex logits)
RECOMMENDED_MODEL = "edgefieldnet-nodiv-meanpool"
DEFAULT_MODELS = (RECOMMENDED_MODEL, BASELINE)
OPERATOR_OPTIONS = dict(k_edge=K_EDGE, k_vertex=128, vertex_gradient=True)
VERTEX_LAPLACIANS = ("cotan", "robust")
#: input features of every model: the heat kernel signature (16 scales), or it followed by
#: the signed mean curvature and its heat diffusion at 8 times (9 channels, extrinsic)
INPUTS = ("hks", "hks+curvature")
HKS_SCALES = 16
#: largest stretch factor of the augmented copies (see :func:`stretched`)
STRETCH = 1.25
#: epochs whose final weights are averaged (those after the learning rate is halved at 50)
AVERAGE_EPOCHS = 10
#: the row of ``edgefieldnet`` (the previous recommendation) with the recommended recipe
#: (``--augment 4``, averaged weights; see :func:`label`): the reference of the report's
#: fold-by-fold comparisons
PAIRED_REFERENCE = f"edgefieldnet, 4 stretched copies, averaged last {AVERAGE_EPOCHS}"
#: learning-rate schedules: halved every 50 epochs (DiffusionNet's), or a cosine decay to 0
SCHEDULES = ("step", "cosine")


def operator_options(vertex_laplacian: str = "cotan", k_edge: int = K_EDGE) -> dict:
    """The options of :func:`compute_operators` for the benchmark (cotan: the cache keys as before)."""
    if vertex_laplacian not in VERTEX_LAPLACIANS:
        raise ValueError(f"vertex_laplacian must be one of {VERTEX_LAPLACIANS}, got {vertex_laplacian!r}")
    options = dict(OPERATOR_OPTIONS, k_edge=k_edge)
    if vertex_laplacian == "cotan":
        return options
    return dict(options, vertex_laplacian=vertex_laplacian)


# --------------------------------------------------------------------------- data


def load_psb(path) -> dict:
    # every array read once: an NpzFile decompresses an array again on each access
    with np.load(path, allow_pickle=False) as data:
        d = {name: data[name] for name in data.files}
    meshes = []
    for i in range(len(d["labels"])):
        v, f = psb_mesh(d, i)
        meshes.append((v.astype(np.float64), f))
    return {
        "meshes": meshes,
        "labels": d["labels"].astype(np.int64),
        "split": d["split"].astype(np.int64),
        "classes": [str(c) for c in d["classes"]],
        "ids": d["psb_ids"].astype(np.int64) if "psb_ids" in d else np.arange(len(d["labels"])),
    }


def subset(dataset: dict, classes: int, per_class: int) -> dict:
    """The first ``per_class`` meshes of each of the first ``classes`` classes (for --quick)."""
    keep = [i for c in range(classes) for i in np.flatnonzero(dataset["labels"] == c)[:per_class]]
    out = {
        k: [dataset[k][i] for i in keep] if k == "meshes" else dataset[k][keep] for k in ("meshes", "labels")
    }
    out["split"] = np.array([int(j >= per_class * 3 // 4) for c in range(classes) for j in range(per_class)])
    out["classes"] = dataset["classes"][:classes]
    return out


def without_degenerate_faces(v, f):
    """The mesh with each zero-area face collapsed (one PSB mesh has one), else as it is."""
    if len(find_degenerate_faces(v, f)):
        v, f = repair_degenerate_faces(v, f)[:2]
    return v, f


def precompute(
    dataset: dict, cache_dir, vertex_laplacian: str = "cotan", k_edge: int = K_EDGE, inputs: str = "hks"
) -> tuple[list[MeshBatch], list[float]]:
    """One single-mesh batch per mesh (operators cached), and the seconds of each mesh computed.

    ``vertex_laplacian``: the Laplacian of the vertex eigenbasis, of the heat kernel
    signatures and of the vertex diffusion (``"robust"``: DiffusionNet's intrinsic
    Delaunay Laplacian, see :func:`compute_operators`); ``k_edge``: the eigenpairs of
    ``L_c``; ``inputs``: one of :data:`INPUTS`.
    """
    if inputs not in INPUTS:
        raise ValueError(f"inputs must be one of {INPUTS}, got {inputs!r}")
    options = operator_options(vertex_laplacian, k_edge)
    cache = OperatorCache(cache_dir)
    batches, computed = [], []
    for (v, f), label in zip(dataset["meshes"], dataset["labels"]):
        v, f = without_degenerate_faces(v, f)
        ops = cache.load(cache.key(v, f, **options))
        if ops is None:  # computed here, and timed (a mesh that failed before raises at once)
            t = time.perf_counter()
            ops = cache.get(v, f, **options)
            computed.append(time.perf_counter() - t)
        x = heat_kernel_signature(ops.vertex_evals, ops.vertex_evecs, count=HKS_SCALES).float()
        if not bool((x > 0).all()):  # at least the constant mode's term: else the eigenpairs are wrong
            raise ValueError(f"mesh of {len(v)} vertices: heat kernel signatures not all positive")
        if inputs == "hks+curvature":
            h = mean_curvature_signature(
                ops.verts, ops.faces, ops.vertex_evals, ops.vertex_evecs, ops.vertex_mass
            )
            x = torch.cat([x, h.float()], dim=1)
        batches.append(MeshBatch.from_operators(ops.to(torch.float32), x, int(label)))
    return batches, computed


def stretched(v: np.ndarray, index: int, copy: int, spread: float = STRETCH, warp: float = 0.0) -> np.ndarray:
    """Copy ``copy`` of mesh ``index``: :func:`random_stretch` by factors up to ``spread``,
    then, with ``warp`` > 0, :func:`random_warp` of that strain, centred and scaled to the
    unit bounding sphere again, as the dataset's meshes are. The same arguments give the
    same copy (so its operators are cached once); the stretch of a warped copy is that of
    the copy without the warp."""
    rng = np.random.default_rng([index, copy])
    w = random_stretch(v, rng, max_factor=spread)
    return random_warp(w, rng, strain=warp) if warp else w


def precompute_copies(
    dataset: dict,
    cache_dir,
    copies: int,
    keep: np.ndarray,
    vertex_laplacian: str = "cotan",
    spread: float = STRETCH,
    warp: float = 0.0,
    k_edge: int = K_EDGE,
    inputs: str = "hks",
) -> list[list[MeshBatch]]:
    """Per mesh, the batches of its ``copies`` stretched copies (:func:`stretched`, by
    factors up to ``spread``, warped with strain ``warp``; none for meshes where ``keep``
    is False), with their operators cached like the meshes'.

    A copy whose operators cannot be computed (a stretch can turn a nearly degenerate face
    into one whose eigenpairs are lost to rounding: ``ValueError``) is left out, and
    reported; the cache records the failure, so later runs leave it out at once.
    """
    out: list[list[MeshBatch]] = [[] for _ in dataset["labels"]]
    dropped = []
    for i in np.flatnonzero(keep) if copies else []:
        v, f = dataset["meshes"][i]
        for c in range(copies):
            copy = stretched(v, int(i), c, spread, warp)
            one = {"meshes": [(copy, f)], "labels": dataset["labels"][i : i + 1]}
            try:
                out[i] += precompute(one, cache_dir, vertex_laplacian, k_edge, inputs)[0]
            except ValueError as e:
                dropped.append(f"mesh {int(i)} copy {c}: {str(e)[:80]}")
    if dropped:
        print(f"augment: left out {len(dropped)} copies: " + "; ".join(dropped), flush=True)
    return out


def validation_flags(dataset: dict, per_class: int = 4) -> np.ndarray:
    """A split for choosing a design without the test meshes: -1 left out, 0 train, 1 validation.

    Within the fixed split's training meshes of each class, the last ``per_class`` by mesh
    id are the validation meshes (as the fixed split takes the last 4 of 20 for its test
    set); the fixed test meshes are left out.
    """
    flags = np.where(dataset["split"] == 1, -1, 0)
    ids = dataset.get("ids", np.arange(len(dataset["labels"])))
    for c in np.unique(dataset["labels"]):
        train = np.flatnonzero((dataset["labels"] == c) & (dataset["split"] == 0))
        flags[train[np.argsort(ids[train])][-per_class:]] = 1
    return flags


def topology_shift_flags(dataset: dict, validation: bool = False) -> np.ndarray:
    """A split across topology: -1 left out, 0 train, 1 test.

    The test meshes are those that are not topological spheres (Euler characteristic other
    than 2) in a class that has spheres; every other mesh trains. Each test mesh so has a
    topology that no training mesh of its class has (a cup with a handle, where the
    training cups have none), while a class without spheres trains whole.

    With ``validation``, the same within the fixed split's training meshes: its test
    meshes are left out (-1), so that a design can be chosen across topology without them.
    """
    labels = np.asarray(dataset["labels"])
    euler = np.array(
        [Topology(torch.as_tensor(f), len(v)).euler_characteristic for v, f in dataset["meshes"]]
    )
    has_spheres = np.isin(labels, labels[euler == 2])
    flags = ((euler != 2) & has_spheres).astype(np.int64)
    if validation:
        flags[np.asarray(dataset["split"]) == 1] = -1
    return flags


def splits(
    dataset: dict,
    folds: int,
    split_file,
    validation: bool = False,
    partition: int = 0,
    topology_shift: bool = False,
):
    """``(name, train mask, test mask)`` per evaluation.

    The fixed split, a user split (a ``.npy`` of one flag per mesh: 0 train, 1 test, -1
    left out), the validation split of :func:`validation_flags`, the split across topology
    of :func:`topology_shift_flags`, or stratified folds: the
    meshes of each class dealt to the ``folds`` folds in an order drawn from ``partition``
    (the same folds for every training seed; another ``partition`` for repeated
    cross-validation).
    """
    n = len(dataset["labels"])
    if folds:
        rng = np.random.default_rng(partition)
        fold = np.zeros(n, dtype=np.int64)
        for c in np.unique(dataset["labels"]):
            idx = rng.permutation(np.flatnonzero(dataset["labels"] == c))
            fold[idx] = np.arange(len(idx)) % folds
        return [(f"fold{k}", fold != k, fold == k) for k in range(folds)]
    if topology_shift:
        flags = topology_shift_flags(dataset, validation)
        return [("topology validation" if validation else "topology", flags == 0, flags == 1)]
    if validation:
        flags = validation_flags(dataset)
        return [("validation", flags == 0, flags == 1)]
    if split_file:
        flags = np.load(split_file)
        if flags.shape != (n,) or not np.isin(flags, (-1, 0, 1)).all():
            raise ValueError(
                f"--split must hold {n} flags of 0 (train), 1 (test) or -1 (left out), got "
                f"shape {flags.shape} and values {sorted(set(np.unique(flags).tolist()))[:5]}"
            )
        if not (flags == 0).any() or not (flags == 1).any():
            raise ValueError("--split needs at least one training (0) and one test (1) mesh")
        return [("split", flags == 0, flags == 1)]
    return [("fixed", dataset["split"] == 0, dataset["split"] == 1)]


# --------------------------------------------------------------------------- training


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


# --------------------------------------------------------------------------- report


def label(r: dict) -> str:
    """The row of a run: its model, the vertex Laplacian when it is not the cotangent one
    and the edge eigenpairs when not ``K_EDGE``, the augmentation, the warp of the copies,
    weight decay, schedule and ``--tag`` if any, and whether the accuracy is that of the
    averaged weights (see :func:`with_averaged`)."""
    lap = r.get("vertex_laplacian", "cotan")
    name = r["model"] if lap == "cotan" else f"{r['model']} ({lap} Laplacian)"
    if r.get("k_edge", K_EDGE) != K_EDGE:
        name += f" ({r['k_edge']} edge eigenpairs)"
    if r.get("input", "hks") != "hks":
        name += ", mean curvature input"
    if r.get("augment"):
        name += f", {r['augment']} stretched copies"
        if r.get("stretch", STRETCH) != STRETCH:
            name += f" (up to {r['stretch']:g})"
    if r.get("warp"):  # of the copies of --augment or --tta
        name += f", warped (strain {r['warp']:g})"
    if r.get("weight_decay"):
        name += f", weight decay {r['weight_decay']:g}"
    if r.get("schedule", "step") != "step":
        name += f", {r['schedule']} schedule"
    if r.get("tag"):
        name += f", {r['tag']}"
    return f"{name}, averaged last {r['average_epochs']}" if r.get("averaged") else name


def with_averaged(results: list[dict]) -> list[dict]:
    """Each run, followed by a row of its averaged weights' accuracies where it has them."""
    out = []
    for r in results:
        out.append(r)
        if "averaged_test_accuracy" in r:
            row = dict(
                r,
                averaged=True,
                test_accuracy=r["averaged_test_accuracy"],
                train_accuracy=r["averaged_train_accuracy"],
            )
            if "averaged_test_predictions" in r:
                row["test_predictions"] = r["averaged_test_predictions"]
            out.append(row)
    return out


def _base(names) -> str:
    """The model times are compared with: the faithful baseline where it ran, else ``diffusionnet``."""
    return BASELINE if BASELINE in names else "diffusionnet"


def table(results: list[dict], models_run=None) -> str:
    """Markdown: per model, test accuracy on the fixed split (over seeds), over the folds,
    and on other splits (``--validation``, ``--split``, ``--topology-shift``) where there are
    any; time (as a ratio to ``diffusionnet``'s step, "-" without its runs); parameters.
    One row per name in ``models_run`` (default: every :func:`label` of ``results``, in order).

    The cross-validation cell is over the folds of partition 0 (the default of
    ``--partition``); the runs of another partition follow it, as ``partition P: ...``,
    so that repeated cross-validation does not change what the first figure means."""
    if models_run is None:
        models_run = list(dict.fromkeys(label(r) for r in results))
    base = [r["seconds_per_step"] for r in results if r["model"] == "diffusionnet"]

    def own(split: str) -> bool:  # --validation or --split, neither the fixed split nor a fold
        return split != "fixed" and not split.startswith("fold")

    other = any(own(r["split"]) for r in results)
    head = "| model | fixed split (mean ± std) | cross-validation (mean ± std) |"
    head += " validation or own split (mean ± std) |" if other else ""
    lines = [
        head + " train s / run | time vs DiffusionNet | parameters |",
        "|---|---|---|" + ("---|" if other else "") + "---|---|---|",
    ]

    def stat(xs):
        if not xs:
            return "-"
        sd = statistics.stdev(xs) if len(xs) > 1 else 0.0
        return f"{statistics.mean(xs):.3f} ± {sd:.3f} (n={len(xs)})"

    for name in models_run:
        rs = [r for r in results if label(r) == name]
        fixed = [r["test_accuracy"] for r in rs if r["split"] == "fixed"]
        cv: dict[int, list[float]] = {}  # partition: accuracies over its fold runs
        for r in rs:
            if r["split"].startswith("fold"):
                cv.setdefault(r.get("partition", 0), []).append(r["test_accuracy"])
        cv_cell = "; ".join(
            stat(xs) if part == 0 else f"partition {part}: {stat(xs)}"
            for part, xs in sorted(cv.items())  # partitions are seeds, 0 or more: 0 first
        )
        rest = [r["test_accuracy"] for r in rs if own(r["split"])]
        ratio = statistics.mean(r["seconds_per_step"] for r in rs) / statistics.mean(base) if base else None
        seconds = statistics.mean(r["train_seconds"] for r in rs)
        cells = [name, stat(fixed), cv_cell or "-"] + ([stat(rest)] if other else [])
        cells += [f"{seconds:.0f}", "-" if ratio is None else f"{ratio:.2f}", f"{rs[0]['parameters']:,}"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def in_partitions(results: list[dict], partitions) -> list[dict]:
    """The runs, without the fold runs of partitions not in ``partitions`` (other splits kept)."""
    return [r for r in results if not r["split"].startswith("fold") or r.get("partition", 0) in partitions]


def paired_table(results: list[dict], reference: str, folds: int | None = None) -> str:
    """Markdown: every row against ``reference`` (a :func:`label`) on the folds both ran.

    Runs are paired by partition, fold and seed. Every seed splits the meshes into the
    same folds (:func:`splits`; the seed changes the training only), so the runs of one
    fold share their test meshes and are not separate samples: the test is over the folds
    (of every ``--partition`` run: repeated cross-validation, Bouckaert and Frank 2004),
    each fold's difference the mean over the seeds that both ran on it. Per row: how many
    folds (and runs) it shares with the reference, the mean over those folds of the reference's
    test accuracy minus the row's, in points, on how many runs the reference is ahead,
    level and behind, and the two-sided p-value of the corrected resampled t test (Nadeau
    and Bengio 2003): the variance of the mean difference over ``n`` folds is taken as
    ``(1/n + n_test/n_train) s^2``, with ``n_test/n_train = 1/(K-1)``, because the
    training sets of the folds overlap, and the naive ``s^2/n`` would make small
    differences look significant. ``folds`` is ``K``; by default one more than the largest
    fold index of the reference's runs. Rows that share fewer than two folds with the
    reference are left out.
    """
    from scipy import stats  # only the table needs it

    # row: (partition, fold, seed): accuracy
    by_fold: dict[str, dict[tuple[int, str, int], float]] = {}
    for r in results:
        accuracies = by_fold.setdefault(label(r), {})
        if r["split"].startswith("fold"):
            accuracies[(r.get("partition", 0), r["split"], r["seed"])] = r["test_accuracy"]
    ref = by_fold.get(reference)
    if not ref:
        raise ValueError(f"no cross-validation runs of {reference!r} to pair with")
    k = folds if folds is not None else 1 + max(int(split[4:]) for _, split, _ in ref)
    if k < 2:
        raise ValueError(f"the corrected t test needs at least 2 folds, got {k}")
    lines = [
        f"Against {reference}, fold by fold (the reference's accuracy minus the model's):",
        "",
        "| model | folds (runs) paired | mean difference (points) | runs: reference ahead / level / behind "
        "| p (corrected t over the folds) |",
        "|---|---:|---:|---|---:|",
    ]
    for name, other in by_fold.items():
        shared = sorted(set(ref) & set(other))
        groups = sorted({key[:2] for key in shared})  # (partition, fold)
        if name == reference or len(groups) < 2:
            continue
        diffs = {key: ref[key] - other[key] for key in shared}
        runs = np.array(list(diffs.values()))
        d = np.array([np.mean([v for key, v in diffs.items() if key[:2] == g]) for g in groups])
        n, mean, var = len(d), float(d.mean()), float(d.var(ddof=1))
        if var > 0:
            t = mean / np.sqrt((1 / n + 1 / (k - 1)) * var)
            p = float(2 * stats.t.sf(abs(t), n - 1))
        else:  # every fold the same difference
            p = 1.0 if mean == 0 else 0.0
        counts = f"{int((runs > 0).sum())} / {int((runs == 0).sum())} / {int((runs < 0).sum())}"
        lines.append(f"| {name} | {n} ({len(runs)}) | {100 * mean:+.2f} | {counts} | {p:.3f} |")
    return "\n".join(lines)


def main(argv=None) -> list[dict]:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", default=None, help="psb_watertight_2k.npz (default: $TORCH_EDGEVF_PSB)")
    p.add_argument(
        "--models", default=",".join(DEFAULT_MODELS), help=f"comma-separated, from {sorted(MODELS)}"
    )
    p.add_argument("--seeds", default="0,1,2")
    p.add_argument("--epochs", type=int, default=60)
    p.add_argument("--folds", type=int, default=0, help="stratified K-fold cross-validation over all meshes")
    p.add_argument(
        "--partition",
        type=int,
        default=0,
        metavar="N",
        help="with --folds: the seed of the meshes' assignment to folds (0: the saved runs' folds); "
        "repeated cross-validation runs the folds of several partitions",
    )
    p.add_argument(
        "--only-folds",
        default=None,
        metavar="K,...",
        help="with --folds: run only these folds (0-based), to spread one cross-validation over processes",
    )
    p.add_argument(
        "--split", default=None, help=".npy of 0 (train) / 1 (test) / -1 (left out) flags, one per mesh"
    )
    p.add_argument(
        "--validation",
        action="store_true",
        help="train on 12 of the fixed split's 16 training meshes per class and test on the other 4 "
        "(the last by id); the fixed test meshes are left out: for choosing a design",
    )
    p.add_argument(
        "--topology-shift",
        action="store_true",
        help="test on the meshes that are not topological spheres, in the classes that have spheres; "
        "train on every other mesh (with --validation: within the fixed split's training meshes)",
    )
    p.add_argument(
        "--average",
        type=int,
        default=AVERAGE_EPOCHS,
        metavar="N",
        help="also report the accuracy of the weights averaged over the last N epochs (0: off)",
    )
    p.add_argument(
        "--augment",
        type=int,
        default=0,
        metavar="K",
        help="K stretched copies of each training mesh (random stretch, see --stretch; operators cached); "
        "each step takes the mesh or one of its copies",
    )
    p.add_argument(
        "--stretch",
        type=float,
        default=STRETCH,
        metavar="S",
        help=f"largest stretch factor of the copies of --augment and --tta (default {STRETCH})",
    )
    p.add_argument(
        "--warp",
        type=float,
        default=0.0,
        metavar="S",
        help="also warp the copies of --augment and --tta smoothly, with strain at most S in [0, 1) "
        "(default 0: stretched only)",
    )
    p.add_argument(
        "--tta",
        type=int,
        default=0,
        metavar="K",
        help="also report the accuracy of the class probabilities averaged over each test mesh and "
        "K stretched copies of it (test-time augmentation)",
    )
    p.add_argument(
        "--weight-decay",
        type=float,
        default=0.0,
        metavar="W",
        help="decoupled weight decay (AdamW) for every model (default 0: Adam)",
    )
    p.add_argument(
        "--schedule",
        default="step",
        choices=SCHEDULES,
        help="learning rate halved every 50 epochs (step, default) or a cosine decay to 0",
    )
    p.add_argument(
        "--tag",
        default=None,
        help="a label for the runs of this call, shown in their table row (e.g. a code version)",
    )
    p.add_argument("--threads", type=int, default=2)
    p.add_argument(
        "--device", default="cpu", help="where the networks train: cpu (default), cuda, cuda:1, mps, ..."
    )
    p.add_argument(
        "--vertex-laplacian",
        default="cotan",
        choices=VERTEX_LAPLACIANS,
        help="Laplacian of the vertex eigenbasis, the input HKS and the vertex diffusion of every model "
        "(robust: DiffusionNet's intrinsic Delaunay Laplacian; needs robust_laplacian)",
    )
    p.add_argument(
        "--input",
        default="hks",
        choices=INPUTS,
        help="input features of every model: the heat kernel signature (16 scales), or it followed by "
        "the signed mean curvature and its heat diffusion at 8 times (extrinsic: tells creases and "
        "bends, which the HKS does not see)",
    )
    p.add_argument(
        "--k-edge",
        type=int,
        default=K_EDGE,
        metavar="K",
        help=f"eigenpairs of L_c, the basis of the vector stream's fields (default {K_EDGE})",
    )
    p.add_argument(
        "--cache",
        default=os.environ.get(
            "TORCH_EDGEVF_CACHE", str(Path.home() / ".cache" / "torch_edgevf" / "operators")
        ),
    )
    p.add_argument("--json", default=None, help="write every run's results here")
    p.add_argument("--profile", action="store_true", help="print a profile of one training step per model")
    p.add_argument(
        "--step-time",
        type=int,
        default=0,
        metavar="N",
        help="only time training steps on every 38th mesh (N meshes), the models alternated, and exit "
        "(with --json: the seconds per step of every round, per model)",
    )
    p.add_argument(
        "--precompute-time",
        type=int,
        default=0,
        metavar="N",
        help="only time the operator precompute per mesh on every 38th mesh (N meshes), "
        "DiffusionNet's against this library's, alternated, and exit",
    )
    p.add_argument(
        "--rounds",
        type=int,
        default=3,
        help="with --step-time / --precompute-time: how often the models alternate",
    )
    p.add_argument("--quick", action="store_true", help="4 classes, 8 meshes each, 3 epochs, one seed")
    p.add_argument(
        "--table", nargs="+", metavar="JSON", help="print the table of saved --json results and exit"
    )
    p.add_argument(
        "--paired",
        default=None,
        metavar="ROW",
        help="with --table: also every row against ROW (a row's name) on the folds both ran, "
        "with the p-value of the corrected resampled t test (--folds: K, by default from the runs)",
    )
    p.add_argument(
        "--partitions",
        default=None,
        metavar="P,...",
        help="with --table: keep the cross-validation runs of these partitions only (default: all)",
    )
    a = p.parse_args(argv)
    if a.paired and not a.table:
        p.error("--paired compares saved runs: give them with --table")
    if a.partitions is not None and not a.table:
        p.error("--partitions selects saved runs: give them with --table")
    if a.table:
        results = [r for f in a.table for r in json.loads(Path(f).read_text())]
        if a.partitions is not None:
            try:
                keep = {int(k) for k in a.partitions.split(",")}
            except ValueError:
                p.error(f"--partitions takes comma-separated numbers, got {a.partitions!r}")
            results = in_partitions(results, keep)
        print(table(with_averaged(results)))
        if a.paired:
            print()
            print(paired_table(with_averaged(results), a.paired, a.folds or None))
        return results
    names = [m for m in a.models.split(",") if m]
    unknown = sorted(set(names) - set(MODELS))
    if unknown:
        p.error(f"unknown models {unknown}; choose from {sorted(MODELS)}")
    if a.rounds < 1:
        p.error("--rounds must be at least 1")
    if a.augment < 0:
        p.error("--augment must be 0 (off) or a number of copies")
    if a.k_edge < 1:
        p.error("--k-edge must be at least 1")
    if not 0 <= a.warp < 1:
        p.error("--warp must be in [0, 1)")
    if a.warp and not (a.augment or a.tta):
        p.error("--warp warps the copies of --augment or --tta; give one of them")
    if not a.stretch >= 1:
        p.error("--stretch must be at least 1")
    if a.tta < 0:
        p.error("--tta must be 0 (off) or a number of copies")
    if a.average < 0:
        p.error("--average must be 0 (off) or a number of epochs")
    if not 0 <= a.weight_decay < float("inf"):
        p.error("--weight-decay must be 0 (off) or a finite positive number")
    if a.folds == 1 or a.folds < 0:
        p.error("--folds must be 0 (off) or at least 2")
    if sum(map(bool, (a.folds, a.split, a.validation or a.topology_shift))) > 1:
        p.error("--folds, --split and --validation or --topology-shift exclude each other")
    only_folds = None
    if a.only_folds is not None:
        try:
            only_folds = {int(k) for k in a.only_folds.split(",")}
        except ValueError:
            p.error(f"--only-folds takes comma-separated fold numbers, got {a.only_folds!r}")
        if not a.folds or not only_folds <= set(range(a.folds)):
            p.error(f"--only-folds needs --folds K and numbers in 0..K-1, got {a.only_folds!r}")
    if a.partition and not a.folds:
        p.error("--partition needs --folds K")
    if a.partition < 0:
        p.error("--partition must be a seed, 0 or more")
    try:
        device = resolve_device(a.device)
        a.data = str(psb_path(a.data))
    except ValueError as e:
        p.error(str(e))
    torch.set_num_threads(a.threads)

    dataset = load_psb(a.data)
    if a.quick:
        dataset = subset(dataset, classes=4, per_class=8)
        a.epochs, a.seeds = min(a.epochs, 3), a.seeds.split(",")[0]
    if a.step_time or a.precompute_time:
        keep = list(range(0, len(dataset["labels"]), 38))[: a.step_time or a.precompute_time]
        dataset = {
            **dataset,
            "meshes": [dataset["meshes"][i] for i in keep],
            "labels": dataset["labels"][keep],
            "split": dataset["split"][keep],
        }
    if a.precompute_time:
        times = precompute_times(
            dataset, rounds=a.rounds, vertex_laplacian=a.vertex_laplacian, k_edge=a.k_edge
        )
        base = statistics.mean(times["diffusionnet"])
        for name, ts in times.items():
            ms = ", ".join(f"{1e3 * t:.0f}" for t in ts)
            print(f"{name}: {ms} ms per mesh; mean vs diffusionnet {statistics.mean(ts) / base:.2f}")
        return [{"model": n, "seconds_per_mesh": ts} for n, ts in times.items()]
    batches, computed = precompute(dataset, a.cache, a.vertex_laplacian, a.k_edge, a.input)
    batches = [b.to(device) for b in batches]  # the operators are computed on the CPU
    if a.step_time:
        times = step_times(names, batches, len(dataset["classes"]), rounds=a.rounds)
        against = _base(times)
        base = statistics.mean(times.get(against, [float("nan")]))
        for name, ts in times.items():
            ms = ", ".join(f"{1e3 * t:.1f}" for t in ts)
            print(f"{name}: {ms} ms per step; mean vs {against} {statistics.mean(ts) / base:.2f}")
        measured = [
            {"model": n, "seconds_per_step": ts, "meshes": len(batches), "threads": a.threads}
            for n, ts in times.items()
        ]
        if a.json:
            Path(a.json).write_text(json.dumps(measured, indent=1) + "\n")
        return measured
    if computed:
        done = f"{len(computed)} computed, {statistics.mean(computed):.3f} s per mesh computed"
    else:
        done = "all from the cache"
    print(f"operators: {len(batches)} meshes, {done}", flush=True)
    results = []
    evaluations = splits(dataset, a.folds, a.split, a.validation, a.partition, a.topology_shift)
    if only_folds is not None:
        evaluations = [evaluations[k] for k in sorted(only_folds)]
    trained = np.any([m for _, m, _ in evaluations], axis=0)
    tested = np.any([m for _, _, m in evaluations], axis=0)
    options = dict(
        vertex_laplacian=a.vertex_laplacian, spread=a.stretch, warp=a.warp, k_edge=a.k_edge, inputs=a.input
    )
    copies = precompute_copies(dataset, a.cache, a.augment, trained, **options)
    tta_copies = precompute_copies(dataset, a.cache, a.tta, tested, **options)
    copies = [[c.to(device) for c in cs] for cs in copies]
    tta_copies = [[c.to(device) for c in cs] for cs in tta_copies]
    for split_name, train_mask, test_mask in evaluations:
        train_set = [b for b, t in zip(batches, train_mask) if t]
        train_copies = [c for c, t in zip(copies, train_mask) if t]
        test_set = [b for b, t in zip(batches, test_mask) if t]
        test_copies = [c for c, t in zip(tta_copies, test_mask) if t] if a.tta else None
        for seed in [int(s) for s in a.seeds.split(",")]:
            for name in names:
                r = train(
                    name,
                    train_set,
                    test_set,
                    seed,
                    a.epochs,
                    len(dataset["classes"]),
                    a.average,
                    train_copies,
                    test_copies,
                    a.weight_decay,
                    a.schedule,
                )
                r.update(split=split_name, epochs=a.epochs, threads=a.threads)
                # the meshes of test_predictions, indices in the file's order
                r.update(test_meshes=np.flatnonzero(test_mask).tolist())
                if a.augment:
                    r["augment"] = a.augment
                if a.tta:
                    r["tta"] = a.tta
                if (a.augment or a.tta) and a.stretch != STRETCH:
                    r["stretch"] = a.stretch
                if a.warp:  # only with --augment or --tta (checked above)
                    r["warp"] = a.warp
                if a.vertex_laplacian != "cotan":
                    r["vertex_laplacian"] = a.vertex_laplacian
                if a.k_edge != K_EDGE:
                    r["k_edge"] = a.k_edge
                if a.input != "hks":
                    r["input"] = a.input
                if a.weight_decay:
                    r["weight_decay"] = a.weight_decay
                if a.schedule != "step":
                    r["schedule"] = a.schedule
                if a.tag:
                    r["tag"] = a.tag
                if a.partition:
                    r["partition"] = a.partition
                print(json.dumps(r), flush=True)
                results.append(r)
                if a.json:
                    Path(a.json).write_text(json.dumps(results, indent=1))
    print(table(with_averaged(results)))
    if a.profile:
        for name in names:
            report = profile_step(name, batches[0], len(dataset["classes"]))
            print(f"\none training step of {name} (10 steps):\n{report}")
    return results


if __name__ == "__main__":
    sys.exit(0 if main() else 1)
