"""The reach-avoid limit against closed forms, monotonicity and the nesting of its outer approximations.

Closed forms (docs/math/limit.md#closed-forms), ``A = B = I``, boxes ``U`` and ``W``:

* ``W`` strictly inside ``U`` on an obstacle-free square: every state can move by any vector of
  ``U ⊖ W`` against every disturbance, so the limit is all of ``S``;
* ``W = U``: ``Pre(R) = (R ⊖ W) ⊕ W`` is the opening of ``R``, which gives back a union of
  boxes ``T`` of at least ``W``'s size, so the limit is ``T``;
* a corridor one cell wide and a ball ``W`` of radius above its half-width: no set of the
  corridor contains a translate of ``W``, so ``Pre`` of anything in it is empty and only ``T``
  remains.

The areas are compared with the independent closed form (cells are unit squares); the outer
slack of the computation (relative ``1e-9``) is far inside the tolerances.
"""

import numpy as np
import pytest
import shapely

from tubejax.analyses.conservatism import (disturbance_polygon, minkowski_sum, pontryagin_difference,
                                           reach_avoid_limit)
from tubejax.model.geometry import Ball, Polytope
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.workspace.gridmap import parse_grid_map

SQUARE = "....\n....\n....\n...1\n"


def _system(U_half, W, A=None, B=None):
    return LinearSystem(A=np.eye(2) if A is None else A, B=np.eye(2) if B is None else B,
                        U=box_input_set(U_half, 2), W=W)


def _box_w(half):
    return Polytope.box([-half, -half], [half, half])


def test_w_strictly_inside_u_gives_all_of_s():
    d = parse_grid_map(SQUARE)
    lim = reach_avoid_limit(d, _system(0.3, _box_w(0.1)), "1")
    assert lim.converged
    assert lim.area == pytest.approx(16.0, abs=1e-6)
    assert lim.free_area == 16.0 and lim.target_area == 1.0
    assert float(shapely.difference(lim.safe, lim.geometry).area) < 1e-6


@pytest.mark.parametrize("half", [0.2, 0.5])
def test_w_equal_to_u_gives_the_target(half):
    d = parse_grid_map(SQUARE)
    lim = reach_avoid_limit(d, _system(half, _box_w(half)), "1")
    assert lim.converged
    assert lim.area == pytest.approx(1.0, abs=1e-6)          # only T (a sliver of the outer slack at most)


def test_ball_wider_than_the_corridor_leaves_only_the_target():
    d = parse_grid_map("1.......2\n")
    lim = reach_avoid_limit(d, _system(3.0, Ball(2, 0.55)), "2")
    assert lim.converged and lim.iterations == 1
    assert lim.area == pytest.approx(1.0, abs=1e-12)
    narrow = reach_avoid_limit(d, _system(3.0, Ball(2, 0.45)), "2")     # fits: the whole corridor
    assert narrow.converged and narrow.area == pytest.approx(9.0, abs=1e-6)


def test_obstacles_and_avoided_labels_are_left_out():
    d = parse_grid_map("1.4.2\n.###.\n3....\n")
    lim = reach_avoid_limit(d, _system(0.3, _box_w(0.1)), "2", avoid=["4"])
    assert lim.converged
    assert lim.free_area == 11.0                               # 12 free cells, the one of label 4 avoided
    assert lim.area == pytest.approx(11.0, abs=1e-6)          # the detour through 3 reaches everything
    cell4 = shapely.box(2, 2, 3, 3)
    assert float(shapely.intersection(lim.geometry, cell4).area) < 1e-9


