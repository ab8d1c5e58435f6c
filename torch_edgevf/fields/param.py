"""Seamless (u, v) parametrization from a cross field (thesis chapter 4, after [BZK09]).

Steps, as in the thesis:

1. *(given)* a smooth cross field ``z`` (``n = 4`` representation vector), e.g. from
   :func:`torch_edgevf.fields.design.curvature_aligned_field`;
2. *singularities* (:func:`torch_edgevf.fields.singularities.singularities`); face singularities
   are moved to new vertices by a 1-to-3 split at their exact location (thesis 4.1, B.2);
3. *cut and comb*: a breadth-first spanning tree of the dual graph; the primal edges it
   does not cross form a cut graph, pruned of dangling branches that end at regular
   vertices, so that what remains joins the singular vertices and the homology
   generators (and the boundary) and the cut mesh is a topological disk. The cross field
   is combed into one direction per face, ``U_f`` (``V_f = J U_f``), by choosing along the
   tree the root closest to the neighbour's, transported across the shared edge. Across
   every cut edge the *matching* ``k_e`` records the rotation by ``k pi/2`` between the
   combed directions of its two faces;
4. *solve* for per-corner ``u`` and ``v`` minimizing
   ``int |grad u - s U|^2 + |grad v - s V|^2`` (``s`` the target gradient norm, one quad
   per ``1/s`` length) with *seamless* transitions across the cut: with ``w = u + i v``,
   ``w_g = i^{-k_e} w_f + t_e`` for the two copies of each vertex of a cut edge (a
   rotation by ``k pi/2`` plus a translation ``t_e``, constant along a seam). The
   constraints are enforced by a quadratic penalty of large weight (they may be
   linearly dependent at cut-graph branchings), so they hold to about ``1e-8`` relative;
5. *(optional, rounding)* the seam translations ``t_e`` are rounded to integers greedily
   (the seam closest to an integer first, then re-solve; transitions stay consistent
   around cut-graph branchings), giving integer-seamless ``(u, v)``. Snapping the cones
   to integer positions as well (``round_cones=True``) is experimental: done this way it
   conflicts with the seam constraints when cones are close (see :func:`parametrize`);
   a full mixed-integer solver [BZK09] rounds both jointly.

The least-squares energy uses the standard P1 gradient per face (equivalent to the
thesis' ``E_z(u) = u^T L u + ...`` with its edge-based ``L = G^* M_z^{-1} G`` only up to
the choice of discretization); the combing and transport use the edge-based
representation and the transport coefficients of the library. This module is not
differentiable (it is combinatorial).

**Not included:** extracting the quad mesh from ``(u, v)`` (the integer iso-lines; see
[EBCK13] "QEx" for a robust method) is beyond the scope of this library.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph as csg
import scipy.sparse.linalg as sla
import torch

from .._dtypes import complex_dtype as complex_dtype_of
from .._validation import as_edge_field
from ..mesh.geometry import mean_edge_length, topology_and_verts
from ..mesh.topology import Topology
from .singularities import face_frame_angles, singularities, split_singular_faces

__all__ = ["CutGraph", "cut_graph", "comb", "Combing", "parametrize", "Parametrization", "flipped_faces"]

log = logging.getLogger(__name__)

_HALF_PI = math.pi / 2


# --------------------------------------------------------------------------- cut graph


@dataclass
class CutGraph:
    """A dual spanning tree and the cut it leaves.

    Attributes
    ----------
    parent : (F,) int64, the parent face in the BFS tree (-1 at roots, one per component)
    parent_edge : (F,) int64, the edge crossed to reach the face from its parent (-1 at roots)
    order : (F,) int64, faces in BFS order (parents first)
    tree_edges : (E,) bool, edges crossed by the dual tree
    cut_edges : (E,) bool, interior edges on the cut after pruning
    """

    parent: np.ndarray
    parent_edge: np.ndarray
    order: np.ndarray
    tree_edges: np.ndarray
    cut_edges: np.ndarray


def dual_tree(topo: Topology):
    ef = topo.edge_faces.numpy()
    interior = (ef >= 0).all(1)
    ei = np.flatnonzero(interior)
    a, b = ef[ei, 0], ef[ei, 1]
    nf = topo.num_faces
    adj = sp.coo_matrix(
        (np.concatenate([ei + 1, ei + 1]), (np.concatenate([a, b]), np.concatenate([b, a]))), shape=(nf, nf)
    ).tocsr()
    parent = np.full(nf, -1, dtype=np.int64)
    seen = np.zeros(nf, dtype=bool)
    orders = []
    for seed in range(nf):
        if seen[seed]:
            continue
        order, pred = csg.breadth_first_order(adj, seed, directed=False, return_predecessors=True)
        seen[order] = True
        parent[order[1:]] = pred[order[1:]]
        orders.append(order)
    order = np.concatenate(orders)
    has = parent >= 0
    parent_edge = np.full(nf, -1, dtype=np.int64)
    parent_edge[has] = np.asarray(adj[parent[has], np.flatnonzero(has)]).ravel() - 1
    tree = np.zeros(topo.num_edges, dtype=bool)
    tree[parent_edge[has]] = True
    return parent, parent_edge, order, tree


def prune_cut(topo: Topology, cut: np.ndarray, keep_vertex: np.ndarray) -> np.ndarray:
    """Remove dangling cut edges whose free end is not a vertex in ``keep_vertex``.

    Boundary edges count in the degrees (so cuts reaching the boundary stay) but are never
    removed or returned.
    """
    edges = topo.edges.numpy()
    cut = cut.copy()
    bnd = topo.boundary_edges.numpy()
    nv = topo.num_vertices
    deg = np.bincount(edges[cut | bnd].ravel(), minlength=nv)
    # vertex -> incident cut edges (CSR)
    ce = np.flatnonzero(cut)
    inc = sp.csr_matrix(
        (np.ones(2 * ce.size), (edges[ce].ravel(), np.repeat(ce, 2))), shape=(nv, topo.num_edges)
    )
    stack = list(np.flatnonzero((deg == 1) & ~keep_vertex))
    while stack:
        v = stack.pop()
        if deg[v] != 1 or keep_vertex[v]:
            continue
        row = inc.indices[inc.indptr[v] : inc.indptr[v + 1]]
        live = row[cut[row]]
        if live.size != 1:
            continue
        e = live[0]
        cut[e] = False
        for x in edges[e]:
            deg[x] -= 1
            if deg[x] == 1 and not keep_vertex[x]:
                stack.append(x)
    return cut


def cut_graph(verts, faces, keep_vertices=None) -> CutGraph:
    """Dual spanning tree and pruned cut graph (step 3).

    Parameters
    ----------
    keep_vertices : (V,) bool array or index list, vertices the cut must reach (the
        singularities); ``None`` prunes to the homology generators only.
    """
    verts, topo = topology_and_verts(verts, faces)
    parent, parent_edge, order, tree = dual_tree(topo)
    interior = ~topo.boundary_edges.numpy()
    cut = interior & ~tree
    keep = np.zeros(topo.num_vertices, dtype=bool)
    if keep_vertices is not None:
        keep[np.asarray(keep_vertices)] = True
    return CutGraph(parent, parent_edge, order, tree, prune_cut(topo, cut, keep))


# --------------------------------------------------------------------------- combing


@dataclass
class Combing:
    """One direction per face and the matchings across edges (step 3).

    Attributes
    ----------
    angle : (F,) float64, angle of ``U_f`` in the face frame of
        :func:`~torch_edgevf.fields.singularities.face_frame_angles` (edge-0 frame = angle 0)
    matching : (E,) int64 in {0, 1, 2, 3}: ``U_g = T_{f->g}(U_f) i^k`` for
        ``f = edge_faces[e, 0]``, ``g = edge_faces[e, 1]`` (0 on the tree and boundary)
    holonomy : (V,) int64 in {0, 1, 2, 3}, sum of the matchings around each vertex
    """

    angle: np.ndarray
    matching: np.ndarray
    holonomy: np.ndarray


def _face_cross_angles(verts, topo, z) -> tuple[np.ndarray, np.ndarray]:
    """(F,) angle of one cross direction at the face centroid, and (F, 3) frame angles."""
    theta = face_frame_angles(verts, topo).detach()
    zf = z.detach()[topo.face_edges.to(z.device)]
    w = (zf * torch.polar(torch.ones_like(theta), 4 * theta)).sum(1)
    return (torch.angle(w) / 4).cpu().numpy().astype(np.float64), theta.cpu().numpy().astype(np.float64)


def _transport_offsets(topo: Topology, theta: np.ndarray, alpha: np.ndarray, edges: np.ndarray):
    """For edges with two faces f (slot 0), g (slot 1): ``psi0 - alpha_g`` where
    ``psi0 = alpha_f - theta^f_a + theta^g_b`` is ``alpha_f`` transported into g."""
    ef = topo.edge_faces.numpy()[edges]
    ec = topo.edge_corners.numpy()[edges]
    f, g = ef[:, 0], ef[:, 1]
    psi0 = alpha[f] - theta[f, ec[:, 0]] + theta[g, ec[:, 1]]
    return psi0 - alpha[g], f, g


def comb(verts, faces, z, cut: CutGraph | None = None) -> Combing:
    """Comb a cross field into one direction per face along the dual tree (step 3)."""
    verts, topo = topology_and_verts(verts, faces)
    z = as_edge_field(z, topo, verts)
    cut = cut_graph(verts, topo) if cut is None else cut
    alpha, theta = _face_cross_angles(verts, topo, z)
    nf = topo.num_faces
    # offset of each tree child: m_g = m_f + delta, delta = round((psi0 - alpha_g) / (pi/2))
    child = np.flatnonzero(cut.parent >= 0)
    pe = cut.parent_edge[child]
    diff, f, g = _transport_offsets(topo, theta, alpha, pe)
    # the transport is from slot 0 to slot 1; if the child is in slot 0, reverse
    rev = f == child
    d = np.where(rev, -diff, diff)
    delta = np.zeros(nf, dtype=np.int64)
    delta[child] = np.rint(d / _HALF_PI).astype(np.int64)
    acc = _tree_cumsum(delta, cut.parent, cut.order)
    angle = alpha + _HALF_PI * acc
    # matchings on interior edges
    ef = topo.edge_faces.numpy()
    interior = np.flatnonzero((ef >= 0).all(1))
    matching = np.zeros(topo.num_edges, dtype=np.int64)
    ec = topo.edge_corners.numpy()[interior]
    fa, ga = ef[interior, 0], ef[interior, 1]
    psi = angle[fa] - theta[fa, ec[:, 0]] + theta[ga, ec[:, 1]]
    matching[interior] = np.mod(np.rint((angle[ga] - psi) / _HALF_PI).astype(np.int64), 4)
    edges = topo.edges.numpy()
    hol = np.zeros(topo.num_vertices, dtype=np.int64)
    np.add.at(hol, edges[:, 1], matching)
    np.add.at(hol, edges[:, 0], -matching)
    return Combing(angle, matching, np.mod(hol, 4))


def _tree_cumsum(delta: np.ndarray, parent: np.ndarray, order: np.ndarray | None = None) -> np.ndarray:
    """``acc[f] = delta[f] + acc[parent[f]]`` (roots: 0), by pointer jumping in O(F log depth)."""
    nf = delta.shape[0]
    acc = np.where(parent >= 0, delta, 0).astype(np.int64)
    p = np.where(parent >= 0, parent, np.arange(nf))
    while True:
        acc = acc + acc[p] * (p != np.arange(nf))
        p = p[p]
        if bool(np.all(p[p] == p)):
            acc = acc + acc[p] * (p != np.arange(nf))
            return acc


# --------------------------------------------------------------------------- rounding


def _pin_rows(idx: np.ndarray, ncls: int) -> sp.csr_matrix:
    k = idx.size
    return sp.csr_matrix(
        (np.ones(2 * k), (np.arange(2 * k), np.concatenate([idx, idx + ncls]))), shape=(2 * k, 2 * ncls)
    )


def _round(x, H, b, C, Tlo, cls, fl, keep, ncls, weight, max_rounds, round_cones=True):
    """Integer rounding (step 5), greedy over seams.

    (a) One copy of every cone vertex (singular, or of non-trivial matching holonomy) is
    rounded to integer ``(u, v)``; its other copies then follow through the integer
    transitions. (b) Seam translations are rounded greedily: the seam whose translation is
    closest to an integer is fixed, the system re-solved, and so on (a seam's cut edges
    share one translation and are fixed together). Rounding them all at once would break
    the closure of the transitions around cut-graph branchings.
    """
    v_of_corner = fl.ravel()
    corner_ok = keep[v_of_corner]
    _, first = np.unique(v_of_corner[corner_ok], return_index=True)
    s_cls = np.unique(cls.ravel()[np.flatnonzero(corner_ok)[first]])
    S = _pin_rows(s_cls, ncls)
    s_val = np.rint(np.concatenate([x[s_cls], x[s_cls + ncls]]))
    if round_cones:
        H = (H + weight * (S.T @ S)).tocsc()
        b = b + weight * (S.T @ s_val)
        x = sla.spsolve(H, b)
    log.info(
        "cones rounded: seams residual %.3g, cones residual %.3g",
        np.abs(C @ x).max(initial=0),
        np.abs(S @ x - s_val).max(initial=0),
    )
    n_edges = Tlo.shape[0] // 2
    fixed = np.zeros(n_edges, dtype=bool)
    rounds = 0
    while not fixed.all():
        t = (Tlo @ x).reshape(-1, 2)
        dist = np.abs(t - np.rint(t)).max(1)
        free = ~fixed
        if rounds >= max_rounds:
            pick = free
        else:
            best = dist[free].min()
            pick = free & (dist <= max(best + 1e-3, 1e-6))
        rows = np.flatnonzero(np.repeat(pick, 2))
        T = Tlo[rows]
        H = (H + weight * (T.T @ T)).tocsc()
        b = b + weight * (T.T @ np.rint(t.ravel()[rows]))
        x = sla.spsolve(H, b)
        fixed |= pick
        rounds += 1
    log.info(
        "rounding: %d cone copies, %d re-solves; residuals: seams %.3g, cones %.3g, translations %.3g",
        s_cls.size,
        rounds,
        np.abs(C @ x).max(initial=0),
        np.abs(S @ x - s_val).max(initial=0),
        np.abs(Tlo @ x - np.rint(Tlo @ x)).max(initial=0),
    )
    return x


# --------------------------------------------------------------------------- solve


@dataclass
class Parametrization:
    """Result of :func:`parametrize`.

    Attributes
    ----------
    verts, faces : the mesh the parametrization lives on (after splitting singular faces)
    uv : (F, 3, 2) tensor, per-corner ``(u, v)``; solved in float64, returned (like
        ``verts``, ``z`` and ``translations``) in the dtype of the input vertices
    z : (E,) cross field on that mesh
    cut_edges : (E,) bool tensor; matching : (E,) int64 (``k_e``, see :class:`Combing`)
    translations : (K, 2), ``t_e`` for the cut edges (in the order of
        ``cut_edges.nonzero()``): ``w_g = i^{-k} w_f + t`` at both ends of the edge
    singular_vertices : (S,) int64
    flipped : int, number of faces with negative signed ``uv`` area
    energy : float, ``int |grad u - s U|^2 + |grad v - s V|^2``
    scale : float ``s``
    rounded : bool
    """

    verts: torch.Tensor
    faces: torch.Tensor
    uv: torch.Tensor
    z: torch.Tensor
    cut_edges: torch.Tensor
    matching: torch.Tensor
    translations: torch.Tensor
    singular_vertices: torch.Tensor
    flipped: int
    energy: float
    scale: float
    rounded: bool
    face_angle: torch.Tensor | None = None


def face_plane(verts: np.ndarray, faces: np.ndarray, theta0_dir: np.ndarray):
    """Per-face 2D corner coordinates in the frame whose x axis is ``theta0_dir``."""
    p = verts[faces]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    x = theta0_dir
    y = np.cross(n, x)
    q = p - p[:, :1]
    return np.stack([(q * x[:, None]).sum(-1), (q * y[:, None]).sum(-1)], -1)  # (F, 3, 2)


def _rot(k: np.ndarray) -> np.ndarray:
    """(K, 2, 2) matrices of multiplication by ``i^{-k}`` on ``(u, v)``."""
    c = np.cos(-k * _HALF_PI).round()
    s = np.sin(-k * _HALF_PI).round()
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def flipped_faces(uv) -> torch.Tensor:
    """(F,) bool: faces whose ``(u, v)`` triangle has negative signed area."""
    uv = torch.as_tensor(uv)
    a = uv[:, 1] - uv[:, 0]
    b = uv[:, 2] - uv[:, 0]
    return (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]) < 0


def parametrize(
    verts,
    faces,
    z,
    scale: float | None = None,
    round_integers: bool = True,
    split: bool = True,
    penalty: float = 1e8,
    max_rounds: int = 200,
    round_cones: bool = False,
) -> Parametrization:
    """Seamless ``(u, v)`` parametrization guided by the cross field ``z`` (chapter 4).

    Parameters
    ----------
    verts : (V, 3) tensor
    faces : (F, 3) int tensor or :class:`Topology`
    z : (E,) complex tensor, representation vector of a cross field (``n = 4``)
    scale : target gradient norm ``s`` (about ``1/s`` per quad side); default
        ``1 / (2 h)`` with ``h`` the mean edge length
    round_integers : round seam translations and singular vertices to integers (step 5)
    split : move face singularities to new vertices first (1-to-3 split, thesis 4.1)
    penalty : weight of the seamless constraints relative to the (area-normalised) energy
    round_cones : also snap one copy of each cone vertex to integer ``(u, v)`` before the
        translations (experimental: with the direct penalty formulation this conflicts
        with the seam constraints on meshes with many close cones, e.g. Spot; off by
        default, so the result is seamless with integer translations but cones are not
        on integer positions)
    max_rounds : at most this many re-solves of the greedy translation rounding (the
        remaining translations are then rounded all at once)

    Returns
    -------
    :class:`Parametrization`
    """
    verts, topo = topology_and_verts(verts, faces)
    z = as_edge_field(z, topo, verts)
    if z.dim() != 1:
        raise ValueError(f"z must have shape (E,), got {tuple(z.shape)}")
    # solved in float64; the result comes back in the input's precision and on its device
    real_dtype, device = verts.dtype, verts.device
    verts = verts.detach().to(torch.float64)
    z = z.detach().to(torch.complex128)
    if split:
        s0 = singularities(verts, topo, z, n=4)
        if s0.singular_faces.numel():
            out = split_singular_faces(verts, topo, z, n=4)
            verts, z = out.verts, out.z
            topo = Topology(out.faces, verts.shape[0])
    sing = singularities(verts, topo, z, n=4)
    h = float(mean_edge_length(verts, topo))
    s = 1.0 / (2 * h) if scale is None else float(scale)

    # step 3: cut and comb; keep detected singular vertices and vertices of non-trivial holonomy
    parent, parent_edge, order, tree = dual_tree(topo)
    base = CutGraph(parent, parent_edge, order, tree, np.zeros(topo.num_edges, dtype=bool))
    cmb = comb(verts, topo, z, base)
    keep = np.zeros(topo.num_vertices, dtype=bool)
    keep[sing.singular_vertices.numpy()] = True
    keep |= cmb.holonomy != 0
    interior = ~topo.boundary_edges.numpy()
    cut = prune_cut(topo, interior & ~tree, keep)
    log.info("cut graph: %d edges, %d kept vertices", int(cut.sum()), int(keep.sum()))

    # step 4: unknowns per cut-mesh vertex (corners merged across non-cut interior edges)
    fl = topo.faces.numpy()
    nf = fl.shape[0]
    ef = topo.edge_faces.numpy()
    ec = topo.edge_corners.numpy()
    glue = np.flatnonzero(interior & ~cut)
    f0, f1 = ef[glue, 0], ef[glue, 1]
    k0, k1 = ec[glue, 0], ec[glue, 1]
    # in slot 0 the edge runs lo -> hi from corner k0+1 to k0+2; in slot 1 from k1+2 to k1+1
    a = np.concatenate([3 * f0 + (k0 + 1) % 3, 3 * f0 + (k0 + 2) % 3])
    b = np.concatenate([3 * f1 + (k1 + 2) % 3, 3 * f1 + (k1 + 1) % 3])
    nc = 3 * nf
    ncls, cls = csg.connected_components(
        sp.coo_matrix((np.ones(a.size), (a, b)), shape=(nc, nc)), directed=False
    )
    cls = cls.reshape(nf, 3)

    vnp = verts.numpy()
    d0 = vnp[fl[:, 2]] - vnp[fl[:, 1]]
    d0 *= topo.face_edge_signs.numpy()[:, :1]
    d0 /= np.linalg.norm(d0, axis=1, keepdims=True)
    P = face_plane(vnp, fl, d0)
    area = 0.5 * np.abs(P[:, 1, 0] * P[:, 2, 1] - P[:, 1, 1] * P[:, 2, 0])
    # hat gradients: grad lambda_k = rot90(P_{k+2} - P_{k+1}) / (2A)
    e = P[:, [2, 0, 1]] - P[:, [1, 2, 0]]
    grad = np.stack([-e[..., 1], e[..., 0]], -1) / (2 * area[:, None, None])  # (F, 3, 2)
    U = s * np.stack([np.cos(cmb.angle), np.sin(cmb.angle)], -1)  # (F, 2)
    V = np.stack([-U[:, 1], U[:, 0]], -1)
    w = np.sqrt(area / area.sum())
    rows = np.broadcast_to(np.arange(2 * nf).reshape(nf, 2, 1), (nf, 2, 3))
    cols = np.broadcast_to(cls[:, None, :], (nf, 2, 3))
    vals = w[:, None, None] * np.transpose(grad, (0, 2, 1))  # (F, 2, 3)
    B = sp.csr_matrix((vals.ravel(), (rows.ravel(), cols.ravel())), shape=(2 * nf, ncls))
    A_ls = sp.block_diag([B, B]).tocsr()  # unknowns: [u (ncls), v (ncls)]
    rhs = np.concatenate([(w[:, None] * U).ravel(), (w[:, None] * V).ravel()])

    # seamless constraints on cut edges: for both endpoints x of the edge,
    # w_g(x) - i^{-k} w_f(x) = t_e, eliminated as differences between the two endpoints
    ce = np.flatnonzero(cut)
    cf, cg = ef[ce, 0], ef[ce, 1]
    kf, kg = ec[ce, 0], ec[ce, 1]
    lo_f, hi_f = cls[cf, (kf + 1) % 3], cls[cf, (kf + 2) % 3]
    lo_g, hi_g = cls[cg, (kg + 2) % 3], cls[cg, (kg + 1) % 3]
    R = _rot(cmb.matching[ce].astype(np.float64))  # (K, 2, 2)

    def transition_rows(xg, xf, sign_rows, extra=None):
        """Rows expressing ``w_g(x) - R w_f(x)`` (2 per edge) as sparse entries."""
        kk = np.arange(ce.size)
        r_list, c_list, v_list = [], [], []
        for comp in range(2):
            r = 2 * kk + comp
            # + w_g component
            r_list.append(r)
            c_list.append(xg + comp * ncls)
            v_list.append(np.ones(ce.size))
            for j in range(2):
                r_list.append(r)
                c_list.append(xf + j * ncls)
                v_list.append(-R[:, comp, j])
        return np.concatenate(r_list), np.concatenate(c_list), sign_rows * np.concatenate(v_list)

    r1, c1, v1 = transition_rows(hi_g, hi_f, 1.0)
    r2, c2, v2 = transition_rows(lo_g, lo_f, -1.0)
    C = sp.csr_matrix(
        (np.concatenate([v1, v2]), (np.concatenate([r1, r2]), np.concatenate([c1, c2]))),
        shape=(2 * ce.size, 2 * ncls),
    )
    Tlo = sp.csr_matrix((np.concatenate([v2 * -1]), (r2, c2)), shape=(2 * ce.size, 2 * ncls))

    # gauge: pin one class per connected component of the cut mesh to (0, 0)
    comp_lbl = topo.components.numpy()[fl[:, 0]]
    pin_cls = np.unique(cls[np.unique(comp_lbl, return_index=True)[1], 0])
    G = sp.csr_matrix(
        (np.ones(2 * pin_cls.size), (np.arange(2 * pin_cls.size), np.concatenate([pin_cls, pin_cls + ncls]))),
        shape=(2 * pin_cls.size, 2 * ncls),
    )
    pen = penalty
    scale_c = 1.0 / h  # constraint rows are in uv units; scale them like gradients
    H = (A_ls.T @ A_ls + pen * scale_c**2 * (C.T @ C) + pen * (G.T @ G)).tocsc()
    b = A_ls.T @ rhs
    x = sla.spsolve(H, b)

    rounded = False
    if round_integers:
        x = _round(x, H, b, C, Tlo, cls, fl, keep, ncls, pen * scale_c**2, max_rounds, round_cones)
        rounded = True

    u, v = x[:ncls], x[ncls:]
    uv = np.stack([u[cls], v[cls]], -1)  # (F, 3, 2)
    t_final = (Tlo @ x).reshape(-1, 2)
    energy = float(np.sum((A_ls @ x - rhs) ** 2) * area.sum())
    flips = flipped_faces(torch.from_numpy(uv))
    dev = topo.faces.device
    complex_dtype = complex_dtype_of(real_dtype)
    return Parametrization(
        verts=verts.to(device=device, dtype=real_dtype),
        faces=topo.faces,
        uv=torch.from_numpy(uv).to(device=device, dtype=real_dtype),
        z=z.to(device=device, dtype=complex_dtype),
        cut_edges=torch.from_numpy(cut).to(dev),
        matching=torch.from_numpy(cmb.matching),
        translations=torch.from_numpy(t_final).to(device=device, dtype=real_dtype),
        singular_vertices=sing.singular_vertices,
        flipped=int(flips.sum()),
        energy=energy,
        scale=s,
        rounded=rounded,
        face_angle=torch.from_numpy(cmb.angle),
    )
