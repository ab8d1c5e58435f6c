"""What the commands share: argument types, checks before any work, loading, pictures."""

from __future__ import annotations

import argparse
import logging
import math
import os
import re
import sys
import time
from typing import Any

log = logging.getLogger("torch_edgevf")

BUILT_IN = "spot_low_resolution (built in)"
"""How the built-in mesh (Spot, 1,654 faces) is named in the output."""

MESH_SUFFIXES = (".obj", ".ply", ".off", ".stl")
FIELD_SUFFIXES = (".npz", ".txt")
MAX_BENCH_LEVEL = 7
"""Largest icosphere level of ``edgevf bench`` (327,680 faces; level 8 needs several GB)."""
MAX_N = 16
MAX_K = 64
MESH_HELP = "OBJ, PLY, OFF or STL file (default: the built-in mesh)"
#: the legend of the pictures of singularities
LEGEND = "singularities: index > 0 green, < 0 red"
_AXES = ("x", "y", "z", "+x", "+y", "+z", "-x", "-y", "-z")


class Progress:
    """Numbered stage messages with elapsed times, on stderr (long work shows progress)."""

    def __init__(self, total: int, quiet: bool = False):
        self.total, self.done, self.quiet = total, 0, quiet
        self.start = time.perf_counter()

    def __call__(self, message: str) -> None:
        self.done += 1
        if not self.quiet:
            elapsed = time.perf_counter() - self.start
            print(f"[{self.done}/{self.total} {elapsed:6.1f}s] {message}", file=sys.stderr, flush=True)


class Parser(argparse.ArgumentParser):
    """Argument errors as one line on stderr (exit 2), naming where to find the usage."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


# --------------------------------------------------------------------------- argument types


def bounded_int(lo: int, hi: int | None = None):
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if value < lo or (hi is not None and value > hi):
            bounds = f"in [{lo}, {hi}]" if hi is not None else f">= {lo}"
            raise argparse.ArgumentTypeError(f"must be an integer {bounds}, got {value}")
        return value

    return parse


def direction(text: str):
    """``auto``, an axis (``y``, ``-z``) or three numbers ``a,b,c`` (not all zero)."""
    t = text.strip().lower()
    if t == "auto" or t in _AXES:
        return t
    parts = [x for x in re.split(r"[,\s]+", t) if x]
    try:
        vec = tuple(float(x) for x in parts)
    except ValueError:
        vec = ()
    if len(vec) != 3 or not all(math.isfinite(x) for x in vec) or not any(vec):
        raise argparse.ArgumentTypeError(
            f"expected 'auto', an axis ({', '.join(_AXES[:3])}, -x, ...) or three numbers a,b,c "
            f"not all zero, got {text!r}"
        )
    return vec


def image_size(text: str):
    """``800`` (square) or ``800x600``."""
    m = re.fullmatch(r"\s*(\d+)\s*(?:[xX]\s*(\d+)\s*)?", text)
    if not m:
        raise argparse.ArgumentTypeError(f"expected WIDTH or WIDTHxHEIGHT in pixels, got {text!r}")
    w, h = int(m.group(1)), int(m.group(2) or m.group(1))
    if not (16 <= w <= 8192 and 16 <= h <= 8192):
        raise argparse.ArgumentTypeError(f"width and height must lie in [16, 8192], got {text!r}")
    return w if w == h and m.group(2) is None else (w, h)


# --------------------------------------------------------------------------- checks before work


def check_input(path: str | None, suffixes, what: str) -> None:
    if path is None:
        return
    if os.path.splitext(path)[1].lower() not in suffixes:
        raise ValueError(f"{path}: unsupported extension for a {what}, expected one of {', '.join(suffixes)}")
    if not os.path.isfile(path):
        raise ValueError(f"{path}: no such file")


def check_output(path: str | None, suffixes, option: str) -> None:
    if not path:
        return
    if os.path.splitext(path)[1].lower() not in suffixes:
        raise ValueError(f"{option} {path}: unsupported extension, expected {' or '.join(suffixes)}")
    folder = os.path.dirname(path) or "."
    if not os.path.isdir(folder):
        raise ValueError(f"{option} {path}: no such directory {folder}")
    if os.path.isdir(path):
        raise ValueError(f"{option} {path}: is a directory")


def png_options(args) -> dict:
    return {"up": args.up, "view": args.view, "size": args.size}


def png(path, render, verts, faces, **kwargs):
    """Render a PNG if matplotlib is installed; otherwise say how to get it."""
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        print(
            "edgevf: matplotlib is not installed, no picture written (pip install 'torch_edgevf[plot]')",
            file=sys.stderr,
        )
        return None
    out = render(verts, faces, path=path, **kwargs)
    print(f"wrote {out}")
    return out


def load(path):
    from ..io import default_mesh, load_mesh

    return default_mesh() if path is None else load_mesh(path)


def load_manifold(path):
    """The mesh and its :class:`Topology`, built once for the whole command; refused
    (``ValueError``) before any work when the topology is unusable."""
    from ..mesh.topology import Topology

    mesh = load(path)
    return mesh, Topology(mesh.faces, num_vertices=mesh.verts.shape[0])  # raises on non-manifold edges


def mesh_name(path) -> str:
    return BUILT_IN if path is None else str(path)


def smallest_eigenvalues(A, M, k):
    """The k smallest generalized eigenvalues of ``A x = lambda M x``."""
    from ..linalg import eigsh

    return eigsh(A, M, k).values.detach().numpy()


def singularity_line(sing) -> str:
    import torch

    idx = torch.cat([sing.face_index, sing.vertex_index])
    idx = idx[idx != 0]
    values, counts = torch.unique(idx, return_counts=True)
    parts = ", ".join(f"{int(c)} of index {float(v):+g}" for v, c in zip(values, counts))
    return f"{int(idx.numel())} singularities ({parts or 'none'}); indices sum to {float(sing.total):g}"


def design(mesh, topo, n: int, align: str):
    from ..fields.design import curvature_aligned_field, smoothest_field

    if align == "curvature":
        return curvature_aligned_field(mesh.verts, topo, n=n)
    return smoothest_field(mesh.verts, topo, n=n)


def crack_tol(args) -> float:
    """The ``--tol`` of info and repair (the library's default when not given)."""
    from ..mesh.diagnose import COINCIDENT_TOL

    return COINCIDENT_TOL if getattr(args, "tol", None) is None else args.tol


def _number(text: str, what: str = "a number") -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None


def tolerance(text: str) -> float:
    value = _number(text)
    if not 0 <= value < 1:
        raise argparse.ArgumentTypeError(f"must be a number in [0, 1), got {value}")
    return value


def positive(text: str) -> float:
    value = _number(text)
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text!r}")
    return value


