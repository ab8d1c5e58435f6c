"""Benchmark of torch_edgevf.linalg against SciPy on the connection Laplacian.

Run: ``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_linalg.py [--level 6] [--mesh path.obj] [--k 24]``
(single-threaded BLAS: on an oversubscribed machine OpenBLAS threads spin on the small
dense Lanczos matrices and slow them down 30x).

Prints a markdown table per mesh and back-end (CHOLMOD when scikit-sparse is installed,
and the pip-only SuperLU path), with ratios:

* factor + solve of ``M_z + L_c`` (one right-hand side) vs ``scipy.sparse.linalg.spsolve``;
* the ``k`` smallest eigenpairs of ``(L_c, M_z)`` vs ``scipy.sparse.linalg.eigsh(A, k, M,
  sigma)`` (default shift-invert: SciPy factors ``A - sigma M`` with SuperLU and, for a
  complex matrix, runs ARPACK's non-Hermitian Arnoldi);
* the single smallest eigenpair vs one factorization;
* backward / forward times for ``solve`` (vs one solve with the factor) and for the
  eigenvalues (vs the forward eigensolve).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import scipy.sparse.linalg as sla
import torch

from torch_edgevf import EdgeOperators, icosphere
from torch_edgevf.linalg import SparseSolver, eigsh, solve
from torch_edgevf.linalg import factor as factor_module
from torch_edgevf.linalg.eigen import default_shift
from torch_edgevf.linalg._utils import as_sparse

SPOT = Path(__file__).resolve().parents[1].parent / "shared" / "meshes" / "spot.obj"


def timed(fn, repeat=1):
    """Best wall time of ``repeat`` runs and the last result."""
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def load(path):
    """Vertices and faces merged by position (``torch_edgevf.io.load_mesh``).

    (``trimesh.load(..., process=True)`` keeps Spot's texture seams split: non-manifold.)
    """
    from torch_edgevf.io import load_mesh

    mesh = load_mesh(path)
    return mesh.verts, mesh.faces


def residual(A, M, lam, X):
    """max_i ||A x_i - lam_i M x_i|| / ||A x_i|| (SciPy matrices, NumPy arrays)."""
    R = A @ X - (M @ X) * lam
    return float((np.linalg.norm(R, axis=0) / np.linalg.norm(A @ X, axis=0)).max())


def bench(name, verts, faces, k, rows):
    ops = EdgeOperators(verts, faces, n=1)
    L, Mz = ops.connection_laplacian.detach().coalesce(), ops.mass.detach().coalesce()
    A, M = as_sparse(L).to_scipy(), as_sparse(Mz).to_scipy()
    n = A.shape[0]
    K_t = (L + Mz.to(L.dtype)).coalesce()
    K = as_sparse(K_t).to_scipy()
    b = torch.randn(n, dtype=L.dtype, generator=torch.Generator().manual_seed(0))
    b_np = b.numpy()
    sigma = default_shift(A, M)

    t_spsolve, _ = timed(lambda: sla.spsolve(K.tocsc(), b_np))
    t_scipy_eig, (w_ref, X_ref) = timed(lambda: sla.eigsh(A, k, M, sigma=sigma, which="LM"))
    res_ref = residual(A, M, w_ref, X_ref)

    for backend in ("cholmod", "superlu"):
        if backend == "cholmod" and factor_module.cholmod_module() is None:
            continue
        saved = factor_module.cholmod_module
        if backend == "superlu":
            factor_module.cholmod_module = lambda: None
        try:
            t_factor, solver = timed(lambda: SparseSolver(K_t), repeat=2)
            t_solve, _ = timed(lambda: solver.factor.solve(b_np), repeat=3)
            t_eig, (lam, X) = timed(lambda: eigsh(L, Mz, k, method="lanczos"))
            t_eig1, (lam1, _) = timed(lambda: eigsh(L, Mz, 1, method="lanczos"))
            res = residual(A, M, lam.numpy(), X.numpy())
            # backward timings
            vals = K_t.values().clone().requires_grad_()
            solver_g = SparseSolver(torch.sparse_coo_tensor(K_t.indices(), vals, K_t.shape))
            x = solve(solver_g, b)
            t_sbwd, _ = timed(lambda: torch.autograd.grad(x.abs().pow(2).sum(), vals, retain_graph=True), 3)
            lv = L.values().clone().requires_grad_()
            mv = Mz.values().clone().requires_grad_()
            t_efwd, pairs = timed(lambda: eigsh(torch.sparse_coo_tensor(L.indices(), lv, L.shape),
                                                torch.sparse_coo_tensor(Mz.indices(), mv, Mz.shape),
                                                k, method="lanczos"))
            t_ebwd, _ = timed(lambda: torch.autograd.grad(pairs.values.sum(), (lv, mv), retain_graph=True), 3)
        finally:
            factor_module.cholmod_module = saved
        eig_err = float(np.abs(np.sort(w_ref) - lam.numpy()).max() / abs(w_ref).max())
        rows += [
            (name, n, backend, f"factor+solve M_z+L_c", t_factor + t_solve, "scipy spsolve", t_spsolve),
            (name, n, backend, f"{k} eigenpairs (res {res:.1e}, rel. err vs scipy {eig_err:.1e})",
             t_eig, f"scipy eigsh sigma (res {res_ref:.1e})", t_scipy_eig),
            (name, n, backend, "smallest eigenpair", t_eig1, "one factorization", t_factor),
            (name, n, backend, "solve backward", t_sbwd, "one solve", t_solve),
            (name, n, backend, f"eigenvalue backward (k={k})", t_ebwd, "eigsh forward", t_efwd),
        ]
        assert abs(float(lam1[0]) - float(lam[0])) <= 1e-8 * abs(float(lam[0])) + 1e-12


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--level", type=int, default=6)
    parser.add_argument("--mesh", type=Path, default=SPOT)
    parser.add_argument("--k", type=int, default=24)
    args = parser.parse_args()
    torch.set_num_threads(max(1, torch.get_num_threads()))
    rows = []
    bench(f"icosphere {args.level}", *icosphere(args.level), args.k, rows)
    if args.mesh.exists():
        bench(args.mesh.stem, *load(args.mesh), args.k, rows)
    print("| mesh | edges | back-end | ours | time (s) | reference | time (s) | ref/ours | ours/ref |")
    print("|---|---|---|---|---|---|---|---|---|")
    for mesh, n, backend, what, t, ref, t_ref in rows:
        print(f"| {mesh} | {n} | {backend} | {what} | {t:.3f} | {ref} | {t_ref:.3f} | {t_ref / t:.2f} "
              f"| {t / t_ref:.2f} |")


if __name__ == "__main__":
    main()
