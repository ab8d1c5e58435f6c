"""Per-face value kernels and the cached assembly plans of the operators.

The internal API that :mod:`torch_edgevf.operators.functional` (one operator per call)
and :class:`~torch_edgevf.operators.module.EdgeOperators` (all operators of one set of
positions, sharing the face geometry) are both written on. Each ``*_values`` kernel maps
a :class:`~torch_edgevf.mesh.geometry.FaceGeometry` (and the orientation signs
``delta``) to the contributions of every face, in the order of the sparsity pattern
returned by :func:`pattern`; each ``*_from`` function assembles one operator from them.
The formulas are those of the table in :mod:`torch_edgevf.operators`.
"""

from __future__ import annotations

from typing import Literal, overload

import numpy as np
import torch

from .._validation import single_mesh
from ..mesh.geometry import (
    OFF_DIAGONAL,
    FaceGeometry,
    face_geometry,
    int_power,
    pair_columns,
    pair_transport,
    topology_and_verts,
)
from ..mesh.topology import DerivedKey, Topology, unique_pairs
from .patterns import (
    EdgePairPattern,
    EdgeVertexPattern,
    Pattern,
    VertexPairPattern,
    diagonal,
    index_dtype,
    sparse_coo,
    symmetric_layout,
)

_PATTERN_KEYS: dict[str, DerivedKey] = {
    "EE": "pattern.EE",
    "EV": "pattern.EV",
    "VV": "pattern.VV",
    "FE": "pattern.FE",
}


@overload
def cached_pattern(topo: Topology, name: Literal["EE"]) -> EdgePairPattern: ...
@overload
def cached_pattern(topo: Topology, name: Literal["EV"]) -> EdgeVertexPattern: ...
@overload
def cached_pattern(topo: Topology, name: Literal["VV"]) -> VertexPairPattern: ...
@overload
def cached_pattern(topo: Topology, name: Literal["FE"]) -> Pattern: ...


def cached_pattern(
    topo: Topology, name: str
) -> Pattern | EdgePairPattern | EdgeVertexPattern | VertexPairPattern:
    """The cached sparsity pattern ``name`` of ``topo`` (built on first use).

    ``"EE"`` (E, E) edge pairs of a face, ``"EV"`` (E, V) edge and corner, ``"VV"`` (V, V)
    corner pairs, ``"FE"`` (F, E) face and edge.
    """

    def build():
        f, fe = topo.compact_faces(), topo.compact_face_edges()  # int32 where the mesh allows
        ne, nv, nf = topo.num_edges, topo.num_vertices, topo.num_faces
        if name == "EE":
            return EdgePairPattern(fe, topo.side_corners())
        if name == "EV":  # pair-major: contribution p F + f, for the corner pair p = 3a + b of face f
            return EdgeVertexPattern(f, topo.edges.numpy(), topo.side_corners(), nv)
        if name == "VV":  # face-major: contribution 9 f + p
            return VertexPairPattern(f, topo.edges.numpy(), topo.side_corners(), nv)
        if name == "FE":
            return Pattern(np.repeat(np.arange(nf), 3), fe, (nf, ne))
        raise KeyError(name)

    return topo.cached(_PATTERN_KEYS[name], build)


def laplace_beltrami_plan(topo: Topology):
    """For ``L = Re(G^H M_z^{-1} G)``: which products of nonzeros of G go where.

    With ``h`` the values of G scaled by ``1 / sqrt(m_row)``, ``L_uu = sum |h_eu|^2`` over the
    nonzeros of column ``u`` and, for ``u < v``, ``L_uv = L_vu = sum Re(conj(h_eu) h_ev)`` over the
    rows ``e`` holding both. Only these upper pairs (at most 6 per row of G) are formed; the
    full matrix is one gather of ``[diagonal, upper, upper]`` into sorted COO order.

    Returns a dict of tensors: ``indices`` (2, nnz) of L, ``rows`` and ``cols`` of G's
    nonzeros, ``p``, ``q`` (positions in G's values of each pair), ``target`` (the unique upper
    entry of each pair), ``num_upper`` and ``gather``.
    """

    def build():
        ev = cached_pattern(topo, "EV")
        rows, cols = ev.indices.numpy()
        nv, ne = topo.num_vertices, topo.num_edges
        counts = np.bincount(rows, minlength=ne)
        start = np.cumsum(counts) - counts
        width = int(counts.max())
        iu, ju = np.triu_indices(width, 1)
        valid = ju[None, :] < counts[:, None]  # iu < ju, so the first is valid too
        p = (start[:, None] + iu[None, :])[valid]
        q = (start[:, None] + ju[None, :])[valid]
        del valid
        # G's rows are sorted by column, so cols[p] < cols[q]
        keys, target = unique_pairs(cols[p], cols[q], nv)
        nu = keys.shape[0]
        up_row = keys // nv
        up_col = keys - up_row * nv
        del keys
        has_diag = np.bincount(cols, minlength=nv) > 0
        indices, gather = symmetric_layout(up_row, up_col, has_diag, nv)
        index = index_dtype(max(nv + 2 * nu, cols.shape[0] + 1))
        return {
            "indices": torch.from_numpy(indices),
            "rows": torch.from_numpy(rows.astype(index)),
            "cols": torch.from_numpy(cols.astype(index)),
            "p": torch.from_numpy(p.astype(index)),
            "q": torch.from_numpy(q.astype(index)),
            "target": torch.from_numpy(target.astype(index)),
            "num_upper": nu,
            "gather": torch.from_numpy(gather),
        }

    return topo.cached("plan.laplace_beltrami", build)


