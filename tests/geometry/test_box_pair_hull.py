"""The hull of two boxes by elimination, against qhull's facets and an LP's answer on each point.

Boxes are drawn on a coarse grid, so they touch, share faces, nest and coincide often. qhull's
facets must equal ours; its vertex list may hold a point that is not a vertex (a triangulated facet's
corner on a face), so vertices are checked one by one: a point we keep is not in the hull of the
other points, a point we leave is in the hull of those we keep (scipy's HiGHS LP).
"""

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import linprog
from scipy.spatial import ConvexHull

from tubejax.model.geometry.box_pair_hull import box_pair_hull
from tubejax.model.geometry.polytope import first_distinct_rows


def corners(lo, hi) -> np.ndarray:
    return np.array([[h if bit else l for l, h, bit in zip(lo, hi, bits)]
                     for bits in itertools.product([0, 1], repeat=len(lo))], dtype=float)


def in_hull(p, V) -> bool:
    k = len(V)
    res = linprog(np.zeros(k), A_eq=np.vstack([V.T, np.ones(k)]), b_eq=np.append(p, 1.0), bounds=(0, None),
                  method="highs")
    return res.status == 0


def rounded_rows(H) -> list:
    return sorted(map(tuple, np.round(H, 7) + 0.0))


@st.composite
def box_pairs(draw):
    n = draw(st.integers(2, 6))
    w = np.array(draw(st.lists(st.sampled_from([0.25, 0.5, 1.0]), min_size=n, max_size=n)))
    grid = st.lists(st.integers(0, 3), min_size=n, max_size=n)
    size = st.lists(st.integers(1, 2), min_size=n, max_size=n)
    lo1, lo2 = np.array(draw(grid)) * w, np.array(draw(grid)) * w
    return lo1, lo1 + np.array(draw(size)) * w, lo2, lo2 + np.array(draw(size)) * w


@settings(max_examples=60, deadline=None)
@given(box_pairs())
def test_facets_are_qhulls_and_vertices_are_extreme(boxes):
    lo1, hi1, lo2, hi2 = boxes
    P = np.vstack([corners(lo1, hi1), corners(lo2, hi2)])
    idx, H = box_pair_hull(P, from_dim=2)
    n = P.shape[1]
    E = ConvexHull(P).equations
    qH = E[:, :n][first_distinct_rows(np.hstack([E[:, :n], -E[:, n:]]))]
    assert rounded_rows(H) == rounded_rows(qH)
    assert np.allclose(np.linalg.norm(H, axis=1), 1.0)
    kept = P[idx]
    assert len(np.unique(kept, axis=0)) == len(kept)
    distinct = np.unique(P, axis=0)
    for p in distinct:
        mine = any(np.array_equal(p, q) for q in kept)
        others = np.array([q for q in distinct if not np.array_equal(p, q)])
        assert mine == (not in_hull(p, others))


def test_a_known_hull_in_3d():
    """Two unit cubes offset by (1, 1, 0): the bounding box's 6 rows and two diagonal faces; 12 vertices
    of the 16 corners (the corners (1, 1, z), one of each cube, are inner)."""
    P = np.vstack([corners([0, 0, 0], [1, 1, 1]), corners([1, 1, 0], [2, 2, 1])])
    assert box_pair_hull(P) is None                                 # 3-D: qhull's, by default
    idx, H = box_pair_hull(P, from_dim=3)
    s = 1 / np.sqrt(2)
    assert rounded_rows(H) == rounded_rows([[0, 0, -1], [0, 0, 1], [-1, 0, 0], [0, -1, 0], [1, 0, 0], [0, 1, 0],
                                            [s, -s, 0], [-s, s, 0]])
    assert sorted(map(tuple, P[idx])) == sorted(
        (x, y, z) for x, y in [(0, 0), (1, 0), (0, 1), (2, 1), (1, 2), (2, 2)] for z in (0, 1))


@pytest.mark.parametrize("points", [
    np.vstack([corners([0, 0], [1, 1]), [[0, 0], [1, 0], [0, 1], [0.5, 0.5]]]),   # not a box
    np.vstack([corners([0, 0], [1, 0]), corners([1, 1], [2, 2])]),               # flat box
    corners([0, 0, 0], [1, 1, 1]),                                               # one box
])
def test_anything_else_is_left_to_qhull(points):
    assert box_pair_hull(points, from_dim=2) is None
