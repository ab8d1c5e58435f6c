"""Tests of torch_edgevf.io: mesh reading (merging, reports, errors), writing, field files."""

import logging
import zipfile
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.csgraph as csgraph
import torch

from torch_edgevf.io import (
    default_mesh,
    edges_from_faces,
    load_field,
    load_mesh,
    save_field,
    save_mesh,
)

from conftest import SHARED

MESH_DIR = SHARED / "meshes"

# shared/meshes/README.md (next to the repository): V, F, Euler characteristic, boundary edges
MESH_TABLE = {
    "spot_low_resolution.obj": (829, 1654, 2, 0),
    "spot.obj": (11533, 23062, 2, 0),
    "fish_low_resolution.obj": (945, 1886, 2, 0),
    "sphere.obj": (642, 1280, 2, 0),
    "torus.obj": (2304, 4608, 0, 0),
    "wingnut.obj": (3047, 6090, 2, 0),
    "penguin.obj": (3362, 6720, 2, 0),
    "goathead.obj": (2763, 5522, 2, 0),
    "koala_low_resolution.obj": (3560, 7116, 2, 0),
    "skull_low_resolution.obj": (5154, 10312, -2, 0),
    "mountain.obj": (25600, 50562, 1, 636),
    "plane_holes.obj": (8519, 16747, -25, 341),
    "bunny.obj": (3301, 6598, 2, 0),
}
# OBJ files with per-corner normals (trimesh would return three vertices per face for them;
# the reader keeps the file's vertex records)
SPLIT_BY_NORMALS = {
    "spot_low_resolution.obj",
    "spot.obj",
    "fish_low_resolution.obj",
    "skull_low_resolution.obj",
    "bunny.obj",
}


def shared_mesh(name: str) -> Path:
    if not MESH_DIR.is_dir():
        pytest.skip(f"shared test meshes not found at {MESH_DIR}")
    return MESH_DIR / name


def obj_positions(path: Path) -> np.ndarray:
    """The file's ``v`` records parsed by Python's float(), for bit-exact comparison."""
    return np.array(
        [line.split()[1:4] for line in path.read_text().splitlines() if line.startswith("v ")], dtype=float
    )


def stats(faces: torch.Tensor, num_vertices: int) -> dict:
    """Edges, boundary edges, components and orientation of a triangle mesh (naive numpy)."""
    f = faces.numpy()
    directed = f[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    undirected, counts = np.unique(np.sort(directed, axis=1), axis=0, return_counts=True)
    adj = sp.coo_matrix((np.ones(len(undirected)), undirected.T), shape=(num_vertices, num_vertices))
    return {
        "E": len(undirected),
        "boundary": int((counts == 1).sum()),
        "nonmanifold": int((counts > 2).sum()),
        "components": csgraph.connected_components(adj, directed=False)[0],
        "oriented": len(np.unique(directed, axis=0)) == len(directed),  # no directed edge twice
    }


def write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def same_bits(a: torch.Tensor, b: torch.Tensor) -> bool:
    """Bitwise equality (distinguishes -0.0 from 0.0, and nan == nan)."""
    if a.is_complex():
        a, b = torch.view_as_real(a), torch.view_as_real(b)
    return (
        a.shape == b.shape
        and a.dtype == b.dtype
        and np.array_equal(a.numpy().view(np.int64), b.numpy().view(np.int64))
    )


@pytest.fixture
def small_mesh():
    """An octahedron with awkward float64 coordinates (not representable in short decimal)."""
    rng = np.random.default_rng(0)
    v = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=float)
    v = v * (1 + rng.random((6, 1)) / 3) + np.array([1e-300, -0.0, 1 / 3])
    f = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])
    return torch.from_numpy(v), torch.from_numpy(f)


# ----------------------------------------------------------------------------- real meshes


@pytest.mark.parametrize("name", sorted(MESH_TABLE))
def test_shared_meshes_match_readme(name):
    mesh = load_mesh(shared_mesh(name))
    V, F, chi, boundary = MESH_TABLE[name]
    s = stats(mesh.faces, len(mesh.verts))
    assert (len(mesh.verts), len(mesh.faces)) == (V, F)
    assert len(mesh.verts) - s["E"] + len(mesh.faces) == chi
    assert s["boundary"] == boundary and s["nonmanifold"] == 0
    assert s["components"] == 1 and s["oriented"]
    assert mesh.verts.dtype == torch.float64 and mesh.faces.dtype == torch.int64
    report = mesh.report
    assert report.merged_vertices == 0 and report.left_apart == []
    assert report.dropped_faces == 0 and report.unreferenced_vertices == 0
    assert torch.equal(mesh.vertex_map, torch.arange(V)) and torch.equal(mesh.vertex_origin, torch.arange(V))
    assert (report.file_vertices, report.file_faces) == (V, F)
    # positions are the file's, bit for bit and in file order
    assert np.array_equal(mesh.verts.numpy(), obj_positions(MESH_DIR / name))


