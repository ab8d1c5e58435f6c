"""24 smallest eigenpairs of the connection Laplacian, torch_edgevf against SciPy, one thread each.

Run from the repository root::

    python benchmarks/bench_eigsh.py                          # 3 runs of 5 rounds, four meshes
    python benchmarks/bench_eigsh.py --runs 1 --rounds 3 --meshes spot

What a user meets: ``L_c`` (n = 1) and ``M_z`` of ``EdgeOperators(v, f)`` on meshes numbered
by the tools that made them (:mod:`meshes`), then ``torch_edgevf.linalg.eigsh(L_c, M_z,
24)`` with its defaults, against ``scipy.sparse.linalg.eigsh(A, 24, M, sigma=-1e-2)`` with
SciPy's defaults (shift-invert with SuperLU, ARPACK; ``tol=0``) on the same matrices. Each
run is a fresh worker process with ``OMP_NUM_THREADS``, ``OPENBLAS_NUM_THREADS``,
``MKL_NUM_THREADS`` = 1 set before any import and ``torch.set_num_threads(1)``; inside, the
two sides alternate (ours, SciPy, ours, ...) ``--rounds`` times and the medians are kept.
Wall and process CPU time are both recorded; on a loaded machine the CPU time of a
single-threaded process is the steadier figure. The eigenvalues of the two sides are compared.

Results: ``benchmarks/results/bench_eigsh.md`` (``--output``).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"
MESHES = ("random_sphere", "spot", "trimesh_ico6", "rna")
THREAD_VARS = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")
TARGET = 0.5
K = 24
SIGMA = -1e-2


def worker(names: list[str], rounds: int) -> dict:
    import numpy as np
    import scipy.sparse.linalg as sla
    import torch

    torch.set_num_threads(1)
    from meshes import mesh

    import torch_edgevf as ev
    from torch_edgevf.linalg import eigsh, to_scipy

    out = {}
    for name in names:
        v, f = mesh(name)
        ops = ev.EdgeOperators(torch.from_numpy(v), torch.from_numpy(f), n=1)
        L, Mz = ops.connection_laplacian.detach().coalesce(), ops.mass.detach().coalesce()
        A, M = to_scipy(L).tocsc(), to_scipy(Mz).tocsc()
        res: dict = {"ours": {"wall": [], "cpu": []}, "scipy": {"wall": [], "cpu": []}}
        found = {}

        def ours():
            return eigsh(L, Mz, K).values.numpy()

        def scipy_side():
            return np.sort(sla.eigsh(A, K, M, sigma=SIGMA)[0].real)

        for r in range(rounds + 1):  # the first round warms up
            for side, fn in (("ours", ours), ("scipy", scipy_side)):
                c0, t0 = time.process_time(), time.perf_counter()
                found[side] = fn()
                wall, cpu = time.perf_counter() - t0, time.process_time() - c0
                if r:
                    res[side]["wall"].append(wall)
                    res[side]["cpu"].append(cpu)
        scale = float(np.abs(found["scipy"]).max())
        out[name] = {
            "vertices": int(v.shape[0]),
            "edges": int(A.shape[0]),
            "max_eigenvalue_diff": float(np.abs(found["ours"] - found["scipy"]).max()) / scale,
            **res,
        }
    return {"meshes": out, "load": os.getloadavg()[0]}


def run_worker(names: list[str], rounds: int) -> dict:
    env = {**os.environ, **{k: "1" for k in THREAD_VARS}}
    args = [
        sys.executable,
        str(Path(__file__).resolve()),
        "--worker",
        "--meshes",
        *names,
        "--rounds",
        str(rounds),
    ]
    proc = subprocess.run(args, env=env, stdout=subprocess.PIPE, text=True, check=True)
    return json.loads(proc.stdout.strip().splitlines()[-1])


def report(runs: list[dict], info: dict, command: str) -> str:
    from common import fmt_time, markdown_table

    names = list(runs[0]["meshes"])
    lines = [
        "## 24 smallest eigenpairs of (L_c, M_z): torch_edgevf.linalg.eigsh / SciPy shift-invert eigsh",
        "",
        f"Command: `{command}`",
        "",
        f"Machine: {info['cores']} cores ({info['cpu']}), shared with other work (1-minute load "
        f"average {info['load_start']} at the start, {info['load_end']} at the end); torch {info['torch']}, "
        f"scipy {info['scipy']}. One thread each side; {len(runs)} runs (fresh processes) of "
        f"{info['rounds']} interleaved rounds, medians per run. Ratios are ours / SciPy: process CPU "
        "time first, wall time in brackets (the wall time of a loaded machine counts the other "
        f"processes' turns). SciPy: `eigsh(A, {K}, M, sigma={SIGMA:g})`, its defaults otherwise (`tol=0`). "
        f"Target <= {TARGET:g} in every run.",
        "",
    ]
    headers = [
        "mesh (V, E)",
        *[f"run {i + 1}: ours / SciPy" for i in range(len(runs))],
        "ours (CPU)",
        "SciPy (CPU)",
        "eigenvalues, max rel. diff",
        "target",
    ]
    rows = []
    for name in names:
        ratios, met = [], True
        for run in runs:
            m = run["meshes"][name]
            rc = statistics.median(m["ours"]["cpu"]) / statistics.median(m["scipy"]["cpu"])
            rw = statistics.median(m["ours"]["wall"]) / statistics.median(m["scipy"]["wall"])
            met &= rc <= TARGET
            ratios.append(f"**{rc:.2f}** ({rw:.2f})")
        m = runs[-1]["meshes"][name]
        rows.append(
            [
                f"{name} ({m['vertices']:,}, {m['edges']:,})",
                *ratios,
                fmt_time(statistics.median(m["ours"]["cpu"])),
                fmt_time(statistics.median(m["scipy"]["cpu"])),
                f"{max(r['meshes'][name]['max_eigenvalue_diff'] for r in runs):.1e}",
                "met" if met else "**missed**",
            ]
        )
    lines += [markdown_table(headers, rows), ""]
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--meshes", nargs="+", default=list(MESHES))
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--output", type=Path, default=RESULTS / "bench_eigsh.md")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    if args.worker:
        print(json.dumps(worker(args.meshes, args.rounds)))
        return 0
    from common import machine_info

    info = machine_info()
    info.update(load_start=round(os.getloadavg()[0], 1), rounds=args.rounds)
    runs = [run_worker(args.meshes, args.rounds) for _ in range(args.runs)]
    info.update(load_end=round(os.getloadavg()[0], 1))
    command = "python benchmarks/bench_eigsh.py " + " ".join(sys.argv[1:] if argv is None else argv)
    text = report(runs, info, command.strip())
    print(text)
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(text + "\n")
    args.output.with_suffix(".json").write_text(json.dumps({"info": info, "runs": runs}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
