"""The real and complex dtypes of one precision, for the whole package.

A field on edges is complex, the mesh it lives on is real: ``float32`` positions carry
``complex64`` fields and ``float64`` positions ``complex128`` ones. Half precision
(``float16``, ``bfloat16``) has no complex counterpart in torch; it maps to ``complex64``.
"""

from __future__ import annotations

import torch

__all__ = ["complex_dtype", "real_dtype"]

_COMPLEX_OF = {
    torch.float16: torch.complex64,
    torch.bfloat16: torch.complex64,
    torch.float32: torch.complex64,
    torch.float64: torch.complex128,
}
_REAL_OF = {torch.complex64: torch.float32, torch.complex128: torch.float64}


def complex_dtype(dtype: torch.dtype) -> torch.dtype:
    """The complex dtype of the same precision (``float32 -> complex64``); complex dtypes are kept."""
    return _COMPLEX_OF.get(dtype, dtype)


def real_dtype(dtype: torch.dtype) -> torch.dtype:
    """The real dtype of the same precision (``complex128 -> float64``); real dtypes are kept."""
    return _REAL_OF.get(dtype, dtype)