@pytest.mark.parametrize("name", sorted(SPLIT_BY_NORMALS))
def test_per_corner_normals_keep_the_file_vertices(name):
    """trimesh gives these files three vertices per triangle; the reader keeps the v records."""
    import trimesh

    path = shared_mesh(name)
    mesh = load_mesh(path, merge=False)
    V, F, _, _ = MESH_TABLE[name]
    assert (len(mesh.verts), len(mesh.faces)) == (V, F)
    peer = trimesh.load(path, process=False)
    assert len(peer.vertices) > V  # split at the normals' seams
    # the same triangles, corner by corner
    assert np.array_equal(mesh.verts.numpy()[mesh.faces.numpy()], peer.vertices[peer.faces])


def test_merging_reconnects_a_soup(tmp_path):
    """A triangle soup (every triangle its own vertices, as STL stores them) is joined back."""
    mesh = default_mesh()
    soup_v = mesh.verts[mesh.faces].reshape(-1, 3)
    soup_f = torch.arange(3 * 1654).reshape(-1, 3)
    save_mesh(tmp_path / "soup.obj", soup_v, soup_f)
    raw = load_mesh(tmp_path / "soup.obj", merge=False)
    merged = load_mesh(tmp_path / "soup.obj")
    assert len(raw.verts) == 3 * 1654 and raw.report.merged_vertices == 0
    assert stats(raw.faces, len(raw.verts))["components"] == 1654  # disconnected triangles
    r = merged.report
    assert len(merged.verts) == 829 and r.merged_vertices == 3 * 1654 - 829 and r.left_apart == []
    assert r.joined_edges == 2481  # every edge of the closed mesh: two boundary edges joined
    assert stats(merged.faces, 829)["components"] == 1
    # the same triangles, corner by corner; the same vertices, in first-occurrence order
    assert torch.equal(raw.verts[raw.faces], merged.verts[merged.faces])
    corners = mesh.faces.numpy().ravel()
    _, first = np.unique(corners, return_index=True)
    perm = corners[np.sort(first)]  # the original vertices in order of first use
    rank = np.argsort(perm)
    assert torch.equal(merged.verts, mesh.verts[perm])
    assert np.array_equal(merged.faces.numpy(), rank[mesh.faces.numpy()])
    assert torch.equal(merged.vertex_map[soup_f], merged.faces)
    assert torch.equal(merged.verts, soup_v[merged.vertex_origin])


def test_default_mesh():
    mesh = default_mesh()
    assert mesh.verts.shape == (829, 3) and mesh.faces.shape == (1654, 3)
    s = stats(mesh.faces, 829)
    assert 829 - s["E"] + 1654 == 2 and s["boundary"] == 0 and s["components"] == 1
    assert default_mesh(dtype=torch.float32).verts.dtype == torch.float32
    verts, faces = mesh  # unpacking
    if MESH_DIR.is_dir():  # the shipped copy only lost its normals
        shared = load_mesh(MESH_DIR / "spot_low_resolution.obj")
        assert torch.equal(shared.verts, verts) and torch.equal(shared.faces, faces)


# ----------------------------------------------------------------------------- clean-up and report


