"""Opt-in tuning of the C allocator for the many medium-sized temporaries of mesh code.

Building a topology or assembling operators on a mesh of ~10^5 faces allocates hundreds
of NumPy and torch temporaries of a few hundred KiB to a few MiB. With glibc's defaults
each one above the mmap threshold is a fresh ``mmap`` whose pages fault in on first
touch, and memory freed at the top of the heap is returned to the system at once, so the
next temporary faults again. On virtual machines a page fault costs microseconds: on the
development machine this was 7,000 faults and about half the time of a ``Topology`` build
at 82k faces.

:func:`tune_allocator` raises the mmap and trim thresholds so that freed memory is reused
(up to ``keep_bytes`` stays mapped to the process). It changes process-wide settings,
which is why the library never calls it on its own; the ``edgevf`` command line calls it.
The same effect without code: ``MALLOC_MMAP_THRESHOLD_=33554432
MALLOC_TRIM_THRESHOLD_=268435456 MALLOC_TOP_PAD_=67108864`` in the environment.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging
import sys

__all__ = ["tune_allocator"]

log = logging.getLogger(__name__)

_M_TRIM_THRESHOLD = -1
_M_TOP_PAD = -2
_M_MMAP_THRESHOLD = -3

MiB = 1 << 20


def tune_allocator(
    keep_bytes: int = 256 * MiB, mmap_threshold: int = 32 * MiB, top_pad: int = 64 * MiB
) -> bool:
    """Let glibc keep and reuse freed memory instead of returning it to the system.

    Parameters
    ----------
    keep_bytes : int
        ``M_TRIM_THRESHOLD``: free memory at the top of the heap kept before trimming.
    mmap_threshold : int
        ``M_MMAP_THRESHOLD``: allocations at least this large get their own ``mmap``
        (glibc caps it at 32 MiB on 64-bit systems).
    top_pad : int
        ``M_TOP_PAD``: extra memory obtained each time the heap grows.

    Returns
    -------
    bool
        True when the settings were applied; False where the C library is not glibc
        (macOS, Windows, musl), in which case nothing changes.
    """
    for name, value in (("keep_bytes", keep_bytes), ("mmap_threshold", mmap_threshold), ("top_pad", top_pad)):
        if not isinstance(value, int) or isinstance(value, bool) or value < 0 or value >= 2**31:
            raise ValueError(f"{name} must be an integer in [0, 2**31), got {value!r}")
    if not sys.platform.startswith("linux"):
        log.debug("tune_allocator: not Linux, nothing changed")
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        log.debug("tune_allocator: no glibc mallopt, nothing changed")
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    ok = all(
        mallopt(param, value) == 1
        for param, value in (
            (_M_MMAP_THRESHOLD, mmap_threshold),
            (_M_TRIM_THRESHOLD, keep_bytes),
            (_M_TOP_PAD, top_pad),
        )
    )
    log.debug("tune_allocator: %s", "applied" if ok else "rejected by mallopt")
    return ok
