"""HiGHS (highspy) solves of the margin-form LP, one at a time.

This is the exact reference path: every verdict of the batched solver is held
against it, and every edge is confirmed by it (docs/math/evidence.md).
"""

from __future__ import annotations

import os
import sys
import threading
import time
from typing import NamedTuple

import highspy
import numpy as np

from ..declarations.tube_lp import TubeLP

__all__ = ["HighsResult", "solve_margin_lp", "solve_margin_lp_from", "pass_margin_lp", "margin_matrix", "new_highs",
           "HIGHS_OPTIONS",
           "BASIS_LOWER",
           "BASIS_BASIC", "BASIS_UPPER", "BASIS_ZERO", "BASIS_NONBASIC"]

#: HiGHS basis statuses (``highspy.HighsBasisStatus`` values) as stored in :class:`HighsResult`.
BASIS_LOWER, BASIS_BASIC, BASIS_UPPER, BASIS_ZERO, BASIS_NONBASIC = (
    int(highspy.HighsBasisStatus.kLower.value), int(highspy.HighsBasisStatus.kBasic.value),
    int(highspy.HighsBasisStatus.kUpper.value), int(highspy.HighsBasisStatus.kZero.value),
    int(highspy.HighsBasisStatus.kNonbasic.value))

#: Tight tolerances: the stored tube is re-checked at 1e-9, so HiGHS must be exact well below that.
HIGHS_OPTIONS = {
    "output_flag": False,
    "primal_feasibility_tolerance": 1e-10,
    "dual_feasibility_tolerance": 1e-10,
    "solver": "simplex",
    "presolve": "off",          # same optima, faster (docs/explanation/performance.md#highs-options)
    "random_seed": 0,
    "threads": 1,
}


class HighsResult(NamedTuple):
    """Outcome of one margin-form solve.

    Attributes
    ----------
    status : str        HiGHS model status (``'Optimal'`` when solved)
    margin : float      ``t*`` (``nan`` unless optimal)
    x : ndarray, shape (n_x,)         the tube variables (without ``t``)
    y : ndarray, shape (n_rows,)      duals of the margin rows ``G x + t <= g`` (>= 0)
    seconds : float
    col_status : ndarray of int8, shape (n_x + 1,), or None
        HiGHS's optimal basis, columns ``x`` then ``t`` (``BASIS_*`` values), when asked for.
    row_status : ndarray of int8, shape (n_rows + n_hard,), or None
        The same for the rows ``G`` then ``G_hard``.
    y_hard : ndarray, shape (n_hard,), or None
        Duals of the hard rows ``G_hard x <= g_hard`` (>= 0).
    """

    status: str
    margin: float
    x: np.ndarray
    y: np.ndarray
    seconds: float
    col_status: np.ndarray | None = None
    row_status: np.ndarray | None = None
    y_hard: np.ndarray | None = None


_ROWWISE = int(highspy.MatrixFormat.kRowwise.value)
_MINIMIZE = int(highspy.ObjSense.kMinimize.value)

_local = threading.local()
_banner_lock = threading.Lock()
_banner_done = False


def new_highs(options: dict | None = None) -> highspy.Highs:
    """A silent ``Highs`` object with :data:`HIGHS_OPTIONS` (and ``options``) set.

    Some highspy releases (1.16) print a banner on stdout from C++ when the first
    ``Highs`` object of a process is created, before any option can be set. That
    first construction runs with file descriptor 1 pointed at ``/dev/null``, so
    HiGHS prints nothing unless asked (``output_flag=True`` in ``options``).
    """
    global _banner_done
    with _banner_lock:
        if _banner_done:
            h = highspy.Highs()
        else:
            sys.stdout.flush()
            saved = os.dup(1)
            try:
                with open(os.devnull, "wb") as null:
                    os.dup2(null.fileno(), 1)
                    h = highspy.Highs()
            finally:
                os.dup2(saved, 1)
                os.close(saved)
            _banner_done = True
    for k, v in {**HIGHS_OPTIONS, **(options or {})}.items():
        h.setOptionValue(k, v)
    return h


def _highs(options: dict | None) -> highspy.Highs:
    """A ``Highs`` instance for this thread with :data:`HIGHS_OPTIONS` (``clearSolver`` before
    each use, so a solve never depends on the previous one); fresh when ``options`` are given."""
    if options:
        return new_highs(options)
    h = getattr(_local, "highs", None)
    if h is None:
        h = _local.highs = new_highs()
    return h


