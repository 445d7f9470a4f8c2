"""Pieces derived once from the row families, each against an independent computation."""

import itertools
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import linprog

from tubejax.abstraction import cross_sections
from tubejax.lp.evidence.rows import implied_tube_bounds
from tubejax.lp.declarations.tube_families import step_regions
from tubejax.model.workspace import parse_grid_map

from tubejax.lp.evidence.check import openloop_support_upper
from tubejax.lp.evidence.exact_problem import exact_polytope
from tubejax.lp.declarations.openloop_families import disturbance_support
from tubejax.lp.evidence.radius_lp import build_radius_lp
from tubejax.lp.declarations.radius_disturbance import with_disturbance
from tubejax.lp.declarations.row_families import ZERO_ROW, kept_rows, zero_rows
from tubejax.lp.declarations.tube_lp import build_tube_lp
from tubejax.lp.declarations.tube_variables import TubeIndex, implied_bounds, tube_variable_bounds
from tubejax.model.geometry import Ball, Polytope
from tubejax.model.problem import pair_problem
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.workspace.gridmap import load_grid_map
from tubejax.model.zshape.kinds import make_z


def test_zero_row_rule_on_hand_cases():
    # rows: with coefficients; zero and binding (g < 0); zero with g = 0; zero with g > 0
    zero = np.array([False, True, True, True])
    g = np.array([5.0, -1.0, 0.0, 2.0])
    assert kept_rows(zero, g).tolist() == [True, True, False, False]
    # the radius form also keeps a zero row that bounds rho (c > 0)
    assert kept_rows(zero, g, np.array([0.0, 0.0, 0.5, 0.0])).tolist() == [True, True, True, False]
    # a batch of right-hand sides over shared rows
    gb = np.array([[1.0, 1.0, -2.0, 3.0], [1.0, -1.0, 1.0, 0.0]])
    assert kept_rows(zero, gb).tolist() == [[True, False, True, False], [True, True, False, False]]
    # rationals: exact zero rows, Fraction right-hand sides
    gq = np.array([Fraction(0), Fraction(-1, 3), Fraction(0), Fraction(1, 7)], dtype=object)
    assert kept_rows(zero, gq).tolist() == [True, True, False, False]


def test_zero_rows_by_norm():
    G = np.array([[0.0, 0.0], [ZERO_ROW / 2, 0.0], [1e-9, 0.0], [0.6, 0.8]])
    assert zero_rows(G).tolist() == [True, True, False, False]
    # rational rows (their nonzeros only): exactly the empty ones, however small a coefficient
    assert zero_rows([{}, {0: Fraction(1, 10 ** 30)}, {}, {1: Fraction(3)}]).tolist() == [True, False, True, False]


@pytest.mark.parametrize("W0", [Ball(2, 1.0), Polytope.from_vertices(np.array([[1, 0.2], [-0.5, 1], [-0.7, -0.9],
                                                                                 [0.3, -1.1]]))])
def test_rho_column_is_what_the_disturbance_takes_from_each_row(corridor_path, W0):
    """The radius form's rho column (found by family name) against the margin LPs at W = {0} and
    W = W0: each row's right-hand side drops by exactly c (the LP's rows are unit rows)."""
    dec = load_grid_map(corridor_path)
    sysm = LinearSystem(A=np.array([[1.0, 0.3], [0.0, 0.9]]), B=0.5 * np.eye(2), U=box_input_set(1.0, 2),
                        W=Ball(2, 0.1))
    prob = pair_problem(dec, sysm, make_z("box", dec.cells[3]), 3, 4, 4)
    lp = build_radius_lp(prob, W0, "tube")
    g0 = build_tube_lp(with_disturbance(prob, Ball(2, 0.0))).g
    g1 = build_tube_lp(with_disturbance(prob, W0)).g
    np.testing.assert_allclose(lp.t_coef, g0 - g1, atol=1e-12)
    assert np.all(lp.t_coef[lp.layout.slice("dynamics")] > 0)
    assert not np.any(np.delete(lp.t_coef, np.arange(lp.G.shape[0])[lp.layout.slice("dynamics")]))


def test_sigma_d_in_both_arithmetics_against_the_minkowski_sum():
    """sigma_{D_l}(H) (one definition, float and rational) against the support of D_l's points
    enumerated as sums w_0 + A w_1 + ... + A^{l-1} w_{l-1} over W's vertices."""
    Wv = np.array([[0.1, 0.02], [-0.05, 0.1], [-0.07, -0.09], [0.03, -0.11]])
    A = np.array([[0.75, -0.25], [0.375, 1.125]])
    sysm = LinearSystem(A=A, B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Polytope.from_vertices(Wv))
    dec = load_grid_map(Path(__file__).resolve().parents[2] / "conf" / "workspace" / "maps" / "corridor.txt")
    L = 3
    prob = pair_problem(dec, sysm, make_z("box", dec.cells[3]), 3, 4, L)
    P = prob.safe
    float_sig = disturbance_support(sysm, P.H, L)
    exact_sig = openloop_support_upper(prob, exact_polytope(P), L).to_fractions()
    for ell in range(L + 1):
        pts = [sum((np.linalg.matrix_power(A, t) @ Wv[k] for t, k in enumerate(ks)), np.zeros(2))
               for ks in itertools.product(range(len(Wv)), repeat=ell)]
        want = np.max(np.array(pts) @ P.H.T, axis=0)
        np.testing.assert_allclose(float_sig[ell], want, atol=1e-12)
        np.testing.assert_allclose(np.array(exact_sig[ell], float), want, atol=1e-12)


