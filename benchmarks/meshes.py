"""The benchmark meshes, each numbered by the tool that made it.

``trimesh_ico6``: trimesh's ``icosphere(6)`` (81,920 faces, trimesh's numbering);
``random_sphere``: the Delaunay triangulation of 10,242 random unit vectors (the convex hull
by SciPy's Qhull, fixed seed, faces turned outward); ``spot``: ``spot.obj`` of the shared
meshes; ``rna``: an RNA molecular surface of the RNA segmentation dataset sample
(``3CXC_9.off``, read as the file holds it and repaired only if the topology refuses it);
``ico6`` / ``ico8``: torch_edgevf's own icospheres (its numbering, for the earlier tables).

Data folders: ``$TORCH_EDGEVF_MESHES`` (default ``shared/meshes`` beside the repository) and
``$TORCH_EDGEVF_RNA`` (default ``shared/datasets/rna_sample`` beside the repository).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from common import REPO, SHARED_MESHES

RNA_SAMPLE = Path(os.environ.get("TORCH_EDGEVF_RNA") or REPO.parent / "shared" / "datasets" / "rna_sample")
RNA_MESH = "3CXC_9"
RANDOM_SPHERE_VERTICES = 10_242
SEED = 0

NAMES = ("trimesh_ico6", "random_sphere", "spot", "rna", "ico6", "ico8")


def random_sphere(
    num_vertices: int = RANDOM_SPHERE_VERTICES, seed: int = SEED
) -> tuple[np.ndarray, np.ndarray]:
    """Delaunay triangulation of random unit vectors: SciPy's convex hull, faces turned outward."""
    from scipy.spatial import ConvexHull

    rng = np.random.default_rng(seed)
    v = rng.standard_normal((num_vertices, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    f = ConvexHull(v).simplices.astype(np.int64)
    p = v[f]
    outward = np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p.sum(1)) > 0
    f[~outward] = f[~outward][:, [0, 2, 1]]
    return v, f


def mesh(name: str) -> tuple[np.ndarray, np.ndarray]:
    """``(verts float64 (V, 3), faces int64 (F, 3))`` numpy arrays of a benchmark mesh."""
    if name == "trimesh_ico6":
        import trimesh

        m = trimesh.creation.icosphere(subdivisions=6)
        return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)
    if name == "random_sphere":
        return random_sphere()
    if name in ("ico6", "ico8"):
        import torch_edgevf as ev

        v, f = ev.icosphere(int(name[3:]))
        return v.numpy(), f.numpy()
    if name == "spot":
        from torch_edgevf.io import load_mesh

        m = load_mesh(SHARED_MESHES / "spot.obj")
        return m.verts.numpy().astype(np.float64), m.faces.numpy().astype(np.int64)
    if name == "rna":
        import torch_edgevf as ev
        from torch_edgevf.io import read_triangles

        v, f, _ = read_triangles(RNA_SAMPLE / "off" / f"{RNA_MESH}.off")
        try:
            ev.Topology(f, num_vertices=len(v))
        except ValueError:
            from torch_edgevf.mesh.repair import repair

            r = repair(v, f)
            v, f = np.asarray(r.verts, dtype=np.float64), np.asarray(r.faces, dtype=np.int64)
        return np.asarray(v, dtype=np.float64), np.asarray(f, dtype=np.int64)
    raise ValueError(f"unknown benchmark mesh {name!r}, expected one of {NAMES}")
