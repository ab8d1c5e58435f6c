"""Quad meshes: ``torch_edgevf.quad_mesh`` against Instant Meshes, at the same vertex count.

Run from the repository root::

    pip install -r benchmarks/requirements-peers.txt     # pynanoinstantmeshes, libigl
    python benchmarks/bench_quad.py                      # the shared meshes + trimesh primitives
    python benchmarks/bench_quad.py --meshes bunny.obj --pictures docs/images
    python benchmarks/bench_quad.py --fields curvature --out benchmarks/results/quad_holes \
        --meshes "scipy holes 0" "scipy holes 1" "scipy holes 2" "scipy holes 3"
    python benchmarks/bench_quad.py --fields curvature --boundary soft \
        --out benchmarks/results/quad_holes_soft --meshes "scipy holes 0" ...

For every mesh, ours runs first (``quad_mesh`` with its defaults: the curvature-aligned
cross field, edge length = the input's mean edge length; also the smoothest field with
``--fields curvature smoothest``); Instant Meshes (Jakob et al. 2015, the
``pynanoinstantmeshes`` binding, 4-RoSy/4-PoSy, extrinsic, pure-quad output) is then asked
for the vertex count that makes its pure-quad output as large as ours: its quad-dominant
mesh is subdivided once at the end (every face split into 3, 4 or 5 quads), so it is asked
for a quarter of our count, and asked again once with the target scaled by the ratio
missed. Measured on both outputs, in the same way:

* irregular vertices: valence != 4 inside, != 2 on the boundary (open meshes: ours with
  ``boundary="hard"``, Instant Meshes with ``align_to_boundaries``);
* mean ``|corner angle - 90 deg|`` over all quad corners;
* distance to the input: from the output's vertices and quad centres (the mean of the
  four corners) to the input triangles (libigl's exact point-mesh distance), mean and
  max, and the Hausdorff distance sampled at the vertices of both meshes, each relative to
  the input's bounding-box diagonal;
* wall time of one call (Instant Meshes on its own threads; ours with one BLAS thread), and
  the ratio ours / Instant Meshes.

Each peer runs in this process, one after the other; loads are printed in the header.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import os
import shlex
import sys
import time
from pathlib import Path

import numpy as np

from common import SHARED_MESHES, machine_info, markdown_table

log = logging.getLogger("bench_quad")

SHARED = [
    "sphere.obj",
    "torus.obj",
    "spot_low_resolution.obj",
    "fish_low_resolution.obj",
    "bunny.obj",
    "wingnut.obj",
    "penguin.obj",
    "goathead.obj",
    "koala_low_resolution.obj",
    "skull_low_resolution.obj",
    "mountain.obj",
    "plane_holes.obj",
]
GENERATED = ["trimesh capsule", "trimesh torus", "trimesh icosphere", "trimesh box", "trimesh cylinder"]


def generated(name: str):
    import trimesh

    if name == "trimesh capsule":
        m = trimesh.creation.capsule(height=1.2, radius=0.5, count=[24, 24])
    elif name == "trimesh torus":
        m = trimesh.creation.torus(1.0, 0.4, major_sections=48, minor_sections=20)
    elif name == "trimesh icosphere":
        m = trimesh.creation.icosphere(subdivisions=4)
    elif name == "trimesh box":
        m = trimesh.creation.box(extents=(1.0, 0.6, 0.4)).subdivide().subdivide().subdivide().subdivide()
    elif name == "trimesh cylinder":
        m = trimesh.creation.cylinder(radius=0.5, height=1.2, sections=40)
        m = m.subdivide().subdivide()
    else:
        raise ValueError(name)
    return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)


def holes(seed: int, points: int = 3000, discs: int = 6):
    """An open height field with holes that no tool of ours made: SciPy's Delaunay
    triangulation of random points in a square (and on the circles of ``discs`` random discs),
    the triangles inside the discs removed; the boundaries of the holes are jagged where a
    random point lies close to a circle."""
    import scipy.spatial

    rng = np.random.default_rng(seed)
    pts = rng.uniform(-1, 1, (points, 2))
    centres, radii = rng.uniform(-0.7, 0.7, (discs, 2)), rng.uniform(0.08, 0.15, discs)
    keep = np.ones(len(pts), dtype=bool)
    for c, r in zip(centres, radii):
        keep &= np.linalg.norm(pts - c, axis=1) > r
    rings = [
        c + r * np.stack([np.cos(t), np.sin(t)], 1)
        for c, r in zip(centres, radii)
        for t in [np.linspace(0, 2 * np.pi, max(12, int(2 * np.pi * r / 0.04)), endpoint=False)]
    ]
    pts = np.concatenate([pts[keep], *rings])
    tri = scipy.spatial.Delaunay(pts).simplices
    centre = pts[tri].mean(1)
    inside = np.zeros(len(tri), dtype=bool)
    for c, r in zip(centres, radii):
        inside |= np.linalg.norm(centre - c, axis=1) < r
    tri = tri[~inside]
    a = pts[tri]
    d1, d2 = a[:, 1] - a[:, 0], a[:, 2] - a[:, 0]
    area = np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]) / 2
    tri = tri[area > 1e-6]  # slivers along the square's border
    used = np.unique(tri)
    remap = np.full(len(pts), -1)
    remap[used] = np.arange(len(used))
    pts, tri = pts[used], remap[tri]
    z = 0.2 * np.sin(2 * pts[:, 0]) * np.cos(3 * pts[:, 1])
    return np.column_stack([pts, z]), tri.astype(np.int64)


def load(name: str):
    if name.startswith("trimesh "):
        return generated(name)
    if name.startswith("scipy holes "):
        return holes(int(name.split()[-1]))
    from torch_edgevf.io import load_mesh

    mesh = load_mesh(SHARED_MESHES / name)
    return mesh.verts.numpy(), mesh.faces.numpy()


@contextlib.contextmanager
def quiet_stdout():
    """Silence the C++ progress output of Instant Meshes (file descriptor 1)."""
    sys.stdout.flush()
    saved = os.dup(1)
    with open(os.devnull, "w") as null:
        os.dup2(null.fileno(), 1)
        try:
            yield
        finally:
            sys.stdout.flush()
            os.dup2(saved, 1)
            os.close(saved)


def is_open(f) -> bool:
    e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), 1)
    return bool((np.unique(e, axis=0, return_counts=True)[1] == 1).any())


def instant_meshes(v, f, target_vertices: int):
    import pynanoinstantmeshes as pim

    def run(count):
        t0 = time.perf_counter()
        with quiet_stdout():
            qv, qf = pim.remesh(
                v.astype(np.float32), f.astype(np.uint32), int(count), align_to_boundaries=is_open(f)
            )
        return np.asarray(qv, dtype=np.float64), np.asarray(qf, dtype=np.int64), time.perf_counter() - t0

    count = max(target_vertices // 4, 8)
    qv, qf, dt = run(count)
    if abs(len(qv) - target_vertices) > 0.05 * target_vertices:
        qv, qf, dt = run(max(int(round(count * target_vertices / len(qv))), 8))
    return qv, qf, dt


def distances(v, f, qv, qf):
    """Distances between the quad mesh and the input, relative to the input's diagonal."""
    import igl

    diag = float(np.linalg.norm(v.max(0) - v.min(0)))
    samples = np.concatenate([qv, qv[qf].mean(1)])
    d2, _, _ = igl.point_mesh_squared_distance(samples, v, f)
    out_in = np.sqrt(d2)
    tri = np.concatenate([qf[:, [0, 1, 2]], qf[:, [0, 2, 3]]])
    d2b, _, _ = igl.point_mesh_squared_distance(v, qv, tri)
    return {
        "mean": float(out_in.mean() / diag),
        "max": float(out_in.max() / diag),
        "hausdorff": float(max(np.sqrt(d2b).max(), np.sqrt(d2[: len(qv)]).max()) / diag),
    }


