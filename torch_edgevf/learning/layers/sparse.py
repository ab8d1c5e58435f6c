"""Checks of features and operators, and products with sparse operators (CSR copies of constant ones)."""

from __future__ import annotations

import warnings
import weakref

import torch

from ..._device import check_devices, sparse_kernels

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
    COO product, which converts and transposes at every call). On a device where torch
    has no CSR product for the dtype (:func:`~torch_edgevf._device.sparse_kernels`: the
    ``meta`` device, MPS for complex dtypes), the gather, on that device, with a warning
    once.
    """
    check_devices(x=x, A=A)
    rows, cols = A.indices()
    vals = A.values()
    if (
        not vals.requires_grad
        and vals.dtype == x.dtype
        and x.layout == torch.strided
        and sparse_kernels(x.device, x.dtype)
    ):
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
