"""Exact decisions of tube problems whose margin is exactly 0 (docs/math/margins.md#zero-margin-edges).

The problems: on an open grid, the paper's system (``A = I``, ``B = 0.5 I``, box ``U``, ball
``W`` of radius 0.2, box ``Z``), a move of three columns. By hand: along the axis of the move,
C4 with ``Z``'s facet ``x <= 1`` lets the tube's trailing face advance by at most
``0.5 (input) - 0.2 (sigma_W) = 0.3`` per step, and it starts at the source's face, three cells
from the target's: ``L >= 10``, and at ``L = 10`` every step must be a full one, so the margin
is exactly 0 (``tube_at_zero_margin`` builds that tube; the independent checker of
``exact_reference.py`` accepts it). At ``L = 9`` the instance is infeasible. Whatever HiGHS
reports -- ``-0.0``, ``+-1e-13``, no optimum, no basis -- the decision must be these.
"""

from fractions import Fraction

import numpy as np
import pytest

from exact_reference import tube_violation as reference_violation
from tubejax.abstraction import cross_sections
from tubejax.model.geometry import Ball
from tubejax.lp.evidence.decide import decide_exactly, float_dual_bound, recheck_refutation
from tubejax.lp.evidence.verdict import CLEAR_MARGIN, Verdict, clear_edge, unproved_verdict_of_result, verdict_of_result
from tubejax.lp.declarations.tube_lp import build_tube_lp, tube_violation
from tubejax.lp.engines.highs import solve_margin_lp
from tubejax.model.problem import pair_problem
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.workspace import parse_grid_map

COLS = 7


@pytest.fixture(scope="module")
def grid():
    d = parse_grid_map("\n".join(["." * COLS] * 2))
    sysm = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
    return d, sysm, cross_sections(d, "box", 1.0)


def problem(grid, i, j, L):
    d, sysm, Z = grid
    return pair_problem(d, sysm, Z[i], i, j, L)


def tube_at_zero_margin(prob, step):
    """The hand-built tube of a move by ``step`` (``(3, 0)``: three columns) in 10 steps: ``eps = 1/2``,
    the centre advancing ``3/10`` per step; inputs ``u = 1`` on the trailing vertices (along the
    move), ``0`` on the leading ones, and ``-+1`` across it (Fractions)."""
    V = [[Fraction(float(c)) for c in v] for v in prob.source.vertices]
    c0 = [sum(v[d] for v in V) / 4 for d in range(2)]
    L = 10
    p = [[c0[d] + Fraction(3, 10) * (ell + 1) * step[d] / 3 for d in range(2)] for ell in range(L)]
    eps = [Fraction(1, 2)] * L
    u = []
    for ell in range(L):
        centre = c0 if ell == 0 else p[ell - 1]
        q = V if ell == 0 else [[centre[d] + Fraction(1, 2) * z for d, z in enumerate(zv)]
                                for zv in [[-1, -1], [1, -1], [1, 1], [-1, 1]]]
        row = []
        for qk in q:
            uk = []
            for d in range(2):
                if step[d]:                     # trailing vertex: a full step; leading: stay
                    uk.append(Fraction(1 if (qk[d] < centre[d]) == (step[d] > 0) else 0) * (1 if step[d] > 0 else -1))
                else:                           # across the move: pull in by 1/2
                    uk.append(Fraction(-1 if qk[d] > centre[d] else 1))
            row.append(uk)
        u.append(row)
    return p, eps, u


@pytest.mark.parametrize("i, j, step", [(1, 4, (3, 0)), (5, 2, (-3, 0)), (COLS + 3, COLS, (-3, 0))])
def test_the_hand_built_tube_has_margin_zero(grid, i, j, step):
    prob = problem(grid, i, j, 10)
    p, eps, u = tube_at_zero_margin(prob, step)
    assert reference_violation(prob, p, eps, u) == 0          # feasible, some constraint tight


def fake(res, **kw):
    return res._replace(**kw)


@pytest.mark.parametrize("margin", [None, -1e-13, 1e-13, -0.0])
def test_zero_margin_is_an_edge_whatever_the_reported_sign(grid, margin):
    prob = problem(grid, 1, 4, 10)
    lp = build_tube_lp(prob)
    res = solve_margin_lp(lp, basis_min_margin=-np.inf)
    if margin is not None:
        res = fake(res, margin=margin)
    v = verdict_of_result(prob, lp, res, tube_violation, "highs")
    assert v.status == "edge" and v.margin >= 0 and v.proof.level == "exact"
    assert v.proof.note.startswith("decided exactly")
    ex = v.proof.exact if v.proof.exact is not None else None
    tube = ex.to_float() if ex is not None else v.tube
    p, eps, u = (np.vectorize(Fraction)(np.asarray(a, float)).tolist() for a in tube) if ex is None else \
        (a.to_fractions().tolist() for a in ex)
    assert reference_violation(prob, p, eps, u) <= 0          # the independent exact checker agrees