def test_minkowski_and_pontryagin_of_a_nonconvex_set_against_brute_force():
    L = shapely.Polygon([(0, 0), (3, 0), (3, 1), (1, 1), (1, 3), (0, 3)])        # an L
    K = np.array([[-0.2, -0.1], [0.3, -0.1], [0.3, 0.25], [-0.2, 0.25]])
    rng = np.random.default_rng(0)
    pts = rng.uniform(-1, 4, size=(4000, 2))
    Kbox, Kneg = shapely.Polygon(K), shapely.Polygon(-K)
    dil, ero = minkowski_sum(L, K), pontryagin_difference(L, K)
    for x in pts:
        p = shapely.Point(*x)
        if min(dil.boundary.distance(p), ero.boundary.distance(p) if not ero.is_empty else 1.0) < 1e-9:
            continue                                                      # on a boundary: either answer
        assert shapely.affinity.translate(Kneg, *x).intersects(L) == dil.covers(p), x   # (x - K) ∩ L ≠ ∅
        assert L.covers(shapely.affinity.translate(Kbox, *x)) == ero.covers(p), x       # x + K ⊆ L


#: Two rooms two cells wide joined by a corridor one cell wide; the target is the left room.
ROOMS = "11######..\n11........\n11######..\n"


def test_monotone_in_the_radius():
    d = parse_grid_map(ROOMS)
    prev, areas, right = None, [], shapely.box(8, 0, 10, 3)
    for r in (0.2, 0.4, 0.55, 0.7):
        lim = reach_avoid_limit(d, _system(0.8, Ball(2, r)), "1")
        assert lim.converged
        areas.append(lim.area)
        if r > 0.5:                                              # W no longer fits the corridor
            assert float(shapely.intersection(lim.geometry, right).area) < 1e-9
        if prev is not None:
            assert float(shapely.difference(lim.geometry, prev.geometry).area) <= 1e-8, f"radius {r}"
        prev = lim
    assert areas[0] == pytest.approx(18.0, abs=1e-6)             # everything
    assert areas[1] == pytest.approx(18.0, abs=1e-6)
    assert 6.0 < areas[2] < 7.0 and 6.0 <= areas[3] < areas[2]     # T and the corridor's mouth


def test_finer_inscribed_polygon_gives_a_contained_limit():
    d = parse_grid_map(ROOMS)
    sys_ = _system(0.8, Ball(2, 0.52))      # the hexagon's height 0.9 fits the corridor, the 24-gon's 1.04 not
    coarse, fine = (reach_avoid_limit(d, sys_, "1", sides=s) for s in (6, 24))
    assert coarse.converged and fine.converged
    assert float(shapely.difference(fine.geometry, coarse.geometry).area) <= 1e-8
    assert coarse.area == pytest.approx(18.0, abs=1e-6) and fine.area < 7.0
    P6, P24 = (shapely.Polygon(disturbance_polygon(Ball(2, 0.52), s)) for s in (6, 24))
    assert P24.contains(P6) and np.linalg.norm(disturbance_polygon(Ball(2, 0.52), 24), axis=1).max() <= 0.52


def test_a_capped_run_is_not_converged():
    d = parse_grid_map("1.......2\n")
    lim = reach_avoid_limit(d, _system(1.0, Ball(2, 0.45)), "2", max_iterations=2)
    assert not lim.converged and lim.iterations == 2
    assert lim.summary() == {"area": lim.area, "iterations": 2, "converged": False}


def test_refusals():
    d = parse_grid_map(SQUARE)
    with pytest.raises(ValueError, match="system.A: the limit needs an invertible A"):
        reach_avoid_limit(d, _system(0.3, _box_w(0.1), A=np.array([[1.0, 1.0], [1.0, 1.0]])), "1")
    with pytest.raises(ValueError, match="target: no cell carries the label '7'"):
        reach_avoid_limit(d, _system(0.3, _box_w(0.1)), "7")
    with pytest.raises(ValueError, match="avoid: the target '1' is also avoided"):
        reach_avoid_limit(d, _system(0.3, _box_w(0.1)), "1", avoid=["1"])
    with pytest.raises(ValueError, match="sides"):
        reach_avoid_limit(d, _system(0.3, Ball(2, 0.1)), "1", sides=2)
    s3 = LinearSystem(A=np.eye(3), B=np.eye(3), U=box_input_set(1.0, 3), W=Ball(3, 0.1))
    with pytest.raises(ValueError, match="2-D"):
        reach_avoid_limit(d, s3, "1")
