"""Exact re-checks of stored evidence (docs/math/evidence.md#proof-levels).

:func:`exact_tube_violation` checks a tube against Problem 2 as docs/math/tube-lp.md writes it (the
per-vertex rows of :mod:`tubejax.lp.declarations.tube_families`) in rationals against the data of
:mod:`tubejax.lp.evidence.exact_problem`; :func:`exact_openloop_violation` does the same for an
open-loop plan. No float H-rep is used. Each row is reported per max-norm unit,
``(a . x - b) / max_i |a_i|``, so the maximum is ``<= 0`` exactly when every constraint holds.
"""

from __future__ import annotations

from fractions import Fraction
from typing import NamedTuple

import numpy as np

from ..declarations.openloop_lp import OpenLoopPlan
from ..declarations.openloop_families import PlanTerms, PlanVars, disturbance_sums, plan_residuals
from ..declarations.tube_variables import Tube
from ..declarations.tube_families import TubeTerms, TubeVars, system_regions, tube_residuals
from ..declarations.row_families import SetRows
from .exact_problem import (_cached, _fkey, _w_key, disturbance_support_upper, exact_polytope, exact_safe_set,
                            exact_system, exact_tube_data)
from .rational import QArray, row_max

__all__ = ["ExactTube", "ExactPlan", "exact_tube_violation", "exact_openloop_violation", "exact_terms",
           "exact_plan_terms", "openloop_support_upper"]


class ExactTube(NamedTuple):
    """A tube in rationals: ``p (L, n)``, ``eps (L,)``, ``u (L, n_v, m)``, each a QArray."""

    p: QArray
    eps: QArray
    u: QArray

    def to_float(self):
        """The nearest float64 :class:`~tubejax.lp.declarations.tube_variables.Tube`."""
        return Tube(self.p.to_float(), self.eps.to_float(), self.u.to_float())

    @classmethod
    def coerce(cls, tube) -> "ExactTube":
        """From a float ``Tube`` (exact values), an ExactTube, or arrays of Fractions."""
        if isinstance(tube, ExactTube):
            return tube
        p, eps, u = tube
        return cls(QArray.coerce(p), QArray.coerce(eps), QArray.coerce(u))


class ExactPlan(NamedTuple):
    """An open-loop plan in rationals: ``u (L, n_v, m)`` (QArray)."""

    u: QArray

    def to_float(self):
        return OpenLoopPlan(self.u.to_float())

    @classmethod
    def coerce(cls, plan) -> "ExactPlan":
        if isinstance(plan, ExactPlan):
            return plan
        u = plan.u if hasattr(plan, "u") else plan
        return cls(QArray.coerce(u))


def _check_shape(name: str, a: QArray, shape: tuple) -> None:
    if tuple(a.shape) != tuple(shape):
        raise ValueError(f"{name} has shape {tuple(a.shape)}, expected {tuple(shape)}")


def exact_tube_violation(prob, tube) -> Fraction:
    """Largest exact violation of C1-C5 (docs/math/tube-lp.md) by ``tube``.

    Parameters
    ----------
    prob : TubeProblem
    tube : Tube (floats, taken at their exact values), ExactTube, or arrays of Fractions
        ``p`` of shape ``(L, n)``, ``eps`` ``(L,)``, ``u`` ``(L, n_v, m)``.

    Returns
    -------
    Fraction
        ``max`` over every row of ``(a . x - b) / max|a|``; ``<= 0`` iff the tube is
        exactly feasible for the rational problem (a ball ``W``'s ``sigma_W`` is rounded
        up, so ``<= 0`` stays a proof).

    Raises
    ------
    ValueError
        For wrong shapes or non-finite values (naming the array).
    ExactGeometryError
        When a polytope's exact facets cannot be established.
    """
    d = exact_tube_data(prob)
    L, (nv, n), m = d.L, d.V.shape, d.system.B.shape[1]
    t = ExactTube.coerce(tube)
    _check_shape("tube p", t.p, (L, n))
    _check_shape("tube eps", t.eps, (L,))
    _check_shape("tube u", t.u, (L, nv, m))
    return max(row_max(r, sc) for _, r, sc in tube_residuals(exact_terms(d), TubeVars(*t)))