def angle(text: str) -> float:
    value = _number(text, "a number of degrees")
    if not 0 <= value < 180:
        raise argparse.ArgumentTypeError(f"must be in [0, 180) degrees, got {text!r}")
    return value


def some(items, limit: int = 10) -> str:
    head = ", ".join(str(i) for i in items[:limit])
    return head if len(items) <= limit else f"{head}, ... ({len(items)} in all)"


def read_soup(path):
    """Vertices, triangles and the reader's report of a file, or of the built-in mesh, unchecked."""
    from ..io import default_mesh, read_triangles

    if path is None:
        mesh = default_mesh()
        return mesh.verts.numpy(), mesh.faces.numpy(), mesh.report
    return read_triangles(path, merge=True)


def start(args, steps: int, outputs=()) -> tuple[Progress, Any, Any]:
    """What a command on a mesh does first: check the mesh file, the ``--png`` path and the
    other ``outputs`` (``(path, suffixes, option)``) before any work, then load the mesh and
    build its topology once. Returns the progress messages (``steps`` of them), the mesh
    and its :class:`~torch_edgevf.mesh.topology.Topology`."""
    check_input(args.mesh, MESH_SUFFIXES, "mesh")
    for path, suffixes, option in outputs:
        check_output(path, suffixes, option)
    check_output(args.png, (".png",), "--png")
    step = Progress(steps + bool(args.png), args.quiet)
    return (step, *load_manifold(args.mesh))


def singularities_png(args, verts, topo, z, n: int, sing, what: str):
    """The ``--png`` picture of a field and its singularities, titled ``what`` and the legend."""
    from ..render import render_singularities

    return png(
        args.png,
        render_singularities,
        verts,
        topo,
        face_index=sing.face_index,
        vertex_index=sing.vertex_index,
        z=z,
        n=n,
        title=f"{what}; {LEGEND}",
        **png_options(args),
    )
