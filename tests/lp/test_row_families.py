"""Every encoding of the tube LP has every row: random small problems, one declaration.

The row families of :mod:`tubejax.lp.declarations.tube_families` are the only description of
Problem 2. For random systems, cells, ``Z`` kinds, horizons and tubes, each encoding is held
to the families' float64 residuals, family by family and by name:

* the dense LP rows (``build_tube_lp``, ``build_tube_lps``): each ``margin`` row is the
  largest of its family's per-vertex residuals (one row per vertex for ``dynamics``);
* the matrix-free operator ``K`` (``tube_matvec``) and the hard rows of a non-box ``U``;
* the exact residuals in rationals (each family's largest row, per unit of its normal);
* the float check ``tube_violation`` (the largest residual);
* the learned-Z Lagrangian (``sum_r y_r (g_r - G_r x)`` over the margin rows);
* the translation-class axes (the families' invariance).

A hand-written row list (``_reference_rows`` in ``test_formulation.py``) and HiGHS hold the
declaration itself to docs/math/tube-lp.md.
"""

import dataclasses
from fractions import Fraction

import jax.numpy as jnp
import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tubejax.analyses.zshape.lagrangian import MarginSolution, lagrangian, pair_geometry, system_arrays
from tubejax.model.geometry import Ball, Halfspaces, Polytope, convex_hull_of
from tubejax.lp.evidence.check import exact_terms
from tubejax.lp.evidence.exact_problem import exact_tube_data
from tubejax.lp.evidence.rational import QArray
from tubejax.lp.evidence.check import exact_plan_terms
from tubejax.lp.evidence.rows import check_against_float, rational_openloop_lp, rational_tube_lp
from tubejax.lp.declarations.openloop_lp import build_openloop_lp, openloop_violation
from tubejax.lp.declarations.openloop_families import (OPENLOOP_FAMILIES, PlanVars, float_plan_terms, plan_identity,
                                                       plan_residuals)
from tubejax.lp.evidence.radius_lp import build_radius_lp
from tubejax.lp.declarations.radius_disturbance import unit_disturbance
from tubejax.lp.declarations.tube_lp import build_tube_lp, margin_rows, tube_violation
from tubejax.model.problem import TubeProblem
from tubejax.lp.declarations.tube_lp_batch import build_tube_lps
from tubejax.lp.declarations.tube_families import TUBE_FAMILIES, TubeVars, float_terms, tube_identity, tube_residuals
from tubejax.lp.declarations.row_families import active, dense_rows, state_lengths
from tubejax.lp.declarations.margin_operator import pack
from tubejax.lp.declarations.tube_operator import tube_matvec, unpack_x
from tubejax.lp.declarations.tube_operator_data import build_tube_data
from tubejax.model.zshape.kinds import make_z
from tubejax.model.system import LinearSystem, box_input_set, one_norm_input_set


@st.composite
def problems(draw):
    rng = np.random.default_rng(draw(st.integers(0, 2 ** 31)))
    L = draw(st.integers(1, 4))
    m = draw(st.integers(1, 2))
    A = np.eye(2) + 0.2 * rng.standard_normal((2, 2))
    B = rng.standard_normal((2, m))
    U = one_norm_input_set(1.0, m) if (m == 2 and draw(st.booleans())) else box_input_set(1.0, m)
    W = Ball(2, 0.05) if draw(st.booleans()) else Polytope.box([-0.05, -0.03], [0.05, 0.03])
    X = None
    if draw(st.booleans()):                             # a state constraint: rows through a point of the pair's hull
        Hx = rng.standard_normal((int(draw(st.integers(1, 3))), 2))
        X = Halfspaces(Hx, Hx @ np.array([0.5, 0.5]) + rng.uniform(0.2, 2.0, len(Hx)), "system.X")
    sysm = LinearSystem(A=A, B=B, U=U, W=W, X=X)
    if draw(st.booleans()):
        Pi = Polytope.box([0.0, 0.0], [1.0, 1.0])
        zkind = draw(st.sampled_from(["box", "cell", "diamond"]))
    else:
        Pi = Polytope.from_vertices(rng.random((6, 2)) + [[0.0, 0.0]])
        zkind = "cell"
    shift = rng.standard_normal(2)
    Pj = Polytope.from_vertices(Pi.vertices + shift)
    S = convex_hull_of(Pi, Pj)
    prob = TubeProblem(sysm, Pi, Pj, S, make_z(zkind, Pi, scale=float(rng.uniform(0.5, 2.0))), L,
                       S.bounding_box(), eps_min=float(draw(st.sampled_from([0.0, 0.01]))))
    lp = build_tube_lp(prob)
    x = lp.lb + rng.random(lp.lb.shape) * (lp.ub - lp.lb)
    return prob, lp, x


