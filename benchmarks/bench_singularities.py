"""Benchmark: singularity detection and the seamless (u, v) solve.

``python benchmarks/bench_singularities.py [--large]`` times, on Spot
(``spot.obj`` of ``common.SHARED_MESHES``, 23k faces) and with ``--large`` on icosphere(8)
(1.31M faces):

* ``singularities`` (region indices, n = 4),
* ``parametrize`` (split, cut, comb, least squares; with greedy rounding on Spot only).

The cross field is the smoothest one on Spot; on the icosphere, the 4th power of the
rotation field ``e_z x p`` (cones at the poles), to keep the eigen-solve out of the timing.
"""

from __future__ import annotations

import argparse
import logging
import time

import torch

import torch_edgevf as ev
from torch_edgevf.fields.param import parametrize
from torch_edgevf.fields.singularities import singularities
from torch_edgevf.mesh.topology import Topology

from common import SHARED_MESHES

log = logging.getLogger("bench_singularities")
SPOT = SHARED_MESHES / "spot.obj"


def timed(fn, repeats: int = 3):
    best, out = float("inf"), None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def rotation_cross_field(verts, topo):
    e = topo.edges
    p = (verts[e[:, 0]] + verts[e[:, 1]]) / 2
    w3 = torch.linalg.cross(torch.tensor([0.0, 0.0, 1.0], dtype=p.dtype).expand_as(p), p)
    w = ev.edges_from_vectors(verts, topo, w3)
    return w.abs() * torch.polar(torch.ones_like(w.real), 4 * torch.angle(w))


def run(name, verts, faces, z, round_integers, repeats):
    topo = Topology(faces, verts.shape[0])
    t_det, s = timed(lambda: singularities(verts, topo, z, n=4), repeats)
    t_par, P = timed(lambda: parametrize(verts, topo, z, round_integers=round_integers), 1)
    row = (
        f"| {name} | {topo.num_faces:,} | {t_det:.3f} | {s.num_singularities} | {s.total:g} | "
        f"{t_par:.2f} | {'yes' if round_integers else 'no'} | {P.flipped} |"
    )
    print(row, flush=True)
    return row


def main(large: bool = False, repeats: int = 3):
    print(
        "| mesh | faces | singularities (s) | singular regions | index sum | parametrize (s) "
        "| rounding | flipped |"
    )
    print("|---|---|---|---|---|---|---|---|")
    rows = []
    if SPOT.exists():
        from torch_edgevf.fields.design import smoothest_field
        from torch_edgevf.io import load_mesh

        v, f = load_mesh(SPOT)
        z = smoothest_field(v, f, n=4)
        rows.append(run("spot.obj", v, f, z, True, repeats))
    else:
        log.warning("%s not found, skipping", SPOT)
    if large:
        v, f = ev.icosphere(8)
        topo = Topology(f)
        z = rotation_cross_field(v, topo)
        rows.append(run("icosphere(8)", v, f, z, False, 1))
    return rows


if __name__ == "__main__":
    logging.basicConfig(level=logging.WARNING)
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--large", action="store_true", help="also run icosphere(8), 1.31M faces")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    main(args.large, args.repeats)
