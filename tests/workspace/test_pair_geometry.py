"""Pair hulls and the obstacle case of many pairs, against the one-pair definitions."""

import numpy as np
import shapely
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from tubejax.abstraction.candidates import all_pairs
from tubejax.errors import GeometryError
from tubejax.model.geometry import Polytope, convex_hull_of, meets_obstacles
from tubejax.model.geometry.obstacles import TOUCH_TOL
from tubejax.model.workspace import box_grid, parse_grid_map
from tubejax.model.workspace.generate import rooms_and_corridors
from tubejax.model.workspace.obstacle_index import ObstacleIndex, _box_pair_depth_bound
from tubejax.model.workspace.pair_hulls import (_pair_polygons, convex_hull_rings, convex_polygons, geos_pair_hull_geoms,
                                                pair_hull_geoms)


@settings(max_examples=30, deadline=None)
@given(st.lists(st.tuples(st.floats(-50, 50), st.floats(-50, 50)), min_size=3, max_size=20),
       st.integers(1, 5))
def test_vectorised_polygons_equal_from_convex_polygon_bit_for_bit(points, copies):
    hull = shapely.convex_hull(shapely.MultiPoint(points))
    if hull.geom_type != "Polygon" or hull.area < 1e-6:
        return
    geoms = np.array([shapely.affinity.translate(hull, 7.0 * k, -3.0 * k) for k in range(copies)])
    try:                              # rings with near-repeated vertices are refused by the reference
        refs = [Polytope.from_convex_polygon(shapely.get_coordinates(g.exterior)) for g in geoms]
    except GeometryError:
        assume(False)
    for got, ref in zip(convex_polygons(geoms), refs):
        for a, b in ((got.vertices, ref.vertices), (got.H, ref.H), (got.h, ref.h)):
            np.testing.assert_array_equal(a, b)


def _point_sets(seed: int) -> np.ndarray:
    """Point sets ``(K, 8, 2)`` made to be hard: integer grids (exactly collinear and repeated
    points), midpoints, and points moved off a line by one ulp."""
    rng = np.random.default_rng(seed)
    K = 400
    ints = rng.integers(-3, 4, size=(K, 8, 2)).astype(float)
    floats = rng.normal(size=(K, 8, 2)) * 10.0 ** rng.integers(-3, 4, size=(K, 1, 1))
    mid = floats.copy()
    mid[:, 3] = 0.5 * (mid[:, 0] + mid[:, 1])
    mid[:, 4] = mid[:, 2]
    ulp = mid.copy()
    ulp[:, 5] = np.nextafter(mid[:, 3], np.inf)
    return np.concatenate([ints, floats, mid, ulp])


def test_monotone_chain_hulls_keep_exactly_geos_extreme_points():
    """:func:`convex_hull_rings` against GEOS's ``convex_hull``: the same vertices,
    counter-clockwise, collinear and repeated points dropped; only the degenerate sets are left."""
    for seed in range(3):
        pts = _point_sets(seed)
        pts[0] = 1.0                                   # one point: degenerate
        pts[1, :, 0] = np.arange(8.0)                  # a segment: degenerate
        rings, left = convex_hull_rings(pts)
        answered = np.concatenate([ks for ks, _ in rings])
        assert sorted(answered.tolist() + left.tolist()) == list(range(len(pts)))
        for k in range(len(pts)):
            hull = shapely.convex_hull(shapely.MultiPoint(pts[k]))
            assert (hull.geom_type == "Polygon") == (k not in left)
        for ks, V in rings:
            area2 = np.sum(V[:, :, 0] * np.roll(V[:, :, 1], -1, axis=1) - np.roll(V[:, :, 0], -1, axis=1) * V[:, :, 1],
                           axis=1)
            assert np.all(area2 > 0)
            for k, ring in zip(ks.tolist(), V):
                hull = shapely.convex_hull(shapely.MultiPoint(pts[k]))
                assert sorted(map(tuple, ring.tolist())) == sorted(map(tuple, shapely.get_coordinates(hull)[:-1].tolist()))


def test_pair_polytopes_equal_geos_ones_bit_for_bit():
    """2-D pair hulls from the monotone chain equal GEOS's through :func:`convex_polygons`."""
    d = parse_grid_map("..#...\n......\n.##...\n......\n")
    cells = list(d.cells) + [Polytope.from_convex_polygon(np.array([[0.0, 0.0], [1.0, 0.1], [0.3, 0.9]])),
                       Polytope.from_convex_polygon(np.array([[0.5, 0.05], [1.0, 0.1], [2.0, 0.3]]))]
    src, dst = all_pairs(len(cells))
    for got, ref in zip(_pair_polygons(cells, src, dst), convex_polygons(geos_pair_hull_geoms(cells, src, dst))):
        for a, b in ((got.vertices, ref.vertices), (got.H, ref.H), (got.h, ref.h)):
            np.testing.assert_array_equal(a, b)
    geoms, ref = pair_hull_geoms(cells, src, dst), geos_pair_hull_geoms(cells, src, dst)
    assert all(shapely.equals_exact(a.normalize(), b.normalize(), 0.0) for a, b in zip(geoms, ref))


