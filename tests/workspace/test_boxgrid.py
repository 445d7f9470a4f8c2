"""n-D box grids: numbering, obstacle removal, labels, 4-D, argument errors."""

import numpy as np
import pytest

from tubejax.model.geometry import Polytope
from tubejax.model.workspace import CellDecomposition, box_grid


def volume(P):
    lo, hi = P.bounding_box()
    return float(np.prod(hi - lo))


def test_2d_count_order_and_tiling():
    dec = box_grid([0, -1], [4, 2], [4, 3])
    assert isinstance(dec, CellDecomposition) and dec.name == "box grid"
    assert dec.n_cells == 12 and dec.dim == 2 and dec.obstacles == ()
    np.testing.assert_array_equal(dec.grid, np.indices((4, 3)).reshape(2, -1).T)
    for P, (i, j) in zip(dec.cells, dec.grid):
        lo, hi = P.bounding_box()
        np.testing.assert_allclose(lo, [i, -1 + j])
        np.testing.assert_allclose(hi, [i + 1, j])
        np.testing.assert_allclose(P.H @ P.vertices.T <= P.h[:, None] + 1e-12, True)
    assert sum(volume(P) for P in dec.cells) == pytest.approx(12.0)
    assert dec.labels == (None,) * 12
    assert not dec.obstacle_case_matrix().any()


def test_int_divisions_and_shared_faces_are_exact():
    dec = box_grid([0, 0], [1, 1], 3)
    assert dec.n_cells == 9
    a = dec.cells[0].bounding_box()[1]            # cell (0, 0) upper corner
    b = dec.cells[4].bounding_box()[0]            # cell (1, 1) lower corner
    np.testing.assert_array_equal(a, b)


def test_obstacle_removal():
    dec = box_grid([0, 0], [4, 4], [4, 4], obstacles=[([1, 1], [2, 2])])
    assert dec.n_cells == 15
    assert [1, 1] not in dec.grid.tolist()
    assert isinstance(dec.obstacles[0], Polytope)
    # touching faces keep the neighbours; a hull across the obstacle is the obstacle case
    i = dec.grid.tolist().index([1, 0])
    j = dec.grid.tolist().index([1, 2])
    k = dec.grid.tolist().index([0, 0])
    assert dec.obstacle_case(i, j) and not dec.obstacle_case(i, k)
    dec2 = box_grid([0, 0], [4, 4], [4, 4], obstacles=[([0.5, 0.5], [1.5, 1.5]),
                                                      Polytope.box([3, 3], [9, 9])])
    removed = {(0, 0), (0, 1), (1, 0), (1, 1), (3, 3)}
    assert {tuple(g) for g in dec2.grid} == {(i, j) for i in range(4) for j in range(4)} - removed
    assert np.all(np.diff([np.ravel_multi_index(tuple(g), (4, 4)) for g in dec2.grid]) > 0)


def test_labels_by_centre():
    dec = box_grid([0, 0], [4, 4], [4, 4], obstacles=[([0, 0], [1, 1])],
                   labels={"goal": ([3, 3], [4, 4]), 7: ([0, 0], [2, 1])})
    assert dec.cells_with_label("goal") == [dec.grid.tolist().index([3, 3])]
    assert dec.labels[dec.grid.tolist().index([1, 0])] == "7"      # (0, 0) is an obstacle
    assert sum(l is not None for l in dec.labels) == 2


def test_4d():
    lo, hi = np.array([-1, -1, -2, -2]), np.array([1, 1, 2, 2])
    dec = box_grid(lo, hi, (3, 3, 2, 2), labels={"origin": ([-1 / 3, -1 / 3, 0, 0], [1 / 3, 1 / 3, 2, 2])})
    with pytest.raises(ValueError, match="contains no whole free cell"):    # a region is visited in whole cells
        box_grid(lo, hi, (3, 3, 2, 2), labels={"origin": (-0.2 * np.ones(4), [0.2, 0.2, 2, 2])})
    assert dec.n_cells == 36 and dec.dim == 4
    assert all(P.vertices.shape == (16, 4) and P.H.shape == (8, 4) for P in dec.cells)
    np.testing.assert_array_equal(dec.grid, np.indices((3, 3, 2, 2)).reshape(4, -1).T)
    assert sum(volume(P) for P in dec.cells) == pytest.approx(float(np.prod(hi - lo)))
    assert sorted(dec.grid[dec.cells_with_label("origin")].tolist()) == [[1, 1, 1, 1]]
    obs = box_grid(lo, hi, (3, 3, 2, 2), obstacles=[(-0.3 * np.ones(4), 0.3 * np.ones(4))])
    assert obs.n_cells == 36 - 4                                  # the 4 cells around the centre
    i = obs.grid.tolist().index([0, 1, 0, 0])
    j = obs.grid.tolist().index([2, 1, 0, 0])
    assert obs.obstacle_case(i, j)


@pytest.mark.parametrize("args, kwargs, match", [
    (([0, 0], [1], 2), {}, "upper"),
    (([0, 0], [1, 0], 2), {}, "upper must exceed lower"),
    (([0, "a"], [1, 1], 2), {}, "lower"),
    (([0, np.nan], [1, 1], 2), {}, "lower"),
    (([], [], 2), {}, "lower"),
    (([0, 0], [1, 1], 0), {}, "divisions"),
    (([0, 0], [1, 1], [2, 2.5]), {}, "divisions"),
    (([0, 0], [1, 1], [2]), {}, "divisions"),
    (([0, 0], [1, 1], [True, 2]), {}, "divisions"),
    (([0, 0], [1, 1], "22"), {}, "divisions"),
    (([0, 0], [1, 1], 2.0), {}, "divisions"),
    (([0, 0], [1, 1], 2), {"obstacles": [([0, 0], [1])]}, r"obstacles\[0\]"),
    (([0, 0], [1, 1], 2), {"obstacles": [([1, 1], [0, 0])]}, r"obstacles\[0\]"),
    (([0, 0], [1, 1], 2), {"obstacles": [([0, 0], [2, 2])]}, "no free cell"),
    (([0, 0], [1, 1], 2), {"labels": {"a": ([5, 5], [6, 6])}}, r"labels\['a'\]"),
    (([0, 0], [1, 1], 2), {"labels": {"a": ([0, 0], [1, 1]), "b": ([0, 0], [0.5, 0.5])}},
     r"labels\['b'\].*already labelled"),
    (([0, 0], [1, 1], 10 ** 4), {}, "more than"),
])
def test_bad_arguments(args, kwargs, match):
    with pytest.raises(ValueError, match=match):
        box_grid(*args, **kwargs)
