"""Assembly, re-assembly, matvec and memory of the edge-based operators.

Run from the repository root::

    python benchmarks/bench_operators.py            # spot, icosphere level 6 and level 8
    python benchmarks/bench_operators.py --quick    # spot and level 6 only (smoke test)

Each mesh is measured in fresh processes: one for torch_edgevf (whose peak RSS is the
memory figure) and one for the peers (libigl, scipy). For each mesh it times

* first assembly of every operator, ``EdgeOperators(v, f)``, topology included;
* first assembly of ``L_c`` (n = 1) and ``M_z`` alone, ``Topology`` build included;
* re-assembly for new positions: ``ops.update(v)``, and ``L_c + M_z`` on a cached topology;
* one product ``L_c @ x`` with a complex128 ``x``: torch COO, torch CSR, scipy CSR;
* libigl's scalar Crouzeix-Raviart Laplacian + mass (the same sparsity as ``L_c``), with
  and without its edge map (``igl.unique_edge_map``), and ``cotmatrix + massmatrix``;

and reports medians, the ratios against their targets, and peak RSS.
Peer packages: ``pip install -r benchmarks/requirements.txt``.
"""

from __future__ import annotations

import argparse
import gc
import itertools
import logging
import sys
from pathlib import Path

import numpy as np

from common import (
    SHARED_MESHES,
    PeakMemory,
    current_rss_bytes,
    emit,
    fmt_bytes,
    fmt_time,
    load_mesh,
    machine_info,
    markdown_table,
    peak_rss_bytes,
    run_worker,
    time_it,
)

log = logging.getLogger("bench_operators")

ALLOCATOR_ENV = "EDGEVF_BENCH_ALLOCATOR"
TARGET_FIRST_VS_IGL = 1.0
TARGET_UPDATE_VS_MATVEC = 3.0
TARGET_PEAK_BYTES = 4 * 10**9
SEED = 0


def _import_edgevf():
    """torch_edgevf, from the environment or, failing that, from this source checkout."""
    try:
        import torch_edgevf
    except ImportError:  # not installed: run against the checkout this script lives in
        sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
        import torch_edgevf
    return torch_edgevf


# --------------------------------------------------------------------------- meshes


def mesh_arrays(name: str) -> tuple[np.ndarray, np.ndarray]:
    """``(verts float64, faces int64)`` numpy arrays of a named benchmark mesh."""
    if name.startswith("ico"):
        ev = _import_edgevf()
        v, f = ev.icosphere(int(name[3:]))
        return v.numpy(), f.numpy()
    _import_edgevf()  # so that load_mesh finds torch_edgevf.io from a plain checkout too
    path = SHARED_MESHES / f"{name}.obj"
    if not path.is_file():
        raise FileNotFoundError(f"benchmark mesh {path} is missing")
    return load_mesh(path)


def perturbed(verts: np.ndarray, scale: float = 1e-3, seed: int = SEED) -> np.ndarray:
    """Positions moved by a fixed-seed noise (a fraction of the bounding box) for update()."""
    rng = np.random.default_rng(seed)
    extent = float(np.ptp(verts, axis=0).max())
    return verts + scale * extent * rng.standard_normal(verts.shape)


def repeats_for(num_faces: int) -> tuple[int, int]:
    """(repeats of assemblies, repeats of a matvec); fewer on large meshes."""
    return (7, 30) if num_faces < 500_000 else (3, 10)


# --------------------------------------------------------------------------- workers


def _maybe_tune_allocator() -> None:
    """Apply ``torch_edgevf.tune_allocator()`` when the parent asked for ``--allocator tuned``."""
    import os

    if os.environ.get(ALLOCATOR_ENV) == "tuned" and not _import_edgevf().tune_allocator():
        raise RuntimeError("--allocator tuned needs glibc (mallopt)")


