"""An exact vertex from HiGHS's optimal basis (docs/math/evidence.md#exact-decisions).

A zero-margin edge's float tube usually misses the exact problem by a few ulps. HiGHS's basis names
the vertex (nonbasic variables at bounds, nonbasic rows tight); rebuilt in rationals, the square
basic system is solved exactly (:func:`solve_exact`) and the vertex handed to the exact checker,
which is the proof: the rebuilt rows only propose. :class:`RationalLP` is the margin-form LP in
rationals (:mod:`tubejax.lp.evidence.rows`), checked row by row against the float LP to ``1e-7``.
"""

from __future__ import annotations

import math
from fractions import Fraction
from functools import lru_cache
from typing import NamedTuple

import flint
import numpy as np

from ..engines.highs import BASIS_BASIC, BASIS_LOWER, BASIS_NONBASIC, BASIS_UPPER, BASIS_ZERO

__all__ = ["RationalLP", "BasisError", "solve_exact", "basis_vertex",
           "snapped_vertex", "snapped_floats", "reconstructed_vertex", "simplest_rational"]


class BasisError(ValueError):
    """The basis does not give an exact vertex (the message says why)."""


class RationalLP(NamedTuple):
    """``G x + c t <= g`` (margin rows), ``G_hard x <= g_hard``, ``lb <= x <= ub``, ``t <= t_max``.

    Attributes
    ----------
    rows : list of dict {column: Fraction}      margin rows (columns ``0 .. n_x - 1``)
    t_coef : list of Fraction                   ``c`` of each margin row (> 0)
    rhs : list of Fraction
    hard_rows : list of dict                    rows without ``t``
    hard_rhs : list of Fraction
    lb, ub : list of Fraction (or None = unbounded), length ``n_x``
    t_max : Fraction
    rhs_relaxed : list of Fraction or None
        The margin rows' right-hand sides of the *relaxed* problem (``sigma_W`` rounded down
        where it is irrational; ``rhs`` has it rounded up): a certificate of infeasibility must
        refute this one. ``None``: the same as ``rhs`` (every datum rational).
    """

    rows: list
    t_coef: list
    rhs: list
    hard_rows: list
    hard_rhs: list
    lb: list
    ub: list
    t_max: Fraction
    rhs_relaxed: list | None = None


def _nonbasic_value(status: int, lo, hi, what: str):
    if status == BASIS_LOWER or (status == BASIS_NONBASIC and lo is not None):
        v = lo
    elif status == BASIS_UPPER:
        v = hi
    elif status == BASIS_ZERO:
        v = Fraction(0)
    else:
        raise BasisError(f"{what}: unknown basis status {status}")
    if v is None:
        raise BasisError(f"{what}: nonbasic at an infinite bound")
    return v


def snapped_vertex(lb: list, ub: list, x: np.ndarray, col_status: np.ndarray) -> list:
    """The float point with every nonbasic column moved onto its exact bound.

    Basic columns keep their float values (taken exactly), clipped into their exact bounds. A
    cheap first repair: HiGHS leaves a variable at a bound up to its feasibility tolerance (an
    input at ``1 + 2e-16``), which the exact check rejects.

    Parameters
    ----------
    lb, ub : list of Fraction or None, length ``n_x``   rational bounds (the record's ``bounds``)
    x : ndarray, shape (n_x,)                            HiGHS's point (without ``t``)
    col_status : ndarray, shape (n_x + 1,)

    Returns
    -------
    list of Fraction, length ``n_x``
    """
    return _vertex(lb, ub, x, col_status, Fraction)


def snapped_floats(lp, x: np.ndarray, col_status: np.ndarray) -> np.ndarray:
    """:func:`snapped_vertex` in float64, onto the float LP's own bounds (cheap, no rationals).

    HiGHS's inputs at ``1 + 2e-16`` become exactly ``1``; bounds that are not floats
    (``1/5``) are left to :func:`snapped_vertex`.

    Returns
    -------
    ndarray, shape (n_x,)
    """
    s = np.asarray(col_status[:lp.lb.shape[0]])
    out = np.clip(np.asarray(x, float), lp.lb, lp.ub)
    out = np.where(s == BASIS_LOWER, lp.lb, out)
    out = np.where(s == BASIS_UPPER, lp.ub, out)
    return np.where(s == BASIS_ZERO, 0.0, out)


def simplest_rational(lo: Fraction, hi: Fraction) -> Fraction:
    """The rational with the smallest denominator in ``[lo, hi]`` (``lo <= hi``).

    Continued fractions (the Stern-Brocot descent): an interval holding an integer gives the
    integer nearest to 0; otherwise ``a + 1 / simplest(1 / (hi - a), 1 / (lo - a))`` with
    ``a = floor(lo)``.
    """
    if lo > hi:
        raise ValueError(f"empty interval [{lo}, {hi}]")
    if lo <= 0 <= hi:
        return Fraction(0)
    if hi < 0:
        return -simplest_rational(-hi, -lo)
    c = math.ceil(lo)
    if c <= hi:
        return Fraction(c)
    a = math.floor(lo)
    return a + 1 / simplest_rational(1 / (hi - a), 1 / (lo - a))


#: Relative width of the interval around a float in which :func:`reconstructed_vertex` looks
#: for the simplest rational (HiGHS's basic values are accurate to about ``1e-13`` here).
RECONSTRUCT_TOL = 2.0 ** -36


