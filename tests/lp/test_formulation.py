"""Tube LP builder and checker: hand-derived cases and the semantics of docs/math/tube-lp.md."""

import math

import numpy as np
import pytest

from tubejax.model.geometry import Ball, Polytope, convex_hull_of, support
from tubejax.lp.declarations.tube_lp import build_tube_lp, tube_violation
from tubejax.lp.declarations.tube_variables import Tube
from tubejax.model.problem import TubeProblem
from tubejax.lp.declarations.tube_families import TubeVars, float_terms, tube_residuals
from tubejax.lp.engines.highs import solve_margin_lp
from tubejax.model.zshape.kinds import make_z
from tubejax.model.system import LinearSystem, box_input_set, one_norm_input_set


def integrator_1d(a, r):
    """x+ = x + u + w, |u| <= a, |w| <= r."""
    return LinearSystem(A=np.eye(1), B=np.eye(1), U=box_input_set(a, 1), W=Ball(1, r))


def solve(prob):
    lp = build_tube_lp(prob)
    res = solve_margin_lp(lp)
    tube = lp.index.split(res.x)
    return res, tube, tube_violation(prob, tube)


def interval_problem(sysm, L):
    Pi, Pj = Polytope.box([0.0], [1.0]), Polytope.box([1.0], [2.0])
    S = convex_hull_of(Pi, Pj)
    return TubeProblem(sysm, Pi, Pj, S, make_z("box", Pi), L, S.bounding_box())


def minimal_L(sysm, L_max=12):
    for L in range(1, L_max + 1):
        res, tube, viol = solve(interval_problem(sysm, L))
        if viol <= 1e-9:
            return L, res.margin
    return None, None


@pytest.mark.parametrize("a, r", [(0.5, 0.1), (0.5, 0.0), (1.0, 0.3), (0.5, 0.3), (0.6, 0.2)])
def test_1d_integrator_minimal_horizon(a, r):
    # The lower tube end moves right by at most a - r per step (C4 with u = a, the
    # worst w = -r), from 0 to at least 1: L >= 1 / (a - r); the upper end and
    # the width (>= 2r) are never binding. So L* = ceil(1 / (a - r)).
    L, margin = minimal_L(integrator_1d(a, r))
    assert L == math.ceil(1.0 / (a - r) - 1e-12)


def test_1d_integrator_radius_threshold():
    # For a = 0.5 and L = 4 steps, feasible iff r <= a - 1/L = 0.25; at r = 0.25 the margin is exactly 0.
    a, L = 0.5, 4
    for r, feasible in [(0.2, True), (0.249, True), (0.25, True), (0.251, False), (0.3, False)]:
        res, tube, viol = solve(interval_problem(integrator_1d(a, r), L))
        assert (viol <= 1e-9) == feasible, r
        assert (res.margin >= -1e-12) == feasible, r
    res, _, _ = solve(interval_problem(integrator_1d(a, 0.25), L))
    assert abs(res.margin) < 1e-9


def test_disturbance_too_large_for_target_is_infeasible(paper_system):
    # W of radius 0.6 cannot fit in a unit cell: Q_L ⊖ W would be empty.
    sysm = paper_system(0.6)
    Pi, Pj = Polytope.box([0, 0], [1, 1]), Polytope.box([1, 0], [2, 1])
    S = convex_hull_of(Pi, Pj)
    for L in (1, 5, 12):
        res, tube, viol = solve(TubeProblem(sysm, Pi, Pj, S, make_z("box", Pi), L, S.bounding_box()))
        assert res.margin < -1e-3 and viol > 1e-3


def test_obstacle_case_constrains_only_l_up_to_L_minus_1(paper_system):
    # Diagonal neighbours [0,1]^2 -> [1,2]^2 with obstacles in the other two squares:
    # S = P_i for l = 1..L-1. The reading of docs/math/tube-lp.md#paper-slips is feasible at
    # r = 0.05; the paper's literal reading (Q_L ⊆ P_i as well) forces Q_L into the single
    # point P_i ∩ P_j: infeasible.
    sysm = paper_system(0.05)
    Pi, Pj = Polytope.box([0, 0], [1, 1]), Polytope.box([1, 1], [2, 2])
    box = convex_hull_of(Pi, Pj).bounding_box()
    prob = TubeProblem(sysm, Pi, Pj, Pi, make_z("box", Pi), 3, box)
    res, tube, viol = solve(prob)
    assert viol <= 1e-9 and res.margin > 0
    QL = tube.vertices(prob.Z, Pi)[-1]
    assert np.any(Pi.violation(QL) > 1e-3)                  # Q_L leaves P_i: allowed at l = L
    lp = build_tube_lp(prob)
    ix = lp.index
    extra = np.zeros((Pi.H.shape[0], ix.size))             # the paper's extra rows: Q_L ⊆ P_i
    for f in range(Pi.H.shape[0]):
        extra[f, ix.p_col(3, 0):ix.p_col(3, 0) + 2] = Pi.H[f]
        extra[f, ix.eps_col(3)] = prob.Z.support(Pi.H[f])
    nrm = np.linalg.norm(extra, axis=1)
    lp2 = lp._replace(G=np.vstack([lp.G, extra / nrm[:, None]]), g=np.concatenate([lp.g, Pi.h / nrm]),
                      row_kind=np.concatenate([lp.row_kind, np.full(len(nrm), 2, np.int8)]))
    assert solve_margin_lp(lp2).margin < -1e-3


