"""Exact 2-D robust backward reachability: an upper bound on every method's edges.

``R_0 = P_j``, ``R_s = S ∩ Pre(R_{s-1})``, edge at ``L`` iff ``P_i ⊆ Pre(R_{L-1})``
(docs/math/open-loop.md#the-exact-2-d-reference). Each operation is exact on a convex polygon
(erosion by ``W`` moves every edge by ``sigma_W`` of its normal). Floating point is pushed the
permissive way (half-planes relaxed by ``_SLACK``, containment up to ``tol``), so tube and open-loop
edges are subsets of these. ``margin`` is the containment slack of ``P_i``'s vertices in
``Pre(R_{L-1})``, not comparable with ``t*``. Polygons are ``(k, 2)`` counter-clockwise arrays.
"""

from __future__ import annotations

import numpy as np

from ..model.geometry import Ball, Polytope, support
from ..lp.evidence.exact_geometry import ccw_ring
from ..lp.evidence.verdict import Verdict, sequential_solver
from ..model.system import LinearSystem

__all__ = ["convex_hull_2d", "clip_halfplane", "clip_halfplanes", "erode", "robust_pre", "backward_reach_sets",
           "containment_slack", "exact_pair", "exact_edges", "exact2d_verdict",
           "exact2d_solve_batch"]

#: Relaxation of every half-plane in the set operations (keeps the result an upper bound).
_SLACK = 1e-12
#: Points closer than this are merged; edges shorter than this carry no normal.
_MERGE = 1e-13


def convex_hull_2d(points) -> np.ndarray:
    """Convex hull of points in the plane (Andrew's monotone chain, the exact hulls' ``ccw_ring``).

    Parameters
    ----------
    points : array_like, shape (N, 2)

    Returns
    -------
    ndarray, shape (k, 2)
        Hull vertices counter-clockwise, collinear points dropped; ``k <= 2``
        for degenerate input (a point or a segment), ``k = 0`` for no points.
    """
    P = np.asarray(points, float).reshape(-1, 2)
    if P.shape[0] == 0:
        return np.zeros((0, 2))
    P = P[np.lexsort((P[:, 1], P[:, 0]))].tolist()
    return _dedupe(np.array(ccw_ring(P)) if len(P) > 1 else np.array(P))


def _dedupe(poly: np.ndarray) -> np.ndarray:
    """Drop cyclically consecutive vertices closer than ``_MERGE`` (keeps at least one)."""
    if poly.shape[0] <= 1:
        return poly
    d = np.abs(poly - np.roll(poly, -1, axis=0)).max(axis=1)
    keep = d > _MERGE
    if not keep.any():
        return poly[:1]
    return poly[keep]


