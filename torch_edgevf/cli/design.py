"""``edgevf design``: an n-direction field designed and saved."""

from __future__ import annotations

from . import common


def cmd_design(args) -> int:
    step, mesh, topo = common.start(args, 2, [(args.output, common.FIELD_SUFFIXES, "-o")])
    from ..fields.singularities import singularities
    from ..io import save_field

    kind = "curvature-aligned" if args.align == "curvature" else "smoothest"
    step(f"designing the {kind} {args.n}-direction field on {common.mesh_name(args.mesh)}")
    z = common.design(mesh, topo, args.n, args.align).detach()
    step(f"writing {args.output}")
    save_field(args.output, mesh.verts, mesh.faces, z, n=args.n)
    print(f"wrote {args.output}: {z.shape[0]} edges, n = {args.n}")
    if args.png:
        step(f"rendering {args.png}")
        sing = singularities(mesh.verts, topo, z, n=args.n)
        common.singularities_png(args, mesh.verts, topo, z, args.n, sing, f"{kind} {args.n}-direction field")
    return 0