def test_checker_detects_each_kind_of_violation(paper_system):
    sysm = paper_system(0.2)
    Pi, Pj = Polytope.box([0, 0], [1, 1]), Polytope.box([1, 0], [2, 1])
    S = convex_hull_of(Pi, Pj)
    prob = TubeProblem(sysm, Pi, Pj, S, make_z("box", Pi), 5, S.bounding_box())
    res, tube, viol = solve(prob)
    assert viol <= 1e-9
    bad = [
        tube._replace(eps=tube.eps * 0.5),                                # C4: tube too thin for W
        tube._replace(p=tube.p + np.array([0.0, 5.0])),                   # C2/C3: outside S and P_j
        tube._replace(u=tube.u * 0 + 1.5),                                # C5: input outside U
        tube._replace(eps=-tube.eps),                                     # C1
        Tube(tube.p[:-1], tube.eps[:-1], tube.u[:-1]),                    # wrong shape
        tube._replace(p=tube.p * np.nan),
    ]
    for b in bad:
        assert tube_violation(prob, b) > 1e-3


def test_margin_form_matches_checker_and_bounds(paper_system):
    # The LP's rows are scaled by their state-space normals (unit facet rows of S, P_j and Z:
    # the p-coefficients of every row have unit length), its optimum t* lower-bounds every row
    # slack, and t* is a state-space distance: the checker's largest per-vertex residual of the
    # optimal tube is exactly -t* (the tube is tight on some row).
    sysm = paper_system(0.1)
    Pi, Pj = Polytope.box([0, 0], [1, 1]), Polytope.box([2, 0], [3, 1])
    S = convex_hull_of(Pi, Pj)
    prob = TubeProblem(sysm, Pi, Pj, S, make_z("box", Pi), 6, S.bounding_box())
    lp = build_tube_lp(prob)
    ix = lp.index
    dyn = lp.layout.slice("dynamics")
    np.testing.assert_allclose(np.linalg.norm(lp.G[:dyn.start, :ix.p.stop], axis=1), 1.0)
    p_next = lp.G[dyn].reshape(lp.layout.shape("dynamics") + (ix.size,))[0][..., ix.p_col(1, 0):ix.p_col(1, 0) + 2]
    np.testing.assert_allclose(np.linalg.norm(p_next, axis=-1), 1.0)      # -H_z at p_{l+1}
    res = solve_margin_lp(lp)
    assert res.margin > 0
    x = res.x
    assert np.max(lp.G @ x - lp.g) <= -res.margin + 1e-9
    assert np.all(x >= lp.lb - 1e-9) and np.all(x <= lp.ub + 1e-9)
    assert tube_violation(prob, lp.index.split(x)) <= 1e-12
    worst = max(float(np.max(r / sc)) for nm, r, sc in tube_residuals(float_terms(prob), TubeVars(*ix.split(x)))
                if r.size and nm in lp.layout.names)                  # the margin rows (not the bounds)
    assert abs(worst + res.margin) <= 1e-9


def _di4(dt=0.5, beta=2.0):
    """The 4-D double integrator of conf/system/double_integrator.yaml, in (p, s = p + beta v)."""
    T = np.array([[1.0, 0.0], [1.0, beta]])
    A1 = T @ np.array([[1.0, dt], [0.0, 1.0]]) @ np.linalg.inv(T)
    B1 = T @ np.array([[dt * dt / 2], [dt]])
    return LinearSystem(A=np.kron(np.eye(2), A1), B=np.kron(np.eye(2), B1), U=box_input_set(1.0, 2), W=Ball(4, 0.02))