def exact_terms(d, V=None, h=None) -> TubeTerms:
    """:class:`~tubejax.lp.declarations.tube_families.TubeTerms` of exact tube data, in rationals.

    Parameters
    ----------
    d : ExactTubeData
    V : QArray, shape (K, n_v, n), optional
        Source vertices of a batch of translated problems (default ``d.V``).
    h : dict of str to QArray (K, f), optional
        Their offsets of the sets that move with the pair (default ``d``'s).
    """
    h = h or {}

    def rows(P, name):
        return SetRows(QArray(P.H), h.get(name, P.h), P.scale)

    sysx = d.system
    sets = {name: rows(P, name) for name, P in d.sets.items()}
    sets["input"] = rows(sysx.U, "input")
    return TubeTerms(d.L, d.V if V is None else V, d.Z.V, sysx.A, sysx.B, rows(d.Z, "Z"), d.sigma_w, sets,
                     QArray.from_fractions([d.eps_min]), QArray.concatenate, d.regions)


def openloop_support_upper(prob, P, L: int, upper: bool = True) -> QArray:
    """Upper bounds of ``sigma_{D_l}(H_P)`` for ``l = 0..L``, shape ``(L + 1, n_f)``.

    ``sigma_{D_l}(a) = sum_{t<l} sigma_W((A^t)^T a)``
    (:func:`~tubejax.lp.declarations.openloop_families.disturbance_sums`), each term by
    :func:`~tubejax.lp.evidence.exact_problem.disturbance_support_upper` (exact for a polytope ``W``).

    Parameters
    ----------
    prob : TubeProblem (its system)
    P : ExactPolytope
    L : int
    upper : bool
        ``False``: lower bounds instead (the relaxed problem of a certificate of infeasibility).
    """
    sysx = exact_system(prob.system)

    def make():
        return disturbance_sums(QArray(P.H), sysx.A, L, lambda rows: disturbance_support_upper(sysx.W, rows, upper),
                                QArray(np.zeros(P.H.shape[0], dtype=object), 1),
                                lambda acc: QArray.concatenate([a[None] for a in acc], axis=0), QArray.reduced)

    key = ("olsig",) + _fkey(prob.system.A) + _w_key(prob.system.W) + \
        (P.H.shape, tuple(P.H.ravel().tolist()), int(L), bool(upper))
    return _cached(key, make)


def exact_plan_terms(prob, upper: bool = True) -> PlanTerms:
    """:class:`~tubejax.lp.declarations.openloop_families.PlanTerms` of ``prob`` in rationals.

    Parameters
    ----------
    prob : TubeProblem (``Z`` and ``eps_min`` are ignored)
    upper : bool
        ``sigma_{D_l}`` rounded up (a proof), or down (the relaxed rows of a certificate).

    Each set's facets are in its float H-rep's order when
    :func:`~tubejax.lp.evidence.exact_problem.in_float_order` (the float LP's rows), else the exact
    hull's; either way exactly the set.
    """
    sysx = exact_system(prob.system)
    L = int(prob.L)
    V = _cached(("verts",) + _fkey(prob.source.vertices), lambda: QArray.from_floats(prob.source.vertices))
    polys = {"safe": exact_safe_set(prob), "target": exact_polytope(prob.target), "input": sysx.U}
    sets = {r: SetRows(QArray(P.H), P.h, P.scale) for r, P in polys.items()}
    sig = {r: openloop_support_upper(prob, polys[r], L, upper) for r in ("safe", "target")}
    return PlanTerms(L, V, sysx.A, sysx.B, sets, sig, QArray.concatenate, system_regions(prob.system))


def exact_openloop_violation(prob, plan) -> Fraction:
    """Largest exact violation of the open-loop constraints (docs/math/open-loop.md) by ``plan``: the
    residuals of :func:`~tubejax.lp.declarations.openloop_families.plan_residuals` in rationals, with
    ``sigma_D`` rounded up.

    Parameters
    ----------
    prob : TubeProblem (``Z`` and ``eps_min`` are ignored)
    plan : OpenLoopPlan, ExactPlan, or an array of shape ``(L, n_v, m)``

    Returns
    -------
    Fraction
        ``<= 0`` iff the plan is exactly feasible (max-norm unit rows).
    """
    d = exact_plan_terms(prob)
    u = ExactPlan.coerce(plan).u
    _check_shape("plan u", u, (d.L, d.V.shape[0], d.B.shape[1]))
    return max(row_max(r, sc) for _, r, sc in plan_residuals(d, PlanVars(u)))
