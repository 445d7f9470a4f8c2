"""Exact (rational) checks of tubes and open-loop plans (docs/math/evidence.md#proof-levels)."""

from decimal import Decimal, getcontext
from fractions import Fraction as F

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import exact_reference as ref
from tubejax.abstraction import build_abstraction
from tubejax.model.geometry import Ball, Polytope
from tubejax.lp.evidence import (ExactPlan, ExactTube, QArray, exact_openloop_violation,
                                 exact_tube_violation, prove_evidence)
from tubejax.lp.evidence.exact_problem import ExactBall, disturbance_support_upper
from tubejax.lp.evidence.prove import inputs_into_u
from tubejax.lp.declarations.tube_lp import tube_violation
from tubejax.lp.declarations.tube_variables import Tube
from tubejax.model.problem import TubeProblem
from tubejax.lp.declarations.openloop_lp import OpenLoopPlan, openloop_violation
from tubejax.lp.evidence.verdict import highs_solver
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.workspace import load_grid_map

openloop_solve_batch = highs_solver("openloop")


def box(lo, hi):
    return Polytope.box(lo, hi)


def exact_tube(p, eps, u):
    return ExactTube(QArray.from_fractions(p), QArray.from_fractions(eps), QArray.from_fractions(u))


# --------------------------------------------------------------------------- hand-derived cases
def problem_1d(u_bound=0.6):
    """``x+ = x + u + w``, ``|u| <= 3/5``, ``W = [-1/10, 1/10]``, ``[0, 1] -> [1/2, 3/2]``, L = 1."""
    s = LinearSystem(A=np.eye(1), B=np.eye(1), U=box_input_set(u_bound, 1), W=box([-0.1], [0.1]))
    return TubeProblem(s, box([0.0], [1.0]), box([0.5], [1.5]), box([0.0], [1.5]), box([-1.0], [1.0]), 1,
                       (np.array([0.0]), np.array([1.5])))


def test_1d_zero_margin_tube_is_exact_while_floats_fail_by_1e17():
    # Q_1 = [p - eps, p + eps] = [1/2, 3/2] = P_j (C3 tight on both sides). C4 at vertex 0:
    # |0 + u_0 - 1| <= eps - 1/10 = 2/5 forces u_0 >= 3/5 = the bound of U: tight too.
    prob = problem_1d()
    for u1 in (F(-2, 5), F(0), F(2, 5)):                  # vertex 1: |1 + u_1 - 1| <= 2/5
        t = exact_tube([[F(1)]], [F(1, 2)], [[[F(3, 5)], [u1]]])
        assert exact_tube_violation(prob, t) == 0       # zero margin, exactly feasible
        assert prove_evidence(prob, t, resolve=False).level == "exact"
        v = tube_violation(prob, t.to_float())           # 0.6 and 0.1 rounded: floats miss by 2.8e-17
        assert 0 < v < 1e-15
        assert exact_tube_violation(prob, t) == ref.tube_violation(prob, *ref.as_lists(t))


