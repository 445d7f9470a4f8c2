"""Exact facets in the float H-rep's order by construction (no matching after the fact).

:func:`~tubejax.lp.evidence.exact_geometry.exact_hull_in_order` proposes one exact facet per float
row and accepts them only when they are exactly ``co(V)``; otherwise the exact data is
:func:`~tubejax.lp.evidence.exact_geometry.exact_hull` (its own order, still ``co(V)``) and the rational
LP builders raise ``BasisError``.
"""

from fractions import Fraction as F

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tubejax.errors import GeometryError
from tubejax.lp.evidence import exact_tube_violation
from tubejax.lp.evidence.basis import BasisError
from tubejax.lp.evidence.check import exact_openloop_violation, exact_plan_terms
from tubejax.lp.evidence.exact_geometry import ExactGeometryError, exact_hull, exact_hull_in_order
from tubejax.lp.evidence.exact_problem import exact_polytope, exact_system, exact_tube_data, in_float_order
from tubejax.lp.evidence.rational import QArray, decimal_rational
from tubejax.lp.evidence.rows import check_against_float, rational_openloop_lp, rational_tube_lp
from tubejax.lp.declarations.openloop_lp import build_openloop_lp
from tubejax.lp.declarations.tube_lp import build_tube_lp
from tubejax.model.problem import TubeProblem
from tubejax.model.geometry import Ball, Polytope
from tubejax.model.system import LinearSystem, box_input_set, one_norm_input_set


def facet_set(E) -> set:
    """``{(primitive normal, offset)}`` of an ExactPolytope."""
    return set(zip(map(tuple, E.H.tolist()), E.h.to_fractions().tolist()))


def unit_rows(E) -> tuple[np.ndarray, np.ndarray]:
    """The exact facets as float unit rows ``(n_f, n)`` and offsets ``(n_f,)``."""
    H = np.array([[float(v) for v in r] for r in E.H.tolist()])
    nrm = np.linalg.norm(H, axis=1)
    return H / nrm[:, None], E.h.to_float() / nrm


def assert_in_float_order(P) -> None:
    E = exact_polytope(P)
    assert in_float_order(P)
    Hu, hu = unit_rows(E)
    assert Hu.shape == P.H.shape
    np.testing.assert_allclose(Hu, P.H, rtol=0, atol=1e-9)
    np.testing.assert_allclose(hu, P.h, rtol=0, atol=1e-9 * (1 + np.max(np.abs(P.vertices))))
    assert facet_set(E) == facet_set(exact_hull(QArray.from_floats(P.vertices)))
    V = P.vertices.astype(object)
    for a, b in zip(E.H.tolist(), E.h.to_fractions().tolist()):      # every vertex inside, exactly
        assert all(sum(F(x) * y for x, y in zip(v, a)) <= b for v in V.tolist())


# ------------------------------------------------------------------ (a) random polytopes
@settings(max_examples=60, deadline=None, derandomize=True)
@given(st.integers(0, 2 ** 32 - 1), st.sampled_from([2, 3, 4]), st.booleans())
def test_random_polytopes_come_out_in_the_float_order(seed, n, grid):
    """Generic points, and points on a binary grid (exactly collinear / coplanar ones abound)."""
    rng = np.random.default_rng(seed)
    k = int(rng.integers(n + 1, n + 10))
    pts = rng.normal(size=(k, n)) * rng.uniform(0.01, 100) + rng.normal(size=n) * 50
    if grid:
        pts = np.round(rng.uniform(-4, 4, size=(k + 6, n)) * 8) / 8 + np.round(rng.normal(size=n) * 8)
    try:
        P = Polytope.from_vertices(pts)
    except GeometryError:
        return
    assert_in_float_order(P)


@pytest.mark.parametrize("n", [1, 2, 3, 4])
def test_boxes_and_one_norm_balls(n):
    lo = np.linspace(-1.3, 0.7, n)
    assert_in_float_order(Polytope.box(lo, lo + np.linspace(0.1, 3.0, n)))
    if n > 1:
        assert_in_float_order(one_norm_input_set(0.3, n))


