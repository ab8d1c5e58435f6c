"""repair() on real meshes and on generated defects: nothing lost unreported, fields end to end.

The real meshes are read from ``../shared`` next to the repository (skipped when absent):
``meshes``, ``meshes/wild`` (meshes with defects: a non-manifold vertex, a non-manifold
edge, zero-area faces, ...) and the PSB file (a sample here, every mesh in the slow lane).
"""

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import torch_edgevf as ev
from torch_edgevf.io import read_triangles

from conftest import SHARED

PSB = SHARED / "datasets" / "psb_watertight_2k.npz"
SLOW = {"spot.obj", "mountain.obj", "plane_holes.obj", "ogre.obj", "beast.obj"}
MESHES = [
    "spot_low_resolution.obj",
    "fish_low_resolution.obj",
    "sphere.obj",
    "torus.obj",
    "wingnut.obj",
    "penguin.obj",
    "goathead.obj",
    "koala_low_resolution.obj",
    "skull_low_resolution.obj",
    "bunny.obj",
    "spot.obj",
    "mountain.obj",
    "plane_holes.obj",
    "wild/teapot.obj",
    "wild/suzanne.obj",
    "wild/ogre.obj",
    "wild/beast.obj",
]


def _accounted(result, num_faces):
    kept = set(result.face_origin.tolist())
    dropped = set(result.report.dropped_faces)
    assert kept.isdisjoint(dropped)
    assert kept | dropped == set(range(num_faces)), "a face was lost without being reported"


def end_to_end(verts, faces):
    """repair, finite operators on the lengths, smoothest cross field, Poincare-Hopf."""
    result = ev.repair(verts, faces)
    _accounted(result, len(faces))
    geom, topo = result.geometry, result.topology
    for op in (ev.connection_laplacian, ev.mass_matrix, ev.laplace_beltrami):
        assert torch.isfinite(op(geom, topo).values()).all(), op.__name__
    z = ev.smoothest_field(geom, topo, n=4)
    assert torch.isfinite(z).all()
    s = ev.singularities(geom, topo, z, n=4)
    assert s.total == pytest.approx(topo.euler_characteristic + s.boundary_turning, abs=1e-6)
    if topo.is_closed:
        assert s.total == topo.euler_characteristic
    return result


@pytest.mark.parametrize(
    "name", [pytest.param(n, marks=pytest.mark.slow) if n.split("/")[-1] in SLOW else n for n in MESHES]
)
def test_shared_mesh_end_to_end(name):
    path = SHARED / "meshes" / name
    if not path.exists():
        pytest.skip(f"{path} is not available")
    verts, faces, _ = read_triangles(path, merge=True)
    before = (verts.copy(), faces.copy())
    result = end_to_end(verts, faces)
    assert np.array_equal(verts, before[0]) and np.array_equal(faces, before[1])
    assert torch.equal(result.verts, torch.from_numpy(verts)[result.vertex_origin])


def test_wild_meshes_need_what_they_need():
    wild = SHARED / "meshes" / "wild"
    if not wild.exists():
        pytest.skip(f"{wild} is not available")
    rep = {p.stem: ev.repair(*read_triangles(p, merge=True)[:2]).report for p in sorted(wild.glob("*.obj"))}
    assert rep["teapot"].non_manifold_vertices
    assert rep["suzanne"].non_manifold_edges and rep["suzanne"].duplicate_faces
    # its four zero-area faces are caps (a corner on the opposite edge): flipped, not mollified
    assert len(rep["ogre"].flipped_caps) == 4 and rep["ogre"].epsilon == 0
    assert rep["beast"].non_manifold_edges


def _psb(indices=None):
    if not PSB.exists():
        pytest.skip(f"{PSB} is not available")
    with np.load(PSB) as data:
        verts, faces = data["verts"], data["faces"]
        vo, fo, ids = data["vert_offsets"], data["face_offsets"], data["psb_ids"]
    for k in range(len(ids)) if indices is None else indices:
        yield (
            int(ids[k]),
            verts[vo[k] : vo[k + 1]].astype(np.float64),
            faces[fo[k] : fo[k + 1]].astype(np.int64),
        )


def test_psb_sample_end_to_end():
    with np.load(PSB) if PSB.exists() else _nothing() as data:
        ids = data["psb_ids"]
    sample = [0, 100, 200, 300, int(np.flatnonzero(ids == 351)[0])]
    for psb_id, v, f in _psb(sample):
        result = end_to_end(v, f)
        if psb_id == 351:  # the benchmark's zero-area face (and a few needles beside it)
            assert 1054 in result.report.mollified_faces and result.epsilon > 0


