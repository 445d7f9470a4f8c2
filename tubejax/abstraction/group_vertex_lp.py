"""The product path's margin LPs solved with one input column per group vertex
(docs/math/product.md#one-input-per-group-vertex: the reduction, why ``t*`` is the full LP's, the mapping back).

:func:`group_vertex_lp` merges the input columns of the vertices that share a group's part of ``(v_k, z_k)``
and keeps one of each set of C4 rows that are then exact duplicates; :func:`expanded_result` maps HiGHS's
answer back onto the full LP. Nothing is decided here: :func:`solve_by_group_vertices` hands a clear mapped
answer to the verdict code, which checks, proves or refutes it against the full LP's own data, and solves the
full LP as before for everything else, so a wrong reduction can only cost that full solve.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.sparse as sp

from ..lp.declarations.sparse_blocks import freeze_csr
from ..lp.declarations.tube_families import float_terms
from ..lp.declarations.tube_lp import TubeLP, rows_key
from ..lp.engines.certify import MARGIN_SAFETY
from ..lp.engines.highs import HighsResult, solve_margin_lp
from ..lp.evidence.decide import float_dual_bound_at_most
from ..lp.evidence.verdict import CLEAR_MARGIN
from ..model.product_structure import axis_groups

__all__ = ["GroupVertexLP", "group_vertex_lp", "expanded_result", "solve_by_group_vertices", "group_vertex_answer",
           "full_solve", "DYNAMICS"]

#: The row family whose rows the input columns reach (found by name in ``lp.layout``).
DYNAMICS = "dynamics"
#: Row selections kept (per rows key and column map; the dynamics rows' duplicates per rows key without
#: the sets' normals): the last this many of each.
KEPT_SELECTIONS = 64


class GroupVertexLP(NamedTuple):
    """A margin LP with one input column per group vertex, and how it maps onto the full LP.

    Attributes
    ----------
    lp : TubeLP
        The reduced LP (``G`` and ``G_csr`` the same CSR matrix, no hard rows, no ``index``/``layout``),
        ``n_red`` columns and ``r_red`` rows.
    col : ndarray of int, shape (n_x,)
        The reduced column of each full column: ``x = x'[col]``.
    row : ndarray of int, shape (n_rows,)
        The reduced row each full row equals.
    count : ndarray, shape (r_red,)
        How many full rows each reduced row stands for.
    """

    lp: TubeLP
    col: np.ndarray
    row: np.ndarray
    count: np.ndarray


_GROUPS: dict = {}
#: How far above the reduced optimum the mapped duals may bound the full LP's margin for that optimum to be
#: taken as the full LP's (their bound is at least the full ``t*``: a larger one means the reduced LP was
#: a restriction, and the full LP is solved).
OPTIMALITY_GAP = 1e-9

_SELECTIONS: dict = {}
_DYNAMICS: dict = {}
_COLUMN_MAPS: dict = {}
_ONE_GROUP: dict = {}
#: Column maps kept (:func:`_column_map`; per source cell's terms and layout), the last this many.
KEPT_COLUMN_MAPS = 4096


def _groups(system) -> tuple | None:
    """``(group of each state axis (n,), group of each input (m,))`` of ``system``'s blocks
    (:func:`~tubejax.model.product_structure.axis_groups`), or ``None`` for one block; kept per ``A, B``."""
    key = (system.A.shape, system.B.shape, system.A.tobytes(), system.B.tobytes())
    if key not in _GROUPS:
        states, inputs = axis_groups(system.A, system.B)
        of_state, of_input = np.empty(system.n, np.int64), np.empty(system.m, np.int64)
        for g, (s, u) in enumerate(zip(states, inputs)):
            of_state[s], of_input[u] = g, g
        _GROUPS[key] = (of_state, of_input) if len(states) >= 2 else None
    return _GROUPS[key]


def _column_map(prob, lp, of_state: np.ndarray, of_input: np.ndarray) -> np.ndarray | None:
    """The full column that stands for each full column, shape ``(n_x,)``: an input column
    ``u_k(l)[d]`` of group ``g`` is that of the first vertex with the same group-``g`` part of ``(v_k, z_k)``
    (the LP's own terms, :func:`~tubejax.lp.declarations.tube_families.float_terms`; the same float64 bits);
    every other column itself. ``None`` where two such columns' bounds differ. The map is kept per
    ``(v_k, z_k)`` (their bytes), groups and layout (:data:`KEPT_COLUMN_MAPS`; read-only)."""
    d = float_terms(prob)
    ix = lp.index
    V, Zv = np.asarray(d.V, float), np.asarray(d.Zv, float)
    key = (V.shape, Zv.shape, V.tobytes(), Zv.tobytes(), of_state.tobytes(), of_input.tobytes(), tuple(ix))
    rep = _COLUMN_MAPS.get(key)
    if rep is None:
        first = np.empty((ix.n_v, ix.m), np.int64)          # the standing vertex of each (vertex, input)
        for g in range(int(of_input.max()) + 1):
            part = np.ascontiguousarray(np.concatenate([V, Zv], axis=1)[:, np.tile(of_state == g, 2)])
            _, at, inv = np.unique(part.view(np.dtype((np.void, part.shape[1] * 8))).ravel(),   # bit for bit
                                   return_index=True, return_inverse=True)
            first[:, of_input == g] = at[np.ravel(inv)][:, None]
        u = np.arange(ix.u.start, ix.u.stop).reshape(ix.L, ix.n_v, ix.m)
        rep = np.arange(ix.size)
        rep[ix.u] = u[:, first, np.arange(ix.m)].ravel()
        rep.setflags(write=False)
        rep = _kept(_COLUMN_MAPS, key, rep, KEPT_COLUMN_MAPS)
    if not (np.array_equal(lp.lb[rep], lp.lb) and np.array_equal(lp.ub[rep], lp.ub)):
        return None
    return rep


def _one_group_facets(prob, of_state: np.ndarray) -> bool:
    """Whether every facet normal of ``Z`` is zero outside one group (kept per normals and groups)."""
    H = np.asarray(prob.Z.H, float)
    key = (H.shape, H.tobytes(), of_state.tobytes())
    hit = _ONE_GROUP.get(key)
    if hit is None:
        touched = np.stack([np.any(H[:, of_state == g] != 0, axis=1) for g in range(int(of_state.max()) + 1)])
        hit = _kept(_ONE_GROUP, key, bool(np.all(touched.sum(axis=0) <= 1)), KEPT_COLUMN_MAPS)
    return hit


def _reduced_columns(M, col: np.ndarray, n_red: int):
    """``M E``: the CSR matrix ``M (R, n_x)`` with its columns summed into ``col (n_x,)``, shape ``(R, n_red)``,
    its explicit zeros dropped and its columns sorted in each row."""
    keep = M.data != 0
    kept = np.concatenate([[0], np.cumsum(keep)])[M.indptr]
    out = sp.csr_matrix((np.asarray(M.data, float)[keep], col[np.asarray(M.indices)[keep]], kept),
                        shape=(M.shape[0], n_red))
    out.sum_duplicates()
    out.eliminate_zeros()
    return out


def _duplicate_rows(M) -> np.ndarray:
    """For each row of the CSR matrix ``M`` the first row with exactly the same nonzeros (columns and
    values, bit for bit), shape ``(R,)``."""
    nnz = np.diff(M.indptr)
    width = int(nnz.max()) if nnz.size else 0
    rows = np.repeat(np.arange(M.shape[0]), nnz)
    slot = np.arange(M.nnz) - np.repeat(M.indptr[:-1], nnz)
    key = np.full((M.shape[0], 1 + 2 * width), -1, np.int64)
    key[:, 0] = nnz
    key[rows, 1 + slot] = M.indices
    key[rows, 1 + width + slot] = np.asarray(M.data, float).view(np.int64)
    _, at, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    return at[np.ravel(inv)]


def _selection(prob, lp, rep: np.ndarray, col: np.ndarray, n_red: int) -> tuple:
    """The reduced matrix's rows before ``g``: ``M E`` restricted to the kept rows (frozen CSR), the row each
    full row equals (``(n_rows,)``, a full row index) and the kept full rows, kept per rows key and column
    map. The dynamics rows' part (their duplicates and their kept rows of ``M E``) is kept per column map
    and the dynamics rows themselves (:func:`_dynamics_part`: the same for every pair of a grid); the other
    rows are mapped again, row by row as ``M E`` maps them (:func:`_other_rows`), so the matrix is
    ``(M E)[kept]``'s, array for array."""
    key = (rows_key(prob), rep.tobytes())
    hit = _SELECTIONS.get(key)
    if hit is None:
        G = lp.G_csr
        dyn = lp.layout.slice(DYNAMICS)
        first, Md = _dynamics_part(G, dyn, col, n_red)
        same = np.arange(G.shape[0])
        same[dyn] = dyn.start + first
        kept = np.flatnonzero(same == np.arange(G.shape[0]))
        parts = [_other_rows(G, 0, dyn.start, col, n_red), _arrays(Md), _other_rows(G, dyn.stop, G.shape[0], col, n_red)]
        hit = _kept(_SELECTIONS, key, (freeze_csr(_stacked_rows(parts, n_red)), same, kept))
    return hit


def _arrays(M) -> tuple:
    """``(data, indices, nonzeros per row)`` of the CSR matrix ``M``."""
    return np.asarray(M.data, float), np.asarray(M.indices), np.diff(M.indptr)


def _other_rows(G, start: int, stop: int, col: np.ndarray, n_red: int) -> tuple:
    """Rows ``start:stop`` of ``G E`` (:func:`_reduced_columns`) as :func:`_arrays`: where each row's columns
    are strictly increasing and none of them is merged (``col`` is the identity on them), the rows with
    their explicit zeros dropped (what :func:`_reduced_columns` makes of them: nothing to sum or sort), else
    :func:`_reduced_columns` itself."""
    a, b = int(G.indptr[start]), int(G.indptr[stop])
    if b == a:                                                  # no entries (the rows after the dynamics rows)
        return np.zeros(0), np.zeros(0, np.asarray(G.indices).dtype), np.zeros(stop - start, np.int64)
    data, idx = np.asarray(G.data[a:b], float), np.asarray(G.indices[a:b], np.int64)
    ptr = np.asarray(G.indptr[start:stop + 1], np.int64) - a
    step = np.diff(idx)
    inner = np.ones(step.size, bool)
    inner[ptr[1:-1][(ptr[1:-1] > 0) & (ptr[1:-1] < idx.size)] - 1] = False          # steps across rows
    if np.all(step[inner] > 0) and np.array_equal(col[idx], idx):
        keep = data != 0
        return data[keep], idx[keep], np.diff(np.concatenate([[0], np.cumsum(keep)])[ptr])
    return _arrays(_reduced_columns(G[start:stop], col, n_red))


def _dynamics_part(G, dyn: slice, col: np.ndarray, n_red: int) -> tuple:
    """For the dynamics rows ``G[dyn]`` (CSR): the first row of ``(G E)[dyn]`` that each equals (an index into
    ``dyn``, :func:`_duplicate_rows`) and the first occurrences' rows of ``G E`` (CSR), kept per column map and
    those rows' own arrays (bit for bit)."""
    a, b = int(G.indptr[dyn.start]), int(G.indptr[dyn.stop])
    key = (n_red, col.tobytes(), dyn.stop - dyn.start, (G.indptr[dyn.start:dyn.stop + 1] - a).tobytes(),
           np.asarray(G.indices[a:b]).tobytes(), np.asarray(G.data[a:b]).tobytes())
    hit = _DYNAMICS.get(key)
    if hit is None:
        ME = _reduced_columns(G[dyn], col, n_red)
        first = _duplicate_rows(ME)
        hit = _kept(_DYNAMICS, key, (first, ME[np.flatnonzero(first == np.arange(ME.shape[0]))]))
    return hit


def _stacked_rows(parts: list, n_cols: int):
    """The rows ``parts`` (:func:`_arrays`, sorted columns in each row), one above the other, as a CSR
    matrix of shape ``(sum R, n_cols)``."""
    nnz = np.concatenate([p[2] for p in parts])
    out = sp.csr_matrix((np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]),
                         np.concatenate([[0], np.cumsum(nnz)])), shape=(nnz.size, n_cols))
    out.has_sorted_indices = True
    return out


