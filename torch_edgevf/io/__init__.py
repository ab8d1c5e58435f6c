"""Reading and writing triangle meshes and edge-based tangent fields.

Meshes
    :func:`load_mesh` reads OFF, OBJ and PLY files itself, each in a few vectorised
    steps (the records gathered and parsed by numpy in one call per block), and STL
    (and PLY layouts the fast reader does not cover) through trimesh with
    ``process=False`` (trimesh neither merges, reorders, drops faces nor fixes
    winding). The vertices are the file's vertex records, in order: an OBJ file's
    ``v`` records, whatever its texture coordinates and normals. It then does its own
    documented clean-up and records every change in a :class:`MeshReport`:

    1. a scene of several geometries (through trimesh) is concatenated, in
       scene-graph order;
    2. faces with a repeated vertex index are dropped, then repeated faces (same
       three vertices in any order) keeping the first;
    3. with ``merge=True`` (the default), vertices at bitwise-identical positions are
       merged where the merge joins two boundary edges into one manifold edge: a crack
       of zero width, as where a seam is stored twice or every triangle has its own
       vertices (STL). Vertices that merging would make a bowtie or the end of an edge
       of three faces (surfaces touching at a vertex or along an edge, three sheets at
       one edge) are left apart and listed (:mod:`~torch_edgevf.io.merge`);
    4. unreferenced vertices are dropped.

    Merging is exact rather than within a tolerance: seam copies of one vertex
    carry the same coordinates, while a tolerance could fuse distinct vertices.
    Positions are never rounded or moved; kept vertices stay in first-occurrence
    order. :class:`MeshData` carries the maps between the file's vertices and the
    mesh's (``vertex_map``, ``vertex_origin``). Polygons (faces of more than three
    corners, of OFF, OBJ and PLY files) are triangulated in their planes by
    :func:`~torch_edgevf.mesh.repair.triangulate` from the file's positions and index
    lists (trimesh would split them into fans from their first corner, which is wrong
    for concave ones); the report names them and shows the face counts of the file
    next to the triangle counts.

    :func:`save_mesh` writes OBJ, OFF (``%.17g`` text) and PLY (binary float64)
    itself, because trimesh writes OBJ and OFF with a fixed number of decimals and
    PLY in float32; STL goes through trimesh and is float32 by definition.

Fields
    :func:`save_field` / :func:`load_field` store a mesh with a complex field on
    its edges, ``z`` of shape ``(E,)`` or ``(E, C)``, and the symmetry order ``n``.
    Edges are the unique pairs ``(i, j)``, ``i < j``, of the faces in lexicographic
    order (:func:`edges_from_faces`). ``.npz`` (``np.savez``, no pickles) is
    bit-exact; ``.txt`` is a plain interchange format::

        edgevf_field version=1 V=<V> F=<F> E=<E> C=<C> n=<n> dims=<1|2>
        x y z                      (V lines)
        a b c                      (F lines, 0-based)
        i j re_1 im_1 ... re_C im_C   (E lines, i < j)

    with floats written as ``%.17g`` (exact round trip). ``dims`` tells whether
    ``z`` was ``(E,)`` or ``(E, C)``. The edge lines of a ``.txt`` file may come in
    any order (they are matched by their endpoints); those of ``.npz`` must be in
    ours.
"""

from __future__ import annotations

from .fields import FieldData, edges_from_faces, load_field, save_field
from .mesh import MESH_FORMATS, default_mesh, load_mesh, read_triangles, save_mesh
from .report import MeshData, MeshReport

__all__ = [
    "MeshData",
    "MeshReport",
    "FieldData",
    "load_mesh",
    "read_triangles",
    "save_mesh",
    "default_mesh",
    "save_field",
    "load_field",
    "edges_from_faces",
    "MESH_FORMATS",
]
