"""Margin LPs with one input column per group vertex (tubejax/abstraction/group_vertex_lp.py).

Against HiGHS on the full LPs of a 4-D (two groups) and a 6-D (three groups) lifted map: the same
optimal margin, an expanded point that passes the full LP's float check (edges), mapped duals whose
weak-duality bound on the full LP is the reduced LP's, and the same verdicts, margins and proof levels
as the reference solver. A problem that is not a product is solved in full, and a wrong reduction only
costs the full solve. The dense rows are written only where a verdict reads them, with the same verdicts
bit for bit as with them written first.
"""

import dataclasses
import pickle

import numpy as np
import pytest

from tubejax.abstraction import group_vertex_lp as gv
from tubejax.abstraction import joint_duals as jd
from tubejax.abstraction.group_vertex_lp import expanded_result, group_vertex_lp, solve_by_group_vertices
from tubejax.abstraction.joint_duals import DualReuseSolver
from tubejax.lp.declarations.tube_lp import DenseNeeded, DenseOnDemand, build_tube_lp, tube_violation, with_dense_rows
from tubejax.lp.evidence import decide
from tubejax.lp.engines.highs import solve_margin_lp
from tubejax.lp.evidence.decide import float_dual_bound
from tubejax.lp.evidence.verdict import VERIFY_TOL, highs_solve_batch
from tubejax.model.geometry import Ball
from tubejax.model.problem import Pairs, pair_problems
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.system_kinds import double_integrator_lookahead
from tubejax.model.workspace import box_grid, parse_grid_map
from tubejax.model.workspace.lookahead import lift_lookahead
from tubejax.model.zshape.kinds import cross_sections


def _lifted_problems(decomp, axes: int, Ls) -> list:
    A, B = double_integrator_lookahead(axes, 0.5, 2.0)
    sysm = LinearSystem(A=A.astype(float), B=B.astype(float), U=box_input_set(1.0, axes), W=Ball(2 * axes, 0.01))
    Z = cross_sections(decomp, "cell", 1.0)
    n = decomp.n_cells
    s, t = np.array([(i, j) for i in range(n) for j in range(n) if i != j]).T
    return [p for L in Ls for p in pair_problems(decomp, sysm, Z, Pairs(s, t, np.zeros(len(s), bool)), L)]


@pytest.fixture(scope="module")
def problems4d():
    """Pairs of a 2 x 2 map lifted by 2 look-ahead slabs per axis (16 cells in R^4, 16 vertices each), every
    ordered pair at L = 2 and 4 (480 problems, 44 of them feasible)."""
    return _lifted_problems(lift_lookahead(parse_grid_map("..\n..\n"), [2, 2]), 2, (2, 4))


@pytest.fixture(scope="module")
def problems6d():
    """The 4 cells of two voxels lifted by 2 look-ahead slabs along x (R^6, 64 vertices each), every pair at
    L = 1..3 (36 problems, 4 of them feasible)."""
    base = box_grid([0, 0, 0], [2, 1, 1], [2, 1, 1])
    return _lifted_problems(lift_lookahead(base, [2, 1, 1]), 3, (1, 2, 3))


def _compare(prob, statuses: set) -> None:
    lp = build_tube_lp(prob)
    red = group_vertex_lp(prob, lp)
    assert red is not None
    full, res = solve_margin_lp(lp), solve_margin_lp(red.lp)
    assert full.status == res.status == "Optimal"
    assert res.margin == pytest.approx(full.margin, abs=1e-12)              # the same t*
    mapped = expanded_result(red, res, lp)
    x = mapped.x
    assert float(np.min(lp.g - lp.G @ x)) == pytest.approx(res.margin, abs=1e-9)   # its margin on the full rows
    if res.margin > 0:
        assert tube_violation(prob, lp.index.split(x)) <= VERIFY_TOL
        statuses.add("edge")
    else:
        statuses.add("infeasible")
    b_red, b_full = float_dual_bound(red.lp, res), float_dual_bound(lp, mapped)
    assert b_full == pytest.approx(b_red, abs=1e-12) and full.margin <= b_full + 1e-9
    G = lp.G_csr
    a_full, a_red = G.T @ mapped.y, red.lp.G.T @ res.y          # G^T y: the reduced one, merged columns split evenly
    np.testing.assert_allclose(a_full, a_red[red.col] / np.bincount(red.col)[red.col], rtol=0, atol=1e-12)


