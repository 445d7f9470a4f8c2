"""The generic batched PDHG core on small dense margin-form LPs with known optima."""

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import linprog

from tubejax.lp.engines.certify import make_margin_certify
from tubejax.lp.engines.pdhg import (FEASIBLE, INFEASIBLE, MAX_ITERS, NEAR_ZERO, RUIZ_AUTO_PASSES, PdhgOptions,
                                     PdhgProblem, ScalingOperator, make_pdhg_runner, pdhg_init, pdhg_scaling,
                                     ruiz_passes)
from tubejax.lp.engines.pool import solve_pool

OPTS = PdhgOptions(max_iters=4000)


class X(NamedTuple):
    x: np.ndarray      # (n, B)
    t: np.ndarray      # (B,)


class Y(NamedTuple):
    y: np.ndarray      # (r, B)


def ops(xp):
    """Dense batched ``K = [G, 1]`` with batch axis last: ``G`` of shape (r, n, B)."""
    def mv(G, z):
        return Y(xp.einsum("rnb,nb->rb", G, z.x) + z.t[None])

    def rmv(G, y):
        return X(xp.einsum("rnb,rb->nb", G, y.y), xp.sum(y.y, axis=0))
    return mv, rmv


def make_problem(G, g, lo, hi, t_lo=-10.0, t_hi=1.0):
    """Margin-form problem arrays from G (B, r, n), g (B, r), lo/hi (B, n)."""
    G = np.moveaxis(np.asarray(G, float), 0, -1)
    g, lo, hi = (np.asarray(a, float).T for a in (g, lo, hi))
    B = G.shape[-1]
    prob = PdhgProblem(G, X(np.zeros_like(lo), -np.ones(B)), Y(g), X(lo, np.full(B, t_lo)),
                       X(hi, np.full(B, t_hi)), Y(np.ones_like(g)))
    z0 = X(0.5 * (lo + hi), np.full(B, t_lo))
    return prob, z0


class Solver:
    """Compile-once runner per width, counting traces."""

    def __init__(self, opts=OPTS):
        self.opts = opts
        self.traces = 0
        mv, rmv = ops(jnp)

        def count():
            self.traces += 1
        self.run = make_pdhg_runner(mv, rmv, make_margin_certify(mv, rmv, jnp), opts, on_trace=count)

    def __call__(self, prob, z0, width):
        mv, rmv = ops(np)
        state = pdhg_init(ScalingOperator(mv, rmv, np.abs(prob.data), prob.data ** 2), prob, z0, self.opts, np)
        return solve_pool(self.run, prob, state, width)


@pytest.fixture(scope="module")
def solver():
    return Solver()


def t_star(G, g, lo, hi):
    """Reference optimum of ``max t`` with HiGHS (scipy)."""
    r, n = G.shape
    A = np.hstack([G, np.ones((r, 1))])
    res = linprog(np.r_[np.zeros(n), -1.0], A_ub=A, b_ub=g,
                  bounds=list(zip(lo, hi)) + [(None, 1.0)], method="highs")
    assert res.status == 0
    return -res.fun


def canonical():
    """(G, g, lo, hi, t*) for a few LPs with known optima."""
    e1, e2 = [1.0, 0.0], [0.0, 1.0]
    m1, m2 = [-1.0, 0.0], [0.0, -1.0]
    box = ([-3.0, -3.0], [3.0, 3.0])
    return [
        ([e1, m1, e2, m2], [1.0, 1.0, 2.0, 2.0], *box, 1.0),          # feasible, margin 1
        ([e1, m1, e2, m2], [-0.5, -0.5, 2.0, 2.0], *box, -0.5),       # infeasible, margin -0.5
        ([e1, e2, m2], [-4.0, 1.0, 1.0], *box, -1.0),                 # infeasible through the box
        ([e1, m1, e2, m2], [0.3, 0.5, 0.1, 0.1], *box, 0.4),          # feasible, margin 0.4 (x1 = -0.1)
    ]


@pytest.mark.parametrize("ruiz", [0, 4])
def test_canonical_lps(solver, ruiz):
    if ruiz:                                  # the Ruiz passes before Pock-Chambolle scaling
        solver = Solver(OPTS._replace(ruiz_iters=ruiz))
    cases = canonical()
    G = [c[0] for c in cases[:2]] + [cases[2][0] + [cases[2][0][0]]] + [cases[3][0]]
    g = [c[1] for c in cases[:2]] + [cases[2][1] + [cases[2][1][0]]] + [cases[3][1]]
    prob, z0 = make_problem(G, g, [c[2] for c in cases], [c[3] for c in cases])
    out = solver(prob, z0, 8)
    want = [FEASIBLE, INFEASIBLE, INFEASIBLE, FEASIBLE]
    assert out.status.tolist() == want
    for b, c in enumerate(cases):
        # the bound is a valid upper bound on t*, and tight for these small LPs
        assert out.bound[b] >= c[4] - 1e-9
        if want[b] == INFEASIBLE:
            assert out.bound[b] < -OPTS.margin_safety
            assert out.bound[b] <= c[4] + 1e-3
        else:
            assert out.viol[b] <= OPTS.feas_tol


def test_zero_margin_is_never_certified_infeasible(solver):
    prob, z0 = make_problem([[[1.0, 0.0], [-1.0, 0.0]]], [[0.0, 0.0]], [[-3, -3]], [[3, 3]])
    out = solver(prob, z0, 8)
    assert out.status[0] in (FEASIBLE, NEAR_ZERO, MAX_ITERS)
    assert out.bound[0] >= -1e-12


