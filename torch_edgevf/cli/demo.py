"""``edgevf demo``: operators, eigenvalues, the smoothest cross field and a picture of it."""

from __future__ import annotations

import time

from . import common


def cmd_demo(args) -> int:
    step, mesh, topo = common.start(args, 3)
    from ..fields.design import smoothest_field
    from ..fields.singularities import singularities
    from ..operators.module import EdgeOperators

    print(f"mesh: {common.mesh_name(args.mesh)}, {mesh.verts.shape[0]} vertices, {mesh.faces.shape[0]} faces")
    if args.k >= mesh.verts.shape[0]:
        raise ValueError(f"-k {args.k}: must be smaller than the number of vertices ({mesh.verts.shape[0]})")
    step("assembling operators")
    t0 = time.perf_counter()
    ops = EdgeOperators(mesh.verts, topo, n=1)
    print(f"topology: {ops.topology}")
    print(f"assembled all operators in {time.perf_counter() - t0:.3f} s (float64, CPU)")
    rows = [
        ("M_z  (edge mass)", ops.mass),
        ("L_c  (connection Laplacian, n=1)", ops.connection_laplacian),
        ("G    (gradient)", ops.gradient),
        ("K    (curl/div)", ops.curl_div),
        ("L    (Laplace-Beltrami G* M_z^-1 G)", ops.laplace_beltrami),
        ("M_v  (vertex mass, full)", ops.vertex_mass),
    ]
    print(f"{'operator':40s} {'shape':>16s} {'nnz':>9s}  dtype")
    for name, a in rows:
        print(f"{name:40s} {str(tuple(a.shape)):>16s} {a._nnz():>9d}  {a.dtype}")
    step("smallest eigenvalues")
    k = args.k
    for n in (1, 2, 4):
        vals = common.smallest_eigenvalues(ops.connection_laplacian_n(n), ops.mass, k)
        print(f"smallest eigenvalues of (L_c^({n}), M_z): " + " ".join(f"{x:.4f}" for x in vals))
    vals = common.smallest_eigenvalues(ops.laplace_beltrami, ops.vertex_mass, k)
    print("smallest eigenvalues of (L, M_v):       " + " ".join(f"{x:.4f}" for x in vals))
    step("smoothest cross field and its singularities")
    z = smoothest_field(mesh.verts, topo, n=4)
    sing = singularities(mesh.verts, topo, z, n=4)
    print(f"smoothest cross field: {common.singularity_line(sing)}")
    if args.png:
        step(f"rendering {args.png}")
        common.singularities_png(args, mesh.verts, topo, z.detach(), 4, sing, "smoothest cross field")
    return 0
