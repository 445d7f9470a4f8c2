"""The open-loop LP through the batched, certified PDHG solver: operator, validation, HiGHS equality."""

from functools import partial
import json
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tubejax.abstraction import build_abstraction
from tubejax.model.geometry import Ball, Polytope
from tubejax.model.problem import TubeProblem
from tubejax.lp.declarations.openloop_lp import OpenLoopPlan, build_openloop_lp, openloop_violation
from tubejax.lp.evidence.verdict import highs_solver, highs_verdict
from tubejax.lp.batch.batch_solver import pdhg_solver
from tubejax.lp.evidence.records.openloop_record import OPENLOOP_PDHG
from tubejax.lp.declarations.openloop_operator import openloop_coef_data, openloop_coef_ops
from tubejax.lp.declarations.openloop_operator import (openloop_dims, openloop_matvec,
                                          openloop_rhs, openloop_rmatvec, openloop_rmatvec_derived,
                                          openloop_transpose, unpack_x, unpack_y)
from tubejax.lp.declarations.margin_operator import pack
from tubejax.lp.declarations.openloop_operator_data import build_openloop_data
from tubejax.model.zshape.kinds import make_z
from tubejax.model.problem import pair_problem
from tubejax.model.system import LinearSystem, box_input_set, one_norm_input_set
from tubejax.model.workspace.gridmap import load_grid_map

openloop_solve_batch = highs_solver("openloop")
openloop_highs_verdict = partial(highs_verdict, form="openloop")

jax.config.update("jax_enable_x64", True)

ROOT = Path(__file__).resolve().parents[2]
VALIDATION = Path("/work/shared/validation/corridor_expected.json")
if not VALIDATION.exists():
    VALIDATION = ROOT / "tests" / "data" / "corridor_expected.json"
PAPER = ROOT / "conf" / "workspace" / "maps" / "paper.txt"
CORRIDOR = ROOT / "conf" / "workspace" / "maps" / "corridor.txt"
Z4 = Polytope.box([-1.0, -1.0], [1.0, 1.0])


def corridor_system(r):
    return LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, r))


@pytest.fixture(scope="module")
def paper_problems():
    dec = load_grid_map(PAPER)
    A = np.array([[1.0, 0.1], [-0.05, 0.95]])
    sysm = LinearSystem(A=A, B=np.array([[0.5, 0.1], [0.0, 0.4]]), U=box_input_set(1.0, 2), W=Ball(2, 0.1))
    Z = [make_z("box", c) for c in dec.cells]
    pairs = [(0, 1), (3, 4), (7, 2), (0, 9), (10, 21), (5, 14)]

    def make(L):      # mixed horizons L and L - 1 in one group
        return [pair_problem(dec, sysm, Z[i], i, j, max(1, L - b % 2)) for b, (i, j) in enumerate(pairs)]
    return make


def double_integrator_problems(reachable=False):
    """Rows whose u-coefficients vanish (``H B = 0`` for the position facets at l = 1).

    ``reachable=False``: some of those rows have a negative right-hand side (kept, and they
    make the margin negative); ``reachable=True``: a wider safe set, only dropped zero rows,
    and the horizons straddle the minimal one (an edge at L = 5).
    """
    A = np.array([[1.0, 0.5], [0.0, 1.0]])
    sysm = LinearSystem(A=A, B=np.array([[0.0], [0.5]]), U=box_input_set(1.0, 1),
                        W=Ball(2, 0.02 if reachable else 0.3))
    out = []
    if reachable:
        Pi, Pj = Polytope.box([0.0, -0.5], [1.0, 0.5]), Polytope.box([0.5, 0.0], [2.0, 1.0])
        S = Polytope.box([-1.0, -1.0], [3.0, 1.0])
        return [TubeProblem(sysm, Pi, Pj, S, Z4, L, S.bounding_box()) for L in (3, 4, 5)]
    for dx, L in [(0.0, 3), (0.6, 2), (-0.4, 3)]:
        Pi = Polytope.box([0.0 + dx, -0.5], [1.0 + dx, 0.5])
        Pj = Polytope.box([1.0 + dx, -0.5], [2.0 + dx, 0.5])
        S = Polytope.box([0.0 + dx, -0.5], [2.0 + dx, 0.5])
        out.append(TubeProblem(sysm, Pi, Pj, S, Z4, L, S.bounding_box()))
    return out


