"""Devices and dtypes of the objects that hold tensors, for the whole package.

* :func:`parse_to` and :func:`move` give the containers of the package (the per-mesh
  operators, batches) the ``.to(device)``, ``.to(dtype)`` and ``.to(device, dtype)`` of
  torch: real tensors take the dtype, complex ones the complex dtype of the same
  precision, integer ones keep theirs; all of them move.
* :func:`check_devices` raises a ``ValueError`` naming two inputs on different devices,
  at the first call (not at the first kernel that would fail deep inside).
* :func:`sparse_kernels` tells whether torch has the sparse CSR products the layers use
  for a dtype on a device (CUDA has them for real and complex dtypes; the ``meta`` device,
  and MPS for complex dtypes, do not). Where it has none, the layers compute the same
  products as gathers and ``index_add`` on that device, and a warning says so once per
  device type and dtype.
"""

from __future__ import annotations

import warnings

import torch

from ._dtypes import complex_dtype, real_dtype

__all__ = ["parse_to", "move", "check_devices", "sparse_kernels", "SparseFallbackWarning", "resolve_device"]


class SparseFallbackWarning(UserWarning):
    """Torch has no sparse CSR product for a dtype on a device: gathers run in its place."""


def parse_to(*args, **kwargs) -> tuple[torch.device | None, torch.dtype | None, bool]:
    """``(device, real dtype, non_blocking)`` of the arguments of ``Tensor.to``.

    The dtype must be float32 or float64 (or complex64 / complex128, which name the same
    precision); anything else raises ``ValueError``.
    """
    try:
        device, dtype, non_blocking, _ = torch._C._nn._parse_to(*args, **kwargs)
    except (TypeError, RuntimeError) as error:
        raise ValueError(f"to() takes a device and/or a dtype, as Tensor.to does: {error}") from None
    if dtype is not None:
        real = real_dtype(dtype)
        if real not in (torch.float32, torch.float64):
            raise ValueError(f"to() takes a floating dtype, torch.float32 or torch.float64, got {dtype}")
        dtype = real
    return device, dtype, bool(non_blocking)


def move(x, device: torch.device | None, dtype: torch.dtype | None, non_blocking: bool = False):
    """``x`` on ``device`` in the precision ``dtype`` (real: ``dtype``; complex: its complex
    dtype; integer and boolean: unchanged). Anything but a tensor is returned as it is."""
    if not isinstance(x, torch.Tensor):
        return x
    target = None
    if dtype is not None and x.is_complex():
        target = complex_dtype(dtype)
    elif dtype is not None and x.is_floating_point():
        target = dtype
    return x.to(device=device, dtype=target, non_blocking=non_blocking)


def check_devices(**tensors) -> None:
    """Raise ``ValueError`` unless the given tensors (``None`` and non-tensors skipped) are on
    one device; the message names the first one and the first on another device."""
    first_name, first = None, None
    for name, t in tensors.items():
        if not isinstance(t, torch.Tensor):
            continue
        if first is None:
            first_name, first = name, t
        elif t.device != first.device:
            raise ValueError(
                f"{name} is on {t.device} but {first_name} is on {first.device}: move them to one "
                f"device (e.g. {name}.to({str(first.device)!r}))"
            )


#: (device type, dtype) -> whether torch has the sparse CSR products there
_SPARSE_KERNELS: dict[tuple[str, torch.dtype], bool] = {}


def _probe(device: torch.device, dtype: torch.dtype) -> bool:
    """Run the products of the layers (COO to CSR, CSR @ dense, the adjoint) on a 2 x 2 matrix."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # "sparse CSR support is in beta"
            idx = torch.tensor([[0, 1, 1], [0, 0, 1]], device=device)
            A = torch.sparse_coo_tensor(idx, torch.ones(3, dtype=dtype, device=device), (2, 2))
            A = A.coalesce()
            AH = (A.t().conj() if A.is_complex() else A.t()).coalesce()
            x = torch.ones((2, 1), dtype=dtype, device=device)
            A.to_sparse_csr() @ x
            AH.to_sparse_csr() @ x
        return True
    except (RuntimeError, NotImplementedError, TypeError):
        return False


def sparse_kernels(device: torch.device, dtype: torch.dtype) -> bool:
    """Whether torch has the sparse CSR products of the layers for ``dtype`` on ``device``.

    Probed once per device type and dtype (always true on the CPU). Where it is false, a
    :class:`SparseFallbackWarning` says once that the products run as gathers and
    ``index_add`` on that device instead (the same numbers, slower).
    """
    device = torch.device(device)
    if device.type == "cpu":
        return True
    key = (device.type, dtype)
    if key not in _SPARSE_KERNELS:
        _SPARSE_KERNELS[key] = ok = _probe(device, dtype)
        if not ok:
            warnings.warn(
                f"torch has no sparse CSR product for {dtype} on the {device.type} device: the sparse "
                "products of torch_edgevf run there as gathers and index_add (the same numbers, slower)",
                SparseFallbackWarning,
                stacklevel=3,
            )
    return _SPARSE_KERNELS[key]


def resolve_device(device) -> torch.device:
    """``device`` (a name such as ``"cpu"``, ``"cuda"``, ``"cuda:1"``, ``"mps"``, or a
    :class:`torch.device`) as a :class:`torch.device`, or a ``ValueError`` saying that torch
    cannot use it here (for the ``--device`` option of training scripts)."""
    try:
        resolved = torch.device(device)
    except (RuntimeError, TypeError) as error:
        raise ValueError(f"{device!r} is not a device: {error}") from None
    try:
        torch.empty(1, device=resolved)
    except (RuntimeError, AssertionError) as error:
        reason = (str(error).strip().splitlines() or [type(error).__name__])[0]
        raise ValueError(f"device {str(resolved)!r} is not available to torch here: {reason}") from None
    return resolved
