"""Open-loop baseline (docs/math/open-loop.md): validation, hand cases, monotonicity, checker."""

from functools import partial
import json
from pathlib import Path

import numpy as np
import pytest

from tubejax.abstraction import build_abstraction
from tubejax.model.geometry import Ball, Polytope
from tubejax.lp.declarations.tube_lp import ROW_C2, ROW_C3, TubeLP
from tubejax.model.problem import TubeProblem
from tubejax.lp.engines.highs import solve_margin_lp
from tubejax.lp.declarations.openloop_lp import (OpenLoopIndex, OpenLoopLP, OpenLoopPlan, build_openloop_lp,
                                                    openloop_nominal, openloop_violation)
from tubejax.lp.declarations.openloop_families import disturbance_support
from tubejax.lp.evidence.verdict import highs_solver, highs_verdict
from tubejax.model.system import LinearSystem, box_input_set, one_norm_input_set
from tubejax.model.workspace.gridmap import load_grid_map

openloop_solve_batch = highs_solver("openloop")
openloop_highs_verdict = partial(highs_verdict, form="openloop")

VALIDATION = Path(__file__).resolve().parents[1] / "data" / "corridor_expected.json"
RADII = (0.0, 0.1, 0.2, 0.3)
Z4 = Polytope.box([-1.0, -1.0], [1.0, 1.0])


def system(r, B=0.5, U=None, A=None):
    return LinearSystem(A=np.eye(2) if A is None else A, B=B * np.eye(2),
                        U=box_input_set(1.0, 2) if U is None else U, W=Ball(2, r))


def two_cell_problem(sysm, L=1):
    """``P_i = [0,1]^2 -> P_j = [1,2] x [0,1]``, free case (``S = P_ij``)."""
    Pi = Polytope.box([0.0, 0.0], [1.0, 1.0])
    Pj = Polytope.box([1.0, 0.0], [2.0, 1.0])
    S = Polytope.box([0.0, 0.0], [2.0, 1.0])
    return TubeProblem(sysm, Pi, Pj, S, Z4, L, S.bounding_box())


@pytest.fixture(scope="module")
def corridor(corridor_path):
    return load_grid_map(corridor_path)


@pytest.fixture(scope="module")
def validation(corridor):
    """The open-loop abstraction of the validation case (r = 0.1, L_max = 10)."""
    return build_abstraction(corridor, system(0.1), L_max=10, solve_batch=openloop_solve_batch,
                             method="openloop", progress=False)


@pytest.fixture(scope="module")
def sweep(corridor):
    """Open-loop abstractions of the corridor for each radius in ``RADII`` (L_max = 5, for time)."""
    return {r: build_abstraction(corridor, system(r), L_max=5, solve_batch=openloop_solve_batch,
                                 method="openloop", progress=False) for r in RADII}


def edge_map(ts):
    return {(e.src, e.dst): e.L for e in ts.edges}


# ------------------------------------------------------------------ validation
def test_corridor_matches_validation(validation, corridor):
    case = json.loads(VALIDATION.read_text())["cases"]["open-loop, r = 0.1"]
    ts = validation
    assert ts.n_cells == case["n_cells"] == corridor.n_cells
    got = sorted([e.src, e.dst, e.L] for e in ts.edges)
    assert got == sorted(case["edges"])
    assert ts.n_edges == case["n_edges"] == 94
    assert ts.stats["n_unconfirmed"] == 0
    assert set(ts.stats["provenance"]) <= {"openloop-highs", "translate"}     # translates of non-edges
    assert {e.provenance for e in ts.edges} == {"openloop-highs"}


def test_every_edge_plan_reverifies(validation, sweep):
    for ts in [validation, *sweep.values()]:
        for k, e in enumerate(ts.edges):
            plan = ts.tubes[k]
            assert isinstance(plan, OpenLoopPlan)
            assert plan.u.shape == (e.L, 4, 2)
            prob = ts.problem(k)                       # pair_problem, Z ignored
            assert openloop_violation(prob, plan) <= 1e-9
            assert e.margin >= -1e-9


def test_edges_shrink_as_radius_grows(sweep):
    counts = [sweep[r].n_edges for r in RADII]
    assert all(a >= b for a, b in zip(counts, counts[1:])), counts
    assert counts[1] > counts[2]                       # 94, 94, 0, 0 on the corridor (L_max = 5)
    # feasibility at a fixed L is monotone in r: edge sets nest and minimal L never drops
    for r0, r1 in zip(RADII, RADII[1:]):
        small, big = edge_map(sweep[r0]), edge_map(sweep[r1])
        assert set(big) <= set(small)
        assert all(big[k] >= small[k] for k in big)


# ------------------------------------------------------------------ hand-derived cases
@pytest.mark.parametrize("r", [0.0, 0.1, 0.3, 0.5, 0.6])
def test_one_step_margin_by_hand(r):
    # B = I, U = [-1,1]^2, one step: each vertex moves by at most 1 per axis into
    # P_j ⊖ B_r = [1+r, 2-r] x [r, 1-r]; vertex (0,0) needs u_x in [1+r, 2-r] -> only r = 0.
    # With B = 2 I each vertex's successor can be anywhere in its unit box, so it can sit in the
    # middle of an interval of width 1 - 2r: the margin, a state-space distance, is (1 - 2r) / 2
    # (feasible iff r <= 1/2).
    prob = two_cell_problem(system(r, B=2.0))
    v = openloop_highs_verdict(prob)
    assert v.margin == pytest.approx((1 - 2 * r) / 2, abs=1e-9)
    assert v.status == ("edge" if r <= 0.5 else "infeasible")
    if v.status == "edge":
        x = openloop_nominal(prob, v.tube.u)
        assert np.all(x[1] >= [1 + r - 1e-9, r - 1e-9]) and np.all(x[1] <= [2 - r + 1e-9, 1 - r + 1e-9])
    prob1 = two_cell_problem(system(r, B=1.0))
    v1 = openloop_highs_verdict(prob1)
    assert v1.status == ("edge" if r == 0 else "infeasible")


