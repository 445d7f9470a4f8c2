"""The radius-parametric LP (docs/math/radius.md), dense and by HiGHS: hand-derived optima, the
meaning of rho* (monotonicity of Problem 2 in the radius), the W0 / rho conventions, rho_max
and the operator's radius form against the dense builder."""

import math

import jax
import numpy as np
import pytest

from tubejax.model.geometry import Ball, Polytope, convex_hull_of, support
from tubejax.lp.declarations.openloop_operator import (openloop_dims, openloop_matvec,
                                                       openloop_rhs)
from tubejax.lp.declarations.openloop_operator_data import build_openloop_data
from tubejax.lp.declarations.openloop_operator import unpack_x as ol_unpack_x
from tubejax.lp.evidence.radius_lp import build_radius_lp, radius_highs_optimum
from tubejax.lp.evidence.registry import FORMULATIONS
from tubejax.lp.evidence.verdict import highs_verdict
from tubejax.lp.declarations.radius_disturbance import (rho_max_bound, scaled_disturbance, unit_disturbance,
                                                        with_disturbance)
from tubejax.lp.declarations.tube_lp import ROW_C4, build_tube_lp, tube_violation
from tubejax.lp.declarations.tube_variables import TubeIndex
from tubejax.model.problem import TubeProblem
from tubejax.lp.declarations.margin_operator import pack
from tubejax.lp.declarations.tube_operator import tube_dims, tube_matvec, tube_rhs, unpack_x
from tubejax.lp.declarations.tube_operator_data import build_tube_data
from tubejax.model.zshape.kinds import make_z
from tubejax.lp.engines.highs import solve_margin_lp
from tubejax.model.problem import pair_problem
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.workspace.gridmap import load_grid_map


def radius_edge_verdict(prob, W0, rho, form="tube"):
    """The evidence for an edge claimed at radius ``rho``: HiGHS's margin form at ``W = rho W0``
    (``W0=None``: the unit disturbance of the system's ``W``), re-checked in float64."""
    W0 = unit_disturbance(prob.system.W)[0] if W0 is None else W0
    return highs_verdict(with_disturbance(prob, scaled_disturbance(W0, rho)), "highs", form=form)


def interval_problem(a, L, r=0.1):
    """x+ = x + u + w, |u| <= a, |w| <= r, from [0, 1] to [1, 2] (S = [0, 2])."""
    sysm = LinearSystem(A=np.eye(1), B=np.eye(1), U=box_input_set(a, 1), W=Ball(1, r))
    Pi, Pj = Polytope.box([0.0], [1.0]), Polytope.box([1.0], [2.0])
    S = convex_hull_of(Pi, Pj)
    return TubeProblem(sysm, Pi, Pj, S, make_z("box", Pi), L, S.bounding_box())


@pytest.mark.parametrize("a", [0.5, 0.6])
@pytest.mark.parametrize("L", [1, 2, 3, 4, 7])
def test_1d_integrator_rho_star_by_hand(a, L):
    # Tube: the lower tube end gains at most a - rho per step (u = a, worst w = -rho) and must
    # go from 0 to 1 in L steps, so rho* = a - 1/L (the width is never binding; rho_max = 1/2).
    # Open loop: vertex 0 needs L a >= 1 + L rho; vertex 1 must end in [1 + L rho, 2 - L rho],
    # so rho* = min(a - 1/L, 1/(2L)).
    prob = interval_problem(a, L)
    tube, _ = radius_highs_optimum(prob, "tube")
    ol, _ = radius_highs_optimum(prob, "openloop")
    assert tube == pytest.approx(a - 1.0 / L, abs=1e-9)
    assert ol == pytest.approx(min(a - 1.0 / L, 1.0 / (2 * L)), abs=1e-9)


def test_rho_star_is_independent_of_the_problems_own_radius():
    for r in (0.0, 0.1, 0.4):
        assert radius_highs_optimum(interval_problem(0.5, 4, r), "tube")[0] == pytest.approx(0.25, abs=1e-9)


@pytest.fixture(scope="module")
def grid_problems(corridor_path, paper_system):
    dec = load_grid_map(corridor_path)
    sysm = paper_system(0.2)
    Z = [make_z("box", c) for c in dec.cells]
    rng = np.random.default_rng(3)
    out = []
    while len(out) < 8:
        i, j = (int(v) for v in rng.integers(dec.n_cells, size=2))
        near = np.linalg.norm(dec.cells[i].vertices.mean(0) - dec.cells[j].vertices.mean(0)) <= 2.5
        if i != j and near:
            out.append(pair_problem(dec, sysm, Z[i], i, j, int(rng.integers(2, 9))))
    return out