def test_2d_zero_margin_tube_is_exact_while_floats_fail_by_1e17():
    # [0,1]^2 -> [1,2] x [0,1] in one step, x+ = x + u + w, |u_i| <= 6/5, ball W of radius 1/5,
    # Z = [-1,1]^2: Q_1 = (3/2, 1/2) + 1/2 Z = P_j; per axis |v_i + u_i - p_i| <= 1/2 - 1/5 = 3/10,
    # so the left vertices need u_x = 6/5 (the bound of U) and every u below sits on a bound.
    s = LinearSystem(A=np.eye(2), B=np.eye(2), U=box_input_set(1.2, 2), W=Ball(2, 0.2))
    S = box([0.0, 0.0], [2.0, 1.0])
    prob = TubeProblem(s, box([0.0, 0.0], [1.0, 1.0]), box([1.0, 0.0], [2.0, 1.0]), S, box([-1.0, -1.0], [1.0, 1.0]),
                       1, S.bounding_box())
    u = [[F(6, 5), F(1, 5)], [F(1, 5), F(4, 5)], [F(1, 5), F(-1, 5)], [F(6, 5), F(-4, 5)]]  # vertices CCW
    t = exact_tube([[F(3, 2), F(1, 2)]], [F(1, 2)], [u])
    assert exact_tube_violation(prob, t) == 0 == ref.tube_violation(prob, *ref.as_lists(t))
    assert 0 < tube_violation(prob, t.to_float()) < 1e-15
    # one input a hair beyond U, or the tube a hair too small: exact rejects
    u[0][0] += F(1, 10 ** 30)
    assert exact_tube_violation(prob, exact_tube([[F(3, 2), F(1, 2)]], [F(1, 2)], [u])) > 0
    u[0][0] -= F(1, 10 ** 30)
    small = exact_tube([[F(3, 2), F(1, 2)]], [F(1, 2) - F(1, 10 ** 30)], [u])
    assert exact_tube_violation(prob, small) > 0


def test_float_feasible_tube_that_violates_exactly_is_rejected():
    prob = problem_1d()
    t = exact_tube([[F(1)]], [F(1, 2) - F(10) ** -13], [[[F(3, 5)], [F(0)]]])   # C4 misses by 1e-13
    assert tube_violation(prob, t.to_float()) <= 1e-12
    assert exact_tube_violation(prob, t) == F(10) ** -13 == ref.tube_violation(prob, *ref.as_lists(t))
    pr = prove_evidence(prob, t.to_float(), resolve=False)
    assert pr.level == "float" and pr.exact_violation > 0 and "fails" in pr.note
    # U = [-0.1, 0.1] means |u| <= 1/10; the float 0.1 is 1/10 + 5.6e-18. [0, 1] -> [0, 1], L = 1,
    # Q_1 = [0, 1] (p = eps = 1/2): C4 needs |v + u - 1/2| <= 2/5, so u = 1/10 at v = 0, -1/10 at v = 1
    s = LinearSystem(A=np.eye(1), B=np.eye(1), U=box_input_set(0.1, 1), W=box([-0.1], [0.1]))
    P = box([0.0], [1.0])
    prob = TubeProblem(s, P, P, P, box([-1.0], [1.0]), 1, P.bounding_box())
    tube = Tube(np.array([[0.5]]), np.array([0.5]), np.array([[[0.1], [-0.1]]]))
    assert tube_violation(prob, tube) <= 1e-12
    assert exact_tube_violation(prob, tube) == F(0.1) - F(1, 10) == ref.tube_violation(prob, *ref.as_lists(tube))
    exact_u = exact_tube([[F(1, 2)]], [F(1, 2)], [[[F(1, 10)], [F(-1, 10)]]])
    assert exact_tube_violation(prob, exact_u) == 0
    assert prove_evidence(prob, tube, resolve=False).level == "float"     # the stored tube itself is no proof
    # pulling its inputs exactly into U (a candidate of prove_with_basis) gives the exact tube above
    pulled = inputs_into_u(prob, tube)
    assert pulled.u.to_fractions().ravel().tolist() == [F(1, 10), F(-1, 10)]
    assert exact_tube_violation(prob, pulled) == 0
    assert inputs_into_u(prob, exact_u) is None                       # nothing outside U: no candidate


