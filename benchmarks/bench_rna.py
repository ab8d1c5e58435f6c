"""Precompute and training step on RNA molecular surfaces, side by side with DiffusionNet.

Run from the repository root (one thread per side; the sample of the dataset by default)::

    python benchmarks/bench_rna.py --data ../shared/datasets/rna_sample
    python benchmarks/bench_rna.py --data RNA-Surface-Segmentation-Dataset --meshes 12

Per mesh, decimated as the segmentation experiment trains (``--target-vertices``) and at
the file's resolution:

* precompute: :func:`torch_edgevf.learning.precompute.compute_operators` as the experiment
  calls it (128 eigenpairs of the vertex Laplacian, 32 of ``L_c``, ``G``, the vertex
  gradient: what every network of the study needs, smooth fields included), and what the
  edge network with local fields needs (``k_edge=0``: the 128
  vertex eigenpairs and ``G``), against DiffusionNet's operator precompute reimplemented
  step by step in ``bench_peers.diffusionnet_reference`` (robust Laplacian, 128 eigenpairs
  by SciPy's shift-invert ARPACK, least-squares vertex gradient); median of ``--repeats``,
  the sides interleaved;
* a training step (forward, backward, Adam; per-vertex head, 260 classes, width 128, 4
  blocks) of the edge-field network (local fields, its default per vertex, and smooth
  fields) and of DiffusionNet on the same mesh and operators.

Times are process CPU times (one thread: the work itself, not the turns of other processes
on a loaded machine, which the wall time would count). Ratios are ours / DiffusionNet
(below 1: faster). The table is printed in Markdown.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import argparse  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import torch  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments" / "rna_segmentation"))

import bench_peers  # noqa: E402
import run as rna_run  # noqa: E402

from torch_edgevf.learning.batching import MeshSample, collate_meshes  # noqa: E402
from torch_edgevf.learning.datasets.rna import prepare_rna_mesh, read_rna_mesh, rna_path, rna_split  # noqa: E402
from torch_edgevf.learning.precompute import compute_operators, heat_kernel_signature  # noqa: E402

from common import machine_info, markdown_table  # noqa: E402

OPTIONS = dict(k_edge=32, k_vertex=128, vertex_gradient=True)
#: what EdgeFieldNet(fields="local") needs: no eigenpair of L_c, no vertex gradient
LOCAL = dict(k_edge=0, k_vertex=128, vertex_gradient=False)


def step_seconds(model, batch, steps: int) -> float:
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    times = []
    for _ in range(steps + 1):
        start = time.process_time()
        opt.zero_grad()
        torch.nn.functional.cross_entropy(model(batch), batch.labels).backward()
        opt.step()
        times.append(time.process_time() - start)
    return statistics.median(times[1:])


def measure(mesh, repeats: int, steps: int) -> dict:
    ours, local, peer = [], [], []
    for _ in range(repeats):
        start = time.process_time()
        ops = compute_operators(mesh.verts, mesh.faces, **OPTIONS)
        ours.append(time.process_time() - start)
        start = time.process_time()
        compute_operators(mesh.verts, mesh.faces, **LOCAL)
        local.append(time.process_time() - start)
        start = time.process_time()
        bench_peers.diffusionnet_reference(mesh.verts, mesh.faces)
        peer.append(time.process_time() - start)
    o32 = ops.to(torch.float32)
    feats = heat_kernel_signature(
        o32.vertex_evals, o32.vertex_evecs, count=16, area=float(o32.face_area.sum()), log=True
    )
    batch = collate_meshes([MeshSample(o32, feats, torch.from_numpy(mesh.mesh_labels))])
    step = {}
    for name in ("edgefieldnet-smooth", "edgefieldnet", "diffusionnet"):
        torch.manual_seed(0)
        step[name] = step_seconds(rna_run.build_model(name, 16, 128), batch, steps)
    return {
        "vertices": len(mesh.verts),
        "ours": statistics.median(ours),
        "local": statistics.median(local),
        "peer": statistics.median(peer),
        "step_ours": step["edgefieldnet-smooth"],
        "step_local": step["edgefieldnet"],
        "step_peer": step["diffusionnet"],
    }


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", default=None, help="the dataset folder (default: $TORCH_EDGEVF_RNA)")
    p.add_argument("--meshes", type=int, default=4, help="the first N test meshes")
    p.add_argument("--target-vertices", type=int, default=5000)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--steps", type=int, default=5)
    a = p.parse_args(argv)
    torch.set_num_threads(1)
    if bench_peers._peer("robust_laplacian") is None:
        print("robust_laplacian is not installed (pip install -r benchmarks/requirements-peers.txt)")
        return 1
    root = rna_path(a.data)
    rows = []
    for name in rna_split(root)["test"][: a.meshes]:
        raw = read_rna_mesh(root, name)
        for label, target in (("decimated", a.target_vertices), ("file", None)):
            r = measure(prepare_rna_mesh(*raw, name=name, target_vertices=target), a.repeats, a.steps)
            rows.append(
                [
                    name,
                    label,
                    f"{r['vertices']:,}",
                    f"{r['peer']:.2f}",
                    f"{r['ours']:.2f}",
                    f"{r['ours'] / r['peer']:.2f}",
                    f"{r['local']:.2f}",
                    f"{r['local'] / r['peer']:.2f}",
                    f"{r['step_peer']:.3f}",
                    f"{r['step_ours']:.3f}",
                    f"{r['step_ours'] / r['step_peer']:.2f}",
                    f"{r['step_local']:.3f}",
                    f"{r['step_local'] / r['step_peer']:.2f}",
                ]
            )
            print(" | ".join(rows[-1]), file=sys.stderr, flush=True)
    print("machine:", ", ".join(f"{k} {v}" for k, v in machine_info().items()))
    print(
        markdown_table(
            [
                "mesh",
                "resolution",
                "vertices",
                "DiffusionNet precompute (s)",
                "ours, smooth fields (s)",
                "ratio",
                "ours, local fields (s)",
                "ratio",
                "DiffusionNet step (s)",
                "ours, smooth fields (s)",
                "ratio",
                "ours, local fields (s)",
                "ratio",
            ],
            rows,
        )
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