def _unit_max(residuals):
    """Each family's largest residual per unit 2-norm of its normal (float), by name."""
    return {nm: (float(np.max(r / sc)) if np.size(r) else None) for nm, r, sc in residuals}


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(problems())
def test_every_encoding_has_every_family(case):
    prob, lp, xv = case
    ix = lp.index
    tube = ix.split(xv)
    x = TubeVars(*tube)
    d = float_terms(prob)
    res = {nm: (r, sc) for nm, r, sc in tube_residuals(d, x)}
    has_x = prob.system.X is not None
    assert set(res) == {"safe", "target", "dynamics", "eps_min", "input"} | ({"X"} if has_x else set())
    assert set(res) == {f.name for f in active(TUBE_FAMILIES, d.sets)}

    # dense rows, family by family, by name: G x - g at the row norm = the vertex-max of the residuals
    nrm = margin_rows(prob)[2]                              # each row's 2-norm before normalising
    assert set(lp.layout.names) == {"safe", "target", "dynamics"} | ({"X"} if has_x else set())
    for fam in active(TUBE_FAMILIES, d.sets):
        role = fam.lp_role(d, prob.system.u_is_box)
        r, _ = res[fam.name]
        if role == "margin":
            sl = lp.layout.slice(fam.name)
            got = (lp.G[sl] @ xv - lp.g[sl]) * nrm[sl]
            want = np.max(r, axis=-2) if fam.compress_vertices else r
            # C2 and C3 are compressed: exact only for eps >= 0 (true for every drawn tube)
            np.testing.assert_allclose(got, np.ravel(want), rtol=0, atol=1e-9)
        elif role == "hard":
            hn = np.linalg.norm(lp.G_hard, axis=1)
            got = (lp.G_hard @ xv - lp.g_hard) / hn
            np.testing.assert_allclose(got, np.ravel(r / res[fam.name][1]), rtol=0, atol=1e-9)
        else:                                              # bounds: every point between them satisfies them
            assert np.max(r) <= 1e-12 or fam.name == "input" and not prob.system.u_is_box
    blp = build_tube_lps([prob, prob])[1]
    np.testing.assert_array_equal(blp.G, lp.G)
    np.testing.assert_array_equal(blp.g, lp.g)

    # the matrix-free operator K: its rows in pack order are the layout's
    if prob.system.u_is_box:
        shape, data = build_tube_data([prob])
        z = np.concatenate([xv, [0.0]])[:, None]
        Kx = pack(tube_matvec(shape, data, unpack_x(shape, z)))[:, 0]
        for nm in lp.layout.names:
            sl = lp.layout.slice(nm)
            np.testing.assert_allclose(Kx[sl], lp.G[sl] @ xv, rtol=0, atol=1e-12, err_msg=nm)

    # the exact residuals, per family (unit 2-norm rows), and the float check
    ex = tube_residuals(exact_terms(exact_tube_data(prob)), TubeVars(*(QArray.from_floats(a) for a in tube)))
    want = _unit_max([(nm, r, sc) for nm, (r, sc) in res.items()])
    for nm, r, _ in ex:
        if not r.num.size:
            assert want[nm] is None
            continue
        n2 = np.sqrt(np.array([float(sum(Fraction(int(v)) ** 2 for v in row)) for row in _normals(nm, prob)]))
        assert abs(float(np.max(r.to_float() / n2)) - want[nm]) <= 1e-9, nm
    worst = max(v for v in want.values() if v is not None)
    assert abs(tube_violation(prob, tube) - max(0.0, worst)) <= 1e-12

    # the rational LP rows of the exact proofs: the float LP's rows, row for row (raises otherwise)
    check_against_float(rational_tube_lp(prob, lp), lp)


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(problems(), st.integers(0, 2 ** 31))
def test_margin_rows_from_cached_families_are_the_declaration_derived_at_once(case, seed):
    """``margin_rows`` assembles an LP from rows memoised per family (the dynamics rows shared by
    every pair, whatever its facets): bit for bit the rows of all families derived at once, for
    pairs whose cells have other facets than the one that filled the caches, and after the
    caches dropped entries."""
    from tubejax.lp.declarations import tube_lp as dense

    prob, _, _ = case
    rng = np.random.default_rng(seed)
    other = dataclasses.replace(prob, source=Polytope.from_vertices(prob.source.vertices @ (np.eye(2) + 0.01 * rng.standard_normal((2, 2)))))
    other = dataclasses.replace(other, safe=convex_hull_of(other.source, other.target))
    budget = dense.ROWS_CACHE_BYTES, dense.LP_ROWS_CACHE_BYTES
    try:
        for p, tiny in ((prob, False), (other, False), (prob, False), (other, True), (prob, True)):
            if p.source.n_vertices != prob.source.n_vertices:
                continue
            # tiny: every put drops all but the newest entry of its cache
            dense.ROWS_CACHE_BYTES, dense.LP_ROWS_CACHE_BYTES = (1, 1) if tiny else budget
            for scaling in dense.MARGIN_SCALINGS:
                G, g, nrm, layout = margin_rows(p, scaling=scaling)
                d = float_terms(p)
                G0, g0, layout0 = dense_rows(d, p.system.m, "margin", p.system.u_is_box, TUBE_FAMILIES, tube_identity)
                nrm0 = (state_lengths(d, "margin", p.system.u_is_box, lambda H: np.linalg.norm(H, axis=1), TUBE_FAMILIES)
                        if scaling == "state" else np.linalg.norm(G0, axis=1))
                np.testing.assert_array_equal(G, G0 / nrm0[:, None])
                np.testing.assert_array_equal(nrm, nrm0)
                np.testing.assert_array_equal(g, g0)
                assert layout == layout0
            for k in list(dense._ROWS_CACHE):               # whole LPs dropped: families assemble them again
                dense._CACHE_USED[id(dense._ROWS_CACHE)][0] -= dense._ROWS_CACHE.pop(k)[0].nbytes
    finally:
        dense.ROWS_CACHE_BYTES, dense.LP_ROWS_CACHE_BYTES = budget


