"""The tube LP of the product family for one full pair, built from the data and solved by HiGHS.

Independent of the factor decomposition and of the project's LP builders: the rows are written out
vertex by vertex from the data (docs/math/product.md#the-product-tube-family) and ``max t`` is
solved with :func:`scipy.optimize.linprog` (``method='highs'``); ``verify --complete`` and the tests
re-solve full pairs with it. Each facet row ``r`` of ``Z`` lives in one group ``g(r)``, so
``y in D_l Z`` iff ``H_r y <= eps_{l, g(r)} h_r`` for every ``r``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.optimize import linprog

from ..model.geometry import Ball, Polytope

__all__ = ["ProductPair", "product_lp_margin"]


def _support(W, a: np.ndarray) -> np.ndarray:
    if isinstance(W, Ball):
        return W.radius * np.linalg.norm(a, axis=1)
    return np.max(a @ W.vertices.T, axis=1)


class ProductPair(NamedTuple):
    """One full pair's sets: ``source`` ``P_i``, ``target`` ``P_j``, ``safe`` ``S`` and ``Z`` (its vertices
    paired with ``source``'s by index), each a :class:`~tubejax.model.geometry.Polytope`."""

    source: Polytope
    target: Polytope
    safe: Polytope
    Z: Polytope


def product_lp_margin(system, pair: ProductPair, groups, L: int, eps_min: float = 0.0, t_max: float = 1.0) -> float:
    """The margin ``t*`` of the product-family tube LP of one pair (``>= 0``: feasible).

    Parameters
    ----------
    system : LinearSystem
    pair : ProductPair                  ``P_i``, ``P_j``, ``S`` and ``Z``
    groups : sequence of sequence of int   the state axes of each group
    L : int
    eps_min : float
    t_max : float                       cap on ``t``

    Returns
    -------
    float
        ``t*`` (capped at ``t_max``); ``-inf`` when even the hard rows (``U``, ``eps >= eps_min``)
        cannot hold.
    """
    source, target, safe, Z = pair
    A, B = system.A, system.B
    n, m = B.shape
    G = len(groups)
    V, Zv = np.asarray(source.vertices, float), np.asarray(Z.vertices, float)
    nv = len(Zv)
    g_of_axis = np.empty(n, dtype=int)
    for g, axes in enumerate(groups):
        g_of_axis[list(axes)] = g
    n_p, n_e, n_u = L * n, L * G, L * nv * m
    nx = n_p + n_e + n_u + 1                           # ..., t last

    def P(l):                                          # column of p_l (l = 1..L), shape (n,)
        return np.arange((l - 1) * n, l * n)

    def E(l):                                          # columns of eps_{l, g}, shape (G,)
        return n_p + np.arange((l - 1) * G, l * G)

    def Ucol(l, k):                                    # u_k(l), l = 0..L-1
        return n_p + n_e + (l * nv + k) * m + np.arange(m)

    def q(l, k):
        """``q_k(l)`` as (coefficient matrix (n, nx), constant (n,))."""
        M = np.zeros((n, nx))
        if l == 0:
            return M, V[k].copy()
        M[np.arange(n), P(l)] = 1.0
        M[np.arange(n), E(l)[g_of_axis]] = Zv[k]
        return M, np.zeros(n)

    rows, rhs = [], []

    def add(H, h, M, c, margin=True):                  # H (M c_x + c) <= h  ->  (H M) x + t <= h - H c
        R = H @ M
        if margin:
            R[:, -1] = 1.0
        rows.append(R)
        rhs.append(h - H @ c)

    Hz, hz = Z.H, Z.h
    rz_group = np.array([g_of_axis[int(np.flatnonzero(r != 0)[0])] for r in Hz])
    sw = _support(system.W, Hz)
    for k in range(nv):
        for l in range(1, L):
            add(safe.H, safe.h, *q(l, k))
        add(target.H, target.h, *q(L, k))
        if system.X is not None:
            for l in range(1, L + 1):
                add(system.X.H, system.X.h, *q(l, k))
        for l in range(L):                             # C4: H_z (A q + B u - p_{l+1}) - eps_{l+1, g(r)} h_z <= -sigma_W
            M, c = q(l, k)
            M = A @ M
            c = A @ c
            M[:, Ucol(l, k)] += B
            M[np.arange(n), P(l + 1)] -= 1.0
            R = Hz @ M
            R[np.arange(len(hz)), E(l + 1)[rz_group]] -= hz
            R[:, -1] = 1.0
            rows.append(R)
            rhs.append(-sw - Hz @ c)
        for l in range(L):                             # C5 (hard)
            M = np.zeros((len(system.U.h), nx))
            M[:, Ucol(l, k)] = system.U.H
            rows.append(M)
            rhs.append(system.U.h.copy())
    A_ub, b_ub = np.vstack(rows), np.concatenate(rhs)
    bounds = [(None, None)] * n_p + [(eps_min, None)] * n_e + [(None, None)] * n_u + [(None, t_max)]
    cost = np.zeros(nx)
    cost[-1] = -1.0
    res = linprog(cost, A_ub=A_ub, b_ub=b_ub, bounds=bounds, method="highs")
    if res.status == 2:
        return float("-inf")
    if res.status != 0:
        raise RuntimeError(f"HiGHS: {res.message}")
    return float(res.x[-1])
