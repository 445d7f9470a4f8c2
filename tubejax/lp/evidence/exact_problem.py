"""The rational data of one tube problem, built from a TubeProblem (docs/math/problem-data.md,
docs/math/tube-lp.md, docs/math/open-loop.md; the two rules are :mod:`tubejax.lp.evidence.rational`'s).

``A``, ``B``, ``eps_min``, a ball's radius and the state constraint's rows are the decimals as
typed; ``U``, a polytope ``W``, ``P_j``, ``S`` (``prob.safe``) and ``Z`` are exact hulls of their
decimal or exact float vertices; a ball's ``sigma_W`` is rounded up. ``prob.safe`` lists a subset of
the cells' vertices, so its exact hull is never larger than the set docs/math/tube-lp.md names: a
proof against it is sound. Facets keep the float H-rep's order when verified
(:func:`in_float_order`); geometry-only data are cached by the bytes of the float data.
"""

from __future__ import annotations

import json
from fractions import Fraction
from typing import NamedTuple

import numpy as np

from ..declarations.tube_families import region_sets, system_regions
from ...model.geometry import Ball, Halfspaces
from .exact_boxes import boxes_hull_in_order, exact_box
from .exact_geometry import (ExactGeometryError, ExactPolytope, exact_halfspaces, exact_hull, exact_hull_in_order,
                             exact_support)
from .rational import QArray, decimal_rational, sqrt_lower, sqrt_upper

__all__ = ["ExactSystem", "ExactTubeData", "exact_system", "exact_tube_data", "exact_polytope", "exact_safe_set",
           "in_float_order", "clear_caches", "ExactBall", "exact_disturbance", "disturbance_support_upper"]

_CACHE: dict = {}
_CACHE_LIMIT = 50_000


def clear_caches() -> None:
    """Forget every cached rationalisation."""
    _CACHE.clear()


def _cached(key, make):
    v = _CACHE.get(key)
    if v is None:
        if len(_CACHE) >= _CACHE_LIMIT:
            _CACHE.clear()
        v = _CACHE[key] = make()
    return v


def _fkey(a) -> tuple:
    a = np.ascontiguousarray(a, dtype=float)
    return a.shape, a.tobytes()


def _pkey(P) -> tuple:
    """Cache key of a float Polytope's data (vertices and H-rep: the exact facets' order)."""
    return _fkey(P.vertices) + _fkey(P.H) + _fkey(P.h)


def _polytope_entry(P, decimals: bool = False, hull_of: tuple = ()) -> tuple[ExactPolytope, bool]:
    """``(co(V) exactly, whether its facets are P's float rows row for row)``; cached.

    ``V``: ``P``'s vertices as exact floats, or by the decimal rule (``decimals``). The facets are
    :func:`exact_hull_in_order`'s when it verifies ``P``'s rows, else :func:`exact_hull`'s. A box, or
    the hull of the two boxes ``hull_of`` names, in ``R^3`` and up, tries :func:`boxes_hull_in_order` first."""
    if isinstance(P, Halfspaces):
        return _cached(("halfspaces",) + _fkey(P.H) + _fkey(P.h),
                       lambda: (exact_halfspaces(QArray.from_decimals(P.H), QArray.from_decimals(P.h)), True))

    def make():
        V = QArray.from_decimals(P.vertices) if decimals else QArray.from_floats(P.vertices)
        boxes = (_boxes(hull_of) or ([exact_box(V)] if P.is_box else [])) if P.dim >= 3 else []   # 1-D, 2-D: no ridge walk
        fast = boxes_hull_in_order(V, P.H, P.h, boxes) if boxes else None
        if fast is not None:
            return fast, True
        try:
            return exact_hull_in_order(V, P.H, P.h), True
        except ExactGeometryError:
            return exact_hull(V), False

    return _cached(("poly", decimals) + _pkey(P), make)


def _boxes(polytopes: tuple) -> list:
    """The exact bounding boxes of ``polytopes`` (of their exact float vertices), ``[]`` unless
    there are some and each is a box (:attr:`~tubejax.model.geometry.Polytope.is_box`)."""
    if not polytopes or not all(getattr(Q, "is_box", False) for Q in polytopes):
        return []
    return [exact_box(QArray.from_floats(Q.vertices)) for Q in polytopes]


def exact_safe_set(prob) -> ExactPolytope:
    """:func:`exact_polytope` ``(prob.safe)``; in the free case (``prob.safe`` is not
    ``prob.source``) of two boxes, by :mod:`~tubejax.lp.evidence.exact_boxes` when it applies."""
    return _polytope_entry(prob.safe, hull_of=() if prob.safe is prob.source else (prob.source, prob.target))[0]


def exact_polytope(P) -> ExactPolytope:
    """The exact set of a :class:`~tubejax.model.geometry.Polytope` or ``Halfspaces`` (cached).

    Polytope: ``co(V)`` of its float vertices (exact values), exactly, its facets in the float
    H-rep's order when :func:`in_float_order` (else the exact hull's own). Halfspaces: its rows
    as given (decimal rule, no vertices).

    Raises
    ------
    ExactGeometryError
        When ``co(V)``'s exact facets cannot be established.
    """
    return _polytope_entry(P)[0]


