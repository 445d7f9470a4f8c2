import numpy as np
import pytest
from hypothesis import example, given, settings, strategies as st

from tubejax.model.geometry import (Ball, Polytope, canonical_vertex_order, convex_hull_of, interiors_intersect,
                                    sample_boundary, sample_uniform, support, support_maximizer)


def test_box_hrep_and_vertices_agree():
    P = Polytope.box([0, 0], [2, 1])
    assert np.allclose(P.vertices, [[0, 0], [2, 0], [2, 1], [0, 1]])  # CCW from bottom-left
    assert np.allclose(np.linalg.norm(P.H, axis=1), 1)
    assert np.all(P.contains(P.vertices))
    assert not P.contains([2.1, 0.5])


@pytest.mark.parametrize("n", [1, 2, 3, 4])
def test_is_box_is_exact(n):
    """``Polytope.box`` (and a 2-D box from its vertices) is a box; a rotation by 1e-9 rad, a parallelotope
    or a triangle is not: no tolerance. (qhull's facets of a box in 3-D and up need not be exactly axis-aligned;
    such a box is then not one, and takes the general path.)"""
    rng = np.random.default_rng(n)
    lo = rng.uniform(-2, 0, n)
    hi = lo + rng.uniform(0.5, 2, n)
    box = Polytope.box(lo, hi)
    assert box.is_box and (n != 2 or Polytope.from_vertices(box.vertices).is_box)
    if n >= 2:
        R = np.eye(n)
        R[:2, :2] = [[np.cos(1e-9), -np.sin(1e-9)], [np.sin(1e-9), np.cos(1e-9)]]
        tilted = Polytope.from_vertices(box.vertices @ R.T)
        shear = Polytope.from_vertices(box.vertices @ (np.eye(n) + np.triu(np.ones((n, n)), 1) / 2).T)
        assert tilted.n_vertices == shear.n_vertices == 2 ** n and not tilted.is_box and not shear.is_box
    if n == 2:
        assert not Polytope.from_vertices([[0, 0], [1, 0], [0, 1]]).is_box


def test_vertex_hrep_roundtrip_random():
    rng = np.random.default_rng(0)
    for n in (2, 3, 4):
        pts = rng.standard_normal((30, n))
        P = Polytope.from_vertices(pts)
        Q = Polytope.from_hrep(P.H * 2.5, P.h * 2.5)       # unnormalised rows are fine
        assert np.allclose(P.vertices, Q.vertices)
        assert np.allclose(np.linalg.norm(Q.H, axis=1), 1)
        assert np.all(P.contains(pts, tol=1e-9))          # every input point is inside its hull


def test_redundant_points_dropped_and_canonical_order():
    P = Polytope.from_vertices([[1, 1], [0, 1], [0.5, 0.5], [1, 0], [0, 0]])
    assert P.n_vertices == 4
    assert np.allclose(P.vertices[0], [0, 0])
    # counter-clockwise: positive signed area
    V = P.vertices
    area2 = np.sum(V[:, 0] * np.roll(V[:, 1], -1) - np.roll(V[:, 0], -1) * V[:, 1])
    assert area2 > 0


def test_nd_canonical_order_is_binary_corner_order():
    V = canonical_vertex_order(np.array([[1, 1, 1], [-1, -1, -1], [1, -1, -1], [-1, 1, -1],
                                         [1, 1, -1], [-1, -1, 1], [1, -1, 1], [-1, 1, 1]]))
    assert np.allclose(V[:4], [[-1, -1, -1], [1, -1, -1], [-1, 1, -1], [1, 1, -1]])


def test_hull_of_two_cells():
    H = convex_hull_of(Polytope.box([0, 0], [1, 1]), Polytope.box([1, 1], [2, 2]))
    assert H.n_vertices == 6
    assert H.contains([1, 1]) and not H.contains([0, 2])


def test_bad_hrep_refused():
    with pytest.raises(ValueError, match="unbounded"):
        Polytope.from_hrep(np.array([[1.0, 0], [0, 1]]), np.array([1.0, 1]))
    with pytest.raises(ValueError, match="empty"):
        Polytope.from_hrep(np.array([[1.0, 0], [-1, 0], [0, 1], [0, -1]]), np.array([-1.0, 0, 1, 1]))
    with pytest.raises(ValueError):
        Polytope.box([0, 0], [0, 1])


@settings(max_examples=30, deadline=None)
@given(st.floats(0.01, 2.0), st.lists(st.floats(-1, 1), min_size=2, max_size=2))
@example(r=1.0, a=[0.0, 8.216509611409862e-158])      # a tiny direction: its norm underflowed
def test_support_functions(r, a):
    a = np.array(a)
    B = Ball(2, r)
    assert np.isclose(support(B, a), r * np.linalg.norm(a))
    w = support_maximizer(B, a)
    assert np.isclose(a @ w, support(B, a)) and np.linalg.norm(w) <= r + 1e-12
    box = Polytope.box([-r, -2 * r], [r, 2 * r])
    assert np.isclose(support(box, a), r * abs(a[0]) + 2 * r * abs(a[1]))
    P = Polytope.from_vertices([[r, 0], [0, r], [-r, 0], [0, -r]])
    assert np.isclose(support(P, a), r * np.max(np.abs(a)))