def _dense(shape, data, b):
    d = jax.tree_util.tree_map(lambda a: a[..., b:b + 1], data)
    nx, nr = openloop_dims(shape)
    K = pack(openloop_matvec(shape, d, unpack_x(shape, np.eye(nx + 1))))
    g, mask = openloop_rhs(shape, d)
    return K, pack(g)[:, 0], pack(mask)[:, 0], d


def _check_against_dense(probs, L_pad):
    shape, data = build_openloop_data(probs, L_pad=L_pad, f_s=8)
    nx, nr = openloop_dims(shape)
    cmv, crmv = openloop_coef_ops(shape)
    for b, pr in enumerate(probs):
        lp = build_openloop_lp(pr)
        K, g, mask, d = _dense(shape, data, b)
        rows = mask > 0
        n_own = lp.G.shape[1]
        assert rows.sum() == lp.G.shape[0]
        np.testing.assert_allclose(K[rows, :n_own], lp.G, atol=1e-14)       # same rows, same order
        assert np.all(K[rows, n_own:nx] == 0)                                # padded inputs unused
        np.testing.assert_allclose(K[rows, nx], 1.0)
        np.testing.assert_allclose(g[rows], lp.g, atol=1e-13)
        np.testing.assert_allclose(data.x_lower[:n_own, b], lp.lb)
        np.testing.assert_allclose(data.x_upper[:n_own, b], lp.ub)
        # K^T (NumPy) is the transpose; the explicit-coefficient form is the same operator
        KT = pack(openloop_rmatvec(shape, d, unpack_y(shape, np.eye(nr))))
        np.testing.assert_allclose(KT, K.T, atol=1e-15)
        c = openloop_coef_data(shape, d)
        Kc = cmv(c, np.eye(nx + 1))
        np.testing.assert_allclose(Kc[rows], K[rows], atol=1e-15)
        assert np.all(Kc[~rows] == 0)
        np.testing.assert_allclose(crmv(c, np.eye(nr)), Kc.T, atol=1e-15)


@pytest.mark.parametrize("L, L_pad", [(1, 1), (2, 4), (4, 4), (3, 5)])
def test_operator_matches_dense_lp(paper_problems, L, L_pad):
    _check_against_dense(paper_problems(L), L_pad)


@pytest.mark.parametrize("reachable", [False, True])
def test_zero_rows_mirror_the_dense_builder(reachable):
    probs = double_integrator_problems(reachable)
    n_kept = n_dropped = 0
    for p in probs:
        lp = build_openloop_lp(p)
        z = np.linalg.norm(lp.G, axis=1) == 0
        assert np.all(lp.g[z] < 0)
        n_kept += int(z.sum())
        nv, fs, ft = p.source.n_vertices, p.safe.H.shape[0], p.target.H.shape[0]
        n_dropped += (p.L - 1) * nv * fs + nv * ft - lp.G.shape[0]
    assert n_dropped > 0 and (n_kept == 0 if reachable else n_kept > 0)
    _check_against_dense(probs, 6)


@pytest.mark.parametrize("L", [1, 3])
def test_rmatvec_is_the_linear_transpose(paper_problems, L):
    probs = paper_problems(L)
    shape, data = build_openloop_data(probs, L_pad=L + 1)
    lean = data._replace(gS=None, gT=None, mS=None, mT=None, x_lower=None, x_upper=None, within_horizon=None)
    dj = jax.tree_util.tree_map(jnp.asarray, lean)
    nx, nr = openloop_dims(shape)
    rng = np.random.default_rng(0)
    x = unpack_x(shape, jnp.asarray(rng.standard_normal((nx + 1, len(probs)))), jnp)
    y = unpack_y(shape, jnp.asarray(rng.standard_normal((nr, len(probs)))), jnp)
    mv = lambda v: openloop_matvec(shape, dj, v, jnp)                      # noqa: E731
    (ref,) = jax.jit(jax.linear_transpose(mv, x))(y)
    got = jax.jit(lambda v: openloop_rmatvec(shape, dj, v, jnp))(y)
    for a, b in zip(got, ref):
        np.testing.assert_allclose(a, b, atol=1e-12)
    # the device path's transpose is the derived one; the host's (NumPy) is the fused one
    derived = jax.jit(lambda v: openloop_rmatvec_derived(shape, dj, v))(y)
    y_host = unpack_y(shape, np.asarray(pack(y, jnp)))
    host = openloop_rmatvec(shape, lean, y_host)
    picked = (jax.jit(lambda v: openloop_transpose(shape, dj, v, jnp))(y), openloop_transpose(shape, lean, y_host))
    for a, b, c, pj, pn in zip(derived, ref, host, *picked):
        np.testing.assert_array_equal(a, b)
        np.testing.assert_allclose(c, b, atol=1e-12)
        np.testing.assert_array_equal(pj, a)
        np.testing.assert_array_equal(pn, c)


