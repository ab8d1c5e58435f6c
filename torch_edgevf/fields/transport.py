"""Transport of edge-based vector and n-direction fields along a vector field (thesis 5.1).

With the covariant derivative ``M_z x = D_w z`` (``x`` the edge values of
``nabla_w psi``, :func:`torch_edgevf.covariant_derivative`; for the representation vectors
of ``n``-direction fields the operator built on the frames ``u^n``, i.e. with ``r^n``), the
thesis transports a field with

.. math::  z(t) = \\exp\\left(t\\, M_z^{-1} D_w\\right) z_0,

computed here as ``expm_multiply(-D_w, M_z, z0, t)`` (:func:`torch_edgevf.linalg.
expm_multiply` computes ``exp(-t M^{-1} A) z0``). This solves
``M_z dz/dt = D_w z``, i.e. ``d psi/dt = nabla_w psi``.

Direction
---------
``direction="backward"`` (the default, the thesis' and [AOCBC15]'s): the value at ``p``
at time ``t`` is the value of ``psi_0`` at ``Phi_t(p)`` (the point reached by following
``w`` for time ``t``), parallel transported back to ``p`` along the integral curve, so
the pattern of the field moves *against* ``w``: a field concentrated at ``q`` ends up
concentrated at ``Phi_{-t}(q)``.  ``direction="forward"`` carries the field *along*
``w`` (``z(t)(Phi_t(p))`` is ``psi_0(p)`` transported to ``Phi_t(p)``); it is the backward
transport for ``-t``.

For a rotation (Killing) field of the sphere ``w = e_z x p`` the flow is the rotation
``Phi_t`` by angle ``t``; transport preserves the pointwise norm, and relative to the
rotated field ``dPhi psi_0`` the transported vector at colatitude ``theta`` is turned by
``t cos(theta)`` about the outward normal (the geodesic curvature ``cot theta`` of the
latitude integrated over its arc length ``t sin theta``), an ``n``-direction field's
representation vector by ``n t cos(theta)``; see ``tests/test_transport.py`` and
``examples/transport_sphere.py`` (thesis figure 5.1).

Stability
---------
The semi-discrete operator ``M_z^{-1} D_w`` is not normal and has a few growing modes:
without regularization, transport along the sphere's rotation field is accurate for
``t ~ 1`` (relative errors ~2% at icosphere level 3, halving per level) but blows up
within one full turn.  As in the thesis ("the solution quickly diverges"), an optional
implicit heat step with the connection Laplacian ``L_c^(n)``,
``z <- (M_z + s L_c)^{-1} M_z z``, regularizes between transport steps, at the price of
damping the norm.  Every call measures the ``M_z``-norm after each step and warns
(:class:`TransportGrowthWarning`) when it grew by more than ``growth_tol`` (5%), with a
suggested smoothing; see :data:`SUGGESTED_SMOOTHING`.  (Along a field with divergence
the norm changes legitimately: raise ``growth_tol`` or pass ``None``.)

The suggestion is sized for vector fields (``n = 1``).  For ``n``-direction fields the
exact solution along the rotation field, ``z(t) = e^{i n t cos(theta)} dPhi (w^n)``, winds
``n`` times faster, so its Rayleigh quotient ``z^H L_c^(n) z / z^H M_z z`` grows like
``(n t)^2``: ``K`` heat steps of size ``s`` take about ``s sum_k (n t_k)^2`` of its norm,
``n^2`` times the vector-field loss, while the growing modes of ``M_z^{-1} D_w^(n)`` grow
faster with ``n`` as well (the phase errors of the discrete transport scale like
``n h``).  The heat step therefore cannot both control the growth and keep the norm of
an ``n >= 2`` field over a full turn on a given mesh as it does for ``n = 1``: the
suggested smoothing damps such a field visibly; use finer meshes or shorter times.
"""

from __future__ import annotations

import math
import warnings

import torch

from .._validation import as_edge_field, check_n
from ..linalg import SparseSolver, expm_multiply, solve
from ..mesh.geometry import topology_and_verts
from ..operators.functional import connection_laplacian, covariant_derivative, mass_matrix

__all__ = ["Transporter", "TransportGrowthWarning", "transport", "SUGGESTED_SMOOTHING"]

DIRECTIONS = ("backward", "forward")

