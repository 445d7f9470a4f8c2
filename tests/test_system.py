import numpy as np
import pytest

from tubejax.model.geometry import Ball, Halfspaces, Polytope
from tubejax.model.system import LinearSystem, SystemError_, box_input_set, one_norm_input_set


def test_valid_system():
    s = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
    assert (s.n, s.m) == (2, 2) and s.u_is_box
    s1 = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=one_norm_input_set(1.0, 2), W=Ball(2, 0.2))
    assert not s1.u_is_box


def test_u_is_box_is_decided_exactly():
    """A box given by its corners is a box; one whose top edge is tilted by 5e-14 is not (its C5 stay
    rows, not the bounding box as variable bounds), though every facet normal is axis-aligned to 1e-12."""
    corners = [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]]
    system = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=Polytope.from_vertices(corners), W=Ball(2, 0.2))
    assert system.u_is_box
    tilted = Polytope.from_vertices([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0 + 1e-13], [-1.0, 1.0]])
    assert np.all(np.sum(np.abs(tilted.H) > 1e-12, axis=1) == 1) and np.count_nonzero(tilted.H) == 5
    assert not LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=tilted, W=Ball(2, 0.2)).u_is_box


@pytest.mark.parametrize("make, match", [
    (lambda: LinearSystem(A=np.ones((2, 3)), B=np.eye(2), U=box_input_set(1, 2), W=Ball(2, .1)), "A must be a square"),
    (lambda: LinearSystem(A=np.eye(2), B=np.eye(3), U=box_input_set(1, 3), W=Ball(2, .1)), r"B must have shape \(2, m\)"),
    (lambda: LinearSystem(A=np.eye(2), B=np.eye(2), U=box_input_set(1, 3), W=Ball(2, .1)), "U lives in R\\^3"),
    (lambda: LinearSystem(A=np.eye(2), B=np.eye(2), U=Polytope.box([0, 0], [1, 1]), W=Ball(2, .1)), "0 in its interior"),
    (lambda: LinearSystem(A=np.eye(2), B=np.eye(2), U=box_input_set(1, 2), W=Ball(3, .1)), "ball in R\\^3"),
    (lambda: LinearSystem(A=np.eye(2), B=np.eye(2), U=box_input_set(1, 2),
                          W=Polytope.box([0.1, 0.1], [1, 1])), "W must contain 0"),
])
def test_bad_systems_are_refused(make, match):
    with pytest.raises(SystemError_, match=match):
        make()


def test_negative_radius_refused():
    with pytest.raises(ValueError, match="radius must be a finite number >= 0"):
        Ball(2, -0.1)
    with pytest.raises(SystemError_, match="bounds must be > 0"):
        box_input_set(-1.0, 2)


def test_built_by_keyword_only():
    import numpy as np
    import pytest

    from tubejax.model.geometry import Ball
    from tubejax.model.system import LinearSystem, box_input_set
    with pytest.raises(TypeError):
        LinearSystem(np.eye(2), 0.5 * np.eye(2), box_input_set(1.0, 2), Ball(2, 0.2))     # positional: refused
    s = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
    assert s.n == 2 and s.m == 2


def test_the_record_round_trips_and_differences_are_named():
    import json

    import numpy as np

    from tubejax.model.geometry import Ball, Polytope
    from tubejax.model.system import LinearSystem, box_input_set, one_norm_input_set
    for W in (Ball(2, 0.2), Polytope.box(-0.1 * np.ones(2), 0.1 * np.ones(2))):
        s = LinearSystem(A=np.array([[1.0, 0.1], [0.0, 1.0]]), B=0.5 * np.eye(2), U=one_norm_input_set(1.0, 2), W=W)
        back = LinearSystem.from_record(json.loads(json.dumps(s.record())))      # through a JSON file
        assert back.differences(s) == [] and s.differences(back) == []
    t = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
    assert s.differences(t) == ["A", "U", "W"]
    u = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.3))
    assert t.differences(u) == ["W"]


def test_a_record_with_a_part_the_system_does_not_have_is_refused_by_name():
    s = LinearSystem(A=np.eye(2), B=np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.1))
    rec = dict(s.record(), Y={"H": [[1.0, 0.0]], "h": [1.0]})
    with pytest.raises(SystemError_, match=r"system\.Y: not a part of the system"):
        LinearSystem.from_record(rec)
    assert s.state_constraints == {}


def test_x_round_trips_and_a_changed_x_is_named():
    X = Halfspaces([[0.0, 1.0]], [0.3], "system.X")
    s = LinearSystem(A=np.eye(2), B=np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.1), X=X)
    back = LinearSystem.from_record(s.record())
    assert back.differences(s) == [] and back.state_constraints["X"].same_as(X)
    rec = s.record()
    rec["X"]["h"] = [0.4]
    assert LinearSystem.from_record(rec).differences(s) == ["X"]
    del rec["X"]
    assert LinearSystem.from_record(rec).differences(s) == ["X"]
    with pytest.raises(SystemError_, match=r"X\.H: rows live in R\^3"):
        LinearSystem(A=np.eye(2), B=np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.1),
                     X=Halfspaces([[0.0, 1.0, 0.0]], [0.3], "X"))