def in_float_order(P, decimals: bool = False) -> bool:
    """Whether the exact facets of ``P`` are its float rows ``P.H``, row for row (Halfspaces: always).

    Parameters
    ----------
    P : Polytope or Halfspaces
    decimals : bool
        ``False``: of :func:`exact_polytope` ``(P)``; ``True``: of the exact polytope of ``P``'s
        vertices by the decimal rule (``P`` a system's ``U``: :func:`exact_system`'s ``U``).
    """
    return _polytope_entry(P, decimals)[1]


class ExactBall(NamedTuple):
    """``{w : ||w||_2 <= radius}`` with a rational radius."""

    dim: int
    radius: Fraction


def exact_disturbance(W):
    """The rational disturbance set of a :class:`~tubejax.model.geometry.Ball` or ``Polytope``.

    Ball: radius by :func:`decimal_rational`; polytope: vertices by
    :func:`decimal_rational` (both are typed data, docs/math/problem-data.md).
    """
    if isinstance(W, Ball):
        return ExactBall(int(W.dim), decimal_rational(W.radius))
    return exact_hull(QArray.from_decimals(W.vertices))


def disturbance_support_upper(W, a, upper: bool = True) -> QArray:
    """A rational upper bound of ``sigma_W(a_f)`` per row, shape ``(n_f,)``.

    Polytope ``W``: exact. Ball: ``r ||a_f||_2`` rounded up (:func:`sqrt_upper`), exact
    when the norm is rational.

    Parameters
    ----------
    W : ExactBall or ExactPolytope
    a : QArray or array of Fractions / ints, shape (n_f, n)
    upper : bool
        ``False``: a rational *lower* bound instead (ball: ``r ||a_f||_2`` rounded down,
        :func:`sqrt_lower`), for the relaxed problem a certificate of infeasibility refutes.
    """
    A = QArray.coerce(a)
    if isinstance(W, ExactBall):
        sq = [sum(v * v for v in row) for row in A.num.tolist()]
        root = sqrt_upper if upper else sqrt_lower
        vals = [W.radius * root(Fraction(s)) / A.den for s in sq]
        return QArray.from_fractions(np.array(vals, dtype=object)) if vals else \
            QArray(np.zeros(0, dtype=object))
    return exact_support(W, A)


class ExactSystem(NamedTuple):
    """Rational ``A (n, n)``, ``B (n, m)`` (QArrays), ``U`` (ExactPolytope) and ``W``
    (ExactBall or ExactPolytope).

    ``U`` is exactly the hull of the decimal vertices, its facets in ``system.U``'s float order
    when ``in_float_order(system.U, decimals=True)``."""

    A: QArray
    B: QArray
    U: ExactPolytope
    W: object


def _w_key(W) -> tuple:
    if isinstance(W, Ball):
        return ("ball", int(W.dim), float(W.radius))
    return ("poly",) + _fkey(W.vertices)


def exact_system(system) -> ExactSystem:
    """The rational data of a :class:`~tubejax.model.system.LinearSystem` (decimal rule; cached)."""
    # every recorded field, so never a stale system; U's H-rep too (the order of U's facets)
    key = ("sys", json.dumps(system.record())) + _pkey(system.U)

    def make():
        return ExactSystem(QArray.from_decimals(system.A), QArray.from_decimals(system.B),
                           _polytope_entry(system.U, decimals=True)[0], exact_disturbance(system.W))

    return _cached(key, make)


class ExactTubeData(NamedTuple):
    """Everything :func:`~tubejax.lp.evidence.check.exact_tube_violation` needs, exact.

    Attributes
    ----------
    system : ExactSystem
    L : int
    V : QArray, shape (n_v, n)        source vertices ``v_{i,k}`` (canonical order)
    Z : ExactPolytope                 ``Z``; ``Z.V[k]`` is paired with ``V[k]``
    sigma_w : QArray, shape (n_fz,)   upper bound of ``sigma_W(H_z)`` (exact unless a ball)
    sets : dict of str to ExactPolytope
        Every set the problem declares but ``U`` (in ``system``), by name (``'safe'``: ``S``,
        ``'target'``: ``P_j``, the state constraints): the keys of ``region_sets(prob)``
    eps_min : Fraction
    regions : frozenset of str
        The sets the problem's system declares (:func:`~tubejax.lp.declarations.tube_families.system_regions`)
    """

    system: ExactSystem
    L: int
    V: QArray
    Z: ExactPolytope
    sigma_w: QArray
    sets: dict
    eps_min: Fraction
    regions: frozenset

    @property
    def safe(self) -> ExactPolytope:
        return self.sets["safe"]

    @property
    def target(self) -> ExactPolytope:
        return self.sets["target"]


def exact_tube_data(prob) -> ExactTubeData:
    """The rational data of a :class:`~tubejax.model.problem.TubeProblem` (see the module doc).

    Raises
    ------
    ExactGeometryError
        When a polytope's exact facets cannot be established.
    """
    sysx = exact_system(prob.system)
    Z = exact_polytope(prob.Z)
    sig = _cached(("sigw",) + _pkey(prob.Z) + _w_key(prob.system.W),
                  lambda: disturbance_support_upper(sysx.W, Z.H))
    V = _cached(("verts",) + _fkey(prob.source.vertices),
                lambda: QArray.from_floats(prob.source.vertices))
    sets = {r: exact_safe_set(prob) if r == "safe" else exact_polytope(P)
            for r, P in region_sets(prob).items() if r != "input"}                        # U: sysx.U (decimals)
    return ExactTubeData(sysx, int(prob.L), V, Z, sig, sets, decimal_rational(prob.eps_min),
                         system_regions(prob.system))
