"""The modules of the PSB study (``experiments/psb_classification``), and two readers of its
outputs, for its tests.

``run`` is the study's command (``run.py``) and ``variants`` its networks; both are
scripts beside each other, imported here as top-level modules.
"""

import sys
from pathlib import Path

import numpy as np

#: the study's folder
STUDY = Path(__file__).resolve().parents[2] / "experiments" / "psb_classification"
sys.path.insert(0, str(STUDY))

import run  # noqa: E402
import variants  # noqa: E402

__all__ = ["STUDY", "run", "variants", "euler_of_closed", "paired_rows"]


def euler_of_closed(dataset) -> np.ndarray:
    """The Euler characteristic of each closed mesh of ``dataset``: V - E + F with E = 3F/2."""
    return np.array([len(v) - len(f) // 2 for v, f in dataset["meshes"]])


def paired_rows(markdown: str) -> dict[str, list[str]]:
    """The rows of the study's ``paired_table``: model name -> its other cells."""
    cells = ([c.strip() for c in line.strip("|").split("|")] for line in markdown.splitlines())
    return {c[0]: c[1:] for c in cells if len(c) > 1 and c[0] not in ("model", "---")}