def pass_margin_lp(h: highspy.Highs, lp: TubeLP) -> None:
    """Pass ``lp``'s margin form (``max t``, as :func:`solve_margin_lp` solves it) to ``h``:
    columns ``x`` then ``t``, rows ``[G c; G_hard 0]`` row-wise (:func:`margin_matrix`).

    Raises
    ------
    ValueError
        HiGHS refuses the model.
    """
    nr, nx = lp.G.shape
    nh = lp.G_hard.shape[0]
    start, index, value = margin_matrix(lp)
    inf = highspy.kHighsInf
    cost = np.zeros(nx + 1)
    cost[nx] = -1.0                                  # minimise -t
    # the array overload of passModel: no HighsLp object, whose setters copy field by field
    passed = h.passModel(nx + 1, nr + nh, value.size, _ROWWISE, _MINIMIZE, 0.0, cost,
                         np.append(lp.lb, max(getattr(lp, "t_min", -inf), -inf)), np.append(lp.ub, lp.t_max),
                         np.full(nr + nh, -inf), np.concatenate([lp.g, lp.g_hard]), start, index, value,
                         np.zeros(nx + 1, np.int32))   # all continuous
    if passed == highspy.HighsStatus.kError:
        raise ValueError(f"HiGHS refused the margin-form LP ({nr + nh} rows, {nx + 1} columns)")


def margin_matrix(lp: TubeLP) -> tuple:
    """The nonzeros of ``[G c; G_hard 0]`` row by row, columns ascending in each row (``c``:
    ``lp.t_coef``, or ones), as HiGHS takes a row-wise matrix: ``start (n_rows + n_hard + 1,)`` and
    ``index (nnz,)`` int32, ``value (nnz,)``. ``G``'s come from ``lp.G_csr`` where the LP carries
    it (never from a dense ``G`` then), else from ``lp.G``; both give the same arrays. The last
    ``[G 1]`` of a read-only ``G_csr`` is kept per thread (translates share theirs; HiGHS copies
    what it gets)."""
    nr, nx = lp.G.shape
    M = getattr(lp, "G_csr", None)
    t_coef = getattr(lp, "t_coef", None)
    c = np.ones(nr) if t_coef is None else np.broadcast_to(np.asarray(t_coef, float), (nr,))
    if M is None or M.shape != (nr, nx):
        s1, i1, v1 = _with_column(*_dense_rows(lp.G), nx, c)
    elif t_coef is None and not M.data.flags.writeable:          # a frozen, shared G_csr
        hit = getattr(_local, "rows", None)
        if hit is None or hit[0] is not M:
            hit = _local.rows = (M, _with_column(*_csr_rows(M.indptr, M.indices, M.data), nx, c))
        s1, i1, v1 = hit[1]
    else:
        s1, i1, v1 = _with_column(*_csr_rows(M.indptr, M.indices, M.data), nx, c)
    if lp.G_hard.shape[0] == 0:
        return s1, i1, v1
    s2, i2, v2 = _dense_rows(lp.G_hard)
    return (np.concatenate([s1, s2[1:] + s1[-1]]).astype(np.int32), np.concatenate([i1, i2]).astype(np.int32),
            np.concatenate([v1, v2]))


def _csr_rows(indptr, indices, data) -> tuple:
    """``(start, index, value)`` of a CSR matrix's nonzeros (its explicit zeros dropped)."""
    keep = data != 0
    if keep.all():
        return np.asarray(indptr), np.asarray(indices), np.asarray(data, float)
    kept = np.concatenate([[0], np.cumsum(keep)])
    return kept[indptr], np.asarray(indices)[keep], np.asarray(data, float)[keep]


