"""The ``edgevf`` command line. ``python -m torch_edgevf`` runs the demo on the built-in mesh.

torch is imported inside the subcommand handlers only, so that ``edgevf --help`` and
argument errors answer at once. Every argument is checked before any work starts; an
error is one line on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import re
import sys
import time

log = logging.getLogger("torch_edgevf")

BUILT_IN = "spot_low_resolution (built in)"
"""How the built-in mesh (Spot, 1,654 faces) is named in the output."""

MESH_SUFFIXES = (".obj", ".ply", ".off", ".stl")
FIELD_SUFFIXES = (".npz", ".txt")
MAX_BENCH_LEVEL = 7
"""Largest icosphere level of ``edgevf bench`` (327,680 faces; level 8 needs several GB)."""
MAX_N = 16
MAX_K = 64
_AXES = ("x", "y", "z", "+x", "+y", "+z", "-x", "-y", "-z")


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


class _Parser(argparse.ArgumentParser):
    """Argument errors as one line on stderr (exit 2), naming where to find the usage."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


# --------------------------------------------------------------------------- argument types


def _bounded_int(lo: int, hi: int | None = None):
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


def _direction(text: str):
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


def _image_size(text: str):
    """``800`` (square) or ``800x600``."""
    m = re.fullmatch(r"\s*(\d+)\s*(?:[xX]\s*(\d+)\s*)?", text)
    if not m:
        raise argparse.ArgumentTypeError(f"expected WIDTH or WIDTHxHEIGHT in pixels, got {text!r}")
    w, h = int(m.group(1)), int(m.group(2) or m.group(1))
    if not (16 <= w <= 8192 and 16 <= h <= 8192):
        raise argparse.ArgumentTypeError(f"width and height must lie in [16, 8192], got {text!r}")
    return w if w == h and m.group(2) is None else (w, h)


# --------------------------------------------------------------------------- checks before work


def _check_input(path: str | None, suffixes, what: str) -> None:
    if path is None:
        return
    if os.path.splitext(path)[1].lower() not in suffixes:
        raise ValueError(f"{path}: unsupported extension for a {what}, expected one of {', '.join(suffixes)}")
    if not os.path.isfile(path):
        raise ValueError(f"{path}: no such file")


def _check_output(path: str | None, suffixes, option: str) -> None:
    if not path:
        return
    if os.path.splitext(path)[1].lower() not in suffixes:
        raise ValueError(f"{option} {path}: unsupported extension, expected {' or '.join(suffixes)}")
    folder = os.path.dirname(path) or "."
    if not os.path.isdir(folder):
        raise ValueError(f"{option} {path}: no such directory {folder}")
    if os.path.isdir(path):
        raise ValueError(f"{option} {path}: is a directory")


def _png_options(args) -> dict:
    return {"up": args.up, "view": args.view, "size": args.size}


def _png(path, render, verts, faces, **kwargs):
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


def _load(path):
    from .io import default_mesh, load_mesh

    return default_mesh() if path is None else load_mesh(path)


def _load_manifold(path):
    """The mesh, refused (ValueError) before any work when its topology is unusable."""
    from .mesh.topology import Topology

    mesh = _load(path)
    Topology(mesh.faces, num_vertices=mesh.verts.shape[0])  # raises on non-manifold edges
    return mesh


def _mesh_name(path) -> str:
    return BUILT_IN if path is None else str(path)


def _smallest_eigenvalues(A, M, k):
    """The k smallest generalized eigenvalues of ``A x = lambda M x``."""
    from .linalg import eigsh

    return eigsh(A, M, k).values.detach().numpy()


def cmd_demo(args) -> int:
    _check_input(args.mesh, MESH_SUFFIXES, "mesh")
    _check_output(args.png, (".png",), "--png")
    from . import EdgeOperators, singularities, smoothest_field
    from .render import render_singularities

    step = _Progress(3 + bool(args.png), args.quiet)
    mesh = _load_manifold(args.mesh)
    print(f"mesh: {_mesh_name(args.mesh)}, {mesh.verts.shape[0]} vertices, {mesh.faces.shape[0]} faces")
    if args.k >= mesh.verts.shape[0]:
        raise ValueError(f"-k {args.k}: must be smaller than the number of vertices ({mesh.verts.shape[0]})")
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
        _png(
            args.png,
            render_singularities,
            mesh.verts,
            mesh.faces,
            face_index=sing.face_index,
            vertex_index=sing.vertex_index,
            z=z.detach(),
            n=4,
            title="smoothest cross field; singularities: index > 0 green, < 0 red",
            **_png_options(args),
        )
    return 0


