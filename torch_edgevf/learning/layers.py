"""Learning layers on complex edge features.

Features live on the edges of a mesh as complex numbers, one per channel: ``z`` of shape
``(E, C)`` is ``C`` tangent vector fields in the edge-based representation (the value at
each edge midpoint, in the frame of the edge oriented from its lower to its higher vertex
index; thesis 2.2). Every layer here is **gauge equivariant**: rotating the frame of an
edge (``z_e -> e^{i theta_e} z_e``, which is what a change of edge orientation does with
``theta_e = pi``) rotates its output the same way, or leaves it unchanged for the real
invariant readouts. Layers therefore give the same answer for any vertex numbering.

Every ``nn.Module`` is a thin wrapper over a function of this file (``LearnedDiffusion``
over :func:`spectral_diffusion` / :func:`implicit_diffusion`, ``ComplexLinear`` over
:func:`complex_linear`, ...); the tests pin each pair together.

==========================  ===========================================================
function / module           operation
==========================  ===========================================================
spectral_diffusion          ``z(t) = Phi diag(exp(-lambda t)) Phi^H M z`` (thesis 3.2)
implicit_diffusion          ``(M + t L)^{-1} M z`` (one implicit Euler step)
gradient_features           ``z = M_z^{-1} G f``: vertex scalars to edge vectors (4.2)
divergence_features         ``-M_v^{-1} G^* z = div + i curl`` per vertex (4.2, B.4)
complex_linear              ``z W``, ``W`` complex ``(C_in, C_out)``, no bias
modulus_relu                ``z relu(|z| + b) / |z|``
invariant_features          ``|z|`` and ``Re(z conj(z A))`` (real, gauge invariant)
pool_edges_to_vertices      weighted mean over the edges around each vertex
pool_edges_to_faces         weighted mean over the three edges of each face
pool_global                 weighted mean over each mesh of a batch
normalize_modulus           ``z / rms_M(z)`` per mesh and channel (scale normalisation)
dropout                     ``F.dropout`` with a faster CPU mask (the same masks)
==========================  ===========================================================

Sparse operators are torch sparse COO tensors (as returned by :mod:`torch_edgevf.operators`,
or block-diagonal ones from :func:`torch_edgevf.data.collate_meshes`); products with them
are written as gathers and ``index_add`` so that gradients reach both the features and
the operator values.
"""

from __future__ import annotations

import math
import numbers
import warnings
import weakref

import torch
import torch.nn.functional as F
from torch import nn

from .._dtypes import complex_dtype, real_dtype
from ..linalg import solve

__all__ = [
    "spectral_diffusion",
    "implicit_diffusion",
    "gradient_features",
    "divergence_features",
    "adjoint_on_basis",
    "complex_linear",
    "modulus_relu",
    "invariant_features",
    "pool_edges_to_vertices",
    "pool_edges_to_faces",
    "pool_global",
    "normalize_modulus",
    "positive_time",
    "MIN_TIME",
    "LearnedDiffusion",
    "GradientFeatures",
    "DivergenceFeatures",
    "ComplexLinear",
    "ModReLU",
    "InvariantReadout",
    "EdgePooling",
    "ModulusNorm",
    "dropout",
    "Dropout",
]


# --------------------------------------------------------------------------- checks


def _check_features(z, name: str = "z", complex_only: bool = False) -> torch.Tensor:
    if not isinstance(z, torch.Tensor):
        raise ValueError(f"{name} must be a torch tensor, got {type(z).__name__}")
    if z.dim() != 2:
        raise ValueError(f"{name} must have shape (N, C), got {tuple(z.shape)}")
    if complex_only and not z.is_complex():
        raise ValueError(f"{name} must be complex (edge vector features), got {z.dtype}")
    if not (z.is_complex() or z.is_floating_point()):
        raise ValueError(f"{name} must be a floating or complex tensor, got {z.dtype}")
    return z


def _check_sparse(A, name: str, rows: int | None = None, cols: int | None = None) -> torch.Tensor:
    if not isinstance(A, torch.Tensor) or A.layout != torch.sparse_coo or A.dim() != 2:
        raise ValueError(f"{name} must be a 2-D torch sparse COO tensor")
    if rows is not None and A.shape[0] != rows:
        raise ValueError(f"{name} has {A.shape[0]} rows, expected {rows}")
    if cols is not None and A.shape[1] != cols:
        raise ValueError(f"{name} has {A.shape[1]} columns, expected {cols}")
    return A if A.is_coalesced() else A.coalesce()


def _check_vector(m, n: int, name: str) -> torch.Tensor:
    if not isinstance(m, torch.Tensor) or m.dim() != 1 or m.shape[0] != n:
        shape = tuple(m.shape) if isinstance(m, torch.Tensor) else type(m).__name__
        raise ValueError(f"{name} must be a ({n},) tensor, got {shape}")
    if m.is_complex():
        raise ValueError(f"{name} must be real, got {m.dtype}")
    return m


