r"""The upwind transport operator of edge-based fields and its time integration.

The thesis' covariant derivative ``D_w`` (:func:`torch_edgevf.covariant_derivative`) is
the Galerkin form :math:`(D_w)_{ab} = \sum_T \int_T \bar\psi_a \nabla_w \psi_b` taken face
by face.  The Crouzeix-Raviart basis fields jump across edges (they are continuous only at
the midpoints) and the face-by-face form ignores those jumps.  Integrating by parts in each
face, its Hermitian part is the edge term
:math:`\tfrac12 \sum_T \int_{\partial T} (w \cdot \nu) \bar\psi_a \psi_b` minus half the
divergence of ``w``: as large as the operator itself and indefinite, so the semi-discrete
transport ``M_z dz/dt = D_w z`` has growing modes.  Dropping the Hermitian part is not
consistent either: the jump terms that the face-by-face form leaves out have a skew-Hermitian
part too, and it is part of the transport.

The discontinuous-Galerkin form with the upwind flux, in the same basis, restores both:

.. math::
    A_w = D_w - J_w - K_w - \tfrac12 B_w - U_w, \quad
    (J_w)_{ab} = \sum_e \int_e \{w\cdot\nu\}\,\lbrack\psi_b\rbrack\,\{\bar\psi_a\}, \quad
    (K_w)_{ab} = \tfrac12 \sum_e \int_e \lbrack w\cdot\nu\rbrack\,\{\bar\psi_a \psi_b\}, \quad
    (U_w)_{ab} = \sum_e \int_e \tfrac12 |w\cdot\nu|\,\lbrack\bar\psi_a\rbrack\lbrack\psi_b\rbrack,

summed over the interior edges ``e`` (unit normal ``nu``, jump ``[.]`` and average
``{.}`` across the edge, in the common frame of the edge: its two faces unfold flat onto
it, so the transport coefficients ``r`` give the traces of the basis fields there), and
``B_w`` the flux term :math:`\int_e (w\cdot\nu)\bar\psi_a\psi_b` of ``D_w`` on the
boundary edges.  ``w`` is the piecewise linear interpolant of its edge values, so
``w . nu`` is linear along an edge and differs between its two faces away from the
midpoint.  ``U_w`` is the upwind penalty, Hermitian positive semi-definite: it damps the
jumps of the field, which are ``O(h)`` for smooth fields, so its dissipation vanishes with
the mesh size; on a boundary edge it adds
:math:`\tfrac12 |w_e\cdot\nu| \int_e \bar\psi_a\psi_b` (the upwind flux with no inflow
data: where ``w`` leaves the mesh the pattern, which moves against ``w``, enters as zero;
for a ``w`` tangent to the boundary the boundary terms vanish with the mesh size).  Then

.. math::  A_w + A_w^H = 2\Delta_w - 2U_w, \qquad
    \Delta_w = -\tfrac12 \operatorname{diag}\Big(\sum_{T \ni e} \tfrac{A_T}{3}
    \operatorname{div}_T w\Big),

exactly: the ``M_z``-norm of a solution of ``M_z dz/dt = A_w z`` changes only as the
divergence of ``w`` says (for a divergence-free ``w`` it never grows), while the scheme is
consistent, with errors of second order in the mesh size on smooth fields
(``benchmarks/results/transport_full_turn_n.md``).  For ``n``-direction fields the traces
use ``r^n`` (the representation vectors), the fluxes ``w``.

Measured alternatives: the skew-Hermitian part of ``D_w`` alone keeps the norm but is
inconsistent (relative error 1.44 after a full turn along the sphere's rotation at any
resolution); projecting ``D_w - J_w`` with a constant flux per edge on its skew-Hermitian
part is inconsistent near the zeros of ``w`` (a 4% error at the poles of the rotation that
does not decrease with refinement): the linear variation of ``w . nu`` along the edges
(``K_w`` and the linear part of ``J_w``) is needed.  Without ``U_w`` (the central flux)
the norm is kept but the dispersion of the unresolved scales is not damped: errors 3 to 4x
larger after a full turn at icosphere level 4.

Time integration
----------------
Explicit polynomial steps :math:`y \leftarrow p(\Delta t\,\tilde K)\,y` on the
``M_z``-symmetrized generator :math:`\tilde K = M_z^{-1/2} A M_z^{-1/2}`, a sparse product
per degree, no factorization.  The numerical range of :math:`\tilde K` lies in the rectangle
:math:`[-\lambda_{\max}(\tilde U), 0] \times i[-\rho(\tilde S), \rho(\tilde S)]`
(:math:`\tilde S` the skew part), both bounds estimated by Lanczos.  Where :math:`|p| \le 1`
on :math:`\Delta t` times that rectangle, :math:`\|p(\Delta t \tilde K)^N\| \le 1 + \sqrt 2`
for every ``N`` (Crouzeix's bound on the numerical range): the steps never grow the field.
The largest such :math:`\Delta t` is found by bisection on the sampled boundary; the step
taken is 5% below it, where :math:`|p| \le 1` holds on a sampling 50x denser as well.  The
rectangle's bounds are Lanczos estimates widened by their residuals and by at least 1%, so
the margin does not carry them; on the sphere's rotation (icosphere 4, a random field, two
turns) the steps first grow the field at 1.2 times the rectangle's stable step.
Every polynomial agrees with the exponential to fourth order (``p(x) = 1 + x + ... + x^4/24
+ ...``), so the steps are fourth-order accurate; the candidates are the classical
Runge-Kutta polynomial (degree 4) and degree-8 polynomials whose higher coefficients
maximize the stable rectangle for an aspect ratio :math:`\lambda_{\max}(\tilde U) / \rho`
of 0.5, 1, 1.7 or 3 (a linear program on the rectangle's boundary).  The integrator takes
the candidate with the largest stable step per sparse product for the operator's own
rectangle, with a 5% margin: the step count follows from ``|w|``, ``t`` and ``h``.  On the
sphere's rotation field (aspect ratio 1.65) the degree-8 polynomial takes 1.5x fewer sparse
products than the classical Runge-Kutta method.  The steps run on the edges renumbered in
the reverse Cuthill-McKee order of the operator's pattern, so that each sparse product reads
its input nearly in order whatever the numbering of the mesh; the parts ``P`` and ``U`` share
one pattern, converted once, and the upwind flux cancels the downwind couplings of
``s P - U`` exactly (the steps' matrix keeps 69% of that pattern on the sphere's rotation).
"""

