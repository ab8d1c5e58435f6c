"""Every edge-based operator of the thesis as a torch sparse COO tensor.

Each public function takes ``(verts, topo)``: vertex positions ``(V, 3)`` (float32 or
float64; gradients flow back to them) and a :class:`~torch_edgevf.topology.Topology` (or a
faces array, from which one is built). The sparsity patterns are computed once per
topology and cached on it; re-assembly for new positions is a gather and a scatter.

Per face, with corners ``a, b`` and third corner ``c``, lengths ``l`` of the opposite
edges, area ``A``, signs ``delta`` and transport ``r_ab`` (:func:`transport_coefficients`):

==========================  ==============================================================
operator                    contribution of one face
==========================  ==============================================================
``M_z``  (E, E)             ``(M_z)_aa += A / 3``                                (3.1, A.2)
``L_c^(n)``  (E, E)         ``(L)_aa += l_a^2 / A``, ``(L)_ab += -l_a l_b cos(alpha_c) / A * r_ba^n``  (3.1, A.3)
``G``  (E, V)               ``G[e_a, v_b] += i delta_b l_b / 6 * r_ba``  (``r_aa = 1``)  (4.2, A.4)
``K``  (F, E)               ``K[f, e_a] = delta_a l_a``                                (3.3)
``D_w``  (E, E)             ``(D)_ab += -delta_b l_b / 3 * Im(w_a r_ab) * r_ba``  (5.1, A.5)
``M_v`` full  (V, V)        ``A / 6`` on the diagonal, ``A / 12`` off it
``L``  (V, V)               ``G^H M_z^{-1} G`` (real)                                  (4.2)
==========================  ==============================================================
"""

from __future__ import annotations

import numpy as np
import torch

from ._sparse import (
    EdgePairPattern,
    EdgeVertexPattern,
    Pattern,
    VertexPairPattern,
    _index_dtype,
    diagonal,
    sparse_coo,
    symmetric_layout,
    unique_pairs,
)
from ._validation import check_n
from .geometry import (
    OFF_DIAGONAL,
    PAIR_A,
    PAIR_B,
    PAIR_C,
    FaceGeometry,
    _topology_and_verts,
    _int_power,
    face_geometry,
    pair_columns,
    pair_transport,
)
from .topology import Topology

__all__ = [
    "mass_matrix",
    "connection_laplacian",
    "gradient",
    "curl_div_operator",
    "face_curl",
    "face_div",
    "vertex_div_curl",
    "real_form",
    "curl_energy",
    "div_energy",
    "laplace_beltrami",
    "vertex_mass",
    "covariant_derivative",
    "cotan_laplacian",
]

_A, _B, _C = PAIR_A, PAIR_B, PAIR_C


# --------------------------------------------------------------------------- patterns


def _pattern(topo: Topology, name: str) -> Pattern:
    """The cached sparsity pattern ``name`` of ``topo`` (built on first use)."""

    def build():
        f, fe = topo._faces, topo._face_edges  # int32 where the mesh allows
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

    return topo.cached(("pattern", name), build)


def _laplace_beltrami_plan(topo: Topology):
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
        ev = _pattern(topo, "EV")
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
        index = _index_dtype(max(nv + 2 * nu, cols.shape[0] + 1))
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

    return topo.cached(("plan", "laplace_beltrami"), build)


# --------------------------------------------------------------------------- helpers


def _prepare(verts, topo) -> tuple[torch.Tensor, Topology, FaceGeometry, torch.Tensor]:
    verts, topo = _topology_and_verts(verts, topo)
    geom = face_geometry(verts, topo)
    signs = topo.face_edge_signs.to(device=verts.device, dtype=verts.dtype)
    return verts, topo, geom, signs


def _complex_dtype(dtype: torch.dtype) -> torch.dtype:
    return torch.complex64 if dtype in (torch.float32, torch.float16, torch.bfloat16) else torch.complex128


