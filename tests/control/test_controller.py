"""Algorithm 1 in closed form: triangulations, barycentric weights, invariance of the tube."""

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from hypothesis import given, settings, strategies as st  # noqa: E402

from tubejax.analyses.control import (control_step, edge_controller, plan_controller, plan_sequence,  # noqa: E402
                                      stack_controllers, triangulate)
from tubejax.analyses.control.controller import PAD_H, _edge_arrays  # noqa: E402
from tubejax.model.geometry import Ball, Polytope  # noqa: E402
from tubejax.model.system import LinearSystem, box_input_set  # noqa: E402

step_batch = jax.jit(jax.vmap(control_step))
step1 = jax.jit(control_step)


@pytest.fixture(scope="module")
def corridor():
    from tubejax.abstraction import build_abstraction
    from tubejax.model.workspace.gridmap import load_grid_map
    d = load_grid_map("/work/shared/validation/corridor.txt")
    s = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
    return build_abstraction(d, s, L_max=10, progress=False)


@pytest.fixture(scope="module")
def all_steps(corridor):
    """Every (edge, l) of the corridor abstraction as one stack, with the control-set vertices."""
    ts = corridor
    ctrl = stack_controllers([_edge_arrays(ts, k) for k in range(ts.n_edges)])
    Qv = np.concatenate([ts.tubes[k].vertices(ts.Z[e.src], ts.decomposition.cells[e.src])[:-1]
                         for k, e in enumerate(ts.edges)])          # (S, n_v, n)
    return ctrl, Qv


@pytest.mark.parametrize("n", [1, 2, 3, 4])
def test_triangulate_box_reproduces_points(n):
    P = Polytope.box(-np.ones(n), 2 * np.ones(n))
    tri = triangulate(P.vertices)
    assert tri.simplices.shape[1] == n + 1
    rng = np.random.default_rng(n)
    u = rng.normal(size=(P.n_vertices, 2))
    x = rng.uniform(-1, 2, size=(50, n))
    k = tri.simplices.shape[0]
    uu, lam, out = step_batch(jnp.asarray(x), *(jnp.broadcast_to(a, (50,) + a.shape) for a in
                               (jnp.asarray(tri.T), jnp.asarray(tri.r),
                                jnp.asarray(tri.simplices), jnp.ones(k, bool),
                                jnp.asarray(u))))
    lam = np.asarray(lam)
    assert np.all(lam >= 0) and np.allclose(lam.sum(1), 1)
    assert np.allclose(lam @ P.vertices, x, atol=1e-12)
    assert np.allclose(np.asarray(uu), lam @ u)
    assert np.all(np.asarray(out) == 0)
    assert np.all(np.count_nonzero(lam > 1e-15, axis=1) <= n + 1)


def test_triangulate_hexagon_and_rejects_flat():
    ang = np.arange(6) * np.pi / 3
    tri = triangulate(np.stack([np.cos(ang), np.sin(ang)], 1))
    assert tri.simplices.shape == (4, 3)
    with pytest.raises(ValueError):
        triangulate(np.array([[0.0, 0], [1, 1], [2, 2]]))


def test_vertices_map_to_their_inputs(corridor, all_steps):
    """At a tube vertex q_k(l), lambda = e_k and u = u_k(l), for every edge and step."""
    ts = corridor
    ctrl, Qv = all_steps
    U = np.concatenate([t.u for t in ts.tubes])                      # (S, n_v, m)
    for v in range(Qv.shape[1]):
        u, lam, out = step_batch(jnp.asarray(Qv[:, v]), ctrl.T, ctrl.r, ctrl.simplices,
                                 ctrl.valid, ctrl.u)
        assert np.allclose(np.asarray(lam), np.eye(Qv.shape[1])[v], atol=1e-9)
        assert np.allclose(np.asarray(u), U[:, v], atol=1e-9)
        assert float(jnp.max(out)) <= 1e-12


def test_edge_controller_shapes(corridor):
    ts = corridor
    e = ts.edges[0]
    c = edge_controller(ts, 0)
    L = e.L
    assert c.u.shape == (L, 4, 2) and c.T.shape == (L, 2, 2, 2) and c.r.shape == (L, 2, 2)
    assert c.simplices.shape == (L, 2, 3) and c.valid.shape == (L, 2)
    assert c.H.shape == (L + 1, 4, 2) and c.h.shape == (L + 1, 4)
    assert c.u.dtype == jnp.float64 and c.n_steps == L
    # check sets: 0 = the source cell, L = Q_L inside the target cell
    assert np.allclose(np.asarray(c.h[0]), ts.decomposition.cells[e.src].h)
    q = ts.tubes[0].vertices(ts.Z[e.src], ts.decomposition.cells[e.src])
    for l in range(L + 1):
        assert np.max(q[l] @ np.asarray(c.H[l]).T - np.asarray(c.h[l])) <= 1e-12
    start = ts.decomposition.cells_with_label("1")[0]
    p = plan_sequence(ts, start, ["2"])
    pc = plan_controller(ts, p)
    assert pc.u.shape[0] == p.cost and pc.H.shape[0] == p.cost + 1