@pytest.mark.parametrize("fixture,step,groups,copies", [("problems4d", 8, 2, 4), ("problems6d", 1, 3, 16)])
def test_the_group_vertex_lp_has_the_full_margin_and_maps_back(request, fixture, step, groups, copies):
    probs = request.getfixturevalue(fixture)
    statuses: set = set()
    for prob in probs[::step]:
        _compare(prob, statuses)
    assert statuses == {"edge", "infeasible"}
    prob = probs[-1]
    lp = build_tube_lp(prob)
    red = group_vertex_lp(prob, lp)
    ix = lp.index
    n_w = 4 * groups                                            # a 2-D box's 4 vertices per group, one input each
    assert red.lp.G.shape[1] == ix.L * (ix.n + 1) + ix.L * n_w
    dyn = lp.layout.slice("dynamics")
    assert set(red.count[red.row[dyn]].tolist()) == {float(copies)}     # 4^(groups - 1) copies of each C4 row
    assert np.all(red.count[red.row[:dyn.start]] == 1)


def test_the_solver_gives_the_reference_verdicts(problems4d, monkeypatch):
    """:class:`DualReuseSolver` with the group-vertex LPs: the reference's statuses, edge margins (to rounding)
    and proof levels."""
    probs = problems4d[100:180]
    full = []
    monkeypatch.setattr(gv, "full_solve", lambda prob, lp: full.append(prob) or solve_margin_lp(lp, basis_min_margin=-1e-6))
    got = DualReuseSolver(solve_by_group_vertices)(probs)
    want = highs_solve_batch(probs)
    assert len(full) < len(probs) // 4                                  # most answers from the reduced LPs
    assert [v.status for v in got] == [v.status for v in want]
    assert {"edge", "infeasible"} <= {v.status for v in want}
    for prob, g, w in zip(probs, got, want):
        if w.status == "edge":
            assert g.margin == pytest.approx(w.margin, abs=1e-12) and g.proof.level == w.proof.level
            assert tube_violation(prob, g.tube) <= VERIFY_TOL


def test_not_a_product_is_solved_in_full(problems4d):
    prob = problems4d[0]
    s = prob.system                                         # every input moves every axis: one block
    p = dataclasses.replace(prob, system=LinearSystem(A=s.A, B=s.B + 0.01, U=s.U, W=s.W))
    lp = build_tube_lp(p)
    assert group_vertex_lp(p, lp) is None
    res, full = solve_by_group_vertices(p, lp), solve_margin_lp(lp)
    assert res.margin == full.margin and np.array_equal(res.x, full.x)
    demanding = dataclasses.replace(prob, min_margin=0.01)
    assert group_vertex_lp(demanding, build_tube_lp(demanding)) is None


def test_a_wrong_reduction_only_costs_the_full_solve(problems4d, monkeypatch):
    """Inputs merged across every vertex (a restriction, not the reduction): the verdicts stay the reference's."""
    def merge_all(prob, lp, of_state, of_input):
        ix = lp.index
        rep = np.arange(ix.size)
        u = np.arange(ix.u.start, ix.u.stop).reshape(ix.L, ix.n_v, ix.m)
        rep[ix.u] = np.broadcast_to(u[:, :1, :], u.shape).ravel()
        return rep
    full = []
    monkeypatch.setattr(gv, "_column_map", merge_all)
    monkeypatch.setattr(gv, "_SELECTIONS", {})
    monkeypatch.setattr(gv, "_DYNAMICS", {})
    monkeypatch.setattr(gv, "full_solve", lambda prob, lp: full.append(prob) or solve_margin_lp(lp, basis_min_margin=-1e-6))
    probs = problems4d[100:140]
    got = DualReuseSolver(solve_by_group_vertices)(probs)
    want = highs_solve_batch(probs)
    assert [v.status for v in got] == [v.status for v in want]
    edges = [p for p, v in zip(probs, want) if v.status == "edge"]
    assert edges and all(any(p is q for q in full) for p in edges)     # every edge from its full LP


