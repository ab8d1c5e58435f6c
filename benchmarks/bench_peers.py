"""Accuracy and speed side by side with peer libraries.

Run from the repository root::

    pip install -r benchmarks/requirements-peers.txt
    python benchmarks/bench_peers.py                  # icospheres 3..6 + spot, bunny, torus
    python benchmarks/bench_peers.py --quick          # icospheres 3..4 + spot_low_resolution
    python benchmarks/bench_peers.py --levels 3 4 5 --meshes torus.obj --no-diffusionnet

Peers (each optional: a missing one is reported and skipped):

* libigl: ``cotmatrix`` + ``massmatrix`` (vertex cotan Laplacian), ``crouzeix_raviart_cotmatrix``
  + ``crouzeix_raviart_massmatrix`` (edge-based scalar Laplacian, the ``n = 0`` case of ``L_c``);
* potpourri3d: ``cotan_laplacian`` + ``vertex_areas``; ``MeshVectorHeatSolver`` (the vertex
  connection Laplacian of the vector heat method, on the intrinsic Delaunay mesh) and its
  ``transport_tangent_vector`` (vector heat transport from one source);
* robust_laplacian: ``mesh_laplacian`` (intrinsic Delaunay + mollification);
* a DiffusionNet-style operator precompute, reimplemented here step by step as in
  ``diffusion_net/geometry.py`` ``compute_operators`` (robust Laplacian, ``k = 128``
  eigenpairs by scipy shift-invert ARPACK, per-vertex least-squares gradient built in a
  Python loop over vertices), against the same steps with torch_edgevf (cotan Laplacian,
  :func:`torch_edgevf.linalg.eigsh`, the edge gradient ``G``).

Accuracy: on icospheres (unit sphere), the first eigenvalues of each generalized problem
``L x = lambda M x``, solved for every operator by the same scipy shift-invert Lanczos,
against ``l (l + 1)`` (scalar Laplacians, ``l = 1, 2, 3``: 15 nonzero eigenvalues) and
``l (l + 1) - 1`` (connection / Bochner Laplacian of vector fields, ``l = 1, 2, 3``: 15
complex eigenvalues; the real multiplicity ``2 (2 l + 1)`` halves in the complex
representation, where ``z`` and ``i z`` span one complex line). Operators whose stiffness
is negative semi-definite by convention (libigl's ``cotmatrix``) are negated.

Speed: median wall times of repeated runs; *ratio* = peer time / torch_edgevf time (above
1: torch_edgevf is faster). The machine is shared: loads are printed in the header.
``OMP_WAIT_POLICY`` defaults to ``PASSIVE`` (set before torch is imported; export another
value to override): on a loaded 2-core machine spinning OpenMP threads made torch's small
parallel ops 10 to 40 times slower (``L_c`` assembly on icosphere level 5: 220 ms vs 20 ms).
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import argparse
import contextlib
import itertools
import json
import logging
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla

from common import SHARED_MESHES, fmt_time, machine_info, markdown_table, time_it

log = logging.getLogger("bench_peers")

RESULTS = Path(__file__).resolve().parent / "results"
K_DIFFUSIONNET = 128
SCALAR_L = (1, 2, 3)
VECTOR_L = (1, 2, 3)
EXTRA = 8  # eigenpairs computed beyond those compared: ARPACK can miss copies at a cluster's end


def _import_edgevf():
    try:
        import torch_edgevf
    except ImportError:  # not installed: run against this checkout
        sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
        import torch_edgevf
    return torch_edgevf


ev = _import_edgevf()
import torch  # noqa: E402  (after the checkout fallback)

from torch_edgevf import linalg as evla  # noqa: E402


def _peer(name: str):
    """The peer module, or None (reported once) when it is not installed."""
    try:
        if name == "igl":
            import igl as mod
        elif name == "pp3d":
            import potpourri3d as mod
        elif name == "robust_laplacian":
            import robust_laplacian as mod
        else:
            raise KeyError(name)
    except ImportError as exc:
        if name not in _MISSING:
            log.warning("peer %s is not installed (%s): skipped", name, exc)
            _MISSING[name] = str(exc)
        return None
    return mod


_MISSING: dict = {}


# --------------------------------------------------------------------------- meshes


def mesh_arrays(name: str):
    """``(label, verts (V, 3) float64, faces (F, 3) int64)`` numpy arrays."""
    if name.startswith("ico"):
        v, f = ev.icosphere(int(name[3:]))
    else:
        v, f = ev.load_mesh(SHARED_MESHES / name)
    return name, np.ascontiguousarray(v.numpy()), np.ascontiguousarray(f.numpy().astype(np.int64))


def repeats_for(num_faces: int) -> int:
    return 7 if num_faces < 10_000 else 4 if num_faces < 50_000 else 2


def to_scipy(a: torch.Tensor) -> sp.csr_matrix:
    a = a.coalesce()
    idx = a.indices().numpy()
    return sp.csr_matrix((a.values().numpy(), (idx[0], idx[1])), shape=tuple(a.shape))


# --------------------------------------------------------------------------- accuracy


def _smallest(L, M, k: int) -> np.ndarray:
    """The ``k`` smallest eigenvalues of ``L x = lambda M x`` (scipy shift-invert, same for all)."""
    L, M = sp.csc_matrix(L), sp.csc_matrix(M)
    if np.real(L.diagonal()).sum() < 0:  # negative semi-definite convention
        L = -L
    vals = sla.eigsh(L, k=k + EXTRA, M=M, sigma=-1e-2, which="LM", tol=1e-10, return_eigenvectors=False)
    return np.sort(vals.real)[:k]


def _exact(ls, shift: int, multiplicity) -> np.ndarray:
    return np.concatenate([[l * (l + 1) - shift] * multiplicity(l) for l in ls]).astype(np.float64)


def _rel_errors(vals: np.ndarray, exact: np.ndarray) -> tuple[float, float]:
    """(mean relative error of the first group, max relative error over all)."""
    rel = np.abs(vals - exact) / exact
    first = exact == exact[0]
    return float(rel[first].mean()), float(rel.max())


def accuracy(level: int) -> dict:
    label, v, f = mesh_arrays(f"ico{level}")
    vt, ft = torch.from_numpy(v), torch.from_numpy(f)
    topo = ev.Topology(ft, v.shape[0])
    scalar_exact = _exact(SCALAR_L, 0, lambda l: 2 * l + 1)  # 15 values
    vector_exact = _exact(VECTOR_L, 1, lambda l: 2 * l + 1)  # 15 complex eigenvalues
    ks, kv = len(scalar_exact) + 1, len(vector_exact)
    ops: dict = {}
    ops["ours: LB = G* M_z^-1 G, full M_v"] = (
        to_scipy(ev.laplace_beltrami(vt, topo)),
        to_scipy(ev.vertex_mass(vt, topo)),
        "s",
    )
    ops["ours: CR scalar L_c^(0), M_z"] = (
        to_scipy(ev.connection_laplacian(vt, topo, 0)),
        to_scipy(ev.mass_matrix(vt, topo)),
        "s",
    )
    ops["ours: cotan, lumped M_v"] = (
        to_scipy(ev.cotan_laplacian(vt, topo)),
        to_scipy(ev.vertex_mass(vt, topo, lumped=True)),
        "s",
    )
    ops["ours: connection L_c^(1), M_z"] = (
        to_scipy(ev.connection_laplacian(vt, topo, 1)),
        to_scipy(ev.mass_matrix(vt, topo)),
        "v",
    )
    igl = _peer("igl")
    if igl is not None:
        ops["libigl: cotmatrix, massmatrix (Voronoi)"] = (igl.cotmatrix(v, f), igl.massmatrix(v, f), "s")
        _, ue, emap = igl.unique_edge_map(f)[:3]
        ops["libigl: crouzeix_raviart_cotmatrix/massmatrix"] = (
            igl.crouzeix_raviart_cotmatrix(v, f, ue, emap),
            igl.crouzeix_raviart_massmatrix(v, f, ue, emap),
            "s",
        )
    pp3d = _peer("pp3d")
    if pp3d is not None:
        area = sp.diags(pp3d.vertex_areas(v, f))
        ops["potpourri3d: cotan_laplacian, vertex_areas"] = (pp3d.cotan_laplacian(v, f), area, "s")
        solver = pp3d.MeshVectorHeatSolver(v, f)
        ops["potpourri3d: vector heat connection Laplacian"] = (solver.get_connection_laplacian(), area, "v")
    rl = _peer("robust_laplacian")
    if rl is not None:
        L, M = rl.mesh_laplacian(v, f)
        ops["robust_laplacian: mesh_laplacian"] = (L, M, "s")
    rows = {}
    for name, (L, M, kind) in ops.items():
        t0 = time.perf_counter()
        if kind == "s":
            vals = _smallest(L, M, ks)
            zero = float(abs(vals[0]))
            mean1, worst = _rel_errors(vals[1:], scalar_exact)
        else:
            vals = _smallest(L, M, kv)
            zero = None
            mean1, worst = _rel_errors(vals, vector_exact)
        rows[name] = {
            "kind": kind,
            "first_group": mean1,
            "max": worst,
            "lambda0": zero,
            "values": vals.tolist(),
            "solve_s": time.perf_counter() - t0,
        }
        log.info("ico%d %-48s l=1 %.2e max %.2e", level, name, mean1, worst)
    return {"mesh": label, "V": int(v.shape[0]), "F": int(f.shape[0]), "operators": rows}


# --------------------------------------------------------------------------- speed


def our_vector_heat(vt, ft, source_edge: int, prefactored=None):
    """Vector heat method on edges (Sharp et al. 2019, with L_c^(1) and L_c^(0) on edges).

    ``X = (M + t L_c^(1))^{-1} M delta`` carries the direction, two scalar solves with
    ``L_c^(0)`` the magnitude: ``Y = X / |X| * u / phi``. Returns the field and the two
    factorizations (pass them back as ``prefactored`` to time the solves alone).
    """
    if prefactored is None:
        topo = ev.Topology(ft, vt.shape[0])
        mass = ev.mass_matrix(vt, topo).coalesce().values()
        h = ev.geometry.mean_edge_length(vt, topo)
        t = float(h) ** 2
        eye = torch.arange(topo.num_edges)
        m_sp = torch.sparse_coo_tensor(torch.stack([eye, eye]), mass, (topo.num_edges,) * 2)
        a_vec = (m_sp.to(torch.complex128) + t * ev.connection_laplacian(vt, topo, 1)).coalesce()
        a_sca = (m_sp + t * ev.connection_laplacian(vt, topo, 0)).coalesce()
        prefactored = (
            evla.SparseSolver(a_vec, hermitian=True),
            evla.SparseSolver(a_sca, hermitian=True),
            mass,
        )
    s_vec, s_sca, mass = prefactored
    ne = mass.shape[0]
    delta = torch.zeros(ne, dtype=torch.complex128)
    delta[source_edge] = 1.0
    x = s_vec.solve(mass.to(torch.complex128) * delta)
    ind = torch.zeros(ne, dtype=torch.float64)
    ind[source_edge] = 1.0
    rhs = torch.stack([mass * ind, mass * ind], dim=1)  # magnitude |delta| = 1 = indicator here
    uphi = s_sca.solve(rhs)
    y = x / x.abs().clamp_min(1e-300) * (uphi[:, 0] / uphi[:, 1].clamp_min(1e-300))
    return y, prefactored


def speed(name: str, diffusionnet: bool) -> dict:
    label, v, f = mesh_arrays(name)
    vt, ft = torch.from_numpy(v), torch.from_numpy(f)
    reps = repeats_for(f.shape[0])
    out: dict = {"mesh": label, "V": int(v.shape[0]), "F": int(f.shape[0]), "timings": {}}
    T = out["timings"]

    def record(key, fn, repeats=reps, warmup=1):
        T[key] = time_it(key, fn, repeats=repeats, warmup=warmup).median

    # ours: first assembly includes building the Topology (edges, incidences, patterns)
    def ours_cr():
        topo = ev.Topology(ft, v.shape[0])
        return ev.connection_laplacian(vt, topo, 0), ev.mass_matrix(vt, topo)

    def ours_cot():
        topo = ev.Topology(ft, v.shape[0])
        return ev.cotan_laplacian(vt, topo), ev.vertex_mass(vt, topo, lumped=True)

    def ours_conn():
        topo = ev.Topology(ft, v.shape[0])
        return ev.connection_laplacian(vt, topo, 1), ev.mass_matrix(vt, topo)

    topo = ev.Topology(ft, v.shape[0])
    ev.connection_laplacian(vt, topo, 1)  # patterns cached on topo
    record("ours CR L+M", ours_cr)
    record("ours cot L+M", ours_cot)
    record("ours L_c+M", ours_conn)
    # new positions on every call (equal positions would reuse the cached face geometry)
    moved = itertools.cycle([vt * (1 + 1e-3 * k) for k in range(1, 4)])

    def ours_conn_cached():
        w = next(moved)
        return ev.connection_laplacian(w, topo, 1), ev.mass_matrix(w, topo)

    record("ours L_c+M (cached topology)", ours_conn_cached)

    igl = _peer("igl")
    if igl is not None:

        def igl_cr():
            _, ue, emap = igl.unique_edge_map(f)[:3]
            return igl.crouzeix_raviart_cotmatrix(v, f, ue, emap), igl.crouzeix_raviart_massmatrix(
                v, f, ue, emap
            )

        record("igl CR L+M", igl_cr)
        record("igl cot L+M", lambda: (igl.cotmatrix(v, f), igl.massmatrix(v, f)))
    pp3d = _peer("pp3d")
    if pp3d is not None:
        record("pp3d cot L+M", lambda: (pp3d.cotan_laplacian(v, f), pp3d.vertex_areas(v, f)))

        def pp3d_conn():
            s = pp3d.MeshVectorHeatSolver(v, f)
            return s.get_connection_laplacian(), pp3d.vertex_areas(v, f)

        record("pp3d connection L+M (solver build)", pp3d_conn)
    rl = _peer("robust_laplacian")
    if rl is not None:
        record("robust_laplacian L+M", lambda: rl.mesh_laplacian(v, f))

    # vector heat transport from one source
    source_edge = int(torch.nonzero((topo.edges == 0).any(1))[0])
    record("ours vector heat (build+factor+solve)", lambda: our_vector_heat(vt, ft, source_edge)[0])
    _, fac = our_vector_heat(vt, ft, source_edge)
    record("ours vector heat (prefactored)", lambda: our_vector_heat(vt, ft, source_edge, fac)[0])
    if pp3d is not None:
        record(
            "pp3d vector heat (build+solve)",
            lambda: pp3d.MeshVectorHeatSolver(v, f).transport_tangent_vector(0, [1.0, 0.0]),
        )
        solver = pp3d.MeshVectorHeatSolver(v, f)
        solver.transport_tangent_vector(0, [1.0, 0.0])  # lets it factor whatever it factors lazily
        record("pp3d vector heat (prefactored)", lambda: solver.transport_tangent_vector(0, [1.0, 0.0]))

    if diffusionnet:
        out["diffusionnet"] = diffusionnet_compare(v, f)
    return out


# --------------------------------------------------------------------------- DiffusionNet-style


def _dn_normals(v, f):
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])  # area-weighted
    vn = np.zeros_like(v)
    for k in range(3):
        np.add.at(vn, f[:, k], fn)
    return vn / np.linalg.norm(vn, axis=1, keepdims=True)


def _dn_frames(v, f):
    """Per-vertex tangent frames as in diffusion_net.geometry.build_tangent_frames."""
    normals = _dn_normals(v, f)
    basis_x = np.tile([1.0, 0.0, 0.0], (v.shape[0], 1))
    bad = np.abs((basis_x * normals).sum(1)) > 0.9
    basis_x[bad] = [0.0, 1.0, 0.0]
    basis_x -= (basis_x * normals).sum(1, keepdims=True) * normals
    basis_x /= np.linalg.norm(basis_x, axis=1, keepdims=True)
    basis_y = np.cross(normals, basis_x)
    return basis_x, basis_y, normals


def _dn_build_grad(v, edges, edge_tangent_vectors):
    """diffusion_net.geometry.build_grad: a per-vertex least-squares fit, in a Python loop."""
    n = v.shape[0]
    vert_edge_outgoing = [[] for _ in range(n)]
    for i_e in range(edges.shape[1]):
        tail, tip = edges[0, i_e], edges[1, i_e]
        if tip != tail:
            vert_edge_outgoing[tail].append(i_e)
    rows, cols, vals = [], [], []
    eps_reg = 1e-5
    for i_v in range(n):
        n_neigh = len(vert_edge_outgoing[i_v])
        lhs = np.zeros((n_neigh, 2))
        rhs = np.zeros((n_neigh, n_neigh + 1))
        lookup = [i_v]
        for i_n in range(n_neigh):
            i_e = vert_edge_outgoing[i_v][i_n]
            lookup.append(edges[1, i_e])
            lhs[i_n][:] = edge_tangent_vectors[i_e][:]
            rhs[i_n][0] = -1
            rhs[i_n][i_n + 1] = 1
        lhs_t = lhs.T
        lhs_inv = np.linalg.inv(lhs_t @ lhs + eps_reg * np.identity(2)) @ lhs_t
        sol = lhs_inv @ rhs
        coefs = (sol[0, :] + 1j * sol[1, :]).T
        for i_n in range(n_neigh + 1):
            rows.append(i_v)
            cols.append(lookup[i_n])
            vals.append(coefs[i_n])
    return sp.coo_matrix((np.array(vals), (np.array(rows), np.array(cols))), shape=(n, n)).tocsc()


def diffusionnet_reference(v, f, k: int = K_DIFFUSIONNET) -> dict:
    """The steps of diffusion_net.geometry.compute_operators, timed one by one."""
    rl = _peer("robust_laplacian")
    if rl is None:
        return {}
    times = {}
    t0 = time.perf_counter()
    frames = _dn_frames(v, f)
    L, M = rl.mesh_laplacian(v, f, mollify_factor=1e-5)
    massvec = M.diagonal()
    times["laplacian"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    eps = 1e-8
    l_eigsh = (L + sp.identity(L.shape[0]) * eps).tocsc()
    mmat = sp.diags(massvec)
    failcount = 0
    while True:
        try:
            evals, evecs = sla.eigsh(l_eigsh, k=k, M=mmat, sigma=eps)
            evals = np.clip(evals, 0.0, float("inf"))
            break
        except RuntimeError:
            failcount += 1
            if failcount > 3:
                raise
            l_eigsh = l_eigsh + sp.identity(L.shape[0]) * (eps * 10**failcount)
    times["eigenbasis"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    edges = np.unique(np.concatenate([e, e[:, ::-1]]), axis=0).T  # both directions
    edge_vecs = v[edges[1]] - v[edges[0]]
    bx, by, nrm = frames
    edge_vecs = edge_vecs - (edge_vecs * nrm[edges[0]]).sum(1, keepdims=True) * nrm[edges[0]]
    etv = np.stack([(edge_vecs * bx[edges[0]]).sum(1), (edge_vecs * by[edges[0]]).sum(1)], axis=-1)
    grad = _dn_build_grad(v, edges, etv)
    times["gradient"] = time.perf_counter() - t0
    times["total"] = sum(times.values())
    return {"times": times, "evals": evals[:8].tolist(), "grad_nnz": int(grad.nnz)}


def diffusionnet_ours(v, f, k: int = K_DIFFUSIONNET) -> dict:
    """The same steps with torch_edgevf: cotan Laplacian, eigsh (CHOLMOD + Lanczos), G."""
    times = {}
    vt, ft = torch.from_numpy(v), torch.from_numpy(f)
    t0 = time.perf_counter()
    topo = ev.Topology(ft, v.shape[0])
    L = ev.cotan_laplacian(vt, topo)
    m = ev.vertex_mass(vt, topo, lumped=True).coalesce().values()
    times["laplacian"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    pairs = evla.eigsh(L, m, k=k)
    times["eigenbasis"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    G = ev.gradient(vt, topo)
    times["gradient"] = time.perf_counter() - t0
    times["total"] = sum(times.values())
    return {
        "times": times,
        "evals": pairs.values[:8].tolist(),
        "grad_nnz": int(G.coalesce().values().numel()),
    }


def diffusionnet_compare(v, f) -> dict:
    log.info("DiffusionNet-style precompute, V = %d (reference, then ours)", v.shape[0])
    ref = diffusionnet_reference(v, f)
    ours = diffusionnet_ours(v, f)
    return {"reference": ref, "ours": ours}


# --------------------------------------------------------------------------- report


def _ratio(peer, ours):
    if peer is None or ours is None:
        return "-"
    return f"{peer / ours:.2f}x"


def report(acc: list, spd: list) -> str:
    parts = []
    if acc:
        parts.append("### Accuracy: sphere spectra (relative eigenvalue errors)\n")
        parts.append(
            "Scalar: 15 nonzero eigenvalues vs l(l+1), l = 1..3. Vector (complex): 15 eigenvalues vs "
            "l(l+1) - 1, l = 1..3. Cells: mean error of the l = 1 group / max error over all 15.\n"
        )
        names = list(acc[0]["operators"])
        rows = []
        for name in names:
            row = [name]
            for a in acc:
                r = a["operators"].get(name)
                row.append("-" if r is None else f"{r['first_group']:.2e} / {r['max']:.2e}")
            rows.append(row)
        parts.append(markdown_table(["operator"] + [f"ico{a['mesh'][3:]} (V={a['V']})" for a in acc], rows))
    if spd:
        groups = [
            (
                "Scalar Crouzeix-Raviart Laplacian + mass (first assembly, edge map / topology included)",
                "ours CR L+M",
                ["igl CR L+M"],
            ),
            (
                "Vertex cotan Laplacian + mass",
                "ours cot L+M",
                ["igl cot L+M", "pp3d cot L+M", "robust_laplacian L+M"],
            ),
            (
                "Connection Laplacian + mass "
                "(ours: edges, n = 1; pp3d: vertices, MeshVectorHeatSolver build)",
                "ours L_c+M",
                ["pp3d connection L+M (solver build)"],
            ),
            (
                "Vector heat transport, one source: build + factor + solve",
                "ours vector heat (build+factor+solve)",
                ["pp3d vector heat (build+solve)"],
            ),
            (
                "Vector heat transport, one source: prefactored solve",
                "ours vector heat (prefactored)",
                ["pp3d vector heat (prefactored)"],
            ),
        ]
        for title, ours_key, peers in groups:
            parts.append(f"\n### {title}\n")
            rows = []
            for s in spd:
                t = s["timings"]
                row = [s["mesh"], s["V"], s["F"], fmt_time(t.get(ours_key))]
                for p in peers:
                    row += [fmt_time(t.get(p)), _ratio(t.get(p), t.get(ours_key))]
                rows.append(row)
            heads = ["mesh", "V", "F", "torch_edgevf"]
            for p in peers:
                heads += [p, "ratio"]
            parts.append(markdown_table(heads, rows))
        dn = [s for s in spd if s.get("diffusionnet")]
        if dn:
            parts.append(
                "\n### DiffusionNet-style precompute (k = 128 eigenbasis + gradient), one run each\n"
            )
            parts.append(
                "Reference: robust_laplacian + scipy eigsh (shift-invert ARPACK) + per-vertex "
                "least-squares gradient in a Python loop, as diffusion_net.geometry.compute_operators. "
                "Ours: cotan Laplacian + torch_edgevf.linalg.eigsh + edge gradient G.\n"
            )
            rows = []
            for s in dn:
                ref, ours = s["diffusionnet"]["reference"], s["diffusionnet"]["ours"]
                rt, ot = ref.get("times", {}), ours["times"]
                row = [s["mesh"], s["V"]]
                for step in ("laplacian", "eigenbasis", "gradient", "total"):
                    row += [f"{fmt_time(rt.get(step))} / {fmt_time(ot[step])}"]
                row.append(_ratio(rt.get("total"), ot["total"]))
                rows.append(row)
            parts.append(
                markdown_table(
                    [
                        "mesh",
                        "V",
                        "Laplacian ref / ours",
                        "eigenbasis ref / ours",
                        "gradient ref / ours",
                        "total ref / ours",
                        "ratio",
                    ],
                    rows,
                )
            )
    if _MISSING:
        parts.append("\nNot installed (skipped): " + ", ".join(f"{k} ({v})" for k, v in _MISSING.items()))
    return "\n".join(parts)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--levels", type=int, nargs="*", default=[3, 4, 5, 6])
    parser.add_argument("--meshes", nargs="*", default=["spot.obj", "bunny.obj", "torus.obj"])
    parser.add_argument("--quick", action="store_true", help="levels 3 4 and spot_low_resolution only")
    parser.add_argument("--no-accuracy", action="store_true")
    parser.add_argument("--no-speed", action="store_true")
    parser.add_argument("--no-diffusionnet", action="store_true")
    parser.add_argument("--diffusionnet-max-vertices", type=int, default=50_000)
    parser.add_argument("--json", type=Path, default=RESULTS / "peers.json")
    parser.add_argument(
        "--blas-threads",
        type=int,
        default=1,
        help="BLAS threads for everyone (torch_edgevf's eigensolver uses 1 anyway); "
        "0 leaves BLAS alone. Oversubscribed OpenBLAS made ARPACK 10x noisier here",
    )
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s", stream=sys.stderr)
    if args.quick:
        args.levels, args.meshes = [3, 4], ["spot_low_resolution.obj"]
    info = machine_info()
    info["blas_threads"] = args.blas_threads or "default"
    limits = contextlib.nullcontext()
    if args.blas_threads:
        try:
            from threadpoolctl import threadpool_limits

            limits = threadpool_limits(limits=args.blas_threads, user_api="blas")
        except ImportError:
            log.warning("threadpoolctl is not installed: BLAS threads left as they are")
    with limits:
        acc, spd = _run(args)
    info["load_average_after"] = [round(x, 2) for x in os.getloadavg()]
    text = report(acc, spd)
    header = (
        f"Machine: {info.get('cpu')}, {info.get('cores')} cores, torch {info.get('torch')} "
        f"({info.get('torch_threads')} threads, OMP_WAIT_POLICY={info.get('omp_wait_policy')}, "
        f"BLAS threads {info['blas_threads']}), libigl {info.get('igl')}, potpourri3d "
        f"{info.get('potpourri3d')}, robust_laplacian {info.get('robust_laplacian')}; load "
        f"{info.get('load_average')} before, {info['load_average_after']} after.\n"
    )
    print(header)
    print(text)
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(
        json.dumps({"machine": info, "accuracy": acc, "speed": spd}, indent=1, default=float)
    )
    log.info("wrote %s", args.json)
    return 0


def _run(args) -> tuple[list, list]:
    acc, spd = [], []
    if not args.no_accuracy:
        for level in args.levels:
            acc.append(accuracy(level))
    if not args.no_speed:
        names = [f"ico{lv}" for lv in args.levels] + [m for m in args.meshes if (SHARED_MESHES / m).exists()]
        for name in names:
            _, v, _ = mesh_arrays(name)
            dn = not args.no_diffusionnet and v.shape[0] <= args.diffusionnet_max_vertices
            spd.append(speed(name, dn))
    return acc, spd


if __name__ == "__main__":
    sys.exit(main())