def _edge_field(z, topo: Topology, like: torch.Tensor, name: str = "z") -> torch.Tensor:
    """Check and convert an edge field ``(E,)`` or ``(E, C)`` to the complex dtype of ``like``."""
    if not isinstance(z, torch.Tensor):
        z = torch.as_tensor(z)
    if z.dim() not in (1, 2) or z.shape[0] != topo.num_edges:
        raise ValueError(
            f"{name} must have shape (E,) or (E, C) with E = {topo.num_edges} edges, got {tuple(z.shape)}"
        )
    if not (z.is_complex() or z.is_floating_point()):
        raise ValueError(f"{name} must be a floating or complex tensor, got {z.dtype}")
    target = _complex_dtype(like.dtype)
    if z.is_complex() and z.dtype != target:
        raise ValueError(f"{name} has dtype {z.dtype} but the mesh is {like.dtype}: expected {target}")
    if not torch.isfinite(z.detach()).all():
        bad = torch.nonzero(~torch.isfinite(z.detach()).reshape(z.shape[0], -1).all(1)).flatten().tolist()
        raise ValueError(f"{name} has NaN or Inf values at edges {bad[:10]}")
    return z.to(device=like.device, dtype=target)


# --------------------------------------------------------------------------- values per face


def _mass_values(geom: FaceGeometry, topo: Topology) -> torch.Tensor:
    """``(M_z)_ee = sum A / 3`` over the (one or two) faces of each edge: two gathers."""
    third = geom.area / 3
    if topo.is_closed:
        sides = topo.edge_faces_t().to(third.device)
        return third.index_select(0, sides[0]) + third.index_select(0, sides[1])
    fe = torch.from_numpy(topo._face_edges).to(third.device)
    return third.new_zeros(topo.num_edges).index_add(0, fe.flatten(), third[:, None].expand(-1, 3).flatten())


def _connection_laplacian_from(geom: FaceGeometry, signs: torch.Tensor, topo: Topology, n: int) -> torch.Tensor:
    """Assemble ``L_c^(n)`` from the 3 diagonal and 3 unique off-diagonal terms of each face.

    For the pair ``(a, b) = (j, j + 1)`` with third corner ``c = j + 2`` the entry is
    ``-(2 d_c / 2A) conj(r_ab)^n`` with ``r_ab = -delta_a delta_b (d_c + i 2A) / (l_a l_b)``;
    the transposed entry is its conjugate (Hermitian). Computed corner-major, on ``(F,)`` rows.
    """
    a2 = geom.double_area
    lt, dt = geom.lengths.t(), geom.dots.t()  # (3, F)
    inv_a2 = 1 / a2
    diag = [2 * lt[k] * lt[k] * inv_a2 for k in range(3)]
    dc = [dt[(j + 2) % 3] for j in range(3)]
    weight = [-2 * dc[j] * inv_a2 for j in range(3)]
    pattern = _pattern(topo, "EE")
    if n == 0:
        return pattern.assemble(diag, weight)
    upper = []
    st = signs.t()
    for j in range(3):
        inv_lab = 1 / (lt[j] * lt[(j + 1) % 3])
        w = weight[j] if n % 2 == 0 else weight[j] * (-st[j] * st[(j + 1) % 3])
        upper.append(w * _int_power(torch.complex(dc[j] * inv_lab, -a2 * inv_lab), n))
    return pattern.assemble(diag, upper)  # lower = conj(upper): Hermitian


def _gradient_values(geom: FaceGeometry, signs: torch.Tensor) -> torch.Tensor:
    """Per-face ``G`` contributions, corner-major ``(9 F,)`` in the order of ``_pattern(topo, "EV")``.

    ``G[e_a, v_b] += i delta_b l_b / 6 r_ba`` simplifies, with ``r_ba = conj(r_ab)``, to
    ``i delta_a l_a / 6`` for ``b = a``, ``-delta_a (2A + i d_c) / (6 l_a)`` for ``b = a + 1``
    and ``-delta_a (-2A + i d_c) / (6 l_a)`` for ``b = a + 2`` (``c`` the third corner).
    """
    lt, dt, st = geom.lengths.t(), geom.dots.t(), signs.t()
    a2 = geom.double_area
    values = [None] * 9
    for a in range(3):
        nxt, prv = (a + 1) % 3, (a + 2) % 3
        scale = -st[a] / (6 * lt[a])
        values[3 * a + a] = torch.complex(torch.zeros_like(a2), st[a] * lt[a] / 6)
        values[3 * a + nxt] = torch.complex(scale * a2, scale * dt[prv])
        values[3 * a + prv] = torch.complex(-scale * a2, scale * dt[nxt])
    return torch.stack(values).reshape(-1)


