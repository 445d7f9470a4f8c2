"""The exact check of :func:`~tubejax.lp.evidence.check.exact_tube_violation` for many float tubes of
problems that share their shapes (translates: everything but the positions), in one pass: the row
families' residuals in rationals with a leading batch axis, each tube's largest row taken exactly
(:func:`row_max_batch`). Problems that do not share these shapes are checked one by one.
"""

from __future__ import annotations

import math
from fractions import Fraction
from typing import Sequence

import numpy as np

from ..declarations.tube_families import TubeVars, region_sets, tube_residuals
from .registry import formulation
from ..declarations.tube_operator_data import vertex_families
from .check import ExactTube, exact_terms, exact_tube_violation
from .exact_problem import exact_tube_data
from .rational import QArray

__all__ = ["exact_tube_violations", "translated_tube_violations", "row_max_batch", "rows_equal"]

#: Relative error bound of the float keys in :func:`row_max_batch` (a few ulps; generous).
_KEY_REL = 1e-12
#: Keys whose exponent leaves this range are not trusted (then the row maximum is taken exactly).
_KEY_RANGE = (1e-280, 1e280)


def row_max_batch(families: Sequence[tuple]) -> list:
    """``max_r values[k, r] / scale[r]`` exactly, for each ``k``.

    Parameters
    ----------
    families : sequence of ``(values, scale)``
        ``values`` a QArray of shape ``(K, ...)`` whose last axis is indexed by the row
        ``r``, ``scale`` an object-int array of shape ``(R,)`` (> 0).

    Returns
    -------
    list of Fraction, length K

    Notes
    -----
    Each entry gets a float key ``float(num) / float(scale * den)`` (three correctly rounded
    operations: relative error below ``4 u``). An entry that is the exact maximum has a key at
    least ``top - 2 * 4u (|top| + |key|)``, where ``top`` is the largest key; only entries
    within ``_KEY_REL`` of that are compared exactly. When some key is not finite, or a
    nonzero entry's key is outside ``_KEY_RANGE`` (rounding there is not relative), every
    entry of that ``k`` is compared exactly.
    """
    nums, dens, keys = [], [], []
    K = None
    for values, scale in families:
        num = values.num
        K = num.shape[0]
        num = num.reshape(K, -1, num.shape[-1]) if num.ndim > 1 else num.reshape(K, 1, 1)
        sc = np.asarray(scale, dtype=object)
        den = np.broadcast_to(sc * values.den, num.shape[1:]).reshape(-1)   # (R_f,) object ints
        num = num.reshape(K, -1)
        nums.append(num)
        dens.append(den)
        with np.errstate(all="ignore"):
            try:
                kf = num.astype(float) / den.astype(float)[None, :]
            except OverflowError:
                kf = np.full(num.shape, np.nan)
        keys.append(kf)
    num = np.concatenate(nums, axis=1)
    den = np.concatenate(dens)
    key = np.concatenate(keys, axis=1)
    a = np.abs(key)
    trusted = np.all(np.isfinite(key) & ((key == 0) | ((a > _KEY_RANGE[0]) & (a < _KEY_RANGE[1]))), axis=1)
    zero_ok = np.all((key != 0) | (num == 0), axis=1)           # a zero key means an exact zero
    top = np.max(np.where(np.isfinite(key), key, -np.inf), axis=1)
    cand = key >= (top - _KEY_REL * np.abs(top))[:, None] - _KEY_REL * a
    cand[~(trusted & zero_ok)] = True                       # untrusted keys: every row compared
    return _exact_max(num, den, cand)