def test_nd_pair_hulls_equal_qhull_per_pair():
    d = box_grid([0, 0, 0, 0], [2, 2, 2, 2], [3, 3, 3, 3], obstacles=[([1, 0, 1, 0], [2, 2, 2, 2])])
    rng = np.random.default_rng(1)
    src = rng.integers(0, d.n_cells, 60)
    dst = (src + rng.integers(1, d.n_cells, 60)) % d.n_cells
    for P, i, j in zip(d.pair_hulls(src, dst), src, dst):
        ref = convex_hull_of(d.cells[min(i, j)], d.cells[max(i, j)])
        np.testing.assert_array_equal(P.vertices, ref.vertices)
        key = lambda H, h: np.round(np.c_[H, h], 9)[np.lexsort(np.round(np.c_[H, h], 9).T[::-1])]  # noqa: E731
        np.testing.assert_allclose(key(P.H, P.h), key(ref.H, ref.h), atol=1e-12)
        assert np.all(P.H @ ref.vertices.T <= P.h[:, None] + 1e-12)     # every point inside
    # the H-reps alone (the vertex-LP rule's input) are the polytopes' facets, in 2-D too
    for dd in (d, parse_grid_map("...#\n.#..\n....\n")):
        s2, d2 = src % dd.n_cells, dst % dd.n_cells
        s2, d2 = s2[s2 != d2], d2[s2 != d2]
        for P, (H, h) in zip(dd.pair_hulls(s2, d2), dd.pair_hull_hreps(s2, d2)):
            np.testing.assert_array_equal(P.H, H)
            np.testing.assert_array_equal(P.h, h)


def reference_cases(d, src, dst):
    return np.array([meets_obstacles(convex_hull_of(d.cells[i], d.cells[j]), d.obstacles)
                     for i, j in zip(src, dst)])


def test_obstacle_cases_match_the_union_rule_on_a_generated_map():
    d = parse_grid_map(rooms_and_corridors(30, 30, seed=3))
    rng = np.random.default_rng(0)
    src = rng.integers(0, d.n_cells, 400)
    dst = (src + rng.integers(1, 40, 400)) % d.n_cells
    got = d.obstacle_cases(src, dst)
    np.testing.assert_array_equal(got, reference_cases(d, src, dst))
    assert 0.2 < got.mean() < 0.9
    assert "obstacle_case" not in d._cache                                  # nothing all-pairs was built
    assert d.obstacle_case(int(src[0]), int(dst[0])) == got[0]


def test_obstacle_pieces_tile_the_union():
    d = parse_grid_map(rooms_and_corridors(40, 40, seed=5))
    index = ObstacleIndex(d.obstacles, 2, tile=4.0)
    assert max(shapely.get_num_coordinates(p) for p in shapely.get_parts(index.union)) > 64
    np.testing.assert_allclose(shapely.area(index.pieces).sum(), index.union.area, rtol=1e-12)
    assert shapely.get_num_coordinates(index.pieces).max() < shapely.get_num_coordinates(index.union)
    inter = shapely.intersection(index.pieces[:, None], index.pieces[None, :])   # disjoint interiors
    area = shapely.area(inter)
    np.fill_diagonal(area, 0.0)
    assert area.max() < 1e-12


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2 ** 31 - 1))
def test_box_obstacle_cases_match_the_overlap_lp(seed):
    """Closed-form box test against the LP, boxes that touch included (grid-aligned corners)."""
    rng = np.random.default_rng(seed)
    obstacles = []
    for _ in range(rng.integers(1, 4)):
        lo = rng.integers(0, 4, 3) / 2.0                                    # on the cell grid: touching
        if rng.random() < 0.5:
            lo = lo + rng.uniform(-0.3, 0.3, 3)                             # or anywhere
        obstacles.append((lo, lo + rng.uniform(0.3, 1.2, 3)))
    try:
        d = box_grid([0, 0, 0], [2, 2, 2], [4, 4, 4], obstacles=obstacles)
    except ValueError:
        return
    src, dst = all_pairs(d.n_cells)
    pick = rng.choice(len(src), min(len(src), 300), replace=False)
    np.testing.assert_array_equal(d.obstacle_cases(src[pick], dst[pick]),
                                  reference_cases(d, src[pick], dst[pick]))


