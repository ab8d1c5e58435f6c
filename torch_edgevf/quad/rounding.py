"""Mixed-integer least squares of an integer-grid map (see :mod:`torch_edgevf.quad.igm`).

The energy ``|A W - rhs|^2`` over the wedge values ``W = P x + Q y`` (``x`` real, ``y``
integer) with the linear constraints ``K [y; 1] = 0``, solved in three steps:

1. :func:`eliminate`: Gaussian elimination of the constraints, pivoting first on unit
   coefficients of the preferred unknowns (the seam translations), gives every solution
   as ``y = B y_ind + b0``; when all pivots are units ``B`` and ``b0`` are integer, so
   integer ``y_ind`` give integer ``y``;
2. :class:`Reduced`: ``x`` is eliminated by one sparse factorization (the Schur
   complement), leaving a small dense quadratic in ``y_ind``;
3. :func:`greedy_round` [BZK09]: phase after phase (cones, then seams), the free unknown
   closest to an integer is fixed and the rest re-solved.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse.linalg as sla

__all__ = ["eliminate", "Reduced", "greedy_round"]


def eliminate(
    K: np.ndarray, prefer: np.ndarray, never: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Solve ``K [y; 1] = 0`` for some unknowns: ``y = B y[ind] + b0``.

    Parameters
    ----------
    K : (r, n + 1) constraints, the last column the constant term
    prefer : (n,) bool, unknowns to make dependent first (on a unit pivot)
    never : (n,) bool, unknowns never made dependent (fixed ones: their value stays 0)

    Returns
    -------
    B : (n, m), b0 : (n,), ind : (m,) indices of the independent unknowns (``never``
    unknowns excluded: their columns of ``B`` are 0). Rows of ``K`` that reduce to
    ``0 = c != 0`` (contradictions) are dropped.
    """
    K = np.asarray(K, dtype=np.float64).copy()
    r, n1 = K.shape
    n = n1 - 1
    K[:, :n][:, never] = 0.0
    active = np.ones(r, dtype=bool)
    pivots: list[tuple[int, int]] = []
    allowed = ~never
    while True:
        rows = np.flatnonzero(active)
        if rows.size == 0:
            break
        mod = np.abs(K[rows][:, :n])
        mod[:, ~allowed] = 0
        mod[mod < 1e-9] = 0
        if not mod.any():
            break
        unit = np.abs(mod - 1) < 1e-9
        cand = unit & prefer[None, :]
        if not cand.any():
            cand = unit
        if cand.any():
            i, j = np.argwhere(cand)[0]
        else:
            m = np.where(mod > 0, mod, np.inf)
            i, j = np.unravel_index(np.argmin(m), m.shape)
        i = rows[i]
        K[i] /= K[i, j]
        others = np.flatnonzero(np.abs(K[:, j]) > 1e-12)
        others = others[others != i]
        K[others] -= K[others, j][:, None] * K[i][None, :]
        K[np.abs(K) < 1e-12] = 0
        active[i] = False
        allowed[j] = False
        pivots.append((i, j))
    dep = np.array([j for _, j in pivots], dtype=np.int64)
    ind = np.setdiff1d(np.flatnonzero(~never), dep)
    B = np.zeros((n, ind.size))
    b0 = np.zeros(n)
    B[ind, np.arange(ind.size)] = 1
    for i, j in pivots:
        B[j] = -K[i, ind]
        b0[j] = -K[i, n]
    return B, b0, ind


class Reduced:
    """``|A (P x + Q y) - rhs|^2`` with ``y = B y_ind + b0`` and ``x`` at its optimum.

    ``energy(y_ind) = y_ind^T S y_ind - 2 g^T y_ind + const``; :meth:`wedges` gives ``W``.
    """

    def __init__(self, A, rhs, P, Q, B, b0):
        H = (A.T @ A).tocsr()
        self.P, self.Q, self.A, self.rhs = P, Q, A, rhs
        Hxx = (P.T @ H @ P).tocsc()
        self.Hxy = (P.T @ H @ Q).tocsr()
        Hyy = (Q.T @ H @ Q).tocsr()
        Atr = A.T @ rhs
        self.bx, by = P.T @ Atr, Q.T @ Atr
        self.B, self.b0 = B, b0
        self.lu = sla.splu(Hxx, permc_spec="MMD_AT_PLUS_A") if Hxx.shape[0] else None
        C = np.column_stack([B, b0])
        M = np.asarray(self.Hxy @ C)
        X0 = self._solve(self.bx)
        XM = self._solve(M)
        SC = C.T @ (Hyy @ C) - M.T @ XM  # Schur complement on [y_ind; 1]
        m = B.shape[1]
        self.S = 0.5 * (SC[:m, :m] + SC[:m, :m].T)
        gy = C.T @ by - M.T @ X0
        self.g = gy[:m] - SC[:m, m]

    def _solve(self, b):
        if self.lu is None:
            return np.zeros_like(b)
        return self.lu.solve(b)

    def y(self, y_ind: np.ndarray) -> np.ndarray:
        return self.B @ y_ind + self.b0

    def x(self, y: np.ndarray) -> np.ndarray:
        return self._solve(self.bx - self.Hxy @ y)

    def wedges(self, y: np.ndarray, x: np.ndarray | None = None) -> np.ndarray:
        x = self.x(y) if x is None else x
        return self.P @ x + self.Q @ y

    def energy(self, W: np.ndarray) -> float:
        return float(np.sum((self.A @ W - self.rhs) ** 2))

    def relaxed(self) -> np.ndarray:
        return np.linalg.lstsq(self.S, self.g, rcond=None)[0] if self.S.size else np.zeros(0)


def greedy_round(S: np.ndarray, g: np.ndarray, phases: list[np.ndarray]):
    """Minimise ``y^T S y - 2 g^T y`` over integers, greedily [BZK09].

    Each step fixes the free unknown of the current phase closest to an integer (ties
    together) and re-solves the rest exactly: fixing ``y_i`` moves the minimiser of the free
    unknowns by ``S_ff^{-1} e_i`` times the step (a rank-one update of the inverse, O(n^2)).
    Unknowns in no phase stay real. Returns ``(y, steps)``.
    """
    n = S.shape[0]
    if n == 0:
        return np.zeros(0), 0
    reg = 1e-12 * max(float(np.trace(S)) / n, 1e-300)
    Sinv = np.linalg.inv(S + reg * np.eye(n))
    cur = Sinv @ g
    free = np.ones(n, dtype=bool)
    steps = 0
    for phase in phases:
        while True:
            cand = phase[free[phase]]
            if cand.size == 0:
                break
            d = np.abs(cur[cand] - np.rint(cur[cand]))
            for i in cand[d <= d.min() + 1e-9]:
                fi = np.flatnonzero(free)
                col = Sinv[:, i].copy()
                step = (np.rint(cur[i]) - cur[i]) / col[i]
                cur[fi] += col[fi] * step
                cur[i] = np.rint(cur[i])
                Sinv -= np.outer(col, col) / col[i]
                Sinv[i, :] = 0
                Sinv[:, i] = 0
                free[i] = False
            steps += 1
    return cur, steps
