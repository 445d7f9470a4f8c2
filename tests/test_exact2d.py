"""Exact 2-D robust backward reachability: geometry, hand cases, validation, soundness."""

import json
from pathlib import Path

import numpy as np
import pytest
import shapely

from tubejax.abstraction import build_abstraction
from tubejax.reachability.exact2d import (backward_reach_sets, clip_halfplane, containment_slack,
                                   convex_hull_2d, erode, exact2d_solve_batch, exact2d_verdict,
                                   exact_edges, exact_pair, robust_pre)
from tubejax.model.geometry import Ball, Polytope
from tubejax.model.problem import TubeProblem
from tubejax.errors import InputError
from tubejax.lp.evidence.registry import FORMULATIONS
from tubejax.lp.evidence.verdict import highs_solver, highs_verdict
from tubejax.reachability.reference_solvers import reference_solver, reference_verdict
from tubejax.model.system import LinearSystem, box_input_set, one_norm_input_set
from tubejax.model.workspace.gridmap import load_grid_map, parse_grid_map

openloop_solve_batch = highs_solver("openloop")

VALIDATION = Path(__file__).resolve().parent / "data" / "corridor_expected.json"
SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
PI = Polytope.box([0.0, 0.0], [1.0, 1.0])
PJ = Polytope.box([1.0, 0.0], [2.0, 1.0])
PIJ = Polytope.box([0.0, 0.0], [2.0, 1.0])


def system(r, B=0.5, U=None, A=None, W=None):
    return LinearSystem(A=np.eye(2) if A is None else A, B=B * np.eye(2),
                        U=box_input_set(1.0, 2) if U is None else U, W=Ball(2, r) if W is None else W)


def as_box(poly):
    return poly.min(axis=0), poly.max(axis=0)


def edge_map(ts):
    return {(e.src, e.dst): e.L for e in ts.edges}


# ------------------------------------------------------------------ geometry
def test_convex_hull_2d():
    pts = np.vstack([SQUARE, [[0.5, 0.5], [0.5, 0.0], [1.0, 1.0]]])
    H = convex_hull_2d(pts)
    assert H.shape == (4, 2)
    assert shapely.Polygon(H).area == pytest.approx(1.0) and shapely.Polygon(H).exterior.is_ccw
    assert convex_hull_2d(np.zeros((0, 2))).shape == (0, 2)
    assert convex_hull_2d([[1.0, 2.0]] * 3).tolist() == [[1.0, 2.0]]
    assert convex_hull_2d([[0, 0], [1, 1], [2, 2]]).tolist() == [[0, 0], [2, 2]]


def test_clip_halfplane():
    lo, hi = as_box(clip_halfplane(SQUARE, [1.0, 0.0], 0.25))
    np.testing.assert_allclose(lo, [0, 0]) and np.testing.assert_allclose(hi, [0.25, 1])
    assert clip_halfplane(SQUARE, [1.0, 0.0], -0.1).shape == (0, 2)
    assert clip_halfplane(SQUARE, [1.0, 0.0], 2.0) is SQUARE
    seg = np.array([[0.0, 0.0], [1.0, 1.0]])
    np.testing.assert_allclose(clip_halfplane(seg, [1.0, 0.0], 0.5), [[0, 0], [0.5, 0.5]])


def test_erode_ball_and_polytope_exactly():
    lo, hi = as_box(erode(SQUARE, Ball(2, 0.2)))
    np.testing.assert_allclose(lo, [0.2, 0.2], atol=1e-11)
    np.testing.assert_allclose(hi, [0.8, 0.8], atol=1e-11)
    lo, hi = as_box(erode(SQUARE, Polytope.box([-0.1, -0.3], [0.2, 0.1])))
    np.testing.assert_allclose(lo, [0.1, 0.3], atol=1e-11)
    np.testing.assert_allclose(hi, [0.8, 0.9], atol=1e-11)
    assert erode(SQUARE, Ball(2, 0.6)).shape[0] == 0
    assert erode(SQUARE, Ball(2, 0.0)) is SQUARE
    assert erode(np.array([[0.0, 0.0], [1.0, 0.0]]), Ball(2, 0.01)).shape[0] == 0
    # a triangle: every edge moves inward by exactly r (no polygonal ball approximation)
    tri = np.array([[0.0, 0.0], [4.0, 0.0], [0.0, 3.0]])
    inner = shapely.Polygon(erode(tri, Ball(2, 0.5)))
    assert shapely.Polygon(tri).exterior.distance(inner) == pytest.approx(0.5, abs=1e-9)