def test_box_depth_bound_hand_cases():
    lo_i, hi_i = np.array([[0.0, 0.0]]), np.array([[1.0, 1.0]])
    lo_j, hi_j = np.array([[2.0, 2.0]]), np.array([[3.0, 3.0]])
    # the diagonal hull passes through the unit square [1, 2]^2: depth along λ = 1/2 is 1/2
    s, slack = _box_pair_depth_bound(lo_i, hi_i, lo_j, hi_j, np.array([[1.0, 1.0]]), np.array([[2.0, 2.0]]))
    np.testing.assert_allclose(s, 0.5, atol=1e-15)
    assert slack[0] < 1e-15
    # an obstacle touching the hull along the face x = 3 of P_j: s* = 0 (depth 0)
    s, _ = _box_pair_depth_bound(lo_i, hi_i, lo_j, hi_j, np.array([[3.0, 2.0]]), np.array([[4.0, 3.0]]))
    assert abs(s[0]) < 1e-15
    # apart: the obstacle [3, 4] x [0, 1] is a unit away from the band
    s, _ = _box_pair_depth_bound(lo_i, hi_i, lo_j, hi_j, np.array([[3.0, 0.0]]), np.array([[4.0, 1.0]]))
    assert s[0] < -0.1


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2 ** 31 - 1), dim=st.sampled_from([3, 4]))
def test_boxes_meeting_obstacles_equal_the_all_pairs_test(seed, dim):
    """The obstacles a pair's box meets, found through the STRtree on two axes, are exactly those of
    the dense (pairs x obstacles) test, boxes that touch (on a half grid) or nearly touch included."""
    rng = np.random.default_rng(seed)

    def boxes(k):
        lo = rng.integers(0, 8, (k, dim)) / 2.0
        lo[rng.random(k) < 0.3] += rng.choice([-TOUCH_TOL, 0.5 * TOUCH_TOL, 2 * TOUCH_TOL])
        return lo, lo + rng.integers(1, 5, (k, dim)) / 2.0
    o_lo, o_hi = boxes(int(rng.integers(1, 40)))
    index = ObstacleIndex([Polytope.box(a, b) for a, b in zip(o_lo, o_hi)], dim, 1.0)
    lo, hi = boxes(200)
    meet = ~(np.any(lo[:, None, :] >= index.o_hi[None] - TOUCH_TOL, axis=2)
             | np.any(index.o_lo[None] >= hi[:, None, :] - TOUCH_TOL, axis=2))
    k, m = index._meeting(lo, hi)
    ref_k, ref_m = np.nonzero(meet)
    np.testing.assert_array_equal(k, ref_k)
    np.testing.assert_array_equal(m, ref_m)


def test_first_distinct_rows_are_those_of_np_unique():
    """``first_distinct_rows`` (by the rounded rows' bytes) keeps the rows ``np.unique`` of the rounded
    rows keeps (first occurrences, in order), as ``_unique_rows`` does with it, and counts as
    ``np.unique(..., axis=0)``: on qhull's triangulated facets of two boxes' hulls, and on rows with ``-0.0``, near-ties and a ``nan``."""
    import itertools
    from scipy.spatial import ConvexHull
    from tubejax.model.geometry.polytope import _DEDUP_DECIMALS, _unique_rows, first_distinct_rows

    def box(lo, hi):
        return np.array([[h if b else lo_ for b, lo_, h in zip(bits, lo, hi)]
                         for bits in itertools.product([0, 1], repeat=len(lo))])

    rng = np.random.default_rng(3)
    cases = []
    for n in (3, 4):
        for _ in range(10):
            lo = rng.integers(-3, 3, n) * 0.1
            P = np.concatenate([box(np.zeros(n), np.ones(n)), box(lo + 0.5, lo + 1.0 + rng.integers(1, 4, n) * 0.3)])
            E = ConvexHull(P).equations
            cases.append((E[:, :n], -E[:, n]))
    A = np.array([[0.0, 1.0], [-0.0, 1.0], [1e-12, 1.0], [0.3, 0.1 + 0.2], [0.3, 0.3], [np.nan, 1.0], [np.nan, 1.0]])
    cases += [(A[:5], np.zeros(5)), (A, np.zeros(7))]
    for A, b in cases:
        Ab = np.hstack([A, b[:, None]])
        want = A[np.sort(np.unique(np.round(Ab, _DEDUP_DECIMALS), axis=0, return_index=True)[1])]
        got = A[first_distinct_rows(Ab)]
        assert np.array_equal(got, want, equal_nan=True)
        assert np.array_equal(_unique_rows(A, b)[0], want, equal_nan=True)
        assert first_distinct_rows(got).size == len(np.unique(np.round(got, _DEDUP_DECIMALS), axis=0))
    assert first_distinct_rows(np.hstack([A[:5], np.zeros((5, 1))])).tolist() == [0, 3]      # -0.0, 1e-12 and 0.1 + 0.2 tie