#: The smoothing suggested when the norm grows, ``(c, k)``: ``smoothing = c A`` (``A`` the
#: area of the mesh, so that the suggestion follows its scale) with at least ``k |t|``
#: steps.  Along the unit sphere's rotation field, one full turn (``t = 2 pi``) of a vector
#: field with ``smoothing = 2.3e-4`` and 8 steps: relative L2 error 0.20 / 0.075 / 0.045
#: at icosphere levels 3 / 4 / 5 (0.45 / 0.92 / 51 without smoothing), ``M_z``-norm 0.88 /
#: 0.94 / 0.97 of the initial one (1.02 / 1.33 / 51 without).  A smoothing proportional to
#: the squared edge length is too weak on fine meshes (level 5 with ``5.7e-5``: error 2.6):
#: the growth rates of the unstable modes increase with the resolution.  The heat step
#: damps n-direction fields (``n >= 2``) more; see ``tests/test_transport_n.py``.
SUGGESTED_SMOOTHING = (2e-5, 1.3)


class TransportGrowthWarning(RuntimeWarning):
    """The ``M_z``-norm of a transported field grew beyond ``growth_tol`` (unstable transport)."""


def _sparse_add(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    return (a + b).coalesce()


class Transporter:
    """Repeated transport along one field on one mesh (operators assembled once).

    Parameters
    ----------
    verts : (V, 3) tensor
    faces : (F, 3) int tensor or :class:`Topology`
    w : (E,) complex tensor, edge values of the transporting vector field
    smoothing : float, ``s >= 0``: implicit heat step ``(M_z + s L_c^(n))^{-1} M_z`` applied
        after every transport step (0 disables it); its factorization is done once.
    n : int >= 1, keyword-only
        The symmetry of the transported fields: 1 for vector fields, ``n`` for the
        representation vectors of ``n``-direction fields (the covariant derivative and the
        smoothing then use ``r^n``).  Anything else raises ``ValueError``: the transported
        representation must match the field it represents.
    direction : {"backward", "forward"}, keyword-only
        ``"backward"`` (the thesis'): the field moves against ``w``; ``"forward"``: along
        ``w`` (see the module documentation).
    growth_tol : float or None, keyword-only
        Warn (:class:`TransportGrowthWarning`) when the ``M_z``-norm of a transported field
        exceeds ``1 + growth_tol`` times its initial norm after any step; ``None`` disables
        the check.

    Examples
    --------
    >>> tr = Transporter(verts, faces, w, smoothing=1e-3)
    >>> z1 = tr(z0, t=0.5, steps=2)
    """

    def __init__(
        self,
        verts,
        faces,
        w,
        smoothing: float = 0.0,
        *,
        n: int = 1,
        direction: str = "backward",
        growth_tol: float | None = 0.05,
    ):
        verts, topo = topology_and_verts(verts, faces)
        if not isinstance(smoothing, (int, float)) or smoothing < 0:
            raise ValueError(f"smoothing must be a float >= 0, got {smoothing!r}")
        try:
            self.n = check_n(n)
        except ValueError:
            raise ValueError(
                f"n must be an integer >= 1 (1 for a vector field, n for the representation vector "
                f"of an n-direction field), got {n!r}"
            ) from None
        if direction not in DIRECTIONS:
            raise ValueError(f"direction must be one of {DIRECTIONS}, got {direction!r}")
        if growth_tol is not None and not (isinstance(growth_tol, (int, float)) and growth_tol >= 0):
            raise ValueError(f"growth_tol must be a float >= 0 or None, got {growth_tol!r}")
        self.direction, self.growth_tol = direction, growth_tol
        self.verts, self.topo = verts, topo
        self.w = as_edge_field(w, topo, verts, name="w")
        if self.w.dim() != 1:
            raise ValueError(f"w must have shape (E,), got {tuple(self.w.shape)}")
        self.D = covariant_derivative(verts, topo, self.w, self.n)
        # expm_multiply(A, M, z, t) = exp(-t M^{-1} A) z: backward is A = -D_w, forward A = D_w
        self._generator = (-self.D).coalesce() if direction == "backward" else self.D.coalesce()
        self.minus_D = (-self.D).coalesce()
        self.M = mass_matrix(verts, topo)
        self.mass = self.M.values()
        self.smoothing = float(smoothing)
        self._smoother = None
        if self.smoothing > 0:
            L = connection_laplacian(verts, topo, self.n)
            A = _sparse_add(self.M.to(self.D.dtype), self.smoothing * L)
            self._smoother = SparseSolver(A, hermitian=True)

    def smooth(self, z: torch.Tensor) -> torch.Tensor:
        """One implicit heat step ``(M_z + s L_c)^{-1} M_z z`` (identity if ``s = 0``)."""
        if self._smoother is None:
            return z
        m = self.mass if z.dim() == 1 else self.mass[:, None]
        return solve(self._smoother, m.to(z.dtype) * z)

    def norm(self, z: torch.Tensor) -> torch.Tensor:
        """The ``M_z``-norm ``sqrt(z^H M_z z)`` (per column for ``(E, C)``)."""
        m = self.mass if z.dim() == 1 else self.mass[:, None]
        return torch.sqrt((m.to(z.real.dtype) * (z.real**2 + z.imag**2)).sum(0))

    def __call__(self, z0, t, steps: int = 1) -> torch.Tensor:
        """Transport ``z0`` for time ``t`` in ``steps`` equal steps (smoothing after each).

        Without smoothing the result does not depend on ``steps``. Differentiable with
        respect to ``z0``, ``t`` (a tensor) and, through the operators, ``verts`` and ``w``.
        Warns (:class:`TransportGrowthWarning`) when the ``M_z``-norm grows beyond
        ``growth_tol``.
        """
        if not isinstance(steps, int) or steps < 1:
            raise ValueError(f"steps must be an integer >= 1, got {steps!r}")
        z = as_edge_field(z0, self.topo, self.verts, name="z0")
        if not torch.is_tensor(t):
            t = torch.tensor(float(t), dtype=self.verts.dtype, device=self.verts.device)
        dt = t / steps
        check = self.growth_tol is not None
        if check:
            with torch.no_grad():
                norm0 = self.norm(z.detach())
            growth = torch.zeros_like(norm0)
        for _ in range(steps):
            z = expm_multiply(self._generator, self.M, z, dt)
            z = self.smooth(z)
            if check:
                with torch.no_grad():
                    ratio = self.norm(z.detach()) / torch.where(norm0 > 0, norm0, 1)
                    growth = torch.maximum(growth, ratio - 1)
        if check and self.growth_tol is not None and float(growth.max()) > self.growth_tol:
            self._warn_growth(float(growth.max()), float(t), steps)
        return z

    transport = __call__

    def _warn_growth(self, growth: float, t: float, steps: int) -> None:
        c, per_unit = SUGGESTED_SMOOTHING
        s = c * float(self.mass.detach().sum())  # the area of the mesh
        suggested_steps = max(steps, math.ceil(per_unit * abs(t)))
        advice = (
            f"pass smoothing={s:.2g} with steps={suggested_steps} (an implicit heat step after each)"
            if self.smoothing < s
            else f"use more steps (steps={2 * steps}) or a shorter time"
        )
        warnings.warn(
            f"transport: the M_z-norm of the field grew by {growth:.1%} over t={t:g} in {steps} "
            f"step(s) (smoothing={self.smoothing:g}): the semi-discrete transport has growing "
            f"modes; {advice}, or set growth_tol=None if the field w has divergence",
            TransportGrowthWarning,
            stacklevel=3,
        )

    def trajectory(self, z0, t, steps: int) -> list[torch.Tensor]:
        """``[z(0), z(t/steps), ..., z(t)]`` (with smoothing after each step)."""
        z = as_edge_field(z0, self.topo, self.verts, name="z0")
        out = [z]
        for _ in range(steps):
            z = self(z, t / steps, 1)
            out.append(z)
        return out


def transport(
    verts,
    faces,
    z0,
    w,
    t,
    steps: int = 1,
    smoothing: float = 0.0,
    *,
    n: int = 1,
    direction: str = "backward",
    growth_tol: float | None = 0.05,
) -> torch.Tensor:
    """Transport the field ``z0`` along ``w`` for time ``t`` (thesis 5.1).

    .. math::  z(t) = \\exp\\left(t M_z^{-1} D_w^{(n)}\\right) z_0

    (``direction="backward"``, the default: the field moves against ``w``; ``"forward"``
    uses ``-t``: it moves along ``w``), with ``smoothing > 0`` an implicit heat step after
    each of the ``steps`` steps.  Warns (:class:`TransportGrowthWarning`) when the
    ``M_z``-norm grows by more than ``growth_tol``.  Differentiable with respect to ``z0``
    and ``t``.

    Parameters
    ----------
    verts : (V, 3) tensor
    faces : (F, 3) int tensor or :class:`Topology`
    z0 : (E,) or (E, C) complex tensor, a vector field (``n = 1``) or the representation
        vector of an ``n``-direction field
    w : (E,) complex tensor, a vector field
    t : float or 0-d tensor
    n, direction, growth_tol : see :class:`Transporter`

    Returns
    -------
    (E,) or (E, C) complex tensor.
    """
    tr = Transporter(verts, faces, w, smoothing, n=n, direction=direction, growth_tol=growth_tol)
    return tr(z0, t, steps)