def test_sampling_stays_in_sets():
    rng = np.random.default_rng(1)
    B = Ball(2, 0.3)
    assert np.all(np.linalg.norm(sample_uniform(B, rng, 500), axis=1) <= 0.3 + 1e-12)
    assert np.allclose(np.linalg.norm(sample_boundary(B, rng, 50), axis=1), 0.3)
    P = Polytope.from_vertices([[1, 0], [0, 1], [-1, 0], [0, -1]])
    assert np.all(P.contains(sample_uniform(P, rng, 300), tol=1e-12))
    on = sample_boundary(P, rng, 100)
    assert np.allclose(P.violation(on), 0, atol=1e-12)


def test_interior_intersection_touching_is_not_intersecting():
    import shapely

    P = Polytope.box([0, 0], [1, 1])
    assert not interiors_intersect(P, Polytope.box([1, 0], [2, 1]))       # shared face
    assert not interiors_intersect(P, Polytope.box([1, 1], [2, 2]))       # shared corner
    assert interiors_intersect(P, Polytope.box([0.9, 0.9], [2, 2]))
    assert not interiors_intersect(P, shapely.box(1, 0, 2, 1))
    # non-convex obstacle: an L-shape whose notch contains P
    L = shapely.Polygon([(0, 0), (3, 0), (3, 1), (1, 1), (1, 3), (0, 3)])
    assert interiors_intersect(Polytope.box([0.5, 0.5], [2, 2]), L)
    assert not interiors_intersect(Polytope.box([1, 1], [3, 3]), L)
    # any dimension, convex obstacles
    C = Polytope.box(np.zeros(4), np.ones(4))
    assert not interiors_intersect(C, Polytope.box(np.ones(4), 2 * np.ones(4)))
    assert interiors_intersect(C, Polytope.box(0.5 * np.ones(4), 2 * np.ones(4)))


@pytest.mark.parametrize("ring, match", [
    ([[0, 0], [1, 1], [2, 2]], r"no area \(its points are collinear\)"),
    ([[0, 0], [1, 0], [1, 0], [0, 1]], r"repeats a vertex: points 1 and 2 coincide at \[1.0, 0.0\]"),
    ([[0, 0], [1, 0], [1, 1], [0, 1], [0, 1]], "repeats a vertex"),
    ([[0, 0], [2, 0], [1, 0.5], [1, 2], [0, 2]], "not convex"),
    ([[0, 0], [1, 0], [np.nan, 1]], "must be finite"),
    ([[0, 0], [1, 0]], ">= 3 points"),
])
def test_from_convex_polygon_refuses_degenerate_rings(ring, match):
    """Issue 11 finding 6: collinear points gave a zero-area polytope, a duplicate vertex NaN facets."""
    from tubejax.errors import GeometryError

    with pytest.raises(GeometryError, match=match):
        Polytope.from_convex_polygon(ring)


def test_from_convex_polygon_keeps_collinear_edge_points_and_agrees_with_qhull():
    P = Polytope.from_convex_polygon([[0, 0], [0.5, 0], [1, 0], [1, 1], [0, 1], [0, 0]])
    Q = Polytope.from_vertices([[0, 0], [1, 0], [1, 1], [0, 1]])
    pts = np.random.default_rng(0).uniform(-0.5, 1.5, (500, 2))
    assert np.array_equal(P.contains(pts, tol=0), Q.contains(pts, tol=0))
    assert np.all(np.isfinite(P.H)) and np.allclose(np.linalg.norm(P.H, axis=1), 1)


def test_degenerate_vertex_sets_get_a_short_message_without_qhull_text():
    from tubejax.errors import GeometryError, InputError

    with pytest.raises(GeometryError) as info:
        Polytope.from_vertices([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    msg = str(info.value)
    assert "do not span R^3" in msg and "QH" not in msg and "\n" not in msg
    with pytest.raises(GeometryError, match="cannot span R\\^2"):
        Polytope.from_vertices([[0, 0], [1, 1]])
    with pytest.raises(GeometryError, match="finite"):
        Polytope.box([0, np.nan], [1, 1])
    with pytest.raises(GeometryError, match="finite"):
        Polytope.from_hrep(np.array([[1.0, 0], [-1, 0], [0, 1], [0, -1]]), np.array([1.0, 1, np.nan, 1]))
    assert issubclass(GeometryError, InputError) and issubclass(GeometryError, ValueError)