def test_dense_rows_are_written_only_on_demand(problems4d):
    """``build_tube_lp(dense=False)``: ``G`` answers its shape only, any read raises ``DenseNeeded``, and
    :func:`with_dense_rows` writes the array :func:`build_tube_lp` writes, bit for bit (``-0.0`` included)."""
    prob = problems4d[7]
    lazy, full = build_tube_lp(prob, dense=False), build_tube_lp(prob)
    assert isinstance(lazy.G, DenseOnDemand) and lazy.G.shape == full.G.shape and lazy.G.ndim == 2
    x = np.zeros(full.G.shape[1])
    for read in (lambda G: G @ x, lambda G: G.T, lambda G: np.asarray(G), lambda G: G[0], lambda G: x @ G):
        with pytest.raises(DenseNeeded):
            read(lazy.G)
    back = pickle.loads(pickle.dumps(lazy))                 # it travels to worker processes as it is
    assert isinstance(back.G, DenseOnDemand) and back.G.shape == lazy.G.shape
    G = with_dense_rows(lazy).G
    assert np.array_equal(G, full.G) and np.array_equal(np.signbit(G), np.signbit(full.G))
    assert with_dense_rows(full) is full


def _dense_bound(lp, res):
    return float_dual_bound(with_dense_rows(lp), res)


def test_the_sparse_dual_bound_compares_as_the_dense_one(problems4d, problems6d, monkeypatch):
    """:func:`float_dual_bound_at_most` from ``G_csr`` gives the dense rows' answer at every threshold,
    those one rounding away from the dense bound included, and reads the dense rows only near it."""
    dense_reads = []
    monkeypatch.setattr(decide, "with_dense_rows", lambda lp: dense_reads.append(1) or with_dense_rows(lp))
    n = 0
    for prob in problems4d[::23] + problems6d[::5]:
        lp = build_tube_lp(prob, dense=False)
        res = solve_margin_lp(lp)
        if res.status != "Optimal":
            continue
        b = _dense_bound(lp, res)
        for thr in (b, np.nextafter(b, np.inf), np.nextafter(b, -np.inf), b + 1e-12, b - 1e-12, b + 1.0, b - 1.0):
            for strict in (False, True):
                assert decide.float_dual_bound_at_most(lp, res, thr, strict) == (b < thr if strict else b <= thr)
        n += 1
    assert n >= 10
    dense_reads.clear()
    assert decide.float_dual_bound_at_most(lp, res, b + 1.0) and not decide.float_dual_bound_at_most(lp, res, b - 1.0)
    assert dense_reads == []                                # far from the bound: the sparse rows decide


def test_the_solver_writes_dense_rows_only_for_verdicts_that_read_them(problems4d, problems6d, monkeypatch):
    """:class:`DualReuseSolver` (dense rows on demand) against the same steps with the dense rows written first
    and the gate's bound taken from them: the same verdicts bit for bit (status, margin, tube, proof level,
    refutation bound); edges never write the dense rows, non-edges whose refutation reads them do."""
    probs = problems4d[100:180] + problems6d
    with monkeypatch.context() as m:
        m.setattr(gv, "float_dual_bound_at_most",
                  lambda lp, res, thr, strict=False: (_dense_bound(lp, res) < thr) if strict
                  else (_dense_bound(lp, res) <= thr))
        ref = DualReuseSolver(solve_by_group_vertices)
        ref._form = ref._form._replace(build=lambda prob, dense=True: build_tube_lp(prob))     # dense first
        want = ref(probs)
    written = []
    monkeypatch.setattr(jd, "with_dense_rows", lambda lp: written.append(lp.G.shape) or with_dense_rows(lp))
    solver = DualReuseSolver(solve_by_group_vertices)
    got = []
    for prob in probs:
        before = len(written)
        got.append(solver.verdict(prob))
        if got[-1].status == "edge":
            assert len(written) == before                   # an edge's verdict reads the sparse rows only
    assert {"edge", "infeasible"} <= {v.status for v in want} and written and 0 < solver.n_reused == ref.n_reused
    for g, w in zip(got, want):
        assert (g.status, float(g.margin).hex(), g.provenance) == (w.status, float(w.margin).hex(), w.provenance)
        if w.status == "edge":
            assert g.proof.level == w.proof.level
            for a, b in zip(g.tube, w.tube):
                np.testing.assert_array_equal(a, b)
        elif w.refutation is not None:
            assert (g.refutation.kind, float(g.refutation.bound).hex()) == (w.refutation.kind,
                                                                            float(w.refutation.bound).hex())


