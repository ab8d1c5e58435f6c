"""Vector and n-direction field design (thesis chapter 3).

Every design is a quadratic problem on the edge values ``z`` (complex ``(E,)``, the
representation vectors of an ``n``-direction field, thesis 2.2) with the connection
Laplacian ``L_c^(n)`` and the edge mass matrix ``M_z`` of :mod:`torch_edgevf.operators`:

==============================  ============================================================
design                          problem
==============================  ============================================================
smoothest (3.1)                 ``L_c z = lambda M_z z``, smallest ``lambda``, ``||z||_M = 1``
curl-/div-free smoothest (3.3)  the same on ``(Re z, Im z)`` with ``Re(L_c) + mu L_curl``
                                (resp. ``L_div``) and the real form of ``M_z``
hard constraints (3.4)          values fixed at some edges, directions at others (see below)
soft alignment (3.4)            ``(L_c - lambda_t M_z) z = M_z w``
heat diffusion (3.2)            ``z(t) = exp(-t M_z^{-1} L_c) z0`` or implicit Euler
curvature (3.4)                 a line field across edges from dihedral angles, diffused
==============================  ============================================================

:class:`FieldDesigner` assembles the operators of one mesh once and keeps the
factorizations it makes (of ``L_c - lambda_t M_z`` per ``lambda_t``, and of the implicit
heat step per time step) for repeated designs; each one-off function builds a designer
and calls the method of the same meaning.

Conventions
-----------
* Constraint values, directions and guides are *representation vectors* in the edge
  frames (the angle-based ``n``-th power of a direction: :func:`~torch_edgevf.fields.nth_power`).
* Eigenvector gauge: an eigenvector is defined up to a unit factor (a global rotation of
  the field) or a sign (real 2E form). :func:`torch_edgevf.linalg.eigsh` scales it so
  that its entry of largest modulus is real and positive; the field is then a
  differentiable function of ``verts`` wherever that entry is unique and the eigenvalue
  simple. Losses invariant to the gauge (``|z|^2``, ``z z^H``) are recommended. Under
  direction constraints the sign is instead fixed so that the field points along the
  given directions on average.
* Heat diffusion times ``t`` are given in units of ``h^2``, ``h`` the mean edge length,
  so that a time means the same smoothing (over about ``sqrt(t)`` edge rings) at any
  mesh scale and resolution.
* Differentiable with respect to ``verts`` (and constraint values and guides) through
  :mod:`torch_edgevf.linalg`. With ``verts.requires_grad``, build a new designer per
  optimisation step: its operators carry the autograd graph of the ``verts`` it was built
  from.

Hard constraints (3.4)
----------------------
A value constraint fixes ``z_e``; a direction constraint ``Re(z_e) Im(w_e) - Im(z_e)
Re(w_e) = 0`` leaves one real unknown ``t_e`` with ``z_e = t_e w_e / |w_e|``. Both are
eliminated (no Lagrange multipliers): with ``P`` the ``(2E, m)`` real map from the ``m``
remaining unknowns ``y`` to ``(Re z, Im z)`` (one nonzero per row) and ``x_C`` the fixed
values, the energy ``x^T A x`` over ``x = x_C + P y`` gives

* with at least one value constraint or a guide: the solve
  ``(P^T A P) y = P^T (M w - A x_C)`` (``A`` positive definite on the free unknowns);
* with direction constraints only: the eigenproblem ``(P^T A P) y = lambda (P^T M P) y``
  (``P^T M P`` stays diagonal) -- the smoothest unit-norm field along the directions.
"""

from __future__ import annotations

import logging
import math

import numpy as np
import torch

