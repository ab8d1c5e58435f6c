"""Foldover-free repair of a map's flipped triangles ([GKK+21] "Foldover-free maps in 50 lines of code").

The energy of Garanzha, Kaporin, Kudryavtseva, Protais, Ray and Sokolov (2021),

.. math::
    F_\\varepsilon = \\sum_t A_t \\Big[
        (1 - \\lambda) \\frac{\\operatorname{tr} J_t^T J_t}{\\chi(\\det J_t, \\varepsilon)}
        + \\lambda \\frac{\\det^2 J_t + 1}{\\chi(\\det J_t, \\varepsilon)} \\Big],
    \\qquad \\chi(D, \\varepsilon) = \\frac{D + \\sqrt{\\varepsilon^2 + D^2}}{2},

with ``J_t`` the Jacobian of a triangle's map relative to its target shape, is finite for
flipped triangles while ``epsilon > 0`` and tends to the (barrier) distortion energy as
``epsilon -> 0``. Minimising it by L-BFGS while lowering ``epsilon`` as the paper prescribes
untangles the map. Here the unknowns are the free vertices of an integer-grid map near its
flipped triangles; the integer unknowns (cones, seam translations) stay fixed, so the result
is still an integer-grid map.
"""

from __future__ import annotations

import logging

import numpy as np
import scipy.optimize as so
import scipy.sparse as sp

__all__ = ["untangle"]

log = logging.getLogger(__name__)

_LAMBDA = 1.0 / 128


def _chi(d, eps):
    """``(d + sqrt(eps^2 + d^2)) / 2``, without cancellation for negative ``d``."""
    r = np.sqrt(eps * eps + d * d)
    return np.where(d >= 0, 0.5 * (d + r), 0.5 * eps * eps / np.maximum(r - d, 1e-300))


def _chi_prime(d, eps):
    return 0.5 * (1 + d / np.sqrt(eps * eps + d * d))


def _energy_grad(c: np.ndarray, rinv: np.ndarray, weight: np.ndarray, eps: float):
    """Energy and its gradient with respect to the corners ``c`` (T, 3, 2)."""
    D = np.stack([c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]], -1)  # (T, 2, 2), columns
    J = D @ rinv
    det = J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0]
    tr = (J**2).sum((1, 2))
    chi = _chi(det, eps)
    chp = _chi_prime(det, eps)
    f = tr / chi
    g = (det**2 + 1) / chi
    e = float((weight * ((1 - _LAMBDA) * f + _LAMBDA * g)).sum())
    cof = np.stack([np.stack([J[:, 1, 1], -J[:, 1, 0]], -1), np.stack([-J[:, 0, 1], J[:, 0, 0]], -1)], -2)
    df = 2 * J / chi[:, None, None] - (tr * chp / chi**2)[:, None, None] * cof
    dg = (2 * det / chi - (det**2 + 1) * chp / chi**2)[:, None, None] * cof
    dJ = weight[:, None, None] * ((1 - _LAMBDA) * df + _LAMBDA * dg)
    dD = dJ @ np.transpose(rinv, (0, 2, 1))
    grad = np.zeros_like(c)
    grad[:, 1] = dD[:, :, 0]
    grad[:, 2] = dD[:, :, 1]
    grad[:, 0] = -grad[:, 1] - grad[:, 2]
    return e, grad, det