U_POLY = Polytope.from_vertices(np.array([[1.0, 0.2], [0.3, 1.0], [-0.8, 0.6], [-0.7, -0.9], [0.6, -0.8]]))


@pytest.mark.parametrize("L, L_pad", [(1, 1), (3, 3), (2, 4)])
def test_hard_input_rows_match_the_dense_lp(L, L_pad):
    """A non-box ``U`` (a pentagon, not symmetric): C5 are hard rows (no ``t``), read by the operator
    off the declaration, after C2 / C3, each the dense LP's ``G_hard`` row unit-normalised; ``K^T``
    is the transpose (fused on the host, explicit coefficients, ``jax.linear_transpose`` on JAX)."""
    dec = load_grid_map(PAPER)
    sysm = LinearSystem(A=np.array([[1.0, 0.1], [-0.05, 0.95]]), B=np.array([[0.5, 0.1], [0.0, 0.4]]),
                        U=U_POLY, W=Ball(2, 0.1))
    assert not sysm.u_is_box
    Z = [make_z("box", c) for c in dec.cells]
    probs = [pair_problem(dec, sysm, Z[i], i, j, L) for i, j in [(0, 1), (3, 4), (7, 2)]]
    shape, data = build_openloop_data(probs, L_pad=L_pad)
    assert shape.f_u == U_POLY.H.shape[0] == 5
    nx, nr = openloop_dims(shape)
    cmv, crmv = openloop_coef_ops(shape)
    for b, pr in enumerate(probs):
        lp = build_openloop_lp(pr)
        K, g, mask, d = _dense(shape, data, b)
        rows = mask > 0
        nm, nh, n_own = lp.G.shape[0], lp.G_hard.shape[0], lp.G.shape[1]
        assert nh == L * pr.source.n_vertices * 5 and rows.sum() == nm + nh
        hn = np.linalg.norm(lp.G_hard, axis=1)
        Kr, gr = K[rows], g[rows]
        np.testing.assert_allclose(Kr[:nm, :n_own], lp.G, atol=1e-14)
        np.testing.assert_allclose(Kr[nm:, :n_own], lp.G_hard / hn[:, None], atol=1e-14)
        np.testing.assert_allclose(gr[:nm], lp.g, atol=1e-13)
        np.testing.assert_allclose(gr[nm:], lp.g_hard / hn, atol=1e-14)
        assert np.all(Kr[:, n_own:nx] == 0)                                   # padded inputs unused
        np.testing.assert_allclose(Kr[:nm, nx], 1.0)
        np.testing.assert_allclose(Kr[nm:, nx], 0.0)                         # hard rows: no margin
        KT = pack(openloop_rmatvec(shape, d, unpack_y(shape, np.eye(nr))))
        np.testing.assert_allclose(KT, K.T, atol=1e-15)
        c = openloop_coef_data(shape, d)
        Kc = cmv(c, np.eye(nx + 1))
        np.testing.assert_allclose(Kc[rows], K[rows], atol=1e-15)
        assert np.all(Kc[~rows] == 0)
        np.testing.assert_allclose(crmv(c, np.eye(nr)), Kc.T, atol=1e-15)
    dj = jax.tree_util.tree_map(jnp.asarray, data.lean())
    rng = np.random.default_rng(2)
    x = unpack_x(shape, jnp.asarray(rng.standard_normal((nx + 1, len(probs)))), jnp)
    y = unpack_y(shape, jnp.asarray(rng.standard_normal((nr, len(probs)))), jnp)
    (ref,) = jax.linear_transpose(lambda v: openloop_matvec(shape, dj, v, jnp), x)(y)
    for a, c in zip(openloop_rmatvec(shape, dj, y, jnp), ref):
        np.testing.assert_allclose(a, c, atol=1e-12)


