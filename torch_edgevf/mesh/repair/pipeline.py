""":func:`repair`: the steps in order, from a triangle soup to a manifold, oriented mesh."""

from __future__ import annotations

import logging

import numpy as np
import torch

from ..._validation import check_positions_dtype, single_mesh
from ..diagnose import COINCIDENT_TOL, _check_tol, _coincident_pairs, _t_junctions
from ..topology import Topology
from .caps import flip_caps
from .cracks import _merge_clusters, _split_at_t_junctions
from .mollify import MOLLIFY_FACTOR, mollify_lengths
from .orient import _orient, _split_vertices
from .polygons import _triangulate
from .report import _component_counts
from .result import RepairResult

log = logging.getLogger(__name__)


def repair(
    verts,
    faces=None,
    mollify_factor: float = MOLLIFY_FACTOR,
    *,
    merge_coincident: bool = False,
    split_t_junctions: bool = False,
    tol: float = COINCIDENT_TOL,
) -> RepairResult:
    """Turn a triangle (or polygon) soup into a mesh the operators accept, reporting every change.

    In order, on copies (the input is never modified and no vertex is moved):

    1. repeated vertex indices are removed from each face (what has fewer than three
       vertices left is dropped), and polygons are triangulated in their best-fit planes
       (:func:`triangulate`): convex ones as fans from their first corner, others by ear
       clipping, so that every triangle keeps the polygon's orientation; a polygon with
       zero area or crossing sides is split into a fan and named in ``fan_faces``;
    2. faces using a vertex with NaN or Inf coordinates are dropped;
    3. coincident vertices (distinct referenced vertices within ``tol`` times the
       bounding-box diagonal, :func:`~torch_edgevf.mesh.diagnose.find_coincident_vertices`)
       are reported; with ``merge_coincident`` each cluster of them is merged into its
       lowest index, which closes a zero-width crack (triangles left with a repeated
       vertex are dropped);
    4. duplicate faces (the same three vertices, in any order) are dropped, the first kept;
    5. T-junctions (a boundary vertex inside a boundary edge of another face,
       :func:`~torch_edgevf.mesh.diagnose.find_t_junctions`) are reported; with
       ``split_t_junctions`` the triangle of that edge is split at each such vertex, a fan
       from its opposite corner with the winding kept, so that both sides of the crack
       share the pieces of the edge;
    6. edges shared by more than two faces (non-manifold) are cut: each of those faces
       keeps its own copy of the edge, a boundary edge;
    7. each sheet (faces connected through manifold edges) is oriented consistently by
       flipping the minority of its faces; a sheet that cannot be oriented (a Moebius
       strip) raises ``ValueError``;
    8. vertices whose faces then form several fans (bowties, ends of cut edges) are split,
       one copy per fan; unreferenced vertices are dropped;
    9. zero-area caps (a corner on the opposite edge) are re-triangulated with the face
       across that edge by an edge flip (:func:`flip_caps`): no vertex is moved and the
       surface is unchanged, so a file written from the result has no zero-area face there;
    10. the zero-area and needle faces left are handled by intrinsic mollification
       (:func:`mollify_lengths`): the edge lengths, not the positions, are changed.

    Parameters
    ----------
    verts : (V, 3) float tensor or array, or a batch of one mesh with ``verts_list()`` and
        ``faces_list()`` (a ``pytorch3d.structures.Meshes``; ``faces`` left out)
    faces : (F, 3) or (F, k) integer tensor or array, or a sequence of index sequences
        (polygons of any sizes)
    mollify_factor : float >= 0, the margin of the triangle inequality relative to the
        mean edge length
    merge_coincident : bool, merge coincident vertices (default: report them only, since
        merging changes the topology); ``vertex_origin`` then names the vertex each
        cluster was merged into and ``merged_to`` maps every input vertex to it
    split_t_junctions : bool, split faces at T-junction vertices (default: report only)
    tol : float in [0, 1), the tolerance of both crack checks relative to the
        bounding-box diagonal of the referenced vertices (0: bitwise-equal positions)

    Returns
    -------
    :class:`RepairResult`: the repair runs on the host (NumPy); its positions and edge
    lengths are returned on the device of a ``verts`` tensor, its index maps and topology
    on the host.

    Raises
    ------
    ValueError
        Wrong shapes or dtypes, indices out of range, nothing left, a non-orientable
        sheet (naming its faces), or a bad option.
    """
    for name, flag in (("merge_coincident", merge_coincident), ("split_t_junctions", split_t_junctions)):
        if not isinstance(flag, (bool, np.bool_)):
            raise ValueError(f"{name} must be True or False, got {flag!r}")
    tol = _check_tol(tol)
    verts, faces = single_mesh(verts, faces, "repair")
    if faces is None:
        raise ValueError("repair needs faces (or a batch of one mesh with faces_list())")
    device = verts.device if isinstance(verts, torch.Tensor) else torch.device("cpu")
    v, out_dtype = _positions(verts)
    nv = v.shape[0]
    tri, origin, report, polys, sides = _triangulate(faces, nv, v=v)
    report.input_vertices = nv
    report.input_faces = len(polys)
    dropped_tri: dict[str, np.ndarray] = {}

    def drop(mask: np.ndarray, why: str):
        nonlocal tri, origin
        if mask.any():
            dropped_tri[why] = np.concatenate([dropped_tri.get(why, np.zeros(0, np.int64)), origin[mask]])
            tri, origin = tri[~mask], origin[~mask]

    finite = np.isfinite(v).all(1)
    if not finite.all():
        report.nonfinite_vertices = np.flatnonzero(~finite).tolist()
        drop((~finite[tri]).any(1), "a vertex with NaN or Inf coordinates")
    pairs = _coincident_pairs(v, tri, tol)
    report.coincident_vertices = [(int(a), int(b)) for a, b in pairs]
    merged_to = np.arange(nv)
    if merge_coincident and len(pairs):
        merged_to = _merge_clusters(pairs, nv)
        moved = np.flatnonzero(merged_to != np.arange(nv))
        report.merged_vertices = {int(i): int(merged_to[i]) for i in moved}
        tri = merged_to[tri]
        collapsed = (tri[:, 0] == tri[:, 1]) | (tri[:, 1] == tri[:, 2]) | (tri[:, 2] == tri[:, 0])
        report.collapsed_faces = np.unique(origin[collapsed]).tolist()
        drop(collapsed, "collapsed by merging coincident vertices")
    # duplicates, the first occurrence kept
    if len(tri):
        _, first, inverse = np.unique(np.sort(tri, axis=1), axis=0, return_index=True, return_inverse=True)
        inverse = inverse.reshape(-1)
        dup = first[inverse] != np.arange(len(tri))
        if dup.any():
            report.duplicate_faces = [
                (int(a), int(b)) for a, b in zip(origin[dup], origin[first[inverse[dup]]]) if a != b
            ]
            drop(dup, "duplicate of another face")
    present = np.zeros(report.input_faces, dtype=bool)
    present[origin] = True
    for why, fs in dropped_tri.items():
        for f in np.unique(fs).tolist():
            if not present[f] and f not in report.dropped_faces:
                report.dropped_faces[f] = why
    for f in np.flatnonzero(~present).tolist():
        report.dropped_faces.setdefault(
            f, "repeated vertex indices" if len(polys[f]) >= 3 else "fewer than 3 vertices"
        )
    if len(tri) == 0:
        raise ValueError("repair: no faces left (all were dropped: " + report.summary() + ")")

    junctions = _t_junctions(v, tri, tol)
    w, t, k, _ = junctions
    a, b = tri[t, (k + 1) % 3], tri[t, (k + 2) % 3]
    report.t_junctions = [
        (int(x), int(p), int(q), int(f))
        for x, p, q, f in zip(w, np.minimum(a, b), np.maximum(a, b), origin[t])
    ]
    if split_t_junctions and len(w):
        tri, origin = _split_at_t_junctions(v, tri, origin, tol, junctions, report)

    tri, flipped = _orient(tri, origin, nv, report)
    new_faces, vertex_origin = _split_vertices(tri, nv, report)
    new_faces, caps = flip_caps(v[vertex_origin], new_faces)
    report.flipped_caps = np.unique(origin[caps]).tolist() if caps else []
    used = np.zeros(nv, dtype=bool)
    used[tri.ravel()] = True
    used[list(report.merged_vertices)] = True  # merged, not unreferenced
    report.unreferenced_vertices = np.flatnonzero(~used).tolist()
    try:
        topo = Topology(torch.from_numpy(new_faces), num_vertices=len(vertex_origin))
    except ValueError as err:  # not expected: every check above makes a valid topology
        raise ValueError(f"repair could not make a manifold mesh: {err}") from err

    new_verts = torch.from_numpy(v[vertex_origin]).to(out_dtype)
    e = topo.edges
    lengths = torch.linalg.vector_norm(new_verts[e[:, 1]] - new_verts[e[:, 0]], dim=-1)
    lengths, eps, moll = mollify_lengths(lengths, topo.face_edges, mollify_factor)
    report.epsilon = float(eps)
    report.delta = (
        float(mollify_factor * lengths.mean())
        if report.epsilon == 0
        else float(mollify_factor * (lengths - eps).mean())
    )
    report.mollified_faces = moll.tolist()
    report.num_vertices, report.num_faces, report.num_edges = (
        topo.num_vertices,
        topo.num_faces,
        topo.num_edges,
    )
    report.components = _component_counts(topo, flipped, moll.numpy())

    result = RepairResult(
        verts=new_verts.to(device),
        faces=topo.faces,
        vertex_origin=torch.from_numpy(vertex_origin),
        face_origin=torch.from_numpy(origin.copy()),
        flipped=torch.from_numpy(flipped),
        topology=topo,
        edge_lengths=lengths.to(device),
        epsilon=report.epsilon,
        report=report,
        input_edges=torch.from_numpy(sides),
        num_input_faces=report.input_faces,
        num_input_vertices=nv,
        merged_to=torch.from_numpy(merged_to),
    )
    if report.changed or report.cracks:
        log.info("%s", report)
    return result


def _positions(verts) -> tuple[np.ndarray, torch.dtype]:
    if isinstance(verts, torch.Tensor):
        if not verts.is_floating_point():
            raise ValueError(f"verts must have a floating dtype, got {verts.dtype}")
        check_positions_dtype(verts)
        dtype = verts.dtype
        v = verts.detach().cpu().numpy().astype(np.float64)
    else:
        arr = np.asarray(verts)
        if not np.issubdtype(arr.dtype, np.floating):
            raise ValueError(f"verts must have a floating dtype, got {arr.dtype}")
        check_positions_dtype(arr)
        dtype = torch.float32 if arr.dtype == np.float32 else torch.float64
        v = arr.astype(np.float64)  # a copy
    if v.ndim != 2 or v.shape[1] != 3 or v.shape[0] == 0:
        raise ValueError(f"verts must have shape (V, 3) with V >= 1, got {tuple(v.shape)}")
    return v, dtype