def prepare(verts, topo) -> tuple[torch.Tensor, Topology, FaceGeometry, torch.Tensor]:
    """Positions (or a geometry standing in for them), topology, face geometry and signs.

    ``verts`` may be a :class:`FaceGeometry` (e.g. :meth:`FaceGeometry.from_edge_lengths`):
    it is then returned in place of the positions and used as the geometry; or a batch of
    one mesh with ``verts_list()`` / ``faces_list()`` (a ``pytorch3d.structures.Meshes``),
    with ``topo`` left out.
    """
    verts, topo = single_mesh(verts, topo, "an operator function")
    if topo is None:
        raise ValueError("the faces (or a Topology) are needed with verts")
    if isinstance(verts, FaceGeometry):
        topo = intrinsic_topology(verts, topo)
        signs = topo.face_edge_signs.to(device=verts.device, dtype=verts.dtype)
        return verts, topo, verts, signs  # type: ignore[return-value]
    verts, topo = topology_and_verts(verts, topo)
    geom = face_geometry(verts, topo)
    signs = topo.face_edge_signs.to(device=verts.device, dtype=verts.dtype)
    return verts, topo, geom, signs


def intrinsic_topology(geom: FaceGeometry, topo) -> Topology:
    """The topology of a :class:`FaceGeometry` used in place of positions, checked against it."""
    if not isinstance(topo, Topology):
        topo = Topology(topo)
    if geom.num_faces != topo.num_faces:
        raise ValueError(f"the geometry has {geom.num_faces} faces but the topology {topo.num_faces}")
    return topo


def mass_values(geom: FaceGeometry, topo: Topology) -> torch.Tensor:
    """``(M_z)_ee = sum A / 3`` over the (one or two) faces of each edge: two gathers."""
    third = geom.area / 3
    if topo.is_closed:
        sides = topo.edge_faces_t().to(third.device)
        return third.index_select(0, sides[0]) + third.index_select(0, sides[1])
    fe = torch.from_numpy(topo.compact_face_edges()).to(third.device)
    return third.new_zeros(topo.num_edges).index_add(0, fe.flatten(), third[:, None].expand(-1, 3).flatten())


def connection_laplacian_from(
    geom: FaceGeometry, signs: torch.Tensor, topo: Topology, n: int
) -> torch.Tensor:
    """Assemble ``L_c^(n)`` from the 3 diagonal and 3 unique off-diagonal terms of each face.

    For the pair ``(a, b) = (j, j + 1)`` with third corner ``c = j + 2`` the entry is
    ``-(2 d_c / 2A) conj(r_ab)^n`` with ``r_ab = -delta_a delta_b (d_c + i 2A) / (l_a l_b)``;
    the transposed entry is its conjugate (Hermitian). Computed corner-major, on ``(F,)`` rows.
    """
    pattern = cached_pattern(topo, "EE")
    tensors = (geom.lengths, geom.double_area, geom.dots)
    if geom.device.type == "cpu" and not (torch.is_grad_enabled() and any(t.requires_grad for t in tensors)):
        dtype = geom.dtype if n == 0 else torch.promote_types(geom.dtype, torch.complex64)
        return pattern.assemble_by_blocks(lambda block: _laplacian_terms(geom, signs, n, block), dtype)
    return pattern.assemble(*_laplacian_terms(geom, signs, n))  # lower = conj(upper): Hermitian


def _laplacian_terms(geom: FaceGeometry, signs: torch.Tensor, n: int, block: slice = slice(None)):
    """The diagonal and upper face terms of ``L_c^(n)`` (three ``(B,)`` columns each) of a block of faces."""
    a2 = geom.double_area[block]
    lt, dt = geom.lengths.t()[:, block], geom.dots.t()[:, block]  # (3, B)
    inv_a2 = 1 / a2
    diag = [2 * lt[k] * lt[k] * inv_a2 for k in range(3)]
    dc = [dt[(j + 2) % 3] for j in range(3)]
    weight = [-2 * dc[j] * inv_a2 for j in range(3)]
    if n == 0:
        return diag, weight
    upper = []
    st = signs.t()[:, block]
    for j in range(3):
        inv_lab = 1 / (lt[j] * lt[(j + 1) % 3])
        w = weight[j] if n % 2 == 0 else weight[j] * (-st[j] * st[(j + 1) % 3])
        re, im = dc[j] * inv_lab, -a2 * inv_lab
        if n == 1:  # the product with the real weight, without a complex copy of it
            upper.append(torch.complex(w * re, w * im))
        else:
            power = int_power(torch.complex(re, im), n)
            upper.append(torch.view_as_complex(torch.view_as_real(power) * w[:, None]))
    return diag, upper


