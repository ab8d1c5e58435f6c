"""Issue 6: cost of the learning pipeline on PSB meshes (about 1000 vertices, 3000 edges).

Run from the repository root::

    python benchmarks/bench_learning.py            # 8 PSB meshes
    python benchmarks/bench_learning.py --quick    # 2 meshes, fewer repeats

Times (median of repeats, one thread):

* ``compute_operators`` per mesh (32 eigenpairs of ``L_c`` and of the cotangent
  Laplacian, vertex gradient), without cache, and a cache hit;
* ``collate_meshes`` of a batch;
* one diffusion layer on ``(E, 24)`` complex features: spectral vs implicit;
* forward + backward of ``EdgeFieldNet`` and ``DiffusionNetBaseline`` (width 24, 3 blocks)
  on the batch.

Prints a markdown table and writes ``benchmarks/results/bench_learning.json``.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile

import numpy as np
import torch

from common import REPO, machine_info, markdown_table, time_it

sys.path.insert(0, str(REPO))

from torch_edgevf import data, models  # noqa: E402
from torch_edgevf import nn as enn  # noqa: E402


def _psb_meshes(count: int):
    d = np.load(data.DEFAULT_PSB_PATH, allow_pickle=False)
    out = []
    for i in range(count):
        v = d["verts"][d["vert_offsets"][i]:d["vert_offsets"][i + 1]]
        f = d["faces"][d["face_offsets"][i]:d["face_offsets"][i + 1]].astype(np.int64)
        out.append((v, f))
    return out


def main(count: int = 8, repeats: int = 5) -> dict:
    torch.set_num_threads(1)
    meshes = _psb_meshes(count)
    options = dict(k_edge=32, k_vertex=32, vertex_gradient=True)
    rows, results = [], {}

    t = time_it("compute_operators", lambda: data.compute_operators(*meshes[0], **options), repeats=max(1, repeats // 2))
    results["compute_operators"] = t
    rows.append(["compute_operators (1 mesh, k=32+32)", f"{t.median * 1e3:.0f} ms"])
    with tempfile.TemporaryDirectory() as tmp:
        cache = data.OperatorCache(tmp)
        cache.get(*meshes[0], **options)
        t = time_it("cache_hit", lambda: cache.get(*meshes[0], **options), repeats=repeats)
    results["cache_hit"] = t
    rows.append(["OperatorCache hit (1 mesh, verified)", f"{t.median * 1e3:.1f} ms"])

    samples = []
    for v, f in meshes:
        o = data.compute_operators(v, f, **options)
        x = data.heat_kernel_signature(o.vertex_evals, o.vertex_evecs, count=16, area=o.face_area.sum())
        samples.append(data.MeshSample(o.to(torch.float32), x.float(), 0))
    t = time_it("collate", lambda: data.collate_meshes(samples), repeats=repeats)
    results["collate"] = t
    rows.append([f"collate_meshes ({count} meshes)", f"{t.median * 1e3:.1f} ms"])

    o = samples[0].operators
    z = torch.randn(o.num_edges, 24, dtype=torch.complex64)
    times = torch.full((24,), 0.01)
    t = time_it("spectral", lambda: enn.spectral_diffusion(z, o.edge_evals, o.edge_evecs, o.edge_mass, times),
                repeats=repeats)
    results["spectral_diffusion"] = t
    rows.append(["spectral_diffusion (E x 24, k=32)", f"{t.median * 1e3:.2f} ms"])
    t = time_it("implicit", lambda: enn.implicit_diffusion(z, o.connection_laplacian, o.edge_mass, times),
                repeats=max(1, repeats // 2))
    results["implicit_diffusion"] = t
    rows.append(["implicit_diffusion (E x 24, 24 factorisations)", f"{t.median * 1e3:.0f} ms"])

    batch = data.collate_meshes(samples)
    for name, cls in (("EdgeFieldNet", models.EdgeFieldNet), ("DiffusionNetBaseline", models.DiffusionNetBaseline)):
        torch.manual_seed(0)
        net = cls(16, 19, width=24, num_blocks=3)

        def step():
            net.zero_grad()
            net(batch).sum().backward()

        t = time_it(name, step, repeats=repeats)
        results[name] = t
        rows.append([f"{name} forward+backward ({count} meshes)", f"{t.median * 1e3:.0f} ms"])

    table = markdown_table(["measurement", "median"], rows)
    out_dir = REPO / "benchmarks" / "results"
    out_dir.mkdir(parents=True, exist_ok=True)
    payload = {"machine": machine_info(), "results": {k: v.as_dict() for k, v in results.items()}}
    (out_dir / "bench_learning.json").write_text(json.dumps(payload, indent=1, default=str))
    return {"table": table, "results": results}


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    out = main(count=2, repeats=2) if args.quick else main()
    print(out["table"])
