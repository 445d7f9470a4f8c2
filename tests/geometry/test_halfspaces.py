"""Halfspaces {x : H x <= h}: checks, distances, records, and the exact rows (hand-derived)."""

from fractions import Fraction

import numpy as np
import pytest

from tubejax.lp.evidence.exact_geometry import exact_halfspaces
from tubejax.lp.evidence.exact_problem import exact_polytope
from tubejax.lp.evidence.rational import QArray
from tubejax.model.geometry import Halfspaces, HalfspacesError


def test_violation_is_the_distance_outside_along_the_worst_row():
    X = Halfspaces([[0.0, 2.0], [-1.0, 0.0]], [1.0, 0.0], "system.X")      # y <= 0.5, x >= 0
    pts = np.array([[1.0, 0.5], [1.0, 0.75], [-0.25, 0.0], [2.0, -3.0]])
    np.testing.assert_allclose(X.violation(pts), [0.0, 0.25, 0.25, -2.0])
    assert X.contains(pts).tolist() == [True, False, False, True]


@pytest.mark.parametrize("H, h, field", [([[0.0, 0.0]], [1.0], "system.X.H: row 0 is zero"),
                                         ([[1.0, 0.0]], [1.0, 2.0], "system.X.h: expected 1 numbers"),
                                         ([[np.nan, 1.0]], [1.0], "must be finite"),
                                         ("abc", [1.0], "system.X")])
def test_bad_rows_are_refused_with_the_field(H, h, field):
    with pytest.raises(HalfspacesError, match=field.replace(".", r"\.")):
        Halfspaces(H, h, "system.X")


def test_record_round_trip_and_keys():
    X = Halfspaces([[0.1, -0.3]], [0.7], "system.X")
    assert Halfspaces.from_record(X.record(), "system.X").same_as(X)
    with pytest.raises(HalfspacesError, match="keys H and h"):
        Halfspaces.from_record({"H": [[1.0]]}, "system.X")


def test_exact_rows_are_primitive_integers_with_the_same_set():
    # 0.1 x - 0.3 y <= 0.7  <=>  x - 3 y <= 7 ;  -0.5 y <= 0.25  <=>  -y <= 1/2
    X = Halfspaces([[0.1, -0.3], [0.0, -0.5]], [0.7, 0.25])
    E = exact_halfspaces(QArray.from_decimals(X.H), QArray.from_decimals(X.h))
    assert E.H.tolist() == [[1, -3], [0, -1]]
    assert E.h.to_fractions().tolist() == [Fraction(7), Fraction(1, 2)]
    assert E.scale.tolist() == [3, 1] and E.V.shape == (0, 2)
    assert exact_polytope(X).H.tolist() == E.H.tolist()       # the evidence layer's entry point