def gradient_values(geom: FaceGeometry, signs: torch.Tensor) -> torch.Tensor:
    """Per-face ``G`` contributions, corner-major ``(9 F,)`` in the order of ``cached_pattern(topo, "EV")``.

    ``G[e_a, v_b] += i delta_b l_b / 6 r_ba`` simplifies, with ``r_ba = conj(r_ab)``, to
    ``i delta_a l_a / 6`` for ``b = a``, ``-delta_a (2A + i d_c) / (6 l_a)`` for ``b = a + 1``
    and ``-delta_a (-2A + i d_c) / (6 l_a)`` for ``b = a + 2`` (``c`` the third corner).
    """
    lt, dt, st = geom.lengths.t(), geom.dots.t(), signs.t()
    a2 = geom.double_area
    values: list[torch.Tensor] = [a2] * 9  # every slot is set below
    for a in range(3):
        nxt, prv = (a + 1) % 3, (a + 2) % 3
        scale = -st[a] / (6 * lt[a])
        values[3 * a + a] = torch.complex(torch.zeros_like(a2), st[a] * lt[a] / 6)
        values[3 * a + nxt] = torch.complex(scale * a2, scale * dt[prv])
        values[3 * a + prv] = torch.complex(-scale * a2, scale * dt[nxt])
    return torch.stack(values).reshape(-1)


def covariant_values(
    geom: FaceGeometry, signs: torch.Tensor, w_pairs: torch.Tensor, n: int = 1, transports=None
) -> torch.Tensor:
    """The values of ``D_w``; ``transports`` = ``(r, r^n)`` of :func:`pair_transport` when the
    caller has them."""
    if transports is None:
        r = pair_transport(geom, signs, 1)
        rn = r if n == 1 else pair_transport(geom, signs, n)
    else:
        r, rn = transports
    scale = -pair_columns(signs * geom.lengths, "b") / 3
    return (scale * (w_pairs * r).imag * rn.conj()).flatten()


def curl_values(geom: FaceGeometry, signs: torch.Tensor) -> torch.Tensor:
    return (signs * geom.lengths).flatten()


def curl_energy_block(verts, topo) -> tuple[torch.Tensor, int]:
    verts, topo, geom, signs = prepare(verts, topo)
    k = signs * geom.lengths
    vals = 2 * pair_columns(k, "a") * pair_columns(k, "b") / geom.double_area[:, None]
    return cached_pattern(topo, "EE").assemble_pairs(vals), topo.num_edges


def embed_block(block: torch.Tensor, offset: int, size: int) -> torch.Tensor:
    return sparse_coo(block.indices() + offset, block.values(), (size, size))


def laplace_beltrami_from(g_values: torch.Tensor, mass: torch.Tensor, topo: Topology) -> torch.Tensor:
    plan = laplace_beltrami_plan(topo)
    dev = g_values.device
    t = {k: (v.to(dev) if isinstance(v, torch.Tensor) else v) for k, v in plan.items()}
    scaled = g_values / torch.sqrt(mass).index_select(0, t["rows"])
    re, im = scaled.real, scaled.imag
    nv = topo.num_vertices
    diag = re.new_zeros(nv).index_add(0, t["cols"], re * re + im * im)
    p, q = t["p"], t["q"]
    prod = re.index_select(0, p) * re.index_select(0, q) + im.index_select(0, p) * im.index_select(0, q)
    upper = re.new_zeros(int(t["num_upper"])).index_add(0, t["target"], prod)
    values = torch.cat([diag, upper, upper]).index_select(0, t["gather"])
    return sparse_coo(t["indices"], values, (nv, nv))


def vertex_mass_from(geom: FaceGeometry, topo: Topology, lumped: bool) -> torch.Tensor:
    faces = topo.faces.to(geom.area.device)
    if lumped:
        third = (geom.area / 3)[:, None].expand(-1, 3)
        return diagonal(geom.area.new_zeros(topo.num_vertices).index_add(0, faces.flatten(), third.flatten()))
    eye = torch.as_tensor(~OFF_DIAGONAL, dtype=geom.area.dtype, device=geom.area.device)
    vals = geom.area[:, None] * (1 + eye) / 12
    return cached_pattern(topo, "VV").assemble(vals.flatten())


def covariant_from(geom, signs, topo, w, n: int = 1, transports=None) -> torch.Tensor:
    w_pairs = w[pair_columns(topo.face_edges.to(w.device), "a")]
    values = covariant_values(geom, signs, w_pairs, n, transports)
    return cached_pattern(topo, "EE").assemble_pairs(values)