def _dense_rows(G: np.ndarray) -> tuple:
    """``(start, index, value)`` of a dense matrix's nonzeros, row by row."""
    flat = np.flatnonzero(G)
    nc = G.shape[1]
    return np.searchsorted(flat // max(nc, 1), np.arange(G.shape[0] + 1)), flat % max(nc, 1), G.ravel()[flat]


def _with_column(start, index, value, col: int, c: np.ndarray) -> tuple:
    """The rows ``(start, index, value)`` with one more entry ``c[r]`` in column ``col`` (after
    every other column) of each row ``r``, where ``c[r] != 0``."""
    extra = np.concatenate([[0], np.cumsum(c != 0)])
    s = (np.asarray(start) + extra).astype(np.int32)
    idx = np.empty(s[-1], np.int32)
    val = np.empty(s[-1])
    pos = np.arange(len(index)) + np.repeat(extra[:-1], np.diff(start))
    idx[pos], val[pos] = index, value
    last = s[1:][c != 0] - 1
    idx[last], val[last] = col, c[c != 0]
    for a in (s, idx, val):
        a.setflags(write=False)
    return s, idx, val


def _result(h: highspy.Highs, lp: TubeLP, t0: float, basis_min_margin: float | None,
            basis: tuple | None = None) -> HighsResult:
    """The :class:`HighsResult` of ``h`` after its run on ``lp``'s margin form (``basis``: the
    statuses to report instead of reading them, when the caller knows them)."""
    nr, nx = lp.G.shape
    status = h.modelStatusToString(h.getModelStatus())
    if h.getModelStatus() != highspy.HighsModelStatus.kOptimal:
        return HighsResult(status, float("nan"), np.full(nx, np.nan), np.full(nr, np.nan),
                           time.perf_counter() - t0)
    sol = h.getSolution()
    xt = np.asarray(sol.col_value)
    yall = -np.asarray(sol.row_dual)                 # HiGHS duals are <= 0 for <= rows when minimising
    y = yall[:nr]
    cs = rs = None
    if basis_min_margin is not None and xt[nx] >= basis_min_margin:
        if basis is not None:
            cs, rs = basis
        else:
            b = h.getBasis()
            if b.valid:
                cs = np.array([v.value for v in b.col_status], dtype=np.int8)
                rs = np.array([v.value for v in b.row_status], dtype=np.int8)
    return HighsResult(status, float(xt[nx]), xt[:nx], np.maximum(y, 0.0), time.perf_counter() - t0, cs, rs,
                       np.maximum(yall[nr:], 0.0))


def solve_margin_lp(lp: TubeLP, options: dict | None = None,
                    basis_min_margin: float | None = None) -> HighsResult:
    """``max t  s.t.  G x + c t <= g,  G_hard x <= g_hard,  lb <= x <= ub,  t_min <= t <= t_max``.

    ``c`` is ``lp.t_coef`` when the LP has one (the radius form), else all ones (the margin
    form); ``t_min`` is ``lp.t_min`` (default ``-inf``).

    The constraint matrix goes to HiGHS row-wise, its nonzeros taken from ``lp.G_csr`` where the
    LP carries it (:func:`margin_matrix`); one ``Highs`` object per thread is reused
    (its solver state cleared between models).

    Parameters
    ----------
    lp : TubeLP
    options : dict, optional
        HiGHS options overriding :data:`HIGHS_OPTIONS` (a fresh ``Highs`` object is used).
    basis_min_margin : float, optional
        Also return HiGHS's optimal basis (``col_status``, ``row_status``) when the
        optimal margin is at least this (``None``: never; ``-inf``: whenever optimal).

    Returns
    -------
    HighsResult
    """
    t0 = time.perf_counter()
    h = _highs(options)
    h.clearSolver()
    pass_margin_lp(h, lp)
    h.run()
    return _result(h, lp, t0, basis_min_margin)


def solve_margin_lp_from(lp: TubeLP, basis: tuple, basis_min_margin: float | None = None) -> HighsResult:
    """:func:`solve_margin_lp`, with HiGHS's simplex started from ``basis``.

    ``basis`` is ``(col_status, row_status)`` as :class:`HighsResult` reports them (of an LP with
    the same rows, e.g. an exact translate of ``lp``'s problem). The model is passed afresh and
    the basis set, so the answer depends on ``lp`` and ``basis`` only (never on an earlier
    solve). Where the basis is optimal for ``lp`` -- the translate of an optimal basis is --
    HiGHS only factorises it and checks it; else
    it iterates from there. Either way the answer is HiGHS's optimum of ``lp``.
    """
    t0 = time.perf_counter()
    h = _highs(None)
    h.clearSolver()
    pass_margin_lp(h, lp)
    cs, rs = basis
    hb = _highs_basis(cs, rs)
    if hb is None or h.setBasis(hb) == highspy.HighsStatus.kError:
        h.clearSolver()                              # a basis of another shape: start cold
        pass_margin_lp(h, lp)
        h.run()
        return _result(h, lp, t0, basis_min_margin)
    h.run()
    kept = (cs, rs) if h.getInfo().simplex_iteration_count == 0 else None
    return _result(h, lp, t0, basis_min_margin, kept)


_STATUSES = {int(v.value): v for v in (highspy.HighsBasisStatus.kLower, highspy.HighsBasisStatus.kBasic,
                                       highspy.HighsBasisStatus.kUpper, highspy.HighsBasisStatus.kZero,
                                       highspy.HighsBasisStatus.kNonbasic)}
_basis_cache = threading.local()


def _highs_basis(cs: np.ndarray, rs: np.ndarray):
    """A ``highspy.HighsBasis`` of the status arrays (the last one is kept: a group shares it)."""
    hit = getattr(_basis_cache, "hit", None)
    if hit is not None and hit[0] is cs and hit[1] is rs:
        return hit[2]
    try:
        b = highspy.HighsBasis()
        b.col_status = [_STATUSES[int(v)] for v in cs]
        b.row_status = [_STATUSES[int(v)] for v in rs]
        b.valid = True
    except (KeyError, TypeError):
        return None
    _basis_cache.hit = (cs, rs, b)
    return b