@lru_cache(maxsize=65536)
def _simplest_near(x: float) -> Fraction:
    q = Fraction(x)
    w = Fraction(RECONSTRUCT_TOL) * (1 + abs(q))
    return simplest_rational(q - w, q + w)


def reconstructed_vertex(lb: list, ub: list, x: np.ndarray, col_status: np.ndarray) -> list:
    """A rational guess of the basis vertex without solving the basic system; parameters and result as
    for :func:`snapped_vertex`.

    Nonbasic columns go onto their exact bounds, each basic one to the simplest rational within a
    relative ``2^-36`` of HiGHS's value (:func:`simplest_rational`), clipped into its bounds; with small
    denominators (dyadic cells, decimal ``A``, ``B``, ``W``) that is the exact vertex. It only proposes:
    the exact check decides, and :func:`basis_vertex` remains the fallback."""
    return _vertex(lb, ub, x, col_status, _simplest_near)


def _vertex(lb: list, ub: list, x: np.ndarray, col_status: np.ndarray, basic) -> list:
    """Nonbasic columns on their exact bounds; basic ones ``basic(value)`` (a Fraction) clipped
    into their exact bounds."""
    out = []
    for c, v in enumerate(np.asarray(x, float).tolist()):
        s = int(col_status[c])
        if s != BASIS_BASIC:
            out.append(_nonbasic_value(s, lb[c], ub[c], f"column {c}"))
            continue
        if not math.isfinite(v):
            raise BasisError(f"column {c}: non-finite value {v!r}")
        q = basic(v)
        lo, hi = lb[c], ub[c]
        out.append(lo if lo is not None and q < lo else hi if hi is not None and q > hi else q)
    return out


def solve_exact(rows: list, rhs: list, unknowns: list) -> dict:
    """Solve the square system ``rows . x = rhs`` exactly.

    FLINT's rational matrices (:class:`flint.fmpq_mat`; docs/explanation/performance.md#exact-linear-solves).

    Parameters
    ----------
    rows : list of dict {unknown: Fraction or int}   (not modified)
    rhs : list of Fraction or int
    unknowns : list of hashable                      exactly ``len(rows)`` of them

    Returns
    -------
    dict {unknown: Fraction}
        ``BasisError`` when the system is not square or is singular.
    """
    if len(rows) != len(unknowns):
        raise BasisError(f"the basic system is not square: {len(rows)} tight rows, "
                         f"{len(unknowns)} basic variables")
    col = {u: j for j, u in enumerate(unknowns)}
    N = len(unknowns)
    if N == 0:
        return {}
    M = flint.fmpq_mat(N, N)
    for i, r in enumerate(rows):
        for u, a in r.items():
            if u not in col:
                raise BasisError(f"row {i} uses {u!r}, which is not an unknown")
            M[i, col[u]] = _fmpq(a)
    try:
        x = M.solve(flint.fmpq_mat(N, 1, [_fmpq(v) for v in rhs]))
    except ZeroDivisionError:
        raise BasisError(f"the basic system is singular ({N} unknowns)") from None
    return {u: Fraction(int(x[j, 0].p), int(x[j, 0].q)) for u, j in col.items()}


def _fmpq(v) -> "flint.fmpq":
    return flint.fmpq(int(v.numerator), int(v.denominator))


def basis_vertex(rlp: RationalLP, col_status: np.ndarray, row_status: np.ndarray) -> tuple[list, Fraction]:
    """The vertex of ``rlp`` that a HiGHS basis names, in exact arithmetic.

    Parameters
    ----------
    rlp : RationalLP
    col_status : ndarray, shape (n_x + 1,)   columns ``x`` then ``t``
    row_status : ndarray, shape (n_rows + n_hard,)

    Returns
    -------
    x : list of Fraction, length ``n_x``
    t : Fraction

    Raises
    ------
    BasisError
    """
    nx = len(rlp.lb)
    nr, nh = len(rlp.rows), len(rlp.hard_rows)
    if col_status.shape != (nx + 1,) or row_status.shape != (nr + nh,):
        raise BasisError(f"basis of shape {col_status.shape}/{row_status.shape} for an LP with "
                         f"{nx + 1} columns and {nr + nh} rows")
    T = nx                                          # the margin's column
    fixed: dict = {}
    for c in range(nx):
        if int(col_status[c]) != BASIS_BASIC:
            fixed[c] = _nonbasic_value(int(col_status[c]), rlp.lb[c], rlp.ub[c], f"column {c}")
    if int(col_status[T]) != BASIS_BASIC:
        fixed[T] = _nonbasic_value(int(col_status[T]), None, rlp.t_max, "the margin t")
    unknowns = [c for c in range(nx + 1) if c not in fixed]
    eqs, rhs = [], []
    all_rows = [(r, c, g) for r, c, g in zip(rlp.rows, rlp.t_coef, rlp.rhs)] + \
               [(r, None, g) for r, g in zip(rlp.hard_rows, rlp.hard_rhs)]
    for k, (row, tc, g) in enumerate(all_rows):
        if int(row_status[k]) == BASIS_BASIC:
            continue
        eq = {}
        s = g
        items = list(row.items()) + ([(T, tc)] if tc is not None else [])
        for c, a in items:
            if c in fixed:
                s -= a * fixed[c]
            else:
                eq[c] = a
        eqs.append(eq)
        rhs.append(s)
    sol = solve_exact(eqs, rhs, unknowns)
    full = {**fixed, **sol}
    return [full[c] for c in range(nx)], full[T]