def _covariant_values(geom: FaceGeometry, signs: torch.Tensor, w_pairs: torch.Tensor) -> torch.Tensor:
    r = pair_transport(geom, signs, 1)
    scale = -pair_columns(signs * geom.lengths, "b") / 3
    return (scale * (w_pairs * r).imag * r.conj()).flatten()


def _curl_values(geom: FaceGeometry, signs: torch.Tensor) -> torch.Tensor:
    return (signs * geom.lengths).flatten()


# --------------------------------------------------------------------------- operators


def mass_matrix(verts, topo) -> torch.Tensor:
    """The edge mass matrix ``M_z`` (thesis 3.1, A.2): real, diagonal, exact (not lumped).

    .. math::  (M_z)_{ee} = \\sum_{T \\ni e} A_T / 3

    Returns
    -------
    (E, E) real sparse tensor.
    """
    verts, topo, geom, _ = _prepare(verts, topo)
    return diagonal(_mass_values(geom, topo))


def connection_laplacian(verts, topo, n: int = 1) -> torch.Tensor:
    """The connection Laplacian ``L_c`` acting on representation vectors of n-direction fields.

    .. math::
        (L_c)_{aa} \\mathrel{+}= \\frac{|e_a|^2}{A_T}, \\qquad
        (L_c)_{ab} \\mathrel{+}= -\\frac{|e_a||e_b|}{A_T} \\cos(\\alpha_c)\\, r_{ba}^n

    (thesis 3.1 and A.3). Hermitian positive semi-definite with a real diagonal;
    ``z^H L_c z`` is the Dirichlet energy of the field. ``n = 0`` gives the real scalar
    Crouzeix-Raviart Laplacian.

    Returns
    -------
    (E, E) sparse tensor, complex for ``n >= 1``, real for ``n = 0``.
    """
    n = check_n(n, minimum=0)
    verts, topo, geom, signs = _prepare(verts, topo)
    return _connection_laplacian_from(geom, signs, topo, n)


def gradient(verts, topo) -> torch.Tensor:
    """The gradient ``G`` from vertex functions to edge fields (thesis 4.2, A.4).

    ``M_z z = G f`` gives the edge field ``z`` of ``grad f``; per face,

    .. math::  G_{e_a, v_b} \\mathrel{+}= \\imath \\delta_b \\frac{|e_b|}{6} r_{ba}, \\quad r_{aa} = 1.

    Returns
    -------
    (E, V) complex sparse tensor.
    """
    verts, topo, geom, signs = _prepare(verts, topo)
    return _pattern(topo, "EV").assemble(_gradient_values(geom, signs))


def curl_div_operator(verts, topo) -> torch.Tensor:
    """``K = G_{e->t} M_e``, the signed face-edge incidence scaled by edge lengths (thesis 3.3).

    ``M_t curl_T = K Re(z)`` and ``M_t div_T = -K Im(z)``, with ``M_t`` the face areas.

    Returns
    -------
    (F, E) real sparse tensor.
    """
    verts, topo, geom, signs = _prepare(verts, topo)
    return _pattern(topo, "FE").assemble(_curl_values(geom, signs))


def _face_circulation(verts, topo, z) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    verts, topo, geom, signs = _prepare(verts, topo)
    z = _edge_field(z, topo, verts)
    fe = topo.face_edges.to(verts.device)
    weights = (signs * geom.lengths)
    zf = z[fe]  # (F, 3) or (F, 3, C)
    if z.dim() == 2:
        weights = weights[..., None]
    area = geom.area if z.dim() == 1 else geom.area[:, None]
    return (weights * zf.real).sum(1), (weights * zf.imag).sum(1), area


def face_curl(verts, topo, z) -> torch.Tensor:
    """(F,) or (F, C) face-wise curl ``curl_T = K Re(z) / A_T`` (circulation theorem, 3.3)."""
    re, _, area = _face_circulation(verts, topo, z)
    return re / area


def face_div(verts, topo, z) -> torch.Tensor:
    """(F,) or (F, C) face-wise divergence ``div_T = -K Im(z) / A_T`` (3.3)."""
    _, im, area = _face_circulation(verts, topo, z)
    return -im / area


