"""Rationals, exact facets and exact safe-set proofs (tubejax.lp.evidence)."""

from fractions import Fraction as F
from itertools import product

import numpy as np
import pytest
import shapely
from scipy.spatial import ConvexHull
from hypothesis import given, settings
from hypothesis import strategies as st

from tubejax.model.geometry import Polytope
from tubejax.lp.evidence import QArray, binary_rational, decimal_rational, exact_hull, sqrt_upper
from tubejax.lp.evidence.exact_geometry import ExactGeometryError, _check_closed, _distinct
from tubejax.lp.evidence.rational import snap_rational
from tubejax.lp.evidence.safe_set import _verify_triangulation, near_pieces, obstacle_pieces, prove_safe_set, separated

finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


def test_rationalisation_rules():
    assert decimal_rational(0.2) == F(1, 5) and binary_rational(0.2) == F(0.2) != F(1, 5)
    assert decimal_rational(1e-7) == F(1, 10 ** 7) and decimal_rational(3.0) == 3
    assert snap_rational(0.4 / 2) == F(1, 5) and snap_rational(1 / 3) == F(1, 3)
    assert snap_rational(0.1 + 0.2) == F(0.1 + 0.2)              # 0.30000000000000004 is not 3/10
    with pytest.raises(ValueError, match="non-finite value nan"):
        decimal_rational(float("nan"))


@settings(max_examples=200, deadline=None, derandomize=True)
@given(st.fractions(min_value=0, max_value=10 ** 6, max_denominator=10 ** 9))
def test_sqrt_upper_is_a_tight_upper_bound(q):
    s = sqrt_upper(q)
    assert s * s >= q
    assert s * s == q or (s * (1 - F(1, 2 ** 60))) ** 2 < q       # within 2^-60 relative


@settings(max_examples=100, deadline=None, derandomize=True)
@given(st.lists(finite, min_size=1, max_size=8))
def test_qarray_holds_floats_exactly_and_round_trips_as_text(xs):
    a = QArray.from_floats(np.array(xs))
    assert a.to_fractions().tolist() == [F(x) for x in xs]
    assert np.array_equal(a.to_float(), np.array(xs))
    b = QArray.from_strings(a.to_strings())
    assert b.to_fractions().tolist() == a.to_fractions().tolist()


def test_qarray_rejects_bad_text():
    with pytest.raises(ValueError):
        QArray.from_strings(np.array(["1/0"]))
    with pytest.raises(ValueError, match="strings"):
        QArray.from_strings(np.array([1.0]))


@settings(max_examples=60, deadline=None, derandomize=True)
@given(st.lists(st.tuples(st.integers(-20, 20), st.integers(-20, 20)), min_size=3, max_size=14, unique=True))
def test_exact_hull_2d_contains_every_point_with_each_facet_supported(pts):
    V = np.array(pts, float) / 8.0                                  # dyadic: exact in floats
    if np.linalg.matrix_rank(V[1:] - V[0]) < 2:
        with pytest.raises(ExactGeometryError):
            exact_hull(V)
        return
    P = exact_hull(V)
    Q = [[F(c) for c in v] for v in V.tolist()]
    H, h = P.H.tolist(), P.h.to_fractions().tolist()
    for a, b in zip(H, h):
        vals = [a[0] * x + a[1] * y for x, y in Q]
        assert max(vals) == b                                       # every facet supports the set
        assert sum(v == b for v in vals) >= 2                       # and carries an edge
    hull = shapely.convex_hull(shapely.multipoints(V))
    assert len(H) == len(shapely.get_coordinates(hull)) - 1         # one facet per hull edge


@pytest.mark.parametrize("n", [3, 4])
def test_exact_hull_nd_boxes_and_simplices(n):
    cube = np.array(list(product([0.0, 1.0], repeat=n)))
    P = exact_hull(cube)
    assert len(P.H) == 2 * n                                       # coplanar simplices merged
    assert sorted(map(tuple, P.H.tolist())) == sorted(
        [tuple(int(s * (i == d)) for i in range(n)) for d in range(n) for s in (-1, 1)])
    rng = np.random.default_rng(n)
    pts = rng.integers(-5, 6, size=(12, n)).astype(float)
    P = exact_hull(pts)
    for a, b in zip(P.H.tolist(), P.h.to_fractions().tolist()):
        assert max(sum(ai * F(x) for ai, x in zip(a, v)) for v in pts.tolist()) == b
    with pytest.raises(ExactGeometryError):
        exact_hull(np.zeros((5, n)))


