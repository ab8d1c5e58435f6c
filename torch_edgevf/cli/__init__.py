"""The ``edgevf`` command line. ``python -m torch_edgevf`` runs the demo on the built-in mesh.

torch is imported inside the subcommand handlers only, so that ``edgevf --help`` and
argument errors answer at once. Every argument is checked before any work starts; an
error is one line on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import logging
import sys

from . import bench, common, demo, design, info, param, prepare_psb, quad, repair, singularities


def build_parser() -> argparse.ArgumentParser:
    # -v/-q are accepted before and after the subcommand: the copy on each subcommand
    # leaves the value alone unless given there (SUPPRESS)
    def global_flags(parser, default):
        parser.add_argument("-v", "--verbose", action="store_true", default=default, help="log details")
        parser.add_argument(
            "-q", "--quiet", action="store_true", default=default, help="no progress messages"
        )

    p = common.Parser(
        prog="edgevf",
        description="Edge-based tangent vector fields on triangle meshes. Without a MESH argument "
        "every command runs on the built-in mesh spot_low_resolution (Spot the cow, 1,654 faces).",
    )
    global_flags(p, False)
    flags = common.Parser(add_help=False)
    global_flags(flags, argparse.SUPPRESS)
    picture_options = common.Parser(add_help=False)
    picture_options.add_argument(
        "--up",
        type=common.direction,
        default="auto",
        help="the picture's vertical: auto, x, y, z, -x, ... or a,b,c",
    )
    picture_options.add_argument(
        "--view",
        type=common.direction,
        default="auto",
        help="direction from the mesh to the camera: auto (the side with the most visible area), "
        "an axis or a,b,c",
    )
    picture_options.add_argument(
        "--size", type=common.image_size, default=(800, 600), help="WIDTHxHEIGHT in pixels (800x600)"
    )
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    symmetry_order = dict(
        type=common.bounded_int(1, common.MAX_N), default=4, help=f"symmetry order (1-{common.MAX_N})"
    )

    def command(module, picture: bool = False, mesh: bool = False):
        """The subparser of a command module: its name, its help (the module docstring's
        line), its handler ``cmd_<name>``, the common flags, the picture options and an
        optional MESH (the built-in mesh without it) where asked."""
        name = module.__name__.rsplit(".", 1)[1]
        doc = module.__doc__.split("\n", 1)[0].split(": ", 1)[1].rstrip(".")
        options = [flags, picture_options] if picture else [flags]
        parser = sub.add_parser(name.replace("_", "-"), parents=options, help=doc)
        if mesh:
            parser.add_argument("mesh", nargs="?", default=None, help=common.MESH_HELP)
        parser.set_defaults(func=getattr(module, f"cmd_{name}"))
        return parser

    p_demo = command(demo, picture=True, mesh=True)
    p_demo.add_argument(
        "-k",
        type=common.bounded_int(1, common.MAX_K),
        default=6,
        help=f"number of eigenvalues (1-{common.MAX_K})",
    )
    p_demo.add_argument(
        "--png",
        default="edgevf_demo.png",
        help="picture of the smoothest cross field with its singularities ('' for none)",
    )
    p_design = command(design, picture=True, mesh=True)
    p_design.add_argument("--n", **symmetry_order)
    p_design.add_argument("--align", choices=["curvature", "none"], default="none")
    p_design.add_argument("-o", "--output", default="field.npz", help="field file, .npz or .txt")
    p_design.add_argument("--png", default=None, help="picture of the field and its singularities")
    p_singularities = command(singularities, picture=True, mesh=True)
    p_singularities.add_argument("--n", **symmetry_order)
    p_singularities.add_argument("--field", default=None, help="a field file written by 'edgevf design'")
    p_singularities.add_argument(
        "--list", type=common.bounded_int(0), default=20, help="how many singularities to list"
    )
    p_singularities.add_argument("--png", default=None, help="picture of the field and its singularities")
    p_param = command(param, picture=True, mesh=True)
    p_param.add_argument("--align", choices=["curvature", "none"], default="curvature")
    p_param.add_argument("--no-round", action="store_true", help="skip the integer rounding")
    p_param.add_argument("--png", default=None, help="checkerboard picture of the parametrization")
    p_quad = command(quad, picture=True, mesh=True)
    p_quad.add_argument("-o", "--output", default="quads.obj", help="the quad mesh (OBJ, PLY or OFF)")
    size = p_quad.add_mutually_exclusive_group()
    size.add_argument("--quads", type=common.bounded_int(1), default=None, help="target number of quads")
    size.add_argument(
        "--edge-length",
        type=common.positive,
        default=None,
        help="target edge length (default: the mean edge length)",
    )
    p_quad.add_argument(
        "--field",
        choices=["curvature", "smoothest"],
        default="curvature",
        help="curvature: the curvature directions where the curvature is anisotropic, the smoothest "
        "field where it is near-umbilic (a sphere: the smoothest field); smoothest: the smoothest field",
    )
    p_quad.add_argument(
        "--sharp-angle",
        type=common.angle,
        default=60.0,
        help="edges with a dihedral angle above this (degrees) constrain the field; 0: none",
    )
    p_quad.add_argument("--boundary", choices=["hard", "soft"], default=None, help="required on open meshes")
    p_quad.add_argument("--png", default=None, help="picture of the quad mesh")
    p_info = command(info, mesh=True)
    p_info.add_argument(
        "--tol",
        type=common.tolerance,
        default=None,
        help="tolerance of the coincident-vertex and T-junction checks, relative to the bounding-box "
        "diagonal (default 1e-6; 0: identical positions only)",
    )
    p_repair = command(repair)
    p_repair.add_argument("mesh", metavar="MESH", help="OBJ, PLY, OFF or STL file")
    p_repair.add_argument("output", metavar="OUT", help="the repaired mesh (OBJ, PLY, OFF or STL)")
    p_repair.add_argument(
        "--maps",
        default=None,
        help=".npz file for the maps to the input (vertex_origin, merged_to, face_origin, flipped) "
        "and the (mollified) edge lengths",
    )
    p_repair.add_argument(
        "--merge-coincident",
        action="store_true",
        help="merge coincident vertices, closing zero-width cracks (default: report them only)",
    )
    p_repair.add_argument(
        "--split-t-junctions",
        action="store_true",
        help="split faces at T-junction vertices, closing the crack (default: report them only)",
    )
    p_repair.add_argument(
        "--tol",
        type=common.tolerance,
        default=None,
        help="tolerance of both checks, relative to the bounding-box diagonal (default 1e-6)",
    )
    p_bench = command(bench)
    p_bench.add_argument(
        "--levels",
        type=common.bounded_int(0, common.MAX_BENCH_LEVEL),
        nargs="*",
        default=[4, 6],
        help=f"icosphere levels (0-{common.MAX_BENCH_LEVEL}; level L has 20 * 4^L faces)",
    )
    p_prepare_psb = command(prepare_psb)
    p_prepare_psb.add_argument(
        "src_dir", metavar="SRC_DIR", help="the benchmark's data folder (with off/1.off ...)"
    )
    p_prepare_psb.add_argument("output", metavar="OUT.npz", help="the file to write")
    p_prepare_psb.add_argument("--faces", type=int, default=2000, help="triangles per mesh (default 2000)")
    return p


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(message)s")
    if args.command is None:
        args = parser.parse_args([*(["-q"] if args.quiet else []), *(["-v"] if args.verbose else []), "demo"])
    from ..allocator import tune_allocator

    tune_allocator()  # our own process: keep freed memory for reuse (see torch_edgevf.allocator)
    try:
        return args.func(args)
    except (ValueError, OSError) as exc:
        message = "; ".join(line.strip() for line in str(exc).splitlines() if line.strip())
        print(f"edgevf: error: {message}", file=sys.stderr)
        return 2