def test_report_counts_cleanup(tmp_path, caplog):
    # v5 repeats v1's position, v6 is unused; face 2 repeats face 1, face 3 has a repeated
    # index; face 4 uses v5, which joins no boundary edge: it stays apart (a zero-area face)
    path = write(
        tmp_path / "dirty.obj",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nv 0 0 0\nv 9 9 9\nf 1 2 3\nf 2 4 3\nf 3 2 1\nf 1 1 2\nf 1 5 2\n",
    )
    with caplog.at_level(logging.WARNING, logger="torch_edgevf.io"):
        mesh = load_mesh(path)
    r = mesh.report
    assert mesh.faces.tolist() == [[0, 1, 2], [1, 3, 2], [0, 4, 1]]
    assert (r.merged_vertices, r.degenerate_faces, r.duplicate_faces) == (0, 1, 1)
    assert (r.file_vertices, r.loaded_vertices, r.num_vertices, r.unreferenced_vertices) == (6, 6, 5, 1)
    assert r.left_apart == [0, 4] and r.repeated_index_faces == [3]
    assert mesh.vertex_map.tolist() == [0, 1, 2, 3, 4, -1] and mesh.vertex_origin.tolist() == [0, 1, 2, 3, 4]
    text = str(r)
    assert (
        "merged 0 vertices" in text
        and "1 degenerate faces, 1 duplicate faces, 1 unreferenced vertices" in text
        and "left 2 vertices apart" in text
        and "dirty.obj" in text
    )
    assert "dirty.obj" in caplog.text  # faces were dropped: logged as a warning


def test_unreferenced_vertices_dropped(tmp_path):
    path = write(tmp_path / "m.off", "OFF\n5 1 0\n0 0 0\n7 7 7\n1 0 0\n0 1 0\n8 8 8\n3 0 2 3\n")
    mesh = load_mesh(path)
    assert mesh.report.unreferenced_vertices == 2 and mesh.faces.tolist() == [[0, 1, 2]]
    assert mesh.verts.tolist() == [[0, 0, 0], [1, 0, 0], [0, 1, 0]]


@pytest.mark.parametrize("ext", ["obj", "off", "ply"])
def test_polygons_are_triangulated_and_reported(tmp_path, ext):
    verts = ["0 0 0", "1 0 0", "1 1 0", "0 1 0", "2 0 0"]
    if ext == "obj":
        text = "".join(f"v {v}\n" for v in verts) + "f 1 2 3 4\nf 2 5 3\n"
    elif ext == "off":
        text = "OFF\n5 2 0\n" + "\n".join(verts) + "\n4 0 1 2 3\n3 1 4 2\n"
    else:
        text = (
            "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\nproperty float z\n"
            "element face 2\nproperty list uchar int vertex_indices\nend_header\n"
            + "\n".join(verts)
            + "\n4 0 1 2 3\n3 1 4 2\n"
        )
    r = load_mesh(write(tmp_path / f"quad.{ext}", text)).report
    assert r.triangulated and (r.file_faces, r.num_faces) == (2, 3)
    assert "triangulated polygons: 2 faces -> 3 triangles" in str(r)


def test_materials_and_groups_share_the_vertex_list(tmp_path):
    write(tmp_path / "two.mtl", "newmtl a\nKd 1 0 0\nnewmtl b\nKd 0 1 0\n")
    path = write(
        tmp_path / "two.obj",
        "mtllib two.mtl\no first\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nusemtl a\nf 1 2 3\n"
        "g second\nusemtl b\nf 1 3 4\n",
    )
    mesh = load_mesh(path)
    assert mesh.report.geometries == 1 and mesh.report.merged_vertices == 0
    assert mesh.verts.shape == (4, 3) and mesh.faces.tolist() == [[0, 1, 2], [0, 2, 3]]
    assert stats(mesh.faces, 4)["components"] == 1


def test_scene_of_several_geometries_is_concatenated(tmp_path):
    """A GLB-like scene read by trimesh (here an STL is one geometry; a scene of two is built)."""
    import trimesh

    a = trimesh.creation.box()
    b = trimesh.creation.box()
    b.apply_translation([3, 0, 0])
    scene = trimesh.Scene([a, b])
    from torch_edgevf.io.report import MeshReport
    from torch_edgevf.io.trimesh_reader import _read_trimesh

    report = MeshReport(path="scene", format="glb")
    verts, faces = _read_trimesh(Path("scene"), report, scene)
    assert report.geometries == 2 and "concatenated 2 geometries" in " ".join(report.notes)
    assert verts.shape == (16, 3) and faces.shape == (24, 3)
    assert stats(torch.from_numpy(faces), 16)["components"] == 2


# ----------------------------------------------------------------------------- errors