def test_robust_pre_by_hand():
    # Pre(P_j) = (P_j ⊖ B_r) ⊕ (-B U) = [1+r, 2-r] x [r, 1-r] ⊕ [-1, 1]^2 (A = I, B = I)
    pre = robust_pre(PJ.vertices, system(0.2, B=1.0))
    lo, hi = as_box(pre)
    np.testing.assert_allclose(lo, [0.2, -0.8], atol=1e-11)
    np.testing.assert_allclose(hi, [2.8, 1.8], atol=1e-11)
    # A = 2 I halves it: A^{-1}(...)
    lo2, hi2 = as_box(robust_pre(PJ.vertices, system(0.2, B=1.0, A=2 * np.eye(2))))
    np.testing.assert_allclose(lo2, lo / 2, atol=1e-11) and np.testing.assert_allclose(hi2, hi / 2, atol=1e-11)


# ------------------------------------------------------------------ hand-derived pairs
@pytest.mark.parametrize("r, L, margin", [(0.0, 1, 0.0), (0.2, 2, 0.6), (0.5, 2, 0.0), (0.6, None, None)])
def test_exact_pair_by_hand(r, L, margin):
    # A = I, B = I, U = [-1,1]^2: one step needs r <= 0 (slack -r); two steps via
    # R_1 = S ∩ Pre(P_j) = [r, 2] x [0, 1] give Pre(R_1) ⊇ P_i iff r <= 1/2, slack 1 - 2r.
    got_L, got_m = exact_pair(system(r, B=1.0), PI, PJ, PIJ, L_max=4)
    assert got_L == L
    if L is not None:
        assert got_m == pytest.approx(margin, abs=1e-9)
    if r == 0.2:
        sets = backward_reach_sets(system(r, B=1.0), PJ, PIJ, 2)
        assert containment_slack(PI, sets[0]) == pytest.approx(-0.2, abs=1e-9)


def test_one_step_two_cells_b2():
    # B = 2 I: Pre(P_j) = [r-1, 4-r] x [r-2, 3-r] for r <= 1/2: an edge at L = 1 with slack 1 - r
    for r, slack in [(0.1, 0.9), (0.5, 0.5)]:
        assert exact_pair(system(r, B=2.0), PI, PJ, PIJ, 3) == (1, pytest.approx(slack, abs=1e-9))
    assert exact_pair(system(0.51, B=2.0), PI, PJ, PIJ, 3)[0] is None


def test_verdict_through_tube_problem():
    prob = TubeProblem(system(0.2, B=1.0), PI, PJ, PIJ, Polytope.box([-1, -1], [1, 1]), 2,
                       PIJ.bounding_box())
    v = exact2d_verdict(prob)
    assert v.status == "edge" and v.tube is None and v.provenance == "exact2d"
    assert v.margin == pytest.approx(0.6, abs=1e-9)
    prob1 = TubeProblem(prob.system, PI, PJ, PIJ, prob.Z, 1, PIJ.bounding_box())
    assert [x.status for x in exact2d_solve_batch([prob1, prob])] == ["infeasible", "edge"]


@pytest.mark.parametrize("method", sorted(FORMULATIONS))
def test_reference_solver_of_each_method(method):
    # an LP's reference is its HiGHS solver, exact2d's the polygon computation: the one switch on solves_lp
    solver, verdict = reference_solver(method), reference_verdict(method)
    if FORMULATIONS[method].solves_lp:
        assert solver is highs_solver(method)
        assert verdict.func is highs_verdict and verdict.keywords == {"form": method}
    else:
        assert solver is exact2d_solve_batch and verdict is exact2d_verdict


def test_reference_solver_of_an_unknown_method():
    for ask in (reference_solver, reference_verdict):
        with pytest.raises(InputError):
            ask("no such method")


def test_slack_agrees_with_uncovered_area(corridor):
    """The vertex-slack test and the area test ``area(P_i - Pre) <= 1e-9`` decide alike."""
    sysm = system(0.2)
    obst = corridor.obstacle_case_matrix()
    n_edge = 0
    for i in range(0, corridor.n_cells, 2):
        for j in range(corridor.n_cells):
            if i == j:
                continue
            safe = corridor.cells[i] if obst[i, j] else corridor.pair_hull(i, j)
            for pre in backward_reach_sets(sysm, corridor.cells[j], safe, 4):
                slack = containment_slack(corridor.cells[i], pre)
                Pi = shapely.Polygon(corridor.cells[i].vertices)
                gap = Pi.area if pre.shape[0] < 3 else Pi.difference(shapely.Polygon(pre)).area
                assert (slack >= -1e-9) == (gap <= 1e-9), (i, j, slack, gap)
                n_edge += slack >= -1e-9
    assert n_edge > 0