def vertex_div_curl(verts, topo, z) -> tuple[torch.Tensor, torch.Tensor]:
    """Vertex-wise divergence and curl from the adjoint of the gradient (thesis 4.2, B.4).

    .. math::  M_v (\\operatorname{div}_v + \\imath \\operatorname{curl}_v) = -G^* z

    with the lumped vertex mass ``M_v``. Unreferenced vertices get 0.

    Returns
    -------
    div, curl : (V,) or (V, C) real tensors.
    """
    verts, topo, geom, signs = _prepare(verts, topo)
    z = _edge_field(z, topo, verts)
    g = _pattern(topo, "EV").assemble(_gradient_values(geom, signs))
    gz = -(g.conj().transpose(0, 1) @ z)
    mass = vertex_mass(verts, topo, lumped=True).values()
    mass = torch.where(mass > 0, mass, torch.ones_like(mass))
    out = gz / (mass if z.dim() == 1 else mass[:, None])
    return out.real, out.imag


def real_form(a: torch.Tensor) -> torch.Tensor:
    """The real ``(2M, 2N)`` form of a complex ``(M, N)`` sparse matrix (thesis 3.3).

    .. math::  \\begin{pmatrix} \\operatorname{Re} A & -\\operatorname{Im} A \\\\
               \\operatorname{Im} A & \\operatorname{Re} A \\end{pmatrix},

    acting on ``(Re z, Im z)``. A real input is treated as having zero imaginary part.
    """
    if not a.is_sparse:
        raise ValueError("real_form expects a sparse COO tensor")
    a = a.coalesce()
    m, n = a.shape
    idx, val = a.indices(), a.values()
    re, im = (val.real, val.imag) if val.is_complex() else (val, torch.zeros_like(val))
    shift_r = torch.tensor([[m], [0]], device=idx.device)
    shift_c = torch.tensor([[0], [n]], device=idx.device)
    indices = torch.cat([idx, idx + shift_c, idx + shift_r, idx + shift_r + shift_c], dim=1)
    values = torch.cat([re, -im, im, re])
    return torch.sparse_coo_tensor(indices, values, (2 * m, 2 * n), check_invariants=False).coalesce()


def _curl_energy_block(verts, topo) -> tuple[torch.Tensor, int]:
    verts, topo, geom, signs = _prepare(verts, topo)
    k = signs * geom.lengths
    vals = 2 * pair_columns(k, "a") * pair_columns(k, "b") / geom.double_area[:, None]
    return _pattern(topo, "EE").assemble_pairs(vals), topo.num_edges


def _embed(block: torch.Tensor, offset: int, size: int) -> torch.Tensor:
    return sparse_coo(block.indices() + offset, block.values(), (size, size))


def curl_energy(verts, topo) -> torch.Tensor:
    """``L_curl = [[K^T M_t^{-1} K, 0], [0, 0]]``, ``(2E, 2E)`` real (thesis 3.3).

    ``x^T L_curl x = int curl(psi)^2`` for ``x = (Re z, Im z)``.
    """
    block, ne = _curl_energy_block(verts, topo)
    return _embed(block, 0, 2 * ne)


def div_energy(verts, topo) -> torch.Tensor:
    """``L_div = [[0, 0], [0, K^T M_t^{-1} K]]``, ``(2E, 2E)`` real (thesis 3.3)."""
    block, ne = _curl_energy_block(verts, topo)
    return _embed(block, ne, 2 * ne)


def _laplace_beltrami_from(g_values: torch.Tensor, mass: torch.Tensor, topo: Topology) -> torch.Tensor:
    plan = _laplace_beltrami_plan(topo)
    dev = g_values.device
    t = {k: (v.to(dev) if isinstance(v, torch.Tensor) else v) for k, v in plan.items()}
    scaled = g_values / torch.sqrt(mass).index_select(0, t["rows"])
    re, im = scaled.real, scaled.imag
    nv = topo.num_vertices
    diag = re.new_zeros(nv).index_add(0, t["cols"], re * re + im * im)
    p, q = t["p"], t["q"]
    prod = re.index_select(0, p) * re.index_select(0, q) + im.index_select(0, p) * im.index_select(0, q)
    upper = re.new_zeros(t["num_upper"]).index_add(0, t["target"], prod)
    values = torch.cat([diag, upper, upper]).index_select(0, t["gather"])
    return sparse_coo(t["indices"], values, (nv, nv))


