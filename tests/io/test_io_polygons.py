"""Polygon faces of OBJ and PLY files: triangulated in their planes by the library's reader.

The polygon is an L-shaped hexagon in a tilted plane. Its reflex corner sees the whole L,
so a fan from there would be valid; the file lists the L from the tip next to it, whose
fan has a triangle that faces against the polygon and overlaps its neighbours (checked by
``test_the_fan_of_the_polygon_is_flipped``, so that the reader tests can fail).
"""

import struct
from pathlib import Path

import numpy as np
import pytest
import trimesh

from torch_edgevf.io import load_mesh, read_triangles

from conftest import SHARED

# the L (area 3) in its own coordinates, counter-clockwise, from a tip next to the reflex corner (1, 1)
L_2D = np.array([(2, 1), (1, 1), (1, 2), (0, 2), (0, 0), (2, 0)], dtype=np.float64)
U_AXIS = np.array([2.0, -2.0, 1.0]) / 3
W_AXIS = np.array([1.0, 2.0, 2.0]) / 3
ORIGIN = np.array([0.5, -1.0, 3.0])
L_3D = ORIGIN + L_2D[:, :1] * U_AXIS + L_2D[:, 1:] * W_AXIS
L_AREA = 3.0
EXTRA = np.array([[5.0, 5.0, 5.0], [6.0, 5.0, 5.0], [5.0, 6.0, 5.0]])  # a separate triangle


def newell_normal(p: np.ndarray) -> np.ndarray:
    """Twice the vector area of the polygon ``p`` (k, 3)."""
    return np.cross(p, np.roll(p, -1, axis=0)).sum(0)