def _singularity_line(sing) -> str:
    import torch

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
    _check_input(args.mesh, MESH_SUFFIXES, "mesh")
    _check_output(args.output, FIELD_SUFFIXES, "-o")
    _check_output(args.png, (".png",), "--png")
    from . import singularities
    from .io import save_field
    from .render import render_singularities

    step = _Progress(2 + bool(args.png), args.quiet)
    mesh = _load_manifold(args.mesh)
    step(
        f"designing the {'curvature-aligned' if args.align == 'curvature' else 'smoothest'} "
        f"{args.n}-direction field on {_mesh_name(args.mesh)}"
    )
    z = _design(mesh, args.n, args.align).detach()
    step(f"writing {args.output}")
    save_field(args.output, mesh.verts, mesh.faces, z, n=args.n)
    print(f"wrote {args.output}: {z.shape[0]} edges, n = {args.n}")
    if args.png:
        step(f"rendering {args.png}")
        sing = singularities(mesh.verts, mesh.faces, z, n=args.n)
        _png(
            args.png,
            render_singularities,
            mesh.verts,
            mesh.faces,
            face_index=sing.face_index,
            vertex_index=sing.vertex_index,
            z=z,
            n=args.n,
            **_png_options(args),
        )
    return 0


def cmd_singularities(args) -> int:
    if args.field and args.mesh:
        raise ValueError("give either a MESH or --field, not both")
    _check_input(args.mesh, MESH_SUFFIXES, "mesh")
    _check_input(args.field, FIELD_SUFFIXES, "field file")
    _check_output(args.png, (".png",), "--png")
    from . import singularities
    from .io import load_field
    from .render import render_singularities

    step = _Progress(1 + (not args.field) + bool(args.png), args.quiet)
    if args.field:
        data = load_field(args.field)
        verts, faces, z, n = data.verts, data.faces, data.z, data.n
        if z.dim() != 1:
            raise ValueError(f"{args.field}: expected one field (E,), got {tuple(z.shape)}")
    else:
        mesh = _load_manifold(args.mesh)
        step(f"designing the smoothest {args.n}-direction field on {_mesh_name(args.mesh)}")
        verts, faces, n = mesh.verts, mesh.faces, args.n
        z = _design(mesh, n, "none")
    z = z.detach()
    step("computing indices")
    sing = singularities(verts, faces, z, n=n)
    print(_singularity_line(sing))
    for kind, where, index in sing.as_list()[: args.list]:
        print(f"  {kind} {where}: {index:+g}")
    if args.png:
        step(f"rendering {args.png}")
        _png(
            args.png,
            render_singularities,
            verts,
            faces,
            face_index=sing.face_index,
            vertex_index=sing.vertex_index,
            z=z,
            n=n,
            **_png_options(args),
        )
    return 0


def cmd_param(args) -> int:
    _check_input(args.mesh, MESH_SUFFIXES, "mesh")
    _check_output(args.png, (".png",), "--png")
    from .fields.param import parametrize
    from .render import render_parametrization

    step = _Progress(2 + bool(args.png), args.quiet)
    mesh = _load_manifold(args.mesh)
    step(f"designing the {'curvature-aligned' if args.align == 'curvature' else 'smoothest'} cross field")
    z = _design(mesh, 4, args.align)
    step("solving for the seamless (u, v) parametrization")
    result = parametrize(mesh.verts, mesh.faces, z.detach(), round_integers=not args.no_round)
    print(
        f"parametrization of {_mesh_name(args.mesh)}: {result.faces.shape[0]} faces, "
        f"{int(result.singular_vertices.numel())} cones, "
        f"{result.flipped} flipped faces, energy {result.energy:.4g}, scale {result.scale:.4g}"
    )
    if args.png:
        step(f"rendering {args.png}")
        _png(args.png, render_parametrization, result.verts, result.faces, uv=result.uv, **_png_options(args))
    return 0


def cmd_bench(args) -> int:
    import torch

    from . import EdgeOperators, icosphere, smoothest_field
    from .mesh.topology import Topology

    step = _Progress(len(args.levels) + 1, args.quiet)
    meshes = [(BUILT_IN, _load(None))]
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


def _read_soup(path):
    """Vertices, triangles and the reader's report of a file, or of the built-in mesh, unchecked."""
    from .io import default_mesh, read_triangles

    if path is None:
        mesh = default_mesh()
        return mesh.verts.numpy(), mesh.faces.numpy(), mesh.report
    return read_triangles(path, merge=True)