def worker_edgevf(name: str) -> dict:
    """Time torch_edgevf on one mesh; peak RSS of this process is the memory figure."""
    import torch

    ev = _import_edgevf()
    _maybe_tune_allocator()
    base_rss = current_rss_bytes()
    v_np, f_np = mesh_arrays(name)
    v = torch.from_numpy(v_np)
    f = torch.from_numpy(f_np)
    # re-assembly gets new positions on every call: torch_edgevf reuses the face geometry of
    # equal positions (without autograd), which would otherwise turn re-assembly into a cache hit
    moved = itertools.cycle([torch.from_numpy(perturbed(v_np, seed=SEED + 1 + k)) for k in range(3)])
    nf = int(f.shape[0])
    reps, mv_reps = repeats_for(nf)
    out = {
        "mesh": name,
        "faces": nf,
        "vertices": int(v.shape[0]),
        "rss_after_load": current_rss_bytes(),
        "rss_after_import": base_rss,
        "threads": torch.get_num_threads(),
    }
    peaks = {}

    def first_lc_mz():
        topo = ev.Topology(f, num_vertices=v.shape[0])
        return ev.connection_laplacian(v, topo, 1), ev.mass_matrix(v, topo)

    with PeakMemory() as pm:
        t_first_lc = time_it("first L_c+M_z (+topology)", first_lc_mz, repeats=reps)
    peaks["first_lc_mz"] = pm.peak

    def topology():
        return ev.Topology(f, num_vertices=v.shape[0])

    t_topo = time_it("Topology build", topology, repeats=reps)

    with PeakMemory() as pm:
        t_first_all = time_it("first EdgeOperators", lambda: ev.EdgeOperators(v, f, n=1), repeats=reps)
    peaks["first_all"] = pm.peak

    ops = ev.EdgeOperators(v, f, n=1)
    topo = ops.topology
    out["edges"] = topo.num_edges
    with PeakMemory() as pm:
        t_update = time_it("update() all", lambda: ops.update(next(moved)), repeats=reps)
    peaks["update_all"] = pm.peak

    def update_lc_mz():
        w = next(moved)
        return ev.connection_laplacian(w, topo, 1), ev.mass_matrix(w, topo)

    t_update_lc = time_it("re-assembly L_c+M_z", update_lc_mz, repeats=reps)
    t_update_lc_only = time_it(
        "re-assembly L_c", lambda: ev.connection_laplacian(next(moved), topo, 1), repeats=reps
    )

    lc = ev.connection_laplacian(v, topo, 1)
    gen = torch.Generator().manual_seed(SEED)
    x = torch.complex(
        torch.randn(topo.num_edges, generator=gen, dtype=torch.float64),
        torch.randn(topo.num_edges, generator=gen, dtype=torch.float64),
    )
    t_mv = time_it("matvec torch COO", lambda: lc @ x, repeats=mv_reps, warmup=3)
    lc_csr = lc.to_sparse_csr()
    t_mv_csr = time_it("matvec torch CSR", lambda: lc_csr @ x, repeats=mv_reps, warmup=3)
    out["peak_rss"] = peak_rss_bytes()  # before the scipy copy below
    out["peak_rss_stages"] = peaks
    out["hwm_exact"] = pm.exact

    from torch_edgevf.linalg import to_scipy

    a = to_scipy(lc)
    xn = x.numpy()
    t_mv_scipy = time_it("matvec scipy CSR", lambda: a @ xn, repeats=mv_reps, warmup=3)
    check = float(np.abs((lc @ x).numpy() - a @ xn).max())
    out["timings"] = {
        t.name: t
        for t in (
            t_first_lc,
            t_topo,
            t_first_all,
            t_update,
            t_update_lc,
            t_update_lc_only,
            t_mv,
            t_mv_csr,
            t_mv_scipy,
        )
    }
    out["matvec_agreement"] = check
    out["nnz_lc"] = int(lc._nnz())
    return out


def worker_peers(name: str, check: bool) -> dict:
    """Time libigl on one mesh (and check our scalar L_c^(0) against its CR Laplacian)."""
    import igl

    _maybe_tune_allocator()
    v, f = mesh_arrays(name)
    reps, _ = repeats_for(f.shape[0])
    out = {"mesh": name, "igl": getattr(igl, "__version__", "?")}

    def cr_first():
        _, ue, emap = igl.unique_edge_map(f)[:3]
        return igl.crouzeix_raviart_cotmatrix(v, f, ue, emap), igl.crouzeix_raviart_massmatrix(v, f, ue, emap)

    _, ue, emap = igl.unique_edge_map(f)[:3]

    def cr_cached():
        return igl.crouzeix_raviart_cotmatrix(v, f, ue, emap), igl.crouzeix_raviart_massmatrix(v, f, ue, emap)

    def cot():
        return igl.cotmatrix(v, f), igl.massmatrix(v, f)

    timings = [
        time_it("igl CR L+M (+edge map)", cr_first, repeats=reps),
        time_it("igl CR L+M", cr_cached, repeats=reps),
        time_it("igl edge map", lambda: igl.unique_edge_map(f), repeats=reps),
        time_it("igl cot L+M", cot, repeats=reps),
    ]
    out["timings"] = {t.name: t for t in timings}
    out["peak_rss"] = peak_rss_bytes()
    if check:
        out["cr_max_abs_diff"] = _compare_with_igl(v, f, ue, emap)
    return out


