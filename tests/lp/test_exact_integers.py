"""The integer kernels of the exact checks: products, row maxima and the greedy independent points."""

import math
from fractions import Fraction as F

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from tubejax.lp.evidence.exact_geometry import independent_points
from tubejax.lp.evidence.rational import QArray, int_matrix, int_products, row_max


def _greedy(P, idx, k):
    """The greedy choice spelled out: keep a point when its difference to the first is not in the
    span of the kept ones' (rank by exact Gaussian elimination over Fractions)."""
    chosen, rows = [idx[0]], []
    for i in idx[1:]:
        v = [F(a - b) for a, b in zip(P[i], P[idx[0]])]
        for piv, row in rows:
            v = [x - v[piv] / row[piv] * y for x, y in zip(v, row)]
        nz = [c for c, x in enumerate(v) if x]
        if nz:
            rows.append((nz[0], v))
            chosen.append(i)
            if len(chosen) == k + 1:
                break
    return chosen


ints = st.integers(-3, 3) | st.integers(-2 ** 70, 2 ** 70)


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 4), st.integers(1, 5), st.integers(1, 5), st.data())
def test_int_products_are_exact_in_either_width(n, r, s, data):
    A = [[data.draw(ints) for _ in range(n)] for _ in range(r)]
    B = [[data.draw(ints) for _ in range(n)] for _ in range(s)]
    got = int_products(A, B)
    assert got.shape == (r, s)
    assert [[int(v) for v in row] for row in got.tolist()] == [[sum(a * b for a, b in zip(ra, rb)) for rb in B]
                                                              for ra in A]


def test_int_products_switch_to_python_ints_near_the_int64_limit():
    big = 2 ** 31
    got = int_products([[big, big]], [[big, big]])            # 2^63: overflows int64
    assert got.dtype == object and int(got[0, 0]) == 2 ** 63



def test_one_int64_rule_for_entries_products_and_sums():
    """int64 only below ``2^62``: each entry (:func:`int_matrix`), and each product times the terms summed
    (:func:`int_products`), so the exact sum is kept even when one int64 matrix meets a large factor."""
    edge = 2 ** 62
    assert int_matrix([[edge - 1, 0]]).dtype == np.int64 and int_matrix([[-edge, 0]]).dtype == object
    assert int_products([[2 ** 30, 2 ** 30]], [[2 ** 31 - 1, 1]]).dtype == np.int64     # 2^61 * 2 < 2^62
    two = int_products([[2 ** 30, 2 ** 30]], [[2 ** 31, 1]])                            # 2^61 * 2 = 2^62
    assert two.dtype == object and int(two[0, 0]) == 2 ** 61 + 2 ** 30
    wide = int_products(int_matrix([[edge - 1, edge - 1]]), [[2, 2]])                    # int64 rows, large sums
    assert wide.dtype == object and int(wide[0, 0]) == 4 * (edge - 1)

@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(-4, 4), st.integers(-4, 4), st.integers(-4, 4)), min_size=1, max_size=12),
       st.integers(1, 3))
def test_independent_is_the_greedy_choice(points, k):
    P = [list(p) for p in points]
    assert independent_points(P, list(range(len(P))), k) == _greedy(P, list(range(len(P))), k)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(-10 ** 20, 10 ** 20), min_size=1, max_size=9), st.data())
def test_row_max_is_the_exact_maximum(nums, data):
    scale = [data.draw(st.integers(1, 12)) for _ in nums]
    den = data.draw(st.integers(1, 10 ** 6))
    got = row_max(QArray(np.array(nums, dtype=object)[None, :], den), np.array(scale, dtype=object))
    assert got == max(F(a, b * den) for a, b in zip(nums, scale))
    assert row_max(QArray(np.zeros((0,), dtype=object), 1), np.zeros(0, dtype=object)) == -10 ** 30
    assert math.gcd(got.numerator, got.denominator) == 1


@settings(max_examples=40, deadline=None)
@given(st.lists(st.lists(ints, min_size=3, max_size=3), min_size=1, max_size=6), st.lists(ints, min_size=3, max_size=3))
def test_int_matrix_gives_the_same_products(A, b):
    assert int_products(int_matrix(A), [b]).tolist() == int_products(A, [b]).tolist()


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 4), st.integers(1, 5), st.data())
def test_qarray_matmul_skips_zeros_exactly(k, f, data):
    a = np.array([[data.draw(ints) for _ in range(k)] for _ in range(300)], dtype=object).reshape(3, 100, k)
    b = np.array([[data.draw(st.integers(-2, 2)) for _ in range(f)] for _ in range(k)], dtype=object)
    got = QArray(a, 3) @ QArray(b, 5)                       # 300 entries: the sparse path
    assert got.den == 15 and (got.num == a @ b).all()
