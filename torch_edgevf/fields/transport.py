"""Transport of edge-based vector and n-direction fields along a vector field (thesis 5.1).

``transport(verts, faces, z0, w, t)`` solves ``d psi/dt = nabla_w psi`` (``direction=
"backward"``, the thesis' and [AOCBC15]'s): the value at ``p`` at time ``t`` is the value
of ``psi_0`` at ``Phi_t(p)`` (the point reached by following ``w`` for time ``t``),
parallel transported back to ``p`` along the integral curve, so the pattern of the field
moves *against* ``w``: a field concentrated at ``q`` ends up concentrated at
``Phi_{-t}(q)``.  ``direction="forward"`` carries the field *along* ``w``; it is the
backward transport along ``-w``.  A negative ``t`` transports along ``-w`` for ``|t|``.
For the representation vectors of ``n``-direction fields (``n > 1``) the operators use the
frames ``u^n`` (``r^n``).

For a rotation (Killing) field of the sphere ``w = e_z x p`` the flow is the rotation
``Phi_t`` by angle ``t``; transport preserves the pointwise norm, and relative to the
rotated field ``dPhi psi_0`` the transported vector at colatitude ``theta`` is turned by
``t cos(theta)`` about the outward normal (the geodesic curvature ``cot theta`` of the
latitude integrated over its arc length ``t sin theta``), an ``n``-direction field's
representation vector by ``n t cos(theta)``; see ``tests/test_transport.py`` and
``examples/transport_sphere.py`` (thesis figure 5.1).

Schemes
-------
``scheme="upwind"`` (the default): ``M_z dz/dt = A_w z`` with the upwind discontinuous-
Galerkin form of the covariant derivative in the edge basis
(:mod:`torch_edgevf.fields.upwind`): ``D_w`` completed by the flux terms of the jumps
of the Crouzeix-Raviart fields across edges (which the face-by-face ``D_w`` leaves out) so
that its Hermitian part is the divergence of ``w`` alone, and the upwind penalty ``-U_w`` on
the jumps.  The ``M_z``-norm never grows beyond what the divergence of ``w`` implies, the
dissipation vanishes with the mesh size, and the error is of second order in it.  Time
integration: explicit fourth-order polynomial steps (degree 8 where its stable step per
sparse product beats the classical Runge-Kutta method's), their number following from the
operator (``|w|``, ``h``) and ``t``; one sparse product per degree, no factorization.  One
full turn along the unit sphere's rotation field, ``z0 = w^n``, on
icosphere 5 keeps the ``M_z``-norm within 0.2% and has relative errors of 0.0023 /
0.0087 / 0.036 for ``n = 1 / 2 / 4``, falling at order 2 with the mesh size
(``benchmarks/results/transport_full_turn_n.md``).

``scheme="thesis"``: the thesis' ``z(t) = exp(t M_z^{-1} D_w) z0`` computed by
:func:`torch_edgevf.linalg.expm_multiply`.  ``M_z^{-1} D_w`` is not normal and has growing
modes: accurate for ``t ~ 1`` (relative errors ~2% at icosphere level 3, halving per
level) but it blows up within one full turn.  As in the thesis ("the solution quickly
diverges"), an optional implicit heat step with the connection Laplacian ``L_c^(n)``,
``z <- (M_z + s L_c)^{-1} M_z z``, regularizes between transport steps at the price of
damping the norm (see :data:`SUGGESTED_SMOOTHING`); for ``n``-direction fields it cannot
both control the growth and keep the norm over a full turn.

Every scheme takes the optional heat step (``smoothing``), and every call measures the
``M_z``-norm after each step and warns (:class:`TransportGrowthWarning`) when it grew by
more than ``growth_tol`` (5%).  Along a field with divergence the norm changes
legitimately: raise ``growth_tol`` or pass ``None``.

Gradients flow to ``z0`` and ``t``; to the positions and ``w`` as well when they require
gradients at construction (the upwind scheme then uses the exact exponential
of :func:`~torch_edgevf.linalg.expm_multiply`, slower, instead of the polynomial steps).
"""

from __future__ import annotations

import math
import warnings

import torch

from .._validation import as_edge_field, check_n
from ..linalg import SparseSolver, expm_multiply, solve
from ..mesh.geometry import topology_and_verts
from ..operators.functional import connection_laplacian, covariant_derivative, mass_matrix
from .upwind import UpwindOperator, propagate, upwind_parts

__all__ = ["Transporter", "TransportGrowthWarning", "transport", "SUGGESTED_SMOOTHING", "SCHEMES"]

DIRECTIONS = ("backward", "forward")

