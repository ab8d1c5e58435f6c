"""The modules of the PSB study (``experiments/psb_classification``), for its tests.

``run`` is the study's command (``run.py``) and ``variants`` its networks; both are
scripts beside each other, imported here as top-level modules.
"""

import sys
from pathlib import Path

#: the study's folder
STUDY = Path(__file__).resolve().parents[2] / "experiments" / "psb_classification"
sys.path.insert(0, str(STUDY))

import run  # noqa: E402
import variants  # noqa: E402

__all__ = ["STUDY", "run", "variants"]