def _edges(poly: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit outward edge normals ``H (f, 2)`` and offsets ``h (f,)`` of a CCW polygon with ``k >= 3``."""
    e = np.roll(poly, -1, axis=0) - poly
    ln = np.linalg.norm(e, axis=1)
    ok = ln > _MERGE
    H = np.stack([e[ok, 1], -e[ok, 0]], axis=1) / ln[ok, None]
    h = np.einsum("ij,ij->i", H, poly[ok])
    return H, h


def clip_halfplane(poly: np.ndarray, a, b: float) -> np.ndarray:
    """``poly ∩ {x : a . x <= b}`` (Sutherland-Hodgman on one edge).

    Parameters
    ----------
    poly : ndarray, shape (k, 2)     convex polygon, point or segment
    a : array_like, shape (2,)
    b : float

    Returns
    -------
    ndarray, shape (k', 2)
    """
    k = poly.shape[0]
    if k == 0:
        return poly
    a = np.asarray(a, float)
    s = poly @ a - b                                # > 0 outside
    if np.all(s <= 0):
        return poly
    if np.all(s > 0):
        return np.zeros((0, 2))
    if k == 1:
        return poly if s[0] <= 0 else np.zeros((0, 2))
    out = []
    for idx in range(k):
        p, q = poly[idx], poly[(idx + 1) % k]
        sp, sq = s[idx], s[(idx + 1) % k]
        if sp <= 0:
            out.append(p)
        if (sp <= 0) != (sq <= 0):
            lam = sp / (sp - sq)
            out.append(p + lam * (q - p))
        if k == 2 and idx == 0:                     # a segment: do not walk back along it
            if sq <= 0:
                out.append(q)
            break
    return _dedupe(np.array(out).reshape(-1, 2))


def clip_halfplanes(poly: np.ndarray, H, h) -> np.ndarray:
    """``poly ∩ {x : H x <= h}``: :func:`clip_halfplane` by each row of ``H (f, 2)``, ``h (f,)`` in order."""
    for a, b in zip(H, h):
        if poly.shape[0] == 0:
            break
        poly = clip_halfplane(poly, a, b)
    return poly


def erode(poly: np.ndarray, W) -> np.ndarray:
    """``poly ⊖ W`` for a convex polygon and a :class:`Ball` or :class:`Polytope` ``W`` (exact).

    Parameters
    ----------
    poly : ndarray, shape (k, 2)
    W : Ball or Polytope

    Returns
    -------
    ndarray, shape (k', 2)
    """
    if poly.shape[0] == 0 or (isinstance(W, Ball) and W.radius == 0.0):
        return poly
    if poly.shape[0] <= 2:      # no interior: a full-dimensional W (ball r > 0, polytope) does not fit
        return np.zeros((0, 2))
    H, h = _edges(poly)
    return clip_halfplanes(poly, H, h - support(W, H) + _SLACK)


def _check_system(system: LinearSystem) -> np.ndarray:
    if system.n != 2:
        raise ValueError(f"system: exact2d needs a 2-D state, got n = {system.n}")
    A = system.A
    if abs(np.linalg.det(A)) <= 1e-12 * max(1.0, np.linalg.norm(A) ** 2):
        raise ValueError("system.A must be invertible for exact2d (Pre(X) = A^-1((X ⊖ W) ⊕ (-B U)))")
    return np.linalg.inv(A)


def robust_pre(poly: np.ndarray, system: LinearSystem, Ainv: np.ndarray | None = None) -> np.ndarray:
    """``Pre(X) = A^{-1}((X ⊖ W) ⊕ (−B U))``, exact for a convex polygon ``X``.

    Parameters
    ----------
    poly : ndarray, shape (k, 2)
    system : LinearSystem            2-D state, invertible ``A``
    Ainv : ndarray, shape (2, 2), optional   ``A^{-1}``, if already known

    Returns
    -------
    ndarray, shape (k', 2)
    """
    if Ainv is None:
        Ainv = _check_system(system)
    Y = erode(poly, system.W)
    if Y.shape[0] == 0:
        return Y
    BU = -(system.U.vertices @ system.B.T)                     # (n_u, 2)
    S = (Y[:, None, :] + BU[None, :, :]).reshape(-1, 2)
    return convex_hull_2d(S @ Ainv.T)


def backward_reach_sets(system: LinearSystem, target: Polytope, safe: Polytope,
                        n_steps: int) -> list[np.ndarray]:
    """The sets ``Pre(R_s)``, ``s = 0 .. n_steps-1``: ``Pre(R_{L-1})`` holds the states from which
    some causal feedback reaches ``target`` in exactly ``L`` steps, staying in ``safe`` at steps
    ``1 .. L-1``, for every disturbance sequence.

    Parameters
    ----------
    system : LinearSystem
    target : Polytope        ``P_j`` (2-D)
    safe : Polytope          ``S`` (2-D)
    n_steps : int            ``>= 1``

    Returns
    -------
    list of ndarray, each of shape (k, 2)
        Entry ``L - 1`` belongs to horizon ``L``; entries after an empty set are empty.
    """
    if int(n_steps) < 1:
        raise ValueError(f"n_steps must be >= 1, got {n_steps}")
    Ainv = _check_system(system)
    for name, P in (("target", target), ("safe", safe)):
        if P.dim != 2:
            raise ValueError(f"{name}: exact2d needs a 2-D polytope, got dimension {P.dim}")
    R = convex_hull_2d(target.vertices)
    out = []
    for s in range(int(n_steps)):
        pre = robust_pre(R, system, Ainv)
        out.append(pre)
        R = clip_halfplanes(pre, safe.H, safe.h + _SLACK)
    return out


def containment_slack(inner: Polytope, poly: np.ndarray) -> float:
    """``min_{v vertex of inner} min_f (h_f - H_f v)`` over the unit edge rows of ``poly``.

    ``>= 0`` iff ``inner ⊆ poly`` (both convex); ``-inf`` when ``poly`` has no interior.
    """
    if poly.shape[0] < 3:
        return float("-inf")
    H, h = _edges(poly)
    return float(np.min(h[None, :] - inner.vertices @ H.T))


def exact_pair(system: LinearSystem, source: Polytope, target: Polytope, safe: Polytope,
               L_max: int, tol: float = 1e-9) -> tuple[int | None, float]:
    """Minimal exact horizon of one pair.

    Returns
    -------
    L : int or None
        Smallest ``L <= L_max`` with ``P_i ⊆ Pre(R_{L-1})`` (up to ``tol``), else ``None``.
    margin : float
        :func:`containment_slack` at that ``L`` (the best slack seen if ``None``).
    """
    best = float("-inf")
    for s, pre in enumerate(backward_reach_sets(system, target, safe, L_max)):
        if pre.shape[0] == 0:
            break
        m = containment_slack(source, pre)
        if m >= -tol:
            return s + 1, m
        best = max(best, m)
    return None, best


def exact_edges(decomp, system: LinearSystem, L_max: int, tol: float = 1e-9) -> dict:
    """The exact edges of a 2-D decomposition: ``{(i, j): (L, margin)}`` with minimal ``L``.

    ``S`` is chosen as in :func:`tubejax.model.problem.pair_problem`. Self-pairs are skipped.

    Parameters
    ----------
    decomp : CellDecomposition       2-D cells
    system : LinearSystem            2-D state, invertible ``A``
    L_max : int                      ``>= 1``

    Returns
    -------
    dict
        ``{(i, j): (L, margin)}``, ``L`` minimal.
    """
    if not isinstance(L_max, (int, np.integer)) or L_max < 1:
        raise ValueError(f"L_max must be an integer >= 1, got {L_max!r}")
    if decomp.dim != 2:
        raise ValueError(f"decomp: exact2d needs 2-D cells, got dimension {decomp.dim}")
    _check_system(system)
    out = {}
    N = decomp.n_cells
    for i in range(N):
        for j in range(N):
            if i == j:
                continue
            safe = decomp.cells[i] if decomp.obstacle_case(i, j) else decomp.pair_hull(i, j)
            L, m = exact_pair(system, decomp.cells[i], decomp.cells[j], safe, L_max, tol)
            if L is not None:
                out[(i, j)] = (L, m)
    return out


def exact2d_verdict(prob, tol: float = 1e-9):
    """Exact verdict for one :class:`~tubejax.model.problem.TubeProblem` (``Z`` ignored).

    Returns
    -------
    tubejax.abstraction.Verdict
        ``'edge'`` when ``P_i ⊆ Pre(R_{L-1})`` up to ``tol``, else ``'infeasible'``;
        ``margin`` is :func:`containment_slack`; ``tube`` is ``None`` (the
        evidence is the polygon computation itself); provenance ``'exact2d'``.
    """
    pre = backward_reach_sets(prob.system, prob.target, prob.safe, int(prob.L))[-1]
    m = containment_slack(prob.source, pre)
    return Verdict("edge" if m >= -tol else "infeasible", m, None, "exact2d")


#: Batch solver for :func:`tubejax.abstraction.build_abstraction` (exact 2-D verdicts).
exact2d_solve_batch = sequential_solver(exact2d_verdict)
exact2d_solve_batch.method = "exact2d"                # read by abstraction.methods.solver_method
exact2d_solve_batch.__name__ = "exact2d_solve_batch"
