"""Exact tubes from HiGHS's optimal basis (docs/math/evidence.md): zero-margin edges get proofs."""

import pickle
from fractions import Fraction as F

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import exact_reference as ref
from tubejax.abstraction import build_abstraction
from tubejax.lp.evidence import exact_tube_violation, prove_evidence, prove_with_basis
from tubejax.lp.evidence.basis import BasisError, basis_vertex, solve_exact
from tubejax.lp.evidence.prove import rational_lp
from tubejax.lp.evidence.rows import check_against_float, rational_tube_lp
from tubejax.lp.declarations.tube_lp import build_tube_lp
from tubejax.lp.engines.highs import BASIS_BASIC, BASIS_LOWER, solve_margin_lp
from tubejax.lp.evidence.verdict import highs_verdict
from tubejax.model.workspace import load_grid_map


@pytest.fixture(scope="module")
def corridor_ts(corridor_path, paper_system):
    return build_abstraction(load_grid_map(corridor_path), paper_system(0.2), L_max=10, progress=False)


def zero_margin(ts):
    return [k for k, e in enumerate(ts.edges) if abs(e.margin) <= 1e-9]


def test_highs_returns_its_optimal_basis(corridor_ts):
    prob = corridor_ts.problem(zero_margin(corridor_ts)[0])
    lp = build_tube_lp(prob)
    assert solve_margin_lp(lp).col_status is None                 # only when asked
    res = solve_margin_lp(lp, basis_min_margin=-np.inf)
    nr, nx = lp.G.shape
    assert res.col_status.shape == (nx + 1,) and res.row_status.shape == (nr,)
    # a basis: as many basic variables (columns and row slacks) as rows
    assert int(np.sum(res.col_status == BASIS_BASIC) + np.sum(res.row_status == BASIS_BASIC)) == nr
    assert solve_margin_lp(lp, basis_min_margin=1.0).col_status is None   # margin below the threshold


def test_corridor_zero_margin_edges_get_exact_tubes_from_the_basis(corridor_ts):
    ks = zero_margin(corridor_ts)
    assert len(ks) == 8
    rebuilt = 0
    for k in ks:
        prob = corridor_ts.problem(k)
        lp = build_tube_lp(prob)
        res = solve_margin_lp(lp, basis_min_margin=-np.inf)
        raw = lp.index.split(res.x)
        pr = prove_with_basis(prob, lp, res, raw)
        assert pr.level == "exact", pr.note
        if exact_tube_violation(prob, raw) > 0:                   # HiGHS's float tube misses exactly
            assert pr.exact is not None and pr.note in ("basic values reconstructed as rationals",
                                                        "basis vertex solved in rationals")
            rebuilt += 1
        ev = pr.exact if pr.exact is not None else raw
        assert ref.tube_violation(prob, *ref.as_lists(ev)) <= 0   # the independent checker agrees
        assert pr.violation <= 1e-9                                # and its rounding passes in floats
    assert rebuilt >= 4


def test_rational_rows_are_the_float_rows(corridor_ts):
    prob = corridor_ts.problem(zero_margin(corridor_ts)[0])
    lp = build_tube_lp(prob)
    rlp = rational_tube_lp(prob, lp)
    check_against_float(rlp, lp)                                  # raises on any mismatch
    assert len(rlp.rows) == lp.G.shape[0]
    # the basis vertex is a vertex: every nonbasic row is tight exactly, t = 0 for zero margin
    res = solve_margin_lp(lp, basis_min_margin=-np.inf)
    x, t = basis_vertex(rlp, res.col_status, res.row_status)
    assert t == 0
    for r, c, g, s in zip(rlp.rows, rlp.t_coef, rlp.rhs, res.row_status):
        val = sum(a * x[j] for j, a in r.items()) + c * t
        assert val <= g and (s == BASIS_BASIC or val == g)


def test_a_wrong_basis_keeps_the_float_level_and_says_why(corridor_ts):
    k = zero_margin(corridor_ts)[0]
    prob = corridor_ts.problem(k)
    lp = build_tube_lp(prob)
    res = solve_margin_lp(lp, basis_min_margin=-np.inf)
    raw = lp.index.split(res.x)
    if exact_tube_violation(prob, raw) <= 0:
        pytest.skip("HiGHS's tube happens to be exact")
    # no tight row, every column at its lower bound: neither a guess nor a solve gives a vertex
    cols = np.full_like(res.col_status, BASIS_LOWER)
    cols[-1] = BASIS_BASIC                                          # the margin t
    bad = res._replace(row_status=np.full_like(res.row_status, BASIS_BASIC), col_status=cols)
    pr = prove_with_basis(prob, lp, bad, raw)
    assert pr.level == "float" and "not square" in pr.note
    nobasis = prove_with_basis(prob, lp, solve_margin_lp(lp), raw)
    assert nobasis.level == "float" and "no basis" in nobasis.note