def _facet_dict(V, P_exact):
    """``{normal: (offset, tight point indices)}`` of an exact hull, in ``_distinct``'s numerators."""
    Q = QArray.coerce(V)
    pts, _ = _distinct(Q)
    out = {}
    for row, off in zip(P_exact.H.tolist(), P_exact.h.to_fractions().tolist()):
        b = off * Q.den
        assert b.denominator == 1
        tight = frozenset(i for i, p in enumerate(pts) if sum(x * y for x, y in zip(row, p)) == b)
        out[tuple(int(x) for x in row)] = (int(b), tight)
    return pts, out


def _max_unit_rows(H) -> set:
    H = np.asarray(H, dtype=float)
    return {tuple(r) for r in np.round(H / np.abs(H).max(axis=1, keepdims=True), 9).tolist()}


def _box_pairs(rng, n, count):
    cube = np.array(list(product([0.0, 1.0], repeat=n)))
    for _ in range(count):
        lo, w = rng.uniform(0, 1, n), rng.uniform(0.1, 0.5, n)
        yield np.vstack([lo + cube * w, lo + rng.integers(-2, 3, n) * w + cube * w])


@pytest.mark.parametrize("n", [3, 4, 5])
def test_nd_facets_equal_qhulls_and_any_missing_facet_is_refused(n):
    """The exact facets of random point sets, pair hulls of boxes (many coplanar points) and grid
    points are qhull's (merged coplanar facets, independently of the exact code), and the
    closure check refuses the facets with any one of them (or two) left out."""
    rng = np.random.default_rng(10 + n)
    cases = [rng.integers(-5, 6, size=(rng.integers(n + 2, 20), n)).astype(float) for _ in range(6)]
    cases += [rng.normal(size=(rng.integers(n + 2, 20), n)) for _ in range(4)]
    cases += list(_box_pairs(rng, n, 6))
    cases.append(np.array(list(product([0.0, 0.5, 1.0], repeat=n))))
    for V in cases:
        P = exact_hull(V)
        hull = ConvexHull(V)
        assert _max_unit_rows(P.H.tolist()) == _max_unit_rows(hull.equations[:, :n])
        pts, facets = _facet_dict(V, P)
        _check_closed(pts, facets)
        keys = list(facets)
        if len(keys) > 12:                           # 5-D random sets have ~100 facets: a sample
            keys = [keys[a] for a in rng.choice(len(keys), 12, replace=False)]
        for k in keys:
            with pytest.raises(ExactGeometryError, match="close up"):
                _check_closed(pts, {a: v for a, v in facets.items() if a != k})
        for a_, b_ in zip(keys, keys[1:]):
            with pytest.raises(ExactGeometryError, match="close up"):
                _check_closed(pts, {a: v for a, v in facets.items() if a not in (a_, b_)})


def test_triangulation_check_catches_a_missing_triangle():
    L = shapely.Polygon([(0, 0), (2, 0), (2, 1), (1, 1), (1, 2), (0, 2)])      # non-convex
    tris = [[tuple(p) for p in shapely.get_coordinates(g)[:3].tolist()]
            for g in shapely.get_parts(shapely.constrained_delaunay_triangles(L))]
    assert _verify_triangulation(L, tris) == ""
    assert "do not add up" in _verify_triangulation(L, tris[1:])
    holed = shapely.Polygon([(0, 0), (4, 0), (4, 4), (0, 4)], [[(1, 1), (1, 3), (3, 3), (3, 1)]])
    assert obstacle_pieces((holed,)).failure == ""


def test_safe_sets_touching_a_non_convex_obstacle_are_proven_and_overlaps_are_not():
    L = shapely.Polygon([(0, 0), (2, 0), (2, 1), (1, 1), (1, 2), (0, 2)])
    inner = Polytope.box([1.0, 1.0], [2.0, 2.0])                   # the notch: touches along two edges
    assert prove_safe_set(inner, (L,)) == (True, "")
    tri = Polytope.from_vertices([[1.0, 2.0], [2.0, 1.0], [2.0, 2.0]])   # touches at the corner only
    assert prove_safe_set(tri, (L,))[0]
    eps = 2.0 ** -40
    over = Polytope.box([1.0 - eps, 1.0], [2.0, 2.0])              # reaches 1e-12 into the obstacle
    ok, why = prove_safe_set(over, (L,))
    assert not ok and "separating" in why
    assert prove_safe_set(inner, (Polytope.box([1.0, 1.0], [3.0, 1.5]),))[0] is False
    assert prove_safe_set(inner, ())[0]


def test_separation_in_3d_uses_an_lp_normal_where_facets_do_not_suffice():
    # two tetrahedra around skew edges: the only separating planes contain both edge directions
    S = exact_hull(np.array([[-1.0, 0, 0], [1, 0, 0], [0, 1, 1], [0, -1, 1]]))
    O = exact_hull(np.array([[0, -1.0, -0.25], [0, 1, -0.25], [1, 0, -1.25], [-1, 0, -1.25]]))
    assert separated(S, O)
    O2 = exact_hull(np.array([[0, -1.0, 0.25], [0, 1, 0.25], [1, 0, -0.75], [-1, 0, -0.75]]))
    assert not separated(S, O2)                                    # these interpenetrate


