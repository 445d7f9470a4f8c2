"""rho* on the one batched engine (optimise mode) against HiGHS's exact rho*: agreement, rigour
of the dual upper bound, certified negatives, no recompiles; the margin form's verdict path
unchanged."""

import numpy as np
import pytest

from tubejax.model.geometry import Ball
from tubejax.lp.evidence.radius_lp import build_radius_lp, radius_highs_optimum
from tubejax.lp.declarations.radius_rows import tube_radius_reference
from tubejax.lp.batch.batch_solver import pdhg_solver
from tubejax.lp.declarations.tube_lp import tube_violation
from tubejax.lp.declarations.tube_variables import Tube
from tubejax.lp.declarations.openloop_lp import OpenLoopPlan
from tubejax.lp.declarations.radius_disturbance import with_disturbance
from tubejax.model.zshape.kinds import make_z
from tubejax.lp.batch.batch_solver import PdhgBatchSolver
from tubejax.model.problem import pair_problem
from tubejax.model.system import LinearSystem, one_norm_input_set
from tubejax.model.workspace.gridmap import load_grid_map

MAPS = {"corridor": "conf/workspace/maps/corridor.txt", "paper": "conf/workspace/maps/paper.txt"}
GAP = 1e-6
#: HiGHS's own primal tolerance (1e-10 on unit rows) moves its rho* by about that much.
HIGHS_TOL = 1e-9


def random_problems(path, sysm, n, seed):
    """``n`` random (pair, L), L in 1..10, pairs at most 3 cells apart (farther ones are pruned)."""
    dec = load_grid_map(path)
    Z = [make_z("box", c) for c in dec.cells]
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < n:
        i, j = (int(v) for v in rng.integers(dec.n_cells, size=2))
        if i != j and np.linalg.norm(dec.cells[i].vertices.mean(0) - dec.cells[j].vertices.mean(0)) <= 3.0:
            out.append(pair_problem(dec, sysm, Z[i], i, j, int(rng.integers(1, 11))))
    return out


@pytest.fixture(scope="module")
def sys02(paper_system):
    """One system for the whole module: executables are keyed by the padded shape, and facet
    padding grows per system, so one system object keeps this module at one compile per form."""
    return paper_system(0.2)


@pytest.fixture(scope="module")
def solvers():
    # one batch width and one padded horizon: one executable per form serves every test here
    kw = dict(pool=64, min_bucket=64, l_buckets=(10,), gap_tol=GAP)
    return {form: pdhg_solver(form, radius=True, **kw) for form in ("tube", "openloop")}


@pytest.mark.parametrize("form", ["tube", "openloop"])
@pytest.mark.parametrize("name", ["paper", "corridor"])      # paper first: its facet counts pad
def test_batched_rho_star_agrees_with_highs(solvers, sys02, form, name):
    seed = {"corridor": 1, "paper": 2}[name] + 10 * (form == "openloop")
    probs = random_problems(MAPS[name], sys02, 48, seed=seed)
    s = solvers[form]
    res = s.optimise(probs)
    ref = np.array([radius_highs_optimum(p, form)[0] for p in probs])
    status = np.array(res.status)
    lower, upper = np.asarray(res.lower), np.asarray(res.upper)
    assert set(status) <= {"optimal", "infeasible"}
    assert res.provenance == ("pdhg",) * len(probs)
    # rigour: the dual bound is never below the exact optimum
    assert np.all(upper >= ref - HIGHS_TOL)
    opt = status == "optimal"
    assert np.all(upper[opt] - lower[opt] <= GAP)
    np.testing.assert_allclose(lower[opt], ref[opt], atol=GAP + HIGHS_TOL)
    np.testing.assert_allclose(res.value[opt], ref[opt], atol=GAP + HIGHS_TOL)
    # 'infeasible': a certified negative rho* (Problem 2 infeasible even at W = {0})
    neg = status == "infeasible"
    assert np.all(upper[neg] < 0) and np.all(ref[neg] < 0)
    assert np.all(ref[opt] >= -GAP - HIGHS_TOL)             # certified whenever negative by a margin
    assert opt.sum() >= 8 and neg.sum() >= 4                 # both kinds occur in the sample
    kind = Tube if form == "tube" else OpenLoopPlan
    assert all(isinstance(x, kind) for x in res.point)


def test_lower_estimate_is_the_radius_of_a_checked_tube(solvers, sys02):
    """The lower estimate is what it says: the returned tube, moved towards the reference
    point just enough to satisfy C2 / C3 (recomputed here with the dense builder), passes the
    independent float64 checker at W of radius ``lower``."""
    probs = random_problems(MAPS["corridor"], sys02, 24, seed=11)
    res = solvers["tube"].optimise(probs)
    checked = 0
    for p, s, lo, tube in zip(probs, res.status, res.lower, res.point):
        if s != "optimal" or lo < 1e-3:
            continue
        lp = build_radius_lp(p, Ball(2, 1.0), "tube")
        x, x_ref = lp.index.pack(tube), tube_radius_reference(p)
        hard = lp.t_coef == 0
        r, rr = (lp.G[hard] @ v - lp.g[hard] for v in (x, x_ref))
        theta = max(0.0, float(np.max(np.where(r > 0, r / (r - rr), 0.0))))
        repaired = lp.index.split((1 - theta) * x + theta * x_ref)
        assert tube_violation(with_disturbance(p, Ball(2, lo)), repaired) <= 1e-9
        assert tube_violation(with_disturbance(p, Ball(2, lo + 1e-3)), repaired) > 1e-6
        checked += 1
    assert checked >= 4


