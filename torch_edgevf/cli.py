"""The ``edgevf`` command line. ``python -m torch_edgevf`` runs the demo on Spot."""

from __future__ import annotations

import argparse
import logging
import sys
import time

import numpy as np
import torch

log = logging.getLogger("torch_edgevf")


def _load(path):
    from .io import default_mesh, load_mesh

    return default_mesh() if path is None else load_mesh(path)


def _scipy(a: torch.Tensor):
    import scipy.sparse as sp

    a = a.detach().coalesce()
    i = a.indices().numpy()
    return sp.csc_matrix((a.values().numpy(), (i[0], i[1])), shape=a.shape)


def _smallest_eigenvalues(A, M, k):
    """The k smallest generalized eigenvalues, with the library's solver when available."""
    try:
        from .linalg import eigsh
    except ImportError:  # the solver package is optional during development
        import scipy.sparse.linalg as spla

        vals = spla.eigsh(_scipy(A), k=k, M=_scipy(M), sigma=-1e-6, return_eigenvectors=False)
        return np.sort(vals.real)
    return eigsh(A, M, k)[0].detach().numpy()


def cmd_demo(args) -> int:
    from . import EdgeOperators

    mesh = _load(args.mesh)
    print(f"mesh: {args.mesh or 'Spot (built-in, public domain, Keenan Crane)'}")
    t0 = time.perf_counter()
    ops = EdgeOperators(mesh.verts, mesh.faces, n=1)
    print(f"topology: {ops.topology}")
    print(f"assembled all operators in {time.perf_counter() - t0:.3f} s (float64, CPU)")
    rows = [
        ("M_z  (edge mass)", ops.mass),
        ("L_c  (connection Laplacian, n=1)", ops.connection_laplacian),
        ("G    (gradient)", ops.gradient),
        ("K    (curl/div)", ops.curl_div),
        ("L    (Laplace-Beltrami G* M_z^-1 G)", ops.laplace_beltrami),
        ("M_v  (vertex mass, full)", ops.vertex_mass),
    ]
    print(f"{'operator':40s} {'shape':>16s} {'nnz':>9s}  dtype")
    for name, a in rows:
        print(f"{name:40s} {str(tuple(a.shape)):>16s} {a._nnz():>9d}  {a.dtype}")
    k = args.k
    for n in (1, 2, 4):
        vals = _smallest_eigenvalues(ops.connection_laplacian_n(n), ops.mass, k)
        print(f"smallest eigenvalues of (L_c^({n}), M_z): " + " ".join(f"{x:.4f}" for x in vals))
    vals = _smallest_eigenvalues(ops.laplace_beltrami, ops.vertex_mass, k)
    print("smallest eigenvalues of (L, M_v):       " + " ".join(f"{x:.4f}" for x in vals))
    return 0


def cmd_info(args) -> int:
    from .diagnose import diagnose

    mesh = _load(args.mesh)
    print(mesh.report if hasattr(mesh, "report") else "")
    report = diagnose(mesh.verts, mesh.faces)
    print(report)
    return 0 if report.ok else 1


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="edgevf", description="Edge-based tangent vector fields on triangle meshes.")
    p.add_argument("-v", "--verbose", action="store_true", help="log progress")
    sub = p.add_subparsers(dest="command")
    d = sub.add_parser("demo", help="operators and their smallest eigenvalues on a mesh (default: Spot)")
    d.add_argument("mesh", nargs="?", default=None)
    d.add_argument("-k", type=int, default=6, help="number of eigenvalues")
    d.set_defaults(func=cmd_demo)
    i = sub.add_parser("info", help="topology of a mesh and any problems found, with their locations")
    i.add_argument("mesh", nargs="?", default=None)
    i.set_defaults(func=cmd_info)
    return p


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(message)s")
    if args.command is None:
        args = parser.parse_args(["demo", *([] if argv is None else argv)])
    try:
        return args.func(args)
    except (ValueError, FileNotFoundError) as exc:
        print(f"edgevf: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
