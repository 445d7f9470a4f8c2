"""rho* of every candidate from one batched solve: brackets against HiGHS, exact critical values,
step functions, candidates pruned at rho = 0 (sound for every rho >= 0)."""

import dataclasses

import numpy as np
import pytest

from tubejax.abstraction.candidates import build_candidates
from tubejax.model.geometry import Ball
from tubejax.lp.evidence.radius_lp import radius_highs_optimum
from tubejax.lp.batch.batch_solver import pdhg_solver
from tubejax.model.problem import pair_problem
from tubejax.analyses.radius_analysis import StepFunction, step_function
from tubejax.lp.declarations.radius_disturbance import zero_disturbance_system
from tubejax.model.system import LinearSystem

FORMS = ("tube", "openloop")


def test_step_function_by_hand():
    s = step_function([0.3, 0.1, 0.2, 0.2 - 1e-11, -0.5, np.inf, np.nan, 0.0])
    assert s.rho.tolist() == [0.0, 0.1, 0.2, 0.3] and s.n.tolist() == [5, 4, 3, 1]
    r = [0.0, 0.05, 0.1, 0.1 + 1e-6, 0.2, 0.2 + 1e-12, 0.3, 0.31, 5.0]
    assert s(r).tolist() == [5, 4, 4, 3, 3, 3, 1, 0, 0]
    assert step_function([]).n.size == 0 and step_function([-1.0])(0.0) == 0
    assert step_function([-2.6e-16, 0.1])(0.0) == 2            # an optimum of 0 computed as -2.6e-16
    assert isinstance(s, StepFunction)


@pytest.mark.parametrize("form", FORMS)
def test_brackets_hold_highs_rho_star(pdhg_tables, highs_tables, form):
    """Every instance's [lower, upper] holds HiGHS's rho* (upper is a rigorous bound), the same
    candidates in the same order, and the gap is the engine's."""
    t, ref = pdhg_tables[form], highs_tables[form]
    assert np.array_equal(t.src, ref.src) and np.array_equal(t.dst, ref.dst) and np.array_equal(t.L, ref.L)
    exact = ref.value
    assert np.all(t.upper >= exact - 1e-9)
    assert np.all(t.lower <= exact + 1e-9)
    ok = t.status == "optimal"
    assert ok.mean() > 0.9 and np.all(t.upper[ok] - t.lower[ok] <= 1e-4 + 1e-12)
    assert set(t.status) <= {"optimal", "infeasible"}            # the rest went to HiGHS


@pytest.mark.parametrize("form", FORMS)
def test_refine_gives_highs_critical_values(pdhg_tables, highs_tables, form):
    shared, ref = pdhg_tables[form], highs_tables[form]
    t = dataclasses.replace(shared, exact=np.full(shared.n_instances, np.nan), stats=dict(shared.stats))
    t.stats.pop("refine_highs_solves", None)
    t.refine()
    c, r = t.critical(), ref.critical()
    assert np.array_equal(c.src, r.src) and np.array_equal(c.dst, r.dst)
    assert c.exact.all() and r.exact.all()
    assert np.allclose(c.value, r.value, rtol=0, atol=1e-9)
    assert t.stats["refine_highs_solves"] < t.n_instances / 2          # only the rivals of the maximum
    grid = np.linspace(0, 0.45, 91)                                     # holds the ties 0.1, 0.2, 0.3
    assert np.array_equal(t.n_edges()(grid), ref.n_edges()(grid))
    t.refine(L_max=5)                                                   # the rivals below L_max = 5 too
    assert t.critical(5).exact.all() and np.array_equal(t.n_edges(5)(grid), ref.n_edges(5)(grid))


@pytest.mark.parametrize("form", FORMS)
def test_step_functions_monotone_and_bounded(highs_tables, pdhg_tables, form):
    grid = np.linspace(0, 0.5, 201)
    t = pdhg_tables[form]
    prev = None
    for L in range(1, t.L_max + 1):                        # non-increasing in rho, non-decreasing in L_max
        n = t.n_edges(L)(grid)
        assert np.all(np.diff(n) <= 0)
        if prev is not None:
            assert np.all(n >= prev)
        prev = n
    assert np.all(t.n_edges(which="upper")(grid) >= t.n_edges(which="lower")(grid))
    assert highs_tables[form].n_edges()(0.0) == len(highs_tables[form].critical().value)


@pytest.mark.parametrize("form", FORMS)
def test_another_radius_of_the_same_shape_reuses_the_executable(corridor, pdhg_solvers, pdhg_tables, form):
    """The size of the system's W does not enter the table: a second solve at another radius
    compiles nothing and gives the same table, bit for bit (deterministic)."""
    from tubejax.analyses.radius_analysis import RadiusTableOptions, solve_radius_table

    dec, sysm, Z = corridor
    s = pdhg_solvers[form]
    traces, compiles = s.n_traces, s.stats["n_compiles"]
    again = solve_radius_table(dec, LinearSystem(A=sysm.A, B=sysm.B, U=sysm.U, W=Ball(2, 0.05)), Z=Z, solver=s,
                               options=RadiusTableOptions(form=form, L_max=10))
    assert s.n_traces == traces and s.stats["n_compiles"] == compiles and again.stats["compile_seconds"] == 0.0
    first = pdhg_tables[form]
    for name in ("value", "lower", "upper"):
        assert np.array_equal(getattr(again, name), getattr(first, name))


