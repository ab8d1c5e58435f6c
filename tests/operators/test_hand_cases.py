"""Hand-computed cases and mathematical identities, on the naive reference and on torch.

Part 1 works out every operator analytically on tiny meshes (comments show the arithmetic)
and asserts both backends reproduce the numbers: this is what makes ``naive_reference``
trustworthy. Part 2 checks identities that hold exactly for any mesh (or for linear fields
on flat meshes), again on both backends.

Notation: corner ``k`` of a face, ``e_k`` the edge opposite it, ``delta_k`` its sign,
``X`` an edge frame written as a complex number in the plane of the face.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_naive_reference import assert_close, torch_backend

import naive_reference as ref

S2 = np.sqrt(2.0)
S3 = np.sqrt(3.0)
PI = np.pi


def cis(t):
    return np.exp(1j * t)


@pytest.fixture(params=["reference", "torch"])
def bk(request):
    """The backend under test: the reference module itself, or the torch adapter."""
    return ref if request.param == "reference" else torch_backend


def close(actual, expected, what="", rel=1e-13):
    assert_close(actual, expected, rel=rel, what=what)


# =========================================================================== Part 1: hand cases
#
# --------------------------------------------------------------------------- right isoceles
# v0 = (0,0,0), v1 = (1,0,0), v2 = (0,1,0); face (0, 1, 2), counter-clockwise (normal +z).
# Edges (sorted): e0 = (0,1), e1 = (0,2), e2 = (1,2).
#   corner 0 (v0): alpha = pi/2, opposite edge {1,2} = e2, delta = +1 (1 < 2), |e| = sqrt2
#   corner 1 (v1): alpha = pi/4, opposite edge {2,0} = e1, delta = -1 (2 > 0), |e| = 1
#   corner 2 (v2): alpha = pi/4, opposite edge {0,1} = e0, delta = +1,         |e| = 1
# Area A = 1/2. Frames: X_e0 = 1, X_e1 = i, X_e2 = (-1+i)/sqrt2 = cis(3pi/4).
# Transport (r_ab = X_a / X_b, corners a -> b):
#   r_01 = -d0 d1 cis(alpha2) = cis(pi/4)      check: X_e2 / X_e1 = cis(3pi/4 - pi/2)
#   r_12 = -d1 d2 cis(alpha0) = i              check: X_e1 / X_e0 = i
#   r_20 = -d2 d0 cis(alpha1) = -cis(pi/4)     check: X_e0 / X_e2 = cis(-3pi/4) = cis(5pi/4)

RIGHT = (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float), np.array([[0, 1, 2]]))


def test_right_triangle_topology_and_geometry(bk):
    v, f = RIGHT
    np.testing.assert_array_equal(bk.edges(f), [[0, 1], [0, 2], [1, 2]])
    fe, sg = bk.face_edge_table(f)
    np.testing.assert_array_equal(fe, [[2, 1, 0]])
    np.testing.assert_array_equal(sg, [[1, -1, 1]])
    close(bk.edge_lengths(v, f), [1, 1, S2])
    close(bk.face_areas(v, f), [0.5])
    close(bk.corner_angles(v, f), [[PI / 2, PI / 4, PI / 4]])
    close(bk.dihedral_angles(v, f), [0, 0, 0])
    # all boundary: pi - alpha
    close(bk.angle_defects(v, f), [PI / 2, 3 * PI / 4, 3 * PI / 4])


def test_right_triangle_transport(bk):
    v, f = RIGHT
    r01, r12, r20 = cis(PI / 4), 1j, cis(5 * PI / 4)
    expected = np.array([[1, r01, np.conj(r20)], [np.conj(r01), 1, r12], [r20, np.conj(r12), 1]])
    close(bk.transport(v, f)[0], expected)
    close(ref.transport_from_frames(v, f)[0], expected)


def test_right_triangle_mass_and_laplacian(bk):
    v, f = RIGHT
    close(bk.mass(v, f), np.eye(3) / 6)  # A/3 = 1/6 on every edge
    # Diagonal |e_a|^2 / A: e0 -> 1/(1/2) = 2, e1 -> 2, e2 -> 2/(1/2) = 4.
    # Off-diagonal -|e_a||e_b| cos(alpha_c) / A * r_ba:
    #   (e2, e1): corners (0, 1), c = 2: -sqrt2 * 1 * cos(pi/4) * 2 = -2; r_10 = cis(-pi/4)
    #             -> L[e2, e1] = -2 cis(-pi/4) = -sqrt2 + sqrt2 i
    #   (e1, e0): corners (1, 2), c = 0: cos(pi/2) = 0 -> 0
    #   (e0, e2): corners (2, 0), c = 1: -1 * sqrt2 * cos(pi/4) * 2 = -2; r_02 = cis(3pi/4)
    #             -> L[e0, e2] = -2 cis(3pi/4) = sqrt2 - sqrt2 i
    L1 = np.array(
        [
            [2, 0, S2 - S2 * 1j],
            [0, 2, -S2 - S2 * 1j],
            [S2 + S2 * 1j, -S2 + S2 * 1j, 4],
        ]
    )
    close(bk.connection_laplacian(v, f, n=1), L1, "L_c^(1)")
    # n = 0: drop r -> real CR Laplacian, rows sum to 0
    L0 = np.array([[2, 0, -2], [0, 2, -2], [-2, -2, 4]], float)
    close(bk.connection_laplacian(v, f, n=0), L0, "L_c^(0)")
    # n = 2: r_10^2 = cis(-pi/2) = -i -> L[e2, e1] = 2i;  r_02^2 = cis(3pi/2) = -i -> L[e0, e2] = 2i
    L2 = np.array([[2, 0, 2j], [0, 2, -2j], [-2j, 2j, 4]])
    close(bk.connection_laplacian(v, f, n=2), L2, "L_c^(2)")
    # The constant field (1, 0) is z_e = conj(X_e) = (1, -i, cis(-3pi/4)); L1 z = 0.
    z = np.array([1, -1j, cis(-3 * PI / 4)])
    close(L1 @ z, np.zeros(3))
    close(L2 @ z**2, np.zeros(3))


def test_right_triangle_gradient(bk):
    v, f = RIGHT
    # G[e_a, f[b]] = i delta_b |e_b| / 6 * r_ba
    # row e2 (corner 0): b=0: i sqrt2/6;  b=1: i(-1)(1)/6 cis(-pi/4) = -(1+i)/(6 sqrt2);
    #                    b=2: i/6 cis(5pi/4) = cis(7pi/4)/6 = (1-i)/(6 sqrt2)
    # row e1 (corner 1): b=1: -i/6;  b=0: i sqrt2/6 cis(pi/4) = (-1+i)/6;  b=2: i/6 (-i) = 1/6
    # row e0 (corner 2): b=2: i/6;   b=0: i sqrt2/6 cis(3pi/4) = (-1-i)/6; b=1: -i/6 * i = 1/6
    G = np.array(
        [
            [(-1 - 1j) / 6, 1 / 6, 1j / 6],
            [(-1 + 1j) / 6, -1j / 6, 1 / 6],
            [1j * S2 / 6, -(1 + 1j) / (6 * S2), (1 - 1j) / (6 * S2)],
        ]
    )
    close(bk.gradient(v, f), G, "G")
    # f = x = (0, 1, 0): M_z^-1 G f = 6 G[:, 1] = (1, -i, -(1+i)/sqrt2) = conj(X_e), the
    # constant gradient (1, 0) in the edge frames.
    close(6 * G[:, 1], [1, -1j, cis(-3 * PI / 4)])
    # K[f, e_a] = delta_a |e_a|: e0 -> +1, e1 -> -1, e2 -> +sqrt2
    K = np.array([[1, -1, S2]])
    close(bk.curl_div_K(v, f), K, "K")
    # L_curl block = K^T K / A
    B = 2 * K.T @ K
    Z = np.zeros((3, 3))
    close(bk.curl_energy(v, f), np.block([[B, Z], [Z, Z]]), "L_curl")
    close(bk.div_energy(v, f), np.block([[Z, Z], [Z, B]]), "L_div")


def test_right_triangle_vertex_operators(bk):
    v, f = RIGHT
    # On a single flat triangle M_z^-1 G f is the exact (constant) gradient, so
    # Re(G^H M_z^-1 G) is the P1 stiffness = cotan Laplacian: weights cot(pi/4)/2 = 1/2 on
    # the legs (0,1), (0,2) and cot(pi/2)/2 = 0 on the hypotenuse.
    C = np.array([[1, -0.5, -0.5], [-0.5, 0.5, 0], [-0.5, 0, 0.5]])
    close(bk.laplace_beltrami(v, f), C, "LB")
    close(bk.cotan_laplacian(v, f), C, "cotan")
    # The imaginary part is the boundary term  int grad(phi_i) x grad(phi_j) = oint phi_i dphi_j:
    # for the counter-clockwise boundary 0 -> 1 -> 2 -> 0 it is +1/2 at (i, j) = (0,1), (1,2),
    # (2,0) and -1/2 at the transposed positions (e.g. 6 * conj(G[:,0]) . G[:,1] = (-1+i)/2).
    Im = 0.5 * np.array([[0, 1, -1], [-1, 0, 1], [1, -1, 0]])
    close(ref.laplace_beltrami_complex(v, f).imag, Im, "Im(G^H M^-1 G)")
    # vertex mass A/6 = 1/12 diagonal, A/12 = 1/24 off-diagonal; lumped A/3 = 1/6
    close(bk.vertex_mass(v, f), (np.ones((3, 3)) + np.eye(3)) / 24, "M_v")
    close(bk.vertex_mass(v, f, lumped=True), np.eye(3) / 6, "lumped M_v")


def test_right_triangle_covariant_derivative(bk):
    v, f = RIGHT
    # w = constant field (1, 0): w_e = conj(X_e) = (1, -i, cis(-3pi/4)). Then w_a r_ab is the
    # same field in frame b, conj(X_b), so Im(w_a r_ab) = -sin(theta_b) (theta_b = arg X_b)
    # and D[e_a, e_b] = delta_b |e_b| sin(theta_b) / 3 * r_ba =: c_b r_ba (diagonal included):
    #   e0: theta = 0          -> c = 0
    #   e1: theta = pi/2,  delta = -1, |e| = 1     -> c = -1/3
    #   e2: theta = 3pi/4, delta = +1, |e| = sqrt2 -> c = sqrt2 * (sqrt2/2) / 3 = 1/3
    # (c_b = int_T d(phi_b)/dx / ... = the x-derivative of the CR hat, integrated against A/3.)
    w = np.array([1, -1j, cis(-3 * PI / 4)])
    D = np.array(
        [
            [0, -1j / 3, cis(3 * PI / 4) / 3],  # r(e1 -> e0) = r_12 = i ; r(e2 -> e0) = r_02
            [0, -1 / 3, cis(PI / 4) / 3],  # r(e2 -> e1) = r_01
            [0, -cis(-PI / 4) / 3, 1 / 3],  # r(e1 -> e2) = r_10
        ]
    )
    close(bk.covariant_derivative(v, f, w), D, "D_w")
    # psi = (x, 0) has d psi / dx = (1, 0): z = psi(q_e)/X_e = (1/2, 0, cis(-3pi/4)/2) and
    # D_w z = M_z (1, 0) in the frames = (1, -i, cis(-3pi/4)) / 6.
    z = np.array([0.5, 0, cis(-3 * PI / 4) / 2])
    close(D @ z, w / 6)


# --------------------------------------------------------------------------- equilateral
# v0 = (0,0), v1 = (1,0), v2 = (1/2, sqrt3/2); all angles pi/3, all lengths 1, A = sqrt3/4.
# e0 = (0,1): corner 2, delta +1, X = 1;  e1 = (0,2): corner 1, delta -1, X = cis(pi/3);
# e2 = (1,2): corner 0, delta +1, X = cis(2pi/3).
# L_c: diagonal 1/A = 4/sqrt3; off-diagonal -cos(pi/3)/A * X_b/X_a = -(2/sqrt3) X_b/X_a.

EQUI = (np.array([[0, 0, 0], [1, 0, 0], [0.5, S3 / 2, 0]]), np.array([[0, 1, 2]]))


def test_equilateral_triangle(bk):
    v, f = EQUI
    close(bk.edge_lengths(v, f), [1, 1, 1])
    close(bk.face_areas(v, f), [S3 / 4])
    close(bk.corner_angles(v, f), [[PI / 3] * 3])
    close(bk.angle_defects(v, f), [2 * PI / 3] * 3)
    close(bk.mass(v, f), np.eye(3) * S3 / 12)
    X = np.array([1, cis(PI / 3), cis(2 * PI / 3)])
    L1 = np.where(np.eye(3) > 0, 4 / S3, -(2 / S3) * X[None, :] / X[:, None])
    close(bk.connection_laplacian(v, f, n=1), L1, "L_c^(1)")
    close(bk.connection_laplacian(v, f, n=0), (6 * np.eye(3) - 2 * np.ones((3, 3))) / S3, "L_c^(0)")
    close(
        bk.connection_laplacian(v, f, n=3),
        np.where(np.eye(3) > 0, 4 / S3, -(2 / S3) * (X[None, :] / X[:, None]) ** 3),
        "L_c^(3)",
    )
    # cotan weight cot(pi/3)/2 = 1/(2 sqrt3) on every edge
    C = (3 * np.eye(3) - np.ones((3, 3))) / (2 * S3)
    close(bk.cotan_laplacian(v, f), C, "cotan")
    close(bk.laplace_beltrami(v, f), C, "LB (single flat face: = cotan)")
    close(bk.curl_div_K(v, f), [[1, -1, 1]], "K")
    # r_01 = -d0 d1 cis(alpha2) = cis(pi/3) = X_e2 / X_e1
    close(bk.transport(v, f)[0, 0, 1], cis(PI / 3))


# --------------------------------------------------------------------------- unit square
# v0 = (0,0), v1 = (1,0), v2 = (1,1), v3 = (0,1); faces A = (0,1,2), B = (0,2,3).
# Edges: e0 = (0,1), e1 = (0,2), e2 = (0,3), e3 = (1,2), e4 = (2,3), lengths (1, sqrt2, 1, 1, 1).
# Face A: corner 0 (v0, pi/4) -> e3 (+1); corner 1 (v1, pi/2) -> e1 (-1); corner 2 (v2, pi/4) -> e0 (+1).
# Face B: corner 0 (v0, pi/4) -> e4 (+1); corner 1 (v2, pi/4) -> e2 (-1); corner 2 (v3, pi/2) -> e1 (+1).
# Frames: X_e0 = 1, X_e1 = cis(pi/4), X_e2 = i, X_e3 = i, X_e4 = -1.


def square(fold: float = 0.0):
    """Unit square; ``fold`` rotates v3 about the diagonal (0,2), downwards (convex) for
    ``fold > 0``: v3 = (1/2 - c/2, 1/2 + c/2, -s/sqrt2), ``|v3 - v0| = |v3 - v2| = 1``."""
    c, s = np.cos(fold), np.sin(fold)
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0.5 - 0.5 * c, 0.5 + 0.5 * c, -s / S2]])
    return v, np.array([[0, 1, 2], [0, 2, 3]])


SQUARE_L1 = np.diag([2, 8, 2, 2, 2]).astype(complex)
# Face A: (e3, e1) with c = v2 (pi/4): -1*sqrt2*cos(pi/4)*2 = -2, r(e1 -> e3) = X_e1/X_e3 = cis(-pi/4)
#         (e1, e0) with c = v0 (pi/4): -2, r(e0 -> e1) = X_e0/X_e1 = cis(-pi/4)
#         (e0, e3) with c = v1 (pi/2): 0
# Face B: (e2, e1) with c = v0 (pi/4): -2, r(e1 -> e2) = X_e1/X_e2 = cis(-pi/4)
#         (e1, e4) with c = v2 (pi/4): -2, r(e4 -> e1) = X_e4/X_e1 = -cis(-pi/4)  -> +2 cis(-pi/4)
#         (e4, e2) with c = v3 (pi/2): 0
for (_a, _b), _val in {
    (3, 1): -2 * cis(-PI / 4),
    (1, 0): -2 * cis(-PI / 4),
    (2, 1): -2 * cis(-PI / 4),
    (1, 4): 2 * cis(-PI / 4),
}.items():
    SQUARE_L1[_a, _b] = _val
    SQUARE_L1[_b, _a] = np.conj(_val)


@pytest.mark.parametrize("fold", [0.0, PI / 3, -PI / 5])
def test_square_intrinsic_operators(bk, fold):
    """Intrinsic operators only see lengths and angles: folding along the diagonal changes
    nothing (the folded square is isometric to the flat one)."""
    v, f = square(fold)
    close(bk.edge_lengths(v, f), [1, S2, 1, 1, 1])
    close(bk.mass(v, f), np.diag([1, 2, 1, 1, 1]) / 6)  # e1 is shared: 2 * (1/2)/3
    close(bk.connection_laplacian(v, f, n=1), SQUARE_L1, "L_c^(1)")
    # n = 0 keeps the moduli with signs of cos: real CR Laplacian
    L0 = np.diag([2, 8, 2, 2, 2]).astype(float)
    for a, b in [(3, 1), (1, 0), (2, 1), (1, 4)]:
        L0[a, b] = L0[b, a] = -2
    close(bk.connection_laplacian(v, f, n=0), L0, "L_c^(0)")
    # K rows: A: e3 +1, e1 -sqrt2, e0 +1;  B: e4 +1, e2 -1, e1 +sqrt2
    close(bk.curl_div_K(v, f), [[1, -S2, 0, 1, 0], [0, S2, -1, 0, 1]], "K")
    # Laplace-Beltrami: boundary edges carry the face gradient, e1 the mean of both:
    #   L = 1/3 (Gram(g_A) + Gram(g_B)) + 1/12 Gram(g_A + g_B), with
    #   g_A = ((-1,0), (1,-1), (0,1), 0), g_B = ((0,-1), 0, (1,0), (-1,1))
    LB = np.array([[5, -2, -1, -2], [-2, 5, -2, -1], [-1, -2, 5, -2], [-2, -1, -2, 5]]) / 6
    close(bk.laplace_beltrami(v, f), LB, "LB")
    # cotan: legs weight cot(pi/4)/2 = 1/2, diagonal (0,2) weight cot(pi/2) = 0
    C = np.array([[1, -0.5, 0, -0.5], [-0.5, 1, -0.5, 0], [0, -0.5, 1, -0.5], [-0.5, 0, -0.5, 1]])
    close(bk.cotan_laplacian(v, f), C, "cotan")
    # vertex masses: v0, v2 in both faces
    M = np.array([[4, 1, 2, 1], [1, 2, 1, 0], [2, 1, 4, 1], [1, 0, 1, 2]]) / 24
    close(bk.vertex_mass(v, f), M, "M_v")
    close(bk.vertex_mass(v, f, lumped=True), np.diag([2, 1, 2, 1]) / 6, "lumped M_v")
    close(bk.angle_defects(v, f), [PI / 2] * 4)


def test_square_boundary_term():
    """Im(G^H M_z^-1 G) = oint phi_i dphi_j on the boundary 0 -> 1 -> 2 -> 3 -> 0."""
    v, f = square()
    Im = np.zeros((4, 4))
    for a, b in [(0, 1), (1, 2), (2, 3), (3, 0)]:
        Im[a, b], Im[b, a] = 0.5, -0.5
    close(ref.laplace_beltrami_complex(v, f).imag, Im)


@pytest.mark.parametrize("fold", [PI / 3, -PI / 5, 0.0, 0.9 * PI])
def test_square_fold_dihedral(bk, fold):
    # e1 = (0,2) runs 0 -> 2 in face B = (0,2,3) (left, n_L) and 2 -> 0 in A (right, n_R = +z).
    # With v3 = (1/2 - c/2, 1/2 + c/2, -s/sqrt2): n_L = (-s/sqrt2, s/sqrt2, c),
    # n_L x n_R = (s/sqrt2, s/sqrt2, 0), t = (1,1,0)/sqrt2 -> t.(n_L x n_R) = s, n_L.n_R = c,
    # so beta = atan2(s, c) = fold: positive when folded away from the normal (convex ridge).
    v, f = square(fold)
    close(bk.dihedral_angles(v, f), [0, fold, 0, 0, 0])
    # Reversing every face flips the normals and swaps left and right: beta -> -beta.
    close(bk.dihedral_angles(v, f[:, ::-1].copy()), [0, -fold, 0, 0, 0])


# --------------------------------------------------------------------------- octahedron


def test_regular_octahedron(bk):
    v, f = ref.octahedron()
    # Edge length sqrt2, faces equilateral with area sqrt3/2, dihedral (interior) angle
    # arccos(-1/3), so the bending angle is pi - arccos(-1/3) = arccos(1/3) > 0 (convex).
    close(bk.edge_lengths(v, f), [S2] * 12)
    close(bk.dihedral_angles(v, f), [np.arccos(1 / 3)] * 12)
    close(bk.angle_defects(v, f), [2 * PI - 4 * PI / 3] * 6)
    close(bk.mass(v, f), np.eye(12) * 2 * (S3 / 2) / 3)
    # each edge in 2 faces: diagonal 2 * |e|^2 / A = 2 * 2 / (sqrt3/2) = 8/sqrt3
    close(np.diag(bk.connection_laplacian(v, f, n=1)), [8 / S3] * 12)


# =========================================================================== Part 2: identities


def close_id(actual, expected, what=""):
    """Identities sum many terms with cancellation: allow 1e-11 relative to max(1, |expected|)."""
    close(actual, expected, what, rel=1e-11)


CLOSED = [("sphere", 0), ("sphere", 1), ("octahedron", 2)]
OPEN = [("flat", 3), ("bumpy", 4)]
ALL = CLOSED + OPEN


def _mesh(kind_seed):
    return ref.random_mesh(kind_seed[1], kind_seed[0])


def _flat_mesh(seed):
    """Random flat mesh, moved into the plane z = 0 with the counter-clockwise side up."""
    v, f = ref.random_mesh(seed, "flat")
    assert np.all(v[:, 2] == 0)
    return v, f


def _complex_frames(v, f):
    X = ref.edge_frames(v, f)
    return X[:, 0] + 1j * X[:, 1]


def _midpoints(v, f):
    E = ref.edges(f)
    q = 0.5 * (v[E[:, 0]] + v[E[:, 1]])
    return q[:, 0] + 1j * q[:, 1]


def _linear_field(B, c, p):
    """psi(p) = B p + c as a complex number, p complex."""
    x, y = p.real, p.imag
    return (B[0, 0] * x + B[0, 1] * y + c[0]) + 1j * (B[1, 0] * x + B[1, 1] * y + c[1])


@pytest.mark.parametrize("case", ALL, ids=str)
@pytest.mark.parametrize("n", [0, 1, 2, 3])
def test_connection_laplacian_hermitian_psd(bk, case, n):
    v, f = _mesh(case)
    L = bk.connection_laplacian(v, f, n=n)
    close_id(L, L.conj().T, "Hermitian")
    close_id(np.diag(L).imag, np.zeros(L.shape[0]), "real diagonal")
    ev = np.linalg.eigvalsh(L)
    assert ev.min() > -1e-12 * ev.max(), ev.min()


@pytest.mark.parametrize("case", ALL, ids=str)
def test_cr_laplacian_is_four_times_p1_stiffness_per_face(bk, case):
    """The CR hat is phi_a = 1 - 2 hat_a, so per face L_c^(0) is 4 times the P1 stiffness of
    the opposite vertices: -2 cot(alpha_c) off the diagonal and 2 (cot alpha_b + cot alpha_c)
    (= |e_a|^2 / A) on it."""
    v, f = _mesh(case)
    fe, _ = ref.face_edge_table(f)
    alpha = ref.corner_angles(v, f)
    L = np.zeros((len(ref.edges(f)),) * 2)
    for t in range(len(f)):
        cot = 1 / np.tan(alpha[t])
        for a in range(3):
            for b in range(3):
                if a == b:
                    L[fe[t, a], fe[t, a]] += 2 * (cot[(a + 1) % 3] + cot[(a + 2) % 3])
                else:
                    L[fe[t, a], fe[t, b]] += -2 * cot[3 - a - b]
    close_id(bk.connection_laplacian(v, f, n=0), L)


@pytest.mark.parametrize("case", ALL, ids=str)
def test_gradient_tangential_part_and_curl_free(bk, case):
    v, f = _mesh(case)
    G, M, K = bk.gradient(v, f), bk.mass(v, f), bk.curl_div_K(v, f)
    func = np.random.default_rng(1).normal(size=v.shape[0])
    z = (G @ func) / np.diag(M)
    E = ref.edges(f)
    close_id(z.real, (func[E[:, 1]] - func[E[:, 0]]) / ref.edge_lengths(v, f), "Re z = (f_j - f_i)/|e|")
    close_id(K @ z.real, np.zeros(len(f)), "curl grad = 0")
    close_id(G @ np.ones(v.shape[0]), np.zeros(len(E)), "grad 1 = 0")


@pytest.mark.parametrize("case", ALL, ids=str)
def test_laplace_beltrami_symmetric_with_constant_kernel(bk, case):
    v, f = _mesh(case)
    L = bk.laplace_beltrami(v, f)
    assert not np.iscomplexobj(L)
    close_id(L, L.T)
    close_id(L @ np.ones(v.shape[0]), np.zeros(v.shape[0]))
    ev = np.linalg.eigvalsh(L)
    assert ev.min() > -1e-12 * ev.max()
    close_id(L, (ref.gradient(v, f).conj().T @ np.linalg.inv(ref.mass(v, f)) @ ref.gradient(v, f)).real)


@pytest.mark.parametrize("case", CLOSED, ids=str)
def test_laplace_beltrami_imaginary_part_vanishes_on_closed_meshes(case):
    # Im(G^H M_z^-1 G)[i, j] = sum_T A_T n_T . (grad phi_i x grad phi_j) = int dphi_i ^ dphi_j,
    # which is a boundary integral; it vanishes on closed meshes.
    v, f = _mesh(case)
    close_id(ref.laplace_beltrami_complex(v, f).imag, np.zeros((v.shape[0],) * 2))


@pytest.mark.parametrize("case", OPEN, ids=str)
def test_laplace_beltrami_imaginary_part_is_boundary_term(case):
    # ... and with a boundary it is oint_{boundary} phi_i dphi_j: for a boundary edge a -> b
    # (counter-clockwise), (delta_jb - delta_ja)(delta_ia + delta_ib)/2.
    v, f = _mesh(case)
    fe, _ = ref.face_edge_table(f)
    bnd = ref.boundary_edge_mask(f)
    Im = np.zeros((v.shape[0],) * 2)
    for t, face in enumerate(f):
        for k in range(3):
            if bnd[fe[t, k]]:
                a, b = face[(k + 1) % 3], face[(k + 2) % 3]
                Im[a, b] += 0.5
                Im[b, a] -= 0.5
    assert np.abs(Im).max() > 0
    close_id(ref.laplace_beltrami_complex(v, f).imag, Im)


@pytest.mark.parametrize("case", ALL, ids=str)
def test_covariant_derivative_diagonal(bk, case):
    v, f = _mesh(case)
    rng = np.random.default_rng(5)
    ne = len(ref.edges(f))
    w = rng.normal(size=ne) + 1j * rng.normal(size=ne)
    d = np.diag(bk.covariant_derivative(v, f, w))
    bnd = ref.boundary_edge_mask(f)
    close_id(d[~bnd], np.zeros((~bnd).sum()), "zero diagonal on interior edges")
    # boundary: one face, -delta |e| / 3 Im(w_e)
    fe, sg = ref.face_edge_table(f)
    lengths = ref.edge_lengths(v, f)
    expected = np.zeros(ne, complex)
    for t in range(len(f)):
        for k in range(3):
            if bnd[fe[t, k]]:
                expected[fe[t, k]] = -sg[t, k] * lengths[fe[t, k]] / 3 * w[fe[t, k]].imag
    close_id(d, expected)


@pytest.mark.parametrize("case", ALL, ids=str)
def test_covariant_derivative_is_real_linear_in_w(bk, case):
    v, f = _mesh(case)
    rng = np.random.default_rng(6)
    ne = len(ref.edges(f))
    w1, w2 = (rng.normal(size=ne) + 1j * rng.normal(size=ne) for _ in range(2))
    D = lambda w: bk.covariant_derivative(v, f, w)  # noqa: E731
    close_id(D(2.0 * w1 - 3.0 * w2), 2.0 * D(w1) - 3.0 * D(w2))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_linear_field_dirichlet_energy_is_exact(bk, seed):
    v, f = _flat_mesh(seed)
    rng = np.random.default_rng(100 + seed)
    B, c = rng.normal(size=(2, 2)), rng.normal(size=2)
    z = _linear_field(B, c, _midpoints(v, f)) / _complex_frames(v, f)
    area = ref.face_areas(v, f).sum()
    close_id(bk.mass(v, f).trace(), area)
    energy = np.vdot(z, bk.connection_laplacian(v, f, n=1) @ z)
    close_id(energy, area * np.sum(B**2), "z^H L_c z = area |B|_F^2")
    # curl and divergence energies of the real form, and the face-wise curl/div themselves
    x = np.concatenate([z.real, z.imag])
    close_id(x @ bk.curl_energy(v, f) @ x, area * (B[1, 0] - B[0, 1]) ** 2, "curl energy")
    close_id(x @ bk.div_energy(v, f) @ x, area * (B[0, 0] + B[1, 1]) ** 2, "div energy")
    K, A = bk.curl_div_K(v, f), ref.face_areas(v, f)
    close_id(K @ z.real / A, np.full(len(f), B[1, 0] - B[0, 1]), "curl_T")
    close_id(-K @ z.imag / A, np.full(len(f), B[0, 0] + B[1, 1]), "div_T")


@pytest.mark.parametrize("n", [1, 2, 3])
def test_constant_n_field_in_kernel_on_flat_mesh(bk, n):
    v, f = _flat_mesh(4)
    u = np.exp(0.7j)
    z = (u / _complex_frames(v, f)) ** n
    close_id(bk.connection_laplacian(v, f, n=n) @ z, np.zeros(len(z)))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_covariant_derivative_of_linear_fields_is_exact(bk, seed):
    # For linear omega and psi on a flat mesh, nabla_omega psi = B_psi omega(p) is linear, so
    # D_w z = M_z x with x its edge-midpoint samples, on every edge (boundary included).
    v, f = _flat_mesh(seed)
    rng = np.random.default_rng(200 + seed)
    Bw, cw, Bp, cp = rng.normal(size=(2, 2)), rng.normal(size=2), rng.normal(size=(2, 2)), rng.normal(size=2)
    q, X = _midpoints(v, f), _complex_frames(v, f)
    w = _linear_field(Bw, cw, q) / X
    z = _linear_field(Bp, cp, q) / X
    om = _linear_field(Bw, cw, q)
    x = _linear_field(Bp, np.zeros(2), om - 0j) / X  # B_psi applied to the vector omega(q)
    close_id(bk.covariant_derivative(v, f, w) @ z, np.diag(bk.mass(v, f)) * x)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_gradient_of_linear_function_is_exact(bk, seed):
    v, f = _flat_mesh(seed)
    g = np.random.default_rng(300 + seed).normal(size=2)
    func = v[:, 0] * g[0] + v[:, 1] * g[1] + 0.3
    z = (bk.gradient(v, f) @ func) / np.diag(bk.mass(v, f))
    close_id(z, (g[0] + 1j * g[1]) / _complex_frames(v, f))


@pytest.mark.parametrize("case", ALL, ids=str)
def test_real_form_acts_like_the_complex_matrix(bk, case):
    v, f = _mesh(case)
    L = ref.connection_laplacian(v, f, n=1)
    rng = np.random.default_rng(8)
    z = rng.normal(size=L.shape[0]) + 1j * rng.normal(size=L.shape[0])
    y = bk.real_form(L) @ np.concatenate([z.real, z.imag])
    close_id(y, np.concatenate([(L @ z).real, (L @ z).imag]))


@pytest.mark.parametrize("case", ALL, ids=str)
def test_vertex_div_curl_of_a_gradient(bk, case):
    # -G^H M_z^-1 G f = -L_complex f: div_v(grad f) = -M_v^-1 L f; curl_v(grad f) = 0 on closed
    # meshes (the imaginary part of G^H M_z^-1 G is a boundary term).
    v, f = _mesh(case)
    func = np.random.default_rng(9).normal(size=v.shape[0])
    z = (ref.gradient(v, f) @ func) / np.diag(ref.mass(v, f))
    Mv = ref.vertex_mass(v, f, lumped=True)
    div, curl = bk.vertex_div_curl(v, f, z, lumped=True)
    close_id(Mv @ div, -ref.laplace_beltrami(v, f) @ func)
    close_id(Mv @ curl, -ref.laplace_beltrami_complex(v, f).imag @ func)
    if case in CLOSED:
        close_id(curl, np.zeros(v.shape[0]))


@pytest.mark.parametrize("case", ALL, ids=str)
def test_masses_integrate_area(bk, case):
    v, f = _mesh(case)
    area = ref.face_areas(v, f).sum()
    close_id(np.trace(bk.mass(v, f)), area)
    close_id(bk.vertex_mass(v, f).sum(), area)
    close_id(bk.vertex_mass(v, f, lumped=True).sum(), area)


@pytest.mark.parametrize("case", ALL, ids=str)
def test_gauss_bonnet(bk, case):
    v, f = _mesh(case)
    chi = v.shape[0] - len(ref.edges(f)) + len(f)
    close_id(bk.angle_defects(v, f).sum(), 2 * PI * chi)


@pytest.mark.parametrize("subdiv", [0, 1])
def test_dihedral_positive_on_convex_mesh(bk, subdiv):
    v, f = ref.icosphere(subdiv)
    beta = bk.dihedral_angles(v, f)
    assert (beta > 0).all()
    # all edges of the icosahedron: pi - arccos(-sqrt5/3)
    if subdiv == 0:
        close_id(beta, np.full(30, PI - np.arccos(-np.sqrt(5) / 3)))


@pytest.mark.parametrize("case", ALL, ids=str)
@pytest.mark.parametrize("n", [0, 1, 2])
def test_renumbering_covariance(bk, case, n):
    """Renumbering the vertices permutes edges and may flip frames X_e -> -X_e, which maps
    z_e -> -z_e: operators must transform as S P L P^T S with S = diag(+-1)^n."""
    v, f = _mesh(case)
    rng = np.random.default_rng(12)
    perm = rng.permutation(v.shape[0])
    v2 = np.empty_like(v)
    v2[perm] = v
    f2 = perm[f]
    E, E2 = ref.edges(f), ref.edges(f2)
    index2 = {tuple(e): k for k, e in enumerate(E2)}
    emap = np.array([index2[tuple(sorted(perm[e]))] for e in E])
    flip = np.where(perm[E[:, 0]] < perm[E[:, 1]], 1.0, -1.0)
    s = flip**n
    L, L2 = bk.connection_laplacian(v, f, n=n), bk.connection_laplacian(v2, f2, n=n)
    close_id(L2[np.ix_(emap, emap)], s[:, None] * L * s[None, :])
    G, G2 = bk.gradient(v, f), bk.gradient(v2, f2)
    close_id(G2[np.ix_(emap, perm)], flip[:, None] * G)
    close_id(bk.dihedral_angles(v2, f2)[emap], bk.dihedral_angles(v, f))
    close_id(bk.laplace_beltrami(v2, f2)[np.ix_(perm, perm)], bk.laplace_beltrami(v, f))