def untangle(
    P: sp.spmatrix,
    Q: sp.spmatrix,
    y: np.ndarray,
    x: np.ndarray,
    wedge: np.ndarray,
    ncls: int,
    target: np.ndarray,
    rings: int = 3,
    max_outer: int = 40,
    max_grow: int = 3,
) -> np.ndarray:
    """Free unknowns ``x`` of the map ``W = P x + Q y`` with no flipped triangle, if found.

    Parameters
    ----------
    P, Q : the sparse maps from the free and the (fixed) integer unknowns to the wedge values,
        rows ``[u (ncls); v (ncls)]``
    y, x : the fixed integers and the free unknowns to start from
    wedge : (F, 3) wedge of every corner
    target : (F, 3, 2) the target shape of every triangle (``J = I`` there)
    rings : the unknowns within this many face rings of the flipped triangles are optimised;
        the region grows (doubling) up to ``max_grow`` times while flips remain

    Returns
    -------
    the new ``x`` (the input one if no flip-free map was found; the caller counts flips).
    """
    nf = wedge.shape[0]
    W0 = Q @ y
    R = np.stack([target[:, 1] - target[:, 0], target[:, 2] - target[:, 0]], -1)
    rdet = R[:, 0, 0] * R[:, 1, 1] - R[:, 0, 1] * R[:, 1, 0]
    rinv = np.stack([np.stack([R[:, 1, 1], -R[:, 0, 1]], -1), np.stack([-R[:, 1, 0], R[:, 0, 0]], -1)], -2)
    rinv = rinv / rdet[:, None, None]
    area = 0.5 * np.abs(rdet)
    # corner -> free unknowns incidence, and face adjacency through shared wedges' vertices
    Pc = P.tocsr()
    corner_rows_u = wedge.ravel()
    Pu, Pv = Pc[corner_rows_u], Pc[ncls + corner_rows_u]  # (3F, nx)
    Pa = (abs(Pu) + abs(Pv)).tocsr()
    face_of_x = sp.csr_matrix(
        (np.ones(Pa.nnz), (np.repeat(np.arange(3 * nf) // 3, np.diff(Pa.indptr)), Pa.indices)),
        shape=(nf, P.shape[1]),
    )
    face_adj = (face_of_x @ face_of_x.T).tocsr()

    def corners(xx):
        W = P @ xx + W0
        return np.stack([W[:ncls][wedge], W[ncls:][wedge]], -1)

    c = corners(x)
    det0 = _orient(c)
    flipped = np.flatnonzero(det0 <= 0)
    if flipped.size == 0:
        return x
    best, best_flips = x, flipped.size
    k = rings
    for _ in range(max_grow + 1):
        region = np.zeros(nf, dtype=bool)
        region[flipped] = True
        frontier = region.copy()
        for _ring in range(k):
            frontier = (face_adj @ frontier.astype(float)) > 0
            region |= frontier
        free_cols = np.unique(face_of_x[region].indices)
        if free_cols.size == 0:  # every corner there is held at an integer: nothing to move
            log.info("untangle: the %d flipped triangles have no free unknown", flipped.size)
            break
        active = np.unique(face_of_x[:, free_cols].tocsc().indices)
        x_new = _optimise(P, W0, best, free_cols, active, wedge, ncls, rinv[active], area[active], max_outer)
        c = corners(x_new)
        det = _orient(c)
        nflip = int((det <= 0).sum())
        log.info("untangle: %d rings, %d free unknowns, %d flips left", k, free_cols.size, nflip)
        if nflip == 0:
            return x_new
        if nflip <= best_flips:
            best, best_flips = x_new, nflip
        flipped = np.flatnonzero(det <= 0)
        k *= 2
    return best


def _orient(c):
    return (c[:, 1, 0] - c[:, 0, 0]) * (c[:, 2, 1] - c[:, 0, 1]) - (c[:, 1, 1] - c[:, 0, 1]) * (
        c[:, 2, 0] - c[:, 0, 0]
    )


def _optimise(P, W0, x0, free_cols, active, wedge, ncls, rinv, area, max_outer):
    """Minimise ``F_eps`` over ``x[free_cols]`` with the paper's ``epsilon`` schedule."""
    Pf = P.tocsc()[:, free_cols].tocsr()
    x_fixed = x0.copy()
    x_fixed[free_cols] = 0
    base = P @ x_fixed + W0
    w_act = wedge[active]
    weight = area / area.sum()
    # rows of the active corners only
    Pu = Pf[w_act.ravel()]
    Pv = Pf[ncls + w_act.ravel()]
    bu, bv = base[:ncls][w_act.ravel()], base[ncls:][w_act.ravel()]

    def corners(z):
        return np.stack([(Pu @ z + bu).reshape(-1, 3), (Pv @ z + bv).reshape(-1, 3)], -1)

    def fun(z, eps):
        c = corners(z)
        e, gc, _ = _energy_grad(c, rinv, weight, eps)
        gz = Pu.T @ gc[..., 0].ravel() + Pv.T @ gc[..., 1].ravel()
        return e, gz

    z = x0[free_cols].copy()
    c = corners(z)
    D = np.stack([c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]], -1) @ rinv
    det = D[:, 0, 0] * D[:, 1, 1] - D[:, 0, 1] * D[:, 1, 0]
    eps = max(1e-8, float(np.sqrt(1e-12 + 0.04 * np.minimum(det.min(), 0) ** 2)))
    stuck = 0
    for _ in range(max_outer):
        e_prev = fun(z, eps)[0]
        res = so.minimize(fun, z, args=(eps,), jac=True, method="L-BFGS-B", options={"maxiter": 300})
        z = res.x
        e, _, det = _energy_grad(corners(z), rinv, weight, eps)
        sigma = max(1 - e / e_prev, 0.1)
        mindet = float(det.min())
        mu = (1 - sigma) * _chi(mindet, eps)
        eps = 2 * np.sqrt(mu * (mu - mindet)) if mindet < mu else 1e-10
        if mindet > 0 and abs(e_prev - e) / e < 1e-5:
            break
        stuck = stuck + 1 if mindet <= 0 and eps < 1e-8 else 0
        if stuck >= 3:  # the barrier no longer moves the folded triangles: give up here
            break
    out = x0.copy()
    out[free_cols] = z
    return out
