"""The PSB study's tables: a row per model and recipe, accuracies over seeds, folds and
splits, and the fold-by-fold comparison with the corrected resampled t test."""

from __future__ import annotations

import statistics

import numpy as np
from psb_data import STRETCH
from psb_training import AVERAGE_EPOCHS
from variants import K_EDGE

#: the faithful DiffusionNet: as its public classification script builds it (no dropout)
BASELINE = "diffusionnet-nodropout"
#: the recommended edge-field network: log-HKS in, no divergence and curl of the fields in
#: the blocks' MLPs, DiffusionNet's readout (the mean of per-vertex logits)
RECOMMENDED_MODEL = "edgefieldnet-nodiv-meanpool"
DEFAULT_MODELS = (RECOMMENDED_MODEL, BASELINE)
#: the row of ``edgefieldnet`` (the previous recommendation) with the recommended recipe
#: (``--augment 4``, averaged weights; see :func:`label`): the reference of the report's
#: fold-by-fold comparisons
PAIRED_REFERENCE = f"edgefieldnet, 4 stretched copies, averaged last {AVERAGE_EPOCHS}"


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


def baseline_of(names) -> str:
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
