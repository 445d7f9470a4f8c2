"""An exact (rational) bounded primal simplex for the margin LP's sign: the last resort of
:mod:`tubejax.lp.evidence.decide` (docs/math/evidence.md#exact-decisions).

It solves, in :class:`fractions.Fraction` arithmetic,
``max t  s.t.  G x + c t <= g,  G_hard x + t <= g_hard,  lb <= x <= ub,  t <= t_max``, whose
optimum is ``>= 0`` exactly when Problem 2 is feasible. It stops at a vertex with ``t >= 0`` (a
rational point, which the caller checks exactly) or at an optimum ``t* < 0``, whose duals are a
certificate (:func:`farkas_value` ``< 0``). A revised simplex on the bounded-variable form, the
tight rows' block solved afresh each iteration (:func:`~tubejax.lp.evidence.basis.solve_exact`);
Bland's rule excludes cycling. It starts from HiGHS's basis when that is exactly primal feasible.
"""

from __future__ import annotations

from fractions import Fraction
from typing import NamedTuple, Sequence

from ..engines.highs import BASIS_BASIC, BASIS_LOWER, BASIS_UPPER
from .basis import BasisError, solve_exact

__all__ = ["ExactLP", "SimplexResult", "exact_lp", "exact_simplex", "farkas_value", "crossed_column", "MAX_PIVOTS"]

#: Pivots after which :func:`exact_simplex` gives up (``BasisError``); Bland's rule terminates,
#: this only bounds the cost of a pathological instance.
MAX_PIVOTS = 5000

_ZERO = Fraction(0)


class ExactLP(NamedTuple):
    """The LP of the module doc. Columns ``0 .. n_x - 1`` are ``x``, column ``n_x`` is ``t``.

    Attributes
    ----------
    rows : list of dict {column: Fraction}   every row, ``t``'s coefficient (> 0) included
    rhs : list of Fraction
    lb, ub : list of Fraction or None, length ``n_x + 1``   (``t``: ``None``, ``t_max``)
    n_x : int
    n_margin : int                           rows ``0 .. n_margin - 1`` are ``G``'s, the rest ``G_hard``'s
    """

    rows: list
    rhs: list
    lb: list
    ub: list
    n_x: int
    n_margin: int


class SimplexResult(NamedTuple):
    """What :func:`exact_simplex` ends with.

    Attributes
    ----------
    feasible : bool               a vertex with ``t >= 0`` was reached
    t : Fraction                  ``t`` at the final vertex (the optimum when not ``feasible``)
    x : list of Fraction          the final vertex's ``x`` (length ``n_x``)
    y : dict {row: Fraction}      the final basis's duals of the tight rows (optimal, ``>= 0``,
                                  when not ``feasible``)
    pivots : int
    warm : bool                   whether it started from the given basis
    """

    feasible: bool
    t: Fraction
    x: list
    y: dict
    pivots: int
    warm: bool


def exact_lp(rlp) -> ExactLP:
    """The :class:`ExactLP` of a :class:`~tubejax.lp.evidence.basis.RationalLP` (hard rows get ``t``
    coefficient ``1``)."""
    nx = len(rlp.lb)
    rows = [{**r, nx: c} for r, c in zip(rlp.rows, rlp.t_coef)] + [{**r, nx: Fraction(1)} for r in rlp.hard_rows]
    return ExactLP(rows, list(rlp.rhs) + list(rlp.hard_rhs), list(rlp.lb) + [None],
                   list(rlp.ub) + [rlp.t_max], nx, len(rlp.rows))


def farkas_value(lp: ExactLP, y: dict, rhs: Sequence | None = None) -> Fraction | None:
    """``max over the box of  y . (g - G x)`` for rows' multipliers ``y >= 0`` (``x`` only, not
    ``t``): a value ``< 0`` proves ``{G x <= g, lb <= x <= ub}`` empty, i.e. Problem 2 infeasible.

    Parameters
    ----------
    y : dict {row: Fraction}          negative entries are not allowed (``ValueError``)
    rhs : list of Fraction, optional  the right-hand sides to refute (default ``lp.rhs``)

    Returns
    -------
    Fraction, or None when a column with a nonzero coefficient ``(G^T y)_j`` is unbounded.
    """
    rhs = lp.rhs if rhs is None else rhs
    a: dict = {}
    val = _ZERO
    for i, yi in y.items():
        if yi < 0:
            raise ValueError(f"multiplier of row {i} is negative")
        if not yi:
            continue
        val += yi * rhs[i]
        for j, v in lp.rows[i].items():
            if j != lp.n_x:
                a[j] = a.get(j, _ZERO) + yi * v
    for j, aj in a.items():                    # + max over the box of -a_j x_j
        if not aj:
            continue
        b = lp.lb[j] if aj > 0 else lp.ub[j]
        if b is None:
            return None
        val -= aj * b
    return val


