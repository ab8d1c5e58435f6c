"""Time to the smoothest 4-direction field, next to one Cholesky factorization.

Run from the repository root::

    python benchmarks/bench_design.py                 # spot.obj and icosphere level 8
    python benchmarks/bench_design.py --quick         # spot.obj and icosphere level 6
    python benchmarks/bench_design.py --levels 6 7 8 --timeout 900

Each mesh runs in a fresh process (so that one mesh's memory does not weigh on the next)
that reports, as soon as each is measured:

* ``build``: ``FieldDesigner(verts, faces, n=4)`` -- topology, ``L_c^(4)`` and ``M_z``;
* ``smoothest``: ``designer.smoothest()`` -- the shift-invert Lanczos of
  :func:`torch_edgevf.linalg.eigsh` for ``k = 1``, which factors ``L_c - sigma M_z`` once;
* ``factor``: one Cholesky factorization of that same matrix ``L_c - sigma M_z`` (same
  default shift) with :func:`torch_edgevf.linalg.factorize` -- the floor the eigensolve
  cannot beat;
* the ratio ``smoothest / factor`` and the eigenvalue.

A mesh whose process exceeds ``--timeout`` seconds is reported with what it measured.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import subprocess
import sys
import time
from pathlib import Path

from common import SHARED_MESHES

log = logging.getLogger("bench_design")

REPO = Path(__file__).resolve().parents[1]
SPOT = SHARED_MESHES / "spot.obj"


def _emit(**record) -> None:
    print(json.dumps(record), flush=True)


def worker(mesh: str) -> None:
    """Measure one mesh and print one JSON line per measurement."""
    sys.path.insert(0, str(REPO))
    import scipy.sparse
    import torch

    from torch_edgevf.fields.design import FieldDesigner
    from torch_edgevf.linalg import factorize, to_scipy
    from torch_edgevf.linalg.eigen import default_shift
    from torch_edgevf.linalg.factor import cholmod_module

    if mesh == "spot":
        from torch_edgevf.io import load_mesh

        data = load_mesh(SPOT)
        verts, faces = data.verts, data.faces
    else:
        from torch_edgevf import icosphere

        verts, faces = icosphere(int(mesh.removeprefix("icosphere")))
    _emit(
        mesh=mesh,
        what="mesh",
        vertices=int(verts.shape[0]),
        faces=int(faces.shape[0]),
        threads=torch.get_num_threads(),
        cholmod=cholmod_module() is not None,
    )

    t0 = time.perf_counter()
    designer = FieldDesigner(verts, faces, n=4)
    _emit(mesh=mesh, what="build", seconds=time.perf_counter() - t0, edges=designer.num_edges)

    t0 = time.perf_counter()
    z, lam = designer.smoothest(return_eigenvalue=True)
    smoothest = time.perf_counter() - t0
    _emit(
        mesh=mesh,
        what="smoothest",
        seconds=smoothest,
        eigenvalue=float(lam),
        rayleigh=float(designer.rayleigh_quotient(z)),
    )

    a = to_scipy(designer.laplacian)
    m = scipy.sparse.diags(designer.mass.detach().numpy()).tocsc()
    sigma = default_shift(a, m)
    k = (a - sigma * m).tocsc()
    t0 = time.perf_counter()
    fac = factorize(k, "cholesky", hermitian=True)
    factor = time.perf_counter() - t0
    _emit(mesh=mesh, what="factor", seconds=factor, backend=fac.backend, ratio=smoothest / factor)


def run(mesh: str, timeout: float) -> list[dict]:
    """Run the worker for ``mesh`` in a fresh process; keep what it printed before a timeout."""
    cmd = [sys.executable, __file__, "--worker", mesh]
    t0 = time.perf_counter()
    timed_out = False
    with subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True, cwd=REPO) as proc:
        try:
            out, _ = proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            out, _ = proc.communicate()
            timed_out = True
    records = [json.loads(line) for line in out.splitlines() if line.startswith("{")]
    if timed_out:
        records.append({"mesh": mesh, "what": "timeout", "seconds": time.perf_counter() - t0})
    return records


def report(records: list[dict]) -> str:
    """A markdown table, one row per mesh."""
    rows = [
        "| mesh | V | F | E | build | smoothest 4-field | one Cholesky (backend) | ratio | eigenvalue |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    by_mesh: dict = {}
    for r in records:
        by_mesh.setdefault(r["mesh"], {})[r["what"]] = r
    for mesh, rec in by_mesh.items():
        missing = "timeout" if "timeout" in rec else "-"

        def sec(key):
            return f"{rec[key]['seconds']:.2f} s" if key in rec else missing

        info, fac = rec.get("mesh", {}), rec.get("factor", {})
        cells = [
            mesh,
            info.get("vertices", "-"),
            info.get("faces", "-"),
            rec.get("build", {}).get("edges", "-"),
            sec("build"),
            sec("smoothest"),
            f"{sec('factor')} ({fac.get('backend', '-')})",
            f"{fac['ratio']:.2f}" if "ratio" in fac else "-",
            f"{rec['smoothest']['eigenvalue']:.6g}" if "smoothest" in rec else "-",
        ]
        rows.append("| " + " | ".join(str(c) for c in cells) + " |")
    return "\n".join(rows)


def main(argv=None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    parser.add_argument("--quick", action="store_true", help="icosphere level 6 instead of 8")
    parser.add_argument("--levels", type=int, nargs="*", help="icosphere levels (default: 8)")
    parser.add_argument("--no-spot", action="store_true")
    parser.add_argument("--timeout", type=float, default=600.0, help="seconds per mesh")
    parser.add_argument("--json", type=Path, help="also write the raw records here")
    args = parser.parse_args(argv)
    if args.worker:
        worker(args.worker)
        return []
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    levels = args.levels or ([6] if args.quick else [8])
    meshes = ([] if args.no_spot else ["spot"]) + [f"icosphere{lv}" for lv in levels]
    log.info("cores: %s, load average: %s", os.cpu_count(), os.getloadavg())
    records = []
    for mesh in meshes:
        log.info("measuring %s (timeout %.0f s)", mesh, args.timeout)
        got = run(mesh, args.timeout)
        for r in got:
            log.info("  %s", r)
        records += got
    log.info("\n%s", report(records))
    if args.json:
        args.json.write_text(json.dumps(records, indent=1))
    return records


if __name__ == "__main__":
    main()
