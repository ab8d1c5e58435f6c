"""The tables of README.md from the saved runs (``runs/*.json``, as written by ``run.py --json``).

    python experiments/rna_segmentation/report.py            # print the tables
    python experiments/rna_segmentation/report.py --check    # fail if README.md differs

Each table sits in README.md between ``<!-- table:NAME -->`` and ``<!-- end -->``; the
headline (``table:rna``) in the repository's README.md.
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
NAMES = {
    "edgefieldnet": "EdgeFieldNet (local edge fields, recommended)",
    "diffusionnet": "DiffusionNet (faithful)",
    "edgefieldnet-smooth": "EdgeFieldNet with smooth fields (L_c eigenbasis)",
    "edgefieldnet-scalar": "EdgeFieldNet without the vector stream",
    "edgefieldnet-vertexvec": "EdgeFieldNet with vertex gradients in place of G",
    "edgefieldnet-divcurl": "EdgeFieldNet with smooth fields, their divergence and curl in the MLPs",
}


def load_runs(folder: Path = HERE / "runs") -> list[dict]:
    rows = []
    for path in sorted(folder.glob("*.json")):
        rows += json.loads(path.read_text())["results"]
    return rows


def _mean_spread(values: list[float]) -> str:
    if len(values) == 1:
        return f"{100 * values[0]:.1f}"
    return f"{100 * statistics.mean(values):.1f} ± {100 * statistics.stdev(values):.1f}"


def table(rows: list[dict], split: str, models: tuple[str, ...]) -> str:
    """Accuracy and mIoU (mean ± standard deviation over seeds, in %), per model."""
    lines = [
        "| network | seeds | accuracy (%) | per seed | mIoU (%) | accuracy at 5k vertices (%) | s / step |",
        "|---|---:|---:|---|---:|---:|---:|",
    ]
    for model in models:
        runs = sorted(
            (r for r in rows if r["model"] == model and r["split"] == split), key=lambda r: r["seed"]
        )
        if not runs:
            continue
        acc = [r["test_accuracy"] for r in runs]
        decimated = [r["test_accuracy_decimated"] for r in runs if "test_accuracy_decimated" in r]
        lines.append(
            f"| {NAMES.get(model, model)} | {', '.join(str(r['seed']) for r in runs)} | {_mean_spread(acc)} "
            f"| {', '.join(f'{100 * a:.1f}' for a in acc)} | {_mean_spread([r['test_miou'] for r in runs])} "
            f"| {_mean_spread(decimated) if decimated else ''} "
            f"| {statistics.mean(r['seconds_per_step'] for r in runs):.2f} |"
        )
    return "\n".join(lines)


def validation_table(rows: list[dict]) -> str:
    """The configuration check: one seed, 6 epochs on 100 training meshes, scored on 40 others."""
    lines = [
        "| network | inputs | seed | accuracy (%) | mIoU (%) | final training accuracy (%) |",
        "|---|---|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {NAMES.get(r['model'], r['model'])} | {r['inputs']} | {r['seed']} "
            f"| {100 * r['test_accuracy']:.1f} | {100 * r['test_miou']:.1f} "
            f"| {100 * r['train_accuracy']:.1f} |"
        )
    return "\n".join(lines)


def curve_table(folder: Path = HERE / "runs" / "curves") -> str:
    """Test accuracy (training accuracy) of each run's checkpoints by epoch, from ``curve.py --json``."""
    points: dict[tuple[str, str, str, str], dict[int, dict]] = {}
    for path in sorted(folder.glob("*.json")):
        for r in json.loads(path.read_text())["curve"]:
            run = re.sub(r"(-e\d+)?\.pt$", "", r["checkpoint"])
            part = f"{r['part']} ({r['meshes']} meshes)"
            points.setdefault((r["model"], r["split"], run, part), {})[r["epoch"]] = r
    epochs = sorted({e for by_epoch in points.values() for e in by_epoch})
    lines = [
        "| network | split | run | scored on | " + " | ".join(f"epoch {e}" for e in epochs) + " |",
        "|---|---|---|---|" + "---:|" * len(epochs),
    ]
    order = list(NAMES)
    for (model, split, run, part), by_epoch in sorted(
        points.items(), key=lambda item: (item[0][3], order.index(item[0][0]) if item[0][0] in order else 99)
    ):
        cells = []
        for e in epochs:
            r = by_epoch.get(e)
            train = "" if r is None or r["train_accuracy"] is None else f" ({100 * r['train_accuracy']:.1f})"
            cells.append("" if r is None else f"{100 * r['test_accuracy']:.1f}{train}")
        lines.append(f"| {NAMES.get(model, model)} | {split} | {run} | {part} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def tables(rows: list[dict]) -> dict[str, str]:
    return {
        "curve": curve_table(),
        "validation": validation_table(load_runs(HERE / "runs" / "validation")),
        "official": table(rows, "official", ("edgefieldnet", "diffusionnet", "edgefieldnet-smooth")),
        "ablations": table(rows, "official", tuple(NAMES)),
        "random1": table(rows, "split_random1.json", ("edgefieldnet", "diffusionnet", "edgefieldnet-smooth")),
    }


def headline(rows: list[dict]) -> str:
    """The repository README's lines: the official split, the recommended network and the
    faithful DiffusionNet, accuracy and mIoU (mean over the seeds run) and time per step."""
    lines = [
        "| network | seeds | per-vertex accuracy (%) | mIoU (%) | s / step |",
        "|---|---:|---:|---:|---:|",
    ]
    for model, label in (("edgefieldnet", "**`EdgeFieldNet`**"), ("diffusionnet", "faithful DiffusionNet")):
        runs = [r for r in rows if r["model"] == model and r["split"] == "official"]
        if runs:
            lines.append(
                f"| {label} | {len(runs)} | {_mean_spread([r['test_accuracy'] for r in runs])} "
                f"| {_mean_spread([r['test_miou'] for r in runs])} "
                f"| {statistics.mean(r['seconds_per_step'] for r in runs):.2f} |"
            )
    return "\n".join(lines)


def fill(readme: str, made: dict[str, str]) -> str:
    for name, text in made.items():
        pattern = re.compile(rf"(<!-- table:{name} -->\n).*?(<!-- end -->)", flags=re.S)
        readme = pattern.sub(lambda m, text=text: m[1] + text + "\n" + m[2], readme)
    return readme


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--check", action="store_true", help="fail if README.md's tables differ from the runs")
    p.add_argument("--write", action="store_true", help="write the tables into README.md")
    a = p.parse_args(argv)
    made = tables(load_runs())
    pages = {HERE / "README.md": made, HERE.parents[1] / "README.md": {"rna": headline(load_runs())}}
    if a.write:
        for path, tables_of in pages.items():
            path.write_text(fill(path.read_text(), tables_of))
        return 0
    if a.check:
        stale = [str(p) for p, tables_of in pages.items() if fill(p.read_text(), tables_of) != p.read_text()]
        if stale:
            print(
                f"the tables of {', '.join(stale)} differ from the saved runs: run report.py --write",
                file=sys.stderr,
            )
            return 1
        return 0
    for name, text in made.items():
        print(f"{name}:\n{text}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