# ------------------------------------------------------------------ the batched solver
@pytest.fixture(scope="module")
def solver():
    # one batch width and one padded horizon: a single executable serves the corridor tests
    return pdhg_solver("openloop", pool=64, min_bucket=64, l_buckets=(10,), tail_width=None)


@pytest.fixture(scope="module")
def corridor():
    return load_grid_map(CORRIDOR)


def _edges(ts):
    return sorted([e.src, e.dst, e.L] for e in ts.edges)


def _check_run(ts, solver):
    st = solver.stats
    assert st["n_lps"] == ts.stats["n_lps"] - ts.stats["n_translated"]     # the rest settled by translation
    assert st["highs_disagreements"] == 0
    assert st["certified_feasible"] + st["certified_infeasible"] + st["sent_to_highs"] == st["n_lps"]
    # most non-edge LPs never reach HiGHS (pruning leaves few non-edges)
    assert st["certified_infeasible"] >= 0.5 * (st["n_lps"] - ts.n_edges)
    assert set(ts.stats["provenance"]) <= {"pdhg-certificate", "pdhg+highs", "highs-fallback", "translate", "highs-translate"}
    assert ts.stats["n_unconfirmed"] == 0 and ts.method == "openloop"
    for k, e in enumerate(ts.edges):                                 # HiGHS plans, re-checked
        assert isinstance(ts.tubes[k], OpenLoopPlan)
        assert e.provenance in ("pdhg+highs", "highs-fallback", "highs-translate")
        assert openloop_violation(ts.problem(k), ts.tubes[k]) <= 1e-9


def test_corridor_validation_case(solver, corridor):
    solver.reset_stats()
    ts = build_abstraction(corridor, corridor_system(0.1), L_max=10, solve_batch=solver,
                           method="openloop", progress=False)
    case = json.loads(VALIDATION.read_text())["cases"]["open-loop, r = 0.1"]
    assert _edges(ts) == sorted(case["edges"])
    assert ts.n_edges == case["n_edges"] == 94
    _check_run(ts, solver)


def test_float32_iterations_keep_the_edges(corridor):
    """float32 iterates (the configuration's default dtype), float64 certificates: the open-loop
    operator keeps the iterates' precision (its transfer blocks were float64 constants, and the
    derived transpose refused the mixed types), and the edges are the validation case's."""
    s32 = pdhg_solver("openloop", pool=64, min_bucket=64, l_buckets=(10,), tail_width=None, dtype="float32")
    ts = build_abstraction(corridor, corridor_system(0.1), L_max=10, solve_batch=s32, method="openloop",
                           progress=False)
    case = json.loads(VALIDATION.read_text())["cases"]["open-loop, r = 0.1"]
    assert _edges(ts) == sorted(case["edges"])
    _check_run(ts, s32)


def test_corridor_equals_highs_path_without_recompiling(solver, corridor):
    traces, n_exe = solver.n_traces, solver.n_executables
    assert traces >= 1
    solver.reset_stats()
    sysm = corridor_system(0.15)
    ts = build_abstraction(corridor, sysm, L_max=10, solve_batch=solver, method="openloop",
                           progress=False)
    ref = build_abstraction(corridor, sysm, L_max=10, solve_batch=openloop_solve_batch,
                            method="openloop", progress=False)
    assert _edges(ts) == _edges(ref)
    _check_run(ts, solver)
    # same shapes (another disturbance radius only changes right-hand sides): nothing compiled
    assert solver.stats["compile_seconds"] == 0.0 and solver.stats["n_compiles"] == 0
    assert solver.n_traces == traces and solver.n_executables == n_exe == 1


