"""The matrix-free tube operator against the dense ``build_tube_lp`` matrix and ``jax.linear_transpose``."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tubejax.model.geometry import Ball
from tubejax.lp.declarations.tube_lp import build_tube_lp
from tubejax.lp.declarations.tube_operator_data import build_tube_data
from tubejax.lp.declarations.margin_operator import pack
from tubejax.lp.declarations.tube_operator import (SHARED_FIELDS, tube_dims, tube_matvec, tube_rhs, tube_rmatvec,
                                                   unpack_x, unpack_y)
from tubejax.model.zshape.kinds import make_z
from tubejax.model.problem import pair_problem
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.workspace.gridmap import load_grid_map

PAPER = "conf/workspace/maps/paper.txt"


@pytest.fixture(scope="module")
def problems():
    dec = load_grid_map(PAPER)
    A = np.array([[1.0, 0.1], [-0.05, 0.95]])
    sysm = LinearSystem(A=A, B=np.array([[0.5, 0.1], [0.0, 0.4]]), U=box_input_set(1.0, 2), W=Ball(2, 0.1))
    Z = [make_z("box", c) for c in dec.cells]
    pairs = [(0, 1), (3, 4), (7, 2), (0, 9), (10, 21), (5, 14)]

    def make(L):
        return [pair_problem(dec, sysm, Z[i], i, j, L) for i, j in pairs]
    return make


def _dense(shape, data, b):
    """Dense ``K`` (rows, n_x + 1), rhs and mask of instance ``b`` through the operator."""
    d = jax.tree_util.tree_map(lambda a: a[..., b:b + 1], data)
    nx, nr = tube_dims(shape)
    K = pack(tube_matvec(shape, d, unpack_x(shape, np.eye(nx + 1))))
    g, mask = tube_rhs(shape, d)
    return K, pack(g)[:, 0], pack(mask)[:, 0], d


@pytest.mark.parametrize("L", [1, 2, 4])
def test_operator_matches_dense_lp(problems, L):
    probs = problems(L)
    shape, data = build_tube_data(probs)
    assert shape.f_v[0] >= 4 and shape.v_steps == ("interior", "last")
    for b, pr in enumerate(probs):
        lp = build_tube_lp(pr)
        K, g, mask, _ = _dense(shape, data, b)
        rows = mask > 0
        nx = lp.G.shape[1]
        np.testing.assert_allclose(K[rows, :nx], lp.G, atol=1e-14)
        np.testing.assert_allclose(K[rows, nx], 1.0)
        np.testing.assert_allclose(g[rows], lp.g, atol=1e-14)
        assert np.all(K[~rows] == 0)
        np.testing.assert_allclose(data.x_lower[:, b], lp.lb)
        np.testing.assert_allclose(data.x_upper[:, b], lp.ub)


def test_padded_horizon_keeps_the_rows(problems):
    """An instance padded to a longer horizon has the same rows on its own variables."""
    probs = problems(2)
    shape, data = build_tube_data(probs, L_pad=5)
    assert shape.L == 5
    for b, pr in enumerate(probs):
        lp = build_tube_lp(pr)
        K, g, mask, _ = _dense(shape, data, b)
        rows = mask > 0
        ix, n, nv, m = lp.index, 2, pr.source.n_vertices, 2
        # columns of the padded layout that belong to the instance's own L = 2 variables
        cols = np.concatenate([np.arange(2 * n), 5 * n + np.arange(2), 5 * n + 5 + np.arange(2 * nv * m)])
        Ks = K[rows][:, cols]
        assert np.all(np.delete(K[rows], np.concatenate([cols, [K.shape[1] - 1]]), axis=1) == 0)
        # same multiset of rows (order differs only by padding)
        a = np.round(np.hstack([Ks, g[rows, None]]), 12)
        bb = np.round(np.hstack([lp.G, lp.g[:, None]]), 12)
        assert sorted(map(tuple, a)) == sorted(map(tuple, bb))
        assert ix.size == len(cols)


@pytest.mark.parametrize("L", [1, 3])
def test_rmatvec_is_the_transpose(problems, L):
    probs = problems(L)
    shape, data = build_tube_data(probs, L_pad=L + 1)
    dj = jax.tree_util.tree_map(jnp.asarray, data)
    nx, nr = tube_dims(shape)
    B = len(probs)
    rng = np.random.default_rng(0)
    x = unpack_x(shape, jnp.asarray(rng.standard_normal((nx + 1, B))), jnp)
    y = unpack_y(shape, jnp.asarray(rng.standard_normal((nr, B))), jnp)
    mv = lambda v: tube_matvec(shape, dj, v, jnp)            # noqa: E731
    (kty_ref,) = jax.jit(jax.linear_transpose(mv, x))(y)
    kty = jax.jit(lambda v: tube_rmatvec(shape, dj, v, jnp))(y)
    for a, b in zip(jax.tree_util.tree_leaves(kty), jax.tree_util.tree_leaves(kty_ref)):
        np.testing.assert_allclose(a, b, atol=1e-12)
    # and the dense view agrees with NumPy
    K, _, _, d = _dense(shape, data, 0)
    KT = pack(tube_rmatvec(shape, d, unpack_y(shape, np.eye(nr))))
    np.testing.assert_allclose(KT, K.T, atol=1e-14)


@pytest.mark.parametrize("L", [1, 3])
def test_shared_coefficients_give_the_same_operator(problems, L):
    """``share=True`` stores the Z-only coefficients once; K and K^T are unchanged."""
    probs = problems(L)
    shape, data = build_tube_data(probs, L_pad=L + 1)
    shape_s, shared = build_tube_data(probs, L_pad=L + 1, share=True)
    assert shape_s == shape
    B = len(probs)
    for k in SHARED_FIELDS + ("dyn0_stacked", "dyn_stacked"):
        assert getattr(shared, k).shape == getattr(data, k).shape[:-1] + (1,), k
    for k in ("dyn0_rhs", "x_lower", "last_step"):
        assert getattr(shared, k).shape[-1] == B, k
    assert all(a.shape[-1] == B for a in jax.tree_util.tree_leaves(shared.vertex_rows))
    nx, nr = tube_dims(shape)
    rng = np.random.default_rng(1)
    x = unpack_x(shape, rng.standard_normal((nx + 1, B)))
    y = unpack_y(shape, rng.standard_normal((nr, B)))
    leaves = jax.tree_util.tree_leaves
    for a, b in zip(leaves(tube_matvec(shape, shared, x)), leaves(tube_matvec(shape, data, x))):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-14)
    for a, b in zip(leaves(tube_rmatvec(shape, shared, y)), leaves(tube_rmatvec(shape, data, y))):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-14)
    for u, v in zip(leaves(tube_rhs(shape, shared)), leaves(tube_rhs(shape, data))):
        np.testing.assert_array_equal(u, v)


def test_coefficients_are_not_shared_when_z_differs(problems):
    probs = problems(2)
    probs[1] = dataclasses.replace(probs[1], Z=make_z("box", probs[1].source, scale=2.0))
    _, data = build_tube_data(probs, share=True)
    assert data.dyn_p.shape[-1] == len(probs)


@pytest.mark.parametrize("L, L_pad", [(1, 1), (3, 3), (2, 4)])
def test_hard_input_rows_match_the_dense_lp(L, L_pad):
    """A non-box ``U``: C5 are hard rows (no ``t``), taken by the operator from the declaration,
    after the margin rows, each the dense LP's ``G_hard`` row unit-normalised; ``K^T`` is the
    transpose (``jax.linear_transpose``)."""
    from tubejax.model.system import one_norm_input_set

    dec = load_grid_map(PAPER)
    sysm = LinearSystem(A=np.array([[1.0, 0.1], [-0.05, 0.95]]), B=np.array([[0.5, 0.1], [0.0, 0.4]]),
                        U=one_norm_input_set(1.0, 2), W=Ball(2, 0.1))
    assert not sysm.u_is_box
    Z = [make_z("box", c) for c in dec.cells]
    probs = [pair_problem(dec, sysm, Z[i], i, j, L) for i, j in [(0, 1), (3, 4), (7, 2)]]
    shape, data = build_tube_data(probs, L_pad=L_pad)
    assert shape.f_u == 4
    nx, nr = tube_dims(shape)
    for b, pr in enumerate(probs):
        lp = build_tube_lp(pr)
        K, g, mask, d = _dense(shape, data, b)
        rows = mask > 0
        nm, nh = lp.G.shape[0], lp.G_hard.shape[0]
        assert rows.sum() == nm + nh == len(lp.G) + L * pr.source.n_vertices * 4
        hn = np.linalg.norm(lp.G_hard, axis=1)
        if L_pad == L:
            Kr = K[rows]
            np.testing.assert_allclose(Kr[:nm, :nx], lp.G, atol=1e-14)
            np.testing.assert_allclose(Kr[nm:, :nx], lp.G_hard / hn[:, None], atol=1e-14)
            np.testing.assert_allclose(g[rows][nm:], lp.g_hard / hn, atol=1e-14)
        np.testing.assert_allclose(K[rows][:nm, nx], 1.0)
        np.testing.assert_allclose(K[rows][nm:, nx], 0.0)              # hard rows: no margin
        assert np.all(K[~rows] == 0)
        KT = pack(tube_rmatvec(shape, d, unpack_y(shape, np.eye(nr))))
        np.testing.assert_allclose(KT, K.T, atol=1e-14)
    dj = jax.tree_util.tree_map(jnp.asarray, data)
    rng = np.random.default_rng(1)
    x = unpack_x(shape, jnp.asarray(rng.standard_normal((nx + 1, len(probs)))), jnp)
    y = unpack_y(shape, jnp.asarray(rng.standard_normal((nr, len(probs)))), jnp)
    (ref,) = jax.linear_transpose(lambda v: tube_matvec(shape, dj, v, jnp), x)(y)
    for a, c in zip(jax.tree_util.tree_leaves(tube_rmatvec(shape, dj, y, jnp)), jax.tree_util.tree_leaves(ref)):
        np.testing.assert_allclose(a, c, atol=1e-12)
