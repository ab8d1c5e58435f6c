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
that have spheres, and trains on every other mesh (see :func:`psb_data.topology_shift_flags`);
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
from pathlib import Path

import numpy as np
import torch

from torch_edgevf.learning import resolve_device
from torch_edgevf.learning.datasets import psb_path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # the study's modules, beside this file
from psb_data import (  # noqa: E402
    INPUTS,
    STRETCH,
    VERTEX_LAPLACIANS,
    load_psb,
    precompute,
    precompute_copies,
    splits,
    subset,
)
from psb_report import DEFAULT_MODELS, baseline_of, in_partitions, paired_table, table, with_averaged  # noqa: E402
from psb_training import (  # noqa: E402
    AVERAGE_EPOCHS,
    SCHEDULES,
    precompute_times,
    profile_step,
    step_times,
    train,
)
from variants import K_EDGE, MODELS  # noqa: E402


def parse(argv=None) -> tuple[argparse.ArgumentParser, argparse.Namespace]:
    """The command's parser and its arguments."""
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
    return p, p.parse_args(argv)


def main(argv=None) -> list[dict]:
    p, a = parse(argv)
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
        against = baseline_of(times)
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