@pytest.mark.parametrize(
    "name, content, message",
    [
        ("missing.obj", None, "no such file"),
        ("mesh.glb", "", "unsupported extension '.glb'"),
        ("empty.obj", "", "no triangle faces found"),
        ("junk.obj", "hello world\n", "no triangle faces found"),
        ("points.obj", "v 0 0 0\nv 1 0 0\n", "point cloud (2 points"),
        (
            "points.ply",
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
            "property float z\nend_header\n0 0 0\n",
            "point cloud",
        ),
        ("junk.ply", "garbage\n", "PLY parser failed"),
        ("junk.off", "garbage\n", "OFF parser failed"),
        ("junk.stl", "garbage\n", "not an STL file"),
        ("nan.obj", "v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n", "not finite"),
        ("bad.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n", "face index outside"),
        ("degenerate.obj", "v 0 0 0\nv 1 0 0\nf 1 2 2\n", "no faces left"),
    ],
)
def test_load_mesh_errors(tmp_path, name, content, message):
    path = tmp_path / name
    if content is not None:
        path.write_text(content)
    with pytest.raises(ValueError, match="cannot read mesh") as info:
        load_mesh(path)
    assert message in str(info.value) and name in str(info.value)


def test_load_mesh_rejects_integer_dtype():
    with pytest.raises(ValueError, match="dtype must be a floating torch dtype"):
        load_mesh("whatever.obj", dtype=torch.int64)


@pytest.mark.parametrize("ext", ["ply", "stl", "off"])
def test_truncated_files(tmp_path, ext):
    mesh = default_mesh()
    save_mesh(tmp_path / f"full.{ext}", mesh.verts, mesh.faces)
    data = (tmp_path / f"full.{ext}").read_bytes()
    (tmp_path / f"cut.{ext}").write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match=f"cannot read mesh .*cut.{ext}"):
        load_mesh(tmp_path / f"cut.{ext}")


def test_save_mesh_errors(tmp_path, small_mesh):
    verts, faces = small_mesh
    with pytest.raises(ValueError, match="unsupported extension"):
        save_mesh(tmp_path / "m.glb", verts, faces)
    with pytest.raises(ValueError, match=r"face indices must lie in \[0, 6\)"):
        save_mesh(tmp_path / "m.obj", verts, faces + 1)
    with pytest.raises(ValueError, match="faces must be a"):
        save_mesh(tmp_path / "m.obj", verts, faces.double())
    with pytest.raises(ValueError, match="verts must be a"):
        save_mesh(tmp_path / "m.obj", verts[:, :2], faces)


# ----------------------------------------------------------------------------- mesh round trips


@pytest.mark.parametrize("ext", ["obj", "ply", "off"])
def test_mesh_round_trip_exact(tmp_path, small_mesh, ext):
    verts, faces = small_mesh
    save_mesh(tmp_path / f"m.{ext}", verts, faces)
    back = load_mesh(tmp_path / f"m.{ext}")
    assert same_bits(back.verts, verts) and torch.equal(back.faces, faces)
    assert back.report.merged_vertices == 0 and back.report.dropped_faces == 0


def test_mesh_round_trip_stl(tmp_path):
    """STL keeps no vertex identity and stores float32: merging restores the connectivity."""
    mesh = default_mesh()
    save_mesh(tmp_path / "m.stl", mesh.verts, mesh.faces)
    back = load_mesh(tmp_path / "m.stl")
    assert back.verts.shape == (829, 3) and back.faces.shape == (1654, 3)
    assert back.report.merged_vertices == 3 * 1654 - 829
    expected = mesh.verts.float().double()[mesh.faces]  # the same triangles, corner by corner
    assert torch.equal(back.verts[back.faces], expected)
    assert stats(back.faces, 829)["components"] == 1


# ----------------------------------------------------------------------------- fields


def test_edges_from_faces():
    edges = edges_from_faces(np.array([[0, 1, 2], [2, 1, 3]]))
    assert edges.tolist() == [[0, 1], [0, 2], [1, 2], [1, 3], [2, 3]]
    assert edges.dtype == np.int64


def special_field(num_edges: int, channels: int | None, seed: int = 0) -> torch.Tensor:
    """Random complex128 values, the first ones replaced by -0.0, subnormals, huge, nan, inf and 1/3."""
    rng = np.random.default_rng(seed)
    shape = (num_edges,) if channels is None else (num_edges, channels)
    z = np.empty(shape, dtype=np.complex128)
    re, im = rng.standard_normal(shape).reshape(-1), rng.standard_normal(shape).reshape(-1)
    re[:4], im[:4] = [-0.0, 5e-324, np.nan, 1 / 3], [0.0, -1e308, np.inf, -0.0]
    z.real, z.imag = re.reshape(shape), im.reshape(shape)  # set parts directly: arithmetic would lose -0.0
    return torch.from_numpy(z)