def test_two_step_case_by_hand():
    # B = I, r = 0.2, L = 2: D_2 has support 0.4, target [1.4, 1.6] x [0.4, 0.6]; the
    # step-1 states must lie in S ⊖ B_0.2 = [0.2, 1.8] x [0.2, 0.8]; reachable.
    prob = two_cell_problem(system(0.2, B=1.0), L=2)
    np.testing.assert_allclose(disturbance_support(prob.system, prob.target.H, 2),
                               [[0] * 4, [0.2] * 4, [0.4] * 4])
    v = openloop_highs_verdict(prob)
    assert v.status == "edge" and v.margin > 0
    x = v.tube.states(prob)
    assert x.shape == (3, 4, 2)
    assert np.all((x[2] >= [1.4 - 1e-9, 0.4 - 1e-9]) & (x[2] <= [1.6 + 1e-9, 0.6 + 1e-9]))
    assert np.all((x[1] >= [0.2 - 1e-9, 0.2 - 1e-9]) & (x[1] <= [1.8 + 1e-9, 0.8 + 1e-9]))


def test_non_box_input_set_uses_hard_rows():
    prob = two_cell_problem(system(0.1, B=2.0, U=one_norm_input_set(1.0, 2)))
    lp = build_openloop_lp(prob)
    assert lp.G_hard.shape == (4 * 4, 8)               # 4 facets of the 1-norm ball x 4 vertices
    v = openloop_highs_verdict(prob)
    assert v.status == "edge"
    assert np.all(np.abs(v.tube.u).sum(axis=-1) <= 1 + 1e-9)
    assert openloop_violation(prob, v.tube) <= 1e-9


# ------------------------------------------------------------------ LP data and checker
def test_lp_layout():
    assert OpenLoopLP._fields == TubeLP._fields
    prob = two_cell_problem(system(0.1), L=3)
    lp = build_openloop_lp(prob)
    ix = lp.index
    assert ix == OpenLoopIndex(3, 4, 2) and ix.size == 24 and lp.G.shape == (lp.g.size, 24)
    assert np.sum(lp.row_kind == ROW_C2) == 2 * 4 * 4 and np.sum(lp.row_kind == ROW_C3) == 4 * 4
    # rows per unit of the facet normal (a state-space distance): each input block is H_f A^s B
    blocks = np.linalg.norm(lp.G.reshape(-1, 3, 4, 2), axis=-1)               # (rows, L, n_v)
    np.testing.assert_allclose(blocks[blocks > 0], np.linalg.norm(prob.system.B, 2))
    np.testing.assert_allclose(lp.lb, -1.0) and np.testing.assert_allclose(lp.ub, 1.0)
    u = np.random.default_rng(0).uniform(-1, 1, (3, 4, 2))
    x = ix.pack(OpenLoopPlan(u))
    assert ix.split(x).u.tolist() == u.tolist()
    assert x[ix.u_col(2, 1, 1)] == u[2, 1, 1]


def test_lp_rows_agree_with_the_checker():
    """The assembled rows and the forward-simulated check agree on feasibility (rotation A)."""
    th = 0.4
    A = 1.1 * np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    prob = two_cell_problem(system(0.05, B=0.7, A=A), L=3)
    lp = build_openloop_lp(prob)
    res = solve_margin_lp(lp)                          # the optimum passes the checker
    assert res.margin > 0
    plan = lp.index.split(res.x)
    assert openloop_violation(prob, plan) <= 1e-9
    rng = np.random.default_rng(1)
    seen = set()
    for scale in np.linspace(0.02, 1.0, 300):          # perturbations of the optimum, both sides
        u = np.clip(plan.u + rng.normal(0.0, scale, plan.u.shape), -1, 1)
        row = np.max(lp.G @ lp.index.pack(OpenLoopPlan(u)) - lp.g)
        viol = openloop_violation(prob, u)
        assert (row <= 1e-12) == (viol <= 1e-12), (row, viol)
        seen.add(bool(viol <= 1e-12))
    assert seen == {True, False}


def test_checker_rejects_corrupted_plans(validation):
    ts = validation
    k = next(k for k, e in enumerate(ts.edges) if e.margin > 1e-6)
    prob, u = ts.problem(k), ts.tubes[k].u
    assert openloop_violation(prob, u) <= 1e-9
    bad = u.copy()
    bad[0, 0, 0] = 1.5                                 # outside U
    assert openloop_violation(prob, bad) == pytest.approx(0.5)
    assert openloop_violation(prob, np.zeros_like(u)) > 0.1   # nobody moves: target missed
    bad = u.copy()
    bad[-1, 2] -= 0.5 * np.sign(bad[-1, 2] + 1e-3)     # one vertex's last input pushed away
    assert openloop_violation(prob, bad) > 1e-3
    assert openloop_violation(prob, u[:-1]) == float("inf")
    nan = u.copy()
    nan[0, 0, 0] = np.nan
    assert openloop_violation(prob, nan) == float("inf")


def test_bad_t_max():
    with pytest.raises(ValueError, match="t_max"):
        build_openloop_lp(two_cell_problem(system(0.1)), t_max=0.0)