#: The transport schemes: ``"upwind"`` (the default) and ``"thesis"`` (see the module
#: documentation).
SCHEMES = ("upwind", "thesis")

#: For ``scheme="thesis"``: the smoothing suggested when the norm grows, ``(c, k)``:
#: ``smoothing = c A`` (``A`` the area of the mesh, so that the suggestion follows its scale)
#: with at least ``k |t|`` steps.  Along the unit sphere's rotation field, one full turn
#: (``t = 2 pi``) of a vector field with ``smoothing = 2.3e-4`` and 8 steps: relative L2
#: error 0.20 / 0.075 / 0.045 at icosphere levels 3 / 4 / 5 (0.45 / 0.92 / 51 without
#: smoothing), ``M_z``-norm 0.88 / 0.94 / 0.97 of the initial one (1.02 / 1.33 / 51
#: without).  The heat step damps n-direction fields (``n >= 2``) more.
SUGGESTED_SMOOTHING = (2e-5, 1.3)


class TransportGrowthWarning(RuntimeWarning):
    """The ``M_z``-norm of a transported field grew beyond ``growth_tol``."""


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
        after every transport step (0, the default, disables it); its factorization is done once.
    n : int >= 1, keyword-only
        The symmetry of the transported fields: 1 for vector fields, ``n`` for the
        representation vectors of ``n``-direction fields (the operators then use ``r^n``).
        Anything else raises ``ValueError``: the transported representation must match
        the field it represents.
    direction : {"backward", "forward"}, keyword-only
        ``"backward"`` (the thesis'): the field moves against ``w``; ``"forward"``: along
        ``w`` (see the module documentation).
    growth_tol : float or None, keyword-only
        Warn (:class:`TransportGrowthWarning`) when the ``M_z``-norm of a transported field
        exceeds ``1 + growth_tol`` times its initial norm after any step; ``None`` disables
        the check.
    scheme : {"upwind", "thesis"}, keyword-only
        The discretization (see the module documentation); ``"upwind"`` by default.

    Examples
    --------
    >>> tr = Transporter(verts, faces, w, n=4)
    >>> z1 = tr(z0, t=0.5)
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
        scheme: str = "upwind",
    ):
        verts, topo = topology_and_verts(verts, faces)
        if not isinstance(smoothing, (int, float)) or isinstance(smoothing, bool) or smoothing < 0:
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
        if scheme not in SCHEMES:
            raise ValueError(f"scheme must be one of {SCHEMES}, got {scheme!r}")
        if growth_tol is not None and not (isinstance(growth_tol, (int, float)) and growth_tol >= 0):
            raise ValueError(f"growth_tol must be a float >= 0 or None, got {growth_tol!r}")
        self.direction, self.growth_tol, self.scheme = direction, growth_tol, scheme
        self.verts, self.topo = verts, topo
        self.w = as_edge_field(w, topo, verts, name="w")
        if self.w.dim() != 1:
            raise ValueError(f"w must have shape (E,), got {tuple(self.w.shape)}")
        self.M = mass_matrix(verts, topo)
        self.mass = self.M.values()
        self._sign = 1 if direction == "backward" else -1
        self._upwind: UpwindOperator | None = None
        if scheme == "thesis":
            self.D = covariant_derivative(verts, topo, self.w, self.n)
            # expm_multiply(A, M, z, t) = exp(-t M^{-1} A) z: backward is A = -D_w, forward A = D_w
            self._generator = (-self.D).coalesce() if direction == "backward" else self.D.coalesce()
        else:
            self.P, self.U, _ = upwind_parts(verts, topo, self.w, self.n)
        self.smoothing = float(smoothing)
        self._smoother = None
        if self.smoothing > 0:
            L = connection_laplacian(verts, topo, self.n)
            A = _sparse_add(self.M.to(L.dtype), self.smoothing * L)
            self._smoother = SparseSolver(A, hermitian=True)

    def operator(self, sign: int = 1) -> torch.Tensor:
        """The generator ``A`` of ``M_z dz/dt = A z`` of the scheme (for ``t > 0``, or
        ``t < 0`` with ``sign=-1``): ``(E, E)`` complex sparse tensor."""
        s = self._sign * sign
        if self.scheme == "thesis":
            return (s * self.D).coalesce()
        return _sparse_add(s * self.P, -self.U)

    @property
    def upwind_operator(self) -> UpwindOperator:
        """The polynomial-step integrator of the upwind scheme (built on first use)."""
        if self.scheme == "thesis":
            raise ValueError("the thesis scheme has no upwind operator")
        if self._upwind is None:
            self._upwind = UpwindOperator(self.P, self.U, self.mass)
        return self._upwind

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

    def num_steps(self, t: float) -> int:
        """The number of polynomial steps the upwind scheme takes for time ``t``."""
        return self.upwind_operator.num_steps(float(t))

    def _step(self, z: torch.Tensor, dt: torch.Tensor) -> torch.Tensor:
        if self.scheme == "thesis":
            return expm_multiply(self._generator, self.M, z, dt)
        sign = 1 if float(dt.detach()) >= 0 else -1
        needs_operator_grad = torch.is_grad_enabled() and (self.P.requires_grad or self.U.requires_grad)
        if needs_operator_grad:
            return expm_multiply((-self.operator(sign)).coalesce(), self.M, z, dt.abs())
        return propagate(self.upwind_operator, z, dt, self._sign * sign)

    def __call__(self, z0, t, steps: int = 1) -> torch.Tensor:
        """Transport ``z0`` for time ``t`` in ``steps`` equal steps (smoothing after each).

        Without smoothing the result hardly depends on ``steps`` (the upwind scheme chooses
        its polynomial steps within each).  Differentiable with respect
        to ``z0`` and ``t`` (a tensor), and to ``verts`` and ``w`` when they required
        gradients at construction.  Warns (:class:`TransportGrowthWarning`) when the
        ``M_z``-norm grows beyond ``growth_tol``.
        """
        if not isinstance(steps, int) or isinstance(steps, bool) or steps < 1:
            raise ValueError(f"steps must be an integer >= 1, got {steps!r}")
        z = as_edge_field(z0, self.topo, self.verts, name="z0")
        if not torch.is_tensor(t):
            t = torch.tensor(float(t), dtype=self.verts.dtype, device=self.verts.device)
        if t.numel() != 1 or t.is_complex() or not bool(torch.isfinite(t.detach()).all()):
            raise ValueError(f"t must be a finite real scalar, got {t!r}")
        t = t.reshape(())
        dt = t / steps
        check = self.growth_tol is not None
        if check:
            with torch.no_grad():
                norm0 = self.norm(z.detach())
            growth = torch.zeros_like(norm0)
        for _ in range(steps):
            z = self._step(z, dt)
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
        if self.scheme == "thesis":
            c, per_unit = SUGGESTED_SMOOTHING
            s = c * float(self.mass.detach().sum())  # the area of the mesh
            suggested_steps = max(steps, math.ceil(per_unit * abs(t)))
            advice = (
                f"pass smoothing={s:.2g} with steps={suggested_steps} (an implicit heat step after each)"
                if self.smoothing < s
                else f"use more steps (steps={2 * steps}) or a shorter time"
            )
            cause = "the semi-discrete transport of the thesis has growing modes; " + advice + ","
        else:
            cause = "the upwind scheme grows only with the divergence of w:"
        warnings.warn(
            f"transport: the M_z-norm of the field grew by {growth:.1%} over t={t:g} in {steps} "
            f"step(s) (scheme={self.scheme!r}, smoothing={self.smoothing:g}): {cause} "
            f"or set growth_tol=None if the field w has divergence",
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
    scheme: str = "upwind",
) -> torch.Tensor:
    """Transport the field ``z0`` along ``w`` for time ``t`` (thesis 5.1).

    Solves ``d psi/dt = nabla_w psi`` (``direction="backward"``, the default: the field
    moves against ``w``; ``"forward"``: along ``w``) with the upwind scheme by default, which
    keeps the ``M_z``-norm of a field transported along a divergence-free ``w`` (it never
    grows; it decays only as the unresolved scales are damped) and converges at second
    order (see the module documentation and :class:`Transporter`).  ``smoothing > 0`` adds
    an implicit heat step after each of the ``steps`` steps.  Warns
    (:class:`TransportGrowthWarning`) when the ``M_z``-norm grows by more than
    ``growth_tol``.  Differentiable with respect to ``z0`` and ``t``.

    Parameters
    ----------
    verts : (V, 3) tensor
    faces : (F, 3) int tensor or :class:`Topology`
    z0 : (E,) or (E, C) complex tensor, a vector field (``n = 1``) or the representation
        vector of an ``n``-direction field
    w : (E,) complex tensor, a vector field
    t : float or 0-d tensor
    n, direction, growth_tol, scheme : see :class:`Transporter`

    Returns
    -------
    (E,) or (E, C) complex tensor.
    """
    tr = Transporter(
        verts, faces, w, smoothing, n=n, direction=direction, growth_tol=growth_tol, scheme=scheme
    )
    return tr(z0, t, steps)
