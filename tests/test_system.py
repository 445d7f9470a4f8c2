import numpy as np
import pytest

from tubejax.geometry import Ball, Polytope
from tubejax.system import LinearSystem, SystemError_, box_input_set, one_norm_input_set


def test_valid_system():
    s = LinearSystem(np.eye(2), 0.5 * np.eye(2), box_input_set(1.0, 2), Ball(2, 0.2))
    assert (s.n, s.m) == (2, 2) and s.u_is_box
    s1 = LinearSystem(np.eye(2), 0.5 * np.eye(2), one_norm_input_set(1.0, 2), Ball(2, 0.2))
    assert not s1.u_is_box


@pytest.mark.parametrize("make, match", [
    (lambda: LinearSystem(np.ones((2, 3)), np.eye(2), box_input_set(1, 2), Ball(2, .1)), "A must be a square"),
    (lambda: LinearSystem(np.eye(2), np.eye(3), box_input_set(1, 3), Ball(2, .1)), r"B must have shape \(2, m\)"),
    (lambda: LinearSystem(np.eye(2), np.eye(2), box_input_set(1, 3), Ball(2, .1)), "U lives in R\\^3"),
    (lambda: LinearSystem(np.eye(2), np.eye(2), Polytope.box([0, 0], [1, 1]), Ball(2, .1)), "0 in its interior"),
    (lambda: LinearSystem(np.eye(2), np.eye(2), box_input_set(1, 2), Ball(3, .1)), "ball in R\\^3"),
    (lambda: LinearSystem(np.eye(2), np.eye(2), box_input_set(1, 2),
                          Polytope.box([0.1, 0.1], [1, 1])), "W must contain 0"),
])
def test_bad_systems_are_refused(make, match):
    with pytest.raises(SystemError_, match=match):
        make()


def test_negative_radius_refused():
    with pytest.raises(ValueError, match="radius must be a finite number >= 0"):
        Ball(2, -0.1)
    with pytest.raises(SystemError_, match="bounds must be > 0"):
        box_input_set(-1.0, 2)