@pytest.mark.parametrize("n", [2, 4])
def test_margin_is_a_state_space_distance_not_a_property_of_z_scale(paper_system, n):
    """Z and (Z / 2, 2 eps) describe the same tubes, so the margin -- a distance in the state
    space -- must not change with Z's scale. Per unit of the LP coefficients it did (issue 22:
    0.009355 vs 0.007401 for one 4-D edge), which the ``'coefficients'`` scaling still shows."""
    sysm = paper_system(0.1) if n == 2 else _di4()
    step = np.eye(n)[0 if n == 2 else 1]                  # 4-D: one cell along s_x = p_x + 2 v_x
    Pi, Pj = Polytope.box(np.zeros(n), np.ones(n)), Polytope.box(step, 1 + step)
    S = convex_hull_of(Pi, Pj)
    L = 3 if n == 2 else 4
    margins = {}
    for scaling in ("state", "coefficients"):
        for scale in (0.5, 1.0, 2.0):
            prob = TubeProblem(sysm, Pi, Pj, S, make_z("box", Pi, scale=scale), L, S.bounding_box())
            margins[scaling, scale] = solve_margin_lp(build_tube_lp(prob, scaling=scaling)).margin
    assert margins["state", 1.0] > 0.01
    for scale in (0.5, 2.0):
        assert margins["state", scale] == pytest.approx(margins["state", 1.0], abs=1e-9)
        assert abs(margins["coefficients", scale] - margins["coefficients", 1.0]) > 1e-4


def test_non_box_input_set_becomes_hard_rows():
    sysm = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=one_norm_input_set(1.0, 2), W=Ball(2, 0.1))
    Pi, Pj = Polytope.box([0, 0], [1, 1]), Polytope.box([1, 0], [2, 1])
    S = convex_hull_of(Pi, Pj)
    prob = TubeProblem(sysm, Pi, Pj, S, make_z("box", Pi), 6, S.bounding_box())
    lp = build_tube_lp(prob)
    assert lp.G_hard.shape[0] == 6 * 4 * 4
    res = solve_margin_lp(lp)
    tube = lp.index.split(res.x)
    assert tube_violation(prob, tube) <= 1e-9
    assert np.all(np.abs(tube.u).sum(axis=-1) <= 1 + 1e-9)


def test_problem_validation():
    sysm = integrator_1d(0.5, 0.1)
    with pytest.raises(ValueError, match="L must be >= 1"):
        interval_problem(sysm, 0)
    Pi = Polytope.box([0, 0], [1, 1])
    with pytest.raises(ValueError, match="needs cells with 2\\^n"):
        make_z("box", Polytope.from_vertices([[0, 0], [1, 0], [0, 1]]))
    assert make_z("regular", Polytope.from_vertices([[0, 0], [1, 0], [0, 1]])).n_vertices == 3
    assert make_z("cell", Pi).n_vertices == 4
    with pytest.raises(ValueError, match="unknown zshape"):
        make_z("star", Pi)


def _reference_rows(prob):
    """Margin rows of Problem 2 written one at a time from docs/math/margins.md (unnormalised)."""
    sysm = prob.system
    L, n, m = int(prob.L), sysm.n, sysm.m
    V, Zv, Hz, hz = prob.source.vertices, prob.Z.vertices, prob.Z.H, prob.Z.h
    nv = V.shape[0]
    size = L * n + L + L * nv * m
    P = lambda ell: slice((ell - 1) * n, ell * n)                 # noqa: E731
    E = lambda ell: L * n + ell - 1                               # noqa: E731
    Ucol = lambda ell, k: slice(L * n + L + (ell * nv + k) * m, L * n + L + (ell * nv + k + 1) * m)  # noqa: E731
    rows, rhs = [], []
    for ell in list(range(1, L)) + [L]:                           # C2 then C3
        H, h = (prob.safe.H, prob.safe.h) if ell < L else (prob.target.H, prob.target.h)
        for f in range(H.shape[0]):
            r = np.zeros(size)
            r[P(ell)] = H[f]
            r[E(ell)] = max(H[f] @ z for z in Zv)
            rows.append(r); rhs.append(h[f])
    sig_w = support(sysm.W, Hz)
    for ell in range(L):                                          # C4
        for k in range(nv):
            for f in range(Hz.shape[0]):
                r = np.zeros(size)
                b = -sig_w[f]
                if ell == 0:
                    b -= Hz[f] @ sysm.A @ V[k]
                else:
                    r[P(ell)] = Hz[f] @ sysm.A
                    r[E(ell)] = Hz[f] @ sysm.A @ Zv[k]
                r[Ucol(ell, k)] = Hz[f] @ sysm.B
                r[P(ell + 1)] = -Hz[f]
                r[E(ell + 1)] = -hz[f]
                rows.append(r); rhs.append(b)
    return np.array(rows), np.array(rhs)