from .._dtypes import complex_dtype
from .._validation import as_edge_field, check_n, single_mesh
from ..linalg import SparseSolver, eigsh, expm_multiply, solve
from ..mesh.geometry import (
    FaceGeometry,
    dihedral_angles,
    edge_lengths,
    edge_lengths_of,
    face_geometry_of,
    topology_and_verts,
)
from ..operators import functional as ops
from ..operators import kernels
from ..operators.patterns import Pattern, diagonal, sparse_coo
from .constraints import constraint_plan
from .powers import nth_power

__all__ = [
    "FieldDesigner",
    "smoothest_field",
    "curl_free_field",
    "div_free_field",
    "constrained_field",
    "aligned_field",
    "heat_diffuse",
    "curvature_field",
    "curvature_aligned_field",
]

log = logging.getLogger(__name__)

_METHODS = ("exponential", "implicit")


def _check_real(x, name: str, minimum: float | None = None) -> float:
    if isinstance(x, torch.Tensor):
        if x.numel() != 1:
            raise ValueError(f"{name} must be a real number, got a tensor of shape {tuple(x.shape)}")
        x = x.item()
    if (
        isinstance(x, bool)
        or not isinstance(x, (int, float, np.integer, np.floating))
        or not math.isfinite(x)
    ):
        raise ValueError(f"{name} must be a finite real number, got {x!r}")
    if minimum is not None and x < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {x!r}")
    return float(x)