def _columns(lp: ExactLP) -> list:
    cols: list = [dict() for _ in range(lp.n_x + 1)]
    for i, r in enumerate(lp.rows):
        for j, v in r.items():
            cols[j][i] = v
    return cols


class _Basis:
    """Statuses (``'L'``, ``'U'``, ``'B'`` per column; the set of tight rows) and the values."""

    def __init__(self, lp: ExactLP, status: list, tight: set):
        self.lp, self.status, self.tight = lp, status, tight

    def basic(self) -> list:
        return [j for j, s in enumerate(self.status) if s == "B"]

    def values(self) -> list:
        """The vertex: nonbasic columns on their bounds, basic ones from the tight rows."""
        lp = self.lp
        x = [lp.lb[j] if s == "L" else lp.ub[j] if s == "U" else None for j, s in enumerate(self.status)]
        bs = set(self.basic())
        eqs, rhs = [], []
        for i in sorted(self.tight):
            eq, s = {}, lp.rhs[i]
            for j, v in lp.rows[i].items():
                if j in bs:
                    eq[j] = v
                else:
                    s -= v * x[j]
            eqs.append(eq)
            rhs.append(s)
        for j, v in solve_exact(eqs, rhs, sorted(bs)).items():
            x[j] = v
        return x

    def feasible(self, x: list) -> bool:
        lp = self.lp
        for j in self.basic():
            if (lp.lb[j] is not None and x[j] < lp.lb[j]) or (lp.ub[j] is not None and x[j] > lp.ub[j]):
                return False
        return all(_dot(lp.rows[i], x) <= lp.rhs[i] for i in range(len(lp.rows)) if i not in self.tight)


def _dot(row: dict, x: list) -> Fraction:
    return sum((v * x[j] for j, v in row.items()), _ZERO)


def _start_from(lp: ExactLP, col_status, row_status) -> _Basis | None:
    """The basis HiGHS reported (``BASIS_*`` codes), or ``None`` if it does not fit."""
    n = lp.n_x + 1
    if col_status is None or row_status is None or len(col_status) != n or len(row_status) != len(lp.rows):
        return None
    status = []
    for j, c in enumerate(int(v) for v in col_status):
        if c == BASIS_BASIC:
            status.append("B")
        elif c == BASIS_LOWER and lp.lb[j] is not None:
            status.append("L")
        elif c == BASIS_UPPER and lp.ub[j] is not None:
            status.append("U")
        else:
            return None
    tight = {i for i, r in enumerate(int(v) for v in row_status) if r != BASIS_BASIC}
    if len(tight) != status.count("B"):
        return None
    return _Basis(lp, status, tight)


def _cold_start(lp: ExactLP, near: Sequence | None) -> _Basis:
    """Every ``x`` on a bound (the one nearer ``near[j]``), ``t`` basic at its largest feasible
    value: the row of least slack (first of equals) is tight, unless ``t_max`` binds first."""
    T = lp.n_x
    status = []
    for j in range(T):
        lo, hi = lp.lb[j], lp.ub[j]
        if lo is None and hi is None:
            raise BasisError(f"column {j} has no finite bound")
        if lo is None or (hi is not None and near is not None and abs(Fraction(float(near[j])) - hi)
                          < abs(Fraction(float(near[j])) - lo)):
            status.append("U")
        else:
            status.append("L")
    x = [lp.lb[j] if s == "L" else lp.ub[j] for j, s in enumerate(status)]
    best, arg = None, None
    for i, r in enumerate(lp.rows):
        v = (lp.rhs[i] - sum((a * x[j] for j, a in r.items() if j != T), _ZERO)) / r[T]
        if best is None or v < best:
            best, arg = v, i
    if best is None or best >= lp.ub[T]:
        return _Basis(lp, status + ["U"], set())
    return _Basis(lp, status + ["B"], {arg})


def _duals(lp: ExactLP, cols: list, basis: _Basis) -> dict:
    """Duals of the tight rows: ``R^T y = e_t`` over the basic columns (0 if ``t`` is nonbasic)."""
    T = lp.n_x
    tight = sorted(basis.tight)
    if basis.status[T] != "B":
        return {i: _ZERO for i in tight}
    ts = set(tight)
    eqs = [{i: v for i, v in cols[j].items() if i in ts} for j in basis.basic()]
    rhs = [Fraction(int(j == T)) for j in basis.basic()]
    return solve_exact(eqs, rhs, tight)


def crossed_column(lb: list, ub: list) -> int | None:
    """The first column whose bounds (Fractions, ``None`` unbounded) cross, ``lb > ub``; ``None`` if none."""
    return next((j for j, (lo, hi) in enumerate(zip(lb, ub)) if lo is not None and hi is not None and lo > hi), None)


