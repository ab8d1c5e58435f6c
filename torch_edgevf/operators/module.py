"""``EdgeOperators``: every operator of a mesh, held as buffers of an ``nn.Module``."""

from __future__ import annotations

import torch
from torch import nn

from .._device import move, parse_to
from .._validation import as_verts, check_n, check_vertex_count, single_mesh
from ..mesh.geometry import face_geometry
from ..mesh.topology import Topology
from . import functional as ops
from . import kernels
from .patterns import diagonal

__all__ = ["EdgeOperators"]


class EdgeOperators(nn.Module):
    """The edge-based operators of one mesh, as torch sparse COO buffers.

    The topology (and every sparsity pattern) is computed once; :meth:`update` re-assembles
    the operators for new vertex positions with a gather and a scatter. Built from a
    ``verts`` that requires grad, the buffers carry the autograd graph back to it: call
    :meth:`update` again in each optimisation step.

    Parameters
    ----------
    verts : (V, 3) float32 or float64 tensor, or a batch of one mesh
        (``pytorch3d.structures.Meshes`` or anything with ``verts_list()`` and
        ``faces_list()``; then ``faces`` is left out)
    faces : (F, 3) integer tensor, or a :class:`Topology`
    n : int
        Symmetry order of :attr:`connection_laplacian` (``n = 0``: scalar CR Laplacian).

    Attributes
    ----------
    edges : (E, 2) int64, ``i < j``, lexicographic
    faces : (F, 3) int64
    verts : (V, 3)
    mass : (E, E) real diagonal ``M_z``
    connection_laplacian : (E, E) ``L_c^(n)`` (complex for ``n >= 1``)
    gradient : (E, V) complex ``G``
    curl_div : (F, E) real ``K``
    laplace_beltrami : (V, V) real ``L = G^* M_z^{-1} G``
    vertex_mass : (V, V) real full FEM mass
    lumped_vertex_mass : (V, V) real diagonal
    face_area : (F,)
    edge_length : (E,)

    Notes
    -----
    ``.to(device)``, ``.to(dtype)``, ``.to(device, dtype)``, ``.float()``, ``.double()``,
    ``.cpu()`` and ``.cuda()`` move every buffer as ``nn.Module.to`` does (in place,
    returning the module), real buffers to the dtype and complex buffers to the matching
    complex dtype (``nn.Module.to(torch.float32)`` alone would drop their imaginary
    parts). :meth:`update` then assembles on that device; the :attr:`topology` stays on
    the host (its sparsity patterns copy their indices to each device once).
    """

    faces: torch.Tensor
    edges: torch.Tensor
    verts: torch.Tensor
    mass: torch.Tensor
    connection_laplacian: torch.Tensor
    gradient: torch.Tensor
    curl_div: torch.Tensor
    laplace_beltrami: torch.Tensor
    vertex_mass: torch.Tensor
    lumped_vertex_mass: torch.Tensor
    face_area: torch.Tensor
    edge_length: torch.Tensor

    def __init__(self, verts, faces=None, n: int = 1):
        super().__init__()
        verts, faces = single_mesh(verts, faces, "EdgeOperators")
        if faces is None:
            raise ValueError("EdgeOperators needs faces (or a batch of one mesh with faces_list())")
        verts = as_verts(verts)
        topo = faces if isinstance(faces, Topology) else Topology(faces, num_vertices=verts.shape[0])
        check_vertex_count(verts, topo.num_vertices)
        n = check_n(n, minimum=0)
        self.topology = topo
        self.n = n
        self.register_buffer("faces", topo.faces.to(verts.device))
        self.register_buffer("edges", topo.edges.to(verts.device))
        for name in (
            "verts",
            "mass",
            "connection_laplacian",
            "gradient",
            "curl_div",
            "laplace_beltrami",
            "vertex_mass",
            "lumped_vertex_mass",
            "face_area",
            "edge_length",
        ):
            self.register_buffer(name, None)
        self.update(verts)

    def _release(self, *names: str) -> None:
        """Drop buffers before their replacement is built (the old one is then freed)."""
        for name in names:
            self._buffers[name] = None

    def update(self, verts) -> EdgeOperators:
        """Re-assemble every operator for new positions of the same mesh (on the module's device)."""
        if isinstance(verts, torch.Tensor) and verts.device != self.faces.device:
            raise ValueError(
                f"verts is on {verts.device} but the operators are on {self.faces.device}: move one "
                f"of them (verts.to({str(self.faces.device)!r}) or operators.to({str(verts.device)!r}))"
            )
        verts = as_verts(verts)
        topo = self.topology
        check_vertex_count(verts, topo.num_vertices)
        geom = face_geometry(verts, topo)  # validates the positions before anything is replaced
        signs = topo.face_edge_signs.to(device=verts.device, dtype=verts.dtype)
        mass_values = kernels.mass_values(geom, topo)
        e = self.edges.to(verts.device)
        # Each operator replaces its predecessor as soon as it is built, so that the old and
        # the new set of operators are never held together (peak memory of large meshes).
        self.verts = verts
        self.mass = diagonal(mass_values)
        self._release("connection_laplacian")
        self.connection_laplacian = kernels.connection_laplacian_from(geom, signs, topo, self.n)
        self._release("gradient", "laplace_beltrami")
        self.gradient = kernels.cached_pattern(topo, "EV").assemble(kernels.gradient_values(geom, signs))
        self.laplace_beltrami = kernels.laplace_beltrami_from(self.gradient.values(), mass_values, topo)
        self.curl_div = kernels.cached_pattern(topo, "FE").assemble(kernels.curl_values(geom, signs))
        self._release("vertex_mass")
        self.vertex_mass = kernels.vertex_mass_from(geom, topo, lumped=False)
        self.lumped_vertex_mass = kernels.vertex_mass_from(geom, topo, lumped=True)
        self.face_area = geom.area
        self.edge_length = torch.linalg.vector_norm(verts[e[:, 1]] - verts[e[:, 0]], dim=-1)
        return self

    @property
    def num_edges(self) -> int:
        return self.topology.num_edges

    @property
    def num_vertices(self) -> int:
        return self.topology.num_vertices

    @property
    def num_faces(self) -> int:
        return self.topology.num_faces

    def connection_laplacian_n(self, n: int) -> torch.Tensor:
        """``L_c`` for another symmetry order ``n`` (the held one is :attr:`connection_laplacian`)."""
        return ops.connection_laplacian(self.verts, self.topology, n)

    def covariant_derivative(self, w) -> torch.Tensor:
        """``D_w``, ``(E, E)`` complex, for an edge field ``w`` ``(E,)`` (thesis 5.1)."""
        return ops.covariant_derivative(self.verts, self.topology, w)

    def curl_energy(self) -> torch.Tensor:
        """``(2E, 2E)`` ``L_curl`` (thesis 3.3)."""
        return ops.curl_energy(self.verts, self.topology)

    def div_energy(self) -> torch.Tensor:
        """``(2E, 2E)`` ``L_div`` (thesis 3.3)."""
        return ops.div_energy(self.verts, self.topology)

    def cotan_laplacian(self) -> torch.Tensor:
        """``(V, V)`` cotangent Laplacian (PSD stiffness), for comparison."""
        return ops.cotan_laplacian(self.verts, self.topology)

    def extra_repr(self) -> str:
        dtype = self.verts.dtype if self.verts is not None else None
        return (
            f"V={self.num_vertices}, E={self.num_edges}, F={self.num_faces}, n={self.n}, "
            f"dtype={dtype}, device={self.faces.device}"
        )

    # dtype conversions that keep complex buffers complex
    def to(self, *args, **kwargs):
        device, real, non_blocking = parse_to(*args, **kwargs)
        return self._apply(lambda t: move(t, device, real, non_blocking))

    def float(self):
        return self.to(torch.float32)

    def double(self):
        return self.to(torch.float64)
