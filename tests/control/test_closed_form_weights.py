"""Algorithm 1's weights in closed form (a fixed triangulation) against an LP (HiGHS).

Algorithm 1 asks for any ``lambda >= 0``, ``sum lambda = 1`` with ``x = sum lambda_k q_k(l)``. HiGHS
decides independently whether such weights exist (a feasibility LP over the step's vertices); the
closed-form weights must exist exactly when HiGHS finds some, and must satisfy the three conditions
(docs/math/control.md, "The closed-form weights are an Algorithm 1 choice").
"""

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from scipy.optimize import linprog  # noqa: E402

from tubejax.analyses.control import control_step, stack_controllers  # noqa: E402
from tubejax.analyses.control.controller import _edge_arrays  # noqa: E402
from tubejax.model.geometry import Ball  # noqa: E402
from tubejax.model.system import LinearSystem, box_input_set  # noqa: E402

step_batch = jax.jit(jax.vmap(control_step))


@pytest.fixture(scope="module")
def corridor_steps():
    """Every (edge, l) of the corridor abstraction: the controller stack and each step's vertices."""
    from tubejax.abstraction import build_abstraction
    from tubejax.model.workspace.gridmap import load_grid_map
    d = load_grid_map("/work/shared/validation/corridor.txt")
    s = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
    ts = build_abstraction(d, s, L_max=10, progress=False)
    ctrl = stack_controllers([_edge_arrays(ts, k) for k in range(ts.n_edges)])
    Qv = np.concatenate([ts.tubes[k].vertices(ts.Z[e.src], ts.decomposition.cells[e.src])[:-1]
                         for k, e in enumerate(ts.edges)])          # (S, n_v, n)
    return ctrl, Qv


def _lp_weights_exist(V, x) -> bool:
    """HiGHS: is there ``lambda >= 0``, ``sum lambda = 1``, ``V^T lambda = x``?"""
    A_eq = np.vstack([V.T, np.ones(len(V))])
    res = linprog(np.zeros(len(V)), A_eq=A_eq, b_eq=np.append(x, 1.0), bounds=(0, None), method="highs")
    assert res.status in (0, 2), res.message
    return res.status == 0


def test_weights_agree_with_lp_inside_and_outside(corridor_steps):
    ctrl, Qv = corridor_steps
    rng = np.random.default_rng(7)
    S = len(Qv)
    steps = rng.choice(S, size=min(S, 25), replace=False)
    for s in steps:
        V = Qv[s]
        c = V.mean(0)
        span = np.ptp(V, axis=0).max()
        # inside: random convex combinations and the vertices; outside: each boundary point pushed 5 % away
        # from the centroid (an interior point), which leaves the hull
        lam = rng.dirichlet(np.ones(len(V)), size=6)
        inside = np.vstack([lam @ V, V])
        outside = c + 1.05 * (V - c)
        X = np.vstack([inside, outside])
        args = (jnp.asarray(a[s])[None].repeat(len(X), 0) for a in (ctrl.T, ctrl.r, ctrl.simplices,
                                                                   ctrl.valid, ctrl.u))
        u, lam_cf, out = (np.asarray(a) for a in step_batch(jnp.asarray(X), *args))
        nv = len(V)
        for x, lw, o, uu in zip(X, lam_cf, out, u):
            exists = _lp_weights_exist(V, x)
            assert exists == (o <= 1e-12), (s, x, o)
            assert np.all(lw >= 0) and abs(lw.sum() - 1) <= 1e-12
            assert np.allclose(uu, lw @ np.asarray(ctrl.u[s]), atol=1e-12)
            if exists:          # Algorithm 1's three conditions, to rounding
                assert np.max(np.abs(lw[:nv] @ V - x)) <= 1e-12 * max(1.0, span)
            assert np.all(lw[nv:] == 0)