def test_one_dimensional_rows():
    E = exact_hull_in_order(QArray.from_floats(np.array([[0.5], [-2.0], [0.25]])), [[1.0], [-1.0]], [0.5, 2.0])
    assert E.H.tolist() == [[1], [-1]] and E.h.to_fractions().tolist() == [F(1, 2), F(2)]
    with pytest.raises(ExactGeometryError):                        # one end only: not co(V)
        exact_hull_in_order(QArray.from_floats(np.array([[0.5], [-2.0]])), [[1.0]], [0.5])


# ------------------------------------------------------------------ (c) hand-derived cases
def test_hand_derived_triangle():
    # CCW from the bottom-left: (0,0) -> (3,0) -> (0,1); facets y >= 0, x + 3y <= 3, x >= 0
    P = Polytope.from_convex_polygon([[0.0, 0.0], [3.0, 0.0], [0.0, 1.0]])
    np.testing.assert_allclose(P.H, [[0, -1], [1 / np.sqrt(10), 3 / np.sqrt(10)], [-1, 0]], atol=1e-15)
    E = exact_polytope(P)
    assert E.H.tolist() == [[0, -1], [1, 3], [-1, 0]]
    assert E.h.to_fractions().tolist() == [0, 3, 0] and E.scale.tolist() == [1, 3, 1]


def test_hand_derived_collinear_ring_points_repeat_their_facet():
    # (1, 0) lies on the edge from (0,0) to (2,0): the float H-rep repeats y >= 0, so does the exact one
    P = Polytope.from_convex_polygon([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]])
    E = exact_polytope(P)
    assert in_float_order(P)
    assert E.H.tolist() == [[0, -1], [0, -1], [1, 0], [0, 1], [-1, 0]]
    assert E.h.to_fractions().tolist() == [0, 0, 2, 1, 0]
    assert facet_set(E) == facet_set(exact_hull(QArray.from_floats(P.vertices)))


def test_hand_derived_simplex_in_3d_and_decimal_input_set():
    P = Polytope.from_vertices([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    want = {(0, 0, -1): 0, (0, -1, 0): 0, (-1, 0, 0): 0, (1, 1, 1): 1}
    E = exact_polytope(P)
    for f, (a, b) in enumerate(zip(map(tuple, E.H.tolist()), E.h.to_fractions().tolist())):
        assert want[a] == b and np.allclose(np.array(a) / np.linalg.norm(a), P.H[f])
    # U by the decimal rule: 0.3 is 3/10, not the float; its facets in U's float order
    sysm = LinearSystem(A=np.eye(2), B=np.eye(2), U=one_norm_input_set(0.3, 2), W=Ball(2, 0.1))
    U = exact_system(sysm).U
    assert in_float_order(sysm.U, decimals=True)
    assert set(U.h.to_fractions().tolist()) == {F(3, 10)}
    np.testing.assert_allclose(unit_rows(U)[0], sysm.U.H, atol=1e-12)


# ------------------------------------------------------------------ (b) nearly collinear vertices
SQUARE = Polytope.box([0.0, 0.0], [2.0, 1.0])


def float_keeps_exact_drops():
    """(1, 1e-13) is inside the rectangle exactly; the ring keeps it as a vertex (two float facets)."""
    return Polytope.from_convex_polygon([[0.0, 0.0], [1.0, 1e-13], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]])


def exact_keeps_float_drops():
    """(1, -1e-14) is a vertex exactly; the float H-rep (the rectangle's) has no facet through it."""
    return Polytope(np.vstack([SQUARE.vertices, [[1.0, -1e-14]]]), SQUARE.H, SQUARE.h)


@pytest.mark.parametrize("make", [float_keeps_exact_drops, exact_keeps_float_drops])
def test_nearly_collinear_vertex_gives_co_v_exactly_and_no_rational_rows(make):
    P = make()
    with pytest.raises(ExactGeometryError):
        exact_hull_in_order(QArray.from_floats(P.vertices), P.H, P.h)
    assert not in_float_order(P)
    E, X = exact_polytope(P), exact_hull(QArray.from_floats(P.vertices))
    assert facet_set(E) == facet_set(X) and E.V.to_fractions().tolist() == X.V.to_fractions().tolist()
    # as the safe set of a tube problem: exact checks work on co(V), the rational LPs refuse
    sysm = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.05))
    src, dst = Polytope.box([0.2, 0.2], [0.8, 0.8]), Polytope.box([1.2, 0.2], [1.8, 0.8])
    prob = TubeProblem(sysm, src, dst, P, Polytope.box([-0.3, -0.3], [0.3, 0.3]), 2, P.bounding_box())
    assert facet_set(exact_tube_data(prob).safe) == facet_set(X)
    assert set(map(tuple, exact_plan_terms(prob).sets["safe"].H.num.tolist())) == {a for a, _ in facet_set(X)}
    p = np.array([[0.5, 0.5], [1.5, 0.5]])
    u = np.zeros((2, 4, 2))
    assert isinstance(exact_tube_violation(prob, (p, np.array([1.0, 1.0]), u)), F)
    assert isinstance(exact_openloop_violation(prob, u), F)
    with pytest.raises(BasisError, match="safe"):
        rational_tube_lp(prob, build_tube_lp(prob))
    with pytest.raises(BasisError, match="safe"):
        rational_openloop_lp(prob, build_openloop_lp(prob))