def test_paper_map_obstacles_are_split_exactly_and_every_free_pair_is_proven():
    from pathlib import Path

    from tubejax.model.workspace import load_grid_map
    d = load_grid_map(Path(__file__).resolve().parents[2] / "conf" / "workspace" / "maps" / "paper.txt")
    ob = obstacle_pieces(d.obstacles)
    assert ob.failure == "" and len(ob.pieces) > 0
    M = d.obstacle_case_matrix()
    N = d.n_cells
    free = [(i, j) for i in range(N) for j in range(i + 1, N) if not M[i, j]]
    assert all(prove_safe_set(d.pair_hull(i, j), d.obstacles)[0] for i, j in free)
    # an obstacle-case hull is never "proven" free
    obst = [(i, j) for i in range(N) for j in range(i + 1, N) if M[i, j]][:40]
    assert not any(prove_safe_set(d.pair_hull(i, j), d.obstacles)[0] for i, j in obst)


def test_cached_safe_set_proofs_share_one_obstacle_key():
    """Every cached proof of a decomposition refers to one key of its obstacles: rebuilding the key
    (a WKB of every obstacle) per edge made the proof pass slow and held a copy per cache entry
    (+490 MB at 2,500 cells, several GB at 10,000)."""
    from pathlib import Path

    from tubejax.lp.evidence.exact_problem import _CACHE, clear_caches
    from tubejax.lp.evidence.safe_set import _obstacles_key
    from tubejax.model.workspace import load_grid_map
    clear_caches()
    d = load_grid_map(Path(__file__).resolve().parents[2] / "conf" / "workspace" / "maps" / "paper.txt")
    assert _obstacles_key(d.obstacles) is _obstacles_key(d.obstacles)
    assert _obstacles_key(list(d.obstacles)) == _obstacles_key(d.obstacles)    # a list: same value, no reuse
    for i, j in [(0, 1), (1, 2), (2, 3)]:
        prove_safe_set(d.pair_hull(i, j), d.obstacles)
    keys = [k for k in _CACHE if k[0] == "safe"]
    assert len(keys) == 3 and len({id(k[-1]) for k in keys}) == 1


def test_nd_hull_with_tiny_and_large_coordinates():
    """A 3-D box with a corner at 1e-300: the common power-of-two denominator makes the
    numerators overflow float, which once reached qhull as inf (a segmentation fault, found
    by the property tests); qhull now sees num / den, correctly rounded."""
    from tubejax.model.geometry import Polytope
    from tubejax.lp.evidence.exact_geometry import exact_hull
    from tubejax.lp.evidence.rational import QArray

    P = Polytope.box([1e-300, 0.0, 0.0], [1.0, 2.0, 3.0])
    H = exact_hull(QArray.from_floats(P.vertices))
    normals = sorted(tuple(int(x) for x in row) for row in H.H)
    assert normals == sorted([(-1, 0, 0), (1, 0, 0), (0, -1, 0), (0, 1, 0), (0, 0, -1), (0, 0, 1)])


@settings(max_examples=60, deadline=None, derandomize=True)
@given(st.lists(st.tuples(st.integers(0, 12), st.integers(0, 12), st.integers(0, 3), st.integers(0, 3)),
                min_size=1, max_size=12),
       st.tuples(st.integers(-1, 12), st.integers(-1, 12), st.integers(0, 5), st.integers(0, 5)), st.integers(2, 3))
def test_the_obstacle_index_proposes_every_piece_a_box_meets(boxes, query, n):
    """:func:`near_pieces` (an STRtree on the first two axes, then the strict test on every axis)
    against the strict box test over every piece: the same pieces, touching ones left out."""
    extra = [0.0] * (n - 2)
    obstacles = [Polytope.box([x / 2, y / 2, *extra], [x / 2 + 0.5 + w / 2, y / 2 + 0.5 + h / 2, *[1.0] * (n - 2)])
                 for x, y, w, h in boxes]
    ob = obstacle_pieces(tuple(obstacles))
    x, y, w, h = query
    lo, hi = np.array([x / 2, y / 2, *([0.5] * (n - 2))]), np.array([x / 2 + w / 2, y / 2 + h / 2, *([2.0] * (n - 2))])
    want = np.flatnonzero(np.all(ob.lo < hi, axis=1) & np.all(lo < ob.hi, axis=1))
    assert near_pieces(ob, lo, hi).tolist() == want.tolist()
