"""The exact simplex and its certificates against an independent exact oracle.

The oracle decides ``{x in box : a_i . x <= b_i}`` non-empty for two variables by brute force in
Fractions: a non-empty bounded polygon has a vertex, and every vertex is the intersection of two
of the lines ``a_i . x = b_i`` and the box's edges, so the set is non-empty iff one of those
intersection points (or a box corner) satisfies every constraint. Nothing of tubejax is used.
The data are small integers built around a point ``x0`` with many rows through it, so that the
feasible set is often that single point: the margin is exactly 0 there.
"""

from fractions import Fraction
from itertools import combinations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from tubejax.lp.evidence.basis import BasisError
from tubejax.lp.evidence.simplex import ExactLP, exact_simplex, farkas_value


def oracle_feasible(rows, rhs, lo, hi) -> bool:
    lines = [(a, b) for a, b in zip(rows, rhs)]
    for d in range(2):                                     # box edges x_d = lo_d, x_d = hi_d
        e = [Fraction(int(d == 0)), Fraction(int(d == 1))]
        lines += [(e, Fraction(lo[d])), (e, Fraction(hi[d]))]
    pts = []
    for (a, b), (c, d_) in combinations(lines, 2):
        det = a[0] * c[1] - a[1] * c[0]
        if det:
            pts.append(((b * c[1] - a[1] * d_) / det, (a[0] * d_ - b * c[0]) / det))
    for x in pts:
        if all(lo[d] <= x[d] <= hi[d] for d in range(2)) and \
                all(a[0] * x[0] + a[1] * x[1] <= b for a, b in zip(rows, rhs)):
            return True
    return False


def make_lp(rows, rhs, lo, hi, coef) -> ExactLP:
    return ExactLP([{0: a[0], 1: a[1], 2: c} for a, c in zip(rows, coef)], list(rhs),
                   [Fraction(lo[0]), Fraction(lo[1]), None], [Fraction(hi[0]), Fraction(hi[1]), Fraction(1)],
                   2, len(rows))


problems = st.fixed_dictionaries({
    "x0": st.tuples(st.integers(-2, 2), st.integers(-2, 2)),
    "rows": st.lists(st.tuples(st.integers(-3, 3), st.integers(-3, 3)).filter(lambda a: a != (0, 0)),
                     min_size=1, max_size=7),
    "slack": st.lists(st.sampled_from([-2, -1, 0, 0, 0, 0, 1, 3]), min_size=7, max_size=7),
    "coef": st.lists(st.sampled_from([1, 2, 3, Fraction(1, 3)]), min_size=7, max_size=7),
})


@settings(max_examples=300, deadline=None)
@given(problems)
def test_sign_equals_the_brute_force_oracle(p):
    rows = [[Fraction(a), Fraction(b)] for a, b in p["rows"]]
    rhs = [a[0] * p["x0"][0] + a[1] * p["x0"][1] + s for a, s in zip(rows, p["slack"])]
    lo, hi = (-3, -3), (3, 3)
    lp = make_lp(rows, rhs, lo, hi, [Fraction(c) for c in p["coef"][:len(rows)]])
    res = exact_simplex(lp)
    want = oracle_feasible(rows, rhs, lo, hi)
    assert res.feasible == want
    if res.feasible:                                       # the vertex satisfies every row exactly
        x = res.x
        assert all(lo[d] <= x[d] <= hi[d] for d in range(2))
        assert all(a[0] * x[0] + a[1] * x[1] <= b for a, b in zip(rows, rhs))
    else:                                                  # the optimal duals are a certificate
        assert res.t < 0 and all(v >= 0 for v in res.y.values())
        assert farkas_value(lp, res.y) < 0


def test_a_single_feasible_point_is_found_exactly():
    # x1 + x2 <= 2, -x1 + x2 <= 0, -x2 <= -1: only (1, 1); margin exactly 0
    rows = [[Fraction(1), Fraction(1)], [Fraction(-1), Fraction(1)], [Fraction(0), Fraction(-1)]]
    lp = make_lp(rows, [Fraction(2), Fraction(0), Fraction(-1)], (-5, -5), (5, 5), [Fraction(1)] * 3)
    res = exact_simplex(lp)
    assert res.feasible and res.t == 0 and res.x == [1, 1]
    # moved by 1/10**30 it is empty, and the certificate says so exactly
    lp2 = lp._replace(rhs=[Fraction(2) - Fraction(1, 10 ** 30), Fraction(0), Fraction(-1)])
    res2 = exact_simplex(lp2)
    assert not res2.feasible and res2.t < 0
    assert farkas_value(lp2, res2.y) < 0
    assert farkas_value(lp, res2.y) == 0                  # the same multipliers refute nothing there


def test_a_warm_start_that_is_not_feasible_falls_back_cold():
    rows = [[Fraction(1), Fraction(1)], [Fraction(-1), Fraction(1)], [Fraction(0), Fraction(-1)]]
    lp = make_lp(rows, [Fraction(2), Fraction(0), Fraction(-1)], (-5, -5), (5, 5), [Fraction(1)] * 3)
    from tubejax.lp.engines.highs import BASIS_BASIC, BASIS_LOWER, BASIS_UPPER
    cs = np.array([BASIS_BASIC, BASIS_LOWER, BASIS_BASIC], np.int8)        # rows 1, 2 tight, x2 = -5:
    rs = np.array([BASIS_UPPER, BASIS_UPPER, BASIS_BASIC], np.int8)        # t = 6 > t_max
    assert not exact_simplex(lp._replace(rhs=[Fraction(-20), Fraction(0), Fraction(-1)]), cs, rs).warm
    res = exact_simplex(lp, cs, rs)
    assert res.feasible and not res.warm and res.x == [1, 1]
    good = np.array([BASIS_BASIC, BASIS_BASIC, BASIS_BASIC], np.int8), np.array([BASIS_UPPER] * 3, np.int8)
    res = exact_simplex(lp, *good)                                          # HiGHS's optimal basis
    assert res.feasible and res.warm and res.pivots == 0 and res.x == [1, 1]


def test_crossed_bounds_are_refused():
    lp = ExactLP([{0: Fraction(1), 1: Fraction(1)}], [Fraction(1)], [Fraction(2), None], [Fraction(1), Fraction(1)],
                 1, 1)
    try:
        exact_simplex(lp)
    except BasisError as exc:
        assert "crossed bounds" in str(exc)
    else:
        raise AssertionError("crossed bounds were accepted")


def test_farkas_value_refuses_negative_multipliers_and_unbounded_columns():
    lp = ExactLP([{0: Fraction(1), 1: Fraction(1)}], [Fraction(-1)], [None, None], [None, Fraction(1)], 1, 1)
    assert farkas_value(lp, {0: Fraction(1)}) is None     # x unbounded below: no bound
    try:
        farkas_value(lp, {0: Fraction(-1)})
    except ValueError:
        pass
    else:
        raise AssertionError("a negative multiplier was accepted")
