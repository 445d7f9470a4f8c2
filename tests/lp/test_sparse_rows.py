"""The tube LP's rows built sparse (``sparse_rows``, ``TubeLP.G_csr``) are the dense declaration's.

Held against independent computations: the families' rows derived on the whole identity
(``lp_blocks``, every unit vector evaluated) bit for bit, signed zeros included, family by family
through the layout's names; HiGHS given the LP as a dense ``passModel`` built here from ``G``
(the model as it was passed before the CSR path) against HiGHS through the CSR path: the same model
arrays, status, margin and solution. Problems: the paper map (2-D), a one-norm ``U`` with a state
constraint (hard rows), a 3-D voxel grid, the 4-D double integrator and the 6-D drone (64 vertices).
"""

import dataclasses
from pathlib import Path
from typing import NamedTuple

import highspy
import numpy as np
import pytest
import yaml

from tubejax.abstraction import cross_sections
from tubejax.lp.declarations import tube_lp
from tubejax.lp.declarations.row_families import dense_rows, lp_blocks, sparse_rows, state_lengths
from tubejax.lp.declarations.sparse_blocks import PROBE_FROM, _probe, csr_dense, family_csr, scale_csr_rows
from tubejax.lp.declarations.tube_families import TUBE_FAMILIES, float_terms, tube_identity
from tubejax.lp.declarations.tube_lp import build_tube_lp, margin_csr, margin_rows
from tubejax.lp.declarations.tube_lp_batch import build_tube_lps
from tubejax.lp.engines.highs import HIGHS_OPTIONS, margin_matrix, new_highs, solve_margin_lp
from tubejax.model.geometry import Ball, Halfspaces, Polytope
from tubejax.model.problem import Pairs, pair_problems
from tubejax.model.system import LinearSystem, box_input_set, one_norm_input_set
from tubejax.model.system_kinds import double_integrator_lookahead
from tubejax.model.workspace import box_grid, load_grid_map
from tubejax.model.workspace.lookahead import lift_lookahead

CONF = Path(__file__).resolve().parents[2] / "conf"


def _system(name: str, radius: float, U=None, X=None) -> LinearSystem:
    cfg = yaml.safe_load((CONF / "system" / f"{name}.yaml").read_text())
    A, B = np.array(cfg["A"], float), np.array(cfg["B"], float)
    U = box_input_set(cfg["U"]["bound"], B.shape[1]) if U is None else U
    return LinearSystem(A=A, B=B, U=U, W=Ball(A.shape[0], radius), X=X)


def _neighbour_problems(decomp, system, zshape: str, L: int, k: int = 4) -> list:
    """Problems of the first ``k`` pairs of touching cells at horizon ``L``."""
    lo, hi = decomp.cell_boxes()
    pairs = [(i, j) for i in range(decomp.n_cells) for j in range(decomp.n_cells)
             if i != j and np.all((lo[j] <= hi[i] + 1e-9) & (hi[j] >= lo[i] - 1e-9))][:k]
    src, dst = np.array(pairs).T
    Zs = cross_sections(decomp, zshape, 1.0)
    return pair_problems(decomp, system, Zs, Pairs(src, dst, np.zeros(len(src), bool)), L)


def _drone(L: int) -> list:
    A, B = double_integrator_lookahead(3, 0.5, 2.0)
    system = LinearSystem(A=A.astype(float), B=B.astype(float), U=box_input_set(1.0, 3), W=Ball(6, 0.01))
    base = box_grid([0, 0, 0], [2, 1, 1], [2, 1, 1])
    return _neighbour_problems(lift_lookahead(base, [2, 1, 1]), system, "cell", L, k=3)