@pytest.mark.parametrize("L", [1, 2, 5])
@pytest.mark.parametrize("one_norm", [False, True])
def test_vectorised_builder_matches_row_by_row_reference(L, one_norm):
    A = np.array([[1.0, 0.1], [0.05, 0.9]])
    B = np.array([[0.5, 0.1], [0.0, 0.4]])
    U = one_norm_input_set(1.0, 2) if one_norm else box_input_set(1.0, 2)
    sysm = LinearSystem(A=A, B=B, U=U, W=Ball(2, 0.1))
    Pi = Polytope.from_vertices(np.array([[0.0, 0.0], [1.0, 0.0], [0.2, 1.0]]))
    Pj = Polytope.box([1.0, 0.0], [2.0, 1.0])
    S = convex_hull_of(Pi, Pj)
    prob = TubeProblem(sysm, Pi, Pj, S, make_z("cell", Pi), L, S.bounding_box())
    lp = build_tube_lp(prob)
    G, g = _reference_rows(prob)
    L_ = int(prob.L)
    # every row per unit of its state-space normal: the facet row of S, P_j or Z it comes from
    nrm = np.concatenate([np.tile(np.linalg.norm(S.H, axis=1), L_ - 1), np.linalg.norm(Pj.H, axis=1),
                          np.tile(np.linalg.norm(prob.Z.H, axis=1), L_ * 3)])
    np.testing.assert_allclose(lp.G, G / nrm[:, None], rtol=0, atol=1e-14)
    np.testing.assert_allclose(lp.g, g / nrm, rtol=0, atol=1e-14)
    assert list(lp.row_kind) == [2] * ((L - 1) * S.H.shape[0]) + [3] * Pj.H.shape[0] + [4] * (L * 3 * prob.Z.H.shape[0])
    if one_norm:                                                  # C5 rows: H_u u_k(l) <= h_u per (l, k)
        Hu = sysm.U.H
        for ell in range(L):
            for k in range(3):
                r0 = (ell * 3 + k) * Hu.shape[0]
                c0 = 3 * L + (ell * 3 + k) * 2
                np.testing.assert_array_equal(lp.G_hard[r0:r0 + Hu.shape[0], c0:c0 + 2], Hu)
        assert np.count_nonzero(lp.G_hard) == np.count_nonzero(Hu) * L * 3
    else:
        assert lp.G_hard.shape == (0, lp.G.shape[1])


def test_tight_bounds_keep_signs_and_nonnegative_margins(corridor_path, paper_system):
    """The implied bounds of ``tube_variable_bounds`` against loose independent boxes
    (``p`` in the bounding box of ``P_ij``, ``0 <= eps <= 100``): same sign of ``t*``
    everywhere and the same margin wherever ``t* >= 0``; tight bounds lie inside the loose."""
    from tubejax.lp.declarations.tube_variables import tube_variable_bounds
    from tubejax.model.problem import pair_problem
    from tubejax.model.workspace.gridmap import load_grid_map
    dec = load_grid_map(corridor_path)
    sysm = paper_system(0.1)
    Z = [make_z("box", c) for c in dec.cells]
    n_pos = n_neg = n_obst = 0
    for i in range(dec.n_cells):
        for j in range(dec.n_cells):
            if i == j or not np.allclose(np.abs(dec.cells[i].centroid - dec.cells[j].centroid).max(), 1.0):
                continue
            for L in (1, 2, 3, 5):
                prob = pair_problem(dec, sysm, Z[i], i, j, L)
                lp = build_tube_lp(prob)
                ix = lp.index
                lo, hi = prob.box
                loose_lb, loose_ub = lp.lb.copy(), lp.ub.copy()
                loose_lb[ix.p], loose_ub[ix.p] = np.tile(lo, L), np.tile(hi, L)
                loose_lb[ix.eps], loose_ub[ix.eps] = 0.0, 100.0
                assert np.all(lp.lb >= loose_lb - 1e-15) and np.all(lp.ub <= loose_ub + 1e-15)
                assert np.all(lp.lb <= lp.ub)
                tight = solve_margin_lp(lp).margin
                loose = solve_margin_lp(lp._replace(lb=loose_lb, ub=loose_ub)).margin
                assert (tight >= -1e-9) == (loose >= -1e-9), (i, j, L, tight, loose)
                if loose >= 0:
                    assert abs(tight - loose) <= 1e-9, (i, j, L, tight, loose)
                    n_pos += 1
                else:
                    n_neg += 1
                n_obst += dec.obstacle_case(i, j)
    assert n_pos >= 5 and n_neg >= 20 and n_obst >= 4, (n_pos, n_neg, n_obst)
    lb, ub = tube_variable_bounds(prob, L_pad=7)                  # padded steps take S's bounds
    ix7 = build_tube_lp(prob).index._replace(L=7)
    assert lb.shape == ub.shape == (ix7.size,)
    s_lo, s_hi = prob.safe.bounding_box()
    np.testing.assert_array_equal(lb[ix7.p_col(6, 0):ix7.p_col(6, 0) + 2], np.maximum(s_lo, prob.box[0]))
    np.testing.assert_array_equal(ub[ix7.p_col(6, 0):ix7.p_col(6, 0) + 2], np.minimum(s_hi, prob.box[1]))