def test_step_regions_come_from_the_pair_families():
    assert step_regions(1) == ("target",)
    assert step_regions(4) == ("safe", "safe", "safe", "target")


@pytest.mark.parametrize("eps_min", ["1/4", "1"])
def test_implied_bounds_are_one_derivation_in_both_arithmetics(eps_min):
    """``implied_bounds`` on the same (dyadic) data in float64 and in Fractions gives the same numbers; where
    eps's bounds cross (eps_min 1 > width(P_j) / width(Z) = 1/2) the rationals keep them crossed (the
    refutation) and ``meet=True`` makes the float ones meet at eps_min."""
    ix = TubeIndex(3, 2, 4, 2)                                   # L = 2 padded to 3: S, P_j, then S again
    data = {"safe": ([0, 0], [2, 1]), "target": ([1, 0], [1.5, 0.5]), "w_Z": [1, 0.5], "w_W": [0.25, 0.25],
            "U": ([-1, -0.5], [1, 0.5])}

    def bounds(num, meet=False):
        a = (lambda x: np.array([num(v) for v in x], dtype=object if num is Fraction else float))
        boxes = {r: (a(data[r][0]), a(data[r][1])) for r in ("safe", "target")}
        return implied_bounds(ix, boxes, a(data["w_Z"]), a(data["w_W"]), num(Fraction(eps_min)),
                              (a(data["U"][0]), a(data["U"][1])), L=2, meet=meet)

    (lbq, ubq), (lbf, ubf) = bounds(Fraction), bounds(float, meet=True)
    assert lbq.dtype == object and all(type(v) is Fraction for v in lbq.tolist() + ubq.tolist())
    for q, f in ((lbq, lbf), (ubq, ubf)):
        assert q[ix.p].tolist() == f[ix.p].tolist() and q[ix.u].tolist() == f[ix.u].tolist()
    assert lbq[ix.p].tolist() == [0, 0, 1, 0, 0, 0] and ubq[ix.u].tolist() == [1, 0.5] * 3 * 4
    e = [ix.eps_col(ell) for ell in (1, 2, 3)]
    if eps_min == "1":
        assert lbq[e].tolist() == [1, 1, 1] and ubq[e].tolist() == [2, Fraction(1, 2), 2]   # step 2 crosses
        assert lbf[e].tolist() == [1.0, 1.0, 1.0] and ubf[e].tolist() == [2.0, 1.0, 2.0]  # they meet at eps_min
    else:
        assert lbq[e].tolist() == [Fraction(1, 2)] * 3 and ubq[e].tolist() == [2, Fraction(1, 2), 2]
        assert lbf[e].tolist() == [0.5] * 3 and ubf[e].tolist() == [2.0, 0.5, 2.0]


@pytest.mark.parametrize("L", [5, 7])
def test_implied_bounds_hold_every_point_of_problem_2(L):
    """The derived bounds (float, and exact) against HiGHS (scipy's linprog) minimising and maximising
    each p and eps over Problem 2 at t = 0 with only C1 and U's box as bounds: every such point lies
    within them."""
    d = parse_grid_map("\n".join(["." * 5] * 2))
    sysm = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
    prob = pair_problem(d, sysm, cross_sections(d, "box", 1.0)[1], 1, 2, L)
    lp = build_tube_lp(prob)
    ix = lp.index
    lb, ub = tube_variable_bounds(prob)
    elb, eub = implied_tube_bounds(prob, lp)
    assert all(type(v) is Fraction for v in elb + eub)               # exact: no float slips through
    np.testing.assert_allclose(lb, np.array(elb, float), atol=1e-12)
    np.testing.assert_allclose(ub, np.array(eub, float), atol=1e-12)
    free = [(None, None)] * ix.size                        # p free, eps >= eps_min (C1), u in U's box
    for c in range(ix.eps.start, ix.eps.stop):
        free[c] = (float(prob.eps_min), None)
    for c in range(ix.u.start, ix.u.stop):
        free[c] = (lb[c], ub[c])
    for j in range(ix.u.start):                            # every p and eps
        for sign in (1.0, -1.0):
            cost = np.zeros(ix.size)
            cost[j] = sign
            res = linprog(cost, A_ub=lp.G, b_ub=lp.g, bounds=free, method="highs")
            assert res.status == 0
            assert lb[j] - 1e-9 <= res.x[j] <= ub[j] + 1e-9