from __future__ import annotations

import math
import weakref

import numpy as np
import scipy.sparse as sp
import torch
from scipy.linalg import eigh_tridiagonal
from scipy.linalg.blas import get_blas_funcs
from scipy.sparse.csgraph import reverse_cuthill_mckee

try:  # the CSR kernel that accumulates into its output (SciPy's own, used by csr @ vector)
    from scipy.sparse._sparsetools import csr_matvec as _csr_matvec
except ImportError:  # pragma: no cover - a SciPy without it: plain products
    _csr_matvec = None

from ..mesh.geometry import int_power, pair_transport
from ..operators.kernels import covariant_from, mass_values, prepare

__all__ = ["UpwindOperator", "upwind_parts"]

#: Safety factor on the largest stable step.
STEP_MARGIN = 0.95

_RK4 = (1.0, 1.0, 1 / 2, 1 / 6, 1 / 24)
#: The candidate step polynomials, by their coefficients ``c_0, c_1, ...`` (module
#: docstring): the classical Runge-Kutta polynomial and the degree-8 polynomials for the
#: aspect ratios 0.5, 1, 1.7 and 3 of the numerical-range rectangle.
STEP_POLYNOMIALS: tuple[tuple[float, ...], ...] = (
    _RK4,
    _RK4 + (0.0070978648523860755, 0.0010372592730561064, 8.54608350325072e-05, 6.6622205552201155e-06),
    _RK4 + (0.007569288700600565, 0.0010220867467816753, 8.755521146688918e-05, 4.161412161004237e-06),
    _RK4 + (0.007514041105196208, 0.0009077848203738264, 6.47373025944663e-05, 2.1003926724332285e-06),
    _RK4 + (0.007043406204139782, 0.0007143301161838981, 3.8749385631719026e-05, 8.678120462794387e-07),
)


def to_numpy(x: torch.Tensor) -> np.ndarray:
    """Detached NumPy copy of ``x`` (on the CPU, conjugation resolved)."""
    return x.detach().cpu().resolve_conj().resolve_neg().numpy()


