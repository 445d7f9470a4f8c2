"""dt*/dZ by the envelope theorem: the Lagrangian's rows against build_tube_lp, the gradient against
finite differences of HiGHS optima, and the custom_vjp around the batched solve (no recompiles)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tubejax.model.geometry import Ball, Polytope
from tubejax.lp.declarations.tube_lp import build_tube_lp
from tubejax.lp.declarations.tube_variables import tube_variable_bounds
from tubejax.lp.engines.highs import solve_margin_lp
from tubejax.model.problem import pair_problem
from tubejax.model.system import LinearSystem, one_norm_input_set
from tubejax.model.workspace.gridmap import load_grid_map, parse_grid_map
from tubejax.analyses.zshape.highs_duals import MarginLpSolver
from tubejax.analyses.zshape.lagrangian import MarginSolution, lagrangian, padded_duals, pair_geometry, system_arrays
from tubejax.analyses.zshape.margin import PairMargins, learning_polytope
from tubejax.model.zshape.params import ZFamily, z_facets, z_from_theta

QUAD = ZFamily("polygon", 2, 4, 4)
L1 = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=one_norm_input_set(1.0, 2), W=Ball(2, 0.2))
ROT = LinearSystem(A=np.array([[1.0, 0.1], [-0.1, 1.0]]), B=0.5 * np.eye(2),
                   U=Polytope.from_vertices([[1.0, 0], [0, 1], [-1, 0], [0, -1]]),
                   W=Polytope.from_vertices([[0.1, 0.0], [0.0, 0.1], [-0.1, 0.0], [0.0, -0.1]]))


@pytest.fixture(scope="module")
def corridor(corridor_path):
    return load_grid_map(corridor_path)


def skewed_theta(seed):
    rng = np.random.default_rng(seed)
    th = np.array([[-1.0, -1], [1, -1], [1, 1], [-1, 1]]) + 0.1 * rng.standard_normal((4, 2))
    th[1, 1] = th[0, 1] + 0.05                       # keep vertex 1 the lowest (the pairing)
    return th


def z_poly(theta):
    return learning_polytope(QUAD, np.asarray(z_from_theta(QUAD, theta)))


def margin(decomp, system, theta, i, j, L):
    return solve_margin_lp(build_tube_lp(pair_problem(decomp, system, z_poly(theta), i, j, L))).margin


def lag_of_theta(theta, g, sol, sa):
    z = z_from_theta(QUAD, theta)
    H, h = z_facets(QUAD, z)
    return lagrangian(z, H, h, g, sol, sa)


_JIT = {}


def lag_jit(system, grad=False):
    """Jitted Lagrangian (or its gradient) with the system's arrays as constants."""
    key = (id(system), grad)
    if key not in _JIT:
        sa = system_arrays(system)
        f = lambda th, g, sol: lag_of_theta(th, g, sol, sa)          # noqa: E731
        _JIT[key] = jax.jit(jax.grad(f) if grad else f)
    return _JIT[key]


@pytest.mark.parametrize("L_pad, extra_fs", [(3, 0), (5, 2)])
def test_lagrangian_rows_equal_the_dense_lp(corridor, L_pad, extra_fs):
    """sum_r y_r (g_r - a_r x) and the eps-bound term, against build_tube_lp on random points (with
    eps >= 0, as the LP's bounds keep it: there max_k H q_k(l) is the LP's row H p_l + sigma_Z(H) eps_l)."""
    rng = np.random.default_rng(0)
    for (i, j) in [(0, 1), (10, 15), (1, 0)]:            # free and obstacle cases
        prob = pair_problem(corridor, L1, z_poly(skewed_theta(1)), i, j, 3)
        lp = build_tube_lp(prob)
        fs = prob.safe.H.shape[0]
        x = rng.standard_normal(lp.index.size)
        x[lp.index.eps] = np.abs(x[lp.index.eps])
        y = rng.random(lp.G.shape[0])
        d = rng.standard_normal(3)
        tube = lp.index.split(x)
        pad = lambda a, shape: np.pad(a, [(0, s - a.shape[k]) for k, s in enumerate(shape)])  # noqa: E731
        f_pad = {"safe": fs + extra_fs, "target": prob.target.H.shape[0]}
        sol = MarginSolution(0.0, pad(tube.p, (L_pad, 2)), pad(tube.eps, (L_pad,)), pad(tube.u, (L_pad, 4, 2)),
                             padded_duals(lp.layout.split(y), 3, L_pad, f_pad), pad(d, (L_pad,)))
        g = pair_geometry(prob, f_pad)
        got = float(lag_jit(L1)(skewed_theta(1), g, sol))
        lb, ub = tube_variable_bounds(prob)
        eb = np.where(d < 0, ub[lp.index.eps], lb[lp.index.eps])
        want = y @ (lp.g - lp.G @ x) - d @ eb
        assert got == pytest.approx(want, rel=1e-12, abs=1e-12)


