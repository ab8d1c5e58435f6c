"""``edgevf param``: a seamless (u, v) parametrization from a curvature-aligned cross field."""

from __future__ import annotations

from . import common


def cmd_param(args) -> int:
    step, mesh, topo = common.start(args, 2)
    from ..fields.param import parametrize
    from ..render import render_parametrization

    step(f"designing the {'curvature-aligned' if args.align == 'curvature' else 'smoothest'} cross field")
    z = common.design(mesh, topo, 4, args.align)
    step("solving for the seamless (u, v) parametrization")
    result = parametrize(mesh.verts, topo, z.detach(), round_integers=not args.no_round)
    print(
        f"parametrization of {common.mesh_name(args.mesh)}: {result.faces.shape[0]} faces, "
        f"{int(result.singular_vertices.numel())} cones, "
        f"{result.flipped} flipped faces, energy {result.energy:.4g}, scale {result.scale:.4g}"
    )
    if args.png:
        step(f"rendering {args.png}")
        title = f"seamless parametrization: checkerboard of (u, v); {result.flipped} flipped faces (red)"
        common.png(
            args.png,
            render_parametrization,
            result.verts,
            result.faces,
            uv=result.uv,
            title=title,
            **common.png_options(args),
        )
    return 0