def test_ball_w_with_irrational_norms_is_rounded_up():
    getcontext().prec = 60
    W = ExactBall(2, F(1, 5))
    a = np.array([[1, 1], [3, 4], [1, 2], [-7, 3]], dtype=object)
    sig = disturbance_support_upper(W, QArray(a, 1)).to_fractions()
    for (x, y), s in zip(a.tolist(), sig):
        true = Decimal(x * x + y * y).sqrt() / 5
        up = Decimal(s.numerator) / Decimal(s.denominator)
        assert up >= true and up - true < Decimal(10) ** -18     # an outward bound, 64 bits tight
    assert sig[1] == 1                                           # |(3, 4)| = 5 is exact
    # a diamond Z has normals (1, 1): sigma_W = r sqrt(2); tubes 1e-12 inside are proven,
    # tubes 1e-15 outside are not -- whatever floats say
    s = LinearSystem(A=np.eye(2), B=np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
    Z = Polytope.from_vertices([[0.0, -1.0], [1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]])
    Pi = box([0.0, 0.0], [1.0, 1.0])
    prob = TubeProblem(s, Pi, Pi, Pi, Z, 1, Pi.bounding_box())
    need = F(Decimal(2).sqrt() / 5)                              # eps >= r sqrt(2) / 1 for C4 with u = p - v
    p = [[F(1, 2), F(1, 2)]]
    u = [[[F(1, 2) - F(c) for c in v] for v in Pi.vertices.tolist()]]
    ok = exact_tube(p, [need + F(10) ** -12], u)
    bad = exact_tube(p, [need - F(10) ** -15], u)
    assert exact_tube_violation(prob, ok) <= 0
    assert exact_tube_violation(prob, bad) > 0
    assert tube_violation(prob, bad.to_float()) <= 1e-9


@pytest.mark.parametrize("W", [box([-0.1, -0.1], [0.1, 0.1]),
                               Polytope.from_vertices([[0.15, 0.0], [0.0, 0.15], [-0.15, 0.0], [0.0, -0.15]]),
                               Ball(2, 0.2)], ids=["box", "polytope", "ball"])
def test_box_polytope_and_ball_w_agree_with_the_independent_checker(W):
    s = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=W)
    ts = build_abstraction(load_grid_map_text("1..\n.#.\n..2\n"), s, L_max=4, progress=False)
    assert ts.n_edges > 10
    for k, e in enumerate(ts.edges):
        prob = ts.problem(k)
        evidence = e.exact if e.exact is not None else ts.tubes[k]
        got = exact_tube_violation(prob, evidence)
        assert got <= 0 and e.proof == "exact"
        assert got == ref.tube_violation(prob, *ref.as_lists(evidence))
        # HiGHS's own float tube: same verdict from both exact checkers
        raw = exact_tube_violation(prob, ts.tubes[k])
        assert raw == ref.tube_violation(prob, *ref.as_lists(ts.tubes[k]))


def load_grid_map_text(text):
    from tubejax.model.workspace import parse_grid_map
    return parse_grid_map(text)


def test_wrong_shapes_and_non_finite_values_are_named():
    prob = problem_1d()
    with pytest.raises(ValueError, match="tube eps has shape"):
        exact_tube_violation(prob, (np.ones((1, 1)), np.ones(2), np.ones((1, 2, 1))))
    with pytest.raises(ValueError, match="non-finite"):
        exact_tube_violation(prob, (np.full((1, 1), np.nan), np.ones(1), np.ones((1, 2, 1))))
    pr = prove_evidence(prob, Tube(np.full((1, 1), np.inf), np.ones(1), np.ones((1, 2, 1))), resolve=False)
    assert pr.level == "float" and "could not run" in pr.note and pr.violation == np.inf


