"""The PSB study's data: the dataset file, its splits, the operators and inputs of every
mesh (cached), and the stretched copies of ``--augment`` and ``--tta``."""

from __future__ import annotations

import time

import numpy as np
import torch
from variants import K_EDGE

from torch_edgevf.learning.augment import random_stretch, random_warp
from torch_edgevf.learning.batching import MeshBatch
from torch_edgevf.learning.cache import OperatorCache
from torch_edgevf.learning.datasets import psb_mesh
from torch_edgevf.learning.precompute import heat_kernel_signature, mean_curvature_signature
from torch_edgevf.mesh.repair import find_degenerate_faces, repair_degenerate_faces
from torch_edgevf.mesh.topology import Topology

OPERATOR_OPTIONS = dict(k_edge=K_EDGE, k_vertex=128, vertex_gradient=True)
VERTEX_LAPLACIANS = ("cotan", "robust")
#: input features of every model: the heat kernel signature (16 scales), or it followed by
#: the signed mean curvature and its heat diffusion at 8 times (9 channels, extrinsic)
INPUTS = ("hks", "hks+curvature")
HKS_SCALES = 16
#: largest stretch factor of the augmented copies (see :func:`stretched`)
STRETCH = 1.25


def operator_options(vertex_laplacian: str = "cotan", k_edge: int = K_EDGE) -> dict:
    """The options of :func:`compute_operators` for the benchmark (cotan: the cache keys as before)."""
    if vertex_laplacian not in VERTEX_LAPLACIANS:
        raise ValueError(f"vertex_laplacian must be one of {VERTEX_LAPLACIANS}, got {vertex_laplacian!r}")
    options = dict(OPERATOR_OPTIONS, k_edge=k_edge)
    if vertex_laplacian == "cotan":
        return options
    return dict(options, vertex_laplacian=vertex_laplacian)


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