@pytest.mark.parametrize("ext", ["npz", "txt"])
@pytest.mark.parametrize("channels", [None, 3])
def test_field_round_trip_exact(tmp_path, small_mesh, ext, channels):
    verts, faces = small_mesh
    z = special_field(12, channels)
    save_field(tmp_path / f"f.{ext}", verts, faces, z, n=4)
    back = load_field(tmp_path / f"f.{ext}")
    assert same_bits(back.verts, verts) and torch.equal(back.faces, faces)
    assert same_bits(back.z, z) and back.n == 4
    assert torch.equal(back.edges, torch.from_numpy(edges_from_faces(faces)))


def test_field_round_trip_default_mesh(tmp_path):
    mesh = default_mesh()
    E = len(edges_from_faces(mesh.faces))
    z = special_field(E, None, seed=1)
    singular = torch.tensor([3, 17])
    save_field(tmp_path / "spot.npz", mesh.verts, mesh.faces, z, n=1, singularities=singular)
    back = load_field(tmp_path / "spot.npz")
    assert E == 2481 and same_bits(back.z, z) and torch.equal(back.extra["singularities"], singular)
    with zipfile.ZipFile(tmp_path / "spot.npz") as zf:  # plain .npy members, nothing pickled
        assert sorted(zf.namelist()) == sorted(
            f"{k}.npy" for k in ["verts", "faces", "edges", "z", "n", "version", "singularities"]
        )


def test_field_txt_format_is_readable_and_order_free(tmp_path, small_mesh):
    verts, faces = small_mesh
    z = special_field(12, None)
    save_field(tmp_path / "f.txt", verts, faces, z, n=2)
    lines = (tmp_path / "f.txt").read_text().splitlines()
    assert lines[0] == "edgevf_field version=1 V=6 F=8 E=12 C=1 n=2 dims=1"
    assert len(lines) == 1 + 6 + 8 + 12
    assert lines[1 + 6 + 8].split()[:2] == ["0", "2"]  # edge lines start with endpoints i < j
    # another tool may list the edges in its own order: they are matched by endpoints
    edge_lines = lines[15:]
    (tmp_path / "g.txt").write_text("\n".join(lines[:15] + edge_lines[::-1]) + "\n")
    assert same_bits(load_field(tmp_path / "g.txt").z, z)


def test_field_save_errors(tmp_path, small_mesh):
    verts, faces = small_mesh
    z = torch.zeros(12, dtype=torch.complex128)
    with pytest.raises(ValueError, match=r"z must have shape \(E,\) or \(E, C\) with E = 12"):
        save_field(tmp_path / "f.npz", verts, faces, z[:11])
    with pytest.raises(ValueError, match="n must be a positive integer"):
        save_field(tmp_path / "f.npz", verts, faces, z, n=0)
    for name in ("edges", "file", "allow_pickle"):
        with pytest.raises(ValueError, match=f"extra array name '{name}' is reserved"):
            save_field(tmp_path / "f.npz", verts, faces, z, **{name: np.zeros(3)})
    with pytest.raises(ValueError, match="not numeric"):
        save_field(tmp_path / "f.npz", verts, faces, z, names=np.array([{}, "a"], dtype=object))
    with pytest.raises(ValueError, match="cannot store extra arrays"):
        save_field(tmp_path / "f.txt", verts, faces, z, labels=np.zeros(3))
    with pytest.raises(ValueError, match="unsupported extension '.json'"):
        save_field(tmp_path / "f.json", verts, faces, z)


