"""Benchmark: one full turn of an n-direction field along the unit sphere's rotation.

``python benchmarks/bench_transport.py [--levels 3 4 5] [--thesis-levels 3 4] [--repeats 3]``
writes ``benchmarks/results/transport_full_turn_n.md``:

* accuracy: ``z0 = w^n`` (``w = e_z x p``, ``n = 1, 2, 4``) transported for ``t = 2 pi`` with
  the default settings of :func:`torch_edgevf.transport` on icosphere levels 3-5; the
  ``M_z``-norm ratio and the relative ``M_z`` error against the exact answer
  ``z0 exp(i n 2 pi cos theta)`` (the holonomy of the latitude circles), with the order
  fitted over the levels (least squares of ``log err`` on ``log h``, ``h`` the mean edge
  length); the thesis scheme (with and without its suggested smoothing) beside it;
* cost: the time of the full turn (the transporter's construction included) against one
  solve with a factorization of the same size, side by side and interleaved, one thread,
  process CPU time (the wall time of a shared machine follows its load), median of
  ``--repeats``: the Hermitian ``M_z + s L_c^(n)`` (the heat step of the
  thesis scheme's smoothing, the default back-end of :class:`~torch_edgevf.linalg.SparseSolver`)
  and the non-Hermitian ``M_z - (dt/2) A`` of the upwind operator (what one Crank-Nicolson
  step would solve, ``SparseSolver``'s default back-end for it), factorizations excluded.
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import platform
import statistics
import time
import warnings
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import torch  # noqa: E402

import torch_edgevf as ev  # noqa: E402
from torch_edgevf.fields.powers import nth_power  # noqa: E402
from torch_edgevf.fields.transport import SUGGESTED_SMOOTHING, Transporter  # noqa: E402
from torch_edgevf.linalg import SparseSolver, solve  # noqa: E402
from torch_edgevf.mesh.topology import Topology  # noqa: E402

log = logging.getLogger("bench_transport")
OUT = Path(__file__).resolve().parent / "results" / "transport_full_turn_n.md"
NS = (1, 2, 4)
T = 2 * math.pi


def rotation_sphere(level: int):
    """Icosphere, unit edge-midpoint directions and the rotation field ``e_z x p``."""
    verts, faces = ev.icosphere(level)
    topo = Topology(faces)
    e = topo.edges
    p = (verts[e[:, 0]] + verts[e[:, 1]]) / 2
    p = p / p.norm(dim=1, keepdim=True)
    w3 = torch.linalg.cross(torch.tensor([0.0, 0.0, 1.0], dtype=p.dtype).expand_as(p), p)
    w = ev.edges_from_vectors(verts, topo, w3)
    h = float((verts[e[:, 0]] - verts[e[:, 1]]).norm(dim=1).mean())
    return verts, topo, p, w, h


def full_turn(verts, topo, p, w, n: int, **kwargs) -> dict:
    """Transport ``w^n`` once around; error, norm ratio, steps and wall time."""
    steps = kwargs.pop("steps", 1)
    t0 = time.process_time()
    tr = Transporter(verts, topo, w, n=n, growth_tol=None, **kwargs)
    z0 = nth_power(w, n)
    z = tr(z0, T, steps)
    seconds = time.process_time() - t0
    exact = z0 * torch.polar(torch.ones_like(p[:, 2]), n * T * p[:, 2])
    return {
        "err": float(tr.norm(z - exact) / tr.norm(exact)),
        "norm": float(tr.norm(z) / tr.norm(z0)),
        "steps": tr.num_steps(T) if tr.scheme == "upwind" else steps,
        "seconds": seconds,
    }


def fitted_order(hs, errs) -> float:
    return float(np.polyfit(np.log(hs), np.log(errs), 1)[0])


def solvers(verts, topo, w, tr_steps: int):
    """One solve with each reference factorization (factored here, outside the timing)."""
    M = ev.mass_matrix(verts, topo)
    s = SUGGESTED_SMOOTHING[0] * float(M.values().sum())
    L = ev.connection_laplacian(verts, topo, 1)
    herm = SparseSolver((M.to(L.dtype) + s * L).coalesce(), hermitian=True)
    tr = Transporter(verts, topo, w)
    dt = T / tr_steps
    cn = SparseSolver((M.to(torch.complex128) - (dt / 2) * tr.operator()).coalesce())
    b = torch.randn(topo.num_edges, dtype=torch.complex128, generator=torch.Generator().manual_seed(0))
    return {
        "Hermitian M + s L_c": lambda: solve(herm, b),
        "non-Hermitian M - dt/2 A": lambda: solve(cn, b),
    }, (herm, cn)


def timing(verts, topo, p, w, repeats: int) -> dict:
    """Interleaved medians of the process CPU time (one thread): the full turn (n = 1, 2, 4,
    construction included) and one solve with each reference factorization."""
    turns = {n: (lambda n=n: full_turn(verts, topo, p, w, n)) for n in NS}
    steps = full_turn(verts, topo, p, w, 1)["steps"]
    refs, _keep = solvers(verts, topo, w, max(1, round(steps / 4)))
    times: dict = {**{f"turn n={n}": [] for n in NS}, **{k: [] for k in refs}}
    for fn in refs.values():
        fn()  # warm-up
    for _ in range(repeats):
        for n, fn in turns.items():
            t0 = time.process_time()
            fn()
            times[f"turn n={n}"].append(time.process_time() - t0)
        for name, fn in refs.items():
            reps = 10
            t0 = time.process_time()
            for _ in range(reps):
                fn()
            times[name].append((time.process_time() - t0) / reps)
    return {k: statistics.median(v) for k, v in times.items()}


def main(argv=None) -> str:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--levels", type=int, nargs="+", default=[3, 4, 5])
    parser.add_argument("--thesis-levels", type=int, nargs="*", default=[3, 4])
    parser.add_argument("--timing-levels", type=int, nargs="*", default=[4, 5])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    warnings.simplefilter("ignore")
    rows, hs, errs = [], {}, {n: [] for n in NS}
    thesis_rows, timing_rows = [], []
    for level in args.levels:
        verts, topo, p, w, h = rotation_sphere(level)
        hs[level] = h
        for n in NS:
            r = full_turn(verts, topo, p, w, n)
            errs[n].append(r["err"])
            rows.append(
                f"| {level} | {topo.num_edges:,} | {n} | {r['norm']:.4f} | {r['err']:.4f} | {r['steps']} | "
                f"{r['seconds']:.2f} |"
            )
            log.info(rows[-1])
        if level in args.thesis_levels:
            c, per_unit = SUGGESTED_SMOOTHING
            s = c * float(ev.mass_matrix(verts, topo).values().sum())
            k = math.ceil(per_unit * T)
            for n in NS:
                plain = full_turn(verts, topo, p, w, n, scheme="thesis")
                smooth = full_turn(verts, topo, p, w, n, scheme="thesis", smoothing=s, steps=k)
                thesis_rows.append(
                    f"| {level} | {n} | {plain['norm']:.3g} | {plain['err']:.3g} | {plain['seconds']:.2f} | "
                    f"{smooth['norm']:.3f} | {smooth['err']:.3f} | {smooth['seconds']:.2f} |"
                )
                log.info(thesis_rows[-1])
        if level in args.timing_levels:
            tm = timing(verts, topo, p, w, args.repeats)
            herm, cn = tm["Hermitian M + s L_c"], tm["non-Hermitian M - dt/2 A"]
            for n in NS:
                turn = tm[f"turn n={n}"]
                timing_rows.append(
                    f"| {level} | {n} | {turn:.3f} | {herm * 1e3:.2f} | {turn / herm:.0f} | "
                    f"{cn * 1e3:.2f} | {turn / cn:.0f} |"
                )
                log.info(timing_rows[-1])
    levels = list(hs)
    orders = {n: fitted_order([hs[lv] for lv in levels], errs[n]) for n in NS} if len(levels) > 1 else {}
    text = [
        "# One full turn (t = 2 pi) along the unit sphere's rotation field w = e_z x p, z0 = w^n",
        "",
        f"Command: `python benchmarks/bench_transport.py --levels {' '.join(map(str, args.levels))} "
        f"--thesis-levels {' '.join(map(str, args.thesis_levels))} "
        f"--timing-levels {' '.join(map(str, args.timing_levels))} --repeats {args.repeats}`.",
        f"Machine: {platform.processor() or platform.machine()}, torch {torch.__version__}, one thread "
        "(`OMP_NUM_THREADS=1`, `torch.set_num_threads(1)`). Times are process CPU times (on a "
        "shared machine the wall times follow its load); the ratios are medians of interleaved runs.",
        "",
        "norm: ||z(2 pi)||_M / ||z0||_M; err: relative M_z-norm error against the exact answer "
        "z0 exp(i n 2 pi cos theta) (backward transport turns the representation vector by "
        "n t cos(theta) relative to the rotated field); steps: the Runge-Kutta steps chosen; "
        "s: CPU time of `Transporter(...)` and the call.",
        "",
        "## Default settings (`transport(verts, faces, z0, w, t, n=n)`: the upwind scheme)",
        "",
        "| level | edges | n | norm | err | steps | s |",
        "| --- | --- | --- | --- | --- | --- | --- |",
        *rows,
        "",
    ]
    if orders:
        text += [
            f"Fitted order of the error in the mesh size h (levels {levels[0]}-{levels[-1]}): "
            + ", ".join(f"n = {n}: {orders[n]:.2f}" for n in NS)
            + ".",
            "",
        ]
    if thesis_rows:
        text += [
            "## The thesis scheme, exp(t M_z^-1 D_w), for comparison",
            "",
            "Without smoothing (one exact exponential), and with the suggested smoothing "
            f"(`SUGGESTED_SMOOTHING` = {SUGGESTED_SMOOTHING}: s = c * area, ceil(1.3 t) = "
            f"{math.ceil(SUGGESTED_SMOOTHING[1] * T)} steps, a heat step after each).",
            "",
            "| level | n | norm | err | s | norm (smoothed) | err (smoothed) | s (smoothed) |",
            "| --- | --- | --- | --- | --- | --- | --- | --- |",
            *thesis_rows,
            "",
        ]
    if timing_rows:
        text += [
            "## Cost: the full turn against one solve of the same size",
            "",
            "turn: median time of the full turn with the default settings (construction "
            "included); solve: median time of one solve with the Hermitian factorization of "
            "M_z + s L_c (the heat step) and with the non-Hermitian one of M_z - (dt/2) A (a "
            "Crank-Nicolson step of the upwind operator), factorizations not counted; ratio: "
            "turn / solve.",
            "",
            "| level | n | turn (s) | Hermitian solve (ms) | ratio | non-Hermitian solve (ms) | ratio |",
            "| --- | --- | --- | --- | --- | --- | --- |",
            *timing_rows,
            "",
        ]
    out = "\n".join(text)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(out)
    return out


if __name__ == "__main__":
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    print(main())
