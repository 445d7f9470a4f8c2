"""The rational data of one tube problem, built from a TubeProblem (docs/math/problem-data.md,
docs/math/tube-lp.md, docs/math/open-loop.md).

What is exact and how (see :mod:`tubejax.lp.evidence.rational` for the two rules):

========================  =============================  ============================
datum                     rational value                 facets
========================  =============================  ============================
``A``, ``B``              decimal (as typed)             --
``U``                     decimal vertices               exact hull of them
``W`` ball                decimal radius                 ``sigma_W`` rounded up
``W`` polytope / box      decimal vertices               exact hull of them
``eps_min``               decimal                        --
source ``P_i``            exact float vertices (paired   --
                          with ``Z`` by index)
target ``P_j``            exact float vertices           exact hull of them
safe set ``S``            exact float vertices of        exact hull of them
                          ``prob.safe``
state constraint          --                             decimal rows and offsets
(``system.X``)                                           (primitive integer rows)
``Z``                     exact float vertices           exact hull of them
========================  =============================  ============================

``prob.safe`` (``P_ij`` or ``P_i``) lists a subset of the cells' vertices, so its exact
hull is never larger than the set docs/math/tube-lp.md names: a proof against it is sound.

Everything that depends only on the geometry (facets, ``sigma_W`` of ``Z``'s facets)
is cached by the bytes of the float data, so the cells shared by many edges, and
problems unpickled in a helper process, are rationalised once.
"""

from __future__ import annotations

import json
from fractions import Fraction
from typing import NamedTuple

import numpy as np

from ..formulations.tube.families import region_sets
from ..formulations.tube.operator_data import vertex_families
from ...model.geometry import Ball, Halfspaces
from .geometry import ExactPolytope, disturbance_support_upper, exact_disturbance, exact_halfspaces, exact_hull
from .rational import QArray, decimal_rational

__all__ = ["ExactSystem", "ExactTubeData", "exact_system", "exact_tube_data", "exact_polytope",
           "clear_caches"]

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


def exact_polytope(P) -> ExactPolytope:
    """Exact hull of a :class:`~tubejax.model.geometry.Polytope`'s float vertices (exact values), or the
    exact rows of a :class:`~tubejax.model.geometry.Halfspaces` (decimal rule, no vertices); cached."""
    if isinstance(P, Halfspaces):
        return _cached(("halfspaces",) + _fkey(P.H) + _fkey(P.h),
                       lambda: exact_halfspaces(QArray.from_decimals(P.H), QArray.from_decimals(P.h)))
    return _cached(("poly",) + _fkey(P.vertices), lambda: exact_hull(QArray.from_floats(P.vertices)))


class ExactSystem(NamedTuple):
    """Rational ``A (n, n)``, ``B (n, m)`` (QArrays), ``U`` (ExactPolytope) and ``W``
    (ExactBall or ExactPolytope), with ``U``'s exact bounding box ``u_lo, u_hi`` (lists)."""

    A: QArray
    B: QArray
    U: ExactPolytope
    W: object
    u_lo: list
    u_hi: list


def _w_key(W) -> tuple:
    if isinstance(W, Ball):
        return ("ball", int(W.dim), float(W.radius))
    return ("poly",) + _fkey(W.vertices)


def exact_system(system) -> ExactSystem:
    """The rational data of a :class:`~tubejax.model.system.LinearSystem` (decimal rule; cached)."""
    key = ("sys", json.dumps(system.record()))          # every recorded field, so never a stale system

    def make():
        U = exact_hull(QArray.from_decimals(system.U.vertices))
        lo, hi = U.bbox()
        return ExactSystem(QArray.from_decimals(system.A), QArray.from_decimals(system.B), U,
                           exact_disturbance(system.W), lo, hi)

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
        The set of every ``VertexIn`` family's region, by name (``'safe'``: ``S``, ``'target'``: ``P_j``)
    eps_min : Fraction
    """

    system: ExactSystem
    L: int
    V: QArray
    Z: ExactPolytope
    sigma_w: QArray
    sets: dict
    eps_min: Fraction

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
    sig = _cached(("sigw",) + _fkey(prob.Z.vertices) + _w_key(prob.system.W),
                  lambda: disturbance_support_upper(sysx.W, Z.H))
    V = _cached(("verts",) + _fkey(prob.source.vertices),
                lambda: QArray.from_floats(prob.source.vertices))
    given = region_sets(prob)
    sets = {f.region: exact_polytope(given[f.region]) for f in vertex_families(prob.system)}
    return ExactTubeData(sysx, int(prob.L), V, Z, sig, sets, decimal_rational(prob.eps_min))