@pytest.mark.parametrize("margin", [-1e-13, 1e-13])
def test_below_the_minimal_horizon_is_refuted_exactly(grid, margin):
    prob = problem(grid, 1, 4, 9)
    lp = build_tube_lp(prob)
    res = fake(solve_margin_lp(lp, basis_min_margin=-np.inf), margin=margin)
    v = verdict_of_result(prob, lp, res, tube_violation, "highs")
    assert v.status == "infeasible" and v.refutation.kind == "exact"
    assert recheck_refutation(prob, lp, v.refutation) == (True, "")
    bad = dict(v.refutation.certificate)
    k = next(iter(bad))
    bad[k] = bad[k] / 1000                                      # a tampered certificate fails
    ok, why = recheck_refutation(prob, lp, v.refutation._replace(certificate=bad))
    assert not ok and "not negative" in why


def test_a_clear_non_edge_keeps_a_float_dual_bound(grid):
    prob = problem(grid, 1, 4, 8)
    lp = build_tube_lp(prob)
    res = solve_margin_lp(lp, basis_min_margin=-np.inf)
    v = verdict_of_result(prob, lp, res, tube_violation, "highs")
    assert v.status == "infeasible" and v.refutation.kind == "dual"
    # HiGHS's optimal duals: the float64 weak-duality bound is the optimum itself, up to its rounding
    assert res.margin <= v.refutation.bound + 1e-12 and v.refutation.bound < -1e-7
    assert v.refutation.bound == float_dual_bound(lp, res)


@pytest.mark.parametrize("L, want", [(10, "edge"), (9, "infeasible")])
def test_without_an_optimum_or_a_basis_the_exact_solve_decides(grid, L, want):
    prob = problem(grid, 1, 4, L)
    lp = build_tube_lp(prob)
    res = solve_margin_lp(lp)
    d = decide_exactly(prob, lp, res._replace(status="Unknown", col_status=None, row_status=None))
    assert d.status == want and d.how == "exact solve"
    if want == "edge":
        ex = d.proof.exact
        assert reference_violation(prob, *(a.to_fractions().tolist() for a in ex)) <= 0
    else:
        assert recheck_refutation(prob, lp, d.refutation)[0]


def test_an_irrational_support_refutes_the_relaxed_problem(grid):
    """With a diamond Z, sigma_W of a ball is irrational (r sqrt 2): certificates must refute the
    problem with it rounded down; primal proofs hold with it rounded up."""
    d, sysm, _ = grid
    from tubejax.model.zshape.kinds import make_z
    Zd = make_z("diamond", d.cells[1], 1.0)
    for L, want in ((2, "infeasible"), (8, "edge")):
        prob = pair_problem(d, sysm, Zd, 1, 2, L)
        lp = build_tube_lp(prob)
        res = solve_margin_lp(lp, basis_min_margin=-np.inf)
        dd = decide_exactly(prob, lp, res._replace(status="Unknown", col_status=None, row_status=None))
        assert dd.status == want, (L, res.margin)
        if want == "infeasible":
            assert recheck_refutation(prob, lp, dd.refutation)[0]


def test_without_proofs_a_clear_edge_is_unconfirmed_and_every_other_verdict_is_the_same(grid):
    """:func:`unproved_verdict_of_result` leaves a clearly feasible problem unproved (``'unconfirmed'``, HiGHS's margin, no
    tube); a zero-margin edge is still proved exactly and a non-edge still refuted."""
    clear = problem(grid, 1, 2, 10)                             # one column in 10 steps: plenty of margin
    cases = [(clear, None), (problem(grid, 1, 4, 10), 1e-13), (problem(grid, 1, 4, 8), None)]
    statuses = []
    for prob, margin in cases:
        lp = build_tube_lp(prob)
        res = solve_margin_lp(lp, basis_min_margin=-np.inf)
        res = res if margin is None else fake(res, margin=margin)
        proved = verdict_of_result(prob, lp, res, tube_violation, "highs")
        bare = unproved_verdict_of_result(prob, lp, res, tube_violation, "highs")
        assert clear_edge(prob, lp, res, tube_violation)[0] == (prob is clear)
        statuses.append(proved.status)
        if prob is clear:
            assert proved.status == "edge" and res.margin > CLEAR_MARGIN
            assert bare == Verdict("unconfirmed", res.margin, None, "highs")
        else:
            assert (bare.status, bare.margin, bare.provenance) == (proved.status, proved.margin, proved.provenance)
            assert getattr(bare.proof, "level", None) == getattr(proved.proof, "level", None)
            assert getattr(bare.refutation, "kind", None) == getattr(proved.refutation, "kind", None)
    assert statuses == ["edge", "edge", "infeasible"]
