"""Heat diffusion of features with a learned time per channel: spectral or implicit."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from ..._device import check_devices
from ..._dtypes import real_dtype
from ...linalg import solve
from .sparse import _check_features, _check_sparse, _check_vector

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
    check_devices(z=z, evals=evals, evecs=evecs, mass=mass, times=times)
    if offsets is None:
        if evals.shape != (k,):
            raise ValueError(f"evals must have shape ({k},), got {tuple(evals.shape)}")
        return _spectral_diffusion(z, evals, evecs, mass, times)
    offsets = [int(o) for o in offsets]
    nb = len(offsets) - 1
    if nb < 1 or offsets[0] != 0 or offsets[-1] != n or any(b < a for a, b in zip(offsets, offsets[1:])):
        raise ValueError(f"offsets must rise from 0 to N = {n}, got {offsets}")
    if evals.shape != (nb, k):
        raise ValueError(
            f"evals must have shape ({nb}, {k}) for a batch of {nb} meshes, got {tuple(evals.shape)}"
        )
    return _spectral_diffusion(z, evals, evecs, mass, times, offsets)


def _spectral_diffusion(z, evals, evecs, mass, times, offsets=None) -> torch.Tensor:
    """:func:`spectral_diffusion` on inputs known to be valid (the checks done by the caller)."""
    x = z * mass[:, None].to(real_dtype(z.dtype))
    if offsets is None:
        coeffs = evecs.conj().transpose(0, 1).to(torch.promote_types(evecs.dtype, x.dtype)) @ x.to(
            torch.promote_types(evecs.dtype, x.dtype)
        )
        coeffs = coeffs * torch.exp(-evals[:, None] * times[None, :])
        return evecs.to(coeffs.dtype) @ coeffs
    offsets = [int(o) for o in offsets]
    nb = len(offsets) - 1
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
    check_devices(z=z, L=L, mass=mass, times=times)
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
        if isinstance(z, torch.Tensor) and z.device != self.raw_times.device:
            raise ValueError(
                f"z is on {z.device} but the module's parameters are on {self.raw_times.device}: "
                f"move one of them (module.to({str(z.device)!r}) or z.to(...))"
            )
        t = self.times.to(real_dtype(z.dtype))
        if self.method == "spectral":
            if evals is None or evecs is None:
                raise ValueError("spectral diffusion needs evals and evecs")
            return spectral_diffusion(z, evals.to(t.dtype), evecs, mass, t, offsets)
        if L is None:
            raise ValueError("implicit diffusion needs the sparse Laplacian L")
        return implicit_diffusion(z, L, mass, t)