def _operator_problems(verts, topo) -> list[str]:
    """NaN or Inf in the connection Laplacian or mass matrix (never raises).

    The geometry already refuses scales whose areas the dtype cannot hold; this also
    assembles ``L_c`` and ``M_z``, so that a mesh is never reported sound while its
    operators are not finite.
    """
    import torch

    from .operators.functional import connection_laplacian, mass_matrix

    try:
        values = {
            "connection Laplacian": connection_laplacian(verts, topo, 1).coalesce().values(),
            "mass matrix": mass_matrix(verts, topo).coalesce().values(),
        }
    except ValueError as exc:
        return [str(exc)]
    return [
        f"the {name} has {int((~torch.isfinite(v)).sum())} NaN or Inf values"
        for name, v in values.items()
        if not bool(torch.isfinite(v).all())
    ]


def cmd_info(args) -> int:
    """Every problem of the file at once (also those the loader rejects, and zero-width cracks)
    and what repair would do, also with the flags that close the cracks."""
    import numpy as np

    from ._validation import face_range_message, faces_out_of_range
    from .mesh.repair import repair

    tol = _crack_tol(args)
    verts, faces, report = _read_soup(args.mesh)
    print(report)
    problems = []
    if report.nonfinite_vertices:
        bad = report.nonfinite_vertices
        problems.append(
            f"{len(bad)} vertices with NaN or Inf coordinates at file vertices [{_some(bad)}]"
            " (the loader rejects the file; repair drops their faces)"
        )
    outside = faces_out_of_range(faces, len(verts))
    if outside:
        problems.append(f"{len(outside)} {face_range_message(outside, len(verts))}")
        faces = np.delete(faces, outside, axis=0)
    problems += report.problems
    if len(faces) == 0:
        problems.append("no faces")
        result = None
    else:
        try:
            result = repair(verts, faces, tol=tol)
        except ValueError as exc:
            problems.append(str(exc))
            result = None
    fix_flags: list[str] = []
    if result is not None:
        rep = result.report
        if rep.duplicate_faces:
            problems.append(f"{len(rep.duplicate_faces)} duplicate faces")
        if rep.non_manifold_edges:
            problems.append(f"{len(rep.non_manifold_edges)} non-manifold edges (more than two faces)")
        if rep.non_manifold_vertices:
            problems.append(f"{len(rep.non_manifold_vertices)} non-manifold vertices (several fans)")
        if rep.flipped_faces:
            problems.append(f"inconsistent orientation: {len(rep.flipped_faces)} faces against their sheet")
        if rep.mollified_faces:
            problems.append(
                f"{len(rep.mollified_faces)} zero-area or needle faces (triangle inequality without margin)"
            )
        if rep.unreferenced_vertices and not report.nonfinite_vertices:
            problems.append(f"{len(rep.unreferenced_vertices)} unreferenced vertices")
        if rep.coincident_vertices:
            fix_flags.append("--merge-coincident")
            problems.append(
                f"{len(rep.coincident_vertices)} pairs of coincident vertices (distinct vertices at one "
                f"position, within {tol:g} of the bounding-box diagonal: a zero-width crack) at vertex "
                f"pairs [{_some(rep.coincident_vertices)}]; 'edgevf repair --merge-coincident' merges them"
            )
        if rep.t_junctions:
            fix_flags.append("--split-t-junctions")
            rows = [f"{w} in ({a}, {b}) of face {f}" for w, a, b, f in rep.t_junctions]
            problems.append(
                f"{len(rows)} T-junctions (a boundary vertex inside a boundary edge of another face: "
                f"a zero-width crack) at [{_some(rows)}]; 'edgevf repair --split-t-junctions' splits "
                "those faces at the vertices"
            )
        topo = result.topology
        problems += _operator_problems(result.verts, topo)
        print(
            f"after repair: {topo.num_vertices} vertices, {topo.num_edges} edges, {topo.num_faces} faces, "
            f"{topo.num_components} components, Euler characteristic {topo.euler_characteristic}, "
            f"{topo.num_boundary_edges} boundary edges"
        )
    print("\n".join(f"problem: {p}" for p in problems) if problems else "no problems found")
    if result is not None and problems:
        print("what 'edgevf repair' would do:")
        print(result.report.summary())
    if fix_flags:
        print(f"what 'edgevf repair {' '.join(fix_flags)}' would do:")
        try:
            fixed = repair(
                verts,
                faces,
                merge_coincident="--merge-coincident" in fix_flags,
                split_t_junctions="--split-t-junctions" in fix_flags,
                tol=tol,
            )
        except ValueError as exc:
            print(f"  it fails: {exc}")
        else:
            print(fixed.report.summary())
    return 1 if problems else 0