def test_certified_negative_needs_no_highs(solvers, sys02, corridor_path):
    dec = load_grid_map(corridor_path)
    sysm = sys02
    far = [(i, j) for i in range(dec.n_cells) for j in range(dec.n_cells)
           if np.linalg.norm(dec.cells[i].vertices.mean(0) - dec.cells[j].vertices.mean(0)) > 2.9][:6]
    probs = [pair_problem(dec, sysm, make_z("box", dec.cells[i]), i, j, 2) for i, j in far]
    res = solvers["tube"].optimise(probs)
    assert res.status == ("infeasible",) * len(probs)
    assert np.all(res.upper < -1e-7)
    assert all(radius_highs_optimum(p, "tube")[0] < 0 for p in probs)


def test_no_recompile_across_calls_and_radii(solvers, sys02, paper_system):
    s = solvers["tube"]
    probs_a = random_problems(MAPS["corridor"], sys02, 16, seed=5)
    s.optimise(probs_a)
    traces, execs = s.n_traces, s.n_executables
    # the same pairs with another W of the same shape: rho* does not depend on it, and the
    # executable (keyed by the padded shape and the mode) is reused
    probs_b = random_problems(MAPS["corridor"], paper_system(0.3), 16, seed=5)
    a, b = s.optimise(probs_a), s.optimise(probs_b)
    assert s.n_traces == traces and s.n_executables == execs
    np.testing.assert_array_equal(a.lower, b.lower)
    np.testing.assert_array_equal(a.upper, b.upper)


@pytest.mark.parametrize("form", ["tube", "openloop"])
def test_non_box_input_set_stays_on_the_batched_path(solvers, form):
    """C5 of a non-box ``U`` (the 1-norm ``U``) are the operators' hard rows, without ``rho``; the
    reference ``u = 0`` is inside ``U``: every rho* is PDHG's, bracketing HiGHS's exact value."""
    sysm = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=one_norm_input_set(1.0, 2), W=Ball(2, 0.2))
    probs = random_problems(MAPS["corridor"], sysm, 32, seed=3)
    res = solvers[form].optimise(probs)
    assert res.provenance == ("pdhg",) * len(probs)
    ref = np.array([radius_highs_optimum(p, form)[0] for p in probs])
    status = np.array(res.status)
    lower, upper = np.asarray(res.lower), np.asarray(res.upper)
    assert np.all(upper >= ref - HIGHS_TOL)                 # rigour of the dual bound
    opt, neg = status == "optimal", status == "infeasible"
    assert opt.sum() >= 4 and neg.sum() >= 4 and np.all(opt | neg)
    np.testing.assert_allclose(lower[opt], ref[opt], atol=GAP + HIGHS_TOL)
    assert np.all(upper[opt] - lower[opt] <= GAP)
    assert np.all(upper[neg] < 0) and np.all(ref[neg] < 0)
    # the lower estimate repairs the point into every row, U's included: never above rho*
    assert np.all(lower[np.isfinite(lower)] <= ref[np.isfinite(lower)] + HIGHS_TOL)


def test_unbatchable_reference_goes_to_highs(solvers, sys02, corridor_path):
    """eps_min so large that eps_min Z fits in no cell: no reference point satisfies C2 / C3, so
    the problem is not batched; HiGHS finds the radius LP infeasible (rho* = -inf)."""
    import dataclasses
    dec = load_grid_map(corridor_path)
    p = dataclasses.replace(pair_problem(dec, sys02, make_z("box", dec.cells[0]), 0, 1, 3), eps_min=0.9)
    res = solvers["tube"].optimise([p])
    assert res.provenance == ("highs",) and res.status == ("infeasible",)
    assert res.upper[0] == -np.inf


def test_radius_solver_gives_no_verdicts(solvers, sys02):
    with pytest.raises(TypeError, match="optimise"):
        solvers["tube"](random_problems(MAPS["corridor"], sys02, 2, seed=0))


def test_margin_form_verdicts_and_traces_unchanged_by_the_optimise_mode(paper_system):
    """The margin form's verdict path is untouched: a second mode on the same solver adds one
    executable and no retrace of the first; verdicts are identical before and after; and the
    margin form's optimum t* (optimise mode) agrees with HiGHS's margin."""
    from tubejax.lp.declarations.tube_lp import build_tube_lp
    from tubejax.lp.engines.highs import solve_margin_lp
    probs = random_problems(MAPS["corridor"], paper_system(0.05), 32, seed=7)
    s = PdhgBatchSolver(pool=32, min_bucket=32, l_buckets=(10,), tail_width=None, max_iters=4096,
                        highs_process=False)
    before = s(probs)
    assert s.n_traces == 1
    opt = s.optimise(probs)
    assert s.n_traces == 2 and s.n_executables == 2
    after = s(probs)
    assert s.n_traces == 2
    assert [v.status for v in before] == [v.status for v in after]
    assert [v.provenance for v in before] == [v.provenance for v in after]
    np.testing.assert_array_equal([v.margin for v in before], [v.margin for v in after])
    t_star = np.array([solve_margin_lp(build_tube_lp(p)).margin for p in probs])
    ok = np.array(opt.status) == "optimal"
    assert ok.sum() >= 4
    assert np.all(opt.upper >= t_star - HIGHS_TOL)
    np.testing.assert_allclose(opt.lower[ok], t_star[ok], atol=1e-6 + HIGHS_TOL)
    assert all(t_star[k] < 0 for k in np.flatnonzero(np.array(opt.status) == "infeasible"))


def test_unknown_mode_is_refused():
    with pytest.raises(ValueError, match="mode"):
        PdhgBatchSolver(mode="fastest")