class FieldDesigner:
    """Field design on one mesh: operators assembled once, factorizations reused.

    Parameters
    ----------
    verts : (V, 3) float tensor, or a :class:`~torch_edgevf.mesh.geometry.FaceGeometry`
        (intrinsic: from edge lengths, e.g. of a repaired mesh; the curvature methods then
        need positions and are not available)
    faces : (F, 3) integer tensor, or a :class:`~torch_edgevf.mesh.topology.Topology`
    n : int >= 1
        Symmetry order: the designed ``z`` are representation vectors of ``n``-direction
        fields (``n = 1`` vector fields, ``2`` line fields, ``4`` cross fields).

    Attributes
    ----------
    topology : Topology
    verts : (V, 3) tensor
    n : int
    mass : (E,) tensor, the diagonal of ``M_z``
    laplacian : (E, E) complex sparse tensor ``L_c^(n)``
    mean_edge_length : scalar tensor ``h`` (the unit of diffusion times is ``h^2``)

    Examples
    --------
    >>> designer = FieldDesigner(verts, faces, n=4)     # doctest: +SKIP
    >>> z = designer.smoothest()                         # doctest: +SKIP
    >>> z_cross = designer.curvature_aligned()           # doctest: +SKIP
    """

    def __init__(self, verts, faces=None, n: int = 1):
        verts, faces = single_mesh(verts, faces, "FieldDesigner")
        self.n = check_n(n)
        if isinstance(verts, FaceGeometry):  # intrinsic: lengths only (no curvature alignment)
            topo = kernels.intrinsic_topology(verts, faces)
            geom = verts
            per_edge = geom.lengths.new_zeros(topo.num_edges).index_put(
                (topo.face_edges.to(geom.device).flatten(),), geom.lengths.flatten()
            )
            self.mean_edge_length = per_edge.mean()
        else:
            verts, topo = topology_and_verts(verts, faces, "FieldDesigner")
            geom = face_geometry_of(verts, topo)
            self.mean_edge_length = edge_lengths_of(verts, topo).mean()
        self.topology = topo
        self.verts = verts
        signs = topo.face_edge_signs.to(device=verts.device, dtype=verts.dtype)
        self._geom, self._signs = geom, signs
        self.mass = kernels.mass_values(geom, topo)
        self.laplacian = self._laplacian(self.n)
        self._solvers: dict = {}
        self._real_laplacian = None

    # ------------------------------------------------------------------ basics

    @property
    def num_edges(self) -> int:
        return self.topology.num_edges

    @property
    def complex_dtype(self) -> torch.dtype:
        return complex_dtype(self.verts.dtype)

    def _laplacian(self, n: int) -> torch.Tensor:
        return kernels.connection_laplacian_from(self._geom, self._signs, self.topology, n)

    def _mass_matrix(self) -> torch.Tensor:
        return diagonal(self.mass.to(self.complex_dtype))

    def _solver(self, key, build) -> SparseSolver:
        if key not in self._solvers:
            self._solvers[key] = SparseSolver(build(), hermitian=True)
            log.debug("factored %s (%s)", key, self._solvers[key].backend)
        return self._solvers[key]

    def _field(self, z, name: str) -> torch.Tensor:
        return as_edge_field(z, self.topology, self.verts, name)

    def norm(self, z) -> torch.Tensor:
        """The ``M_z`` norm ``sqrt(z^H M_z z)`` of an edge field (the field's L2 norm)."""
        z = self._field(z, "z")
        return torch.sqrt((self.mass * z.abs() ** 2).sum())

    def energy(self, z) -> torch.Tensor:
        """The Dirichlet energy ``z^H L_c z`` (real) of a representation vector field."""
        z = self._field(z, "z")
        return (z.conj() * (self.laplacian @ z[:, None])[:, 0]).sum().real

    def rayleigh_quotient(self, z) -> torch.Tensor:
        """``z^H L_c z / z^H M_z z``."""
        return self.energy(z) / self.norm(z) ** 2

    # ------------------------------------------------------------------ smoothest (3.1, 3.3)

    def smoothest(self, return_eigenvalue: bool = False, *, tol: float | None = None, maxiter: int = 1000):
        """The smoothest ``n``-field: the first eigenvector of ``L_c z = lambda M_z z`` (3.1).

        .. math::  z = \\arg\\min_{z^H M_z z = 1} z^H L_c^{(n)} z

        ``tol`` and ``maxiter`` go to :func:`~torch_edgevf.linalg.eigsh`.

        Returns
        -------
        z : (E,) complex tensor, ``z^H M_z z = 1``, gauge as in the module docstring
        lambda : scalar tensor, only if ``return_eigenvalue``
        """
        values, vectors = eigsh(self.laplacian, self.mass, k=1, tol=tol, maxiter=maxiter)
        z = vectors[:, 0]
        return (z, values[0]) if return_eigenvalue else z

    def _real_system(self, mu_curl: float = 0.0, mu_div: float = 0.0) -> torch.Tensor:
        """``real_form(L_c) + mu_curl L_curl + mu_div L_div`` (2E, 2E), thesis 3.3."""
        a = ops.real_form(self.laplacian)
        if mu_curl or mu_div:
            block, ne = kernels.curl_energy_block(self.verts, self.topology)
            parts = [a]
            if mu_curl:
                parts.append(mu_curl * kernels.embed_block(block, 0, 2 * ne))
            if mu_div:
                parts.append(mu_div * kernels.embed_block(block, ne, 2 * ne))
            a = _sum_sparse(parts)
        return a

    def _smoothest_real(self, mu_curl: float, mu_div: float, return_eigenvalue: bool, **eigsh_options):
        a = self._real_system(mu_curl, mu_div)
        m2 = torch.cat([self.mass, self.mass])
        values, vectors = eigsh(a, m2, k=1, **eigsh_options)
        x = vectors[:, 0]
        ne = self.num_edges
        z = torch.complex(x[:ne], x[ne:])
        return (z, values[0]) if return_eigenvalue else z

    def curl_free(
        self,
        mu: float = 1.0,
        return_eigenvalue: bool = False,
        *,
        tol: float | None = None,
        maxiter: int = 1000,
    ):
        """The smoothest field penalising curl (thesis 3.3).

        Smallest eigenvector of

        .. math::  (\\operatorname{Re}(L_c) + \\mu L_{curl})\\, x = \\lambda\\, M\\, x,
                   \\qquad x = (\\operatorname{Re} z, \\operatorname{Im} z),

        i.e. the minimiser of ``E_D + mu int curl(psi)^2`` over unit-norm fields. ``mu``
        balances smoothness and curl and is in units of the Dirichlet energy (scale-free);
        a small ``mu`` only lifts the global-rotation freedom, a large one drives the curl
        to zero. The sign gauge makes the largest entry of ``x`` positive.

        ``tol`` and ``maxiter`` go to :func:`~torch_edgevf.linalg.eigsh`.

        Returns
        -------
        z : (E,) complex tensor, unit ``M_z`` norm (and the eigenvalue if asked)
        """
        mu = _check_real(mu, "mu", 0.0)
        return self._smoothest_real(mu, 0.0, return_eigenvalue, tol=tol, maxiter=maxiter)

    def div_free(
        self,
        mu: float = 1.0,
        return_eigenvalue: bool = False,
        *,
        tol: float | None = None,
        maxiter: int = 1000,
    ):
        """The smoothest field penalising divergence: :meth:`curl_free` with ``L_div`` (3.3)."""
        mu = _check_real(mu, "mu", 0.0)
        return self._smoothest_real(0.0, mu, return_eigenvalue, tol=tol, maxiter=maxiter)

    # ------------------------------------------------------------------ constraints (3.4)

    def constrained(
        self,
        edges=None,
        values=None,
        direction_edges=None,
        directions=None,
        guide=None,
        lam: float = 0.0,
        mu_curl: float = 0.0,
        mu_div: float = 0.0,
    ):
        """The smoothest field under hard constraints, optionally with a soft guide (3.4).

        Minimises ``x^T (A - lam M) x - 2 x^T M w`` (``A = real_form(L_c) + mu_curl L_curl +
        mu_div L_div``, ``x = (Re z, Im z)``, ``w`` the guide, zero if not given) subject to

        * ``z[edges] = values`` (value constraints), and
        * ``Re(z_e) Im(w_e) - Im(z_e) Re(w_e) = 0`` for ``e`` in ``direction_edges`` with
          ``w_e = directions`` (direction constraints: ``z_e`` parallel or antiparallel to
          ``w_e``, any norm),

        by elimination (module docstring). With direction constraints only and no guide,
        the problem is homogeneous and the result is the unit-norm smoothest field along
        the directions (a constrained eigenproblem), signed to point along them on average.

        Parameters
        ----------
        edges : (K,) int tensor, optional
        values : (K,) complex tensor, optional (representation vectors)
        direction_edges : (D,) int tensor, optional
        directions : (D,) complex tensor, optional, nonzero (representation vectors)
        guide : (E,) complex tensor, optional
        lam : float, ``lambda_t`` of the soft alignment, below the first eigenvalue
        mu_curl, mu_div : float >= 0

        Returns
        -------
        (E,) complex tensor; ``z[edges] == values`` exactly and the direction constraints
        hold to rounding.

        Raises
        ------
        ValueError
            Out-of-range or non-integer edges, mismatched lengths, a zero direction,
            contradictory constraints (an edge given two different values, or both a value
            and a direction), or constraints leaving no free unknown.
        """
        lam = _check_real(lam, "lam")
        mu_curl = _check_real(mu_curl, "mu_curl", 0.0)
        mu_div = _check_real(mu_div, "mu_div", 0.0)
        plan = constraint_plan(
            edges, values, direction_edges, directions, self.num_edges, self.verts, self.complex_dtype
        )
        ne = self.num_edges
        a = self._real_system(mu_curl, mu_div)
        m2 = torch.cat([self.mass, self.mass])
        if lam:
            a = _sum_sparse([a, diagonal(-lam * m2)])
        dtype = self.verts.dtype
        p_row, p_col, p_val, x_fixed, m = plan["rows"], plan["cols"], plan["coef"], plan["x_fixed"], plan["m"]
        a = a.coalesce()
        idx, val = a.indices(), a.values()
        col_of = torch.full((2 * ne,), -1, dtype=torch.int64, device=idx.device)
        col_of[p_row] = p_col
        coef = torch.zeros(2 * ne, dtype=dtype, device=idx.device)
        coef[p_row] = p_val
        r, c = idx[0], idx[1]
        keep = (col_of[r] >= 0) & (col_of[c] >= 0)
        red_vals = val[keep] * coef[r[keep]] * coef[c[keep]]
        red_rows, red_cols = col_of[r[keep]], col_of[c[keep]]
        pattern = Pattern(red_rows.cpu().numpy(), red_cols.cpu().numpy(), (m, m))
        a_red = pattern.assemble(red_vals)
        m_red = torch.zeros(m, dtype=dtype, device=idx.device).index_add(0, p_col, m2[p_row] * p_val**2)

        homogeneous = guide is None and not plan["has_values"]
        if homogeneous:
            if m < 2:
                raise ValueError("the constraints leave fewer than 2 free real unknowns: nothing to design")
            _, vectors = eigsh(a_red, m_red, k=1)
            y = vectors[:, 0]
        else:
            rhs = torch.zeros(m, dtype=dtype, device=idx.device)
            if guide is not None:
                w = self._field(guide, "guide")
                mw = torch.cat([self.mass * w.real, self.mass * w.imag])
                rhs = rhs.index_add(0, p_col, p_val * mw[p_row])
            if plan["has_values"]:
                fixed_c = ~keep & (col_of[r] >= 0) & (col_of[c] < 0)
                rr, cc = r[fixed_c], c[fixed_c]
                rhs = rhs.index_add(0, col_of[rr], -coef[rr] * val[fixed_c] * x_fixed[cc])
            y = solve(a_red, rhs, hermitian=True)
        x = x_fixed.index_add(0, p_row, p_val * y[p_col])
        z = torch.complex(x[:ne], x[ne:])
        if homogeneous:
            d_idx, d_unit = plan["direction_edges"], plan["direction_units"]
            align = (d_unit.conj() * z[d_idx]).real.sum()
            z = torch.where(align.detach() < 0, -z, z)
        return z

    # ------------------------------------------------------------------ soft alignment (3.4)

    def aligned(self, guide, lam: float = 0.0) -> torch.Tensor:
        """Soft alignment to a guide field ``w`` (thesis 3.4): ``(L_c - lambda_t M_z) z = M_z w``.

        The minimiser of ``z^H (L_c - lambda_t M_z) z - 2 Re <w, z>_M``. ``lambda_t``
        trades smoothness for alignment: the normalised alignment
        ``Re <w, z>_M / (||w||_M ||z||_M)`` decreases monotonically as ``lambda_t`` grows
        from ``-inf`` (``z -> w / |lambda_t|``, pure alignment) towards the first eigenvalue
        ``lambda_1`` (``z`` tends to the projection of ``w`` on the smoothest fields), and
        ``lambda_t = 0`` is the thesis's default trade-off. Needs ``lambda_t < lambda_1``
        (the system is then positive definite; otherwise a warning is logged and the
        stationary point of the indefinite energy is returned). The factorization of ``L_c - lambda_t M_z``
        is kept for the next call with the same ``lambda_t``.

        Parameters
        ----------
        guide : (E,) complex tensor, a representation vector field
        lam : float

        Returns
        -------
        (E,) complex tensor.
        """
        lam = _check_real(lam, "lam")
        w = self._field(guide, "guide")
        if not bool((w.detach() != 0).any()):
            raise ValueError("guide is zero everywhere: there is nothing to align to")
        solver = self._solver(("aligned", lam), lambda: self._shifted(-lam))
        if solver.backend == "superlu":  # the Cholesky path failed: not positive definite
            log.warning(
                "lam = %g is not below the first eigenvalue: L_c - lam M_z is indefinite and the "
                "result is a stationary point of the energy, not its minimiser",
                lam,
            )
        return solver.solve(self.mass * w)

    def _shifted(self, shift: float) -> torch.Tensor:
        """``L_c + shift M_z`` on the pattern of ``L_c``."""
        if shift == 0:
            return self.laplacian
        return _sum_sparse([self.laplacian, diagonal((shift * self.mass).to(self.complex_dtype))])

    # ------------------------------------------------------------------ heat diffusion (3.2)

    def diffuse(self, z0, t: float, method: str = "exponential", steps: int = 1) -> torch.Tensor:
        """Heat-diffuse a field (thesis 3.2): ``dz/dt = -M_z^{-1} L_c z``.

        .. math::  z(t) = \\exp(-t\\, h^2 M_z^{-1} L_c)\\, z_0  \\quad \\text{(exponential)}

        or ``steps`` implicit Euler steps ``(M_z + dt L_c) z_{k+1} = M_z z_k``,
        ``dt = t h^2 / steps`` (unconditionally stable, first order, over-smooths less for
        more steps). ``t`` is in units of ``h^2`` (``h`` the mean edge length); the thesis's
        ``t = h / 10`` for curvature equals ``t = 1`` here on a mesh with ``h = 0.1``. Both
        are contractive in the ``M_z`` norm.

        Parameters
        ----------
        z0 : (E,) or (E, C) complex tensor
        t : float >= 0
        method : {"exponential", "implicit"}
        steps : int >= 1 (implicit only)

        Returns
        -------
        tensor like ``z0``.
        """
        t = _check_real(t, "t", 0.0)
        if method not in _METHODS:
            raise ValueError(f"method must be one of {_METHODS}, got {method!r}")
        steps = check_n(steps)
        z = self._field(z0, "z0")
        if t == 0:
            return z
        return self._diffuse(z, t * self.mean_edge_length**2, method, steps)

    def _diffuse(self, z: torch.Tensor, t_phys: torch.Tensor, method: str, steps: int) -> torch.Tensor:
        """Diffusion for the physical time ``t_phys`` (a tensor: differentiable in ``verts``)."""
        if method == "exponential":
            return expm_multiply(self.laplacian, self.mass, z, t_phys)
        dt = t_phys / steps
        solver = self._solver(("implicit", float(dt.detach())), lambda: self._heat_matrix(dt))
        m = self.mass if z.dim() == 1 else self.mass[:, None]
        for _ in range(steps):
            z = solver.solve(m * z)
        return z

    def _heat_matrix(self, dt: torch.Tensor) -> torch.Tensor:
        lap = self.laplacian
        scaled = sparse_coo(lap.indices(), dt * lap.values(), lap.shape)
        return _sum_sparse([scaled, diagonal(self.mass.to(self.complex_dtype))])

    # ------------------------------------------------------------------ curvature (3.4)

    def curvature(self, diffusion_time: float | None = None, weighting: str = "integrated") -> torch.Tensor:
        """The curvature-direction field as an ``n``-representation vector (thesis 3.4).

        A line field (``n = 2``) with one term per edge, across the edge (``beta_e`` is the
        signed dihedral angle, ``|e|`` the length, ``3 M_e`` the area of the adjacent faces):

        ``weighting="integrated"`` (default)
            ``z2_e = -beta_e |e| / (3 M_e)``: the traceless part of the edge-based shape
            operator ``sum_e beta_e |e| e_perp e_perp^T / area`` of Cohen-Steiner and Morvan
            (2003), whose integral over a region converges to that of the smooth shape
            operator; it points along the direction of largest signed curvature.
        ``weighting="thesis"``
            the angle-based square of ``w_e = i beta_e / |e|``, i.e.
            ``z2_e = -|beta_e| / |e|`` (largest absolute curvature). Exact on regular
            meshes (a cylinder), but the ``1 / |e|`` weight favours short edges, which on
            stretched meshes leaves a bias that does not fall under refinement (on an
            ellipsoid, the mean angle error stays constant as the mesh is refined).

        The line field is then heat-diffused with ``L_c^(2)`` (:meth:`diffuse`, implicit
        Euler in 4 steps) and, for ``n = 2 m``, raised to ``z_n = |z2| e^{i m arg z2}``
        (e.g. the cross field ``n = 4`` of the line field's direction and its
        perpendicular).

        Parameters
        ----------
        diffusion_time : float >= 0, optional
            In units of ``h^2`` (0: no diffusion). Default: the thesis's ``t = h / 10``
            made scale-invariant by measuring lengths in units of ``R = sqrt(area / 4 pi)``,
            i.e. ``t = R / (10 h)`` here. Because it is physically ``h R / 10``, the
            smoothing radius shrinks like ``sqrt(h)`` -- more slowly than the mesh -- so the
            smoothed directions converge under refinement.
        weighting : {"integrated", "thesis"}

        Returns
        -------
        (E,) complex tensor (the ``n``-representation vector; boundary edges start at 0).

        Raises
        ------
        ValueError
            For odd ``n`` (curvature directions are line fields) or an unknown weighting.
        """
        if self.n % 2:
            raise ValueError(f"curvature directions form a line field: n must be even, got n = {self.n}")
        if weighting not in ("integrated", "thesis"):
            raise ValueError(f"weighting must be 'integrated' or 'thesis', got {weighting!r}")
        if diffusion_time is None:  # t = h R / 10 physically, R = sqrt(area / 4 pi)
            radius = torch.sqrt(self._geom.area.sum() / (4 * math.pi))
            t_phys = self.mean_edge_length * radius / 10
        else:
            t_phys = _check_real(diffusion_time, "diffusion_time", 0.0) * self.mean_edge_length**2
        beta = dihedral_angles(self.verts, self.topology)
        length = edge_lengths(self.verts, self.topology)
        if weighting == "integrated":
            z2 = torch.complex(-beta * length / (3 * self.mass), torch.zeros_like(beta))
        else:
            z2 = nth_power(torch.complex(torch.zeros_like(beta), beta / length), 2)
        if diffusion_time is None or diffusion_time > 0:
            designer2 = self if self.n == 2 else self._companion(2)
            z2 = designer2._diffuse(z2, t_phys, "implicit", 4)
        return z2 if self.n == 2 else nth_power(z2, self.n // 2)

    def _companion(self, n: int) -> FieldDesigner:
        key = ("companion", n)
        if key not in self._solvers:
            self._solvers[key] = FieldDesigner(self.verts, self.topology, n)
        return self._solvers[key]

    def curvature_aligned(
        self, lam: float = 0.0, diffusion_time: float | None = None, weighting: str = "integrated"
    ) -> torch.Tensor:
        """The field softly aligned (:meth:`aligned`) to :meth:`curvature` (thesis 3.4).

        Returns
        -------
        (E,) complex tensor, unit ``M_z`` norm (the scale of the soft-alignment solution is
        arbitrary: it is proportional to the curvature).
        """
        z = self.aligned(self.curvature(diffusion_time, weighting), lam)
        return z / self.norm(z)


# ---------------------------------------------------------------------- helpers


def _sum_sparse(parts) -> torch.Tensor:
    """Sum of sparse COO tensors of one shape, coalesced (differentiable in the values)."""
    parts = [p.coalesce() for p in parts]
    idx = torch.cat([p.indices() for p in parts], dim=1)
    dtype = parts[0].values().dtype
    for p in parts[1:]:
        dtype = torch.promote_types(dtype, p.values().dtype)
    vals = torch.cat([p.values().to(dtype) for p in parts])
    shape = parts[0].shape
    key = idx[0] * shape[1] + idx[1]
    uniq, inverse = torch.unique(key, return_inverse=True)
    out = vals.new_zeros(uniq.numel()).index_add(0, inverse, vals)
    return sparse_coo(torch.stack([uniq // shape[1], uniq % shape[1]]), out, shape)


# ---------------------------------------------------------------------- one-off functions


def smoothest_field(
    verts, faces=None, n: int = 1, *, tol: float | None = None, maxiter: int = 1000
) -> torch.Tensor:
    """The smoothest ``n``-direction field of a mesh (thesis 3.1).

    The eigenvector of the smallest eigenvalue of ``L_c^(n) z = lambda M_z z``, with
    ``z^H M_z z = 1`` and the gauge of :func:`torch_edgevf.linalg.eigsh` (entry of largest
    modulus real positive). Differentiable with respect to ``verts``.

    Parameters
    ----------
    verts : (V, 3) float tensor, or a :class:`~torch_edgevf.mesh.geometry.FaceGeometry`
    faces : (F, 3) integer tensor or Topology
    n : int >= 1
    tol, maxiter : see :func:`torch_edgevf.linalg.eigsh`

    Returns
    -------
    (E,) complex tensor: the representation vector (take
    :func:`~torch_edgevf.fields.nth_root` for one of the ``n`` directions).
    """
    return FieldDesigner(verts, faces, n).smoothest(tol=tol, maxiter=maxiter)


def curl_free_field(verts, faces=None, mu: float = 1.0, n: int = 1) -> torch.Tensor:
    """The smoothest field penalising curl with weight ``mu`` (thesis 3.3); see
    :meth:`FieldDesigner.curl_free`."""
    return FieldDesigner(verts, faces, n).curl_free(mu)


def div_free_field(verts, faces=None, mu: float = 1.0, n: int = 1) -> torch.Tensor:
    """The smoothest field penalising divergence (thesis 3.3); see
    :meth:`FieldDesigner.div_free`."""
    return FieldDesigner(verts, faces, n).div_free(mu)


def constrained_field(
    verts, faces=None, edges=None, values=None, direction_edges=None, directions=None, n: int = 1, **kwargs
) -> torch.Tensor:
    """The smoothest field under hard value and direction constraints (thesis 3.4); see
    :meth:`FieldDesigner.constrained`."""
    return FieldDesigner(verts, faces, n).constrained(edges, values, direction_edges, directions, **kwargs)


def aligned_field(verts, faces, guide, lam: float = 0.0, n: int = 1) -> torch.Tensor:
    """Soft alignment ``(L_c - lambda_t M_z) z = M_z w`` (thesis 3.4); see
    :meth:`FieldDesigner.aligned`."""
    return FieldDesigner(verts, faces, n).aligned(guide, lam)


def heat_diffuse(
    verts, faces, z0, t: float, n: int = 1, method: str = "exponential", steps: int = 1
) -> torch.Tensor:
    """Heat diffusion of an ``n``-field for time ``t h^2`` (thesis 3.2); see
    :meth:`FieldDesigner.diffuse`."""
    return FieldDesigner(verts, faces, n).diffuse(z0, t, method, steps)


def curvature_field(
    verts, faces=None, n: int = 2, diffusion_time: float | None = None, weighting: str = "integrated"
) -> torch.Tensor:
    """The curvature line field (``n = 2``) or cross field (``n = 4``) representation
    vector (thesis 3.4); see :meth:`FieldDesigner.curvature`."""
    return FieldDesigner(verts, faces, n).curvature(diffusion_time, weighting)


def curvature_aligned_field(
    verts,
    faces=None,
    n: int = 4,
    lam: float = 0.0,
    diffusion_time: float | None = None,
    weighting: str = "integrated",
) -> torch.Tensor:
    """The smooth ``n``-field softly aligned to the curvature directions (thesis 3.4); see
    :meth:`FieldDesigner.curvature_aligned`."""
    return FieldDesigner(verts, faces, n).curvature_aligned(lam, diffusion_time, weighting)