@pytest.mark.parametrize("form", ["tube", "openloop"])
def test_problem_2_is_feasible_exactly_up_to_rho_star(grid_problems, form):
    """Monotonicity: Problem 2 at W = rho W0 (margin form, HiGHS, evidence re-checked) is
    feasible just below rho* and infeasible just above."""
    W0 = Ball(2, 1.0)
    n_pos = 0
    for prob in grid_problems:
        rho, _ = radius_highs_optimum(prob, form)
        for d in (1e-6, 1e-3):
            above = radius_edge_verdict(prob, W0, max(rho + d, 0.0), form)
            assert above.status == "infeasible", (rho, d)
            if rho - d >= 0:
                below = radius_edge_verdict(prob, W0, rho - d, form)
                assert below.status == "edge" and below.tube is not None, (rho, d)
                n_pos += 1
    assert n_pos >= 4                                       # the sample has edges at some radius


def test_edge_verdict_stores_the_tube_of_that_radius():
    prob = interval_problem(0.5, 4)
    v = radius_edge_verdict(prob, Ball(1, 1.0), 0.2)
    assert v.status == "edge" and v.provenance == "highs"
    # the tube is for W of radius 0.2: it passes the checker there and fails it at 0.3
    assert tube_violation(with_disturbance(prob, Ball(1, 0.2)), v.tube) <= 1e-9
    assert tube_violation(with_disturbance(prob, Ball(1, 0.3)), v.tube) > 1e-3


def test_disturbance_conventions_put_rho_in_user_units():
    W0, rho = unit_disturbance(Ball(2, 0.3))
    assert isinstance(W0, Ball) and W0.radius == 1.0 and rho == 0.3
    W0, rho = unit_disturbance(Polytope.box([-0.1, -0.1], [0.1, 0.1]))
    assert rho == pytest.approx(0.1)
    np.testing.assert_allclose(W0.bounding_box()[1], [1.0, 1.0])
    diamond = Polytope.from_vertices([[0.15, 0], [0, 0.15], [-0.15, 0], [0, -0.15]])
    W0, rho = unit_disturbance(diamond)
    assert W0 is diamond and rho == 1.0
    rect = Polytope.box([-0.1, -0.2], [0.1, 0.2])               # not a cube: scale factor
    assert unit_disturbance(rect)[1] == 1.0
    with pytest.raises(ValueError, match="interior of W"):
        unit_disturbance(Polytope.from_vertices([[0, 0], [1, 0], [0, 1]]))
    d = np.random.default_rng(0).standard_normal((20, 2))
    for W in (Ball(2, 0.3), Polytope.box([-0.1, -0.1], [0.1, 0.1]), diamond):
        W0, rho = unit_disturbance(W)
        np.testing.assert_allclose(support(scaled_disturbance(W0, rho), d), support(W, d), atol=1e-14)
    assert support(scaled_disturbance(diamond, 0.0), d).max() == 0.0
    with pytest.raises(ValueError, match="radius"):
        scaled_disturbance(Ball(2, 1.0), -0.1)


def test_box_disturbance_threshold_is_its_half_width(paper_system):
    """A box W = [-h, h]^2: Problem 2 feasible iff h <= rho* (rho in half-width units)."""
    dec = load_grid_map("conf/workspace/maps/corridor.txt")
    box = Polytope.box([-0.1, -0.1], [0.1, 0.1])
    sysm = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=box)
    prob = pair_problem(dec, sysm, make_z("box", dec.cells[0]), 0, 1, 5)
    rho, _ = radius_highs_optimum(prob, "tube")
    assert 0.05 < rho < 0.5
    for h, ok in ((rho - 1e-4, "edge"), (rho + 1e-4, "infeasible")):
        v = radius_edge_verdict(prob, None, h, "tube")
        assert v.status == ok
        assert isinstance(with_disturbance(prob, scaled_disturbance(unit_disturbance(box)[0], h)).system.W,
                          Polytope)