def _kept(cache: dict, key, value, limit: int = 0):
    """``cache[key] = value``, the oldest entries dropped beyond ``limit`` (default :data:`KEPT_SELECTIONS`)."""
    while len(cache) >= (limit or KEPT_SELECTIONS):
        cache.pop(next(iter(cache)))
    cache[key] = value
    return value


def group_vertex_lp(prob, lp) -> GroupVertexLP | None:
    """The LP of :class:`GroupVertexLP` for ``prob``'s full margin LP ``lp``, or ``None`` where it is not
    made: a problem demanding a margin, a ``U`` that is not a box, hard rows or a radius column, one
    block of ``A, B``, a facet of ``Z`` over two groups, merged columns with other bounds, or duplicate
    rows whose right-hand sides differ (all checked on the data, exactly)."""
    if (float(prob.min_margin) != 0.0 or not prob.system.u_is_box or lp.G_hard.shape[0] != 0
            or getattr(lp, "t_coef", None) is not None or lp.layout is None or DYNAMICS not in lp.layout.names
            or lp.G_csr is None):
        return None
    groups = _groups(prob.system)
    if groups is None or not _one_group_facets(prob, groups[0]):
        return None
    rep = _column_map(prob, lp, *groups)
    if rep is None:
        return None
    stand, col = np.unique(rep, return_inverse=True)
    col = np.ravel(col)
    M, same, kept = _selection(prob, lp, rep, col, stand.size)
    if not np.array_equal(lp.g[same], lp.g):                    # duplicates by their rows alone: rhs too
        return None
    row = np.searchsorted(kept, same)
    red = lp._replace(G=M, g=lp.g[kept], row_kind=lp.row_kind[kept], G_hard=np.zeros((0, stand.size)),
                      g_hard=np.zeros(0), lb=lp.lb[stand], ub=lp.ub[stand], index=None, layout=None, G_csr=M)
    return GroupVertexLP(red, col, row, np.bincount(row, minlength=kept.size).astype(float))