@pytest.mark.parametrize("system_name, i, j, L, seed", [
    ("l1", 0, 1, 3, 1), ("l1", 10, 15, 6, 1), ("l1", 9, 20, 10, 2), ("l1", 1, 0, 2, 3),
    ("rot", 0, 1, 4, 1), ("rot", 11, 12, 6, 2),
])
def test_gradient_matches_finite_differences(corridor, system_name, i, j, L, seed):
    system = L1 if system_name == "l1" else ROT
    theta = skewed_theta(seed)
    prob = pair_problem(corridor, system, z_poly(theta), i, j, L)
    sol = MarginLpSolver(warm=False).solve(prob)
    g = pair_geometry(prob)
    grad = np.asarray(lag_jit(system, grad=True)(theta, g, sol))
    h = 1e-6
    fd = np.zeros_like(theta)
    for a in range(4):
        for b in range(2):
            e = np.zeros_like(theta)
            e[a, b] = h
            up, dn = margin(corridor, system, theta + e, i, j, L), margin(corridor, system, theta - e, i, j, L)
            fd[a, b] = (up - dn) / (2 * h)
    assert float(sol.t) == pytest.approx(margin(corridor, system, theta, i, j, L), abs=1e-12)
    assert np.linalg.norm(fd) > 1e-4                             # a real dependence on Z
    assert np.linalg.norm(grad - fd) <= 1e-3 * np.linalg.norm(fd)


def test_custom_vjp_batched_solve_and_no_recompile():
    decomp = parse_grid_map("...\n.#.")
    pairs = np.array([(0, 1), (1, 2), (0, 3), (2, 4)])
    pm = PairMargins(decomp, L1, pairs, QUAD, L_max=6)
    th = skewed_theta(4)
    w = jnp.array([1.0, -0.5, 2.0, 0.3])

    @jax.jit
    def f(theta, L):
        return jnp.sum(w * pm(jnp.broadcast_to(z_from_theta(QUAD, theta), (4, 4, 2)), L))

    vg = jax.jit(jax.value_and_grad(f))
    L = jnp.array([3, 4, 6, 5])
    v, g = vg(th, L)
    t = np.array([margin(decomp, L1, th, i, j, int(l)) for (i, j), l in zip(pairs, L)])
    assert float(v) == pytest.approx(float(np.sum(np.asarray(w) * t)), abs=1e-10)
    fd = np.zeros_like(th)
    for a in range(4):
        for b in range(2):
            e = np.zeros_like(th)
            e[a, b] = 1e-6
            fd[a, b] = (float(f(th + e, L)) - float(f(th - e, L))) / 2e-6
    assert np.linalg.norm(np.asarray(g) - fd) <= 1e-3 * np.linalg.norm(fd)
    vg(th + 0.01, jnp.array([2, 5, 6, 6]))                    # new Z and horizons: same executable
    assert vg._cache_size() == 1 and f._cache_size() == 1
    np.testing.assert_allclose(np.asarray(pm(jnp.broadcast_to(z_from_theta(QUAD, th), (4, 4, 2)), L)), t,
                               atol=1e-12)


def test_gradient_of_an_eight_vertex_z_paired_with_edge_points(corridor):
    """A chamfer-family Z (8 vertices, the cell's vertices and edge midpoints as q_k(0)): the
    custom_vjp gradient against finite differences of HiGHS optima on the refined problems."""
    from tubejax.model.zshape.kinds import make_z

    fam = ZFamily("polygon", 2, 8, 8)
    rng = np.random.default_rng(5)
    theta = np.asarray(make_z("chamfer", corridor.cells[0]).vertices) * 1.0
    theta[1:] += 0.03 * rng.standard_normal((7, 2))             # vertex 0 stays the lowest
    pairs = np.array([(0, 1), (10, 15)])
    pm = PairMargins(corridor, L1, pairs, fam, L_max=6)
    L = jnp.array([3, 6])

    def f(th):
        return jnp.sum(pm(jnp.broadcast_to(z_from_theta(fam, th), (2, 8, 2)), L))

    v, g = jax.value_and_grad(f)(theta)
    Z = learning_polytope(fam, z_from_theta(fam, theta))
    direct = sum(solve_margin_lp(build_tube_lp(pair_problem(corridor, L1, Z, int(i), int(j), int(l)))).margin
                 for (i, j), l in zip(pairs, [3, 6]))
    assert float(v) == pytest.approx(direct, abs=1e-10)
    assert pair_problem(corridor, L1, Z, 0, 1, 3).source.n_vertices == 8
    fd = np.zeros_like(theta)
    for a in range(8):
        for b in range(2):
            e = np.zeros_like(theta)
            e[a, b] = 1e-6
            fd[a, b] = (float(f(theta + e)) - float(f(theta - e))) / 2e-6
    assert np.linalg.norm(fd) > 1e-4
    assert np.linalg.norm(np.asarray(g) - fd) <= 1e-3 * np.linalg.norm(fd)