def _column_map_afresh(prob, lp, of_state, of_input):
    """:func:`gv._column_map` as it was before its maps were kept: derived for every LP."""
    d = gv.float_terms(prob)
    ix = lp.index
    V, Zv = np.asarray(d.V, float), np.asarray(d.Zv, float)
    first = np.empty((ix.n_v, ix.m), np.int64)
    for g in range(int(of_input.max()) + 1):
        part = np.ascontiguousarray(np.concatenate([V, Zv], axis=1)[:, np.tile(of_state == g, 2)])
        _, at, inv = np.unique(part.view(np.dtype((np.void, part.shape[1] * 8))).ravel(),
                               return_index=True, return_inverse=True)
        first[:, of_input == g] = at[np.ravel(inv)][:, None]
    u = np.arange(ix.u.start, ix.u.stop).reshape(ix.L, ix.n_v, ix.m)
    rep = np.arange(ix.size)
    rep[ix.u] = u[:, first, np.arange(ix.m)].ravel()
    if not (np.array_equal(lp.lb[rep], lp.lb) and np.array_equal(lp.ub[rep], lp.ub)):
        return None
    return rep


def _selection_afresh(lp, col, n_red):
    """:func:`gv._selection` as it was before the dynamics part was kept: ``M E`` of the whole LP, then its rows."""
    ME = gv._reduced_columns(lp.G_csr, col, n_red)
    dyn = lp.layout.slice(gv.DYNAMICS)
    first = gv._duplicate_rows(ME[dyn])
    same = np.arange(ME.shape[0])
    same[dyn] = dyn.start + first
    kept = np.flatnonzero(same == np.arange(ME.shape[0]))
    return ME[kept], same, kept


def _same_csr(a, b) -> None:
    assert a.shape == b.shape and a.has_sorted_indices == b.has_sorted_indices
    for x in ("data", "indices", "indptr"):
        u, v = getattr(a, x), getattr(b, x)
        assert u.dtype == v.dtype and np.array_equal(u, v) and np.array_equal(np.signbit(u), np.signbit(v)), x


def test_kept_column_maps_and_selections_are_the_arrays_made_afresh(problems4d, problems6d, monkeypatch):
    """The kept column maps, the kept dynamics parts and the other rows mapped on their own give the arrays that
    deriving everything for each LP gives, bit for bit (dtypes, ``-0.0`` and the sorted flag included), on a
    first and on a kept pass; the other rows' fast path agrees with :func:`gv._reduced_columns` where it declines."""
    for cache in ("_SELECTIONS", "_DYNAMICS", "_COLUMN_MAPS"):
        monkeypatch.setattr(gv, cache, {})
    probs = problems4d[::7] + problems6d[::3]
    n = 0
    for _ in range(2):
        for prob in probs:
            lp = build_tube_lp(prob, dense=False)
            groups = gv._groups(prob.system)
            rep, want = gv._column_map(prob, lp, *groups), _column_map_afresh(prob, lp, *groups)
            assert (rep is None) == (want is None)
            if rep is None:
                continue
            assert rep.dtype == want.dtype and np.array_equal(rep, want)
            stand, col = np.unique(rep, return_inverse=True)
            col = np.ravel(col)
            M, same, kept = gv._selection(prob, lp, rep, col, stand.size)
            M2, same2, kept2 = _selection_afresh(lp, col, stand.size)
            _same_csr(M, M2)
            assert np.array_equal(same, same2) and np.array_equal(kept, kept2)
            dyn = lp.layout.slice(gv.DYNAMICS)                 # the input columns: the fallback
            d, i, k = gv._other_rows(lp.G_csr, dyn.start, dyn.stop, col, stand.size)
            R = gv._reduced_columns(lp.G_csr[dyn], col, stand.size)
            assert np.array_equal(d, R.data) and np.array_equal(i, R.indices) and np.array_equal(k, np.diff(R.indptr))
            n += 1
    assert n >= 2 * 60 and gv._COLUMN_MAPS and gv._DYNAMICS


def test_refuting_dual_rows_are_the_dense_rows(problems4d):
    """The rows a refuting dual's ``G^T y`` reads, written from the sparse rows alone, are the dense rows' bit for bit."""
    rng = np.random.default_rng(0)
    for prob in problems4d[::40]:
        lazy, full = build_tube_lp(prob, dense=False), build_tube_lp(prob)
        rows = np.sort(rng.choice(full.G.shape[0], 40, replace=False))
        got, want = jd._dense_rows_of(lazy, rows), full.G[rows]
        assert got.flags.c_contiguous and np.array_equal(got, want) and np.array_equal(np.signbit(got), np.signbit(want))
        y = rng.random(rows.size)
        assert np.array_equal(got.T @ y, want.T @ y)
