"""The tube LP (Problem 2, docs/math/tube-lp.md) of a :class:`~tubejax.model.problem.TubeProblem`.

``x = (p (L, n), eps (L,), u (L, n_v, m))`` (:mod:`.tube_variables`); the margin form appends ``t``:
``max t  s.t.  G x + t 1 <= g``, ``G_hard x <= g_hard``, ``lb <= x <= ub``, ``t <= t_max``. Rows of
``G`` (C2-C4) are divided by their state-space normal's length, so ``t`` is a state-space distance
(docs/math/margins.md#state-space-distances); C1 and a box ``U`` are bounds. Problem 2 is feasible
iff ``t* >= 0``. The finite bounds on ``p``, ``eps`` (:func:`~.tube_variables.tube_variable_bounds`)
are implied by C2-C4 at ``t >= 0``, so they change no nonnegative margin.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp

from ...model.problem import TubeProblem
from .tube_families import TUBE_FAMILIES, TubeVars, VertexIn, float_terms, region_sets, tube_identity, tube_residuals
from .row_families import RowLayout, dense_rhs, dense_rows, families_in, sparse_rows, state_lengths
from .sparse_blocks import csr_dense, csr_nbytes, freeze_csr, scale_csr_rows
from .tube_variables import Tube, TubeIndex, check_bound_families, tube_index, tube_variable_bounds

__all__ = ["TubeLP", "build_tube_lp", "DenseOnDemand", "DenseNeeded", "with_dense_rows", "tube_violation", "tube_hard_rows", "row_kinds", "margin_rows", "margin_csr",
           "rows_key", "MARGIN_SCALINGS", "worst_residual", "ROW_C2", "ROW_C3", "ROW_C4"]

ROW_C2, ROW_C3, ROW_C4 = 2, 3, 4


class TubeLP(NamedTuple):
    """LP data of one tube problem (margin form; see the module docstring).

    Attributes
    ----------
    G : (n_rows, n_x), unit rows C2, C3, C4; g : (n_rows,)
    row_kind : (n_rows,) int8, ROW_C2 / ROW_C3 / ROW_C4
    G_hard : (n_hard, n_x), C5 rows of a non-box ``U`` (else 0 rows); g_hard : (n_hard,)
    lb, ub : (n_x,), variable bounds
    t_max, t_min : float, bounds on the margin (``t_min`` default ``-inf``)
    index : TubeIndex
    t_coef : (n_rows,) or None, ``t``'s column (``None``: all ones; the radius form sets it)
    layout : RowLayout or None, which rows each row family holds (rows are found by name)
    G_csr : scipy.sparse.csr_matrix (n_rows, n_x) or None, ``G`` itself in CSR form (columns sorted
        in each row), what HiGHS is given (:func:`~tubejax.lp.engines.highs.pass_margin_lp`);
        ``None``: derived from ``G`` there. Never set to another matrix than ``G``.

    An LP built with ``build_tube_lp(..., dense=False)`` holds in ``G`` a :class:`DenseOnDemand`
    (its ``shape`` only) until :func:`with_dense_rows` writes the dense rows.
    """

    G: np.ndarray
    g: np.ndarray
    row_kind: np.ndarray
    G_hard: np.ndarray
    g_hard: np.ndarray
    lb: np.ndarray
    ub: np.ndarray
    t_max: float
    index: TubeIndex
    t_coef: np.ndarray | None = None
    t_min: float = -np.inf
    layout: RowLayout | None = None
    G_csr: object = None


def build_tube_lp(prob: TubeProblem, t_max: float = 1.0, scaling: str = "state", dense: bool = True) -> TubeLP:
    """Assemble the margin-form LP of :class:`TubeProblem` (float64: ``G`` dense and, built first, its
    CSR form ``G_csr``) from its row families.

    Rows: those of :data:`~.tube_families.TUBE_FAMILIES` with the ``margin`` role (``safe``,
    ``target``, then ``dynamics``), each unit-normalised; ``lp.layout`` names them.
    ``dense=False``: ``G`` is a :class:`DenseOnDemand` stand-in, for a caller that reads ``G_csr`` and
    makes the dense rows (:func:`with_dense_rows`) only where it needs them.

    Returns
    -------
    TubeLP
        ``G`` has shape ``((L-1) f_S + f_j + L n_v f_z, (n + 1) L + L n_v m)``.
    """
    check_bound_families(prob.system)
    d = float_terms(prob)
    M, g, nrm, layout = margin_csr(prob, d, scaling)
    lb, ub = tube_variable_bounds(prob)
    G_hard, g_hard = tube_hard_rows(prob, d)
    return TubeLP(csr_dense(M) if dense else DenseOnDemand(M.shape), g / nrm, row_kinds(layout), G_hard, g_hard, lb,
                  ub, float(t_max), tube_index(prob), layout=layout, G_csr=M)


class DenseNeeded(BaseException):
    """Raised by a :class:`DenseOnDemand` read: the caller writes the dense rows (:func:`with_dense_rows`)
    and does again what it was doing. A ``BaseException``, so that no ``except Exception`` on the way can
    take it for a failure of its own."""


class DenseOnDemand:
    """The ``G`` of a :class:`TubeLP` whose dense rows are not written (``build_tube_lp(..., dense=False)``):
    it answers ``shape`` and ``ndim`` (and pickles); any other use raises :class:`DenseNeeded`.

    At ``L = 8`` a 6-D joint LP's dense ``G`` is a 6,450 x 1,592 array (80 MB, 0.35 % nonzero); writing it
    took about half of the time of a joint edge whose verdict never reads it (its HiGHS model and exact proof
    read ``G_csr`` and the problem's own data)."""

    __slots__ = ("shape",)
    ndim = 2

    def __init__(self, shape):
        self.shape = tuple(shape)

    def __getattr__(self, name):
        if name.startswith("__"):                   # protocols probed (pickle, copy, numpy's interfaces): absent
            raise AttributeError(name)
        raise DenseNeeded(name)

    def _needed(self, *args, **kw):
        raise DenseNeeded("the dense rows")

    __array__ = __matmul__ = __rmatmul__ = __getitem__ = __iter__ = __len__ = _needed


def with_dense_rows(lp: TubeLP) -> TubeLP:
    """``lp`` with the dense rows ``G`` written from ``G_csr`` (the same array :func:`build_tube_lp` writes);
    ``lp`` itself where they are."""
    return lp._replace(G=csr_dense(lp.G_csr)) if isinstance(lp.G, DenseOnDemand) else lp


def margin_rows(prob: TubeProblem, d=None, scaling: str = "state", rhs: bool = True) -> tuple:
    """The rows of the margin form, scaled: ``G (n_rows, n_x)`` (read-only, shared by problems with the
    same rows), the unscaled ``g (n_rows,)`` (``None`` with ``rhs=False``), the scales ``(n_rows,)`` and
    the :class:`~.row_families.RowLayout`. ``scaling`` is one of :data:`MARGIN_SCALINGS`; ``G`` is
    :func:`margin_csr`'s matrix made dense, memoised per :func:`rows_key` and scaling."""
    d = float_terms(prob) if d is None else d
    key = rows_key(prob) + (scaling,)
    hit = _ROWS_CACHE.get(key)
    if hit is None:
        M, _, nrm, layout = margin_csr(prob, d, scaling, rhs=False)     # raises for an unknown scaling
        G = csr_dense(M)
        G.setflags(write=False)
        hit = _cache_put(_ROWS_CACHE, key, (G, nrm, layout))
    G, nrm, layout = hit
    return G, dense_rhs(d, "margin", prob.system.u_is_box, TUBE_FAMILIES) if rhs else None, nrm, layout


def margin_csr(prob: TubeProblem, d=None, scaling: str = "state", rhs: bool = True) -> tuple:
    """:func:`margin_rows` with ``G`` a CSR matrix ``(n_rows, n_x)`` (read-only, shared), assembled
    from each family's scaled rows (:func:`_family_rows`), memoised per :func:`rows_key` and scaling."""
    if scaling not in MARGIN_SCALINGS:
        raise ValueError(f"scaling must be one of {MARGIN_SCALINGS}, got {scaling!r}")
    d = float_terms(prob) if d is None else d
    key = rows_key(prob) + (scaling,)
    hit = _CSR_CACHE.get(key)
    if hit is None:
        fams = [f for f in families_in(TUBE_FAMILIES, d) if f.lp_role(d, prob.system.u_is_box) == "margin"]
        blocks = [_family_rows(prob, d, f, scaling) for f in fams]
        M = sp.vstack([b[0] for b in blocks], format="csr") if blocks else sp.csr_matrix((0, tube_index(prob).size))
        M.has_sorted_indices = True
        nrm = np.concatenate([b[1] for b in blocks]) if blocks else np.zeros(0)
        hit = _cache_put(_CSR_CACHE, key, (freeze_csr(M), nrm,
                                           RowLayout(tuple(f.name for f in fams), tuple(b[2] for b in blocks))))
    M, nrm, layout = hit
    return M, dense_rhs(d, "margin", prob.system.u_is_box, TUBE_FAMILIES) if rhs else None, nrm, layout


def _family_rows(prob: TubeProblem, d, family, scaling: str) -> tuple:
    """One family's scaled margin rows ``(G (R, n_x) CSR, scales (R,), grid)``, memoised by
    :func:`rows_key` without the normals plus, for a family over a set, that set's normals: so the
    dynamics rows, the bulk of the LP, are derived once for every pair of a grid."""
    region = getattr(family, "region", None)
    normals = ()
    if region is not None:
        P = region_sets(prob)[region]
        normals = (P.H.shape, np.ascontiguousarray(P.H, dtype=float).tobytes())
    key = (family.name, scaling, normals) + rows_key(prob, normals=False)
    hit = _FAMILY_CACHE.get(key)
    if hit is None and _tiles_steps(prob, d, family, scaling):
        base = _family_rows(dataclasses.replace(prob, L=TILE_HORIZON), d._replace(L=TILE_HORIZON), family, scaling)
        hit = _tiled(base, tube_index(prob))
        if hit is not None:
            hit = _cache_put(_FAMILY_CACHE, key, hit)
    if hit is None:
        u_is_box = prob.system.u_is_box
        M, _, layout = sparse_rows(d, prob.system.m, "margin", u_is_box, (family,), tube_identity)
        if scaling == "state":
            nrm = state_lengths(d, "margin", u_is_box, lambda H: np.linalg.norm(H, axis=1), (family,))
        else:
            nrm = np.linalg.norm(csr_dense(M), axis=1)          # the dense rows' norms, bit for bit
        hit = _cache_put(_FAMILY_CACHE, key, (freeze_csr(scale_csr_rows(M, nrm)), nrm, layout.shapes[0]))
    return hit


#: The horizon whose one interior step's rows :func:`_tiled` repeats (``l = 1`` of ``L = 2``).
TILE_HORIZON = 2


def _tiles_steps(prob: TubeProblem, d, family, scaling: str) -> bool:
    """Whether ``family``'s rows at ``prob.L`` are :func:`_tiled` from those at :data:`TILE_HORIZON`: a
    compressed :class:`~.tube_families.VertexIn` over the interior steps, scaled by ``'state'``, beyond that
    horizon, whose ``lhs`` at the zero tube has no ``-0.0`` (``d``: ``prob``'s float terms).

    Why the rows are then the same, entry for entry, as :func:`_family_rows` derives them at ``prob.L``
    (docs/explanation/performance.md#sparse-margin-rows): ``lhs`` reads, for the rows of step ``l``, only
    ``p_l`` and ``eps_l``, and every vector it is evaluated on holds there zeros, a unit vector of ``p_l`` or
    ``eps_l = 1``, the same operands (in the same shapes) at every horizon: the zeros give the zero tube's
    ``+0.0`` (no entry), the others the entries of step ``l = 1`` at :data:`TILE_HORIZON`."""
    if scaling != "state" or int(prob.L) <= TILE_HORIZON or not isinstance(family, VertexIn):
        return False
    if family.steps != "interior" or not family.compress_vertices:
        return False
    (nv, n), m = d.Zv.shape, prob.system.m
    zero = TubeVars(np.zeros((1, TILE_HORIZON, n)), np.zeros((1, TILE_HORIZON)), np.zeros((1, TILE_HORIZON, nv, m)))
    return not np.any(np.signbit(family.lhs(d._replace(L=TILE_HORIZON), zero)))


def _tiled(base: tuple, ix: TubeIndex) -> tuple | None:
    """The rows ``(G (R, n_x) CSR, scales (R,), grid)`` of an interior-step family at ``ix.L`` from ``base``,
    its rows at :data:`TILE_HORIZON` (one step: columns ``p_1`` and ``eps_1``): step ``l``'s rows are
    ``base``'s with ``p_1[d]`` moved to ``p_l[d]`` and ``eps_1`` to ``eps_l``; ``None`` where ``base`` has
    an entry in another column (then the rows are derived as before)."""
    M, nrm, grid = base
    n, S = ix.n, ix.L - 1
    cols = np.asarray(M.indices, np.int64)
    on_p, on_eps = cols < n, cols == TILE_HORIZON * n
    if not np.all(on_p | on_eps):
        return None
    steps = np.arange(S)[:, None]
    idx = np.where(on_p, cols + n * steps, ix.L * n + steps).ravel()
    nnz = np.diff(M.indptr)
    indptr = np.concatenate([[0], np.cumsum(np.tile(nnz, S))])
    out = sp.csr_matrix((np.tile(M.data, S), idx.astype(M.indices.dtype), indptr.astype(M.indptr.dtype)),
                        shape=(S * M.shape[0], ix.size))
    out.has_sorted_indices = True
    return freeze_csr(out), np.tile(nrm, S), (S,) + tuple(grid[1:])


def _cache_put(cache: dict, key, value: tuple):
    """``cache[key] = value`` (its first item a dense or CSR matrix), dropping the oldest other entries while
    the cache holds more than its budget (:data:`LP_ROWS_CACHE_BYTES`, :data:`ROWS_CACHE_BYTES`)."""
    used = _CACHE_USED[id(cache)]
    budget = ROWS_CACHE_BYTES if cache is _FAMILY_CACHE else LP_ROWS_CACHE_BYTES
    cache[key] = value
    used[0] += csr_nbytes(value[0])
    while used[0] > budget and len(cache) > 1:
        try:                                      # HiGHS worker threads may evict the same entry
            used[0] -= csr_nbytes(cache.pop(next(iter(cache)))[0])
        except (KeyError, StopIteration, RuntimeError):
            break
    return value


#: How margin rows are scaled: ``'state'`` (by the state-space normal: transition files of format
#: 3 on) and ``'coefficients'`` (by the coefficients over the LP variables: formats 1 and 2).
MARGIN_SCALINGS = ("state", "coefficients")


_ROWS_CACHE: dict = {}                  # whole LPs, dense (margin_rows)
_CSR_CACHE: dict = {}                   # whole LPs, CSR (margin_csr)
_FAMILY_CACHE: dict = {}                # single families, CSR (_family_rows)
_CACHE_USED = {id(_ROWS_CACHE): [0], id(_CSR_CACHE): [0], id(_FAMILY_CACHE): [0]}      # bytes held, per cache
#: Bytes the memoised rows of single families (:func:`_family_rows`) may hold: sized so that a grid
#: whose cells are not exact translates keeps its family rows over the streamed rounds instead of
#: deriving them again on every pass (docs/explanation/performance.md#memoised-lp-rows).
ROWS_CACHE_BYTES = 224 << 20
#: Bytes the memoised whole LPs of :func:`margin_rows` may hold, and so may those of :func:`margin_csr`
#: (their families assemble them again).
LP_ROWS_CACHE_BYTES = 32 << 20


def rows_key(prob: TubeProblem, normals: bool = True) -> tuple:
    """Everything the margin rows' coefficients depend on: ``L``, ``A``, ``B``, ``Z``, the source's
    vertex count and (``normals``) the facet normals of every set a family reads
    (:func:`~.tube_families.region_sets`), not where the sets lie."""
    s = prob.system
    core = (int(prob.L), prob.source.n_vertices, s.A.shape, s.B.shape, s.A.tobytes(), s.B.tobytes(),
            prob.Z.vertices.shape, prob.Z.vertices.tobytes(), prob.Z.H.shape, prob.Z.H.tobytes(), prob.Z.h.tobytes())
    if not normals:
        return core
    return core + (tuple((name, P.H.shape, np.ascontiguousarray(P.H, dtype=float).tobytes())
                         for name, P in sorted(region_sets(prob).items())),)


#: The row kinds of the families of the margin LP (``TubeLP.row_kind``).
FAMILY_KINDS = {"safe": ROW_C2, "target": ROW_C3, "dynamics": ROW_C4}


def row_kinds(layout) -> np.ndarray:
    """``TubeLP.row_kind`` of a row layout, shape ``(n_rows,)``."""
    return np.concatenate([np.full(int(np.prod(sh)), FAMILY_KINDS.get(nm, 0), np.int8)
                           for nm, sh in zip(layout.names, layout.shapes)] or [np.zeros(0, np.int8)])


def tube_hard_rows(prob: TubeProblem, d=None) -> tuple:
    """``G_hard (n_hard, n_x)``, ``g_hard (n_hard,)``: the rows of every family with the ``hard``
    role (C5 for a non-box ``U``; none for a box, whose C5 are variable bounds)."""
    sysm = prob.system
    G, g, _ = dense_rows(float_terms(prob) if d is None else d, sysm.m, "hard", sysm.u_is_box, TUBE_FAMILIES,
                         tube_identity)
    return G, g


def tube_violation(prob: TubeProblem, tube: Tube) -> float:
    """Largest violation of C1-C5 by ``tube``, recomputed from the geometry in float64: every family
    of :data:`~.tube_families.TUBE_FAMILIES` vertex by vertex, each row per unit of its state-space
    normal; ``inf`` for wrong shapes or non-finite values. A value ``<= 1e-9`` confirms the tube."""
    sysm = prob.system
    L, n, nv, m = int(prob.L), sysm.n, prob.source.n_vertices, sysm.m
    p, eps, u = (np.asarray(a, float) for a in tube)
    if p.shape != (L, n) or eps.shape != (L,) or u.shape != (L, nv, m):
        return float("inf")
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(eps)) and np.all(np.isfinite(u))):
        return float("inf")
    return float(max(0.0, worst_residual(tube_residuals(float_terms(prob), TubeVars(p, eps, u)))))


def worst_residual(residuals, batch: tuple = ()) -> np.ndarray:
    """The largest ``residual / scale`` of :func:`~.tube_families.tube_residuals` in float64, shape ``batch``."""
    if not batch:
        return np.float64(max((float(np.max(r / sc)) for _, r, sc in residuals if np.size(r)), default=-np.inf))
    worst = np.full(batch, -np.inf)
    for _, r, sc in residuals:
        r = np.broadcast_to(r, batch + np.shape(r)[len(batch):])
        if r.size:
            worst = np.maximum(worst, np.max((r / sc).reshape(batch + (-1,)), axis=-1))
    return worst
