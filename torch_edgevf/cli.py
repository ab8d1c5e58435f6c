"""The ``edgevf`` command line. ``python -m torch_edgevf`` runs the demo on Spot."""

from __future__ import annotations

import argparse
import logging
import sys
import time

import torch

from .allocator import tune_allocator
from .linalg import eigsh

log = logging.getLogger("torch_edgevf")


class _Progress:
    """Numbered stage messages with elapsed times, on stderr (long work shows progress)."""

    def __init__(self, total: int, quiet: bool = False):
        self.total, self.done, self.quiet = total, 0, quiet
        self.start = time.perf_counter()

    def __call__(self, message: str) -> None:
        self.done += 1
        if not self.quiet:
            elapsed = time.perf_counter() - self.start
            print(f"[{self.done}/{self.total} {elapsed:6.1f}s] {message}", file=sys.stderr, flush=True)


def _png(path, render, *args, **kwargs):
    """Render a PNG if matplotlib is installed; otherwise say how to get it."""
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        print(
            "edgevf: matplotlib is not installed, no picture written (pip install 'torch_edgevf[plot]')",
            file=sys.stderr,
        )
        return None
    out = render(*args, path, **kwargs)
    print(f"wrote {out}")
    return out


def _load(path):
    from .io import default_mesh, load_mesh

    return default_mesh() if path is None else load_mesh(path)


def _smallest_eigenvalues(A, M, k):
    """The k smallest generalized eigenvalues of ``A x = lambda M x``."""
    return eigsh(A, M, k).values.detach().numpy()


def cmd_demo(args) -> int:
    from . import EdgeOperators, singularities, smoothest_field
    from .render import render_field

    step = _Progress(4, args.quiet)
    mesh = _load(args.mesh)
    print(f"mesh: {args.mesh or 'Spot (built-in, public domain, Keenan Crane)'}")
    step("assembling operators")
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
    step("smallest eigenvalues")
    k = args.k
    for n in (1, 2, 4):
        vals = _smallest_eigenvalues(ops.connection_laplacian_n(n), ops.mass, k)
        print(f"smallest eigenvalues of (L_c^({n}), M_z): " + " ".join(f"{x:.4f}" for x in vals))
    vals = _smallest_eigenvalues(ops.laplace_beltrami, ops.vertex_mass, k)
    print("smallest eigenvalues of (L, M_v):       " + " ".join(f"{x:.4f}" for x in vals))
    step("smoothest cross field and its singularities")
    z = smoothest_field(mesh.verts, mesh.faces, n=4)
    sing = singularities(mesh.verts, mesh.faces, z, n=4)
    print(f"smoothest cross field: {_singularity_line(sing)}")
    if args.png:
        step(f"rendering {args.png}")
        _png(args.png, render_field, mesh.verts, mesh.faces, z, n=4, title="smoothest cross field")
    return 0


def _singularity_line(sing) -> str:
    idx = torch.cat([sing.face_index, sing.vertex_index])
    idx = idx[idx != 0]
    values, counts = torch.unique(idx, return_counts=True)
    parts = ", ".join(f"{int(c)} of index {float(v):+g}" for v, c in zip(values, counts))
    return f"{int(idx.numel())} singularities ({parts or 'none'}); indices sum to {float(sing.total):g}"


def _design(mesh, n: int, align: str):
    from .fields.design import curvature_aligned_field, smoothest_field

    if align == "curvature":
        return curvature_aligned_field(mesh.verts, mesh.faces, n=n)
    return smoothest_field(mesh.verts, mesh.faces, n=n)


def cmd_design(args) -> int:
    from .io import save_field
    from .render import render_field

    step = _Progress(2 + bool(args.png), args.quiet)
    mesh = _load(args.mesh)
    step(
        f"designing the {'curvature-aligned' if args.align == 'curvature' else 'smoothest'} "
        f"{args.n}-direction field"
    )
    z = _design(mesh, args.n, args.align)
    step(f"writing {args.output}")
    save_field(args.output, mesh.verts, mesh.faces, z.detach(), n=args.n)
    print(f"wrote {args.output}: {z.shape[0]} edges, n = {args.n}")
    if args.png:
        step(f"rendering {args.png}")
        _png(args.png, render_field, mesh.verts, mesh.faces, z.detach(), n=args.n)
    return 0


def cmd_singularities(args) -> int:
    from . import singularities
    from .io import load_field
    from .render import render_singularities

    step = _Progress(2, args.quiet)
    if args.field:
        data = load_field(args.field)
        verts, faces, z, n = data.verts, data.faces, data.z, data.n
        if z.dim() != 1:
            raise ValueError(f"{args.field}: expected one field (E,), got {tuple(z.shape)}")
    else:
        mesh = _load(args.mesh)
        step(f"designing the smoothest {args.n}-direction field")
        verts, faces, n = mesh.verts, mesh.faces, args.n
        z = _design(mesh, n, "none")
    step("computing indices")
    sing = singularities(verts, faces, z.detach(), n=n)
    print(_singularity_line(sing))
    for kind, where, index in sing.as_list()[: args.list]:
        print(f"  {kind} {where}: {index:+g}")
    if args.png:
        _png(args.png, render_singularities, verts, faces, sing.face_index, sing.vertex_index)
    return 0


