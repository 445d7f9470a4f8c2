"""The closed-loop monitor of the system's state constraints (``system.state_constraints``).

The tube LP proves every tube set inside every ``X = {x : H x <= h}``, so a simulated state outside
one means the guarantee was broken (or something unproven was simulated). A state is *outside* when
:meth:`~tubejax.model.geometry.Halfspaces.violation` is not ``<= tol`` (the tube exits' rule: the
boundary is inside, NaN outside). Generic over
:attr:`~tubejax.model.system.LinearSystem.state_constraints`.
"""

from __future__ import annotations

import numpy as np

from ...model.geometry import Halfspaces

__all__ = ["state_constraint_violation", "outside_state_constraint", "count_outside_state_constraints"]


def state_constraint_violation(S: Halfspaces, X) -> np.ndarray:
    """The distance of points outside ``S``: ``max_i (H_i x - h_i) / ||H_i||`` (``<= 0`` inside).

    (:meth:`Halfspaces.violation`, with the dimension checked).

    Parameters
    ----------
    S : Halfspaces
        ``{x : H x <= h}`` in ``R^n``, ``H (f, n)``, ``h (f,)``.
    X : array_like, shape (..., n)

    Returns
    -------
    ndarray of float64, shape (...)
    """
    X = np.asarray(X, dtype=np.float64)
    if X.shape[-1] != S.dim:
        raise ValueError(f"{S.name}: points in R^{X.shape[-1]}, the constraint is in R^{S.dim}")
    return S.violation(X)


def outside_state_constraint(S: Halfspaces, X, tol: float = 1e-9) -> np.ndarray:
    """Whether points lie outside ``S``: ``not (violation <= tol)`` (a NaN point is outside).

    Parameters
    ----------
    S : Halfspaces
    X : array_like, shape (..., n)
    tol : float
        Distance outside still counted as inside (the simulation's tube-exit tolerance).

    Returns
    -------
    ndarray of bool, shape (...)
    """
    return ~(state_constraint_violation(S, X) <= tol)


def count_outside_state_constraints(constraints: dict, X, tol: float = 1e-9) -> dict:
    """Per state constraint, how many states of each run lie outside it.

    Parameters
    ----------
    constraints : dict
        ``{name: Halfspaces}``, e.g. ``system.state_constraints`` (may be empty).
    X : array_like, shape (runs, T, n)
        The states of each run (every step, the initial state included).
    tol : float
        As in :func:`outside_state_constraint`.

    Returns
    -------
    dict
        ``{name: ndarray of int64, shape (runs,)}`` in the order of ``constraints``.
    """
    X = np.asarray(X, dtype=np.float64)
    if X.ndim != 3:
        raise ValueError(f"expected states of shape (runs, T, n), got {X.shape}")
    return {name: np.count_nonzero(outside_state_constraint(S, X, tol), axis=1).astype(np.int64)
            for name, S in constraints.items()}
