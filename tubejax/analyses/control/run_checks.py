"""Host checks of simulated runs: which states break the guarantee, as per-run flags
(docs/math/control.md#closed-loop-simulation).

:func:`~tubejax.analyses.control.closed_loop.rollout` returns data-dependent failures as arrays
(never exceptions inside ``jit``); the host turns them into flags for obstacle entries, tube exits
(beyond ``tol``), missed targets and each state constraint
(:mod:`~tubejax.analyses.control.state_monitor`). Each check is per state, so checking the runs
in chunks never changes a result.
"""

from __future__ import annotations

import numpy as np
import shapely

from ...model.geometry import Polytope
from .state_monitor import count_outside_state_constraints

__all__ = ["in_obstacle_interior", "in_cells"]


def _violation(P: Polytope, X: np.ndarray) -> np.ndarray:
    """``max(H x - h)`` of ``P`` for float64 points ``X (..., n)``, facet by facet in elementwise
    float64 (as :meth:`Polytope.violation`, without a stacked matmul: many points, few facets)."""
    H, h = P.H, P.h
    out = None
    for f in range(len(h)):
        v = X[..., 0] * H[f, 0]
        for j in range(1, X.shape[-1]):
            v += X[..., j] * H[f, j]
        v -= h[f]
        out = v if out is None else np.maximum(out, v, out=out)
    return out


def in_cells(decomp, X, tol: float = 1e-9, cells=None, first=()) -> np.ndarray:
    """Whether points lie in any of ``cells`` (default: all), up to ``tol``. ``X (..., n)`` -> ``(...)``.

    The cells in ``first`` (those most points lie in, e.g. a plan's) are tried first, and each
    further cell only on the points no cell has taken yet: the same answer as trying every cell
    on every point, at a cost that hardly grows with the number of cells.
    """
    X = np.asarray(X, float)
    shape = X.shape[:-1]
    ids = list(range(decomp.n_cells) if cells is None else cells)
    if len(first):
        allowed = set(ids)
        head = [i for i in dict.fromkeys(int(c) for c in first) if i in allowed]
        seen = set(head)
        ids = head + [i for i in ids if i not in seen]
    pts = X.reshape(-1, X.shape[-1])
    out = np.zeros(len(pts), bool)
    todo = np.arange(len(pts))
    for i in ids:
        if not todo.size:
            break
        inside = _violation(decomp.cells[i], pts if todo.size == len(pts) else pts[todo]) <= tol
        out[todo[inside]] = True
        todo = todo[~inside]
    return out.reshape(shape)


def in_obstacle_interior(decomp, X, tol: float = 1e-9) -> np.ndarray:
    """Whether points lie in ``int O``: strictly inside an obstacle and in no cell up to ``tol``.

    Parameters
    ----------
    decomp : CellDecomposition
    X : array, shape (..., n)

    Returns
    -------
    ndarray of bool, shape (...)
    """
    X = np.asarray(X, float)
    hit = np.zeros(X.shape[:-1], bool)
    for o in decomp.obstacles:
        if isinstance(o, Polytope):
            hit |= _violation(o, X) < -tol
        else:
            if X.shape[-1] != 2:
                raise ValueError("shapely obstacles need 2-D states")
            hit |= shapely.contains_xy(o, X[..., 0], X[..., 1])
    if hit.any():                              # only the points inside an obstacle need the cells
        hit[hit] = ~in_cells(decomp, X[hit], tol)
    return hit


def _first_true(F):
    """Index of the first True along the last axis, ``-1`` if none."""
    return np.where(F.any(-1), np.argmax(F, axis=-1), -1)


def _check_runs(decomp, plan, X, viol, tol: float, constraints=None) -> dict:
    """The per-state host checks of some runs (``X (runs, S+1, n)``, ``viol (runs, S+1)``) as per-run arrays;
    ``constraints`` (``{name: Halfspaces}``) adds ``outside_<name>``, states outside it per run."""
    obst = in_obstacle_interior(decomp, X)
    exits = ~(viol <= tol)                   # a NaN state is an exit too
    if getattr(decomp, "domain", None) is not None:       # a convex workspace (a box grid's box)
        ws_exit = ~(_violation(decomp.domain, X) <= 1e-9)
    else:
        ws_exit = ~in_cells(decomp, X, 1e-9, first=plan.cells) & ~obst
    times = plan.segment_times
    reached = np.stack([in_cells(decomp, X[:, t], 1e-9, plan.target_cells[k])
                        for k, t in enumerate(times)], axis=1) if times else np.ones((len(X), 0), bool)
    outside = {f"outside_{k}": c for k, c in count_outside_state_constraints(constraints or {}, X, tol).items()}
    return dict(obstacle_entry=obst.any(1), first_obstacle_time=_first_true(obst), tube_exit=exits.any(1),
                first_exit_time=_first_true(exits), targets_reached=reached, workspace_exit=ws_exit.any(1),
                **outside)