def expanded_result(red: GroupVertexLP, res: HighsResult, lp) -> HighsResult:
    """HiGHS's answer ``res`` for ``red.lp`` as an answer for the full LP ``lp``: ``x = x'[col]`` clipped into
    ``lp``'s bounds (a proposal: the verdict checks it), ``y = y'[row] / count[row]`` (so ``G^T y`` is
    ``G'^T y'`` on ``p``, ``eps`` and each merged column's value split evenly over its columns), no basis."""
    if res.status != "Optimal":
        return HighsResult(res.status, float("nan"), np.full(lp.G.shape[1], np.nan), np.full(lp.G.shape[0], np.nan),
                           res.seconds)
    x = np.clip(res.x[red.col], lp.lb, lp.ub)
    y = res.y[red.row] / red.count[red.row]
    return HighsResult("Optimal", res.margin, x, y, res.seconds, None, None, np.zeros(0))


def full_solve(prob, lp) -> HighsResult:
    """HiGHS on the full LP, as :func:`~tubejax.lp.evidence.verdict.confirm_with_highs` solves it."""
    return solve_margin_lp(lp, basis_min_margin=-CLEAR_MARGIN)


def solve_by_group_vertices(prob, lp) -> HighsResult:
    """HiGHS's answer for ``prob``'s full LP ``lp``, from its group-vertex LP where that answer is clear
    (module docstring), else :func:`full_solve`.

    Clear: an optimum above ``CLEAR_MARGIN`` whose mapped point keeps a margin above ``CLEAR_MARGIN`` on
    ``lp``'s own rows and whose mapped duals bound ``lp``'s margin within :data:`OPTIMALITY_GAP` of it (so
    it is ``lp``'s optimum to that gap), or one below ``-CLEAR_MARGIN`` whose mapped duals give ``lp``'s weak-duality bound
    (:func:`~tubejax.lp.evidence.decide.float_dual_bound`) below ``-MARGIN_SAFETY`` (both bounds compared as the
    dense rows compare them, :func:`~tubejax.lp.evidence.decide.float_dual_bound_at_most`). The verdict code then
    checks, proves or refutes it on ``lp`` as it does HiGHS's own answer, and re-solves ``lp`` wherever it
    needs a basis.
    """
    return group_vertex_answer(prob, lp)[0]


def group_vertex_answer(prob, lp) -> tuple[HighsResult, bool]:
    """:func:`solve_by_group_vertices`' answer, and whether it is known to refute ``lp``: ``True`` for a mapped
    answer below ``-CLEAR_MARGIN`` (its float weak-duality bound on ``lp``,
    :func:`~tubejax.lp.evidence.decide.float_dual_bound`, is below ``-MARGIN_SAFETY`` as the dense rows compute
    it, checked here), ``False`` where that is not known (then a caller checks it itself)."""
    red = group_vertex_lp(prob, lp)
    if red is not None:
        res = expanded_result(red, solve_margin_lp(red.lp), lp)
        if res.status == "Optimal":
            if (res.margin > CLEAR_MARGIN and np.min(lp.g - lp.G_csr @ res.x) > CLEAR_MARGIN
                    and float_dual_bound_at_most(lp, res, res.margin + OPTIMALITY_GAP)):
                return res, False
            if res.margin < -CLEAR_MARGIN and float_dual_bound_at_most(lp, res, -MARGIN_SAFETY, strict=True):
                return res, True
    return full_solve(prob, lp), False