# --------------------------------------------------------------------------- open loop
def test_openloop_hand_case_exact_zero_margin():
    # x+ = x + u + w, W = [-1/10, 1/10], [0, 1] -> [1/2, 3/2] in L = 2 with S = [0, 3/2]:
    # D_1 = W, D_2 = W + W: xbar_k(2) in [1/2 + 1/5, 3/2 - 1/5] = [7/10, 13/10];
    # from v_0 = 0 with |u| <= 7/20 the plan u = (7/20, 7/20) lands exactly on 7/10.
    s = LinearSystem(A=np.eye(1), B=np.eye(1), U=box_input_set(0.35, 1), W=box([-0.1], [0.1]))
    prob = TubeProblem(s, box([0.0], [1.0]), box([0.5], [1.5]), box([0.0], [1.5]), box([-1.0], [1.0]), 2,
                       (np.array([0.0]), np.array([1.5])))
    u = [[[F(7, 20)], [F(0)]], [[F(7, 20)], [F(0)]]]
    plan = ExactPlan(QArray.from_fractions(u))
    assert exact_openloop_violation(prob, plan) == 0 == ref.openloop_violation(prob, u)
    assert prove_evidence(prob, plan, resolve=False).level == "exact"
    # in floats the plan is on the boundary up to rounding (0.35 + 0.35 != 0.7; 0 or 1e-16 by the order
    # of operations): only the exact check decides it
    assert 0 <= openloop_violation(prob, plan.to_float()) < 1e-15
    u[1][0][0] -= F(10) ** -20
    assert exact_openloop_violation(prob, ExactPlan(QArray.from_fractions(u))) > 0


def test_openloop_abstraction_is_exact_and_matches_the_independent_checker(corridor_path):
    s = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=box([-0.05, -0.05], [0.05, 0.05]))
    ts = build_abstraction(load_grid_map(corridor_path), s, L_max=3, progress=False,
                           solve_batch=openloop_solve_batch, method="openloop")
    assert ts.n_edges > 20 and ts.stats["proof"]["exact"] == ts.n_edges
    for k, e in enumerate(ts.edges):
        prob = ts.problem(k)
        plan = e.exact if e.exact is not None else ts.tubes[k]
        assert isinstance(plan, (ExactPlan, OpenLoopPlan))
        got = exact_openloop_violation(prob, plan)
        assert got <= 0
        assert got == ref.openloop_violation(prob, ExactPlan.coerce(plan).u.to_fractions().tolist())


@settings(max_examples=60, deadline=None, derandomize=True)
@given(st.data())
def test_checkers_agree_on_random_problems_and_tubes(data):
    """Random decimal A, B, U, W, random cells and rational tubes: both exact checkers agree exactly."""
    n = data.draw(st.sampled_from([1, 2]), label="n")
    dec = st.integers(-9, 9).map(lambda k: k / 10)
    A = np.array([[data.draw(dec) + (i == j) for j in range(n)] for i in range(n)])
    B = np.array([[data.draw(dec) + 0.5 * (i == j) for j in range(n)] for i in range(n)])
    ub = data.draw(st.sampled_from([0.3, 1.0, 1.7]))
    W = box([-0.1] * n, [0.2] * n) if data.draw(st.booleans()) else \
        Polytope.from_vertices(np.vstack([0.15 * np.eye(n), -0.1 * np.ones((1, n))]))
    s = LinearSystem(A=A, B=B, U=box_input_set(ub, n), W=W)
    lo = np.array([data.draw(st.integers(0, 3)) / 4 for _ in range(n)])
    src, dst = box(lo, lo + 1), box(lo + 0.5, lo + 1.5)
    S = Polytope.from_vertices(np.vstack([src.vertices, dst.vertices]))
    L = data.draw(st.integers(1, 3), label="L")
    prob = TubeProblem(s, src, dst, S, box([-1.0] * n, [1.0] * n), L, S.bounding_box())
    q = st.fractions(min_value=-2, max_value=3, max_denominator=40)
    p = [[data.draw(q) for _ in range(n)] for _ in range(L)]
    eps = [data.draw(st.fractions(min_value=0, max_value=1, max_denominator=40)) for _ in range(L)]
    u = [[[data.draw(q) for _ in range(n)] for _ in range(2 ** n)] for _ in range(L)]
    t = exact_tube(p, eps, u)
    assert exact_tube_violation(prob, t) == ref.tube_violation(prob, p, eps, u)
    plan = [[[data.draw(q) for _ in range(n)] for _ in range(2 ** n)] for _ in range(L)]
    assert exact_openloop_violation(prob, ExactPlan(QArray.from_fractions(plan))) == ref.openloop_violation(prob, plan)
