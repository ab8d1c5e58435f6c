"""Whitespace-separated numbers of text records, parsed in C by numpy, and counts per line.

The readers of OFF, OBJ and PLY files gather the records they need into one byte string
(one record a line) and parse it in a single call; the counts per line tell whether
every record has the expected number of fields (triangles, three coordinates) or which
rows are polygons.
"""

from __future__ import annotations

import numpy as np


def parse_numbers(text: str | bytes, dtype) -> np.ndarray | None:
    """The numbers of ``text`` (separated by any whitespace) as a flat array, or None.

    None when a token is not a number of ``dtype`` (``1.5`` or ``x`` for integers).
    ``nan`` and ``inf`` are numbers.
    """
    try:
        return np.fromstring(text, dtype=dtype, sep=" ")
    except ValueError:
        return None


def line_starts(b: np.ndarray) -> np.ndarray:
    """Offsets of the lines of the bytes ``b`` (``\\n``-separated; a final empty line not counted)."""
    starts = np.concatenate(([0], np.flatnonzero(b == 10) + 1))
    return starts[starts < len(b)] if len(b) else starts[:0]


def per_line(mask: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """The number of True entries of ``mask`` (one per byte) in each line starting at ``starts``."""
    if not len(starts):
        return np.zeros(0, dtype=np.int64)
    return np.add.reduceat(mask.view(np.uint8), starts, dtype=np.int64)


def token_starts(b: np.ndarray) -> np.ndarray:
    """(len(b),) bool: the bytes that start a whitespace-separated token."""
    space = b <= 32  # space, tab, \r, \n and other control characters
    out = ~space
    out[1:] &= space[:-1]
    return out


def tokens_per_line(text: str | bytes, num_lines: int) -> np.ndarray:
    """(num_lines,) int64: the whitespace-separated tokens of each ``\\n``-separated line of ``text``."""
    data = text.encode("latin-1", errors="replace") if isinstance(text, str) else text
    b = np.frombuffer(data, dtype=np.uint8)
    counts = per_line(token_starts(b), line_starts(b))
    out = np.zeros(num_lines, dtype=np.int64)
    out[: min(num_lines, len(counts))] = counts[:num_lines]
    return out
