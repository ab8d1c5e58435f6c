"""Deliberately naive reference of every edge-based operator (numpy, dense, per-face loops).

This module is independent of ``torch_edgevf``: it re-derives each operator straight from the
thesis formulas (chapters 2-5, appendix A) with one Python loop over faces and dense numpy
arrays, so that tests can compare the vectorised torch implementation against it. It is meant
to be obviously correct, not fast; use it on meshes with at most a few hundred faces.

Conventions (identical to ``torch_edgevf.mesh.topology``)
----------------------------------------------------
* ``verts`` is a ``(V, 3)`` float64 array, ``faces`` an ``(F, 3)`` integer array of
  counter-clockwise triangles; corner ``k`` of face ``f`` is the vertex ``f[k]``.
* Edges are the unique pairs ``(i, j)``, ``i < j``, sorted lexicographically; the frame
  ``X_e`` of an edge is the unit vector from ``v_i`` to ``v_j``.
* The edge opposite corner ``k`` joins ``f[k+1]`` and ``f[k+2]`` (indices mod 3); its sign
  ``delta_k`` is ``+1`` when ``f[k+1] < f[k+2]`` (the face runs along it from low to high).
* ``alpha_k`` is the interior angle at corner ``k``, ``A`` the face area, ``|e_k|`` the length
  of the edge opposite corner ``k``.
* Transport inside a face (thesis sec. 2.3): ``r[a, b]`` converts a coefficient expressed in
  the frame of the edge opposite corner ``a`` into the frame of the edge opposite corner
  ``b``, i.e. ``r[a, b] = X_a / X_b`` when the frames are written as complex numbers in the
  face plane (face normal = counter-clockwise orientation). For the counter-clockwise
  successor ``b = a + 1 (mod 3)`` and ``c`` the third corner,
  ``r[a, b] = -delta_a delta_b exp(i alpha_c)``; then ``r[b, a] = conj(r[a, b])`` and
  ``r[a, a] = 1``. (The thesis writes ``r_ij = -delta_i delta_j e^{i alpha_k}`` for the
  oriented triangle ``T_ijk``, i.e. ``j`` follows ``i`` counter-clockwise.)
  :func:`transport_from_frames` computes the same numbers from the 3D frames directly.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "edges",
    "face_edge_table",
    "edge_lengths",
    "face_areas",
    "corner_angles",
    "transport",
    "transport_from_frames",
    "mass",
    "connection_laplacian",
    "gradient",
    "curl_div_K",
    "real_form",
    "curl_energy",
    "div_energy",
    "laplace_beltrami",
    "laplace_beltrami_complex",
    "vertex_mass",
    "vertex_div_curl",
    "covariant_derivative",
    "cotan_laplacian",
    "dihedral_angles",
    "angle_defects",
    "edge_frames",
    "boundary_edge_mask",
    "random_mesh",
    "octahedron",
    "icosphere",
    "grid_mesh",
]


# --------------------------------------------------------------------------- topology


def _as_arrays(verts, faces):
    verts = np.asarray(verts, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    return verts, faces


def edges(faces) -> np.ndarray:
    """(E, 2) int64: the unique undirected edges ``(i, j)``, ``i < j``, sorted lexicographically."""
    pairs = set()
    for f in np.asarray(faces, dtype=np.int64):
        for k in range(3):
            i, j = int(f[(k + 1) % 3]), int(f[(k + 2) % 3])
            pairs.add((min(i, j), max(i, j)))
    return np.array(sorted(pairs), dtype=np.int64).reshape(-1, 2)


def _edge_index(faces) -> dict:
    return {(int(i), int(j)): e for e, (i, j) in enumerate(edges(faces))}


def face_edge_table(faces):
    """Per face and corner: ``(edge id, delta)`` of the edge opposite that corner.

    Returns ``face_edges (F, 3) int64`` and ``signs (F, 3) int64``.
    """
    faces = np.asarray(faces, dtype=np.int64)
    index = _edge_index(faces)
    fe = np.zeros(faces.shape, dtype=np.int64)
    sg = np.zeros(faces.shape, dtype=np.int64)
    for t, f in enumerate(faces):
        for k in range(3):
            i, j = int(f[(k + 1) % 3]), int(f[(k + 2) % 3])
            fe[t, k] = index[(min(i, j), max(i, j))]
            sg[t, k] = 1 if i < j else -1
    return fe, sg


def boundary_edge_mask(faces) -> np.ndarray:
    """(E,) bool: edges with exactly one incident face."""
    fe, _ = face_edge_table(faces)
    count = np.zeros(len(edges(faces)), dtype=np.int64)
    for row in fe:
        for e in row:
            count[e] += 1
    return count == 1


# --------------------------------------------------------------------------- per-face geometry


def _face_local(verts, f):
    """Geometry of one face: corner angles, opposite lengths, area, deltas (all length 3)."""
    p = [verts[f[k]] for k in range(3)]
    lengths = np.array([np.linalg.norm(p[(k + 2) % 3] - p[(k + 1) % 3]) for k in range(3)])
    angles = np.zeros(3)
    for k in range(3):
        u = p[(k + 1) % 3] - p[k]
        v = p[(k + 2) % 3] - p[k]
        angles[k] = np.arctan2(np.linalg.norm(np.cross(u, v)), np.dot(u, v))
    area = 0.5 * np.linalg.norm(np.cross(p[1] - p[0], p[2] - p[0]))
    deltas = np.array([1 if f[(k + 1) % 3] < f[(k + 2) % 3] else -1 for k in range(3)])
    return angles, lengths, area, deltas


def _face_transport(angles, deltas) -> np.ndarray:
    """3x3 complex ``r[a, b]`` for one face, from the thesis formula."""
    r = np.eye(3, dtype=np.complex128)
    for a in range(3):
        b = (a + 1) % 3
        c = (a + 2) % 3
        r[a, b] = -deltas[a] * deltas[b] * np.exp(1j * angles[c])
        r[b, a] = np.conj(r[a, b])
    return r


def edge_lengths(verts, faces) -> np.ndarray:
    """(E,) length of each edge."""
    verts, faces = _as_arrays(verts, faces)
    return np.array([np.linalg.norm(verts[j] - verts[i]) for i, j in edges(faces)])


def face_areas(verts, faces) -> np.ndarray:
    """(F,) area of each face."""
    verts, faces = _as_arrays(verts, faces)
    return np.array([_face_local(verts, f)[2] for f in faces])


def corner_angles(verts, faces) -> np.ndarray:
    """(F, 3) interior angle at each corner."""
    verts, faces = _as_arrays(verts, faces)
    return np.array([_face_local(verts, f)[0] for f in faces]).reshape(-1, 3)


def transport(verts, faces) -> np.ndarray:
    """(F, 3, 3) complex: ``r[f, a, b]`` from the frame of edge ``a`` to that of edge ``b``."""
    verts, faces = _as_arrays(verts, faces)
    out = np.zeros((len(faces), 3, 3), dtype=np.complex128)
    for t, f in enumerate(faces):
        angles, _, _, deltas = _face_local(verts, f)
        out[t] = _face_transport(angles, deltas)
    return out


def transport_from_frames(verts, faces) -> np.ndarray:
    """Same as :func:`transport`, but from the 3D edge frames: ``r[a, b] = X_a / X_b``.

    Each face gets an orthonormal basis ``(u, n x u)`` of its plane (``n`` the
    counter-clockwise unit normal); a frame becomes the complex number ``X.u + i X.(n x u)``.
    """
    verts, faces = _as_arrays(verts, faces)
    out = np.zeros((len(faces), 3, 3), dtype=np.complex128)
    for t, f in enumerate(faces):
        p = [verts[f[k]] for k in range(3)]
        n = np.cross(p[1] - p[0], p[2] - p[0])
        n /= np.linalg.norm(n)
        u = (p[1] - p[0]) / np.linalg.norm(p[1] - p[0])
        w = np.cross(n, u)
        frames = []
        for k in range(3):
            i, j = int(f[(k + 1) % 3]), int(f[(k + 2) % 3])
            lo, hi = min(i, j), max(i, j)
            x = verts[hi] - verts[lo]
            x /= np.linalg.norm(x)
            frames.append(np.dot(x, u) + 1j * np.dot(x, w))
        for a in range(3):
            for b in range(3):
                out[t, a, b] = frames[a] / frames[b]
    return out


def edge_frames(verts, faces) -> np.ndarray:
    """(E, 3) unit vectors ``X_e`` from the lower to the higher vertex index."""
    verts, faces = _as_arrays(verts, faces)
    out = []
    for i, j in edges(faces):
        x = verts[j] - verts[i]
        out.append(x / np.linalg.norm(x))
    return np.array(out).reshape(-1, 3)


# --------------------------------------------------------------------------- edge operators


def mass(verts, faces) -> np.ndarray:
    """(E, E) real diagonal ``M_z``: ``M_z[e, e] = sum over faces containing e of A / 3``."""
    verts, faces = _as_arrays(verts, faces)
    fe, _ = face_edge_table(faces)
    ne = len(edges(faces))
    M = np.zeros((ne, ne))
    for t, f in enumerate(faces):
        _, _, area, _ = _face_local(verts, f)
        for a in range(3):
            M[fe[t, a], fe[t, a]] += area / 3.0
    return M


def connection_laplacian(verts, faces, n: int = 1) -> np.ndarray:
    """(E, E) complex ``L_c^(n)`` (thesis sec. 3.1 and appendix A.3).

    Per face: ``L[e_a, e_a] += |e_a|^2 / A`` and, for ``a != b`` with ``c`` the third corner,
    ``L[e_a, e_b] += -|e_a| |e_b| cos(alpha_c) / A * r[b, a]^n``.
    """
    verts, faces = _as_arrays(verts, faces)
    fe, _ = face_edge_table(faces)
    ne = len(edges(faces))
    L = np.zeros((ne, ne), dtype=np.complex128)
    for t, f in enumerate(faces):
        angles, lengths, area, deltas = _face_local(verts, f)
        r = _face_transport(angles, deltas)
        for a in range(3):
            L[fe[t, a], fe[t, a]] += lengths[a] ** 2 / area
            for b in range(3):
                if b == a:
                    continue
                c = 3 - a - b
                L[fe[t, a], fe[t, b]] += -lengths[a] * lengths[b] * np.cos(angles[c]) / area * r[b, a] ** n
    return L


def gradient(verts, faces) -> np.ndarray:
    """(E, V) complex ``G`` (thesis sec. 4.2, appendix A.4).

    Per face and corners ``a, b`` (``b`` may equal ``a``):
    ``G[e_a, f[b]] += i delta_b |e_b| / 6 * r[b, a]``.
    """
    verts, faces = _as_arrays(verts, faces)
    fe, _ = face_edge_table(faces)
    ne, nv = len(edges(faces)), verts.shape[0]
    G = np.zeros((ne, nv), dtype=np.complex128)
    for t, f in enumerate(faces):
        angles, lengths, _, deltas = _face_local(verts, f)
        r = _face_transport(angles, deltas)
        for a in range(3):
            for b in range(3):
                G[fe[t, a], f[b]] += 1j * deltas[b] * lengths[b] / 6.0 * r[b, a]
    return G


def curl_div_K(verts, faces) -> np.ndarray:
    """(F, E) real ``K`` with ``K[f, e_a] = delta_a |e_a|`` (thesis sec. 3.3).

    ``curl_T = K Re(z) / A_T`` and ``div_T = -K Im(z) / A_T``.
    """
    verts, faces = _as_arrays(verts, faces)
    fe, _ = face_edge_table(faces)
    ne = len(edges(faces))
    K = np.zeros((len(faces), ne))
    for t, f in enumerate(faces):
        _, lengths, _, deltas = _face_local(verts, f)
        for a in range(3):
            K[t, fe[t, a]] += deltas[a] * lengths[a]
    return K


def real_form(A) -> np.ndarray:
    """(2n, 2m) real form ``[[Re A, -Im A], [Im A, Re A]]`` of a complex (n, m) matrix."""
    A = np.asarray(A, dtype=np.complex128)
    return np.block([[A.real, -A.imag], [A.imag, A.real]])


def _KtMK(verts, faces) -> np.ndarray:
    K = curl_div_K(verts, faces)
    Mt_inv = np.diag(1.0 / face_areas(verts, faces))
    return K.T @ Mt_inv @ K


def curl_energy(verts, faces) -> np.ndarray:
    """(2E, 2E) ``L_curl = [[K^T M_t^-1 K, 0], [0, 0]]``."""
    B = _KtMK(verts, faces)
    Z = np.zeros_like(B)
    return np.block([[B, Z], [Z, Z]])


def div_energy(verts, faces) -> np.ndarray:
    """(2E, 2E) ``L_div = [[0, 0], [0, K^T M_t^-1 K]]``."""
    B = _KtMK(verts, faces)
    Z = np.zeros_like(B)
    return np.block([[Z, Z], [Z, B]])


def laplace_beltrami_complex(verts, faces) -> np.ndarray:
    """(V, V) complex ``G^H M_z^-1 G`` (before taking the real part)."""
    G = gradient(verts, faces)
    Minv = np.diag(1.0 / np.diag(mass(verts, faces)))
    return G.conj().T @ Minv @ G


def laplace_beltrami(verts, faces) -> np.ndarray:
    """(V, V) real ``L = Re(G^H M_z^-1 G)`` (thesis eq. 4.2)."""
    return laplace_beltrami_complex(verts, faces).real


def vertex_mass(verts, faces, lumped: bool = False) -> np.ndarray:
    """(V, V) P1 mass: full ``A/6`` diagonal and ``A/12`` off-diagonal, or lumped ``A/3``."""
    verts, faces = _as_arrays(verts, faces)
    nv = verts.shape[0]
    M = np.zeros((nv, nv))
    for f in faces:
        _, _, area, _ = _face_local(verts, f)
        for a in range(3):
            if lumped:
                M[f[a], f[a]] += area / 3.0
            else:
                for b in range(3):
                    M[f[a], f[b]] += area / 6.0 if a == b else area / 12.0
    return M


def vertex_div_curl(verts, faces, z, lumped: bool = False):
    """Vertex divergence and curl from ``-G^H z = M_v (div_v + i curl_v)`` (thesis B.4).

    Unreferenced vertices (zero rows of ``M_v``) are not supported.
    """
    G = gradient(verts, faces)
    Mv = vertex_mass(verts, faces, lumped=lumped)
    rhs = -G.conj().T @ np.asarray(z, dtype=np.complex128)
    sol = np.linalg.solve(Mv.astype(np.complex128), rhs)
    return sol.real, sol.imag


def covariant_derivative(verts, faces, w) -> np.ndarray:
    """(E, E) complex ``D_w`` for an edge field ``w`` (thesis sec. 5.1, appendix A.5).

    Per face, ``a != b``: ``D[e_a, e_b] += -delta_b |e_b| / 3 * Im(w_a r[a, b]) * r[b, a]``;
    ``a == b``: ``D[e_a, e_a] += -delta_a |e_a| / 3 * Im(w_a)`` (cancels on interior edges).
    """
    verts, faces = _as_arrays(verts, faces)
    w = np.asarray(w, dtype=np.complex128)
    fe, _ = face_edge_table(faces)
    ne = len(edges(faces))
    D = np.zeros((ne, ne), dtype=np.complex128)
    for t, f in enumerate(faces):
        angles, lengths, _, deltas = _face_local(verts, f)
        r = _face_transport(angles, deltas)
        for a in range(3):
            wa = w[fe[t, a]]
            for b in range(3):
                # r[a, a] = 1, so the diagonal formula is the same expression.
                D[fe[t, a], fe[t, b]] += -deltas[b] * lengths[b] / 3.0 * np.imag(wa * r[a, b]) * r[b, a]
    return D


def cotan_laplacian(verts, faces) -> np.ndarray:
    """(V, V) positive semi-definite cotangent stiffness matrix."""
    verts, faces = _as_arrays(verts, faces)
    nv = verts.shape[0]
    C = np.zeros((nv, nv))
    for f in faces:
        angles, _, _, _ = _face_local(verts, f)
        for k in range(3):
            i, j = f[(k + 1) % 3], f[(k + 2) % 3]
            w = 0.5 / np.tan(angles[k])
            C[i, j] -= w
            C[j, i] -= w
            C[i, i] += w
            C[j, j] += w
    return C


# --------------------------------------------------------------------------- extrinsic geometry


def _unit_normal(verts, f):
    n = np.cross(verts[f[1]] - verts[f[0]], verts[f[2]] - verts[f[0]])
    return n / np.linalg.norm(n)


def dihedral_angles(verts, faces) -> np.ndarray:
    """(E,) signed dihedral angle; positive on convex edges, 0 on boundary edges.

    ``beta = atan2(t . (n_L x n_R), n_L . n_R)``, ``t`` the unit edge vector from low to high,
    ``n_L`` the normal of the face running along the edge low -> high, ``n_R`` of the other.
    """
    verts, faces = _as_arrays(verts, faces)
    fe, sg = face_edge_table(faces)
    E = edges(faces)
    left = -np.ones(len(E), dtype=np.int64)
    right = -np.ones(len(E), dtype=np.int64)
    for t in range(len(faces)):
        for k in range(3):
            if sg[t, k] > 0:
                left[fe[t, k]] = t
            else:
                right[fe[t, k]] = t
    beta = np.zeros(len(E))
    for e, (i, j) in enumerate(E):
        if left[e] < 0 or right[e] < 0:
            continue
        tvec = verts[j] - verts[i]
        tvec /= np.linalg.norm(tvec)
        nl = _unit_normal(verts, faces[left[e]])
        nr = _unit_normal(verts, faces[right[e]])
        beta[e] = np.arctan2(np.dot(tvec, np.cross(nl, nr)), np.dot(nl, nr))
    return beta


def angle_defects(verts, faces) -> np.ndarray:
    """(V,) ``2 pi - sum of angles`` at interior vertices, ``pi - sum`` at boundary vertices.

    Unreferenced vertices are not supported (they would get ``2 pi``).
    """
    verts, faces = _as_arrays(verts, faces)
    nv = verts.shape[0]
    on_boundary = np.zeros(nv, dtype=bool)
    for (i, j), is_boundary in zip(edges(faces), boundary_edge_mask(faces)):
        if is_boundary:
            on_boundary[i] = on_boundary[j] = True
    total = np.zeros(nv)
    for f in faces:
        angles, _, _, _ = _face_local(verts, f)
        for k in range(3):
            total[f[k]] += angles[k]
    return np.where(on_boundary, np.pi, 2.0 * np.pi) - total


# --------------------------------------------------------------------------- test meshes


def _orient_outward(verts, faces):
    """Flip faces of a star-shaped closed mesh around the origin so that normals point out."""
    out = []
    for f in faces:
        n = np.cross(verts[f[1]] - verts[f[0]], verts[f[2]] - verts[f[0]])
        c = verts[f].mean(axis=0)
        out.append([f[0], f[1], f[2]] if np.dot(n, c) > 0 else [f[0], f[2], f[1]])
    return np.array(out, dtype=np.int64)


def octahedron():
    """Regular octahedron with outward (counter-clockwise) faces: 6 vertices, 8 faces."""
    verts = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=np.float64)
    faces = []
    for x in (0, 1):
        for y in (2, 3):
            for z in (4, 5):
                faces.append([x, y, z])
    return verts, _orient_outward(verts, np.array(faces))


def icosphere(subdivisions: int = 1):
    """Unit icosahedron, subdivided ``subdivisions`` times (1 -> 42 vertices, 80 faces)."""
    phi = (1.0 + np.sqrt(5.0)) / 2.0
    verts = []
    for a in (-1.0, 1.0):
        for b in (-phi, phi):
            verts += [[0.0, a, b], [a, b, 0.0], [b, 0.0, a]]
    verts = np.array(verts)
    verts /= np.linalg.norm(verts, axis=1, keepdims=True)
    # The 20 faces are the triples of mutually nearest vertices (edge length is the minimum).
    d = np.linalg.norm(verts[:, None] - verts[None], axis=2)
    edge_len = np.min(d[d > 1e-9])
    adj = np.abs(d - edge_len) < 1e-6
    faces = []
    for i in range(12):
        for j in range(i + 1, 12):
            for k in range(j + 1, 12):
                if adj[i, j] and adj[j, k] and adj[i, k]:
                    faces.append([i, j, k])
    faces = _orient_outward(verts, np.array(faces))
    for _ in range(subdivisions):
        verts_l = [v for v in verts]
        mid = {}

        def midpoint(i, j):
            key = (min(i, j), max(i, j))
            if key not in mid:
                p = verts_l[i] + verts_l[j]
                verts_l.append(p / np.linalg.norm(p))
                mid[key] = len(verts_l) - 1
            return mid[key]

        new_faces = []
        for a, b, c in faces:
            ab, bc, ca = midpoint(a, b), midpoint(b, c), midpoint(c, a)
            new_faces += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        verts = np.array(verts_l)
        faces = np.array(new_faces, dtype=np.int64)
    return verts, faces


def grid_mesh(n: int = 4, jitter: float = 0.2, seed: int = 0):
    """Flat ``(n+1) x (n+1)`` grid on the unit square (z = 0), random diagonals, jittered
    interior vertices; counter-clockwise faces (normal +z)."""
    rng = np.random.default_rng(seed)
    h = 1.0 / n
    verts = np.array([[i * h, j * h, 0.0] for j in range(n + 1) for i in range(n + 1)])
    for j in range(1, n):
        for i in range(1, n):
            verts[j * (n + 1) + i, :2] += jitter * h * rng.uniform(-1, 1, size=2)
    faces = []
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i
            b, c, d = a + 1, a + n + 2, a + n + 1  # counter-clockwise square a b c d
            if rng.random() < 0.5:
                faces += [[a, b, c], [a, c, d]]
            else:
                faces += [[a, b, d], [b, c, d]]
    return verts, np.array(faces, dtype=np.int64)


def _renumber(verts, faces, rng):
    """Random vertex permutation and random cyclic rotation of each face's corners."""
    perm = rng.permutation(verts.shape[0])  # old index -> new index
    new_verts = np.empty_like(verts)
    new_verts[perm] = verts
    new_faces = perm[faces]
    shifts = rng.integers(0, 3, size=len(faces))
    new_faces = np.array([np.roll(f, s) for f, s in zip(new_faces, shifts)], dtype=np.int64)
    return new_verts, new_faces


