"""The batched PDHG decides 4-D tube LPs itself (issue 23, item 3): checked against HiGHS."""

import numpy as np
import pytest

from tubejax.abstraction import build_abstraction
from tubejax.lp.batch.batch_solver import PdhgBatchSolver
from tubejax.model.geometry import Ball
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.workspace import box_grid


def double_integrator_ps(dt=0.5, beta=2.0):
    """Two sampled double integrators in (p, s = p + beta v) coordinates (conf/system/double_integrator.yaml)."""
    A1, B1 = np.array([[1.0, dt], [0.0, 1.0]]), np.array([[dt * dt / 2], [dt]])
    T = np.array([[1.0, 0.0], [1.0, beta]])
    A1, B1 = T @ A1 @ np.linalg.inv(T), T @ B1
    return np.kron(np.eye(2), A1), np.kron(np.eye(2), B1)


@pytest.fixture(scope="module")
def grid_and_system():
    A, B = double_integrator_ps()
    system = LinearSystem(A=A, B=B, U=box_input_set(1.0, 2), W=Ball(4, 0.02))
    return box_grid([0, 0, 0, 0], [3, 3, 2, 2], [3, 3, 2, 2]), system


def test_default_pdhg_decides_4d_tube_lps_and_finds_the_highs_edges(grid_and_system):
    decomp, system = grid_and_system
    solver = PdhgBatchSolver(pool=64, min_bucket=16, highs_process=False)
    assert solver.options.ruiz_iters == "auto"
    got = build_abstraction(decomp, system, solve_batch=solver, zshape="cell", L_max=8, progress=False)
    want = build_abstraction(decomp, system, zshape="cell", L_max=8, progress=False)
    assert want.n_edges > 0
    assert {(e.src, e.dst, e.L) for e in got.edges} == {(e.src, e.dst, e.L) for e in want.edges}
    counts = solver.stats["status_counts"]
    ran = sum(v for k, v in counts.items() if k not in ("pad", "running"))
    decided = sum(counts.get(k, 0) for k in ("feasible", "near_zero", "infeasible"))
    assert ran > 0 and decided >= 0.95 * ran, counts
    assert np.all(got.verify() <= 1e-9)


def test_a_bad_ruiz_setting_is_refused_up_front():
    with pytest.raises(ValueError, match="ruiz_iters"):
        PdhgBatchSolver(ruiz_iters="sometimes")


def test_reused_duals_refute_only_what_highs_refutes(grid_and_system):
    """Instances streamed in small chunks reuse the last certified dual of their key (pairs at
    the same offset): every verdict equals HiGHS's, and every certificate, reused or not, bounds
    HiGHS's optimum from above (weak duality on the instance's own data)."""
    from tubejax.lp.evidence.verdict import highs_verdict
    from tubejax.model.problem import pair_problem
    from tubejax.model.zshape.kinds import make_z
    decomp, system = grid_and_system
    probs = [pair_problem(decomp, system, make_z("cell", decomp.cells[i]), i, j, L)
             for i in range(0, decomp.n_cells, 3) for j in range(decomp.n_cells) if i != j for L in (2, 3)]
    reuse = PdhgBatchSolver(pool=16, min_bucket=16, chunk=32, highs_process=False)
    plain = PdhgBatchSolver(pool=16, min_bucket=16, chunk=32, highs_process=False)
    plain.form = plain.form._replace(dual_key=None)                      # no key: no dual reused
    got, ref = reuse(probs), plain(probs)
    assert reuse.stats["duals_reused"] > 0.2 * len(probs) and plain.stats["duals_reused"] == 0
    assert reuse.stats["slot_iterations"] < plain.stats["slot_iterations"]
    highs = [highs_verdict(p) for p in probs]
    assert [v.status for v in got] == [v.status for v in highs] == [v.status for v in ref]
    for v, h in zip(got, highs):
        if v.provenance == "pdhg-certificate":
            assert v.margin < -reuse.options.margin_safety and h.margin <= v.margin + 1e-9
