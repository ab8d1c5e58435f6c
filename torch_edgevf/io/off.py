"""The OFF reader (ASCII, polygons, records wrapped over lines)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .numbers import parse_numbers


def _read_off(path: Path):
    """Vertices and faces of an ASCII OFF file, or None for another variant (binary).

    The faces are an ``(F, k)`` array when every face has ``k`` corners (``k = 3``:
    triangles, used as they are), else a list of index arrays (polygons of several sizes).
    Records are read as tokens, so a record may wrap over several lines; what follows the
    last number of a record on its line (colours, normals) is skipped. ``#`` starts a
    comment. Header variants ``OFF``, ``COFF``, ``NOFF``, ``STOFF``... with the counts on
    the header line or the next.
    """
    text = path.read_bytes().decode("latin-1")
    fast = _read_plain_off(text)
    if fast is not None:
        return fast
    lines = [line.split("#", 1)[0].split() for line in text.splitlines()]
    tokens = [(i, t) for i, words in enumerate(lines) for t in words]
    if (
        not tokens
        or not tokens[0][1].upper().endswith("OFF")
        or "BINARY" in {t.upper() for _, t in tokens[:3]}
    ):
        return None
    header = tokens[0][1].upper()
    pos = 1

    def number(kind):
        nonlocal pos
        if pos >= len(tokens):
            raise ValueError(f"cannot read mesh {path}: the OFF file ends inside the {kind} records")
        line, tok = tokens[pos]
        pos += 1
        return line, tok

    def skip_line(line):
        nonlocal pos
        while pos < len(tokens) and tokens[pos][0] == line:
            pos += 1

    try:
        dim = 4 if header.startswith("4") or "4OFF" in header else 3
        counts = [int(number("header")[1]) for _ in range(3)]
        nv, nf = counts[0], counts[1]
        verts = np.empty((nv, 3), dtype=np.float64)
        extras = header != "OFF"  # COFF, NOFF, STOFF...: per-vertex data after the coordinates
        for i in range(nv):
            coords = [number("vertex") for _ in range(dim)]
            verts[i] = [float(t) for _, t in coords[:3]]
            if extras:
                skip_line(coords[-1][0])
        polys = []
        for _ in range(nf):
            line, tok = number("face")
            k = int(tok)
            idx = [number("face") for _ in range(k)]
            polys.append(np.array([int(t) for _, t in idx], dtype=np.int64))
            last = idx[-1][0] if idx else line
            rest = [t for ln, t in tokens[pos : pos + 64] if ln == last]
            if rest and not _whole_records(rest):
                skip_line(last)  # a colour after the indices
    except ValueError as err:
        if "ends inside" in str(err):
            raise
        raise ValueError(f"cannot read mesh {path}: not a valid OFF file ({err})") from err
    if nf == 0:
        raise ValueError(f"cannot read mesh {path}: it is a point cloud ({nv} points, no faces)")
    return verts, polys


def _read_plain_off(text: str):
    """The common case of :func:`_read_off` in one vectorised parse, or None.

    A plain ``OFF`` header, no comments, three coordinates per vertex, faces of one size
    and nothing after the indices of a face; anything else (or counts that do not add
    up) returns None and goes through the general reader.
    """
    if "#" in text:
        return None
    head = text.split(None, 4)
    if len(head) < 5 or head[0] != "OFF":
        return None
    try:
        nv, nf = int(head[1]), int(head[2])
        int(head[3])
    except ValueError:
        return None
    if nv < 0 or nf <= 0:
        return None
    values = parse_numbers(head[4], np.float64)
    start = 3 * nv
    if values is None or len(values) <= start:
        return None
    corners = values[start]
    if corners != int(corners) or corners < 3 or len(values) != start + nf * (int(corners) + 1):
        return None
    records = values[start:].reshape(nf, int(corners) + 1)
    index = records[:, 1:]
    if (records[:, 0] != corners).any() or (np.abs(index) >= 2**53).any() or (index != np.trunc(index)).any():
        return None
    return values[:start].reshape(nv, 3), index.astype(np.int64)


def _whole_records(words: list[str]) -> bool:
    """Whether ``words`` are complete face records ``k i_1 .. i_k`` (not a colour)."""
    i = 0
    while i < len(words):
        if not words[i].isdigit():
            return False
        i += int(words[i]) + 1
    return i == len(words)
