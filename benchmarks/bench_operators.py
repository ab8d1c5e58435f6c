"""First assembly, re-assembly and matvec of the edge-based operators, side by side with libigl.

Run from the repository root::

    python benchmarks/bench_operators.py                 # the default meshes, 1 thread and all
    python benchmarks/bench_operators.py --threads 1     # one thread only
    python benchmarks/bench_operators.py --quick         # trimesh's icosphere 6 alone, 5 rounds
    python benchmarks/bench_operators.py --memory        # also peak RSS at 1.3M faces (icosphere 8)

What a user meets: meshes numbered by the tools that made them (:mod:`meshes`: trimesh's
icosphere 6, a random Delaunay sphere, Spot, an RNA molecular surface; ``ico6`` is
torch_edgevf's own icosphere, for the earlier tables), the *first* assembly timed from the
faces (``Topology`` included, nothing cached), and every side on the same threads: a worker
process per thread count sets ``OMP_NUM_THREADS``, ``MKL_NUM_THREADS``,
``OPENBLAS_NUM_THREADS`` and ``IGL_NUM_THREADS`` (libigl's own thread pool, which ignores
OpenMP's variable) before any import, and ``torch.set_num_threads``. Each measurement is
interleaved (ours, libigl, ours, libigl, ...) and the median of the rounds is kept, with
the process CPU time beside the wall time (on a loaded machine the CPU time of a
single-threaded side is the steadier figure).

Rows, per mesh and thread count:

* first ``L_c`` (n = 1) + ``M_z`` from the faces, against libigl's ``unique_edge_map`` +
  ``crouzeix_raviart_cotmatrix`` + ``crouzeix_raviart_massmatrix`` (the scalar
  Crouzeix-Raviart Laplacian, the sparsity of ``L_c``), and the same with the edge map given;
* first ``EdgeOperators(v, f)`` (every operator);
* re-assembly of ``L_c + M_z`` for new positions on a cached topology, against one product
  ``L_c @ x`` (complex128).

Results: ``benchmarks/results/bench_operators.md`` and ``.json`` (``--output``).
Peer packages: ``pip install -r benchmarks/requirements-peers.txt``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"
MESHES = ("trimesh_ico6", "random_sphere", "spot", "rna", "ico6")
THREAD_VARS = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "IGL_NUM_THREADS")
TARGET_FIRST_VS_IGL = 1.0
TARGET_UPDATE_VS_MATVEC = 3.0
TARGET_PEAK_BYTES = 4 * 10**9


def timed(fn):
    """``(wall, cpu)`` seconds of one call of ``fn``; the result is dropped inside."""
    import gc

    gc.collect()
    c0, t0 = time.process_time(), time.perf_counter()
    out = fn()
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    del out
    return wall, cpu


def interleaved(fns: dict, rounds: int, warmup: int = 1) -> dict:
    """``{name: {"wall": [...], "cpu": [...]}}``: the callables run in turn, ``rounds`` times."""
    out = {name: {"wall": [], "cpu": []} for name in fns}
    for r in range(warmup + rounds):
        for name, fn in fns.items():
            wall, cpu = timed(fn)
            if r >= warmup:
                out[name]["wall"].append(wall)
                out[name]["cpu"].append(cpu)
    return out


def worker(names: list[str], rounds: int) -> dict:
    """Time every mesh in this process (threads set by the parent's environment)."""
    import igl
    import numpy as np
    import torch
    from meshes import mesh

    threads = int(os.environ["OMP_NUM_THREADS"])
    torch.set_num_threads(threads)
    import torch_edgevf as ev

    results = {"threads": threads, "torch_threads": torch.get_num_threads(), "meshes": {}}
    for name in names:
        v, f = mesh(name)
        vt, ft = torch.from_numpy(v), torch.from_numpy(f)
        load0 = os.getloadavg()[0]

        def ours():
            topo = ev.Topology(ft, num_vertices=vt.shape[0])
            return ev.connection_laplacian(vt, topo, 1), ev.mass_matrix(vt, topo)

        def peer():
            _, ue, emap = igl.unique_edge_map(f)[:3]
            return igl.crouzeix_raviart_cotmatrix(v, f, ue, emap), igl.crouzeix_raviart_massmatrix(
                v, f, ue, emap
            )

        _, ue, emap = igl.unique_edge_map(f)[:3]

        def peer_cached():
            return igl.crouzeix_raviart_cotmatrix(v, f, ue, emap), igl.crouzeix_raviart_massmatrix(
                v, f, ue, emap
            )

        first = interleaved({"ours": ours, "igl": peer, "igl_cached": peer_cached}, rounds)
        every = interleaved({"all": lambda: ev.EdgeOperators(vt, ft, n=1)}, max(3, rounds // 2))
        # re-assembly gets new positions every call (equal positions would be a memo hit)
        topo = ev.Topology(ft, num_vertices=vt.shape[0])
        rng = np.random.default_rng(0)
        extent = float(np.ptp(v, axis=0).max())
        moved = [torch.from_numpy(v + 1e-3 * extent * rng.standard_normal(v.shape)) for _ in range(3)]
        state = {"i": 0}

        def update():
            state["i"] += 1
            w = moved[state["i"] % 3]
            return ev.connection_laplacian(w, topo, 1), ev.mass_matrix(w, topo)

        lc = ev.connection_laplacian(vt, topo, 1)
        gen = torch.Generator().manual_seed(0)
        x = torch.randn(topo.num_edges, dtype=torch.complex128, generator=gen)
        again = interleaved({"update": update, "matvec": lambda: lc @ x}, rounds)
        results["meshes"][name] = {
            "vertices": int(v.shape[0]),
            "faces": int(f.shape[0]),
            "edges": topo.num_edges,
            "load_before": load0,
            "cr_max_abs_diff": _compare_with_igl(ev, v, f, ue, emap) if f.shape[0] < 500_000 else None,
            **first,
            **every,
            **again,
        }
    return results


def _compare_with_igl(ev, v, f, ue, emap) -> float:
    """max |L_c^(0) - libigl's CR Laplacian| after matching the edge orders (they agree)."""
    import igl
    import numpy as np
    import torch

    from torch_edgevf.linalg import to_scipy

    topo = ev.Topology(torch.from_numpy(f), num_vertices=len(v))
    l0 = to_scipy(ev.connection_laplacian(torch.from_numpy(v), topo, 0))
    nv = len(v)
    ours = topo.edges.numpy()
    perm = np.searchsorted(ours[:, 0] * nv + ours[:, 1], ue.min(1) * nv + ue.max(1))
    return float(abs(l0[perm][:, perm] - igl.crouzeix_raviart_cotmatrix(v, f, ue, emap)).max())


def memory_worker(name: str) -> dict:
    """Peak RSS of the first ``EdgeOperators(v, f)`` on one mesh, in a process of its own."""
    import resource

    import torch
    from meshes import mesh

    import torch_edgevf as ev

    v, f = mesh(name)
    ops = ev.EdgeOperators(torch.from_numpy(v), torch.from_numpy(f), n=1)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    return {"mesh": name, "faces": int(f.shape[0]), "edges": ops.num_edges, "peak_rss": peak}


def run_worker(args: list[str], threads: int) -> dict:
    import subprocess

    env = {**os.environ, **{k: str(threads) for k in THREAD_VARS}}
    proc = subprocess.run(
        [sys.executable, str(Path(__file__).resolve()), *args], env=env, stdout=subprocess.PIPE, text=True
    )
    if proc.returncode != 0:
        raise RuntimeError(f"worker {args} failed with exit code {proc.returncode}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _median(xs):
    import statistics

    return statistics.median(xs)


def report(runs: dict, info: dict, memory: dict | None) -> str:
    from common import fmt_time, markdown_table

    lines = [
        "## torch_edgevf operator benchmark",
        "",
        f"Command: `{info['command']}`",
        "",
        f"Machine: {info['cores']} cores ({info['cpu']}); torch {info['torch']}, numpy {info['numpy']}, "
        f"scipy {info['scipy']}, libigl {info['igl']}; Python {info['python']}. "
        f"1-minute load average {info['load_start']} at the start, {info['load_end']} at the end "
        f"({info['seconds']:.0f} s). Medians of {info['rounds']} interleaved rounds (ours, libigl, ...); "
        "wall time, and process CPU time in brackets; ratios are ours / reference. `L_c` is n = 1 "
        "(complex128), meshes float64. Each thread count runs in a worker of its own with "
        "`OMP_NUM_THREADS`, `MKL_NUM_THREADS`, `OPENBLAS_NUM_THREADS`, `IGL_NUM_THREADS` and "
        "`torch.set_num_threads` set to it.",
        "",
    ]
    for threads, run in runs.items():
        meshes = run["meshes"]
        headers = [f"{threads} thread(s): median wall (CPU)"] + [
            f"{name} ({m['faces']:,} F, {m['edges']:,} E)" for name, m in meshes.items()
        ]

        def t(key):
            return [
                f"{fmt_time(_median(m[key]['wall']))} ({fmt_time(_median(m[key]['cpu']))})"
                for m in meshes.values()
            ]

        def ratio(a, b, target=None):
            cells = []
            for m in meshes.values():
                rw = _median(m[a]["wall"]) / _median(m[b]["wall"])
                rc = _median(m[a]["cpu"]) / _median(m[b]["cpu"])
                mark = "" if target is None else (" met" if rw <= target else " **missed**")
                cells.append(f"**{rw:.2f}** ({rc:.2f}){mark}")
            return cells

        rows = [
            ["first L_c + M_z (Topology included)", *t("ours")],
            ["libigl CR Laplacian + mass (+ `unique_edge_map`)", *t("igl")],
            ["libigl CR Laplacian + mass (edge map given)", *t("igl_cached")],
            [
                f"**first L_c + M_z / libigl** (target <= {TARGET_FIRST_VS_IGL:g})",
                *ratio("ours", "igl", TARGET_FIRST_VS_IGL),
            ],
            ["first L_c + M_z / libigl with its edge map given", *ratio("ours", "igl_cached")],
            ["first `EdgeOperators(v, f)`, every operator", *t("all")],
            ["re-assembly L_c + M_z (topology cached)", *t("update")],
            ["one matvec `L_c @ x`, complex128", *t("matvec")],
            [
                f"**re-assembly / matvec** (target <= {TARGET_UPDATE_VS_MATVEC:g})",
                *ratio("update", "matvec", TARGET_UPDATE_VS_MATVEC),
            ],
            [
                "L_c^(0) vs libigl CR, max abs diff",
                *[
                    "-" if m["cr_max_abs_diff"] is None else f"{m['cr_max_abs_diff']:.1e}"
                    for m in meshes.values()
                ],
            ],
            ["1-min load average before the mesh", *[f"{m['load_before']:.1f}" for m in meshes.values()]],
        ]
        lines += [markdown_table(headers, rows), ""]
    if memory:
        peak = memory["peak_rss"]
        mark = "met" if peak < TARGET_PEAK_BYTES else "**missed**"
        lines += [
            f"Peak RSS of a process that builds `EdgeOperators` of {memory['mesh']} "
            f"({memory['faces']:,} faces): {peak / 1e9:.2f} GB "
            f"(target < {TARGET_PEAK_BYTES / 1e9:g} GB, {mark}).",
            "",
        ]
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--meshes", nargs="+", default=list(MESHES), help=f"default: {' '.join(MESHES)}")
    parser.add_argument(
        "--threads", nargs="+", default=["1", "all"], help="thread counts ('all': every core)"
    )
    parser.add_argument("--rounds", type=int, default=9, help="interleaved rounds per measurement")
    parser.add_argument("--quick", action="store_true", help="trimesh_ico6 alone, 5 rounds, one thread")
    parser.add_argument("--memory", action="store_true", help="peak RSS at 1.3M faces (icosphere 8)")
    parser.add_argument("--output", type=Path, default=RESULTS / "bench_operators.md")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--memory-worker", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    if args.worker:
        print(json.dumps(worker(args.meshes, args.rounds)))
        return 0
    if args.memory_worker:
        print(json.dumps(memory_worker(args.memory_worker)))
        return 0
    if args.quick:
        args.meshes, args.rounds, args.threads = ["trimesh_ico6"], 5, ["1"]
    from common import machine_info

    info = machine_info()
    info.update(load_start=round(os.getloadavg()[0], 1), rounds=args.rounds)
    given = sys.argv[1:] if argv is None else argv
    info["command"] = " ".join(["python benchmarks/bench_operators.py", *given])
    t0 = time.perf_counter()
    runs = {}
    for spec in args.threads:
        threads = os.cpu_count() if spec == "all" else int(spec)
        runs[threads] = run_worker(
            ["--worker", "--meshes", *args.meshes, "--rounds", str(args.rounds)], threads
        )
    memory = run_worker(["--memory-worker", "ico8"], os.cpu_count()) if args.memory else None
    info.update(load_end=round(os.getloadavg()[0], 1), seconds=time.perf_counter() - t0)
    text = report(runs, info, memory)
    print(text)
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(text + "\n")
    args.output.with_suffix(".json").write_text(
        json.dumps({"info": info, "runs": runs, "memory": memory}, indent=1)
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