def _normals(nm, prob):
    """The exact integer normals of family ``nm`` (rows of the exact H-reps, any order)."""
    e = exact_tube_data(prob)
    return {"safe": e.safe.H, "target": e.target.H, "dynamics": e.Z.H, "input": e.system.U.H,
            "eps_min": np.array([[1]], dtype=object), "X": e.sets["X"].H if "X" in e.sets else None}[nm]


def test_translation_groups_come_from_the_families():
    """The classes' translations are those every family is invariant under: ``A``'s fixed
    translations for Problem 2; a state constraint, which stays put while the pair moves, keeps
    only those its rows do not see (``H_x c = 0``)."""
    from tubejax.lp.declarations.tube_families import translation_groups

    A = np.array([[1.0, 0.0, 0.3], [0.0, 0.9, 0.0], [0.0, 0.0, 1.0]])
    sysm = LinearSystem(A=A, B=np.eye(3), U=box_input_set(1.0, 3), W=Ball(3, 0.1))
    assert translation_groups(sysm).tolist() == [0, -1, -1]
    on_y = LinearSystem(A=A, B=np.eye(3), U=box_input_set(1.0, 3), W=Ball(3, 0.1),
                        X=Halfspaces([[0.0, 1.0, 0.0]], [5.0], "system.X"))
    assert translation_groups(on_y).tolist() == [0, -1, -1]        # X does not involve axis 0
    on_x = LinearSystem(A=A, B=np.eye(3), U=box_input_set(1.0, 3), W=Ball(3, 0.1),
                        X=Halfspaces([[1.0, 0.0, 1.0]], [5.0], "system.X"))
    assert translation_groups(on_x).tolist() == [-1, -1, -1]
    # the double integrator in (p, s): p and s move together; a speed limit |v| = |s - p| / 2 <= 1
    # does not see that translation, a bound on p does
    di = np.array([[0.75, 0.25], [-0.25, 1.25]])
    kw = dict(A=di, B=np.array([[0.125], [1.125]]), U=box_input_set(1.0, 1), W=Ball(2, 0.02))
    assert translation_groups(LinearSystem(**kw)).tolist() == [0, 0]
    speed = Halfspaces([[-0.5, 0.5], [0.5, -0.5]], [1.0, 1.0], "system.X")
    assert translation_groups(LinearSystem(**kw, X=speed)).tolist() == [0, 0]
    assert translation_groups(LinearSystem(**kw, X=Halfspaces([[1.0, 0.0]], [1.0], "system.X"))).tolist() == [-1, -1]
    # a translate along a free axis has the same residuals, translated: check it on a tube
    rng = np.random.default_rng(1)
    Pi = Polytope.box([0.0, 0.0, 0.0], [1.0, 1.0, 1.0])
    Pj = Polytope.box([1.0, 0.0, 0.0], [2.0, 1.0, 1.0])
    S = convex_hull_of(Pi, Pj)
    c = np.array([3.0, 0.0, 0.0])
    mv = lambda P: Polytope.from_vertices(P.vertices + c)              # noqa: E731
    prob = TubeProblem(sysm, Pi, Pj, S, make_z("box", Pi), 2, S.bounding_box())
    moved = TubeProblem(sysm, mv(Pi), mv(Pj), mv(S), make_z("box", Pi), 2,
                        (S.bounding_box()[0] + c, S.bounding_box()[1] + c))
    lp = build_tube_lp(prob)
    t = lp.index.split(lp.lb + rng.random(lp.lb.shape) * (lp.ub - lp.lb))
    r0 = tube_residuals(float_terms(prob), TubeVars(*t))
    r1 = tube_residuals(float_terms(moved), TubeVars(t.p + c, t.eps, t.u))
    for (nm, a, _), (_, b, _) in zip(r0, r1):          # the moved hull may list its facets in another order
        np.testing.assert_allclose(np.sort(a, axis=-1), np.sort(b, axis=-1), rtol=0, atol=1e-12, err_msg=nm)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(problems(), st.integers(0, 2 ** 31))
