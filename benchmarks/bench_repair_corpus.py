"""Repair of every shared real mesh and every PSB mesh, end to end; writes results/repair_corpus.md.

For each mesh: read it as the file holds it (vertices merged by exact position), run
:func:`torch_edgevf.repair`, assemble ``L_c`` (n = 4) and ``M_z`` on the (mollified)
lengths, design the smoothest cross field and check Poincare-Hopf,
``sum of indices = chi + B`` (``B`` the boundary term of the singularities).

    python benchmarks/bench_repair_corpus.py [--no-psb]
"""

from __future__ import annotations

import argparse
import time
from collections import Counter
from pathlib import Path

import numpy as np
import torch

import torch_edgevf as ev
from torch_edgevf.io import read_triangles

from common import SHARED_MESHES

PSB = SHARED_MESHES.parent / "datasets" / "psb_watertight_2k.npz"
OUT = Path(__file__).resolve().parent / "results" / "repair_corpus.md"

KINDS = {
    "triangulated": lambda r: r.triangulated_faces,
    "repeated indices": lambda r: r.repeated_index_faces,
    "duplicate faces": lambda r: r.duplicate_faces,
    "orientation (faces flipped)": lambda r: r.flipped_faces,
    "non-manifold edges cut": lambda r: r.non_manifold_edges,
    "non-manifold vertices split": lambda r: r.non_manifold_vertices,
    "unreferenced vertices": lambda r: r.unreferenced_vertices,
    "mollified (zero-area or needle faces)": lambda r: r.mollified_faces,
}


def check(verts, faces) -> dict:
    t0 = time.perf_counter()
    result = ev.repair(verts, faces)
    geom, topo = result.geometry, result.topology
    lc = ev.connection_laplacian(geom, topo, n=4)
    mz = ev.mass_matrix(geom, topo)
    finite = bool(torch.isfinite(lc.values()).all() and torch.isfinite(mz.values()).all())
    z = ev.smoothest_field(geom, topo, n=4)
    s = ev.singularities(geom, topo, z, n=4)
    ph = abs(s.total - (topo.euler_characteristic + s.boundary_turning)) < 1e-6
    return {
        "result": result,
        "finite": finite,
        "ph": ph,
        "chi": topo.euler_characteristic,
        "total": s.total,
        "boundary": s.boundary_turning,
        "seconds": time.perf_counter() - t0,
    }


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--no-psb", action="store_true")
    args = parser.parse_args()
    rows, needs = [], Counter()
    files = sorted(SHARED_MESHES.glob("*.obj")) + sorted((SHARED_MESHES / "wild").glob("*.obj"))
    for path in files:
        verts, faces, _ = read_triangles(path, merge=True)
        out = check(verts, faces)
        rep = out["result"].report
        done = [k for k, get in KINDS.items() if get(rep)]
        needs.update(done)
        rows.append((path.relative_to(SHARED_MESHES).as_posix(), len(faces), done, out))
        print(
            f"{rows[-1][0]}: {', '.join(done) or 'nothing'}; finite {out['finite']}, PH {out['ph']}",
            flush=True,
        )
    psb_rows, psb_needs, psb_ok = [], Counter(), 0
    if PSB.exists() and not args.no_psb:
        with np.load(PSB) as data:
            verts, faces = data["verts"], data["faces"]
            vo, fo, ids = data["vert_offsets"], data["face_offsets"], data["psb_ids"]
        for k in range(len(ids)):
            v = verts[vo[k] : vo[k + 1]].astype(np.float64)
            f = faces[fo[k] : fo[k + 1]].astype(np.int64)
            out = check(v, f)
            done = [name for name, get in KINDS.items() if get(out["result"].report)]
            psb_needs.update(done)
            psb_ok += out["finite"] and out["ph"]
            if done:
                psb_rows.append((int(ids[k]), done))
    lines = [
        "# Repair corpus",
        "",
        "Every shared real mesh (`shared/meshes`, `shared/meshes/wild`) and every PSB mesh",
        "(`psb_watertight_2k.npz`), read as the file holds it (vertices merged by exact position),",
        "through `repair`, then `L_c` (n = 4) and `M_z` on the (mollified) edge lengths, the",
        "smoothest cross field and its singularities. PH: the indices sum to",
        "`chi + B` (`B` the boundary term, 0 on closed meshes). Written by",
        "`benchmarks/bench_repair_corpus.py`.",
        "",
        "| mesh | faces | repairs | components | chi | B | finite | PH | s |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, nf, done, out in rows:
        topo = out["result"].topology
        lines.append(
            f"| {name} | {nf} | {', '.join(done) or '-'} | {topo.num_components} | {out['chi']} | "
            f"{out['boundary']:.3g} | {'yes' if out['finite'] else 'NO'} | {'yes' if out['ph'] else 'NO'} | "
            f"{out['seconds']:.1f} |"
        )
    ok = sum(out["finite"] and out["ph"] for *_, out in rows)
    lines += ["", f"Shared meshes: {len(rows)}, {ok} end to end (finite operators, PH);"]
    lines.append(f"{sum(1 for r in rows if r[2])} needed a repair: " + _counts(needs) + ".")
    if psb_rows or psb_ok:
        n_psb = psb_ok if not psb_rows else len(ids)
        lines += [
            "",
            f"PSB: {n_psb} meshes, {psb_ok} end to end; {len(psb_rows)} needed a repair: "
            + _counts(psb_needs)
            + (" (psb ids " + ", ".join(str(i) for i, _ in psb_rows) + ")." if psb_rows else "."),
        ]
    OUT.write_text("\n".join(lines) + "\n")
    print(f"wrote {OUT}")


def _counts(c: Counter) -> str:
    return ", ".join(f"{k} {v}" for k, v in c.most_common()) or "none"


if __name__ == "__main__":
    main()
