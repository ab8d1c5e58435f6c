"""``edgevf quad``: a pure quad mesh from a cross field (integer-grid map and quad extraction)."""

from __future__ import annotations

from . import common

QUAD_SUFFIXES = (".obj", ".off", ".ply")


def cmd_quad(args) -> int:
    step, mesh, topo = common.start(args, 2, [(args.output, QUAD_SUFFIXES, "-o")])
    from ..quad.mesh import quad_mesh, quad_mesh_report, save_quad_mesh

    step(f"designing the {args.field} cross field and its integer-grid map")
    result = quad_mesh(
        mesh.verts,
        topo.faces,
        quads=args.quads,
        edge_length=args.edge_length,
        field=args.field,
        sharp_angle=None if args.sharp_angle == 0 else args.sharp_angle,
        boundary=args.boundary,
    )
    report = quad_mesh_report(result.verts, result.quads)
    step(f"writing {args.output}")
    save_quad_mesh(args.output, result.verts, result.quads)
    print(
        f"quad mesh of {common.mesh_name(args.mesh)}: {report.num_quads} quads, "
        f"{report.num_vertices} vertices, "
        f"{report.irregular.size} irregular (the field's {result.cone_index.numel()} cones), Euler "
        f"characteristic {report.euler_characteristic}, mean |corner angle - 90| "
        f"{report.angle_deviation:.2f} deg; wrote {args.output}"
    )
    if args.png:
        from ..render.quads import render_quad_mesh

        step(f"rendering {args.png}")
        common.png(args.png, render_quad_mesh, result.verts, result.quads, **common.png_options(args))
    return 0