def exact_simplex(lp: ExactLP, col_status=None, row_status=None, near=None,
                  max_pivots: int = MAX_PIVOTS) -> SimplexResult:
    """Run the simplex of the module doc until ``t >= 0`` or optimality.

    Parameters
    ----------
    lp : ExactLP
    col_status, row_status : ndarray, optional
        A HiGHS basis of this LP's rows and columns (``t`` last): the start when it is square,
        non-singular and exactly primal feasible.
    near : sequence of float, optional
        A point (length ``>= n_x``) the cold start's bounds are chosen near.

    Raises
    ------
    BasisError
        Inconsistent data (a column without bounds, crossed bounds) or more than ``max_pivots``.
    """
    j = crossed_column(lp.lb[:lp.n_x], lp.ub[:lp.n_x])
    if j is not None:
        raise BasisError(f"column {j}: crossed bounds {lp.lb[j]} > {lp.ub[j]}")
    T = lp.n_x
    if any(not r.get(T, 0) > 0 for r in lp.rows):
        raise BasisError("every row needs a positive coefficient of t")
    lp = lp._replace(rows=[{j: Fraction(v) for j, v in r.items() if v} for r in lp.rows])   # no stored zeros
    cols = _columns(lp)
    basis, warm, x = _start_from(lp, col_status, row_status), True, None
    if basis is not None:
        try:
            x = basis.values()
            if not basis.feasible(x):
                basis = None
        except BasisError:
            basis = None
    if basis is None:
        basis, warm = _cold_start(lp, near), False
        x = basis.values()
    nrow = len(lp.rows)
    for pivots in range(max_pivots + 1):
        if x[T] >= 0:
            return SimplexResult(True, x[T], x[:T], {}, pivots, warm)
        y = _duals(lp, cols, basis)
        q, up = _entering(lp, cols, basis, y)
        if q is None:                                        # optimal, t* < 0
            return SimplexResult(False, x[T], x[:T], y, pivots, warm)
        _pivot(lp, cols, basis, x, q, up, nrow)
        x = basis.values()
    raise BasisError(f"the exact simplex did not finish within {max_pivots} pivots")


def _entering(lp: ExactLP, cols: list, basis: _Basis, y: dict):
    """Bland's rule: the improving nonbasic variable of least index (columns, then the slacks
    of tight rows as ``n_x + 1 + row``), and whether it increases; ``(None, None)`` if optimal."""
    T = lp.n_x
    for j, s in enumerate(basis.status):
        if s == "B":
            continue
        d = Fraction(int(j == T)) - sum((v * y[i] for i, v in cols[j].items() if i in y), _ZERO)
        if (s == "L" and d > 0) or (s == "U" and d < 0):
            return j, s == "L"
    for i in sorted(basis.tight):
        if y[i] < 0:                        # raising this slack raises t
            return T + 1 + i, True
    return None, None


def _pivot(lp: ExactLP, cols: list, basis: _Basis, x: list, q: int, up: bool, nrow: int) -> None:
    """One Bland pivot (or bound flip) on entering variable ``q``; updates ``basis`` in place."""
    T = lp.n_x
    bs = basis.basic()
    tight = sorted(basis.tight)
    bset = set(bs)
    # direction of the basic columns per unit step of q: R d = -(column of q on the tight rows)
    if q <= T:
        sgn = 1 if up else -1
        col = {i: -sgn * v for i, v in cols[q].items() if i in basis.tight}
        dx = {q: Fraction(sgn)}
    else:
        col = {q - T - 1: Fraction(-1)}
        dx = {}
    eqs = [{j: v for j, v in lp.rows[i].items() if j in bset} for i in tight]
    d = solve_exact(eqs, [col.get(i, _ZERO) for i in tight], bs) if bs else {}
    dx.update(d)
    best, leave = None, None                                # (ratio, index of the leaving variable)

    def offer(ratio, idx):
        nonlocal best, leave
        if best is None or ratio < best or (ratio == best and idx < leave):
            best, leave = ratio, idx

    for j in bs:
        v = d.get(j, _ZERO)
        if v > 0 and lp.ub[j] is not None:
            offer((lp.ub[j] - x[j]) / v, j)
        elif v < 0 and lp.lb[j] is not None:
            offer((lp.lb[j] - x[j]) / v, j)
    if q <= T and lp.lb[q] is not None and lp.ub[q] is not None:
        offer(lp.ub[q] - lp.lb[q], q)                        # a bound flip
    for r in range(nrow):
        if r in basis.tight or (q > T and r == q - T - 1):
            continue
        delta = sum((v * dx[j] for j, v in lp.rows[r].items() if j in dx), _ZERO)
        if delta > 0:
            offer((lp.rhs[r] - _dot(lp.rows[r], x)) / delta, T + 1 + r)
    if best is None:
        raise BasisError("the exact simplex found an unbounded direction (the LP is bounded: inconsistent data)")
    if leave == q:                                           # bound flip
        basis.status[q] = "L" if basis.status[q] == "U" else "U"
        return
    if q <= T:
        basis.status[q] = "B"
    else:
        basis.tight.discard(q - T - 1)
    if leave <= T:
        basis.status[leave] = "U" if d.get(leave, _ZERO) > 0 else "L"
    else:
        basis.tight.add(leave - T - 1)
