"""The 4-D double integrator on a box grid (conf/system/double_integrator.yaml).

The state is (p_x, s_x, p_y, s_y) with the look-ahead position s = p + beta * v: in plain
(p, v) coordinates no box is contractive for a double integrator, so box cells admit no tube
at all (see the config file); in (p, s) coordinates they do.
"""

from pathlib import Path

import numpy as np
import pytest
from omegaconf import OmegaConf
from scipy.spatial import Delaunay

from tubejax.abstraction import build_abstraction
from tubejax.model.geometry import Ball, sample_boundary, sample_uniform
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.workspace import box_grid

CONF = Path(__file__).resolve().parents[1] / "conf"
DT, BETA = 0.5, 2.0


def double_integrator(dt=DT, beta=None):
    """Two decoupled sampled double integrators; in (p, s = p + beta v) coordinates when beta is given."""
    A1 = np.array([[1.0, dt], [0.0, 1.0]])
    B1 = np.array([[dt * dt / 2], [dt]])
    if beta is not None:
        T = np.array([[1.0, 0.0], [1.0, beta]])
        A1, B1 = T @ A1 @ np.linalg.inv(T), T @ B1
    return np.kron(np.eye(2), A1), np.kron(np.eye(2), B1)


def test_config_matches_the_transformed_double_integrator():
    cfg = OmegaConf.load(CONF / "system" / "double_integrator.yaml")
    A, B = double_integrator(float(cfg.dt), float(cfg.beta))
    np.testing.assert_allclose(np.array(cfg.A, float), A, atol=1e-15)
    np.testing.assert_allclose(np.array(cfg.B, float), B, atol=1e-15)
    ws = OmegaConf.load(CONF / "workspace" / "boxgrid4d.yaml")
    d = box_grid(list(ws.lower), list(ws.upper), list(ws.divisions),
                 obstacles=[tuple(o) for o in ws.obstacles],
                 labels={k: tuple(v) for k, v in ws.labels.items()})
    assert d.dim == 4 and d.n_cells == 12
    # s-range == position range: v = (s - p) / beta never points out of the workspace
    lo, hi = np.array(ws.lower), np.array(ws.upper)
    np.testing.assert_array_equal(lo[[0, 2]], lo[[1, 3]])
    np.testing.assert_array_equal(hi[[0, 2]], hi[[1, 3]])


def test_position_velocity_boxes_give_no_tube():
    """In (p, v) coordinates a box cell cannot be steered into an equal box cell under any W."""
    A, B = double_integrator()
    sysm = LinearSystem(A=A, B=B, U=box_input_set(1.0, 2), W=Ball(4, 0.01))
    d = box_grid([0, -1, 0, -1], [2, 1, 1, 1], [2, 2, 1, 1])
    ts = build_abstraction(d, sysm, zshape="cell", L_max=4, progress=False)
    assert ts.n_edges == 0


@pytest.fixture(scope="module")
def di_ts():
    A, B = double_integrator(beta=BETA)
    sysm = LinearSystem(A=A, B=B, U=box_input_set(1.0, 2), W=Ball(4, 0.02))
    # x-axis: 2 x 2 cells in (p_x, s_x); y-axis: one cell the tube must stay in
    d = box_grid([0, 0, 0, 0], [2, 2, 1, 1], [2, 2, 1, 1])
    return build_abstraction(d, sysm, zshape="cell", L_max=8, progress=False)


def test_abstraction_has_verified_edges(di_ts):
    assert di_ts.n_edges >= 6
    assert di_ts.stats["n_unconfirmed"] == 0
    v = di_ts.verify()
    assert v.size == di_ts.n_edges and np.all(v <= 1e-9)
    assert all(e.margin >= -1e-9 for e in di_ts.edges)


def simulate_edge(ts, k, rng, runs=40, boundary=False):
    """Algorithm 1 in n-D: barycentric coordinates from a Delaunay triangulation of each tube set."""
    e, tube = ts.edges[k], ts.tubes[k]
    prob = ts.problem(k)
    Q = tube.vertices(ts.Z[e.src], ts.decomposition.cells[e.src])   # (L+1, n_v, n)
    n = Q.shape[2]
    x = sample_uniform(prob.source, rng, runs)
    x[: Q.shape[1]] = Q[0][: min(runs, Q.shape[1])]                  # the cell's corners too
    for ell in range(e.L):
        tri = Delaunay(Q[ell])
        s = tri.find_simplex(x, tol=1e-9)
        assert np.all(s >= 0), f"state left the tube at step {ell}"
        T = tri.transform[s]
        b = np.einsum("rij,rj->ri", T[:, :n], x - T[:, n])
        bary = np.hstack([b, 1 - b.sum(axis=1, keepdims=True)])
        assert np.all(bary >= -1e-9)
        lam = np.zeros((runs, Q.shape[1]))
        np.put_along_axis(lam, tri.simplices[s], bary, axis=1)
        np.testing.assert_allclose(lam @ Q[ell], x, atol=1e-9)
        u = lam @ tube.u[ell]
        assert np.all(ts.system.U.contains(u, tol=1e-9))
        draw = sample_boundary if boundary else sample_uniform
        w = draw(ts.system.W, rng, runs)
        x = x @ ts.system.A.T + u @ ts.system.B.T + w
        if ell + 1 < e.L:
            assert np.all(prob.safe.contains(x, tol=1e-9)), f"left S at step {ell + 1}"
    return x


@pytest.mark.parametrize("boundary", [False, True])
def test_every_edge_holds_in_simulation(di_ts, boundary):
    rng = np.random.default_rng(1)
    cells = di_ts.decomposition.cells
    for k, e in enumerate(di_ts.edges):
        xL = simulate_edge(di_ts, k, rng, boundary=boundary)
        assert np.all(cells[e.dst].contains(xL, tol=1e-9)), (e.src, e.dst, e.L)
