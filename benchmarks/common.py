"""Shared helpers for the benchmarks: timing, peak memory, mesh loading, markdown tables.

Every benchmark script imports this module from its own folder (``python benchmarks/x.py``
puts ``benchmarks/`` first on ``sys.path``). Nothing here depends on torch_edgevf, so the
peers (libigl, potpourri3d, ...) can be timed in a process that never imports it.
"""

from __future__ import annotations

import gc
import json
import logging
import os
import platform
import resource
import statistics
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

log = logging.getLogger(__name__)

REPO = Path(__file__).resolve().parents[1]
# The benchmark meshes (spot.obj, bunny.obj, ...): $TORCH_EDGEVF_MESHES, else the folder
# shared/meshes next to the repository.
SHARED_MESHES = Path(os.environ.get("TORCH_EDGEVF_MESHES") or REPO.parent / "shared" / "meshes")


# --------------------------------------------------------------------------- timing


@dataclass
class Timing:
    """Wall-clock times of the repeats of one measurement, in seconds."""

    name: str
    times: list = field(default_factory=list)
    cpu_times: list = field(default_factory=list)

    @property
    def median(self) -> float:
        return statistics.median(self.times)

    @property
    def min(self) -> float:
        return min(self.times)

    def as_dict(self) -> dict:
        return {
            "name": self.name,
            "times": self.times,
            "median": self.median,
            "min": self.min,
            "cpu_times": self.cpu_times,
        }


def time_it(
    name: str,
    fn: Callable[[], object],
    repeats: int = 5,
    warmup: int = 1,
    setup: Callable[[], object] | None = None,
) -> Timing:
    """Median-of-``repeats`` wall time of ``fn()`` after ``warmup`` untimed calls.

    ``setup()`` (untimed) runs before every call, warm-ups included; its result, if not
    ``None``, is passed to ``fn``. The result of ``fn`` is dropped before the next call, and
    ``gc.collect()`` runs between calls so that one repeat's garbage is not freed inside the
    next one's timed region. Process CPU times are kept too (all threads): on a shared
    machine they are less sensitive to other processes than wall times.
    """
    timing = Timing(name)
    for k in range(warmup + repeats):
        arg = setup() if setup is not None else None
        gc.collect()
        c0 = time.process_time()
        t0 = time.perf_counter()
        out = fn() if arg is None else fn(arg)
        elapsed = time.perf_counter() - t0
        cpu = time.process_time() - c0
        del out, arg
        if k >= warmup:
            timing.times.append(elapsed)
            timing.cpu_times.append(cpu)
    gc.collect()
    log.info("%-28s median %s over %d (min %s)", name, fmt_time(timing.median), repeats, fmt_time(timing.min))
    return timing


def fmt_time(seconds: float | None) -> str:
    """``1.23 s``, ``45.6 ms`` or ``789 us``; ``-`` for ``None``."""
    if seconds is None:
        return "-"
    if seconds >= 1:
        return f"{seconds:.2f} s"
    if seconds >= 1e-3:
        return f"{seconds * 1e3:.1f} ms" if seconds < 0.1 else f"{seconds * 1e3:.0f} ms"
    return f"{seconds * 1e6:.0f} us"


def fmt_bytes(n: float | None) -> str:
    if n is None:
        return "-"
    return f"{n / 2**30:.2f} GiB" if n >= 2**30 else f"{n / 2**20:.0f} MiB"


# --------------------------------------------------------------------------- memory


def peak_rss_bytes() -> int:
    """Peak resident set size of this process so far (``ru_maxrss``; kB on Linux, B on macOS)."""
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return int(peak) if sys.platform == "darwin" else int(peak) * 1024


def _status_kb(key: str) -> int | None:
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith(key + ":"):
                    return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None


def current_rss_bytes() -> int | None:
    """Current resident set size (Linux ``VmRSS``), or ``None`` where unavailable."""
    return _status_kb("VmRSS")


class PeakMemory:
    """Peak RSS of a code region (Linux: resets ``VmHWM`` through ``/proc/self/clear_refs``).

    Elsewhere, or where the reset is refused, it reports the process peak so far, which is
    an upper bound. ``torch``'s CPU allocations are ordinary heap memory and count.

    >>> with PeakMemory() as pm: ...
    >>> pm.peak, pm.before
    """

    def __enter__(self) -> PeakMemory:
        gc.collect()
        self.exact = False
        try:
            with open("/proc/self/clear_refs", "w") as fh:
                fh.write("5")
            self.exact = _status_kb("VmHWM") is not None
        except OSError:
            pass
        self.before = current_rss_bytes()
        return self

    def __exit__(self, *exc) -> None:
        hwm = _status_kb("VmHWM") if self.exact else None
        self.peak = hwm if hwm is not None else peak_rss_bytes()