def random_lps(seed, B=24, r=12, n=5):
    rng = np.random.default_rng(seed)
    G = rng.standard_normal((B, r, n))
    G /= np.linalg.norm(G, axis=2, keepdims=True)
    lo, hi = -np.ones((B, n)), np.ones((B, n))
    xs = rng.uniform(-0.8, 0.8, (B, n))
    slack = rng.uniform(0.02, 0.3, (B, r))
    g = np.einsum("brn,bn->br", G, xs) + slack              # feasible by construction: t* >= 0.02
    # make every other instance infeasible: two opposite rows that cannot both hold
    bad = np.arange(B) % 2 == 1
    G[bad, 0] = G[bad, 1] * -1.0
    g[bad, 0] = -g[bad, 1] - rng.uniform(0.05, 0.5, bad.sum())
    ts = np.array([t_star(G[b], g[b], lo[b], hi[b]) for b in range(B)])
    return G, g, lo, hi, ts, bad


def test_random_lps_feasible_and_infeasible(solver):
    G, g, lo, hi, ts, bad = random_lps(0)
    assert np.all(ts[~bad] >= 0.02 - 1e-9) and np.all(ts[bad] < -0.02)
    prob, z0 = make_problem(G, g, lo, hi)
    out = solver(prob, z0, 8)                                  # 24 instances through 8 slots
    assert np.all(out.status[~bad] == FEASIBLE)
    assert np.all(out.status[bad] == INFEASIBLE)
    assert np.all(out.bound >= ts - 1e-9)                      # weak duality holds on every instance
    assert np.all(out.viol[~bad] <= OPTS.feas_tol)


def test_batch_equals_python_loop_and_no_recompile(solver):
    G, g, lo, hi, ts, bad = random_lps(1, B=6)
    prob, z0 = make_problem(G, g, lo, hi)
    batched = solver(prob, z0, 8)
    traces = solver.traces
    again = solver(prob, z0, 8)                                # same shapes: no new trace
    assert solver.traces == traces
    np.testing.assert_array_equal(again.it, batched.it)
    for b in range(6):
        pb, zb = make_problem(G[b:b + 1], g[b:b + 1], lo[b:b + 1], hi[b:b + 1])
        one = solver(pb, zb, 8)                                # the instance alone (padded slots)
        assert one.status[0] == batched.status[b]
        assert one.it[0] == batched.it[b]
        np.testing.assert_allclose(one.bound[0], batched.bound[b], rtol=1e-12, atol=1e-14)
    assert solver.traces == traces


@pytest.mark.parametrize("cap_tol", [0.0, 1e-2, 10.0])
def test_the_cap_tolerance_decides_near_zero_or_max_iters(cap_tol):
    # 16 iterations decide few instances; at the cap a violation <= cap_tol is NEAR_ZERO
    opts = PdhgOptions(max_iters=16, zero_after=10 ** 6, cap_tol=cap_tol)
    G, g, lo, hi, ts, bad = random_lps(3)
    prob, z0 = make_problem(G, g, lo, hi)
    out = Solver(opts)(prob, z0, 32)
    open_ = (out.status != FEASIBLE) & (out.status != INFEASIBLE)
    assert np.all(out.it[open_] == 16)
    assert np.all((out.status[open_] == NEAR_ZERO) == (out.viol[open_] <= cap_tol))
    assert np.all((out.status[open_] == MAX_ITERS) == (out.viol[open_] > cap_tol))
    if cap_tol == 10.0:
        assert np.any(out.status == NEAR_ZERO)
    if cap_tol == 0.0:
        assert np.any(out.status == MAX_ITERS)


def test_ruiz_auto_scales_states_of_three_or_more_dimensions_only():
    auto = PdhgOptions()
    assert auto.ruiz_iters == "auto"
    assert [ruiz_passes(auto, n) for n in (None, 1, 2, 3, 4)] == [0, 0, 0, RUIZ_AUTO_PASSES, RUIZ_AUTO_PASSES]
    assert ruiz_passes(auto._replace(ruiz_iters=5), 2) == 5 and ruiz_passes(auto._replace(ruiz_iters=0), 4) == 0
    for bad in (-1, "always", 2.0, True, None):
        with pytest.raises(ValueError, match=r"PdhgOptions.ruiz_iters: expected 'auto' or an integer >= 0"):
            ruiz_passes(auto._replace(ruiz_iters=bad), 4)
    # the passes equilibrate: rows of very different norms come out of the scaling closer together
    rng = np.random.default_rng(0)
    G = rng.normal(size=(3, 6, 4)) * np.array([1e-2, 1.0, 1e2, 1.0, 1e-1, 10.0])[None, :, None]
    prob, _ = make_problem(G, rng.uniform(0.5, 1.0, (3, 6)), -np.ones((3, 4)), np.ones((3, 4)))
    mv, rmv = ops(np)

    def row_spread(state_dim):
        dr, dc = pdhg_scaling(ScalingOperator(mv, rmv, np.abs(prob.data), prob.data ** 2), prob, auto, np, state_dim)
        K = np.concatenate([prob.data, np.ones((6, 1, 3))], axis=1) * dr.y[:, None] * \
            np.concatenate([dc.x, dc.t[None]], axis=0)[None]
        norms = np.linalg.norm(K, axis=1)                     # (rows, B)
        return np.max(norms.max(axis=0) / norms.min(axis=0))
    assert row_spread(4) < 0.5 * row_spread(2)
