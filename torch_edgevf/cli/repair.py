"""``edgevf repair``: a mesh made manifold and consistently oriented, every change reported."""

from __future__ import annotations

from . import common


def cmd_repair(args) -> int:
    """Repair a mesh file and write the result (and, with --maps, the maps back to the input)."""
    import numpy as np

    from .._validation import face_range_message, faces_out_of_range
    from ..io import save_mesh
    from ..mesh.repair import repair

    verts, faces, report = common.read_soup(args.mesh)
    outside = faces_out_of_range(faces, len(verts))
    if outside:
        raise ValueError(f"{len(outside)} {face_range_message(outside, len(verts))}")
    result = repair(
        verts,
        faces,
        merge_coincident=args.merge_coincident,
        split_t_junctions=args.split_t_junctions,
        tol=common.crack_tol(args),
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
