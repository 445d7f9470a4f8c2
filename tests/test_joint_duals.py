"""The product path's joint-LP solver that reuses refuting duals (tubejax/abstraction/joint_duals.py).

Compared, problem by problem, with the reference solver (one HiGHS solve and confirmation each,
``highs_solve_batch``) on translated pairs of a grid: same statuses, the same edges with the same
margins and tubes, and some problems refuted by an earlier problem's dual (whose bound HiGHS's own
optimum must respect).
"""

import numpy as np
import pytest

from tubejax.abstraction.joint_duals import DualReuseSolver, dual_bound
from tubejax.lp.declarations.tube_lp import build_tube_lp
from tubejax.lp.engines.highs import solve_margin_lp
from tubejax.lp.evidence.decide import float_dual_bound
from tubejax.lp.evidence.verdict import highs_solve_batch
from tubejax.model.geometry import Ball
from tubejax.model.problem import Pairs, pair_problems
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.workspace import box_grid
from tubejax.model.zshape.kinds import cross_sections


@pytest.fixture(scope="module")
def translates():
    """Problems of a 5x5 grid: every pair at offset (1, 1), (2, 1) or (2, 2) cells, at L = 1..3 (a
    step moves at most 0.5 per axis, so the far ones are infeasible at small L)."""
    d = box_grid([0, 0], [5, 5], [5, 5])
    sysm = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.1))
    Z = cross_sections(d, "box", 1.0)
    c = np.array([P.vertices.mean(axis=0) for P in d.cells])
    pairs = [(i, j) for i in range(d.n_cells) for j in range(d.n_cells)
             if tuple(np.abs(c[j] - c[i])) in {(1.0, 1.0), (2.0, 1.0), (2.0, 2.0)}]
    s, t = np.array(pairs).T
    return [p for L in (1, 2, 3) for p in pair_problems(d, sysm, Z, Pairs(s, t, np.zeros(len(s), bool)), L)]


def test_reused_duals_give_the_reference_verdicts(translates):
    solver = DualReuseSolver()
    got = solver(translates)
    want = highs_solve_batch(translates)
    assert [v.status for v in got] == [v.status for v in want]
    assert solver.n_reused > 0 and solver.n_solved + solver.n_reused == len(translates)
    assert any(v.status == "edge" for v in want) and any(v.status == "infeasible" for v in want)
    for g, w in zip(got, want):
        if w.status == "edge":
            assert g.margin == w.margin
            for a, b in zip(g.tube, w.tube):
                np.testing.assert_array_equal(a, b)
        elif g.refutation is not None and "earlier LP" in g.refutation.note:
            assert w.margin <= g.margin + 1e-9 and g.margin < 0     # HiGHS's optimum under the reused dual's bound


def test_dual_bound_is_float_dual_bound(translates):
    """``dual_bound`` of HiGHS's own duals equals :func:`float_dual_bound` of the LP they came from."""
    n = 0
    for prob in translates:
        lp = build_tube_lp(prob)
        res = solve_margin_lp(lp)
        if res.status != "Optimal" or res.margin >= 0:
            continue
        y = np.maximum(np.nan_to_num(np.asarray(res.y, float), nan=0.0), 0.0)
        a = lp.G.T @ y
        b = dual_bound((np.arange(a.size), a), y, lp.g, lp.lb, lp.ub)
        assert b == pytest.approx(float_dual_bound(lp, res), abs=1e-12) and res.margin <= b + 1e-9
        k, ka = np.flatnonzero(y), np.flatnonzero(a)             # the nonzeros alone give the same bound
        assert dual_bound((ka, a[ka]), y[k], lp.g[k], lp.lb, lp.ub) == pytest.approx(b, abs=1e-12)
        n += 1
        if n == 5:
            break
    assert n == 5