def measure(v, f, qv, qf, seconds):
    from torch_edgevf.quad.mesh import quad_mesh_report

    r = quad_mesh_report(qv, qf)
    return {
        "vertices": r.num_vertices,
        "quads": r.num_quads,
        "euler": r.euler_characteristic,
        "manifold": r.manifold,
        "closed": r.closed,
        "irregular": int(r.irregular.size),
        "angle_deviation": r.angle_deviation,
        "distance": distances(v, f, qv, qf),
        "seconds": seconds,
    }


def ours(v, f, field: str, boundary: str = "hard"):
    import torch
    from threadpoolctl import threadpool_limits

    from torch_edgevf.quad.mesh import quad_mesh

    t0 = time.perf_counter()
    with threadpool_limits(limits=1):
        q = quad_mesh(
            torch.from_numpy(v), torch.from_numpy(f), field=field, boundary=boundary if is_open(f) else None
        )
    dt = time.perf_counter() - t0
    return q.verts.numpy(), q.quads.numpy(), dt, q


def picture(path, qv, qf, title):
    from torch_edgevf.render.quads import render_quad_mesh

    render_quad_mesh(qv, qf, path, size=(640, 480), title=title)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--meshes", nargs="*", default=SHARED + GENERATED)
    p.add_argument(
        "--fields", nargs="*", default=["curvature", "smoothest"], choices=["curvature", "smoothest"]
    )
    p.add_argument("--out", default="benchmarks/results/quad")
    p.add_argument("--boundary", default="hard", choices=["hard", "soft"], help="alignment on open meshes")
    p.add_argument("--pictures", default=None, help="folder for PNG pictures of both quad meshes")
    p.add_argument(
        "--picture-meshes", nargs="*", default=["spot_low_resolution.obj", "bunny.obj", "wingnut.obj"]
    )
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    import torch

    torch.set_num_threads(1)
    rows, records = [], []
    info = machine_info()
    for name in args.meshes:
        v, f = load(name)
        made = {}
        for field in args.fields:
            record = {"mesh": name, "input_vertices": len(v), "field": field}
            try:
                qv, qf, dt, q = ours(v, f, field, args.boundary)
                made[field] = (qv, qf)
                record["ours"] = measure(v, f, qv, qf, dt)
                record["ours"]["cones"] = int(q.cone_index.numel())
                record["ours"]["field_cones"] = int(q.grid_map.num_field_cones)
            except ValueError as exc:
                record["ours"] = {"error": str(exc)}
                log.info("%s %s: ours failed: %s", name, field, exc)
            records.append(record)
        target = next(
            (r["ours"]["vertices"] for r in records[-len(args.fields) :] if "vertices" in r["ours"]), len(v)
        )
        iv, iq, idt = instant_meshes(v, f, target)
        im = measure(v, f, iv, iq, idt)
        for r in records[-len(args.fields) :]:
            r["instant_meshes"] = im
        if args.pictures and name in args.picture_meshes:
            stem = Path(name).stem.replace(" ", "_")
            picture(
                Path(args.pictures) / f"quad_{stem}_instant_meshes.png",
                iv,
                iq,
                f"Instant Meshes: {len(iv)} vertices, {im['irregular']} irregular",
            )
            for field, (qv, qf) in made.items():
                rep = measure(v, f, qv, qf, 0.0)
                picture(
                    Path(args.pictures) / f"quad_{stem}_{field}.png",
                    qv,
                    qf,
                    f"torch_edgevf ({field}): {len(qv)} vertices, {rep['irregular']} irregular",
                )
        for r in records[-len(args.fields) :]:
            rows.append(row(r))
            log.info("%s", " | ".join(map(str, rows[-1])))
    header = [
        "mesh (input V)",
        "field",
        "V ours / IM",
        "irregular ours / IM",
        "mean |angle - 90| ours / IM (deg)",
        "mean dist ours / IM",
        "Hausdorff ours / IM",
        "time ours / IM (s)",
        "time ratio",
    ]
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".json").write_text(json.dumps({"machine": info, "records": records}, indent=1))
    text = (
        "# Quad meshes against Instant Meshes\n\n"
        f"`python benchmarks/bench_quad.py {shlex.join(argv or sys.argv[1:])}`\n\n"
        f"Machine: {info}\n\n" + markdown_table(header, rows) + "\n"
    )
    out.with_suffix(".md").write_text(text)
    print(text)
    return 0


def row(r):
    o, i = r["ours"], r["instant_meshes"]
    name = f"{r['mesh']} ({r['input_vertices']})"
    if "error" in o:
        return [
            name,
            r["field"],
            f"failed / {i['vertices']}",
            f"- / {i['irregular']}",
            f"- / {i['angle_deviation']:.2f}",
            "-",
            "-",
            f"- / {i['seconds']:.1f}",
            o["error"][:60],
        ]
    return [
        name,
        r["field"],
        f"{o['vertices']} / {i['vertices']}",
        f"**{o['irregular']}** / {i['irregular']}"
        if o["irregular"] < i["irregular"]
        else f"{o['irregular']} / {i['irregular']}",
        f"{o['angle_deviation']:.2f} / {i['angle_deviation']:.2f}",
        f"{o['distance']['mean']:.1e} / {i['distance']['mean']:.1e}",
        f"{o['distance']['hausdorff']:.1e} / {i['distance']['hausdorff']:.1e}",
        f"{o['seconds']:.1f} / {i['seconds']:.1f}",
        f"{o['seconds'] / i['seconds']:.1f}",
    ]


if __name__ == "__main__":
    sys.exit(main())