def _compare_with_igl(v, f, ue, emap) -> float:
    """max |L_c^(0) - igl CR Laplacian| after matching edge orders (they should agree)."""
    import igl
    import torch

    ev = _import_edgevf()
    topo = ev.Topology(torch.from_numpy(f), num_vertices=len(v))
    l0 = ev.connection_laplacian(torch.from_numpy(v), topo, 0)
    nv = len(v)
    ours = topo.edges.numpy()
    key_ours = ours[:, 0] * nv + ours[:, 1]
    key_igl = ue.min(1) * nv + ue.max(1)
    perm = np.searchsorted(key_ours, key_igl)
    from torch_edgevf.linalg import to_scipy

    mine = to_scipy(l0)[perm][:, perm]
    theirs = igl.crouzeix_raviart_cotmatrix(v, f, ue, emap)
    return float(abs(mine - theirs).max())


# --------------------------------------------------------------------------- report


def _median(result: dict, key: str) -> float | None:
    t = result.get("timings", {}).get(key)
    return None if t is None else t["median"]


def report(cases: list[str], results: dict, info: dict) -> str:
    cols = []
    for name in cases:
        ours, peers = results[name]["edgevf"], results[name].get("peers", {})
        cols.append((name, ours, peers))

    def row(label, fn):
        return [label] + [fn(o, p) for _, o, p in cols]

    def t(key, src="o"):
        def cell(o, p):
            timing = (o if src == "o" else p).get("timings", {}).get(key)
            if timing is None:
                return "-"
            return f"{fmt_time(timing['median'])} ({fmt_time(timing['min'])})"

        return cell

    def ratio(num, den, target=None, num_src="o", den_src="p"):
        def cell(o, p):
            a = _median(o if num_src == "o" else p, num)
            b = _median(o if den_src == "o" else p, den)
            if a is None or b is None:
                return "-"
            r = a / b
            if target is None:
                return f"{r:.2f}"
            return f"**{r:.2f}** {'ok' if r <= target else 'MISS'}"

        return cell

    def peak(o, p):
        value = o.get("peak_rss")
        mark = "ok" if value is not None and value < TARGET_PEAK_BYTES else "MISS"
        return f"**{fmt_bytes(value)}** ({value / 1e9:.2f} GB) {mark}" if value is not None else "-"

    headers = ["measurement: median (min)"] + [
        f"{name} ({o['faces']:,} F, {o['edges']:,} E)" for name, o, _ in cols
    ]
    rows = [
        row("first assembly, all operators `EdgeOperators(v, f)`", t("first EdgeOperators")),
        row("first assembly, L_c + M_z (Topology included)", t("first L_c+M_z (+topology)")),
        row("  of which Topology build", t("Topology build")),
        row("libigl CR Laplacian + mass (+ `unique_edge_map`)", t("igl CR L+M (+edge map)", "p")),
        row("libigl CR Laplacian + mass (edge map given)", t("igl CR L+M", "p")),
        row("libigl cotmatrix + massmatrix (reference)", t("igl cot L+M", "p")),
        row("re-assembly, all operators `ops.update(v)`", t("update() all")),
        row("re-assembly, L_c + M_z (topology cached)", t("re-assembly L_c+M_z")),
        row("re-assembly, L_c alone", t("re-assembly L_c")),
        row("matvec `L_c @ x` complex128, torch COO", t("matvec torch COO")),
        row("matvec, torch CSR (reference)", t("matvec torch CSR")),
        row("matvec, scipy CSR (reference)", t("matvec scipy CSR")),
        row(
            f"**first L_c+M_z / libigl CR (+edge map)** (target <= {TARGET_FIRST_VS_IGL:g})",
            ratio("first L_c+M_z (+topology)", "igl CR L+M (+edge map)", TARGET_FIRST_VS_IGL),
        ),
        row("first L_c+M_z / libigl CR (edge map given)", ratio("first L_c+M_z (+topology)", "igl CR L+M")),
        row(
            f"**re-assembly L_c+M_z / matvec** (target <= {TARGET_UPDATE_VS_MATVEC:g})",
            ratio("re-assembly L_c+M_z", "matvec torch COO", TARGET_UPDATE_VS_MATVEC, den_src="o"),
        ),
        row("re-assembly all / matvec", ratio("update() all", "matvec torch COO", den_src="o")),
        row("re-assembly L_c+M_z / libigl CR (edge map given)", ratio("re-assembly L_c+M_z", "igl CR L+M")),
        row(f"**peak RSS, torch_edgevf process** (target < {TARGET_PEAK_BYTES / 1e9:g} GB)", peak),
        row("  peak in first `EdgeOperators`", lambda o, p: fmt_bytes(o["peak_rss_stages"].get("first_all"))),
        row("  peak in first L_c + M_z", lambda o, p: fmt_bytes(o["peak_rss_stages"].get("first_lc_mz"))),
        row("  RSS after imports and mesh", lambda o, p: fmt_bytes(o.get("rss_after_load"))),
        row("peak RSS, libigl process", lambda o, p: fmt_bytes(p.get("peak_rss"))),
        row(
            "L_c^(0) vs libigl CR, max abs diff",
            lambda o, p: "-" if p.get("cr_max_abs_diff") is None else f"{p['cr_max_abs_diff']:.1e}",
        ),
        row("repeats (assembly / matvec)", lambda o, p: "{} / {}".format(*repeats_for(o["faces"]))),
        row("1-min load average before the run", lambda o, p: f"{o.get('load_before', 0):.1f}"),
    ]
    mem = info.get("memory_bytes")
    lines = [
        "## torch_edgevf operator benchmark",
        "",
        f"Machine: {info['cores']} cores ({info['cpu']}), {fmt_bytes(mem)} RAM, {info['platform']}; "
        f"load average at start {info.get('load_average')}.",
        f"torch {info['torch']} ({info.get('torch_threads')} intra-op threads, default), "
        f"numpy {info['numpy']}, "
        f"scipy {info['scipy']}, libigl {info.get('igl')}; Python {info['python']}. "
        "Meshes are float64; `L_c` is n = 1 (complex128). "
        f"OMP_WAIT_POLICY={info.get('omp_wait_policy')} in the workers (on a shared, loaded machine "
        "spinning OpenMP threads stall every small parallel op: use PASSIVE there); "
        f"allocator: {info.get('allocator')} (`tuned` = `torch_edgevf.tune_allocator()` in both workers, "
        "which lets glibc reuse freed memory instead of faulting fresh pages in).",
        "",
        markdown_table(headers, rows),
        "",
        "Peak RSS is the whole torch_edgevf process (Python, torch, the mesh, every repeat), "
        "measured with `/proc/self/status` VmHWM per stage and `ru_maxrss` overall.",
    ]
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="spot and icosphere level 6 only")
    parser.add_argument("--worker", choices=["edgevf", "peers"], help=argparse.SUPPRESS)
    parser.add_argument("--mesh", help=argparse.SUPPRESS)
    parser.add_argument("--check", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--no-peers", action="store_true", help="skip libigl")
    parser.add_argument("--output", type=Path, help="also write the markdown report here")
    parser.add_argument(
        "--omp-wait-policy",
        default="default",
        help="OMP_WAIT_POLICY of the workers ('default' leaves it unset; PASSIVE on a shared, "
        "loaded machine)",
    )
    parser.add_argument(
        "--allocator",
        choices=["default", "tuned"],
        default="default",
        help="'tuned' calls torch_edgevf.tune_allocator() in both workers (ours and libigl's)",
    )
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s", stream=sys.stderr)

    if args.worker == "edgevf":
        emit(worker_edgevf(args.mesh))
        return 0
    if args.worker == "peers":
        emit(worker_peers(args.mesh, args.check))
        return 0

    cases = ["spot", "ico6"] if args.quick else ["spot", "ico6", "ico8"]
    import torch  # noqa: F401  (machine_info reports its version and thread count)

    info = machine_info()  # load average before the runs
    env = {} if args.omp_wait_policy.lower() == "default" else {"OMP_WAIT_POLICY": args.omp_wait_policy}
    info["omp_wait_policy"] = env.get("OMP_WAIT_POLICY", "unset")
    env[ALLOCATOR_ENV] = info["allocator"] = args.allocator
    results = {}
    script = Path(__file__).resolve()
    for name in cases:
        results[name] = {"edgevf": run_worker([script, "--worker", "edgevf", "--mesh", name], env=env)}
        if not args.no_peers:
            check = ["--check"] if results[name]["edgevf"]["faces"] < 500_000 else []
            results[name]["peers"] = run_worker(
                [script, "--worker", "peers", "--mesh", name, *check], env=env
            )
        gc.collect()
    text = report(cases, results, info)
    print(text)
    if args.output is not None:
        args.output.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