def from_numpy(x: np.ndarray, like: torch.Tensor, dtype: torch.dtype | None = None) -> torch.Tensor:
    """Tensor from a NumPy array on the device of ``like`` with ``dtype``."""
    return torch.from_numpy(np.ascontiguousarray(x)).to(device=like.device, dtype=dtype)


# per topology: the coalescing plans of the operators' patterns (sorted unique indices and
# the position of every contribution among them), which depend on the faces alone
_PLANS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _coo(topo, key: str, rows: list, cols: list, vals: list, n: int) -> torch.Tensor:
    """The coalesced ``(n, n)`` sum of the contributions, by a cached plan (one scatter)."""
    r, c = torch.cat(rows), torch.cat(cols)
    plans = _PLANS.setdefault(topo, {})
    plan = plans.get(key)
    if plan is None or plan[1].shape[0] != r.shape[0]:
        keys = (r * n + c).cpu().numpy()
        unique, inverse = np.unique(keys, return_inverse=True)
        idx = torch.from_numpy(np.stack([unique // n, unique % n]))
        plan = (idx, torch.from_numpy(inverse.reshape(-1)))
        plans[key] = plan
    idx, inverse = plan
    v = torch.cat(vals)
    out = v.new_zeros(idx.shape[1]).index_add(0, inverse.to(v.device), v)
    return torch.sparse_coo_tensor(idx.to(v.device), out, (n, n), is_coalesced=True, check_invariants=False)


def upwind_parts(verts, topo, w: torch.Tensor, n: int = 1) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The odd and even parts of the upwind transport operator, and the mass.

    ``A_{s w} = s P - U`` for ``s = +-1``: ``P = D_w - J_w - K_w - B_w / 2`` changes sign
    with ``w``, ``U = U_w`` (Hermitian, positive semi-definite) does not.  Differentiable
    in the positions and in ``w``.

    Returns
    -------
    P, U : (E, E) complex sparse tensors (coalesced)
    mass : (E,) the diagonal of ``M_z``
    """
    verts, topo, geom, signs = prepare(verts, topo)
    dev = geom.lengths.device
    ne = topo.num_edges
    fe = topo.face_edges.to(dev)
    r1 = pair_transport(geom, signs, 1)
    rn = r1 if n == 1 else int_power(r1, n)  # (sigma e^{i alpha})^n: what pair_transport(.., n) gives
    D = covariant_from(geom, signs, topo, w, n, transports=(r1, rn)).coalesce()
    rows, cols, vals = [D.indices()[0]], [D.indices()[1]], [D.values()]
    cdtype = D.values().dtype
    # per side (face f, corner k; edge e = fe[f, k]): the traces of the two wing fields on e,
    # eps (1 - 2s) r_ae^n with s running along the frame of e; the outward flux w . nu of w's
    # midpoint value; and lam, the coefficient of (1 - 2s) in the face's own w_h . nu on e
    r1, rn = r1.reshape(-1, 3, 3), rn.reshape(-1, 3, 3)
    wing = torch.tensor([[1, 2], [2, 0], [0, 1]], device=dev)  # corners k + 1, k + 2
    wing_eps = torch.stack([-signs, signs], 2)  # (F, 3, 2)
    corners = torch.arange(3, device=dev)
    fw = fe[:, wing]  # (F, 3, 2) edge ids of the wings
    trace_n = wing_eps * rn[:, wing, corners[:, None]]  # r[f, wing, k]
    trace_1 = wing_eps * r1[:, wing, corners[:, None]]
    flux = -signs * w.imag[fe]  # (F, 3)
    lam = -signs * (trace_1 * w[fw]).sum(2).imag
    length = geom.lengths
    sc = torch.from_numpy(np.asarray(topo.side_corners(), dtype=np.int64)).to(dev)
    inner = (sc >= 0).all(1)

    def side(corner):
        f, k = corner // 3, corner % 3
        return fw[f, k], trace_n[f, k], flux[f, k], lam[f, k], length[f, k]

    urows, ucols, uvals = [], [], []
    edges = torch.nonzero(inner).flatten()
    if edges.numel():
        ids0, c0, fl0, lam0, l_e = side(sc[edges, 0])
        ids1, c1, fl1, lam1, _ = side(sc[edges, 1])
        ids = torch.cat([ids0, ids1], 1)  # (Ei, 4): the wings of side 0, then side 1
        c = torch.cat([c0, c1], 1)
        fl = torch.stack([fl0, fl0, fl1, fl1], 1)
        outer = c.conj()[:, :, None] * c[:, None, :] * (l_e / 6)[:, None, None]
        br = ids[:, :, None].expand(-1, 4, 4).flatten()
        bc = ids[:, None, :].expand(-1, 4, 4).flatten()
        # J: int (w . nu)[psi_b]{conj psi_a}, the central flux with w's midpoint value
        rows.append(br)
        cols.append(bc)
        vals.append(-(outer * fl[:, None, :]).flatten())
        # the linear part of w . nu: J_c - J at (e, b) and K at (e, b), (b, e)
        dl = torch.stack([lam0 - lam1, lam0 - lam1, lam1 - lam0, lam1 - lam0], 1)
        g = (lam0 + lam1)[:, None]
        e_col = edges[:, None].expand(-1, 4).flatten()
        at_e = (l_e[:, None] * c * (dl / 6 + g / 12)).flatten()
        at_b = (l_e[:, None] * c.conj() * (g / 12)).flatten()
        rows += [e_col, ids.flatten()]
        cols += [ids.flatten(), e_col]
        vals += [-at_e, -at_b]
        # U: int |w . nu| / 2 [conj psi_a][psi_b]
        sigma = torch.tensor([1.0, 1.0, -1.0, -1.0], dtype=flux.dtype, device=dev)
        urows.append(br)
        ucols.append(bc)
        uvals.append((outer * ((sigma[:, None] * sigma[None, :])[None] * fl0.abs()[:, None, None])).flatten())
    # boundary edges: P drops the Hermitian half of D's flux term int (w_h . nu) conj(psi_a) psi_b
    # (w_h . nu = m + lam (1 - 2s) on the edge); U gets |m| / 2 int |psi|^2, so that the
    # upwind flux on the boundary is the face's own trace where w enters the mesh and zero
    # where it leaves (no inflow data for the pattern, which moves against w)
    edges = torch.nonzero(~inner).flatten()
    if edges.numel():
        corner = sc[edges].max(1).values
        ids, c, m, lb, l_e = side(corner)
        outer = c.conj()[:, :, None] * c[:, None, :] * (l_e / 3)[:, None, None]
        wr, wc = ids[:, :, None].expand(-1, 2, 2).flatten(), ids[:, None, :].expand(-1, 2, 2).flatten()
        rows += [wr, edges]
        cols += [wc, edges]
        vals += [-(outer * (m / 2)[:, None, None]).flatten(), -(l_e * m / 2).to(cdtype)]
        e_col = edges[:, None].expand(-1, 2).flatten()
        at_e = (l_e * lb / 6)[:, None] * c
        rows += [e_col, ids.flatten()]
        cols += [ids.flatten(), e_col]
        vals += [-at_e.flatten(), -at_e.conj().flatten()]
        urows += [wr, edges]
        ucols += [wc, edges]
        uvals += [(outer * (m.abs() / 2)[:, None, None]).flatten(), (l_e * m.abs() / 2).to(cdtype)]
    if urows:
        U = _coo(topo, "U", urows, ucols, [u.to(cdtype) for u in uvals], ne)
    else:
        empty = torch.zeros((2, 0), dtype=torch.long, device=dev)
        U = torch.sparse_coo_tensor(empty, D.values()[:0], (ne, ne), check_invariants=False).coalesce()
    P = _coo(topo, "P", rows, cols, [v.to(cdtype) for v in vals], ne)
    return P, U, mass_values(geom, topo)


def _csr(a: torch.Tensor, scale: np.ndarray) -> sp.csr_matrix:
    """``diag(scale) a diag(scale)`` as a SciPy CSR matrix (complex128)."""
    idx = a.indices().detach().cpu().numpy()
    v = to_numpy(a.values()).astype(np.complex128) * scale[idx[0]] * scale[idx[1]]
    return sp.csr_matrix((v, (idx[0], idx[1])), shape=tuple(a.shape))


def _ordered_pair(P: torch.Tensor, U: torch.Tensor, scale: np.ndarray):
    """``diag(scale) X diag(scale)`` for ``X = P, U`` as CSR matrices in the reverse
    Cuthill-McKee order of their pattern, and that order.

    ``P`` and ``U`` of :func:`upwind_parts` have one pattern (coalesced, sorted by rows): it
    is converted once, and both matrices are gathers of their values into it."""
    n = P.shape[0]
    if U._nnz() != P._nnz() or not torch.equal(U.indices(), P.indices()):
        P_csr, U_csr = _csr(P, scale), _csr(U, scale)
        order = reverse_cuthill_mckee((P_csr + U_csr).tocsr(), symmetric_mode=True).astype(np.int64)
        return P_csr[order][:, order].tocsr(), U_csr[order][:, order].tocsr(), order
    rows, cols = P.indices().detach().cpu().numpy()
    indptr = np.zeros(n + 1, dtype=np.int32)
    np.cumsum(np.bincount(rows, minlength=n), out=indptr[1:])
    ones = np.ones(rows.shape[0], dtype=np.int8)
    pattern = sp.csr_matrix((ones, cols.astype(np.int32), indptr), shape=(n, n))
    order = reverse_cuthill_mckee(pattern, symmetric_mode=True).astype(np.int64)
    unorder = np.empty_like(order)
    unorder[order] = np.arange(n)
    # the position of every entry in the reordered CSR (1-based: a stored 0 could be dropped)
    where = sp.csr_matrix((np.arange(1.0, rows.shape[0] + 1), (unorder[rows], unorder[cols])), shape=(n, n))
    gather = where.data.astype(np.int64) - 1
    weight = (scale[rows] * scale[cols])[gather]

    def ordered(a: torch.Tensor) -> sp.csr_matrix:
        data = to_numpy(a.values()).astype(np.complex128)[gather] * weight
        return sp.csr_matrix((data, where.indices, where.indptr), shape=(n, n))

    return ordered(P), ordered(U), order


def _matvec_add(a: sp.csr_matrix, x: np.ndarray, out: np.ndarray) -> None:
    """``out += a @ x`` in place: SciPy's CSR kernel accumulates into its output, which
    saves the zeroed result and the separate addition of each Horner step."""
    if _csr_matvec is not None and x.ndim == 1 and a.dtype == x.dtype == out.dtype:
        _csr_matvec(a.shape[0], a.shape[1], a.indptr, a.indices, a.data, x, out)
    else:
        out += a @ x


def _apply_polynomial(coef, hK: sp.csr_matrix, y: np.ndarray) -> np.ndarray:
    """``p(hK) y`` for ``p`` of ``coef`` by Horner's rule, one sparse product per degree."""
    y = np.ascontiguousarray(y, dtype=hK.dtype)
    u = coef[-1] * y
    for c in coef[-2::-1]:
        nxt = np.multiply(y, c)
        _matvec_add(hK, u, nxt)
        u = nxt
    return u


def stable_scale(coef, s: float, h: float) -> float:
    """The largest ``c`` with ``|p| <= 1`` on ``c ([-h, 0] x i[-s, s])`` (``p`` of ``coef``)."""
    if s <= 0 and h <= 0:
        return math.inf
    ys = np.linspace(0.0, s, 257)
    xs = np.linspace(-h, 0.0, 257)
    pts = np.concatenate([1j * ys, -h + 1j * ys, xs + 1j * s])  # p has real coefficients
    lo, hi = 0.0, 2.0 * len(coef) / max(s, h)
    for _ in range(32):
        c = 0.5 * (lo + hi)
        if np.all(np.abs(np.polyval(coef[::-1], c * pts)) <= 1 + 1e-12):
            lo = c
        else:
            hi = c
    return lo


def _best_polynomial(s: float, h: float) -> tuple[tuple[float, ...], float]:
    """The step polynomial with the largest stable step per sparse product, and that step."""
    scales = [stable_scale(p, s, h) for p in STEP_POLYNOMIALS]
    if not all(math.isfinite(c) for c in scales):
        return _RK4, math.inf
    best = max(range(len(scales)), key=lambda i: scales[i] / (len(STEP_POLYNOMIALS[i]) - 1))
    return STEP_POLYNOMIALS[best], scales[best]


#: Lanczos steps for the bounds of the numerical range.
LANCZOS_STEPS = 20


def _spectral_bounds(a: sp.csr_matrix, steps: int = LANCZOS_STEPS) -> tuple[float, float]:
    """Lower and upper bounds of the spectrum of the Hermitian ``a``: ``steps`` Lanczos steps
    from a fixed start vector, the extreme Ritz values widened by their residuals
    ``|beta_k s_k|`` and by at least 1% (Zhou and Li's bounds, safe in practice; the steps'
    5% margin covers the rest), clipped to the Gershgorin bound.  The vector updates are
    BLAS calls in place: at 20 steps on 30,000 edges they would otherwise cost as much as
    the sparse products."""
    if a.nnz == 0:
        return 0.0, 0.0
    row_sums = np.add.reduceat(np.abs(a.data), a.indptr[:-1][np.diff(a.indptr) > 0])
    bound = float(row_sums.max())  # Gershgorin
    axpy, nrm2, scal = get_blas_funcs(("axpy", "nrm2", "scal"), dtype=a.dtype)
    v = (np.cos(np.arange(a.shape[0]) * 0.618) + 1.0).astype(a.dtype)
    v = scal(1.0 / nrm2(v), v)
    previous, u = np.zeros_like(v), np.empty_like(v)
    b = 0.0
    alpha, beta = [], []
    for _ in range(min(steps, a.shape[0])):
        u[:] = 0
        _matvec_add(a, v, u)
        al = float(np.vdot(v, u).real)
        axpy(v, u, a=-al)
        axpy(previous, u, a=-b)
        b = float(nrm2(u))
        alpha.append(al)
        beta.append(b)
        if b <= 1e-12 * max(abs(al), 1e-300):
            break
        previous, v, u = v, scal(1.0 / b, u), previous  # u's buffer becomes the new v
    theta, s = eigh_tridiagonal(np.array(alpha), np.array(beta[:-1]))
    residual = np.abs(beta[-1] * s[-1])
    lo = theta[0] - max(residual[0], 0.01 * abs(theta[0]))
    hi = theta[-1] + max(residual[-1], 0.01 * abs(theta[-1]))
    return max(lo, -bound), min(hi, bound)


class UpwindOperator:
    """``M_z dz/dt = A_{sw} z`` integrated by polynomial steps on the ``M_z``-symmetrized generator.

    Parameters
    ----------
    P, U : (E, E) complex sparse tensors (:func:`upwind_parts`)
    mass : (E,) diagonal of ``M_z``
    """

    def __init__(self, P: torch.Tensor, U: torch.Tensor, mass: torch.Tensor):
        m = to_numpy(mass).astype(np.float64)
        scale = 1.0 / np.sqrt(m)
        # the steps run in the reverse Cuthill-McKee order of the operator's pattern: the
        # sparse products then read their input vector nearly in order (module docstring)
        self._P, self._U, self._order = _ordered_pair(P, U, scale)
        self._unorder = np.empty_like(self._order)
        self._unorder[self._order] = np.arange(self._order.shape[0])
        self.sqrt_mass = np.sqrt(m)[self._order]
        self._K: dict[int, sp.csr_matrix] = {}
        self._KH: dict[int, sp.csr_matrix] = {}
        skew = 0.5 * (self._P - self._P.conj().T)
        lo, hi = _spectral_bounds((1j * skew).tocsr())
        self.skew_radius = max(-lo, hi)
        # the top of U's spectrum is well separated: 10 steps bound it within 0.3% of 20
        # steps' bound on icosphere 5 (1.2% above the true value), the skew part needs 20
        self.damping = max(_spectral_bounds(self._U, LANCZOS_STEPS // 2)[1], 0.0)
        self.coefficients, stable = _best_polynomial(self.skew_radius, self.damping)
        self.max_step = STEP_MARGIN * stable

    def generator(self, sign: int) -> sp.csr_matrix:
        if sign not in self._K:
            P, U = self._P, self._U
            if np.array_equal(P.indptr, U.indptr) and np.array_equal(P.indices, U.indices):  # no sparse sum
                K = sp.csr_matrix((sign * P.data - U.data, P.indices.copy(), P.indptr.copy()), shape=P.shape)
                K.eliminate_zeros()  # the upwind flux cancels the downwind couplings exactly
                self._K[sign] = K
            else:
                self._K[sign] = (sign * P - U).tocsr()
        return self._K[sign]

    def adjoint(self, sign: int) -> sp.csr_matrix:
        if sign not in self._KH:
            self._KH[sign] = self.generator(sign).conj().T.tocsr()
        return self._KH[sign]

    def num_steps(self, t: float) -> int:
        """The number of steps for time ``|t|``."""
        if t == 0 or not math.isfinite(self.max_step):
            return 1
        return max(1, math.ceil(abs(t) / self.max_step))

    def _inward(self, z: np.ndarray, power: int) -> np.ndarray:
        """``M^(power/2) z`` in the operator's edge order, from ``z`` in the caller's."""
        s = self.sqrt_mass if power > 0 else 1.0 / self.sqrt_mass
        z = z[self._order]
        return z * (s if z.ndim == 1 else s[:, None])

    def _outward(self, y: np.ndarray, power: int) -> np.ndarray:
        """``M^(power/2) y`` in the caller's edge order, from ``y`` in the operator's."""
        s = self.sqrt_mass if power > 0 else 1.0 / self.sqrt_mass
        return (y * (s if y.ndim == 1 else s[:, None]))[self._unorder]

    def propagate(
        self, z: np.ndarray, t: float, sign: int, adjoint: bool = False
    ) -> tuple[np.ndarray, np.ndarray]:
        """``R(h K)^N z`` (in ``z`` variables) and the state before the last step."""
        K = self.adjoint(sign) if adjoint else self.generator(sign)
        steps = self.num_steps(t)
        hK = K * (abs(t) / steps)
        y = self._inward(z.astype(np.complex128), +1 if not adjoint else -1)
        prev = y
        for _ in range(steps):
            prev = y
            y = _apply_polynomial(self.coefficients, hK, y)
        back = -1 if not adjoint else +1
        return self._outward(y, back), self._outward(prev, back)

    def rate(self, prev: np.ndarray, t: float, sign: int) -> np.ndarray:
        """``d/d|t|`` of ``R(|t| K / N)^N z0`` (``N`` fixed), from the state before the last step."""
        K = self.generator(sign)
        h = abs(t) / self.num_steps(t)
        y = self._inward(prev, +1)
        hK = K * h
        derivative = [k * c for k, c in enumerate(self.coefficients)][1:]  # d/dh p(hK) y = K p'(hK) y
        return self._outward(K @ _apply_polynomial(derivative, hK, y), -1)


class _Propagate(torch.autograd.Function):
    @staticmethod
    def forward(ctx, z0, t, op: UpwindOperator, sign: int):
        tf = float(t)
        y, prev = op.propagate(to_numpy(z0), tf, sign)
        real = z0.dtype == torch.float32
        dtype = z0.dtype if z0.is_complex() else (torch.complex64 if real else torch.complex128)
        ctx.op, ctx.sign, ctx.tf = op, sign, tf
        ctx.z0_complex, ctx.z0_dtype = z0.is_complex(), z0.dtype
        ctx.prev = prev if ctx.needs_input_grad[1] else None
        ctx.save_for_backward(t)
        return from_numpy(y, z0, dtype)

    @staticmethod
    def backward(ctx, g):
        (t,) = ctx.saved_tensors
        op, sign, tf = ctx.op, ctx.sign, ctx.tf
        g_np = to_numpy(g)
        grad_z0 = grad_t = None
        if ctx.needs_input_grad[0]:
            gz, _ = op.propagate(g_np, tf, sign, adjoint=True)
            gz_t = from_numpy(gz, g, g.dtype)
            grad_z0 = gz_t if ctx.z0_complex else gz_t.real.to(ctx.z0_dtype)
        if ctx.needs_input_grad[1]:
            rate = op.rate(ctx.prev, tf, sign) * (1.0 if tf >= 0 else -1.0)
            grad_t = torch.tensor(float(np.real(np.vdot(g_np, rate))), dtype=t.dtype, device=t.device)
        return grad_z0, grad_t, None, None


def propagate(op: UpwindOperator, z0: torch.Tensor, t: torch.Tensor, sign: int) -> torch.Tensor:
    """``z(|t|)`` for ``M_z dz/dt = A_{sign w} z``, differentiable in ``z0`` and ``t``."""
    return _Propagate.apply(z0, t, op, sign)
