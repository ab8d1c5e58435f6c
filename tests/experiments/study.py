"""The modules of the PSB study (``experiments/psb_classification``), and two readers of its
outputs, for its tests.

``run`` is the study's command (``run.py``), ``psb_data``, ``psb_training`` and
``psb_report`` its data, training and tables, and ``variants`` (with
``variants_common``) its networks; all are scripts beside each other, imported here as
top-level modules.
"""

import json
import sys
from pathlib import Path

import numpy as np
import torch

from torch_edgevf.learning import batching, precompute

from conftest import load_script

#: the study's folder
STUDY = Path(__file__).resolve().parents[2] / "experiments" / "psb_classification"
sys.path.insert(0, str(STUDY))

import psb_data  # noqa: E402
import psb_report  # noqa: E402
import psb_training  # noqa: E402
import variants  # noqa: E402
import variants_common  # noqa: E402

run = load_script(STUDY / "run.py", "psb_run")  # the RNA study has a ``run.py`` too

__all__ = [
    "README",
    "RECOMMENDED",
    "RERUN",
    "ROOT",
    "STUDY",
    "psb_data",
    "psb_report",
    "psb_training",
    "run",
    "variants",
    "variants_common",
    "euler_of_closed",
    "paired_rows",
    "saved_runs",
    "joined_text",
    "seed_of",
    "fold_counts",
    "SAMPLE_OPTIONS",
    "sample",
    "one_batch",
]


def euler_of_closed(dataset) -> np.ndarray:
    """The Euler characteristic of each closed mesh of ``dataset``: V - E + F with E = 3F/2."""
    return np.array([len(v) - len(f) // 2 for v, f in dataset["meshes"]])


def paired_rows(markdown: str) -> dict[str, list[str]]:
    """The rows of the study's ``paired_table``: model name -> its other cells."""
    cells = ([c.strip() for c in line.strip("|").split("|")] for line in markdown.splitlines())
    return {c[0]: c[1:] for c in cells if len(c) > 1 and c[0] not in ("model", "---")}


#: the repository root
ROOT = STUDY.parents[1]
#: the study's README: its tables, its reading and its report
README = "experiments/psb_classification/README.md"
#: this release's runs of the recommended recipe, the reference of the README's verdicts
RERUN = "edgefieldnet, 4 stretched copies, coefficients, averaged last 10"
#: the recommended network, with the recommended recipe
RECOMMENDED = "edgefieldnet-nodiv-meanpool, 4 stretched copies, averaged last 10"


def saved_runs(name: str) -> list[dict]:
    """The runs saved in the study's folder, ``experiments/psb_classification/NAME``."""
    return json.loads((STUDY / name).read_text())


def joined_text(path: str) -> str:
    """The text of the repository's file ``path`` with its lines joined by single spaces,
    so that a phrase is found wherever the file breaks its lines."""
    return " ".join((ROOT / path).read_text().split())


def seed_of(r: dict) -> int:
    """The seed of a run (a sort key)."""
    return r["seed"]


def fold_counts(rows, label, seed) -> dict[str, int]:
    """Correct of 76 per fold (``"fold0"``, ...) of partition 0 for the runs of ``seed``
    labelled ``label`` (``rows`` through ``psb_report.with_averaged``)."""
    return {
        r["split"]: round(r["test_accuracy"] * 76)
        for r in rows
        if psb_report.label(r) == label
        and r["seed"] == seed
        and r.get("partition", 0) == 0
        and r["split"].startswith("fold")
    }


#: the operators of the networks' test meshes
SAMPLE_OPTIONS = dict(k_edge=16, k_vertex=16, vertex_gradient=True)


def sample(v, f, label=0, dtype=torch.float64) -> batching.MeshSample:
    """Mesh ``(v, f)`` with its operators and 8-scale heat kernel signatures, labelled ``label``."""
    ops = precompute.compute_operators(v, f, **SAMPLE_OPTIONS)
    x = precompute.heat_kernel_signature(ops.vertex_evals, ops.vertex_evecs, count=8)
    return batching.MeshSample(ops.to(dtype), x.to(dtype), label)


def one_batch(v, f, label=0, dtype=torch.float64) -> batching.MeshBatch:
    """The batch of :func:`sample` alone."""
    return batching.collate_meshes([sample(v, f, label, dtype)])