def test_critical_value_is_max_over_L(highs_tables, corridor):
    """A pair's critical disturbance is max_L rho*(i, j, L), and best_L attains it (independently
    re-solved by HiGHS for a few pairs)."""
    dec, sysm, Z = corridor
    t = highs_tables["tube"]
    c = t.critical()
    for p in range(0, len(c.src), 17):
        i, j = int(c.src[p]), int(c.dst[p])
        vals = [radius_highs_optimum(pair_problem(dec, sysm, Z[i], i, j, L), "tube")[0]
                for L in t.L[(t.src == i) & (t.dst == j)]]
        assert abs(max(vals) - c.value[p]) <= 1e-9
        rho_best = radius_highs_optimum(pair_problem(dec, sysm, Z[i], i, j, int(c.best_L[p])), "tube")[0]
        assert abs(rho_best - c.value[p]) <= 1e-9


@pytest.mark.parametrize("r", [0.1, 0.2, 0.3])
def test_pruning_at_zero_is_weakest(corridor, r):
    """The candidates at W = {0} include those at every W = rho W0 (the rules use W only through
    sigma_W, which grows with rho), and instances pruned at 0 are infeasible at 0 (HiGHS)."""
    dec, sysm, Z = corridor
    zero = build_candidates(dec, zero_disturbance_system(sysm), 10)
    at_r = build_candidates(dec, LinearSystem(A=sysm.A, B=sysm.B, U=sysm.U, W=Ball(2, r)), 10)
    inst = lambda c: {(int(i), int(j), L + 1) for (i, j, row) in zip(c.src, c.dst, c.keep)  # noqa: E731
                      for L in np.flatnonzero(row)}
    kept0 = inst(zero)
    assert inst(at_r) <= kept0 and len(inst(at_r)) < len(kept0)
    rng = np.random.default_rng(int(10 * r))
    pruned = [(i, j, L) for i in range(dec.n_cells) for j in range(dec.n_cells) for L in (1, 3, 6)
              if i != j and (i, j, L) not in kept0 and abs(i - j) <= 4]
    for k in rng.choice(len(pruned), size=12, replace=False):
        i, j, L = pruned[k]
        assert radius_highs_optimum(pair_problem(dec, sysm, Z[i], i, j, L), "tube")[0] < 0


def test_bad_arguments(corridor, highs_tables):
    from tubejax.analyses.radius_analysis import RadiusTableOptions, solve_radius_table, transition_system_at

    dec, sysm, Z = corridor
    with pytest.raises(ValueError, match="form: expected one of"):
        solve_radius_table(dec, sysm, Z=Z, options=RadiusTableOptions(form="exact2d"))
    with pytest.raises(ValueError, match="solver: expected 'pdhg', 'highs'"):
        solve_radius_table(dec, sysm, Z=Z, solver="mpax", options=RadiusTableOptions(L_max=1))
    copy = pdhg_solver("tube", radius=True)
    copy.form = copy.form._replace()                # equal fields, name and radius flag: not the record's object
    wrongs = {"'tube'$": pdhg_solver("tube"), "'openloop' \\(radius form\\)$": pdhg_solver("openloop", radius=True),
              "'tube' \\(radius form\\), another object than the record's own form$": copy,
              "a function without a form$": lambda problems: []}
    for got, wrong in wrongs.items():               # margin form; the other LP's; a copy; no engine
        with pytest.raises(ValueError, match="solver: expected the batched engine on the 'tube' LP's radius form "
                                             "\\(pdhg_solver\\('tube', radius=True\\)\\), got " + got):
            solve_radius_table(dec, sysm, Z=Z, solver=wrong, options=RadiusTableOptions(L_max=1))
    with pytest.raises(ValueError, match=r"L_max: expected an integer in \[1, 10\]"):
        highs_tables["tube"].critical(11)
    with pytest.raises(ValueError, match="the radius must be a finite number >= 0"):
        transition_system_at(highs_tables["tube"], -0.1)
    with pytest.raises(ValueError, match="is not 0.1 W0"):
        transition_system_at(highs_tables["tube"], 0.1, sysm)              # sysm has W of radius 0.2


@pytest.mark.parametrize("form", FORMS)
def test_translates_take_their_representatives_values(pdhg_tables, highs_tables, form):
    """The engine solves one instance per exact translation class; every other instance's rho*,
    solved on its own by HiGHS, is its representative's (to HiGHS's tolerance)."""
    t, ref = pdhg_tables[form], highs_tables[form]
    shared = t.rep != np.arange(t.n_instances)
    assert shared.sum() > t.n_instances / 2 and t.stats["n_translated"] == shared.sum()
    assert np.array_equal(t.L[shared], t.L[t.rep[shared]])
    assert np.array_equal(ref.rep, t.rep) and ref.stats["n_translated"] == shared.sum()
    k = np.flatnonzero(shared)
    own = np.array([radius_highs_optimum(p, form)[0] for p in ref.problems(k)], float)    # one by one, here
    assert np.array_equal(np.isfinite(own), np.isfinite(ref.value[t.rep[k]]))
    fin = np.isfinite(own)
    assert np.allclose(own[fin], ref.value[t.rep[k]][fin], rtol=0, atol=1e-9)