@pytest.mark.slow
def test_psb_all_end_to_end():
    for _, v, f in _psb():
        end_to_end(v, f)


class _nothing:
    def __enter__(self):
        pytest.skip(f"{PSB} is not available")

    def __exit__(self, *exc):
        return False


# --------------------------------------------------------------------------- generated defects


def _sphere(level=2):
    v, f = ev.icosphere(level)
    return v.numpy().copy(), f.numpy().copy()


@st.composite
def defective(draw):
    """An icosphere with random defects; returns verts, faces (polygon list) and what was done."""
    v, f = _sphere(2)
    faces = [list(map(int, t)) for t in f]
    rng = np.random.default_rng(draw(st.integers(0, 2**31 - 1)))
    kinds = draw(
        st.sets(
            st.sampled_from(["flip", "fan", "bowtie", "sliver", "collinear", "dup", "repeat"]), min_size=1
        )
    )
    nv = len(v)
    if "flip" in kinds:  # a patch around a vertex, flipped
        c = int(rng.integers(nv))
        for i, t in enumerate(faces):
            if c in t:
                faces[i] = t[::-1]
    if "fan" in kinds:  # extra faces on one edge: a non-manifold fan
        a, b = faces[int(rng.integers(len(faces)))][:2]
        for _ in range(int(rng.integers(1, 4))):
            v = np.vstack([v, (v[a] + v[b]) / 2 + rng.normal(scale=0.2, size=3)])
            faces.append([a, b, len(v) - 1])
    if "bowtie" in kinds:  # a second sphere glued at one vertex
        w, g = _sphere(1)
        off = len(v)
        v = np.vstack([v, w + 3.0])
        g = g + off
        g[g == off] = int(rng.integers(nv))  # its vertex 0 is one of ours
        faces += [list(map(int, t)) for t in g]
    if "sliver" in kinds:  # a vertex moved onto the line of two neighbours: zero area, no move in repair
        t = faces[int(rng.integers(len(faces)))]
        v[t[0]] = v[t[1]] + 1e-9 * (v[t[2]] - v[t[1]])
    if "collinear" in kinds:
        t = faces[int(rng.integers(len(faces)))]
        v[t[0]] = 0.5 * (v[t[1]] + v[t[2]])
    if "dup" in kinds:
        i = int(rng.integers(len(faces)))
        faces.append(faces[i][::-1] if rng.random() < 0.5 else list(faces[i]))
    if "repeat" in kinds:
        t = faces[int(rng.integers(len(faces)))]
        faces.append([t[0], t[0], t[1]])
        faces.append([t[0], t[1], t[1], t[2]])
    return v, faces, kinds


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(defective())
def test_generated_defects_lose_nothing_unreported(case):
    v, faces, kinds = case
    given_faces = [list(t) for t in faces]
    result = ev.repair(v, faces)
    assert faces == given_faces  # not modified
    _accounted(result, len(faces))
    rep = result.report
    # each triangle is an input face (or a piece of one), with the input vertices; a
    # flipped cap and the face across its longest edge share their four vertices
    tri_in = result.vertex_origin[result.faces].numpy()
    caps = [set(faces[c]) for c in rep.flipped_caps]
    quads = [(c, c | set(g)) for c in caps for g in faces if len(c & set(g)) == 2]
    for row, f in zip(tri_in, result.face_origin.tolist()):
        corners, face = set(row.tolist()), set(faces[f])
        assert corners <= face or any(corners <= q and len(face & c) >= 2 for c, q in quads)
    # every dropped face has a reason that names it elsewhere in the report
    dup = {a for a, _ in rep.duplicate_faces}
    for f, why in rep.dropped_faces.items():
        assert f in dup or f in rep.repeated_index_faces, (f, why)
    if "flip" in kinds:
        assert rep.flipped_faces
    if "fan" in kinds:
        assert rep.non_manifold_edges
    if "bowtie" in kinds:
        assert rep.split_vertices
    if "collinear" in kinds:  # a cap: flipped with its neighbour, or mollified
        assert rep.flipped_caps or (rep.mollified_faces and result.epsilon > 0)
    topo, geom = result.topology, result.geometry
    lc = ev.connection_laplacian(geom, topo, n=1)
    assert torch.isfinite(lc.values()).all()
    slack = geom.lengths.sum(1, keepdim=True) - 2 * geom.lengths
    assert float(slack.min()) > 0