def _exact_max(num: np.ndarray, den: np.ndarray, cand: np.ndarray) -> list:
    """``max_r num[k, r] / den[r]`` over the rows ``r`` with ``cand[k, r]``, exactly, for each ``k``
    (``num (K, R)``, ``den (R,)`` object ints; ``cand (K, R)`` bool with a row in each ``k``): the
    candidates brought to one denominator (rows of one family share theirs), then the largest
    numerator per ``k``."""
    if num.shape[0] == 0:
        return []
    ks, rs = np.nonzero(cand)                               # sorted by k
    D = 1
    for d in {int(d) for d in den[np.unique(rs)].tolist()}:
        D = D // math.gcd(D, d) * d
    fac = np.array([D // int(d) for d in den.tolist()], dtype=object)
    best = np.maximum.reduceat(num[ks, rs] * fac[rs], np.flatnonzero(np.r_[True, ks[1:] != ks[:-1]]))
    return [Fraction(int(v), D) for v in best.tolist()]


def _alike(p, p0) -> bool:
    """Whether ``p`` has ``p0``'s ``L``, system, ``Z``, ``eps_min`` and source vertex array shape."""
    return (int(p.L) == int(p0.L) and p.system is p0.system and p.eps_min == p0.eps_min
            and p.source.vertices.shape == p0.source.vertices.shape
            and (p.Z is p0.Z or np.array_equal(p.Z.vertices, p0.Z.vertices)))


def _shared(problems) -> bool:
    """Whether ``problems`` can be checked in one pass (equal shapes, system, ``Z``, ``eps_min``)."""
    return all(_alike(p, problems[0]) for p in problems[1:])


def _stack(tubes, *shapes):
    """``(p, eps, u)`` of ``tubes`` stacked on a leading axis as QArrays (float tubes at their
    exact values), or ``None`` when some part is not finite or has another shape."""
    if not any(formulation("tube").is_exact(t) for t in tubes):
        parts = [np.array([np.asarray(t[a], float) for t in tubes]) for a in range(3)]
        if any(x.shape[1:] != sh for x, sh in zip(parts, shapes)) or not all(np.all(np.isfinite(x)) for x in parts):
            return None
        return tuple(QArray.from_floats(x) for x in parts)
    try:
        ex = [ExactTube.coerce(t) for t in tubes]
    except (ValueError, TypeError):
        return None
    if any(tuple(q.shape) != sh for t in ex for q, sh in zip(t, shapes)):
        return None
    return tuple(QArray.concatenate([t[a][None] for t in ex], axis=0) for a in range(3))


def rows_equal(a: QArray, b: QArray) -> np.ndarray:
    """Exact elementwise equality of two QArrays, reduced over all axes but the first, ``(K,)``."""
    x, y, _ = a._common(b)
    eq = np.asarray(x == y, dtype=bool)
    return eq.reshape(eq.shape[0], -1).all(axis=1)


def _moving_regions(system) -> list:
    """The ``VertexIn`` regions whose sets move with the pair (``S``, ``P_j``)."""
    return [f.region for f in vertex_families(system) if f.moves_with_pair]


def _translated_sets(problems, d0, first):
    """``(V, h)`` of every problem (``V (K, n_v, n)``, ``h``: region -> ``(K, f)``), exact, derived
    from the exact data ``d0`` of the problem ``first`` when every problem's source and moving sets
    (``S``, ``P_j``) are ``first``'s moved by one exact offset ``c_k`` (the first source vertex's): then
    ``H x <= h + H c_k`` is the moved set, exactly. ``None`` when some problem is not such a
    translate (or shapes differ)."""
    regions = _moving_regions(problems[0].system)
    try:
        src = QArray.from_floats(np.array([p.source.vertices for p in problems]))
        moved = {r: QArray.from_floats(np.array([region_sets(p)[r].vertices for p in problems])) for r in regions}
        c = src[:, 0, :] - QArray.from_floats(np.asarray(first.source.vertices, float)[None, 0])   # (K, n) exact offsets
    except ValueError:                                     # ragged shapes, non-finite values
        return None
    for X, X0 in [(src, d0.V)] + [(moved[r], d0.sets[r].V) for r in regions]:
        if X.shape[1:] != X0.shape or not rows_equal(X, X0[None] + c[:, None, :]).all():
            return None
    return src, {r: d0.sets[r].h[None] + c @ QArray(d0.sets[r].H, 1).T for r in regions}


def exact_tube_violations(problems: Sequence, tubes: Sequence, reference=None) -> list:
    """:func:`~tubejax.lp.evidence.check.exact_tube_violation` of ``tubes[k]`` for ``problems[k]``.

    Parameters
    ----------
    problems : sequence of TubeProblem, length K
    tubes : sequence of Tube (floats, taken at their exact values) or ExactTube, length K
        (``p (L, n)``, ``eps (L,)``, ``u (L, n_v, m)``)
    reference : TubeProblem, optional
        The problem whose exact data the others' are derived from when they are its exact translates
        (default ``problems[0]``; e.g. a class representative whose data are already made); it is not
        checked itself.

    Returns
    -------
    list of Fraction, length K
        Each ``<= 0`` iff that tube is exactly feasible (errors as for one tube).
    """
    K = len(problems)
    if K == 0:
        return []
    first = problems[0] if reference is None else reference
    if (K == 1 and reference is None) or not _shared([first, *problems]):
        return [exact_tube_violation(p, t) for p, t in zip(problems, tubes)]
    d0 = exact_tube_data(first)
    sets = _translated_sets(problems, d0, first)
    if sets is None:
        data = [exact_tube_data(p) for p in problems]
        regions = _moving_regions(problems[0].system)
        for d in data:                  # equal facet normals of the moving sets (their offsets may differ)
            if not all(np.array_equal(d.sets[r].H, d0.sets[r].H) for r in regions):
                return [exact_tube_violation(p, t) for p, t in zip(problems, tubes)]
        sets = (QArray.concatenate([d.V[None] for d in data], axis=0),
                {r: QArray.concatenate([d.sets[r].h[None] for d in data], axis=0) for r in regions})
    V, h = sets                         # (K, nv, n), region -> (K, f)
    L, (nv, n), m = d0.L, d0.V.shape, d0.system.B.shape[1]
    stacked = _stack(tubes, (L, n), (L,), (L, nv, m))
    if stacked is None:
        return [exact_tube_violation(p, t) for p, t in zip(problems, tubes)]
    terms = exact_terms(d0, V, h)
    return row_max_batch([(r, sc) for _, r, sc in tube_residuals(terms, TubeVars(*stacked)) if r.num.size])


def _unit_moves_invariant(d0, tube: ExactTube, groups: np.ndarray, regions: list) -> Fraction | None:
    """The exact violation of ``tube`` for the exact data ``d0``, when moving the data (source
    vertices, the sets ``regions`` that move with the pair) and ``p_l`` by the unit translation of
    each group of axes leaves every family's exact residual (:func:`tube_residuals`) as it is;
    else ``None``."""
    n = d0.V.shape[1]
    moves = np.array([(groups == g).astype(float) for g in np.unique(groups[groups >= 0])]).reshape(-1, n)
    E = QArray.from_floats(np.vstack([np.zeros((1, n)), moves]))                    # (1 + G, n)
    V = d0.V[None] + E[:, None, :]
    h = {r: d0.sets[r].h[None] + E @ QArray(d0.sets[r].H, 1).T for r in regions}
    K = E.shape[0]
    x = TubeVars(tube.p[None] + E[:, None, :], QArray.concatenate([tube.eps[None]] * K, axis=0),
                 QArray.concatenate([tube.u[None]] * K, axis=0))
    res = [(r, sc) for _, r, sc in tube_residuals(exact_terms(d0, V, h), x) if r.num.size]
    if not all(rows_equal(r[1:], r[:1]).all() for r, _ in res):
        return None
    return row_max_batch([(r[:1], sc) for r, sc in res])[0]


def translated_tube_violations(canon, tube, problems: Sequence, shifts: np.ndarray, groups: np.ndarray) -> list:
    """The exact violation of ``tube`` moved by ``shifts[k]`` (``p_l -> p_l + shifts[k]``) for
    ``problems[k]``, from one exact check of ``tube`` for ``canon``; ``None`` where that does not
    apply (check that one as :func:`exact_tube_violations` does).

    The four exact conditions under which a member inherits ``canon``'s violation, and why, are in
    docs/math/evidence.md#the-exact-check-of-a-translated-tube; (4) is
    :func:`_unit_moves_invariant`, checked once for all members.

    Parameters
    ----------
    canon : TubeProblem
    tube : Tube or ExactTube
        ``(p (L, n), eps (L,), u (L, n_v, m))``, taken at its exact values.
    problems : sequence of TubeProblem, length K
    shifts : ndarray, shape (K, n)
    groups : ndarray of int, shape (n,)
        ``-1`` for an axis that does not move, else its group's first axis
        (:func:`~tubejax.lp.declarations.tube_families.translation_groups`).

    Returns
    -------
    list of Fraction or None, length K
    """
    K = len(problems)
    out: list = [None] * K
    groups = np.asarray(groups, dtype=np.int64)
    shifts = np.asarray(shifts, dtype=float).reshape(K, -1)
    first = np.where(groups >= 0, groups, 0)
    ok = (np.array([_alike(p, canon) for p in problems], dtype=bool) & np.all(np.isfinite(shifts), axis=1)
          & np.all(np.where(groups >= 0, shifts == shifts[:, first], shifts == 0), axis=1))
    try:
        d0 = exact_tube_data(canon)
        t = ExactTube.coerce(tube)
        regions = _moving_regions(canon.system)
        moving = [(d0.V, lambda p: p.source.vertices)] + \
            [(d0.sets[r].V, lambda p, r=r: region_sets(p)[r].vertices) for r in regions]
        for X0, get in moving:
            ok &= np.array([np.shape(get(p)) == tuple(X0.shape) for p in problems], dtype=bool)
        ks = np.flatnonzero(ok)
        if ks.size == 0 or tuple(t.p.shape) != (d0.L, d0.V.shape[1]) or tuple(t.eps.shape) != (d0.L,) \
                or tuple(t.u.shape) != (d0.L, d0.V.shape[0], d0.system.B.shape[1]):
            return out
        c = QArray.from_floats(shifts[ks])                                             # exact offsets
        for X0, get in moving:
            X = QArray.from_floats(np.array([get(problems[k]) for k in ks]))
            ok[ks] &= rows_equal(X, X0[None] + c[:, None, :])
        viol = _unit_moves_invariant(d0, t, groups, regions) if ok.any() else None
    except (ValueError, ArithmeticError):              # non-finite data, degenerate sets
        return out
    if viol is None:
        return out
    return [viol if ok[k] else None for k in range(K)]
