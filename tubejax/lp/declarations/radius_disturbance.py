"""The disturbance shape ``W_0`` and the radius ``rho`` of ``W = rho W_0`` (docs/math/radius.md).

``rho`` is in the user's units: a ball's radius (``W_0`` the unit ball), a cube's half-width
(``W_0 = [-1, 1]^n``), else a scale factor (``W_0 = W``, ``rho = 1``). ``W_0`` must have 0 in its
interior (so ``rho < 0`` relaxes every row it enters); a polytope with 0 on its boundary is refused.
``rho_max_bound`` is a rigorous upper bound on the largest ``rho`` with ``P ⊖ rho W_0 != ∅``, so
``rho <= rho_max`` cuts off no feasible point of Problem 2.
"""

from __future__ import annotations

import dataclasses
import weakref

import numpy as np
from scipy.optimize import linprog

from ...model.geometry import Ball, Polytope, support
from .tube_variables import axis_widths

__all__ = ["unit_disturbance", "scaled_disturbance", "with_disturbance", "rho_max_bound", "zero_disturbance_system"]

_CUBE_TOL = 1e-12
_UNIT_BOX: dict = {}                                       # one [-1, 1]^n per dimension
_rho_max_cache: dict = {}                                  # by cell shape up to translation
_rho_max_by_cell = weakref.WeakKeyDictionary()             # by cell object (fast path)


def unit_disturbance(W) -> tuple[Ball | Polytope, float]:
    """``(W_0, rho)`` with ``W = rho W_0`` (see the module docstring).

    Parameters
    ----------
    W : Ball or Polytope
        A system's disturbance set.

    Returns
    -------
    W0 : Ball or Polytope
    rho : float

    Raises
    ------
    ValueError
        If ``W`` is a polytope without ``0`` in its interior, or another type.
    """
    if isinstance(W, Ball):
        return Ball(W.dim, 1.0), float(W.radius)
    if not isinstance(W, Polytope):
        raise ValueError(f"W must be a Ball or a Polytope, got {type(W).__name__}")
    if np.any(W.h <= _CUBE_TOL):
        raise ValueError("the radius form needs 0 in the interior of W (W = rho W0 must relax every "
                         f"row as rho decreases); smallest facet offset of W: {float(np.min(W.h)):.3g}")
    n = W.dim
    lo, hi = W.bounding_box()
    h = float(hi[0])
    cube = (W.n_vertices == 2 ** n and np.allclose(hi, h, rtol=0, atol=_CUBE_TOL * max(h, 1.0))
            and np.allclose(lo, -h, rtol=0, atol=_CUBE_TOL * max(h, 1.0))
            and np.allclose(np.abs(W.vertices), h, rtol=0, atol=_CUBE_TOL * max(h, 1.0)))
    if cube:
        if n not in _UNIT_BOX:
            _UNIT_BOX[n] = Polytope.box(-np.ones(n), np.ones(n))
        return _UNIT_BOX[n], h
    return W, 1.0


def scaled_disturbance(W0, rho: float) -> Ball | Polytope:
    """``rho W0`` as a set the system accepts (``rho = 0``: the ball of radius 0, i.e. ``{0}``).

    Raises
    ------
    ValueError
        If ``rho`` is negative or not finite.
    """
    rho = float(rho)
    if not (np.isfinite(rho) and rho >= 0):
        raise ValueError(f"the radius must be a finite number >= 0, got {rho}")
    if isinstance(W0, Ball):
        return Ball(W0.dim, rho * W0.radius)
    if rho == 0.0:
        return Ball(W0.dim, 0.0)
    return Polytope.from_vertices(rho * W0.vertices)


def with_disturbance(problem, W):
    """``problem`` (a ``TubeProblem``) with its system's ``W`` replaced by ``W``."""
    return dataclasses.replace(problem, system=dataclasses.replace(problem.system, W=W))


def _key(P: Polytope, W0) -> tuple:
    """Translation-invariant key of ``P`` and the identity of ``W0``."""
    c = P.vertices.mean(axis=0)
    w = ("ball", W0.dim, W0.radius) if isinstance(W0, Ball) else np.round(W0.vertices, 14).tobytes()
    return np.round(P.H, 12).tobytes(), np.round(P.h - P.H @ c, 12).tobytes(), w


def rho_max_bound(P: Polytope, W0) -> float:
    """A rigorous upper bound on ``max {rho : P ⊖ rho W0 != ∅}`` (tight to rounding).

    ``P ⊖ rho W0 = {c : H c <= h - rho sigma_{W0}(H)}``: the LP ``max rho`` over ``(c, rho)``
    (for a unit ball ``W0`` it is the Chebyshev radius). Its optimal dual ``y >= 0`` gives, for
    every feasible ``(c, rho)`` with ``c`` in ``P``'s bounding box (where ``P ⊖ rho W0``
    lies for ``rho >= 0``), ``rho s^T y <= h^T y - c^T H^T y``: the bound is computed from
    that inequality, so the LP's tolerances cannot make it too small. It is capped by the
    axis-width bound ``min_i width_i(P) / width_i(W0)``. Cached per cell shape up to
    translation.

    Returns
    -------
    float (> 0 for a full-dimensional ``P``)
    """
    known = _rho_max_by_cell.get(P)
    if known is not None and W0 in known:
        return known[W0]
    key = _key(P, W0)
    if key in _rho_max_cache:
        _rho_max_by_cell.setdefault(P, {})[W0] = _rho_max_cache[key]
        return _rho_max_cache[key]
    n = P.dim
    lo, hi = P.bounding_box()
    bound = float(np.min((hi - lo) / axis_widths(W0)))
    s = support(W0, P.H)
    cost = np.zeros(n + 1)
    cost[-1] = -1.0
    res = linprog(cost, A_ub=np.hstack([P.H, s[:, None]]), b_ub=P.h,
                  bounds=[(None, None)] * n + [(0.0, None)], method="highs")
    if res.status == 0:
        y = np.maximum(-np.asarray(res.ineqlin.marginals, float), 0.0)
        r = P.H.T @ y
        sy = float(s @ y)
        if sy > 0:
            num = float(P.h @ y + np.sum(np.maximum(-r * lo, -r * hi)))
            bound = min(bound, num / sy)
    bound = bound * (1.0 + 1e-12) + 1e-15                 # outward rounding
    _rho_max_cache[key] = bound
    _rho_max_by_cell.setdefault(P, {})[W0] = bound
    return bound


def zero_disturbance_system(system):
    """``system`` with ``W = {0}`` (the radius ``0``), every other part kept: where candidate pruning
    is sound for every radius."""
    return dataclasses.replace(system, W=scaled_disturbance(unit_disturbance(system.W)[0], 0.0))