def test_a_rectangle_safe_set_gives_rational_rows_in_the_float_order():
    """The control of the case above: the same problem with the plain rectangle."""
    sysm = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=one_norm_input_set(1.0, 2), W=Ball(2, 0.05))
    src, dst = Polytope.box([0.2, 0.2], [0.8, 0.8]), Polytope.box([1.2, 0.2], [1.8, 0.8])
    prob = TubeProblem(sysm, src, dst, SQUARE, Polytope.box([-0.3, -0.3], [0.3, 0.3]), 2, SQUARE.bounding_box())
    lp = build_tube_lp(prob)
    check_against_float(rational_tube_lp(prob, lp), lp)
    olp = build_openloop_lp(prob)
    check_against_float(rational_openloop_lp(prob, olp), olp)


def test_same_vertices_other_float_order_keep_their_own_order():
    """The caches key the float H-rep too: a box built two ways (same vertices, rows in other
    orders) gives each its own exact row order, for ``U``, ``Z`` and ``sigma_W`` over ``Z``'s rows."""
    box = Polytope.box([-0.5, -0.5], [0.5, 0.5])
    ring = Polytope.from_vertices(box.vertices)
    assert np.array_equal(box.vertices, ring.vertices) and not np.array_equal(box.H, ring.H)
    W = Polytope.from_vertices([[-0.05, -0.02], [0.04, -0.03], [0.01, 0.06]])
    src, dst = Polytope.box([0.2, 0.2], [0.8, 0.8]), Polytope.box([1.2, 0.2], [1.8, 0.8])
    safe = Polytope.box([0.0, 0.0], [2.0, 1.0])
    for P in (box, ring):
        sysm = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=P, W=W)
        np.testing.assert_allclose(unit_rows(exact_system(sysm).U)[0], P.H, atol=1e-12)
        d = exact_tube_data(TubeProblem(sysm, src, dst, safe, P, 1, safe.bounding_box()))
        np.testing.assert_allclose(unit_rows(d.Z)[0], P.H, atol=1e-12)
        Wq = [[decimal_rational(x) for x in w] for w in W.vertices.tolist()]        # W: the decimal rule
        want = [max(sum(x * y for x, y in zip(w, a)) for w in Wq) for a in d.Z.H.tolist()]
        assert d.sigma_w.to_fractions().tolist() == want