def cmd_param(args) -> int:
    from .fields.param import parametrize
    from .render import render_parametrization

    step = _Progress(2, args.quiet)
    mesh = _load(args.mesh)
    step("designing the curvature-aligned cross field")
    z = _design(mesh, 4, args.align)
    step("solving for the seamless (u, v) parametrization")
    result = parametrize(mesh.verts, mesh.faces, z.detach(), round_integers=not args.no_round)
    print(
        f"parametrization: {result.faces.shape[0]} faces, {int(result.singular_vertices.numel())} cones, "
        f"{result.flipped} flipped faces, energy {result.energy:.4g}, scale {result.scale:.4g}"
    )
    if args.png:
        _png(args.png, render_parametrization, result.verts, result.faces, result.uv)
    return 0


def cmd_bench(args) -> int:
    from . import EdgeOperators, icosphere, smoothest_field
    from .mesh.topology import Topology

    step = _Progress(len(args.levels) + 1, args.quiet)
    meshes = [("Spot (default mesh)", _load(None))]
    meshes += [(f"icosphere level {lvl}", icosphere(lvl)) for lvl in args.levels]
    print("| mesh | faces | first assembly (all) | re-assembly (all) | L_c matvec | smoothest 4-field |")
    print("|---|---:|---:|---:|---:|---:|")
    for name, (verts, faces) in meshes:
        step(name)
        t0 = time.perf_counter()
        ops = EdgeOperators(verts, Topology(faces, num_vertices=verts.shape[0]))
        first = time.perf_counter() - t0
        t0 = time.perf_counter()
        ops.update(verts)
        again = time.perf_counter() - t0
        x = torch.randn(ops.num_edges, dtype=torch.complex128)
        t0 = time.perf_counter()
        ops.connection_laplacian @ x
        matvec = time.perf_counter() - t0
        t0 = time.perf_counter()
        smoothest_field(verts, ops.topology, n=4)
        design = time.perf_counter() - t0
        print(
            f"| {name} | {ops.num_faces} | {first:.3f} s | {again:.3f} s | {matvec * 1e3:.1f} ms "
            f"| {design:.3f} s |"
        )
    return 0


def cmd_info(args) -> int:
    from .mesh.diagnose import diagnose

    mesh = _load(args.mesh)
    print(mesh.report if hasattr(mesh, "report") else "")
    report = diagnose(mesh.verts, mesh.faces)
    print(report)
    return 0 if report.ok else 1


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="edgevf",
        description="Edge-based tangent vector fields on triangle meshes. "
        "Without a MESH argument every command runs on the built-in mesh, Spot.",
    )
    p.add_argument("-v", "--verbose", action="store_true", help="log details")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress messages")
    sub = p.add_subparsers(dest="command")
    d = sub.add_parser("demo", help="operators, eigenvalues, the smoothest cross field and a picture")
    d.add_argument("mesh", nargs="?", default=None)
    d.add_argument("-k", type=int, default=6, help="number of eigenvalues")
    d.add_argument(
        "--png", default="edgevf_demo.png", help="picture of the smoothest cross field ('' for none)"
    )
    d.set_defaults(func=cmd_demo)
    g = sub.add_parser("design", help="design an n-direction field and save it")
    g.add_argument("mesh", nargs="?", default=None)
    g.add_argument("--n", type=int, default=4)
    g.add_argument("--align", choices=["curvature", "none"], default="none")
    g.add_argument("-o", "--output", default="field.npz", help=".npz or .txt")
    g.add_argument("--png", default=None)
    g.set_defaults(func=cmd_design)
    s = sub.add_parser("singularities", help="singularities of the smoothest field, or of a saved one")
    s.add_argument("mesh", nargs="?", default=None)
    s.add_argument("--n", type=int, default=4)
    s.add_argument("--field", default=None, help="a field file written by 'edgevf design'")
    s.add_argument("--list", type=int, default=20, help="how many singularities to list")
    s.add_argument("--png", default=None)
    s.set_defaults(func=cmd_singularities)
    q = sub.add_parser("param", help="seamless (u, v) parametrization from a curvature-aligned cross field")
    q.add_argument("mesh", nargs="?", default=None)
    q.add_argument("--align", choices=["curvature", "none"], default="curvature")
    q.add_argument("--no-round", action="store_true", help="skip the integer rounding")
    q.add_argument("--png", default=None)
    q.set_defaults(func=cmd_param)
    i = sub.add_parser("info", help="topology of a mesh and any problems found, with their locations")
    i.add_argument("mesh", nargs="?", default=None)
    i.set_defaults(func=cmd_info)
    b = sub.add_parser("bench", help="quick timings on Spot and icospheres")
    b.add_argument("--levels", type=int, nargs="*", default=[4, 6])
    b.set_defaults(func=cmd_bench)
    return p


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(message)s")
    if args.command is None:
        args = parser.parse_args([*(["-q"] if args.quiet else []), "demo"])
    tune_allocator()  # our own process: keep freed memory for reuse (see torch_edgevf.allocator)
    try:
        return args.func(args)
    except (ValueError, FileNotFoundError) as exc:
        print(f"edgevf: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