def test_learning_lagrangian_has_every_margin_row(case, seed):
    """The learned-Z Lagrangian (``tubejax.analyses.zshape.lagrangian``) at a point ``x`` with duals ``y``
    equals ``sum_r y_r (g_r - G_r x)`` over the dense LP's margin rows, family by family by name."""
    prob, lp, xv = case
    if not prob.system.u_is_box:
        return
    rng = np.random.default_rng(seed)
    ix = lp.index
    L, n, nv, m = ix
    tube = ix.split(xv)
    y = rng.random(lp.G.shape[0])
    rows = lp.layout.split(y)
    fs, ft, fz = prob.safe.H.shape[0], prob.target.H.shape[0], prob.Z.H.shape[0]
    y_safe = np.zeros((L, fs))                          # every step: row l - 1 holds step l's duals
    y_safe[:L - 1] = rows["safe"]
    y_target = np.zeros((L, ft))
    y_target[L - 1] = rows["target"][0]
    duals = {"safe": y_safe, "target": y_target, "dynamics": rows["dynamics"]}
    f_pad = {"safe": fs, "target": ft}
    if prob.system.X is not None:                       # X covers every step: its rows are (L, f_x) as they are
        duals["X"], f_pad["X"] = rows["X"], prob.system.X.H.shape[0]
    sol = MarginSolution(np.float64(0.0), tube.p, tube.eps, tube.u, duals, np.zeros(L))
    got = float(lagrangian(jnp.asarray(prob.Z.vertices), jnp.asarray(prob.Z.H), jnp.asarray(prob.Z.h),
                           pair_geometry(prob, f_pad), sol, system_arrays(prob.system)))
    want = float(y @ (lp.g - lp.G @ xv))
    assert abs(got - want) <= 1e-9 * (1 + abs(want)), (got, want)
    assert fz == rows["dynamics"].shape[-1]


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(problems(), st.integers(0, 2 ** 31))
def test_every_openloop_encoding_has_every_family(case, seed):
    """The open-loop LP (``OPENLOOP_FAMILIES``): its dense rows, its float and exact checks, its
    rational rows and its radius form's rows, family by family, from the one declaration."""
    prob, _, _ = case
    prob = dataclasses.replace(prob, system=dataclasses.replace(prob.system, X=None))
    rng = np.random.default_rng(seed)
    lp = build_openloop_lp(prob)
    u = lp.lb + rng.random(lp.lb.shape) * (lp.ub - lp.lb)
    plan = lp.index.split(u).u
    d = float_plan_terms(prob)
    res = {nm: (r, sc) for nm, r, sc in plan_residuals(d, PlanVars(plan))}
    assert set(res) == {"safe", "target", "input"}
    # the dense rows, family by family in layout order; the LP drops the zero rows with g >= 0
    G, g, layout = dense_rows(d, prob.system.m, "margin", prob.system.u_is_box, OPENLOOP_FAMILIES, plan_identity)
    assert layout.names == ("safe", "target")
    full = np.concatenate([np.ravel(res[nm][0] / res[nm][1]) for nm in layout.names])
    lens = np.concatenate([np.broadcast_to(res[nm][1], res[nm][0].shape).ravel() for nm in layout.names])
    np.testing.assert_allclose((G @ u - g) / lens, full, rtol=0, atol=1e-9)
    keep = (np.linalg.norm(G, axis=1) > 1e-12) | (g < 0)
    np.testing.assert_allclose(lp.G @ u - lp.g, full[keep], rtol=0, atol=1e-9)
    assert abs(openloop_violation(prob, plan) - max(0.0, max(float(np.max(r / sc)) for r, sc in res.values()
                                                             if np.size(r)))) <= 1e-12
    # the exact residuals (sigma_D rounded up) per unit 2-norm of the exact normals
    ex = plan_residuals(exact_plan_terms(prob), PlanVars(QArray.from_floats(plan)))
    for nm, r, _ in ex:
        if not r.num.size:
            continue
        H = np.array([[float(v) for v in row] for row in r_normals(prob, nm)])
        got = float(np.max(r.to_float() / np.linalg.norm(H, axis=1)))
        assert abs(got - float(np.max(res[nm][0] / res[nm][1]))) <= 1e-9, nm
    # the rational rows of the proofs, and the radius form's rows (the same rows, sigma_D in rho's column)
    check_against_float(rational_openloop_lp(prob, lp), lp)
    rlp = build_radius_lp(prob, form="openloop")
    W0, rho = unit_disturbance(prob.system.W)
    if rlp.G.shape == lp.G.shape:
        np.testing.assert_allclose(rlp.G, lp.G, rtol=0, atol=1e-12)
        np.testing.assert_allclose(rlp.g - rho * rlp.t_coef, lp.g, rtol=0, atol=1e-9)


def r_normals(prob, nm):
    """The exact integer normals of open-loop family ``nm``."""
    e = exact_plan_terms(prob)
    return e.sets[nm].H.to_fractions()
