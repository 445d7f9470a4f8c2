"""The step functions ``n(rho)`` of the radius analysis: how many values reach each radius.

``n_edges(rho)``, the number of edges at the radius ``rho``, is the number of pairs whose
critical disturbance is at least ``rho``
(:meth:`~tubejax.analyses.radius_analysis.radius_table.RadiusTable.n_edges`): :func:`step_function`
turns such values into a :class:`StepFunction`, values closer than :data:`RHO_STEP_TOL`
counting as one breakpoint.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["RHO_STEP_TOL", "StepFunction", "step_function"]


#: HiGHS's ``rho*`` is exact to its tolerances (about ``1e-10`` on unit rows), and its verdicts
#: accept a tube within ``1e-9``: values this close (relative to ``max(1, |rho|)``) are one
#: breakpoint of a :class:`StepFunction`, and a value this close below a radius reaches it.
RHO_STEP_TOL = 1e-9


class StepFunction(NamedTuple):
    """``n(rho) = #{values >= rho}`` for ``rho >= 0``: a non-increasing step function.

    Attributes
    ----------
    rho : ndarray, shape (m,)
        The breakpoints, ascending: ``n`` drops just after each. Values closer than
        :data:`RHO_STEP_TOL` are one breakpoint, their largest.
    n : ndarray of int, shape (m,)
        ``n[k] = n(rho)`` on ``(rho[k-1], rho[k]]`` (on ``[0, rho[0]]`` for ``k = 0``);
        ``n(rho) = 0`` beyond ``rho[-1]``.
    """

    rho: np.ndarray
    n: np.ndarray

    def __call__(self, r) -> np.ndarray:
        """``n`` at the radii ``r`` (any shape); a breakpoint within :data:`RHO_STEP_TOL` below
        ``r`` still counts (at such a tie the verified system at ``r`` is the authority)."""
        r = np.asarray(r, float)
        k = np.searchsorted(self.rho, r - RHO_STEP_TOL * np.maximum(1.0, np.abs(r)), side="left")
        return np.append(self.n, 0)[np.minimum(k, len(self.n))]


def step_function(values) -> StepFunction:
    """The :class:`StepFunction` of ``values``: values within :data:`RHO_STEP_TOL` below ``0``
    count as ``0`` (an optimum of ``0`` computed as ``-1e-16``), lower and non-finite values never."""
    v = np.asarray(values, float)
    v = np.sort(np.maximum(v[np.isfinite(v) & (v >= -RHO_STEP_TOL)], 0.0))
    if not v.size:
        return StepFunction(np.zeros(0), np.zeros(0, dtype=int))
    new = np.diff(v) > RHO_STEP_TOL * np.maximum(1.0, np.abs(v[1:]))
    start = np.flatnonzero(np.concatenate([[True], new]))          # first value of each cluster
    last = np.append(start[1:], len(v)) - 1
    return StepFunction(v[last], (len(v) - start).astype(int))