def test_rho_max_bound():
    sq = Polytope.box([3.0, 1.0], [4.0, 2.0])
    assert rho_max_bound(sq, Ball(2, 1.0)) == pytest.approx(0.5, abs=1e-11)
    assert rho_max_bound(sq, Polytope.box([-1, -1], [1, 1])) == pytest.approx(0.5, abs=1e-11)
    tri = Polytope.from_vertices([[0, 0], [2, 0], [0, 1]])
    a, b, c = 2.0, 1.0, math.sqrt(5.0)                          # inradius = area / semiperimeter
    inr = 1.0 / ((a + b + c) / 2)
    got = rho_max_bound(tri, Ball(2, 1.0))
    assert inr <= got <= inr + 1e-11                            # rigorous: never below
    assert rho_max_bound(tri, Ball(2, 1.0)) == got              # cached


@pytest.mark.parametrize("form", ["tube", "openloop"])
def test_radius_lp_structure(grid_problems, form):
    W0 = Ball(2, 1.0)
    for prob in grid_problems[:4]:
        lp = build_radius_lp(prob, W0, form)
        c = lp.t_coef
        assert np.all(c >= 0) and lp.t_min < 0 < lp.t_max
        if form == "tube":
            assert np.all((c > 0) == (lp.row_kind == ROW_C4))
            # C4 rows: rho's coefficient is sigma_W0 of the normalised H_z row, i.e. the rhs
            # offset of the margin form at radius 1 (build_tube_lp, W = unit ball)
            ref = build_tube_lp(with_disturbance(prob, W0))
            zero = build_tube_lp(with_disturbance(prob, Ball(2, 0.0)))
            np.testing.assert_allclose(c, zero.g - ref.g, atol=1e-13)
            np.testing.assert_allclose(lp.g, zero.g)
            np.testing.assert_allclose(lp.lb, zero.lb)
        else:
            assert np.all(c > 0)
        # the reference point satisfies every row with rho = t_min, and the rows without rho strictly
        x = FORMULATIONS[form].radius.reference(prob)
        assert np.all(lp.G @ x + c * lp.t_min <= lp.g)
        assert np.all(lp.G[c == 0] @ x < lp.g[c == 0])
        assert np.all((lp.lb <= x) & (x <= lp.ub))
        # HiGHS solves it with the generalised t column; the optimum is inside the bounds
        res = solve_margin_lp(lp)
        assert res.status == "Optimal" and lp.t_min < res.margin < lp.t_max


def test_tube_operator_radius_form_matches_dense(grid_problems):
    probs = grid_problems[:4]
    W0 = Ball(2, 1.0)
    shape, data = build_tube_data(probs, W0=W0)
    assert shape.form == "radius" and data.dyn0_rho is not None
    nx, _ = tube_dims(shape)
    for b, pr in enumerate(probs):
        d = jax.tree_util.tree_map(lambda a: a[..., b:b + 1], data)
        K = pack(tube_matvec(shape, d, unpack_x(shape, np.eye(nx + 1))))
        g, mask = (pack(v)[:, 0] for v in tube_rhs(shape, d))
        lp = build_radius_lp(pr, W0, "tube")
        rows = mask > 0
        # the operator pads the horizon to the group's largest L: compare the real columns
        pad, own = TubeIndex(shape.L, 2, 4, 2), lp.index
        cols = np.concatenate([np.arange(pad.p_col(1, 0), pad.p_col(1, 0) + own.L * 2),
                               pad.eps_col(1) + np.arange(own.L),
                               pad.u_col(0, 0, 0) + np.arange(own.L * 4 * 2)])
        np.testing.assert_allclose(K[rows][:, cols], lp.G, atol=1e-14)
        np.testing.assert_allclose(K[rows, nx], lp.t_coef, atol=1e-14)
        np.testing.assert_allclose(g[rows], lp.g, atol=1e-14)


def test_openloop_operator_radius_form_matches_dense(grid_problems):
    W0 = Ball(2, 1.0)
    for pr in grid_problems[:4]:
        shape, d = build_openloop_data([pr], W0=W0)
        assert shape.form == "radius"
        nx, _ = openloop_dims(shape)
        K = pack(openloop_matvec(shape, d, ol_unpack_x(shape, np.eye(nx + 1))))
        g, mask = (pack(v)[:, 0] for v in openloop_rhs(shape, d))
        lp = build_radius_lp(pr, W0, "openloop")
        rows = mask > 0
        np.testing.assert_allclose(K[rows, :nx], lp.G, atol=1e-14)
        np.testing.assert_allclose(K[rows, nx], lp.t_coef, atol=1e-14)
        np.testing.assert_allclose(g[rows], lp.g, atol=1e-14)


def test_bad_form_is_refused(grid_problems):
    with pytest.raises(ValueError, match="form"):
        build_radius_lp(grid_problems[0], form="exact2d")