# ------------------------------------------------------------------ validation (corridor)
@pytest.fixture(scope="module")
def corridor(corridor_path):
    return load_grid_map(corridor_path)


@pytest.fixture(scope="module")
def cases():
    return json.loads(VALIDATION.read_text())["cases"]


@pytest.fixture(scope="module")
def corridor_r02(corridor):
    s = system(0.2)
    return {"exact": build_abstraction(corridor, s, L_max=10, solve_batch=exact2d_solve_batch,
                                       progress=False, method="exact2d"),
            "tube": build_abstraction(corridor, s, L_max=10, progress=False)}


def test_corridor_r02_exact_equals_tube_validation(corridor_r02, cases):
    expected = {(a, b): L for a, b, L in cases["tube, r = 0.2"]["edges"]}
    ex = corridor_r02["exact"]
    assert edge_map(ex) == expected and ex.n_edges == 78
    assert set(ex.stats["provenance"]) == {"exact2d"}
    assert all(e.margin >= -1e-9 for e in ex.edges)
    assert edge_map(corridor_r02["tube"]) == expected


def test_corridor_r005_exact_contains_tube(corridor, cases):
    ex = exact_edges(corridor, system(0.05), 10)
    tube = {(a, b): L for a, b, L in cases["tube, r = 0.05"]["edges"]}
    assert set(tube) <= set(ex)
    assert all(ex[k][0] <= tube[k] for k in tube)
    assert len(ex) == 102                        # measured: equal to the tube LP here too


# ------------------------------------------------------------------ soundness on small maps
SMALL = "..#.\n....\n.#..\n"
_rot = 1.05 * np.array([[np.cos(0.3), -np.sin(0.3)], [np.sin(0.3), np.cos(0.3)]])
SYSTEMS = {
    "ball r=0.1": system(0.1),
    "rotation A": system(0.1, A=_rot),
    "1-norm U, box W": system(0.0, U=one_norm_input_set(1.0, 2), W=Polytope.box([-0.1, -0.05], [0.1, 0.05])),
    "m=1 shear": LinearSystem(A=np.array([[1.0, 0.3], [0.0, 1.0]]), B=np.array([[0.3], [0.6]]),
                              U=box_input_set(1.0, 1), W=Ball(2, 0.05)),
}


@pytest.fixture(scope="module")
def small_runs():
    d = parse_grid_map(SMALL, "small")
    out = {}
    for name, s in SYSTEMS.items():
        out[name] = {
            "exact": {k: v[0] for k, v in exact_edges(d, s, 6).items()},
            "tube": edge_map(build_abstraction(d, s, L_max=6, progress=False)),
            "openloop": edge_map(build_abstraction(d, s, L_max=6, solve_batch=openloop_solve_batch,
                                                   method="openloop", progress=False)),
        }
    return out


@pytest.mark.parametrize("name", list(SYSTEMS))
def test_exact_is_an_upper_bound(small_runs, name):
    run = small_runs[name]
    ex = run["exact"]
    assert ex, "the exact reference found no edge"
    for method in ("tube", "openloop"):
        got = run[method]
        assert set(got) <= set(ex), (method, set(got) - set(ex))
        assert all(ex[k] <= got[k] for k in got), method


def test_exact_beats_tube_somewhere(small_runs):
    """Measured: with a 1-norm U and a box W the exact reference has strictly more edges."""
    run = small_runs["1-norm U, box W"]
    assert len(run["exact"]) > len(run["tube"])


# ------------------------------------------------------------------ errors
def test_argument_errors(corridor):
    with pytest.raises(ValueError, match="system: exact2d needs a 2-D state"):
        s3 = LinearSystem(A=np.eye(3), B=np.eye(3), U=box_input_set(1.0, 3), W=Ball(3, 0.1))
        backward_reach_sets(s3, Polytope.box([0] * 3, [1] * 3), Polytope.box([0] * 3, [1] * 3), 1)
    sing = system(0.1, A=np.array([[1.0, 0.0], [0.0, 0.0]]))
    with pytest.raises(ValueError, match="system.A must be invertible"):
        exact_edges(corridor, sing, 3)
    with pytest.raises(ValueError, match="L_max"):
        exact_edges(corridor, system(0.1), 0)
    with pytest.raises(ValueError, match="n_steps"):
        backward_reach_sets(system(0.1), PJ, PIJ, 0)