def _crack_tol(args) -> float:
    """The ``--tol`` of info and repair (the library's default when not given)."""
    from .mesh.diagnose import COINCIDENT_TOL

    return COINCIDENT_TOL if getattr(args, "tol", None) is None else args.tol


def _tolerance(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not 0 <= value < 1:
        raise argparse.ArgumentTypeError(f"must be a number in [0, 1), got {value}")
    return value


def _some(items, limit: int = 10) -> str:
    head = ", ".join(str(i) for i in items[:limit])
    return head if len(items) <= limit else f"{head}, ... ({len(items)} in all)"


def cmd_repair(args) -> int:
    """Repair a mesh file and write the result (and, with --maps, the maps back to the input)."""
    import numpy as np

    from ._validation import face_range_message, faces_out_of_range
    from .io import save_mesh
    from .mesh.repair import repair

    verts, faces, report = _read_soup(args.mesh)
    outside = faces_out_of_range(faces, len(verts))
    if outside:
        raise ValueError(f"{len(outside)} {face_range_message(outside, len(verts))}")
    result = repair(
        verts,
        faces,
        merge_coincident=args.merge_coincident,
        split_t_junctions=args.split_t_junctions,
        tol=_crack_tol(args),
    )
    print(result.report.summary())
    save_mesh(args.output, result.verts, result.faces)
    print(f"wrote {args.output}")
    if args.maps:
        np.savez(
            args.maps,
            vertex_origin=result.vertex_origin.numpy(),
            merged_to=result.merged_to.numpy() if result.merged_to is not None else np.arange(len(verts)),
            face_origin=result.face_origin.numpy(),
            flipped=result.flipped.numpy(),
            edges=result.topology.edges.numpy(),
            edge_lengths=result.edge_lengths.numpy(),
            epsilon=np.float64(result.epsilon),
        )
        print(f"wrote {args.maps}")
    if result.mollified:
        print(
            f"note: {len(result.report.mollified_faces)} faces still have zero area in the written "
            "positions; the operators need the mollified lengths (repair() in Python, or --maps)"
        )
    return 0


def cmd_prepare_psb(args) -> int:
    from .learning.prepare import prepare_psb

    if not args.output.lower().endswith(".npz"):
        raise ValueError(f"OUT must be a .npz file, got {args.output}")
    if args.faces < 4:
        raise ValueError(f"--faces must be at least 4, got {args.faces}")
    result = prepare_psb(args.src_dir, args.output, faces=args.faces, show_progress=not args.quiet)
    skipped = f", left out: psb ids {result['skipped']}" if result["skipped"] else ""
    print(f"wrote {result['path']}: {result['meshes']} meshes{skipped}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    # -v/-q are accepted before and after the subcommand: the copy on each subcommand
    # leaves the value alone unless given there (SUPPRESS)
    def global_flags(parser, default):
        parser.add_argument("-v", "--verbose", action="store_true", default=default, help="log details")
        parser.add_argument(
            "-q", "--quiet", action="store_true", default=default, help="no progress messages"
        )

    p = _Parser(
        prog="edgevf",
        description="Edge-based tangent vector fields on triangle meshes. Without a MESH argument "
        "every command runs on the built-in mesh spot_low_resolution (Spot the cow, 1,654 faces).",
    )
    global_flags(p, False)
    common = _Parser(add_help=False)
    global_flags(common, argparse.SUPPRESS)
    picture = _Parser(add_help=False)
    picture.add_argument(
        "--up",
        type=_direction,
        default="auto",
        help="the picture's vertical: auto, x, y, z, -x, ... or a,b,c",
    )
    picture.add_argument(
        "--view",
        type=_direction,
        default="auto",
        help="direction from the mesh to the camera: auto (the side with the most visible area), "
        "an axis or a,b,c",
    )
    picture.add_argument(
        "--size", type=_image_size, default=(800, 600), help="WIDTHxHEIGHT in pixels (800x600)"
    )
    mesh_help = "OBJ, PLY, OFF or STL file (default: the built-in mesh)"
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    d = sub.add_parser(
        "demo",
        parents=[common, picture],
        help="operators, eigenvalues, the smoothest cross field and a picture of it",
    )
    d.add_argument("mesh", nargs="?", default=None, help=mesh_help)
    d.add_argument("-k", type=_bounded_int(1, MAX_K), default=6, help=f"number of eigenvalues (1-{MAX_K})")
    d.add_argument(
        "--png",
        default="edgevf_demo.png",
        help="picture of the smoothest cross field with its singularities ('' for none)",
    )
    d.set_defaults(func=cmd_demo)
    g = sub.add_parser("design", parents=[common, picture], help="design an n-direction field and save it")
    g.add_argument("mesh", nargs="?", default=None, help=mesh_help)
    g.add_argument("--n", type=_bounded_int(1, MAX_N), default=4, help=f"symmetry order (1-{MAX_N})")
    g.add_argument("--align", choices=["curvature", "none"], default="none")
    g.add_argument("-o", "--output", default="field.npz", help="field file, .npz or .txt")
    g.add_argument("--png", default=None, help="picture of the field and its singularities")
    g.set_defaults(func=cmd_design)
    s = sub.add_parser(
        "singularities",
        parents=[common, picture],
        help="singularities of the smoothest field, or of a saved one",
    )
    s.add_argument("mesh", nargs="?", default=None, help=mesh_help)
    s.add_argument("--n", type=_bounded_int(1, MAX_N), default=4, help=f"symmetry order (1-{MAX_N})")
    s.add_argument("--field", default=None, help="a field file written by 'edgevf design'")
    s.add_argument("--list", type=_bounded_int(0), default=20, help="how many singularities to list")
    s.add_argument("--png", default=None, help="picture of the field and its singularities")
    s.set_defaults(func=cmd_singularities)
    q = sub.add_parser(
        "param",
        parents=[common, picture],
        help="seamless (u, v) parametrization from a curvature-aligned cross field",
    )
    q.add_argument("mesh", nargs="?", default=None, help=mesh_help)
    q.add_argument("--align", choices=["curvature", "none"], default="curvature")
    q.add_argument("--no-round", action="store_true", help="skip the integer rounding")
    q.add_argument("--png", default=None, help="checkerboard picture of the parametrization")
    q.set_defaults(func=cmd_param)
    i = sub.add_parser(
        "info", parents=[common], help="topology of a mesh and any problems found, with their locations"
    )
    i.add_argument("mesh", nargs="?", default=None)
    i.add_argument(
        "--tol",
        type=_tolerance,
        default=None,
        help="tolerance of the coincident-vertex and T-junction checks, relative to the bounding-box "
        "diagonal (default 1e-6; 0: identical positions only)",
    )
    i.set_defaults(func=cmd_info)
    rp = sub.add_parser(
        "repair",
        parents=[common],
        help="make a mesh manifold and consistently oriented, report every change, and save it",
    )
    rp.add_argument("mesh", metavar="MESH", help="OBJ, PLY, OFF or STL file")
    rp.add_argument("output", metavar="OUT", help="the repaired mesh (OBJ, PLY, OFF or STL)")
    rp.add_argument(
        "--maps",
        default=None,
        help=".npz file for the maps to the input (vertex_origin, merged_to, face_origin, flipped) "
        "and the (mollified) edge lengths",
    )
    rp.add_argument(
        "--merge-coincident",
        action="store_true",
        help="merge coincident vertices, closing zero-width cracks (default: report them only)",
    )
    rp.add_argument(
        "--split-t-junctions",
        action="store_true",
        help="split faces at T-junction vertices, closing the crack (default: report them only)",
    )
    rp.add_argument(
        "--tol",
        type=_tolerance,
        default=None,
        help="tolerance of both checks, relative to the bounding-box diagonal (default 1e-6)",
    )
    rp.set_defaults(func=cmd_repair)
    b = sub.add_parser("bench", parents=[common], help=f"quick timings on {BUILT_IN} and icospheres")
    b.add_argument(
        "--levels",
        type=_bounded_int(0, MAX_BENCH_LEVEL),
        nargs="*",
        default=[4, 6],
        help=f"icosphere levels (0-{MAX_BENCH_LEVEL}; level L has 20 * 4^L faces)",
    )
    b.set_defaults(func=cmd_bench)
    r = sub.add_parser(
        "prepare-psb",
        parents=[common],
        help="build psb_watertight_2k.npz from the Princeton Segmentation Benchmark's OFF files",
    )
    r.add_argument("src_dir", metavar="SRC_DIR", help="the benchmark's data folder (with off/1.off ...)")
    r.add_argument("output", metavar="OUT.npz", help="the file to write")
    r.add_argument("--faces", type=int, default=2000, help="triangles per mesh (default 2000)")
    r.set_defaults(func=cmd_prepare_psb)
    return p


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(message)s")
    if args.command is None:
        args = parser.parse_args([*(["-q"] if args.quiet else []), *(["-v"] if args.verbose else []), "demo"])
    from .allocator import tune_allocator

    tune_allocator()  # our own process: keep freed memory for reuse (see torch_edgevf.allocator)
    try:
        return args.func(args)
    except (ValueError, OSError) as exc:
        message = "; ".join(line.strip() for line in str(exc).splitlines() if line.strip())
        print(f"edgevf: error: {message}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