def test_field_npz_mismatch_raises(tmp_path, small_mesh):
    verts, faces = small_mesh
    z = special_field(12, None)
    good = dict(
        verts=verts.numpy(),
        faces=faces.numpy(),
        edges=edges_from_faces(faces),
        z=z.numpy(),
        n=np.int64(1),
        version=np.int64(1),
    )

    def check(message, **changes):
        np.savez(tmp_path / "bad.npz", **{**good, **changes})
        with pytest.raises(ValueError, match="cannot load field .*bad.npz") as info:
            load_field(tmp_path / "bad.npz")
        assert message in str(info.value)

    other_faces = faces.numpy().copy()
    other_faces[0] = other_faces[0, ::-1]  # same edges: still valid
    np.savez(tmp_path / "ok.npz", **{**good, "faces": other_faces})
    assert load_field(tmp_path / "ok.npz").faces.shape == (8, 3)

    check("do not match", edges=good["edges"][::-1])
    check("do not match", faces=np.array([[0, 1, 2]] * 8))
    check("z must have shape", z=z.numpy()[:11])
    check("z must be complex128", z=np.zeros(12, dtype=np.complex64))
    check("format version 2", version=np.int64(2))
    check("n must be a positive integer", n=np.int64(-1))
    check("face indices must lie", faces=faces.numpy() + 10)
    np.savez(tmp_path / "bad.npz", **{k: v for k, v in good.items() if k != "edges"})
    with pytest.raises(ValueError, match=r"missing arrays \['edges'\]"):
        load_field(tmp_path / "bad.npz")
    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    with pytest.raises(ValueError, match="not a readable .npz"):
        load_field(tmp_path / "bad.npz")
    with pytest.raises(ValueError, match="no such file"):
        load_field(tmp_path / "nothing.npz")


def test_field_txt_mismatch_raises(tmp_path, small_mesh):
    verts, faces = small_mesh
    save_field(tmp_path / "f.txt", verts, faces, special_field(12, None))
    lines = (tmp_path / "f.txt").read_text().splitlines()

    def check(message, new_lines):
        (tmp_path / "bad.txt").write_text("\n".join(new_lines) + "\n")
        with pytest.raises(ValueError, match="cannot load field .*bad.txt") as info:
            load_field(tmp_path / "bad.txt")
        assert message in str(info.value)

    face_changed = lines.copy()
    face_changed[7] = "0 1 4"  # face 0 was 0 2 4: edges (0, 1) appears, (0, 2) loses a face
    check("do not match", face_changed)
    swapped = lines.copy()
    i, j, *rest = swapped[15].split()
    swapped[15] = " ".join([j, i, *rest])
    check("i < j", swapped)
    check("announces", lines[:-1])
    check("first line must be", ["hello"] + lines[1:])
    check("version 9", [lines[0].replace("version=1", "version=9")] + lines[1:])
    check("cannot parse the vertex lines", lines[:1] + ["a b c"] + lines[2:])
    check("must have 4 numbers", lines[:15] + [lines[15] + " 7"] + lines[16:])


OBJ_LAYOUTS = {
    "plain": "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n",
    "crlf": "v 0 0 0\r\nv 1 0 0\r\nv 0 1 0\r\nv 1 1 0\r\nf 1 2 3\r\nf 2 4 3\r\n",
    "tabs and indents": "v\t0 0 0\n  v 1\t0 0\n\tv 0 1 0\nv 1 1 0\n  f 1 2 3\nf\t2 4 3",
    "comments": "# a square\nv 0 0 0 # origin\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3 # first\nf 2 4 3\n",
    "colours and w": "v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 0 1 0 1.0\nv 1 1 0\nf 1/1 2/2 3/3\nf 2//1 4//1 3//1\n",
    "negative, interleaved": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\nv 1 1 0\nf -3 -1 -2\n",
    "objects and groups": "o a\nv 0 0 0\nv 1 0 0\nv 0 1 0\ng g1\nf 1 2 3\no b\nv 1 1 0\nusemtl m\nf 2 4 3\n",
}


@pytest.mark.parametrize("layout", sorted(OBJ_LAYOUTS))
def test_obj_layouts_read_alike(tmp_path, layout):
    mesh = load_mesh(write(tmp_path / "square.obj", OBJ_LAYOUTS[layout]))
    assert mesh.faces.tolist() == [[0, 1, 2], [1, 3, 2]]
    assert mesh.verts.tolist() == [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]
    assert (mesh.report.file_vertices, mesh.report.file_faces) == (4, 2)


@pytest.mark.parametrize(
    "content, message",
    [
        ("v 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "record 'v 0 0': fewer than three coordinates"),
        ("v 0 0 x\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "record 'v 0 0 x': not a number"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3.5\n", "record 'f 1 2 3.5'"),
        ("v 0 0 0\nv 1 0 0\nl 1 2\n", "it holds lines"),
    ],
)
def test_obj_errors_name_the_record(tmp_path, content, message):
    with pytest.raises(ValueError, match="cannot read mesh .*bad.obj") as info:
        load_mesh(write(tmp_path / "bad.obj", content))
    assert message in str(info.value)