def test_padding_keeps_results():
    """Mixed triangle/square cells: padded simplices and vertices never get picked."""
    sq = _edge_like(Polytope.box([0.0, 0.0], [1.0, 1.0]))
    tr = _edge_like(Polytope.from_vertices([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]))
    c = stack_controllers([tr, sq])
    assert c.u.shape[1:] == (4, 2) and c.T.shape[1] == 2
    assert not bool(c.valid[0, 1]) and float(c.h[0, 3]) == PAD_H
    u, lam, out = step1(jnp.array([0.2, 0.3]), c.T[0], c.r[0], c.simplices[0], c.valid[0],
                               c.u[0])
    assert float(out) == 0 and float(lam[3]) == 0
    V = Polytope.from_vertices([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]).vertices
    assert np.allclose(np.asarray(lam)[:3] @ V, [0.2, 0.3])
    assert c.H.shape == (3, 4, 2)


def _edge_like(P):
    tri = triangulate(P.vertices)
    u = np.ones((P.n_vertices, 2))
    return [tri.T], [tri.r], [tri.simplices], [u], [P.H, P.H], [P.h, P.h]


def test_outside_is_reported_and_input_stays_in_U(corridor):
    ts = corridor
    c = edge_controller(ts, 3)
    U = ts.system.U
    for x in ([5.0, 5.0], [-3.0, 0.2], [0.5, 100.0]):
        u, lam, out = step1(jnp.asarray(x), c.T[1], c.r[1], c.simplices[1], c.valid[1],
                                   c.u[1])
        assert float(out) > 0
        lam = np.asarray(lam)
        assert np.all(lam >= 0) and np.isclose(lam.sum(), 1)
        assert U.violation(np.asarray(u)) <= 1e-12


def test_jit_does_not_recompile():
    traces = []

    def f(x, T, r, s, v, u):
        traces.append(1)
        return control_step(x, T, r, s, v, u)

    jf = jax.jit(f)
    tri = triangulate(Polytope.box([0.0, 0.0], [1.0, 1.0]).vertices)
    args = (jnp.asarray(tri.T), jnp.asarray(tri.r), jnp.asarray(tri.simplices),
            jnp.ones(2, bool), jnp.ones((4, 2)))
    a = jf(jnp.array([0.1, 0.2]), *args)
    b = jf(jnp.array([0.7, 0.4]), *args)
    assert len(traces) == 1
    assert not np.allclose(np.asarray(a[1]), np.asarray(b[1]))


@settings(max_examples=60, deadline=None)
@given(weights=st.lists(st.floats(0.0, 1.0), min_size=4, max_size=4),
       angle=st.floats(0.0, 2 * np.pi), frac=st.floats(0.0, 1.0))
def test_next_state_in_next_tube_set(all_steps, corridor, weights, angle, frac):
    """x in Q_l (any convex combination of its vertices), w in W => x+ in Q_{l+1}, every edge, every l."""
    ctrl, Qv = all_steps
    sysm = corridor.system
    lam = np.asarray(weights) + 1e-12
    lam /= lam.sum()
    x = np.einsum("k,skn->sn", lam, Qv)
    w = sysm.W.radius * frac * np.array([np.cos(angle), np.sin(angle)])
    u, _, out = step_batch(jnp.asarray(x), ctrl.T, ctrl.r, ctrl.simplices, ctrl.valid, ctrl.u)
    assert float(jnp.max(out)) <= 1e-9
    xn = x @ sysm.A.T + np.asarray(u) @ sysm.B.T + w
    H, h = np.asarray(ctrl.H[1:]), np.asarray(ctrl.h[1:])
    viol = np.max(np.einsum("sfn,sn->sf", H, xn) - h, axis=1)
    assert np.max(viol) <= 1e-9, f"worst step {np.argmax(viol)}: {np.max(viol)}"
    assert np.max(np.asarray(u) @ sysm.U.H.T - sysm.U.h) <= 1e-9