def signed_areas(verts: np.ndarray, tris: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Areas of the triangles projected on ``normal``: positive where they turn as the polygon."""
    a, b, c = (verts[tris[:, i]] for i in range(3))
    return 0.5 * np.cross(b - a, c - a) @ (normal / np.linalg.norm(normal))


def check_polygon(verts: np.ndarray, tris: np.ndarray, k: int = 6, area: float = L_AREA, polygon=L_3D):
    """``tris`` are the ``k - 2`` triangles of ``polygon``, all turning as it does, covering it once."""
    assert tris.shape == (k - 2, 3)
    assert np.array_equal(np.unique(tris), np.arange(k)) and np.allclose(verts[:k], polygon, atol=1e-12)
    a = signed_areas(verts, tris, newell_normal(polygon))
    assert (a > 1e-9).all(), a
    assert a.sum() == pytest.approx(area, rel=1e-12)


def fmt(x: float) -> str:
    return f"{x:.17g}"


def write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def test_the_fan_of_the_polygon_is_flipped():
    fan = np.array([[0, j, j + 1] for j in range(1, 5)])
    a = signed_areas(L_3D, fan, newell_normal(L_3D))
    assert a.min() < 0 and a.sum() == pytest.approx(L_AREA)  # a flipped triangle, overlaps cancelling


# ----------------------------------------------------------------------------- OBJ


def obj_positions(extra: bool = False) -> str:
    pts = np.vstack([EXTRA, L_3D]) if extra else L_3D
    return "".join(f"v {fmt(x)} {fmt(y)} {fmt(z)}\n" for x, y, z in pts)


OBJ_VARIANTS = {
    "plain": obj_positions() + "f 1 2 3 4 5 6\n",
    "v/vt/vn": obj_positions()
    + "".join(f"vt {i / 6} {i / 7}\n" for i in range(6))
    + "vn -0.6666 -0.3333 0.6666\n"
    + "f 1/1/1 2/2/1 3/3/1 4/4/1 5/5/1 6/6/1\n",
    "v//vn": obj_positions() + "vn 0 0 1\nf 1//1 2//1 3//1 4//1 5//1 6//1\n",
    "v/vt": obj_positions() + "vt 0 0\nvt 1 0\nf 1/1 2/2 3/1 4/2 5/1 6/2\n",
    "negative": obj_positions() + "f -6 -5 -4 -3 -2 -1\n",
    "negative v/vt/vn": obj_positions()
    + "vt 0 0\nvn 0 0 1\nf -6/-1/-1 -5/-1/-1 -4/1/1 -3/1/1 -2/1/1 -1/1/1\n",
    "continued": obj_positions() + "f 1 2 3 \\\n  4 5 \\\n6\n",
    "comments": "# an L\n" + obj_positions() + "f 1 2 3 4 5 6 # the L\n# f 1 2 3\n",
}


@pytest.mark.parametrize("variant", list(OBJ_VARIANTS))
def test_obj_polygon_triangulated_in_its_plane(tmp_path, variant):
    path = write(tmp_path / "l.obj", OBJ_VARIANTS[variant])
    mesh = load_mesh(path)
    verts, tris = mesh.verts.numpy(), mesh.faces.numpy()
    check_polygon(verts, tris)
    r = mesh.report
    assert r.triangulated_faces == [0] and (r.file_faces, r.num_faces) == (1, 4)
    text = str(r)
    assert "triangulated polygons: 1 faces -> 4 triangles" in text
    assert "(1 polygons split into triangles in their planes)" in text
    assert "fans" not in text


def test_obj_polygon_in_a_second_object_with_relative_indices(tmp_path):
    text = (
        "o first\n"
        + "".join(f"v {fmt(x)} {fmt(y)} {fmt(z)}\n" for x, y, z in EXTRA)
        + "g tri\nusemtl a\nf 1 2 3\n"
        + "o second\n"
        + obj_positions()
        + "g hexagon\nusemtl b\ns 1\nf -6 -5 -4 -3 -2 -1\nl 1 2\n"
    )
    v, f, r = read_triangles(write(tmp_path / "two.obj", text))
    assert v.shape == (9, 3) and np.array_equal(v[:3], EXTRA)
    assert f[0].tolist() == [0, 1, 2]  # faces in file order
    check_polygon(v[3:], f[1:] - 3)
    assert r.triangulated_faces == [1] and (r.file_faces, r.loaded_faces) == (2, 5)
    assert "triangulated polygons: 2 faces -> 5 triangles" in str(r)


def test_obj_polygon_with_shared_vertices_and_out_of_range_index(tmp_path):
    # the L and the square glued to its tip side (2, 0)-(2, 1), sharing two vertices
    square = ORIGIN + np.array([[3, 0], [3, 1]])[:, :1] * U_AXIS + np.array([[3, 0], [3, 1]])[:, 1:] * W_AXIS
    text = obj_positions() + "".join(f"v {fmt(x)} {fmt(y)} {fmt(z)}\n" for x, y, z in square)
    mesh = load_mesh(write(tmp_path / "glued.obj", text + "f 1 2 3 4 5 6\nf 6 7 8 1\n"))
    assert mesh.faces.shape == (6, 3) and mesh.report.triangulated_faces == [0, 1]
    check_polygon(mesh.verts.numpy(), mesh.faces[:4].numpy())
    normal = newell_normal(L_3D)
    assert (signed_areas(mesh.verts.numpy(), mesh.faces[4:].numpy(), normal) > 0).all()
    with pytest.raises(ValueError, match="face index outside"):
        load_mesh(write(tmp_path / "bad.obj", obj_positions() + "f 1 2 3 4 5 9\n"))
    with pytest.raises(ValueError, match="not a valid OBJ file"):
        load_mesh(write(tmp_path / "junk.obj", obj_positions() + "f 1 2 3 4 5 x\n"))


@pytest.mark.parametrize("ext", ["obj", "ply"])
def test_polygon_without_a_plane_keeps_the_fan_and_is_named(tmp_path, ext):
    pts = [(0, 0, 0), (1, 0, 0), (2, 0, 0), (3, 0, 0), (0, 1, 0), (1, 1, 0)]  # a straight quad, a triangle
    if ext == "obj":
        text = "".join(f"v {x} {y} {z}\n" for x, y, z in pts) + "f 1 5 6\nf 1 2 3 4\n"
    else:
        text = (
            ply_header("ascii", 6, 2) + "".join(f"{x} {y} {z}\n" for x, y, z in pts) + "3 0 4 5\n4 0 1 2 3\n"
        )
    r = read_triangles(write(tmp_path / f"flat.{ext}", text))[2]
    assert r.triangulated_faces == [1] and r.loaded_faces == 3
    text = str(r)
    assert "triangulated polygons: 2 faces -> 3 triangles" in text
    assert (
        "1 polygons without a plane or not simple in it were split into fans from their first corner" in text
    )
    assert "file faces [1]" in text


# ----------------------------------------------------------------------------- PLY


def ply_header(fmt_name: str, nv: int, nf: int, scalar: str = "double", extra_face: str = "") -> str:
    return (
        f"ply\nformat {fmt_name} 1.0\ncomment an L\nelement vertex {nv}\n"
        f"property {scalar} x\nproperty {scalar} y\nproperty {scalar} z\n"
        f"element face {nf}\nproperty list uchar int vertex_indices\n{extra_face}end_header\n"
    )


def ply_file(path: Path, fmt_name: str, polys: list[list[int]], verts: np.ndarray) -> Path:
    head = ply_header(fmt_name, len(verts), len(polys))
    if fmt_name == "ascii":
        body = "".join(" ".join(fmt(x) for x in v) + "\n" for v in verts)
        body += "".join(f"{len(p)} " + " ".join(map(str, p)) + "\n" for p in polys)
        path.write_text(head + body)
        return path
    e = ">" if "big" in fmt_name else "<"
    data = np.asarray(verts, dtype=f"{e}f8").tobytes()
    data += b"".join(struct.pack(f"{e}B{len(p)}i", len(p), *p) for p in polys)
    path.write_bytes(head.encode() + data)
    return path


PLY_FORMATS = ["ascii", "binary_little_endian", "binary_big_endian"]


@pytest.mark.parametrize("fmt_name", PLY_FORMATS)
@pytest.mark.parametrize("mixed", [False, True], ids=["hexagon", "with-triangle"])
def test_ply_polygon_triangulated_in_its_plane(tmp_path, fmt_name, mixed):
    # trimesh reads the hexagon alone (all lists of one length); a binary file mixing it with a
    # triangle is one its binary reader rejects
    verts = np.vstack([L_3D, EXTRA]) if mixed else L_3D
    polys = [[0, 1, 2, 3, 4, 5]] + ([[6, 7, 8]] if mixed else [])
    mesh = load_mesh(ply_file(tmp_path / "l.ply", fmt_name, polys, verts))
    v, f = mesh.verts.numpy(), mesh.faces.numpy()
    check_polygon(v, f[:4])
    r = mesh.report
    assert r.triangulated_faces == [0] and r.num_faces == 4 + mixed
    if mixed:
        assert f[4].tolist() == [6, 7, 8] and np.array_equal(v[6:], EXTRA)
    text = str(r)
    assert f"triangulated polygons: {1 + mixed} faces -> {4 + mixed} triangles" in text
    assert "(1 polygons split into triangles in their planes)" in text


def test_binary_ply_whose_list_sizes_add_up(tmp_path):
    # a quad, a triangle and a pentagon: 12 indices, as many as three quads, so trimesh's
    # binary reader takes every list to be a quad without noticing; the stored counts tell
    sq = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=np.float64)
    verts = np.vstack([sq, sq + [3, 0, 0], L_3D])
    polys = [[0, 1, 2, 3], [4, 5, 6], [8, 9, 10, 11, 12]]  # the pentagon: the L's first five corners
    path = ply_file(tmp_path / "sizes.ply", "binary_little_endian", polys, verts)
    v, f, r = read_triangles(path)
    assert len(f) == 2 + 1 + 3 and r.triangulated_faces == [0, 2]
    assert f[2].tolist() == [4, 5, 6]
    pent = L_3D[:5]
    check_polygon(v[8:], f[3:] - 8, k=5, area=np.linalg.norm(newell_normal(pent)) / 2, polygon=pent)


@pytest.mark.parametrize("endian", ["<", ">"])
def test_binary_ply_with_int_counts_and_other_properties(tmp_path, endian):
    # per-face colour around the index list (and an int count), then an element trimesh would also read
    name = "binary_big_endian" if endian == ">" else "binary_little_endian"
    head = (
        f"ply\nformat {name} 1.0\nelement vertex 9\nproperty double x\nproperty double y\n"
        "property double z\nproperty uchar red\nelement face 2\nproperty uchar flag\n"
        "property list int uint vertex_index\nproperty float quality\n"
        "element edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n"
    )
    vrow = np.dtype([("p", f"{endian}f8", 3), ("red", "u1")])
    vdata = np.zeros(9, vrow)
    vdata["p"], vdata["red"] = np.vstack([EXTRA, L_3D]), 7
    faces = b"".join(
        struct.pack(f"{endian}Bi{len(p)}If", 1, len(p), *p, 0.5) for p in ([0, 1, 2], [3, 4, 5, 6, 7, 8])
    )
    path = tmp_path / "props.ply"
    path.write_bytes(head.encode() + vdata.tobytes() + faces + struct.pack(f"{endian}2i", 0, 1))
    v, f, r = read_triangles(path)
    assert f[0].tolist() == [0, 1, 2] and r.triangulated_faces == [1]
    check_polygon(v[3:], f[1:] - 3)


def test_ply_triangle_strips_still_read(tmp_path):
    text = (
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
        "element tristrips 1\nproperty list int int vertex_indices\nend_header\n"
        "0 0 0\n1 0 0\n0 1 0\n1 1 0\n4 0 1 2 3\n"
    )
    v, f, r = read_triangles(write(tmp_path / "strip.ply", text))
    assert f.tolist() == [[0, 1, 2], [2, 1, 3]] and "unrolled triangle strips" in str(r)


# ----------------------------------------------------------------------------- triangles as before


def trimesh_arrays(path: Path) -> tuple[np.ndarray, np.ndarray]:
    loaded = trimesh.load(path, process=False)
    return np.asarray(loaded.vertices, dtype=np.float64), np.asarray(loaded.faces, dtype=np.int64)


TRIANGLE_OBJS = {
    "plain": obj_positions(extra=True) + "f 1 2 3\nf 4 5 6\nf 4 6 7\n",
    "v/vt/vn": obj_positions(extra=True)
    + "vt 0 0\nvt 1 0\nvt 0 1\nvn 0 0 1\n"
    + "f 1/1/1 2/2/1 3/3/1\nf 4/1/1 5/2/1 6/3/1\nf 4/2/1 6/3/1 7/1/1\n",
    "comments": "# triangles\n" + obj_positions(extra=True) + "# f 1 2 3 4\nf 1 2 3\nf 4 5 6\n",
    "continued": obj_positions(extra=True) + "f 1 2 \\\n3\nf 4 5 6\n",
}


@pytest.mark.parametrize("variant", list(TRIANGLE_OBJS))
def test_triangle_obj_reads_as_trimesh_does(tmp_path, variant):
    """The same triangles, corner by corner, as trimesh reads; the vertices are the file's records
    (trimesh drops unused ones and splits those with several texture coordinates)."""
    path = write(tmp_path / "tri.obj", TRIANGLE_OBJS[variant])
    v, f, r = read_triangles(path)
    tv, tf = trimesh_arrays(path)
    assert np.array_equal(v[f], tv[tf]) and np.array_equal(v, np.vstack([EXTRA, L_3D]))
    assert r.triangulated_faces == [] and "split into triangles in their planes" not in str(r)


@pytest.mark.parametrize("fmt_name", PLY_FORMATS)
def test_triangle_ply_reads_as_trimesh_does(tmp_path, fmt_name):
    path = ply_file(
        tmp_path / "tri.ply", fmt_name, [[0, 1, 2], [3, 4, 5], [3, 5, 6]], np.vstack([EXTRA, L_3D])
    )
    v, f, r = read_triangles(path)
    tv, tf = trimesh_arrays(path)
    assert np.array_equal(v, tv) and np.array_equal(f, tf) and r.triangulated_faces == []


def test_shared_triangle_mesh_reads_as_trimesh_does():
    path = SHARED / "meshes" / "spot_low_resolution.obj"
    if not path.is_file():
        pytest.skip(f"{path} is not available")
    v, f, r = read_triangles(path)
    tv, tf = trimesh_arrays(path)
    assert np.array_equal(v[f], tv[tf]) and (len(v), len(tv)) == (829, 3 * 1654)
    assert (r.file_vertices, r.loaded_vertices, r.file_faces, r.loaded_faces) == (829, 829, 1654, 1654)
