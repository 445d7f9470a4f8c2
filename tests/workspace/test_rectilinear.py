"""Rectilinear obstacles (tubejax.model.workspace.rectilinear) and the faster obstacle-case test: the
same cases as GEOS overlays of the pair hulls with the union, on every path."""

import numpy as np
import pytest
import shapely
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import tubejax.model.workspace.obstacle_index as oi
from tubejax.model.workspace import parse_grid_map
from tubejax.model.workspace.generate import rooms_and_corridors
from tubejax.model.workspace.pair_hulls import pair_hull_geoms
from tubejax.model.workspace.rectilinear import convex_box_areas, polygon_vertices, rectangles_of


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2 ** 31 - 1))
def test_convex_box_areas_equal_geos_overlays(seed):
    rng = np.random.default_rng(seed)
    K = 300
    pts = rng.normal(0, 2, size=(K, int(rng.integers(3, 9)), 2))
    if seed % 2:
        pts = np.round(pts)                      # grid points: collinear ones, shared edges, touching
    g = shapely.convex_hull(shapely.multipoints(pts))
    g = g[shapely.get_type_id(g) == 3]
    V, n = polygon_vertices(g)
    lo = rng.uniform(-3, 1, size=(len(g), 2))
    hi = lo + rng.uniform(0, 3, size=(len(g), 2))
    if seed % 2:
        lo, hi = np.round(lo), np.round(hi) + 1
    got = convex_box_areas(V, n, lo, hi)
    ref = shapely.area(shapely.intersection(g, shapely.box(lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1])))
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12)


def test_a_box_touching_a_polygon_overlaps_by_nothing():
    V, n = polygon_vertices(np.array([shapely.box(0, 0, 1, 1)]))
    assert convex_box_areas(V, n, np.array([[1.0, 0.0]]), np.array([[2.0, 1.0]]))[0] == 0.0
    assert convex_box_areas(V, n, np.array([[0.5, 0.5]]), np.array([[2.0, 2.0]]))[0] == 0.25


def test_rectangles_tile_a_rectilinear_union_and_refuse_others():
    d = parse_grid_map(rooms_and_corridors(30, 30, seed=3))
    index = oi.ObstacleIndex(d.obstacles, 2, tile=4.0)
    r = rectangles_of(index.union)
    assert r is not None and len(r) > 10
    boxes = shapely.box(*r.T)
    np.testing.assert_allclose(shapely.area(boxes).sum(), index.union.area, rtol=1e-12)
    assert shapely.area(shapely.union_all(boxes).symmetric_difference(index.union)) < 1e-9
    inter = shapely.area(shapely.intersection(boxes[:, None], boxes[None, :]))   # disjoint interiors
    np.fill_diagonal(inter, 0.0)
    assert inter.max() == 0.0
    assert rectangles_of(shapely.Polygon([(0, 0), (2, 0), (0, 2)])) is None      # a slanted edge
    assert rectangles_of(shapely.box(0, 0, 3, 3).difference(shapely.box(1, 1, 2, 2))) is not None


def _reference(d, src, dst):
    idx = d._obstacle_index()
    return shapely.area(shapely.intersection(pair_hull_geoms(d.cells, src, dst), idx.union)) > oi.TOUCH_TOL


@pytest.mark.parametrize("rects", [True, False])
@pytest.mark.parametrize("threads", [1, 2])
def test_obstacle_cases_equal_the_union_overlay_on_every_path(monkeypatch, rects, threads):
    monkeypatch.setattr(oi, "_CASE_THREADS", threads)
    monkeypatch.setattr(oi, "_MIN_PER_THREAD", 64)
    d = parse_grid_map(rooms_and_corridors(28, 28, seed=11))
    index = d._obstacle_index()
    if not rects:
        monkeypatch.setattr(index, "rects", None)
    else:
        assert index.rects is not None
    rng = np.random.default_rng(1)
    src = rng.integers(0, d.n_cells, 3000)
    dst = (src + rng.integers(1, 60, 3000)) % d.n_cells
    got = d.obstacle_cases(src, dst)
    np.testing.assert_array_equal(got, _reference(d, src, dst))
    assert 0.2 < got.mean() < 0.9


@pytest.mark.parametrize("rects", [True, False])
def test_overlaps_at_the_hulls_edge_are_decided_as_before(monkeypatch, rects):
    """Cells [0,1]^2 and [2,3]^2: the hull's edge from (1,0) to (3,2) runs inside the pair's
    bounding box. A wall reaching over that edge by 1e-3 is an obstacle case, one that stops
    short of it or only touches it is not; a sliver of the bounding box's frame never is."""
    from tubejax.model.geometry import Polytope
    cells = [Polytope.box([0.0, 0.0], [1.0, 1.0]), Polytope.box([2.0, 2.0], [3.0, 3.0])]
    lo = np.array([[0.0, 0.0], [2.0, 2.0]])
    hi = lo + 1.0
    hulls = lambda a, b: pair_hull_geoms(cells, a, b)            # noqa: E731
    for wall, expect in ((shapely.box(2.0, 0.0, 3.0, 1.0 + 1e-3), True),   # over the edge near (2, 1): 5e-7
                         (shapely.box(2.5, 0.0, 3.0, 1.0), False),         # below the edge: outside the hull
                         (shapely.Polygon([(1, 0), (3, 0), (3, 2)]), False),  # exactly the outside triangle
                         (shapely.box(3.0 - 1e-13, 2.0, 4.0, 3.0), False),   # 1e-13 into cell 1: below the tolerance
                         (shapely.box(3.0, 0.0, 4.0, 3.0), False)):          # touching the frame
        index = oi.ObstacleIndex([wall], 2, tile=4.0)
        if not rects:
            monkeypatch.setattr(index, "rects", None)
        got = bool(index.pair_cases(cells, lo, hi, np.array([0]), np.array([1]), hulls)[0])
        ref = bool(shapely.area(shapely.intersection(hulls(np.array([0]), np.array([1]))[0], wall)) > oi.TOUCH_TOL)
        assert got == ref == expect