def test_certificates_are_rigorous_on_the_host(solver, corridor):
    """Every certified-infeasible problem really has a negative HiGHS margin above its bound."""
    sysm = corridor_system(0.1)
    Z = make_z("box", corridor.cells[0])
    probs = [pair_problem(corridor, sysm, Z, i, j, L) for i in range(4) for j in range(6) if i != j
             for L in (1, 3)]
    out = solver(probs)
    n_cert = 0
    for p, v in zip(probs, out):
        ref = openloop_highs_verdict(p)
        assert v.status == ref.status
        if v.provenance == "pdhg-certificate":
            n_cert += 1
            assert ref.margin <= v.margin + 1e-9 and v.margin < 0
        else:
            assert v.margin == pytest.approx(ref.margin, abs=1e-12)
    assert n_cert > 0
    # an all-zero dual gives no bound; a box-feasible point's violation is finite
    from tubejax.lp.engines.pdhg_adapters import host_flat_certificates, margin_start
    from tubejax.lp.declarations import openloop_operator as olop
    shape, data = build_openloop_data(probs[:3], L_pad=4)
    prob, z0 = margin_start(olop.OPENLOOP_OPERATOR, shape, data)
    viol, bound = host_flat_certificates(olop.OPENLOOP_OPERATOR, shape, data, z0, np.zeros_like(prob.g))
    assert np.all(np.isinf(bound)) and np.all(np.isfinite(viol))


def test_double_integrator_and_non_box_input_set():
    probs = double_integrator_problems(False) + double_integrator_problems(True)
    out = pdhg_solver("openloop", pool=16, min_bucket=16, tail_width=None, l_buckets=(6,))(probs)
    for p, v in zip(probs, out):
        ref = openloop_highs_verdict(p)
        assert v.status == ref.status
        if v.status == "edge":
            assert openloop_violation(p, v.tube) <= 1e-9
    assert [v.status for v in out[3:]] == ["infeasible", "infeasible", "edge"]
    assert out[0].provenance == "pdhg-certificate"
    sysm = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=one_norm_input_set(1.0, 2), W=Ball(2, 0.1))
    dec = load_grid_map(CORRIDOR)
    Z = make_z("box", dec.cells[0])
    probs = [pair_problem(dec, sysm, Z, 0, 1, L) for L in (1, 4)]
    assert all(OPENLOOP_PDHG.batched(p) for p in probs)          # C5 of a non-box U: the operator's hard rows
    out = pdhg_solver("openloop")(probs)
    assert out[0].provenance == "pdhg-certificate"                 # L = 1 cannot reach: PDHG proves it
    for p, v in zip(probs, out):
        assert v.status == openloop_highs_verdict(p).status
        if v.status == "edge":
            assert openloop_violation(p, v.tube) <= 1e-9


@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_non_box_input_set_stays_on_the_batched_path(solver, corridor, dtype):
    """C5 of a non-box ``U`` (the 1-norm ``U`` of conf/system/integrator2d_l1.yaml) are hard rows
    the open-loop operator takes from the declaration: every LP is PDHG's or settled by translation
    (none goes to HiGHS unbatched), with exactly HiGHS's edges (44, recorded before the change), in
    float64 and in float32 iterations (the configuration's default)."""
    sysm = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=one_norm_input_set(1.0, 2), W=Ball(2, 0.1))
    if dtype == "float32":
        solver = pdhg_solver("openloop", pool=64, min_bucket=64, l_buckets=(10,), tail_width=None, dtype="float32")
    solver.reset_stats()
    ts = build_abstraction(corridor, sysm, L_max=6, solve_batch=solver, method="openloop", progress=False)
    ref = build_abstraction(corridor, sysm, L_max=6, solve_batch=openloop_solve_batch, method="openloop",
                            progress=False)
    assert _edges(ts) == _edges(ref) and ts.n_edges == 44
    st = solver.stats
    assert sum(st["status_counts"].values()) + st["translated_to_highs"] == st["n_lps"] > 0
    assert st["highs_disagreements"] == 0 and st["certified_infeasible"] > 0
    assert ts.stats["n_unconfirmed"] == 0
    for k, e in enumerate(ts.edges):                                 # HiGHS plans, re-checked
        assert openloop_violation(ts.problem(k), ts.tubes[k]) <= 1e-9