def laplace_beltrami(verts, topo) -> torch.Tensor:
    """The Laplace-Beltrami stiffness ``L = Re(G^* M_z^{-1} G)`` (thesis 4.2).

    Real, symmetric, positive semi-definite, constants in its kernel; acts on the 2-ring.
    On closed meshes ``G^* M_z^{-1} G`` is real; with a boundary its imaginary part is the
    antisymmetric form ``int grad g x grad f`` (a boundary integral), and ``L`` is the real
    part, the Dirichlet form ``int grad g . grad f``.
    Pair it with :func:`vertex_mass` (full) for the generalized eigenproblem ``L f = lambda M_v f``.

    Returns
    -------
    (V, V) real sparse tensor.
    """
    verts, topo, geom, signs = _prepare(verts, topo)
    g = _pattern(topo, "EV").assemble(_gradient_values(geom, signs))
    return _laplace_beltrami_from(g.values(), _mass_values(geom, topo), topo)


def vertex_mass(verts, topo, lumped: bool = False) -> torch.Tensor:
    """The P1 vertex mass matrix ``M_v``: full FEM (default) or lumped (``A/3`` per face).

    Returns
    -------
    (V, V) real sparse tensor (diagonal when ``lumped``).
    """
    verts, topo, geom, _ = _prepare(verts, topo)
    return _vertex_mass_from(geom, topo, lumped)


def _vertex_mass_from(geom: FaceGeometry, topo: Topology, lumped: bool) -> torch.Tensor:
    faces = topo.faces.to(geom.area.device)
    if lumped:
        third = (geom.area / 3)[:, None].expand(-1, 3)
        return diagonal(geom.area.new_zeros(topo.num_vertices).index_add(0, faces.flatten(), third.flatten()))
    eye = torch.as_tensor(~OFF_DIAGONAL, dtype=geom.area.dtype, device=geom.area.device)
    vals = geom.area[:, None] * (1 + eye) / 12
    return _pattern(topo, "VV").assemble(vals.flatten())


def covariant_derivative(verts, topo, w) -> torch.Tensor:
    """The covariant derivative ``D_w`` along the edge field ``w`` (thesis 5.1, A.5).

    ``M_z x = D_w z`` gives the edge field ``x`` of ``nabla_w psi``; per face,

    .. math::  (D_w)_{ab} \\mathrel{+}= -\\delta_b \\frac{|e_b|}{3}
               \\operatorname{Im}(w_a r_{ab})\\, r_{ba}

    including ``a = b`` (``r_aa = 1``), whose contributions cancel on interior edges and
    leave the boundary diagonal. Real-linear (not complex-linear) in ``w``.

    Parameters
    ----------
    w : (E,) complex tensor (a real tensor is taken as having zero imaginary part)

    Returns
    -------
    (E, E) complex sparse tensor.
    """
    verts, topo, geom, signs = _prepare(verts, topo)
    w = _edge_field(w, topo, verts, name="w")
    if w.dim() != 1:
        raise ValueError(f"w must have shape (E,), got {tuple(w.shape)}")
    return _covariant_from(geom, signs, topo, w)


def _covariant_from(geom, signs, topo, w) -> torch.Tensor:
    w_pairs = w[pair_columns(topo.face_edges.to(w.device), "a")]
    return _pattern(topo, "EE").assemble_pairs(_covariant_values(geom, signs, w_pairs))


def cotan_laplacian(verts, topo) -> torch.Tensor:
    """The cotangent Laplacian, as a positive semi-definite stiffness matrix (for comparison).

    .. math::  C_{ij} = -\\tfrac12 (\\cot \\alpha_{ij} + \\cot \\beta_{ij}), \\quad C_{ii} = -\\sum_j C_{ij}

    Returns
    -------
    (V, V) real sparse tensor.
    """
    verts, topo, geom, _ = _prepare(verts, topo)
    cot = geom.cotangents
    off = torch.as_tensor(OFF_DIAGONAL, device=cot.device)
    diag = 0.5 * (cot.sum(1, keepdim=True) - pair_columns(cot, "a"))
    vals = torch.where(off, -0.5 * pair_columns(cot, "c"), diag)
    return _pattern(topo, "VV").assemble(vals.flatten())

