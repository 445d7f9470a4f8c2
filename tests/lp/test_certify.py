"""Float64 certificates on real tube LPs: accepted when valid, rejected when corrupted."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tubejax.lp.declarations.tube_operator import TUBE_OPERATOR
from tubejax.lp.engines.pdhg_adapters import host_flat_certificates
from tubejax.lp.engines.certify import (FEAS_TOL, MARGIN_SAFETY, dual_bound,
                                make_margin_certify, primal_violation)
from tubejax.lp.declarations.tube_lp import build_tube_lp
from tubejax.lp.engines.highs import solve_margin_lp
from tubejax.lp.declarations.tube_operator_data import build_tube_data
from tubejax.lp.declarations.margin_operator import pack
from tubejax.lp.declarations.tube_operator import (TUBE_OPERATOR, tube_matvec, tube_rhs, tube_rmatvec, unpack_x,
                                                   unpack_y)
from tubejax.model.zshape.kinds import make_z
from tubejax.model.problem import pair_problem
from tubejax.model.workspace.gridmap import load_grid_map

CORRIDOR = "/work/shared/validation/corridor.txt"


def host_tube_certificates(shape, data, X, Y):
    """The tube PDHG form's host re-check (what the engine trusts) at the pytree points ``X``, ``Y``."""
    return host_flat_certificates(TUBE_OPERATOR, shape, data, pack(X), pack(Y))


@pytest.fixture(scope="module")
def solved(paper_system):
    """Corridor pair (0, 1): infeasible at L = 1, 2, feasible (margin > 0) at L = 4."""
    from pathlib import Path
    path = CORRIDOR if Path(CORRIDOR).exists() else "tests/data/corridor.txt"
    dec = load_grid_map(path)
    sysm = paper_system(0.2)
    Z = [make_z("box", c) for c in dec.cells]
    probs = [pair_problem(dec, sysm, Z[0], 0, 1, L) for L in (1, 2, 4)]
    shape, data = build_tube_data(probs, L_pad=4)
    res = [solve_margin_lp(build_tube_lp(p)) for p in probs]
    return probs, shape, data, res


def _embed(shape, probs, res):
    """HiGHS primal / dual of each problem in the padded flat layout (columns = instances)."""
    from tubejax.lp.declarations.tube_operator import tube_dims
    nx, nr = tube_dims(shape)
    B = len(probs)
    z = np.zeros((nx + 1, B))
    y = np.zeros((nr, B))
    for b, (p, r) in enumerate(zip(probs, res)):
        L = p.L
        lp = build_tube_lp(p)
        ix = lp.index
        rows = lp.layout.split(r.y)                 # the HiGHS duals of each row family, by name
        tube = ix.split(r.x)
        zb = unpack_x(shape, z[:, b:b + 1])
        zb.p[:L, :, 0] = tube.p
        zb.eps[:L, 0] = tube.eps
        zb.u0[:, :, 0] = tube.u[0]
        zb.u[:L - 1, :, :, 0] = tube.u[1:]
        yb = unpack_y(shape, y[:, b:b + 1])
        yb.vertex_rows[0][:L - 1, :, 0] = rows["safe"]
        yb.vertex_rows[1][:, 0] = rows["target"][0]
        yb.y0[:, :, 0] = rows["dynamics"][0]
        yb.y4[:L - 1, :, :, 0] = rows["dynamics"][1:]
    return z, y


def test_highs_solutions_certify(solved):
    probs, shape, data, res = solved
    margins = np.array([r.margin for r in res])
    assert margins[0] < 0 and margins[1] < 0 and margins[2] > 0
    z, y = _embed(shape, probs, res)
    viol, bound = host_tube_certificates(shape, data, unpack_x(shape, z), unpack_y(shape, y))
    # the feasible tube satisfies Problem 2, the infeasible ones' duals prove t* < 0
    assert viol[2] <= FEAS_TOL
    assert np.all(bound[:2] < -MARGIN_SAFETY)
    np.testing.assert_allclose(bound, margins, atol=1e-7)       # HiGHS duals are optimal
    assert np.all(bound >= margins - 1e-9)


def test_corrupted_primal_point_is_rejected(solved):
    probs, shape, data, res = solved
    z, y = _embed(shape, probs, res)
    zc = z.copy()
    X = unpack_x(shape, zc)
    X.p[3, :, 2] = probs[2].source.centroid    # the last tube centre back in the source cell
    viol, _ = host_tube_certificates(shape, data, X, unpack_y(shape, y))
    assert viol[2] > 0.1
    X = unpack_x(shape, z.copy())
    X.u0[0, 0, 2] = 1.5                        # an input outside U (a hard bound)
    viol, _ = host_tube_certificates(shape, data, X, unpack_y(shape, y))
    assert viol[2] >= 0.5 - 1e-12
    X = unpack_x(shape, z.copy())
    X.eps[0, 2] = np.nan
    viol, _ = host_tube_certificates(shape, data, X, unpack_y(shape, y))
    assert viol[2] == np.inf


def test_corrupted_dual_ray_is_rejected(solved):
    probs, shape, data, res = solved
    z, y = _embed(shape, probs, res)
    Z = unpack_x(shape, z)
    # drop the dynamics rows (C4): still a valid bound, but no longer a proof of t* < 0
    # (without C4 any tube inside the cells is feasible)
    Y = unpack_y(shape, y.copy())
    Y.y0[:] = 0.0
    Y.y4[:] = 0.0
    _, bound = host_tube_certificates(shape, data, Z, Y)
    assert np.all(bound[:2] >= -MARGIN_SAFETY)
    # zero, NaN, or sign-flipped duals prove nothing
    for bad in (np.zeros_like(y), np.full_like(y, np.nan), -y):
        _, bound = host_tube_certificates(shape, data, Z, unpack_y(shape, bad))
        assert np.all(bound == np.inf)


def test_bound_is_sound_for_random_duals(solved):
    probs, shape, data, res = solved
    margins = np.array([r.margin for r in res])
    rng = np.random.default_rng(0)
    z, y = _embed(shape, probs, res)
    for _ in range(50):
        yr = rng.exponential(size=y.shape) * (rng.random(y.shape) < 0.3)
        _, bound = host_tube_certificates(shape, data, unpack_x(shape, z), unpack_y(shape, yr))
        assert np.all(bound >= margins - 1e-9)


def test_jax_and_numpy_certificates_agree(solved):
    probs, shape, data, res = solved
    z, y = _embed(shape, probs, res)
    rng = np.random.default_rng(1)
    y = y + 0.01 * rng.random(y.shape)
    g, mask = tube_rhs(shape, data)
    lo, hi = TUBE_OPERATOR.bounds(shape, data)
    v_np = primal_violation(lambda d, v: tube_matvec(shape, d, v), data, g, mask, lo, hi, unpack_x(shape, z))
    b_np = dual_bound(lambda d, v: tube_rmatvec(shape, d, v), data, g, mask, lo, hi, unpack_y(shape, y))
    J = lambda t: jax.tree_util.tree_map(jnp.asarray, t)        # noqa: E731
    cert = make_margin_certify(lambda d, v: tube_matvec(shape, d, v, jnp),
                               lambda d, v: tube_rmatvec(shape, d, v, jnp), jnp)
    from tubejax.lp.engines.pdhg import PdhgProblem
    prob = PdhgProblem(J(data), None, J(g), J(lo), J(hi), J(mask))
    v_j, b_j = jax.jit(cert)(prob, J(unpack_x(shape, z)), J(unpack_y(shape, y)))
    np.testing.assert_allclose(v_j, v_np, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(b_j, b_np, rtol=1e-12, atol=1e-15)