def _cases() -> dict:
    paper = load_grid_map(CONF / "workspace" / "maps" / "paper.txt")
    X = Halfspaces(np.array([[1.0, 0.3], [-0.2, 1.0]]), np.array([40.0, 40.0]), "system.X")
    l1 = _system("integrator2d_l1", 0.1, U=one_norm_input_set(1.0, 2), X=X)
    ws = yaml.safe_load((CONF / "workspace" / "boxgrid4d.yaml").read_text())
    grid4 = box_grid(ws["lower"], ws["upper"], ws["divisions"], obstacles=[tuple(o) for o in ws["obstacles"]])
    grid3 = box_grid([0, 0, 0], [3, 2, 2], [3, 2, 2], obstacles=[([1, 1, 0], [2, 2, 1])])
    s2, s3, s4 = _system("integrator2d", 0.2), _system("integrator3d", 0.05), _system("double_integrator", 0.02)
    return {
        "paper-2d": lambda: [p for L in (1, 4, 30) for p in _neighbour_problems(paper, s2, "box", L)],
        "l1-hard-rows-2d": lambda: [p for L in (3, 30) for p in _neighbour_problems(paper, l1, "cell", L, k=2)],
        "voxels-3d": lambda: [p for L in (6, 12) for p in _neighbour_problems(grid3, s3, "cell", L)],
        "double-integrator-4d": lambda: [p for L in (2, 8) for p in _neighbour_problems(grid4, s4, "cell", L)],
        "drone-6d": lambda: _drone(3),
    }


CASES = _cases()


@pytest.fixture(scope="module", params=sorted(CASES))
def problems(request):
    return CASES[request.param]()


def test_the_cases_exercise_the_column_probes(problems):
    sizes = [build_tube_lp(p).G.shape[1] for p in problems]
    assert max(sizes) >= PROBE_FROM                        # some LP finds its columns by probing


def test_sparse_rows_are_the_families_rows_on_the_whole_identity(problems):
    for p in problems:
        d = float_terms(p)
        for role in ("margin", "hard"):
            M, g, layout = sparse_rows(d, p.system.m, role, p.system.u_is_box, TUBE_FAMILIES, tube_identity)
            blocks = lp_blocks(d, p.system.m, role, p.system.u_is_box, TUBE_FAMILIES, tube_identity)
            n_x = tube_identity(d, p.system.m)[0].shape[0]
            G0 = np.concatenate([b[2].T for b in blocks]) if blocks else np.zeros((0, n_x))
            assert M.shape == G0.shape and M.has_sorted_indices
            assert csr_dense(M).tobytes() == np.ascontiguousarray(G0).tobytes()      # signed zeros too
            assert np.all((M.data != 0) | np.signbit(M.data))                       # no stored +0.0
            assert M.nnz == np.count_nonzero(G0) + np.count_nonzero((G0 == 0) & np.signbit(G0))
            np.testing.assert_array_equal(g, np.concatenate([b[3] for b in blocks]) if blocks else np.zeros(0))
            assert layout.names == tuple(b[0] for b in blocks) and layout.shapes == tuple(b[1] for b in blocks)
            for name, grid, Gb, gb in blocks:                                        # rows found by name
                rows = layout.slice(name)
                assert csr_dense(M[rows]).tobytes() == np.ascontiguousarray(Gb.T).tobytes()
                np.testing.assert_array_equal(g[rows], gb)
            Gd, gd, layout_d = dense_rows(d, p.system.m, role, p.system.u_is_box, TUBE_FAMILIES, tube_identity)
            assert Gd.tobytes() == np.ascontiguousarray(G0).tobytes() and layout_d == layout
            np.testing.assert_array_equal(gd, g)


def test_tube_lps_carry_their_rows_in_csr_form(problems):
    lps = build_tube_lps(problems)
    for p, lp_b in zip(problems, lps):
        lp = build_tube_lp(p)
        assert lp.G_csr is not None and lp_b.G_csr is not None
        assert csr_dense(lp.G_csr).tobytes() == lp.G.tobytes()
        assert csr_dense(lp_b.G_csr).tobytes() == lp_b.G.tobytes() == lp.G.tobytes()
        G, g, nrm, layout = margin_rows(p)
        M, g2, nrm2, layout2 = margin_csr(p)
        assert csr_dense(M).tobytes() == G.tobytes() == lp.G.tobytes()
        np.testing.assert_array_equal(g, g2)
        np.testing.assert_array_equal(nrm, nrm2)
        assert layout == layout2 == lp.layout