#: CSR copies of ``A`` and ``A^H`` for the sparse operators multiplied by :func:`_spmm`,
#: kept as long as the operator itself
_CSR_CACHE: dict[int, tuple[torch.Tensor, torch.Tensor]] = {}


def _kept(cache: dict, key, tensors: tuple[torch.Tensor, ...], build):
    """``cache[key]``, made by ``build()`` at the first call and dropped as soon as one of
    ``tensors`` is freed (``key`` holds their ids, which Python reuses)."""
    out = cache.get(key)
    if out is None:
        out = cache[key] = build()
        for t in tensors:
            weakref.finalize(t, cache.pop, key, None)
    return out


def _csr_pair(A: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(A, A^H)`` in CSR layout, converted once per operator (``A`` coalesced COO)."""

    def convert():
        with warnings.catch_warnings():  # "sparse CSR support is in beta"
            warnings.simplefilter("ignore", UserWarning)
            AH = A.t().conj() if A.is_complex() else A.t()
            return (A.to_sparse_csr(), AH.coalesce().to_sparse_csr())

    return _kept(_CSR_CACHE, id(A), (A,), convert)


#: ``G^H Phi`` per pair of constant operators (see :func:`adjoint_on_basis`)
_BASIS_CACHE: dict[tuple[int, int], torch.Tensor] = {}


def adjoint_on_basis(G: torch.Tensor, evecs: torch.Tensor) -> torch.Tensor:
    r"""``G^H Phi`` (``(V, k)``): the adjoint of the gradient applied to each column of ``Phi``.

    For edge fields ``u = Phi c`` in the span of an ``M_z``-orthonormal basis ``Phi``
    (``(E, k)``), the divergence and curl ``-M_v^{-1} G^* u`` are ``-M_v^{-1} (G^H Phi) c``,
    and the coefficients of a gradient field, ``Phi^H M_z (M_z^{-1} G f)``, are
    ``(G^H Phi)^H f``: one dense ``(V, k)`` matrix replaces both sparse products. For a
    batch, ``G`` is block diagonal and ``Phi`` stacks the meshes' bases row-wise, so the
    rows of mesh ``b`` are ``G_b^H Phi_b``.

    When neither ``G`` nor ``evecs`` needs a gradient (precomputed operators), the
    product is computed once per pair of tensors and kept while both exist; otherwise it
    is computed at each call and differentiable in both.
    """
    if G.requires_grad or evecs.requires_grad:
        return _spmm(G, evecs, adjoint=True)
    return _kept(_BASIS_CACHE, (id(G), id(evecs)), (G, evecs), lambda: _spmm(G, evecs, adjoint=True))


class _ConstantSpmm(torch.autograd.Function):
    """``A @ x`` for a constant sparse ``A`` given as CSR ``A`` and ``A^H``; gradient ``A^H g``."""

    @staticmethod
    def forward(ctx, x, A, AH):
        ctx.AH = AH
        return A @ x

    @staticmethod
    def backward(ctx, g):
        return ctx.AH @ g, None, None


def _spmm(A: torch.Tensor, x: torch.Tensor, adjoint: bool = False) -> torch.Tensor:
    """``A @ x`` (or ``A^H @ x``) for a coalesced sparse ``A`` and a dense ``(N, C)`` ``x``.

    Where the values of ``A`` need a gradient, written as a gather and an ``index_add``
    so that gradients reach both ``x`` and the values, for real and complex dtypes
    alike; otherwise a product with CSR copies of ``A`` and ``A^H`` made once per
    operator (gradients reach ``x``; several times faster than the gather, and than a
    COO product, which converts and transposes at every call).
    """
    rows, cols = A.indices()
    vals = A.values()
    if not vals.requires_grad and vals.dtype == x.dtype and x.layout == torch.strided:
        A_csr, AH_csr = _csr_pair(A)
        if adjoint:
            A_csr, AH_csr = AH_csr, A_csr
        return _ConstantSpmm.apply(x.contiguous(), A_csr, AH_csr)
    if adjoint:
        rows, cols = cols, rows
        vals = vals.conj() if vals.is_complex() else vals
        n_out = A.shape[1]
    else:
        n_out = A.shape[0]
    dtype = torch.promote_types(vals.dtype, x.dtype)
    prod = vals.to(dtype)[:, None] * x.to(dtype)[cols]
    out = torch.zeros((n_out, x.shape[1]), dtype=dtype, device=x.device)
    return out.index_add(0, rows, prod)


#: smallest diffusion time of ``positive_time(..., "clamp")``
MIN_TIME = 1e-8


def positive_time(raw: torch.Tensor, mode: str = "softplus") -> torch.Tensor:
    """Map parameters to positive diffusion times.

    ``"softplus"``: ``log(1 + e^raw)``; ``"abs"``: ``|raw|``; ``"clamp"``: ``raw`` itself,
    clamped at :data:`MIN_TIME` in value while its gradient passes unchanged (a
    straight-through clamp, as DiffusionNet clamps its times: the time moves at the
    optimiser's rate, which ``softplus`` slows down by ``sigmoid(raw)`` for small times).
    """
    if mode == "softplus":
        return F.softplus(raw)
    if mode == "abs":
        return raw.abs()
    if mode == "clamp":
        return raw + (raw.clamp_min(MIN_TIME) - raw).detach()
    raise ValueError(f"mode must be 'softplus', 'abs' or 'clamp', got {mode!r}")


def _inverse_softplus(t: torch.Tensor) -> torch.Tensor:
    return t + torch.log(-torch.expm1(-t))


# --------------------------------------------------------------------------- diffusion


def spectral_diffusion(z, evals, evecs, mass, times, offsets=None) -> torch.Tensor:
    r"""Heat diffusion in a truncated eigenbasis, one diffusion time per channel.

    .. math::  z(t) = \Phi \, \mathrm{diag}(e^{-\lambda t}) \, \Phi^H M z

    with :math:`(\lambda, \Phi)` the ``k`` smallest eigenpairs of :math:`(L, M)`,
    :math:`\Phi^H M \Phi = I` (thesis 3.2 with :math:`L = L_c`, :math:`M = M_z`; the same
    formula diffuses vertex scalars with a scalar Laplacian). The result is the
    projection of ``z`` on the span of :math:`\Phi`, diffused; at ``t = 0`` it is the
    projection itself. The projector :math:`\Phi\Phi^H M` does not depend on the phase
    or sign chosen for each eigenvector, nor on a rotation inside an eigenspace that is
    kept whole.

    Parameters
    ----------
    z : (N, C) real or complex tensor
        Features: edge fields (``N = E``) or vertex scalars (``N = V``).
    evals : (k,) real tensor, or (B, k) for a batch
    evecs : (N, k) tensor, ``M``-orthonormal columns; a batch stacks the meshes' bases
        row-wise, ``(sum N_b, k)``
    mass : (N,) real tensor, the diagonal of ``M``
    times : (C,) real tensor, ``>= 0``
    offsets : (B + 1,) int sequence or tensor, optional
        Row offsets of the meshes of a batch in ``z`` and ``evecs``.

    Returns
    -------
    (N, C) tensor with the dtype of ``z`` promoted with ``evecs``.
    """
    z = _check_features(z)
    n, c = z.shape
    if not isinstance(evecs, torch.Tensor) or evecs.dim() != 2 or evecs.shape[0] != n:
        raise ValueError(
            f"evecs must have shape ({n}, k), got "
            f"{tuple(evecs.shape) if isinstance(evecs, torch.Tensor) else type(evecs).__name__}"
        )
    k = evecs.shape[1]
    mass = _check_vector(mass, n, "mass")
    if not isinstance(times, torch.Tensor) or times.shape != (c,) or times.is_complex():
        raise ValueError(
            f"times must be a real ({c},) tensor (one per channel), got "
            f"{tuple(times.shape) if isinstance(times, torch.Tensor) else type(times).__name__}"
        )
    if not isinstance(evals, torch.Tensor) or evals.is_complex():
        raise ValueError("evals must be a real tensor")
    x = z * mass[:, None].to(real_dtype(z.dtype))
    if offsets is None:
        if evals.shape != (k,):
            raise ValueError(f"evals must have shape ({k},), got {tuple(evals.shape)}")
        coeffs = evecs.conj().transpose(0, 1).to(torch.promote_types(evecs.dtype, x.dtype)) @ x.to(
            torch.promote_types(evecs.dtype, x.dtype)
        )
        coeffs = coeffs * torch.exp(-evals[:, None] * times[None, :])
        return evecs.to(coeffs.dtype) @ coeffs
    offsets = [int(o) for o in offsets]
    nb = len(offsets) - 1
    if nb < 1 or offsets[0] != 0 or offsets[-1] != n or any(b < a for a, b in zip(offsets, offsets[1:])):
        raise ValueError(f"offsets must rise from 0 to N = {n}, got {offsets}")
    if evals.shape != (nb, k):
        raise ValueError(
            f"evals must have shape ({nb}, {k}) for a batch of {nb} meshes, got {tuple(evals.shape)}"
        )
    dtype = torch.promote_types(evecs.dtype, x.dtype)
    out = []
    for b in range(nb):
        phi = evecs[offsets[b] : offsets[b + 1]].to(dtype)
        coeffs = phi.conj().transpose(0, 1) @ x[offsets[b] : offsets[b + 1]].to(dtype)
        coeffs = coeffs * torch.exp(-evals[b][:, None] * times[None, :])
        out.append(phi @ coeffs)
    return out[0] if nb == 1 else torch.cat(out, dim=0)


def implicit_diffusion(z, L, mass, times) -> torch.Tensor:
    r"""Heat diffusion by one implicit Euler step, one time per channel.

    .. math::  z(t) = (M + t L)^{-1} M z

    solved with the differentiable sparse :func:`~torch_edgevf.linalg.solve` (gradients
    reach ``z``, ``times``, the values of ``L`` and ``mass``). One factorisation per
    channel; for a batch pass the block-diagonal ``L`` of the batch.

    Parameters
    ----------
    z : (N, C) real or complex tensor
    L : (N, N) sparse tensor, Hermitian positive semidefinite with a stored diagonal
    mass : (N,) real tensor
    times : (C,) real tensor, ``> 0``

    Returns
    -------
    (N, C) tensor.
    """
    z = _check_features(z)
    n, c = z.shape
    L = _check_sparse(L, "L", n, n)
    mass = _check_vector(mass, n, "mass")
    if not isinstance(times, torch.Tensor) or times.shape != (c,) or times.is_complex():
        raise ValueError(f"times must be a real ({c},) tensor (one per channel)")
    rows, cols = L.indices()
    diag = rows == cols
    if int(diag.sum()) != n:
        raise ValueError("L must store every diagonal entry (its pattern lacks some)")
    vals = L.values()
    m_on_pattern = torch.zeros_like(vals.real if vals.is_complex() else vals)
    m_on_pattern = m_on_pattern.index_put(
        (torch.nonzero(diag).flatten(),), mass[rows[diag]].to(m_on_pattern.dtype)
    )
    rhs = z * mass[:, None].to(real_dtype(z.dtype))
    if vals.is_complex() and not rhs.is_complex():
        rhs = rhs.to(vals.dtype)
    out = []
    for ch in range(c):
        a_vals = times[ch].to(m_on_pattern.dtype) * vals + m_on_pattern
        A = torch.sparse_coo_tensor(L.indices(), a_vals, L.shape, is_coalesced=True, check_invariants=False)
        out.append(solve(A, rhs[:, ch], hermitian=True))
    return torch.stack(out, dim=1)


class LearnedDiffusion(nn.Module):
    """Heat diffusion with a learned, positive time per channel (wraps the two functions).

    Parameters
    ----------
    channels : int
    method : {"spectral", "implicit"}
    init_times : float or (channels,) sequence
        Initial times (default: log-spaced from ``1e-3`` to ``1e-1``; with
        ``positivity="clamp"``, 0 is allowed and is the default: no diffusion at first).
    positivity : {"softplus", "abs", "clamp"}
        How the raw parameter is mapped to a positive time (:func:`positive_time`).

    Forward
    -------
    spectral: ``forward(z, mass, evals=..., evecs=..., offsets=None)``;
    implicit: ``forward(z, mass, L=...)``.
    """

    def __init__(
        self, channels: int, method: str = "spectral", init_times=None, positivity: str = "softplus"
    ):
        super().__init__()
        if method not in ("spectral", "implicit"):
            raise ValueError(f"method must be 'spectral' or 'implicit', got {method!r}")
        if not isinstance(channels, int) or channels < 1:
            raise ValueError(f"channels must be a positive integer, got {channels!r}")
        positive_time(torch.zeros(1), positivity)  # validates
        self.method, self.positivity = method, positivity
        if init_times is None:
            init = (
                torch.zeros(channels, dtype=torch.float64)
                if positivity == "clamp"
                else torch.logspace(-3, -1, channels, dtype=torch.float64)
            )
        else:
            init = torch.as_tensor(init_times, dtype=torch.float64).expand(channels).clone()
        if bool((init < 0).any()) or (positivity != "clamp" and bool((init == 0).any())):
            raise ValueError("init_times must be positive (or zero with positivity='clamp')")
        raw = _inverse_softplus(init) if positivity == "softplus" else init
        self.raw_times = nn.Parameter(raw.to(torch.get_default_dtype()))

    @property
    def times(self) -> torch.Tensor:
        """(C,) the positive diffusion times."""
        return positive_time(self.raw_times, self.positivity)

    def forward(self, z, mass, evals=None, evecs=None, offsets=None, L=None):
        t = self.times.to(real_dtype(z.dtype))
        if self.method == "spectral":
            if evals is None or evecs is None:
                raise ValueError("spectral diffusion needs evals and evecs")
            return spectral_diffusion(z, evals.to(t.dtype), evecs, mass, t, offsets)
        if L is None:
            raise ValueError("implicit diffusion needs the sparse Laplacian L")
        return implicit_diffusion(z, L, mass, t)


# --------------------------------------------------------------------------- gradient


def gradient_features(f, G, mass=None) -> torch.Tensor:
    r"""Edge gradient fields of vertex scalars: :math:`z = M_z^{-1} G f` (thesis 4.2).

    ``Re(z_e) = (f_j - f_i) / |e|`` along the edge (4.1); ``Im(z_e)`` is the normal
    component. Gauge-equivariant and intrinsic. A complex ``f = a + i b`` gives
    ``grad a + J grad b`` (``J`` the rotation by a quarter turn): gradients and
    co-gradients in one product. Without ``mass``, ``G f`` itself (for an operator that
    gives the field directly, such as
    :func:`~torch_edgevf.learning.precompute.vertex_gradient_operator`).

    Parameters
    ----------
    f : (V, C) real or complex tensor
    G : (E, V) complex sparse tensor (:func:`~torch_edgevf.operators.gradient`)
    mass : (E,) real tensor, the diagonal of ``M_z``, optional

    Returns
    -------
    (E, C) complex tensor.
    """
    f = _check_features(f, "f")
    G = _check_sparse(G, "G", cols=f.shape[0])
    z = _spmm(G, f if f.is_complex() else f.to(complex_dtype(f.dtype)))
    if mass is None:
        return z
    mass = _check_vector(mass, G.shape[0], "mass")
    # times the reciprocal: the same numbers as the quotient (a complex number divided
    # by a real one is multiplied by its reciprocal), several times faster
    return z * mass.to(z.real.dtype).reciprocal()[:, None]


def divergence_features(z, G, vertex_mass) -> torch.Tensor:
    r"""Divergence and curl per vertex from the adjoint of the gradient (thesis 4.2, B.4).

    .. math::  M_v (\operatorname{div}_v + \imath \operatorname{curl}_v) = -G^* z

    Both parts are gauge invariant (real scalars per vertex), so the output can be fed
    to any real layer.

    Parameters
    ----------
    z : (E, C) complex tensor
    G : (E, V) complex sparse tensor
    vertex_mass : (V,) real tensor, the (lumped) vertex masses

    Returns
    -------
    (V, C) complex tensor, ``div + i curl``.
    """
    z = _check_features(z, complex_only=True)
    G = _check_sparse(G, "G", rows=z.shape[0])
    vertex_mass = _check_vector(vertex_mass, G.shape[1], "vertex_mass")
    out = -_spmm(G, z, adjoint=True)
    return out * vertex_mass.to(out.real.dtype).reciprocal()[:, None]  # as in gradient_features


class GradientFeatures(nn.Module):
    """Module form of :func:`gradient_features`: ``forward(f, G, mass)``."""

    def forward(self, f, G, mass):
        return gradient_features(f, G, mass)


class DivergenceFeatures(nn.Module):
    """Module form of :func:`divergence_features`: ``forward(z, G, vertex_mass)``."""

    def forward(self, z, G, vertex_mass):
        return divergence_features(z, G, vertex_mass)


# --------------------------------------------------------------------------- pointwise layers


def complex_linear(z, weight) -> torch.Tensor:
    """``z W`` with a complex ``(C_in, C_out)`` weight: commutes with ``z -> e^{i theta} z``.

    Parameters
    ----------
    z : (N, C_in) complex tensor
    weight : (C_in, C_out) complex tensor, or (C_in, C_out, 2) real (real and imaginary parts)
    """
    z = _check_features(z, complex_only=True)
    if weight.dim() == 3 and weight.shape[-1] == 2 and not weight.is_complex():
        weight = torch.view_as_complex(weight.contiguous())
    if weight.dim() != 2 or weight.shape[0] != z.shape[1]:
        raise ValueError(f"weight must have shape ({z.shape[1]}, C_out), got {tuple(weight.shape)}")
    return z @ weight.to(z.dtype)


class ComplexLinear(nn.Module):
    """Rotation-equivariant linear map of channels, complex weights and no bias.

    The weight is stored as a real ``(C_in, C_out, 2)`` parameter (real and imaginary
    parts), so optimisers and ``DistributedDataParallel`` see real tensors only. A bias
    would break equivariance; put one on the modulus with :class:`ModReLU`.

    Initialisation: real and imaginary parts ``N(0, 1 / (2 C_in))``, so that
    ``E|zW|^2 = E|z|^2`` per channel.
    """

    def __init__(self, in_channels: int, out_channels: int):
        super().__init__()
        for name, c in (("in_channels", in_channels), ("out_channels", out_channels)):
            if not isinstance(c, int) or c < 1:
                raise ValueError(f"{name} must be a positive integer, got {c!r}")
        self.in_channels, self.out_channels = in_channels, out_channels
        self.weight = nn.Parameter(torch.randn(in_channels, out_channels, 2) / math.sqrt(2 * in_channels))

    def forward(self, z):
        return complex_linear(z, self.weight)

    def extra_repr(self) -> str:
        return f"{self.in_channels}, {self.out_channels}"


def modulus_relu(z, bias, eps: float | None = None) -> torch.Tensor:
    r"""``z relu(|z| + b) / |z|``: a ReLU on the modulus that keeps the phase.

    Gauge equivariant. At ``z = 0`` the output is ``0``; the denominator is clamped at
    ``eps`` (default ``1e-6`` in single, ``1e-12`` in double precision) so that values
    and gradients stay finite. For ``b > 0`` the map is
    discontinuous at ``0`` (every nonzero ``z`` gets modulus at least ``b``), as for
    any ModReLU; the learned biases usually become negative (a dead zone).

    Parameters
    ----------
    z : (N, C) complex tensor
    bias : (C,) real tensor
    """
    z = _check_features(z, complex_only=True)
    if not isinstance(bias, torch.Tensor) or bias.shape not in ((z.shape[1],), ()) or bias.is_complex():
        raise ValueError(f"bias must be a real ({z.shape[1]},) tensor")
    rdt = real_dtype(z.dtype)
    if eps is None:
        eps = 1e-6 if rdt == torch.float32 else 1e-12
    r = z.abs()
    scale = F.relu(r + bias.to(rdt)) / r.clamp_min(eps)
    return z * scale


class ModReLU(nn.Module):
    """Module form of :func:`modulus_relu` with a learned bias per channel (init ``bias``)."""

    def __init__(self, channels: int, bias: float = 0.0):
        super().__init__()
        self.bias = nn.Parameter(torch.full((channels,), float(bias)))

    def forward(self, z):
        return modulus_relu(z, self.bias)


def invariant_features(z, weight=None, modulus: bool = True) -> torch.Tensor:
    r"""Real, gauge-invariant features of complex edge features.

    ``|z|`` (``(N, C)``, if ``modulus``) and, given a complex ``(C, C)`` weight ``A``,
    the products :math:`\mathrm{Re}(z \cdot \overline{z A})` between channels (``(N, C)``;
    the gradient features of DiffusionNet, here per edge). Both are unchanged by
    ``z -> e^{i theta} z``. Concatenated along channels.

    Parameters
    ----------
    z : (N, C) complex tensor
    weight : (C, C) complex tensor, or (C, C, 2) real, optional
    modulus : bool

    Returns
    -------
    (N, C) or (N, 2C) real tensor.
    """
    z = _check_features(z, complex_only=True)
    if weight is None and not modulus:
        raise ValueError("invariant_features needs modulus=True or a weight")
    parts = []
    if modulus:
        parts.append(z.abs())
    if weight is not None:
        w = complex_linear(z, weight)
        if w.shape[1] != z.shape[1]:
            raise ValueError(f"weight must be ({z.shape[1]}, {z.shape[1]}), got C_out = {w.shape[1]}")
        parts.append((z * w.conj()).real)
    return parts[0] if len(parts) == 1 else torch.cat(parts, dim=1)


class InvariantReadout(nn.Module):
    """Module form of :func:`invariant_features` (learned ``(C, C)`` complex weight).

    Output ``(N, 2C)`` (modulus and products), or ``(N, C)`` with ``products=False``.
    """

    def __init__(self, channels: int, products: bool = True, modulus: bool = True):
        super().__init__()
        self.modulus = modulus
        self.weight = (
            nn.Parameter(torch.randn(channels, channels, 2) / math.sqrt(2 * channels)) if products else None
        )
        self.out_channels = channels * (int(modulus) + int(products))

    def forward(self, z):
        return invariant_features(z, self.weight, modulus=self.modulus)


# --------------------------------------------------------------------------- dropout

#: the low 53 bits of a random 64-bit integer, ``k``: the uniform double ``k 2^-53`` that
#: torch's CPU generator draws for each element of ``bernoulli_``
_MANTISSA = (1 << 53) - 1


def dropout(x: torch.Tensor, p: float = 0.5, training: bool = True) -> torch.Tensor:
    """:func:`torch.nn.functional.dropout`, its mask drawn about twice as fast on the CPU.

    On the CPU, ``F.dropout`` draws its mask with ``bernoulli_``, one element at a time;
    here the same 64-bit random integers are drawn with ``random_`` and compared with
    the probability as integers, in one vectorised step. The masks, the outputs, the
    gradients and the generator's state afterwards are those of ``F.dropout`` with the
    same seed (the tests check it), so a seeded run trains exactly as with
    ``nn.Dropout``. A complex ``x`` (which ``F.dropout`` does not take on the CPU) keeps
    or zeroes each complex entry whole: a real mask, so the layer commutes with gauge
    rotations. Elsewhere (another device, ``p`` of 0 or 1, evaluation) this is
    ``F.dropout`` itself.
    """
    if isinstance(p, bool) or not isinstance(p, numbers.Real) or not 0 <= p <= 1:
        raise ValueError(f"p must be a probability in [0, 1], got {p!r}")
    p = float(p)
    if not (x.is_floating_point() or x.is_complex()):
        raise ValueError(f"x must be a floating or complex tensor, got {x.dtype}")
    if not training or p == 0 or p == 1 or x.device.type != "cpu":
        return F.dropout(x, p, training)
    keep = 1.0 - p
    # bernoulli_(keep) keeps an element when k 2^-53 < keep, i.e. when k < ceil(keep 2^53)
    bits = torch.empty_like(x, dtype=torch.int64).random_()
    noise = ((bits & _MANTISSA) < math.ceil(keep * 2.0**53)).to(real_dtype(x.dtype))
    noise.div_(keep)
    return x * noise


class Dropout(nn.Dropout):
    """:class:`torch.nn.Dropout` with the faster CPU mask of :func:`dropout` (same masks)."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if self.inplace:
            return super().forward(x)
        return dropout(x, self.p, self.training)


# --------------------------------------------------------------------------- pooling


def _check_weight(weight, n: int, like: torch.Tensor) -> torch.Tensor:
    if weight is None:
        return torch.ones(n, dtype=like.dtype, device=like.device)
    return _check_vector(weight, n, "weight").to(like.dtype)


def pool_edges_to_vertices(x, edges, num_vertices: int, weight=None) -> torch.Tensor:
    r"""Weighted mean of edge features over the edges incident to each vertex.

    .. math::  y_v = \frac{\sum_{e \ni v} w_e x_e}{\sum_{e \ni v} w_e}

    With ``w = M_z`` (default in the models) this is area weighted. Use it on invariant
    (real) features: a complex edge feature lives in its edge's frame. With a ``weight``
    tensor that needs no gradient (precomputed masses), the mean is one sparse product
    with the ``(V, E)`` matrix of the ``w_e / sum w``, built once per pair of ``edges``
    and ``weight`` tensors and kept while both exist.

    Parameters
    ----------
    x : (E, C) real tensor
    edges : (E, 2) int tensor
    num_vertices : int
    weight : (E,) nonnegative real tensor, optional (default 1)

    Returns
    -------
    (V, C) tensor; vertices with no incident edge get 0.
    """
    x = _check_features(x, "x")
    if not isinstance(edges, torch.Tensor) or edges.shape != (x.shape[0], 2):
        raise ValueError(f"edges must have shape ({x.shape[0]}, 2)")
    w = _check_weight(weight, x.shape[0], x.real if x.is_complex() else x)
    if w is weight and not (weight.requires_grad or x.is_complex()) and edges.device == x.device == w.device:
        return _spmm(_pooling_operator(edges, weight, num_vertices), x)
    e = edges.to(x.device)
    wx = w[:, None] * x
    num = torch.zeros((num_vertices, x.shape[1]), dtype=x.dtype, device=x.device)
    num = num.index_add(0, e[:, 0], wx).index_add(0, e[:, 1], wx)
    return num / _weight_at_vertices(e, w, num_vertices)[:, None]


def _weight_at_vertices(e: torch.Tensor, w: torch.Tensor, num_vertices: int) -> torch.Tensor:
    """The sum of ``w`` over the edges at each vertex, 1 at a vertex on no edge (a divisor)."""
    den = torch.zeros(num_vertices, dtype=w.dtype, device=e.device)
    den = den.index_add(0, e[:, 0], w).index_add(0, e[:, 1], w)
    return torch.where(den > 0, den, torch.ones_like(den))


#: the pooling matrices of :func:`pool_edges_to_vertices` per (edges, weight, vertex count)
_POOL_CACHE: dict[tuple[int, int, int], torch.Tensor] = {}


def _pooling_operator(edges: torch.Tensor, weight: torch.Tensor, num_vertices: int) -> torch.Tensor:
    """The ``(V, E)`` sparse matrix of the weighted mean over the edges at each vertex.

    Entries ``w_e / sum_{e' ni v} w_e'`` at ``(v, e)`` for both ends of each edge; built
    once per pair of constant tensors and kept while both exist.
    """

    def build():
        e = edges.to(torch.int64)
        if e.numel() and (int(e.min()) < 0 or int(e.max()) >= num_vertices):
            raise ValueError(
                f"edges must hold vertex indices in [0, {num_vertices}), got {e.min()}..{e.max()}"
            )
        den = _weight_at_vertices(e, weight, num_vertices)
        rows = torch.cat([e[:, 0], e[:, 1]])
        cols = torch.arange(e.shape[0], device=e.device).repeat(2)
        vals = torch.cat([weight / den[e[:, 0]], weight / den[e[:, 1]]])
        return torch.sparse_coo_tensor(
            torch.stack([rows, cols]), vals, (num_vertices, e.shape[0]), check_invariants=False
        ).coalesce()

    return _kept(_POOL_CACHE, (id(edges), id(weight), num_vertices), (edges, weight), build)


def pool_edges_to_faces(x, face_edges, weight=None) -> torch.Tensor:
    """Weighted mean of edge features over the three edges of each face.

    Parameters
    ----------
    x : (E, C) real tensor
    face_edges : (F, 3) int tensor (:attr:`Topology.face_edges`)
    weight : (E,) nonnegative real tensor, optional

    Returns
    -------
    (F, C) tensor.
    """
    x = _check_features(x, "x")
    if not isinstance(face_edges, torch.Tensor) or face_edges.dim() != 2 or face_edges.shape[1] != 3:
        raise ValueError("face_edges must have shape (F, 3)")
    w = _check_weight(weight, x.shape[0], x.real if x.is_complex() else x)
    fe = face_edges.to(x.device)
    wf = w[fe]  # (F, 3)
    return (wf[..., None] * x[fe]).sum(1) / wf.sum(1).clamp_min(torch.finfo(w.dtype).tiny)[:, None]


def pool_global(x, weight=None, batch=None, num_meshes: int | None = None) -> torch.Tensor:
    """Weighted mean of features over each mesh of a batch.

    Parameters
    ----------
    x : (N, C) tensor
    weight : (N,) nonnegative real tensor, optional (e.g. ``M_z`` for edges)
    batch : (N,) int tensor, mesh index of each row; default all 0
    num_meshes : int, default ``batch.max() + 1``

    Returns
    -------
    (B, C) tensor.
    """
    x = _check_features(x, "x")
    w = _check_weight(weight, x.shape[0], x.real if x.is_complex() else x)
    if batch is None:
        batch = torch.zeros(x.shape[0], dtype=torch.int64, device=x.device)
    if not isinstance(batch, torch.Tensor) or batch.shape != (x.shape[0],):
        raise ValueError(f"batch must be a ({x.shape[0]},) int tensor")
    nb = int(batch.max()) + 1 if num_meshes is None else int(num_meshes)
    num = torch.zeros((nb, x.shape[1]), dtype=x.dtype, device=x.device).index_add(0, batch, w[:, None] * x)
    den = torch.zeros(nb, dtype=w.dtype, device=x.device).index_add(0, batch, w)
    return num / den.clamp_min(torch.finfo(w.dtype).tiny)[:, None]


class EdgePooling(nn.Module):
    """Module form of the three pooling functions.

    Parameters
    ----------
    to : {"vertex", "face", "global"}

    Forward
    -------
    ``vertex``: ``forward(x, edges=..., num_vertices=..., weight=None)``;
    ``face``: ``forward(x, face_edges=..., weight=None)``;
    ``global``: ``forward(x, weight=None, batch=None, num_meshes=None)``.
    """

    def __init__(self, to: str = "global"):
        super().__init__()
        if to not in ("vertex", "face", "global"):
            raise ValueError(f"to must be 'vertex', 'face' or 'global', got {to!r}")
        self.to_ = to

    def forward(
        self, x, weight=None, edges=None, num_vertices=None, face_edges=None, batch=None, num_meshes=None
    ):
        if self.to_ == "vertex":
            if edges is None or num_vertices is None:
                raise ValueError("vertex pooling needs edges and num_vertices")
            return pool_edges_to_vertices(x, edges, num_vertices, weight)
        if self.to_ == "face":
            if face_edges is None:
                raise ValueError("face pooling needs face_edges")
            return pool_edges_to_faces(x, face_edges, weight)
        return pool_global(x, weight, batch, num_meshes)

    def extra_repr(self) -> str:
        return f"to={self.to_!r}"


def normalize_modulus(
    z, weight=None, batch=None, num_meshes: int | None = None, eps: float = 1e-8
) -> torch.Tensor:
    r"""Divide each channel of each mesh by its weighted root-mean-square modulus.

    .. math::  z_e \leftarrow z_e \Big/
               \sqrt{\textstyle\sum_{e'} w_{e'} |z_{e'}|^2 / \sum_{e'} w_{e'} + \epsilon}

    over the edges of the same mesh; gauge equivariant (the scale is invariant).

    Parameters
    ----------
    z : (N, C) complex or real tensor
    weight : (N,) real tensor, optional (``M_z`` for edges)
    batch : (N,) int tensor, optional (mesh of each row)
    """
    z = _check_features(z)
    power = pool_global(z.real**2 + z.imag**2 if z.is_complex() else z**2, weight, batch, num_meshes)
    scale = torch.rsqrt(power + eps)
    return z * (scale if batch is None else scale[batch]).to(real_dtype(z.dtype))


class ModulusNorm(nn.Module):
    """Module form of :func:`normalize_modulus` (no parameters)."""

    def __init__(self, eps: float = 1e-8):
        super().__init__()
        self.eps = eps

    def forward(self, z, weight=None, batch=None, num_meshes=None):
        return normalize_modulus(z, weight, batch, num_meshes, self.eps)
