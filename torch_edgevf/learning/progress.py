"""A progress bar for long precomputations (tqdm when installed, else a small built-in one).

It is silent when stderr is not a terminal, and under pytest.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterable, Sized

__all__ = ["progress"]


def _progress_enabled(enabled: bool | None) -> bool:
    if enabled is not None:
        return bool(enabled)
    if "PYTEST_CURRENT_TEST" in os.environ:
        return False
    return bool(getattr(sys.stderr, "isatty", lambda: False)())


class _SimpleBar:
    """A minimal stderr progress bar (used when tqdm is not installed)."""

    def __init__(self, iterable, total, desc):
        self.iterable, self.total, self.desc = iterable, total, desc

    def __iter__(self):
        total = self.total
        for i, item in enumerate(self.iterable, 1):
            yield item
            shown = f"{i}/{total}" if total else str(i)
            sys.stderr.write(f"\r{self.desc}: {shown}")
            sys.stderr.flush()
        sys.stderr.write("\n")
        sys.stderr.flush()


def progress(iterable: Iterable, total: int | None = None, desc: str = "", enabled: bool | None = None):
    """Wrap ``iterable`` in a progress bar on stderr.

    Uses ``tqdm`` when it is installed, else a small built-in bar. ``enabled=None``
    (default) shows it only when stderr is a terminal and not under pytest.
    """
    if total is None and isinstance(iterable, Sized):
        total = len(iterable)
    if not _progress_enabled(enabled):
        return iterable
    try:
        from tqdm.auto import tqdm
    except ImportError:
        return _SimpleBar(iterable, total, desc)
    return tqdm(iterable, total=total, desc=desc, file=sys.stderr)
