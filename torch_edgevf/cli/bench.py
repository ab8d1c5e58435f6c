"""``edgevf bench``: quick timings on the built-in mesh and icospheres."""

from __future__ import annotations

import time

from . import common


def cmd_bench(args) -> int:
    import torch

    from ..fields.design import smoothest_field
    from ..mesh.meshes import icosphere
    from ..mesh.topology import Topology
    from ..operators.module import EdgeOperators

    step = common.Progress(len(args.levels) + 1, args.quiet)
    meshes = [(common.BUILT_IN, common.load(None))]
    meshes += [(f"icosphere level {lvl}", icosphere(lvl)) for lvl in args.levels]
    print("| mesh | faces | first assembly (all) | re-assembly (all) | L_c matvec | smoothest 4-field |")
    print("|---|---:|---:|---:|---:|---:|")
    for name, (verts, faces) in meshes:
        step(name)
        t0 = time.perf_counter()
        ops = EdgeOperators(verts, Topology(faces, num_vertices=verts.shape[0]))
        first = time.perf_counter() - t0
        t0 = time.perf_counter()
        ops.update(verts)
        again = time.perf_counter() - t0
        x = torch.randn(ops.num_edges, dtype=torch.complex128)
        t0 = time.perf_counter()
        ops.connection_laplacian @ x
        matvec = time.perf_counter() - t0
        t0 = time.perf_counter()
        smoothest_field(verts, ops.topology, n=4)
        design = time.perf_counter() - t0
        print(
            f"| {name} | {ops.num_faces} | {first:.3f} s | {again:.3f} s | {matvec * 1e3:.1f} ms "
            f"| {design:.3f} s |"
        )
    return 0
