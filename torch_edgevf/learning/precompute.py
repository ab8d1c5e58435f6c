"""The per-mesh operators that the learning layers take, computed once per mesh.

:class:`MeshOperators` holds what the networks of :mod:`torch_edgevf.learning.models`
need for one mesh (``M_z``, ``G``, ``L_c``, eigenpairs, ...); :func:`compute_operators`
computes them in float64, the eigenpairs with :func:`torch_edgevf.linalg.eigsh`.
:class:`MeshFields` declares the per-mesh tensors once, for :class:`MeshOperators` and for
the batches of :mod:`torch_edgevf.learning.batching`.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, fields
from typing import Any, Protocol, overload

import numpy as np
import scipy.sparse as sp
import torch

from .._device import check_devices, move, parse_to
from .._dtypes import complex_dtype
from .._validation import as_verts, is_mesh_batch, mesh_list, single_mesh
from ..linalg import eigsh
from ..mesh.geometry import FaceGeometry, edge_lengths, face_areas, vertex_normals
from ..mesh.repair import find_degenerate_faces, mollify_lengths
from ..mesh.topology import Topology
from ..operators import functional as ops
from .layers import spectral_diffusion

__all__ = [
    "MeshFields",
    "MeshOperators",
    "compute_operators",
    "robust_vertex_laplacian",
    "heat_kernel_signature",
    "mean_curvature_signature",
    "vertex_gradient_operator",
]


_SPARSE = "sparse_coo"


@dataclass
class MeshFields:
    """The tensors of one mesh, or of a batch of meshes as one disconnected mesh.

    Attributes
    ----------
    verts : (V, 3) float tensor
    faces : (F, 3) int64 tensor
    edges : (E, 2) int64 tensor, ``i < j``
    face_edges : (F, 3) int64 tensor, the edge opposite each corner
    edge_mass : (E,) real, the diagonal of ``M_z``
    vertex_mass : (V,) real, lumped vertex masses
    face_area : (F,) real
    gradient : (E, V) complex sparse ``G``
    connection_laplacian : (E, E) sparse ``L_c^(n)``
    edge_evals, edge_evecs : (k_e,), (E, k_e)
        Smallest eigenpairs of ``(L_c^(n), M_z)``, ``Phi^H M_z Phi = I``.
    vertex_evals, vertex_evecs : (k_v,), (V, k_v)
        Smallest eigenpairs of a vertex Laplacian with the lumped mass (see
        :func:`compute_operators`), ``Phi^T M_v Phi = I``.
    vertex_gradient : (V, V) complex sparse or None
        Least-squares tangent-plane vertex gradient (the DiffusionNet-style baseline).
    """

    verts: torch.Tensor
    faces: torch.Tensor
    edges: torch.Tensor
    face_edges: torch.Tensor
    edge_mass: torch.Tensor
    vertex_mass: torch.Tensor
    face_area: torch.Tensor
    gradient: torch.Tensor
    connection_laplacian: torch.Tensor
    edge_evals: torch.Tensor
    edge_evecs: torch.Tensor
    vertex_evals: torch.Tensor
    vertex_evecs: torch.Tensor
    vertex_gradient: torch.Tensor | None = None

    @property
    def num_vertices(self) -> int:
        return int(self.verts.shape[0])

    @property
    def device(self) -> torch.device:
        """The device of the tensors (that of ``verts``)."""
        return self.verts.device

    @property
    def dtype(self) -> torch.dtype:
        """The real dtype of the tensors (that of ``verts``); complex ones are its complex dtype."""
        return self.verts.dtype

    def to(self, *args, **kwargs):
        """A copy on another device and/or in another precision, as ``Tensor.to``.

        ``to(device)``, ``to(dtype)``, ``to(device, dtype)``, ``to(other_tensor)`` and the
        keywords ``device=``, ``dtype=``, ``non_blocking=``. Every tensor moves, the sparse
        ones included; real tensors take ``dtype`` (float32 or float64), complex ones the
        complex dtype of the same precision, integer ones keep theirs. The object itself
        is not changed.
        """
        device, dtype, non_blocking = parse_to(*args, **kwargs)
        new = copy.copy(self)
        for f in fields(self):
            setattr(new, f.name, move(getattr(self, f.name), device, dtype, non_blocking))
        new._moved_from(self)
        return new

    def _moved_from(self, source) -> None:
        """Called on the result of :meth:`to` (a shallow copy of ``source``)."""

    def float(self):
        """:meth:`to` ``torch.float32`` (complex tensors: ``complex64``)."""
        return self.to(torch.float32)

    def double(self):
        """:meth:`to` ``torch.float64`` (complex tensors: ``complex128``)."""
        return self.to(torch.float64)

    def cpu(self):
        """:meth:`to` the CPU."""
        return self.to("cpu")

    def tensors(self) -> dict[str, torch.Tensor]:
        """The tensors of the object by field name (the sparse ones included; None left out)."""
        return {f.name: x for f in fields(self) if isinstance(x := getattr(self, f.name), torch.Tensor)}

    @property
    def num_edges(self) -> int:
        return int(self.edges.shape[0])

    @property
    def num_faces(self) -> int:
        return int(self.faces.shape[0])

    def __getstate__(self) -> dict:
        # Sparse tensors travel as (indices, values, shape) and are rebuilt without the
        # invariant checks (they were checked when built): torch's own reduction of a
        # sparse tensor, used between DataLoader workers and the main process, rebuilds
        # it with the checks implicitly off and warns about it.
        state = dict(self.__dict__)
        for name, value in state.items():
            if isinstance(value, torch.Tensor) and value.layout == torch.sparse_coo:
                value = value.coalesce()
                state[name] = (_SPARSE, value.indices(), value.values(), tuple(value.shape))
        return state

    def __setstate__(self, state: dict) -> None:
        for name, value in state.items():
            if isinstance(value, tuple) and len(value) == 4 and value[0] == _SPARSE:
                _, indices, values, shape = value
                state[name] = torch.sparse_coo_tensor(
                    indices, values, shape, is_coalesced=True, check_invariants=False
                )
        self.__dict__.update(state)


@dataclass
class MeshOperators(MeshFields):
    """The operators of one mesh used by the learning layers.

    The tensors of :class:`MeshFields` and ``n : int``, the symmetry order of ``L_c``.
    """

    n: int = 1

    def check(self) -> None:
        """Raise ``ValueError`` if the shapes are inconsistent."""
        V, E, F = self.num_vertices, self.num_edges, self.num_faces
        expect = {
            "verts": (V, 3),
            "faces": (F, 3),
            "edges": (E, 2),
            "face_edges": (F, 3),
            "edge_mass": (E,),
            "vertex_mass": (V,),
            "face_area": (F,),
            "gradient": (E, V),
            "connection_laplacian": (E, E),
            "edge_evals": (self.edge_evals.shape[0],),
            "edge_evecs": (E, self.edge_evals.shape[0]),
            "vertex_evals": (self.vertex_evals.shape[0],),
            "vertex_evecs": (V, self.vertex_evals.shape[0]),
        }
        if self.vertex_gradient is not None:
            expect["vertex_gradient"] = (V, V)
        for name, shape in expect.items():
            got = tuple(getattr(self, name).shape)
            if got != shape:
                raise ValueError(f"MeshOperators.{name} has shape {got}, expected {shape}")
        if int(self.faces.max()) >= V or int(self.edges.max()) >= V or int(self.face_edges.max()) >= E:
            raise ValueError("MeshOperators has out-of-range indices")


def vertex_gradient_operator(verts, faces=None) -> torch.Tensor:
    r"""Least-squares tangent-plane gradient at vertices, complex (the DiffusionNet scheme).

    Each vertex gets a tangent frame ``(x_i, y_i)`` (``x_i`` the projection of its first
    neighbouring edge on the plane normal to the area-weighted vertex normal); the
    gradient :math:`g_i = g_x + \imath g_y` minimises
    :math:`\sum_{j \sim i} (g \cdot a_{ij} - (f_j - f_i))^2` over the neighbours, with
    :math:`a_{ij}` the tangent coordinates of :math:`v_j - v_i`. The frame is arbitrary per
    vertex, so only gauge-invariant features (``|g|``, ``Re(g conj(A g))``) are meaningful.

    Returns
    -------
    (V, V) complex sparse tensor ``D`` with ``g = D f``.
    """
    verts, faces = single_mesh(verts, faces, "vertex_gradient_operator")
    verts = as_verts(verts).detach()
    topo = faces if isinstance(faces, Topology) else Topology(faces, num_vertices=verts.shape[0])
    v = verts.to(torch.float64).cpu().numpy()
    f = topo.faces.numpy()
    e = topo.edges.numpy()
    # area-weighted face normals (twice the area; zero for a collapsed face)
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    normal = np.zeros_like(v)
    np.add.at(normal, f.ravel(), np.repeat(fn, 3, axis=0))
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    src = np.concatenate([e[:, 0], e[:, 1]])
    dst = np.concatenate([e[:, 1], e[:, 0]])
    order = np.lexsort((dst, src))
    src, dst = src[order], dst[order]
    d = v[dst] - v[src]
    first = np.zeros(v.shape[0], dtype=np.int64)
    first[src[::-1]] = np.arange(src.shape[0])[::-1]  # first outgoing edge of each vertex
    x = d[first] - (d[first] * normal).sum(1, keepdims=True) * normal
    x /= np.maximum(np.linalg.norm(x, axis=1, keepdims=True), 1e-300)
    y = np.cross(normal, x)
    a = np.stack([(d * x[src]).sum(1), (d * y[src]).sum(1)], axis=1)  # (2E, 2)
    N = np.zeros((v.shape[0], 2, 2))
    np.add.at(N, src, a[:, :, None] * a[:, None, :])
    # regularised relative to each vertex's own scale, floored for a vertex whose
    # neighbours all coincide with it (a decimator can leave such vertices)
    floor = 1e-12 * float(np.mean((d * d).sum(1)))
    scale = np.maximum(np.trace(N, axis1=1, axis2=2), floor)[:, None, None]
    N += 1e-8 * scale * np.eye(2)
    c = np.einsum("eij,ej->ei", np.linalg.inv(N)[src], a)
    cz = c[:, 0] + 1j * c[:, 1]
    rows = np.concatenate([src, src])
    cols = np.concatenate([dst, src])
    vals = np.concatenate([cz, -cz])
    D = sp.coo_matrix((vals, (rows, cols)), shape=(v.shape[0],) * 2).tocsr().tocoo()
    cdtype = complex_dtype(verts.dtype)
    idx = torch.from_numpy(np.stack([D.row, D.col]).astype(np.int64))
    return (
        torch.sparse_coo_tensor(idx, torch.from_numpy(D.data).to(cdtype), D.shape, check_invariants=False)
        .coalesce()
        .to(verts.device)
    )


def robust_vertex_laplacian(verts, topo: Topology, mollify_factor: float = 1e-5):
    """The intrinsic Delaunay Laplacian and lumped mass of ``robust_laplacian`` (float64).

    Returns ``(L, mass)``: ``L`` a ``(V, V)`` sparse COO tensor (positive semidefinite),
    ``mass`` ``(V,)``. Raises ``ValueError`` naming the package when it is not installed.
    """
    try:
        import robust_laplacian
    except ImportError as e:
        raise ValueError(
            "vertex_laplacian='robust' needs the robust_laplacian package: pip install robust_laplacian"
        ) from e
    v = np.ascontiguousarray(verts.detach().cpu().numpy(), dtype=np.float64)
    f = np.ascontiguousarray(topo.faces.cpu().numpy(), dtype=np.int64)
    L, M = robust_laplacian.mesh_laplacian(v, f, mollify_factor=mollify_factor)
    L = sp.coo_matrix(L)
    idx = torch.as_tensor(np.vstack([L.row, L.col]).astype(np.int64))
    vals = torch.as_tensor(L.data, dtype=torch.float64)
    Lt = torch.sparse_coo_tensor(idx, vals, L.shape, check_invariants=False).coalesce()
    return Lt, torch.as_tensor(np.asarray(M.diagonal(), dtype=np.float64))


class MeshesLike(Protocol):
    """A batch of meshes as ``pytorch3d.structures.Meshes`` holds one (or anything alike)."""

    def verts_list(self) -> list: ...

    def faces_list(self) -> list: ...


@overload
def compute_operators(
    verts: MeshesLike, faces: None = None, *args: Any, **kwargs: Any
) -> list[MeshOperators]: ...


@overload
def compute_operators(verts: Any, faces: Any, *args: Any, **kwargs: Any) -> MeshOperators: ...


def compute_operators(
    verts,
    faces=None,
    n: int = 1,
    k_edge: int = 32,
    k_vertex: int = 32,
    vertex_laplacian: str = "cotan",
    vertex_gradient: bool = False,
    tol: float | None = None,
    dtype: torch.dtype = torch.float64,
    device=None,
):
    """Compute the :class:`MeshOperators` of a mesh (in float64, then returned in ``dtype``).

    The computation runs on the CPU (SciPy and torch); the result is returned on
    ``device``, by default the device of ``verts`` (the CPU for arrays).

    Parameters
    ----------
    verts : (V, 3) float tensor or array, or a batch of meshes
        A batch with ``verts_list()`` and ``faces_list()`` (a
        ``pytorch3d.structures.Meshes``; then ``faces`` is left out) gives a list of
        :class:`MeshOperators`, one per mesh, each on the device of its vertices.
    faces : (F, 3) int tensor or array, or a Topology
    n : int >= 1, symmetry order of ``L_c``
    k_edge, k_vertex : int, numbers of eigenpairs of ``(L_c, M_z)`` and of the vertex
        Laplacian (with the lumped vertex mass); ``k_edge=0`` computes none of ``L_c``
        (``edge_evals`` and ``edge_evecs`` empty: for networks that do not use them, such as
        ``EdgeFieldNet(fields="local")``)
    vertex_laplacian : {"cotan", "edge", "robust"}
        ``"cotan"``: cotangent Laplacian with the lumped vertex mass;
        ``"edge"``: ``L = G^* M_z^{-1} G`` of thesis 4.2 with the lumped vertex mass;
        ``"robust"``: the intrinsic Delaunay Laplacian and its lumped mass of Sharp and
        Crane 2020, from the ``robust_laplacian`` package (``pip install robust_laplacian``;
        mollification ``1e-5``), as DiffusionNet computes its operators. With
        ``"robust"`` the ``vertex_mass`` returned is that mass (the one the vertex
        eigenvectors are orthonormal in).
    vertex_gradient : bool
        Also compute :func:`vertex_gradient_operator` (for the baseline).
    tol : float, optional
        Tolerance of the eigenpairs, ``tol`` of :func:`torch_edgevf.linalg.eigsh`
        (default: its default, ``1e-13`` in float64).
    dtype : torch.float64 or torch.float32
        Dtype of the real tensors returned (complex ones in the matching complex dtype);
        everything is computed in float64 first. Use ``torch.float32`` for networks in
        single precision (the models check that batch and parameters agree).
    device : torch.device or str, optional
        Where the result is returned (default: the device of ``verts``).
    """
    options = dict(
        n=n,
        k_edge=k_edge,
        k_vertex=k_vertex,
        vertex_laplacian=vertex_laplacian,
        vertex_gradient=vertex_gradient,
        tol=tol,
        dtype=dtype,
        device=device,
    )
    if is_mesh_batch(verts):
        return [compute_operators(v, f, **options) for v, f in mesh_list(verts, faces)]
    if faces is None:
        raise ValueError("compute_operators needs faces (or a batch of meshes with faces_list())")
    return _compute_operators(verts, faces, **options)


def _compute_operators(
    verts, faces, n, k_edge, k_vertex, vertex_laplacian, vertex_gradient, tol, dtype, device
) -> MeshOperators:
    """:func:`compute_operators` of one mesh."""
    if dtype not in (torch.float32, torch.float64):
        raise ValueError(f"dtype must be torch.float32 or torch.float64, got {dtype!r}")
    if vertex_laplacian not in ("cotan", "edge", "robust"):
        raise ValueError(f"vertex_laplacian must be 'cotan', 'edge' or 'robust', got {vertex_laplacian!r}")
    if not isinstance(n, int) or isinstance(n, bool) or n < 1:
        raise ValueError(f"n must be an integer >= 1, got {n!r}")
    verts = as_verts(verts).detach()
    device = verts.device if device is None else torch.device(device)
    verts = verts.to(device="cpu", dtype=torch.float64)
    topo = faces if isinstance(faces, Topology) else Topology(faces, num_vertices=verts.shape[0])
    ne, nv = topo.num_edges, topo.num_vertices
    for name, k, size, least in (("k_edge", k_edge, ne, 0), ("k_vertex", k_vertex, nv, 1)):
        if not isinstance(k, int) or isinstance(k, bool) or not least <= k < size:
            raise ValueError(f"{name} must be an integer in [{least}, {size - 1}], got {k!r}")
    geometry = _intrinsic_geometry(verts, topo)
    edge_mass = ops.mass_matrix(geometry, topo).values()
    Lc = ops.connection_laplacian(geometry, topo, n)
    if vertex_laplacian == "robust":
        Lv, vmass = robust_vertex_laplacian(verts, topo)
    else:
        vmass = ops.vertex_mass(geometry, topo, lumped=True).values()
        Lv = (
            ops.cotan_laplacian(geometry, topo)
            if vertex_laplacian == "cotan"
            else ops.laplace_beltrami(geometry, topo)
        )
    with torch.no_grad():
        vertex = eigsh(Lv, vmass, k_vertex, tol=tol)
        if k_edge:
            edge = eigsh(Lc, edge_mass, k_edge, tol=tol)
            ew, ev = edge.values.clamp_min(0.0), edge.vectors
        else:  # none asked: empty, so that batches and caches keep one layout
            ew = edge_mass.new_zeros(0)
            ev = torch.zeros(ne, 0, dtype=Lc.dtype)
    # eigsh makes the largest-modulus entry of every eigenvector real positive: a
    # deterministic sign (the models only use sign-invariant quantities)
    vw, vv = vertex.values.clamp_min(0.0), vertex.vectors
    out = MeshOperators(
        verts=verts,
        faces=topo.faces.clone(),
        edges=topo.edges.clone(),
        face_edges=topo.face_edges.clone(),
        edge_mass=edge_mass,
        vertex_mass=vmass,
        face_area=geometry.area if isinstance(geometry, FaceGeometry) else face_areas(verts, topo),
        gradient=ops.gradient(geometry, topo).coalesce(),
        connection_laplacian=Lc.coalesce(),
        edge_evals=ew,
        edge_evecs=ev.contiguous(),
        vertex_evals=vw,
        vertex_evecs=vv.contiguous(),
        vertex_gradient=vertex_gradient_operator(verts, topo) if vertex_gradient else None,
        n=n,
    )
    return out.to(device, dtype)


def _intrinsic_geometry(verts: torch.Tensor, topo: Topology):
    """The positions, or where some face has zero area, the intrinsic geometry of the
    mollified edge lengths (:func:`~torch_edgevf.mesh.repair.mollify_lengths`, as the
    robust Laplacian of Sharp and Crane 2020 does): the operators of a real mesh with
    collapsed faces (a decimator leaves them) are then finite, and those of every other
    mesh unchanged."""
    if len(find_degenerate_faces(verts.numpy(), topo.faces.numpy())) == 0:
        return verts
    lengths, _, _ = mollify_lengths(edge_lengths(verts, topo), topo.face_edges)
    return FaceGeometry.from_lengths(lengths[topo.face_edges])


def _signature_times(times, count: int, dtype: torch.dtype, device) -> torch.Tensor:
    """The diffusion times of the signatures: ``times``, or ``count`` log-spaced in ``[1e-2, 1]``."""
    if times is None:
        return torch.logspace(-2, 0, count, dtype=dtype, device=device)
    return torch.as_tensor(times, dtype=dtype, device=device)


def heat_kernel_signature(
    evals, evecs, times=None, count: int = 16, area=None, log: bool = False
) -> torch.Tensor:
    r"""Heat kernel signature per vertex, scale normalised (intrinsic input features).

    .. math::  h(x, t) = A \sum_i e^{-\lambda_i A t} \phi_i(x)^2

    with ``A`` the total area (so the features of a mesh and of a scaled copy agree),
    :math:`\phi_i` ``M_v``-orthonormal. Invariant to rigid motions, to the numbering
    and to the sign of each eigenvector.

    Parameters
    ----------
    evals : (k,) real tensor
    evecs : (V, k) real tensor
    times : (T,) tensor, default ``logspace(-2, 0, count)``
    area : float or tensor, total surface area (default 1)
    log : bool
        Return ``log h``: the signatures span orders of magnitude over their times and
        between the tips and the bodies of shapes, and the logarithm makes those ratios
        differences a linear layer can use. The input of the recommended
        :class:`~torch_edgevf.learning.models.EdgeFieldNet`.

    Returns
    -------
    (V, T) tensor.

    Raises
    ------
    ValueError
        ``log=True`` and a signature is not positive (the constant mode's term alone is
        positive: the eigenpairs are then wrong).
    """
    if evecs.dim() != 2 or evals.shape != (evecs.shape[1],):
        raise ValueError(
            f"evals (k,) and evecs (V, k) do not match: {tuple(evals.shape)}, {tuple(evecs.shape)}"
        )
    check_devices(evals=evals, evecs=evecs)
    times = _signature_times(times, count, evals.dtype, evals.device)
    area = torch.as_tensor(1.0 if area is None else area, dtype=evals.dtype, device=evals.device)
    weights = torch.exp(-evals[None, :] * area * times[:, None])  # (T, k)
    h = area * (evecs**2) @ weights.transpose(0, 1)
    if not log:
        return h
    bad = ~(h.detach() > 0)
    if bool(bad.any()):
        v, c = (int(i) for i in bad.nonzero()[0])
        raise ValueError(
            f"log=True needs positive heat kernel signatures, got {float(h[v, c])} at vertex {v}, "
            f"time {c} (check the eigenpairs: the constant mode alone gives a positive value)"
        )
    return torch.log(h)


def mean_curvature_signature(
    verts, faces, evals, evecs, mass, times=None, count: int = 8, compress: bool = True
) -> torch.Tensor:
    r"""Signed mean curvature per vertex and its heat diffusion (extrinsic input features).

    .. math::  H_i = \frac{\langle (C x)_i, n_i \rangle}{2 m_i} \sqrt{A / 4\pi}, \qquad
               H(t) = \Phi\, e^{-\Lambda A t}\, \Phi^\top M H

    with ``C`` the cotangent Laplacian, ``n_i`` the angle-weighted vertex normal, ``m_i``
    the vertex mass and ``A`` the total area: the mean curvature is scale normalised (1 on
    a round sphere of any radius) and diffused at the times of
    :func:`heat_kernel_signature`. On a closed mesh the sign is that of the outward
    normal (positive where the surface is convex), whatever the orientation of the faces;
    on a mesh with boundary it follows the orientation of the faces. Invariant to rigid
    motions, to scaling, to the numbering and to the sign of each eigenvector, and
    differentiable in every input (computed in float64). The heat kernel signature is
    intrinsic (the same on every isometric bending of a surface); these features are
    not: they tell a crease from a flat patch.

    Parameters
    ----------
    verts : (V, 3) float tensor
    faces : (F, 3) int tensor, or a Topology
    evals, evecs : (k,), (V, k) eigenpairs of a vertex Laplacian, ``M``-orthonormal
        (``vertex_evals`` and ``vertex_evecs`` of :func:`compute_operators`)
    mass : (V,) lumped vertex mass ``M`` (``vertex_mass``)
    times : (T,) tensor, default ``logspace(-2, 0, count)``
    compress : bool
        Return ``sign(h) log(1 + |h|)`` of each value (default): the curvature of a
        sharp crease is orders of magnitude above that of a smooth part.

    Returns
    -------
    (V, 1 + T) tensor in the dtype of ``evecs``: ``H`` itself, then ``H(t)`` per time.
    """
    verts = as_verts(verts)
    topo = faces if isinstance(faces, Topology) else Topology(faces, num_vertices=verts.shape[0])
    if evecs.dim() != 2 or evals.shape != (evecs.shape[1],) or evecs.shape[0] != verts.shape[0]:
        raise ValueError(
            f"evals (k,) and evecs (V, k) must match the {verts.shape[0]} vertices: "
            f"{tuple(evals.shape)}, {tuple(evecs.shape)}"
        )
    if mass.shape != (verts.shape[0],) or not bool((mass > 0).all()):
        raise ValueError(f"mass must be ({verts.shape[0]},) and positive, got shape {tuple(mass.shape)}")
    if not isinstance(count, int) or isinstance(count, bool) or count < 1:
        raise ValueError(f"count must be a positive integer, got {count!r}")
    check_devices(verts=verts, evals=evals, evecs=evecs, mass=mass)
    dtype = evecs.dtype
    x, m = verts.to(torch.float64), mass.to(torch.float64)
    normal_curvature = (ops.cotan_laplacian(x, topo) @ x) / (2 * m[:, None])
    h = (normal_curvature * vertex_normals(x, topo)).sum(1)
    if topo.is_closed and torch.linalg.det(x[topo.faces.to(x.device)]).sum() < 0:
        h = -h  # a closed mesh with inward-facing faces: the outward normal is the other one
    area = face_areas(x, topo).sum()
    h = h * torch.sqrt(area / (4 * torch.pi))
    times = _signature_times(times, count, torch.float64, x.device)
    lam, phi = evals.to(torch.float64), evecs.to(torch.float64)
    diffused = spectral_diffusion(h[:, None].expand(-1, times.shape[0]), lam, phi, m, area * times)
    out = torch.cat([h[:, None], diffused], dim=1)
    if compress:
        out = torch.sign(out) * torch.log1p(out.abs())
    return out.to(dtype)
