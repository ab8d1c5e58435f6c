"""``edgevf info``: the topology of a mesh and every problem found, with their locations."""

from __future__ import annotations

from . import common


def _operator_problems(verts, topo) -> list[str]:
    """NaN or Inf in the connection Laplacian or mass matrix (never raises).

    The geometry already refuses scales whose areas the dtype cannot hold; this also
    assembles ``L_c`` and ``M_z``, so that a mesh is never reported sound while its
    operators are not finite.
    """
    import torch

    from ..operators.functional import connection_laplacian, mass_matrix

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

    from .._validation import face_range_message, faces_out_of_range
    from ..mesh.repair import repair

    tol = common.crack_tol(args)
    verts, faces, report = common.read_soup(args.mesh)
    print(report)
    problems = []
    if report.nonfinite_vertices:
        bad = report.nonfinite_vertices
        problems.append(
            f"{len(bad)} vertices with NaN or Inf coordinates at file vertices [{common.some(bad)}]"
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
                f"pairs [{common.some(rep.coincident_vertices)}]; "
                "'edgevf repair --merge-coincident' merges them"
            )
        if rep.t_junctions:
            fix_flags.append("--split-t-junctions")
            rows = [f"{w} in ({a}, {b}) of face {f}" for w, a, b, f in rep.t_junctions]
            problems.append(
                f"{len(rows)} T-junctions (a boundary vertex inside a boundary edge of another face: "
                f"a zero-width crack) at [{common.some(rows)}]; 'edgevf repair --split-t-junctions' splits "
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