# --------------------------------------------------------------------------- meshes


def load_mesh(path) -> tuple:
    """``(verts (V, 3) float64, faces (F, 3) int64)`` as numpy arrays.

    Uses ``torch_edgevf.io.load_mesh`` when the package provides it (it merges duplicated
    vertices and drops degenerate faces, and reports what it changed), otherwise
    ``trimesh.load(path, process=True)``.
    """
    import numpy as np

    try:
        from torch_edgevf.io import load_mesh as edgevf_load
    except ImportError:
        edgevf_load = None
    if edgevf_load is not None:
        data = edgevf_load(path)
        return data.verts.numpy().astype(np.float64), data.faces.numpy().astype(np.int64)
    import trimesh

    mesh = trimesh.load(str(path), process=True, force="mesh")
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)


# --------------------------------------------------------------------------- machine


def machine_info() -> dict:
    """Cores, CPU model, memory, load, and library versions, for the report header."""
    info = {
        "python": platform.python_version(),
        "platform": platform.platform(),
        "cores": os.cpu_count(),
        "cpu": platform.processor() or platform.machine(),
    }
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    info["cpu"] = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    try:
        info["memory_bytes"] = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        pass
    try:
        info["load_average"] = [round(x, 2) for x in os.getloadavg()]
    except OSError:
        pass
    from importlib import metadata

    for key, dist in (
        ("torch", "torch"),
        ("numpy", "numpy"),
        ("scipy", "scipy"),
        ("igl", "libigl"),
        ("potpourri3d", "potpourri3d"),
        ("robust_laplacian", "robust_laplacian"),
    ):
        try:
            info[key] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            info[key] = None
    info["omp_wait_policy"] = os.environ.get("OMP_WAIT_POLICY")
    try:
        import torch

        info["torch_threads"] = torch.get_num_threads()
        info["torch_interop_threads"] = torch.get_num_interop_threads()
    except ImportError:
        pass
    return info


# --------------------------------------------------------------------------- subprocesses


def run_worker(args: Sequence[str], timeout: float | None = None, env: dict | None = None) -> dict:
    """Run ``python <args>`` in a fresh process and return the JSON of its last stdout line.

    A fresh process per measurement group keeps peak-RSS readings separate and stops one
    group's allocator state from leaking into the next.
    """
    cmd = [sys.executable, *map(str, args)]
    log.info("running %s", " ".join(cmd[1:]))
    t0 = time.perf_counter()
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    proc = subprocess.run(
        cmd,
        stdout=subprocess.PIPE,
        stderr=None,
        text=True,
        timeout=timeout,
        env=None if env is None else {**os.environ, **env},
    )
    if proc.returncode != 0:
        raise RuntimeError(f"worker {' '.join(cmd[1:])} failed with exit code {proc.returncode}")
    lines = [line for line in proc.stdout.splitlines() if line.strip()]
    if not lines:
        raise RuntimeError(f"worker {' '.join(cmd[1:])} printed nothing")
    result = json.loads(lines[-1])
    result["worker_wall_s"] = time.perf_counter() - t0
    result["load_before"] = load
    return result


def emit(result: dict) -> None:
    """Print ``result`` as one JSON line (the last line a worker writes to stdout)."""
    sys.stdout.write(json.dumps(result, default=_jsonable) + "\n")
    sys.stdout.flush()


def _jsonable(obj):
    if isinstance(obj, Timing):
        return obj.as_dict()
    if hasattr(obj, "__dataclass_fields__"):
        return asdict(obj)
    if hasattr(obj, "item"):
        return obj.item()
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


# --------------------------------------------------------------------------- tables


def markdown_table(headers: Sequence[str], rows: Sequence[Sequence[object]], align: str | None = None) -> str:
    """A GitHub markdown table; ``align`` is one character per column (``l``, ``r``, ``c``)."""
    cells = [[str(h) for h in headers]] + [["" if c is None else str(c) for c in row] for row in rows]
    widths = [max(len(r[k]) for r in cells) for k in range(len(headers))]
    align = align or "l" + "r" * (len(headers) - 1)
    rule = {"l": ":{}", "r": "{}:", "c": ":{}:"}

    def line(row):
        return (
            "| "
            + " | ".join(c.ljust(w) if a == "l" else c.rjust(w) for c, w, a in zip(row, widths, align))
            + " |"
        )

    sep = (
        "|" + "|".join(rule[a].format("-" * (w + 2 - len(rule[a]) + 2)) for w, a in zip(widths, align)) + "|"
    )
    return "\n".join([line(cells[0]), sep, *map(line, cells[1:])])
