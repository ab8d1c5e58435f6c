"""``edgevf singularities``: the singularities of the smoothest field, or of a saved one."""

from __future__ import annotations

from . import common


def cmd_singularities(args) -> int:
    if args.field and args.mesh:
        raise ValueError("give either a MESH or --field, not both")
    common.check_input(args.mesh, common.MESH_SUFFIXES, "mesh")
    common.check_input(args.field, common.FIELD_SUFFIXES, "field file")
    common.check_output(args.png, (".png",), "--png")
    from ..fields.singularities import singularities
    from ..io import load_field

    step = common.Progress(1 + (not args.field) + bool(args.png), args.quiet)
    if args.field:
        data = load_field(args.field)
        verts, faces, z, n = data.verts, data.faces, data.z, data.n
        if z.dim() != 1:
            raise ValueError(f"{args.field}: expected one field (E,), got {tuple(z.shape)}")
    else:
        mesh, faces = common.load_manifold(args.mesh)
        step(f"designing the smoothest {args.n}-direction field on {common.mesh_name(args.mesh)}")
        verts, n = mesh.verts, args.n
        z = common.design(mesh, faces, n, "none")
    z = z.detach()
    step("computing indices")
    sing = singularities(verts, faces, z, n=n)
    print(common.singularity_line(sing))
    for kind, where, index in sing.as_list()[: args.list]:
        print(f"  {kind} {where}: {index:+g}")
    if args.png:
        step(f"rendering {args.png}")
        what = f"the {n}-direction field of {args.field}" if args.field else f"smoothest {n}-direction field"
        common.singularities_png(args, verts, faces, z, n, sing, what)
    return 0
