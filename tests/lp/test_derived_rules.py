"""Pieces derived once from the row families, each against an independent computation."""

from fractions import Fraction

import numpy as np

from tubejax.lp.formulations.row_families import ZERO_ROW, kept_rows, zero_rows


def test_zero_row_rule_on_hand_cases():
    # rows: with coefficients; zero and binding (g < 0); zero with g = 0; zero with g > 0
    zero = np.array([False, True, True, True])
    g = np.array([5.0, -1.0, 0.0, 2.0])
    assert kept_rows(zero, g).tolist() == [True, True, False, False]
    # the radius form also keeps a zero row that bounds rho (c > 0)
    assert kept_rows(zero, g, np.array([0.0, 0.0, 0.5, 0.0])).tolist() == [True, True, True, False]
    # a batch of right-hand sides over shared rows
    gb = np.array([[1.0, 1.0, -2.0, 3.0], [1.0, -1.0, 1.0, 0.0]])
    assert kept_rows(zero, gb).tolist() == [[True, False, True, False], [True, True, False, False]]
    # rationals: exact zero rows, Fraction right-hand sides
    gq = np.array([Fraction(0), Fraction(-1, 3), Fraction(0), Fraction(1, 7)], dtype=object)
    assert kept_rows(zero, gq).tolist() == [True, True, False, False]


def test_zero_rows_by_norm():
    G = np.array([[0.0, 0.0], [ZERO_ROW / 2, 0.0], [1e-9, 0.0], [0.6, 0.8]])
    assert zero_rows(G).tolist() == [True, True, False, False]