def _dense_model(lp):
    """``[G c; G_hard 0]`` row-wise from the dense ``G``: the nonzeros of the whole matrix, row-major."""
    nr, nx = lp.G.shape
    nh = lp.G_hard.shape[0]
    Mx = np.zeros((nr + nh, nx + 1))
    Mx[:nr, :nx] = lp.G
    Mx[nr:, :nx] = lp.G_hard
    Mx[:nr, nx] = 1.0 if lp.t_coef is None else lp.t_coef
    flat = np.flatnonzero(Mx)
    return (np.searchsorted(flat // (nx + 1), np.arange(nr + nh + 1)).astype(np.int32),
            (flat % (nx + 1)).astype(np.int32), Mx.ravel()[flat])


def _solve_dense(lp):
    """HiGHS on the margin form passed from the dense matrix: status, margin, x."""
    nr, nx = lp.G.shape
    nh = lp.G_hard.shape[0]
    start, index, value = _dense_model(lp)
    h = new_highs()
    h.clearSolver()
    cost = np.zeros(nx + 1)
    cost[nx] = -1.0
    inf = highspy.kHighsInf
    h.passModel(nx + 1, nr + nh, value.size, int(highspy.MatrixFormat.kRowwise.value),
                int(highspy.ObjSense.kMinimize.value), 0.0, cost, np.append(lp.lb, max(lp.t_min, -inf)),
                np.append(lp.ub, lp.t_max), np.full(nr + nh, -inf), np.concatenate([lp.g, lp.g_hard]),
                start, index, value, np.zeros(nx + 1, np.int32))
    h.run()
    status = h.modelStatusToString(h.getModelStatus())
    xt = np.asarray(h.getSolution().col_value)
    return status, (float(xt[nx]) if status == "Optimal" else float("nan")), xt[:nx]


def test_highs_through_the_csr_path_solves_the_dense_model(problems):
    assert HIGHS_OPTIONS["threads"] == 1                   # one thread: the same model, the same answer
    for p in problems:
        lp = build_tube_lp(p)
        radius = lp._replace(t_coef=np.where(np.arange(lp.G.shape[0]) % 3 == 0, 0.0, 0.5))   # zeros in t's column
        for case in (lp, radius):
            ref = _dense_model(case)
            for got in (margin_matrix(case), margin_matrix(case._replace(G_csr=None))):
                for a, b in zip(got, ref):
                    assert a.dtype == b.dtype
                    np.testing.assert_array_equal(a, b)
            status, margin, x = _solve_dense(case)
            res = solve_margin_lp(case)
            assert res.status == status
            if status == "Optimal":
                assert res.margin == margin
                np.testing.assert_array_equal(res.x, x)


class _Vars(NamedTuple):
    a: np.ndarray


def test_column_probes_never_miss_a_coefficient():
    """A family reading two columns per row, with exact zeros, ``-0.0`` and tiny weights, whole
    blocks of columns unread: the CSR form has the dense one's coefficients, and the probes skip
    the unread blocks."""
    rng = np.random.default_rng(0)
    n_x, R = 900, 500
    read = np.concatenate([np.arange(0, 60), np.arange(400, 430), [899]])     # columns the rows read
    c1, c2 = rng.choice(read, R), rng.choice(read, R)
    w1 = rng.standard_normal(R) * np.where(rng.random(R) < 0.1, 1e-300, 1.0)
    w2 = rng.standard_normal(R)
    w1[::7], w2[::5], w2[::11] = 0.0, -0.0, 0.0

    def evaluate(x):
        return x.a[:, c1] * w1 + x.a[:, c2] * w2

    x = _Vars(np.eye(n_x))
    dense = evaluate(x).T                                   # (R, n_x): every unit vector evaluated
    M = family_csr(evaluate, x, n_x, R)
    blocks, reach = _probe(evaluate, x, n_x)                # the columns whose NaN probe reaches a row
    cols = np.concatenate([blk for blk, r in zip(blocks, reach) if r.any()])
    assert set(read) <= set(cols.tolist()) and cols.size < n_x / 4
    got = csr_dense(M)
    np.testing.assert_array_equal(got, dense)               # every nonzero bit for bit (tiny ones too)
    # a -0.0 kept is the dense one's; where a row reads no column of a block, +0.0 (0 w1 + 0 w2 may be -0.0)
    assert np.all(~np.signbit(got) | np.signbit(dense))
    assert np.signbit(got[got == 0]).any()
    assert not np.signbit(got[:, np.setdiff1d(np.arange(n_x), cols)]).any()


def test_blocks_reaching_disjoint_rows_share_their_evaluations():
    """Rows ``r`` reading columns ``r`` and ``r + 1`` (a banded matrix, like a tube's input columns,
    each reaching its own vertex's rows): far fewer vectors evaluated than columns, the same matrix."""
    rng = np.random.default_rng(1)
    n_x = 1000
    w1, w2 = rng.standard_normal(n_x), rng.standard_normal(n_x)
    w2[::3] = -0.0
    nxt = (np.arange(n_x) + 1) % n_x
    evaluated = []

    def evaluate(x):
        evaluated.append(x.a.shape[0])
        return x.a[:, np.arange(n_x)] * w1 + x.a[:, nxt] * w2

    x = _Vars(np.eye(n_x))
    dense = evaluate(x).T
    evaluated.clear()
    got = csr_dense(family_csr(evaluate, x, n_x, n_x))
    np.testing.assert_array_equal(got, dense)
    assert np.all(~np.signbit(got) | np.signbit(dense))
    assert sum(evaluated) < n_x / 4                          # probes + a few shared groups, not n_x vectors


def _signed_zero_safe_sets(problems) -> list:
    """``problems`` with their safe set's normals rotated so that some have only signed coefficients
    (``-0.0`` and negative ones: the zero tube's row may be ``-0.0``), where the dimension is 2."""
    out = []
    for p in problems:
        if p.system.n != 2:
            continue
        lo, hi = p.safe.bounding_box()
        V = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
        H = np.array([[-0.6, -0.8], [-1.0, -0.0], [-0.0, -1.0], [1.0, 0.0], [0.0, 1.0]])
        h = np.array([-(0.6 * lo[0] + 0.8 * lo[1]) + 1.0, -lo[0], -lo[1], hi[0], hi[1]])
        out.append(dataclasses.replace(p, safe=Polytope(V, H, h)))
    return out


def test_interior_rows_tiled_across_horizons_are_the_derived_ones(problems):
    """The safe set's rows at ``L > 2`` repeated from ``L = 2`` (:func:`tube_lp._tiled`) are the rows derived
    at ``L`` (:func:`sparse_rows` on the whole identity, scaled), bit for bit: the same entries (signed zeros
    too), columns, scales and grid; for normals with only signed coefficients too."""
    safe = TUBE_FAMILIES[0]
    tiled = 0
    for p in problems + _signed_zero_safe_sets(problems):
        if int(p.L) <= tube_lp.TILE_HORIZON:
            continue
        tube_lp._FAMILY_CACHE.clear()
        tube_lp._CACHE_USED[id(tube_lp._FAMILY_CACHE)][0] = 0
        d = float_terms(p)
        tiled += tube_lp._tiles_steps(p, d, safe, "state")
        M, nrm, grid = tube_lp._family_rows(p, d, safe, "state")
        M0, _, layout = sparse_rows(d, p.system.m, "margin", p.system.u_is_box, (safe,), tube_identity)
        nrm0 = state_lengths(d, "margin", p.system.u_is_box, lambda H: np.linalg.norm(H, axis=1), (safe,))
        M0 = scale_csr_rows(M0, nrm0)
        assert M.shape == M0.shape and tuple(grid) == tuple(layout.shapes[0])
        np.testing.assert_array_equal(M.indptr, M0.indptr)
        np.testing.assert_array_equal(M.indices, M0.indices)
        assert M.data.tobytes() == M0.data.tobytes() and nrm.tobytes() == nrm0.tobytes()
    assert tiled > 0 or all(int(p.L) <= tube_lp.TILE_HORIZON for p in problems)