def test_verdicts_carry_their_proof_and_pickle(corridor_ts):
    k = zero_margin(corridor_ts)[0]
    v = highs_verdict(corridor_ts.problem(k))
    assert v.status == "edge" and v.proof.level == "exact"
    w = pickle.loads(pickle.dumps(v))                              # helper processes send verdicts back
    assert w.proof.level == "exact" and w.proof.exact_violation == v.proof.exact_violation
    if v.proof.exact is not None:
        assert np.array_equal(w.proof.exact.eps.num, v.proof.exact.eps.num)
        assert all(np.array_equal(a, b) for a, b in zip(v.tube, v.proof.exact.to_float()))


def test_prove_evidence_resolves_when_the_stored_tube_misses(corridor_ts):
    k = zero_margin(corridor_ts)[0]
    prob = corridor_ts.problem(k)
    lp = build_tube_lp(prob)
    raw = lp.index.split(solve_margin_lp(lp).x)
    pr = prove_evidence(prob, raw)
    assert pr.level == "exact"
    assert prove_evidence(prob, raw, resolve=False).level == ("exact" if exact_tube_violation(prob, raw) <= 0
                                                              else "float")


@settings(max_examples=40, deadline=None, derandomize=True)
@given(st.integers(2, 7), st.integers(0, 10 ** 6))
def test_exact_solver_solves_random_systems(n, seed):
    rng = np.random.default_rng(seed)
    M = rng.integers(-3, 4, size=(n, n)) * (rng.random((n, n)) < 0.5) + np.diag(rng.integers(1, 4, size=n) * 5)
    rows = [{j: F(int(v), int(rng.integers(1, 6))) for j, v in enumerate(r) if v} for r in M]
    b = [F(int(v), 7) for v in rng.integers(-9, 10, size=n)]
    x = solve_exact(rows, b, list(range(n)))
    for r, bi in zip(rows, b):                                     # checked by substitution
        assert sum(a * x[j] for j, a in r.items()) == bi


def test_exact_solver_refuses_singular_and_non_square_systems():
    with pytest.raises(BasisError, match="singular"):
        solve_exact([{0: F(1), 1: F(1)}, {0: F(2), 1: F(2)}], [F(1), F(2)], [0, 1])
    with pytest.raises(BasisError, match="not square"):
        solve_exact([{0: F(1)}], [F(1)], [0, 1])


def test_rational_lp_of_a_non_box_u_has_hard_rows(paper_system):
    import numpy as np_
    from tubejax.model.geometry import Ball
    from tubejax.model.system import LinearSystem, one_norm_input_set
    from tubejax.model.workspace import parse_grid_map
    s = LinearSystem(A=np_.eye(2), B=0.5 * np_.eye(2), U=one_norm_input_set(1.0, 2), W=Ball(2, 0.05))
    ts = build_abstraction(parse_grid_map("1..\n..2\n"), s, L_max=3, progress=False)
    assert ts.n_edges > 5 and ts.stats["proof"]["exact"] == ts.n_edges
    prob = ts.problem(0)
    lp = build_tube_lp(prob)
    rlp = rational_lp(prob, lp)
    check_against_float(rlp, lp)
    assert len(rlp.hard_rows) == lp.G_hard.shape[0] > 0


@settings(max_examples=60, deadline=None, derandomize=True)
@given(st.integers(-10 ** 6, 10 ** 6), st.integers(1, 10 ** 4), st.integers(0, 10 ** 4), st.integers(1, 10 ** 4))
def test_simplest_rational_has_the_smallest_denominator_in_the_interval(a, b, c, d):
    from tubejax.lp.evidence.basis import simplest_rational
    lo = F(a, b)
    hi = lo + F(c, d)
    q = simplest_rational(lo, hi)
    assert lo <= q <= hi
    # brute force: no smaller denominator has a point in [lo, hi]
    for den in range(1, q.denominator):
        assert -(-lo * den // 1) > hi * den, (lo, hi, q, den)  # ceil(lo den) > hi den


def test_reconstructed_vertex_is_the_basis_vertex(corridor_ts):
    """On zero-margin edges the rounding guess and the exact basic solve give the same point."""
    from tubejax.lp.evidence.basis import reconstructed_vertex
    from tubejax.lp.evidence.rows import tube_bounds
    hits = 0
    for k in zero_margin(corridor_ts):
        prob = corridor_ts.problem(k)
        lp = build_tube_lp(prob)
        res = solve_margin_lp(lp, basis_min_margin=-np.inf)
        rlp = rational_tube_lp(prob, lp)
        x_basis, _ = basis_vertex(rlp, res.col_status, res.row_status)
        x_guess = reconstructed_vertex(*tube_bounds(prob, lp), res.x, res.col_status)
        hits += x_guess == x_basis
        pr = prove_with_basis(prob, lp, res, lp.index.split(res.x))
        assert pr.level == "exact"
    assert hits == len(zero_margin(corridor_ts))