def random_mesh(seed: int, kind: str = "sphere", noise: float = 0.15):
    """Small random test mesh with vertices randomly renumbered (mixed edge orientations).

    kind
        ``"sphere"``: icosahedron subdivided once (42 vertices, 80 faces, closed) with radial
        and tangential noise; ``"octahedron"``: perturbed octahedron (closed, 8 faces);
        ``"flat"``: flat jittered 4x4 grid in the plane z = 0 (boundary, 32 faces), randomly
        rotated about z; ``"bumpy"``: the same grid lifted to a random smooth height field
        (curved, with boundary).
    """
    rng = np.random.default_rng(seed)
    if kind == "sphere":
        verts, faces = icosphere(1)
        verts = verts * (1.0 + noise * rng.uniform(-1, 1, size=(len(verts), 1)))
        verts = verts + 0.3 * noise * rng.normal(size=verts.shape) / 4.0
    elif kind == "octahedron":
        verts, faces = octahedron()
        verts = verts * (1.0 + noise * rng.uniform(-1, 1, size=(len(verts), 1)))
        verts = verts + 0.5 * noise * rng.normal(size=verts.shape) / 4.0
    elif kind in ("flat", "bumpy"):
        verts, faces = grid_mesh(4, jitter=0.25, seed=int(rng.integers(1 << 30)))
        theta = rng.uniform(0, 2 * np.pi)
        rot = np.array([[np.cos(theta), -np.sin(theta), 0], [np.sin(theta), np.cos(theta), 0], [0, 0, 1]])
        verts = verts @ rot.T + np.array([rng.normal(), rng.normal(), 0.0])
        if kind == "bumpy":
            a, b, c = rng.normal(size=3)
            x, y = verts[:, 0], verts[:, 1]
            verts[:, 2] = 0.3 * (a * np.sin(2 * x + b) * np.cos(1.5 * y + c) + 0.5 * x * y)
    else:
        raise ValueError(f"unknown mesh kind {kind!r}")
    return _renumber(verts, faces, rng)
