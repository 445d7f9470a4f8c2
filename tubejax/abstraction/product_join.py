"""The join of the factor abstractions into the full transition system (docs/math/product.md#the-join).

A full pair ``(i, j)`` is an edge at the least ``L`` at which every group's factor LP
``(f_g(i), f_g(j), L, variant)`` is feasible, its margin the least of theirs; the variant is
``'box'`` when the interior of the bounding box of ``P_i u P_j`` meets no obstacle's interior
(:func:`box_obstacle_cases`, exact), ``'source'`` otherwise. Feasible horizons are the bits of a
``uint64`` (:attr:`FactorTable.mask`), so the join is a bitwise AND of gathered masks, over only
the pairs within reach, streamed in blocks of source cells that fit ``memory_mb``. ``'source'``
pairs whose hull ``co(P_i u P_j)`` is obstacle-free are listed for the joint LP with the paper's
safe set (:func:`tubejax.abstraction.product_abstraction.build_product_abstraction` solves them).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely

from ..model.geometry import Polytope, interiors_intersect
from ..model.product_structure import ProductStructure
from ..model.workspace.decomposition import CellDecomposition
from ..model.workspace.lookahead import position_view
from ..model.workspace.rectilinear import rectangles_of

__all__ = ["JoinedEdges", "BYTES_PER_CANDIDATE", "GRID_TABLE_MAX", "box_obstacle_cases", "hull_obstacle_cases",
           "join_factors", "join_weights", "shard_weights", "JOINT_PAIR_WEIGHT", "lowest_bit"]

#: Working memory of the join per candidate pair (bytes), for its block size.
BYTES_PER_CANDIDATE = 160
#: A pair left to the joint LP, in pairs the join enumerates: what one costs a shard, for balancing
#: shards (docs/explanation/performance.md, Shard weights of the product path).
JOINT_PAIR_WEIGHT = 10_000
#: Most entries of the summed-volume table of the bounding-box obstacle test (:class:`_GridObstacles`).
GRID_TABLE_MAX = 2 ** 24


@dataclass(frozen=True)
class JoinedEdges:
    """The edges of the join, one row per edge, and the pairs left to the joint LP.

    Attributes
    ----------
    src, dst, L : ndarray of int, shape (E,)
    margin : ndarray of float, shape (E,)    the least factor margin
    variant : ndarray of int, shape (E,)     0 ``'box'``, 1 ``'source'``
    joint_src, joint_dst : ndarray of int, shape (J,)
        Pairs whose bounding box meets an obstacle while ``co(P_i u P_j)`` does not (and that have a
        horizon worth a joint LP).
    joint_box_mask : ndarray of uint64, shape (J,)
        The horizons worth a joint LP: feasible in the ``'box'`` variant (the paper's LP at ``L`` is a
        restriction of it) and below the ``'source'`` variant's least ``L`` (which the pair has anyway).
    box_tested : ndarray of int, shape (N,)
        Per source cell, the pairs whose bounding box was tested against the obstacles (0 for cells not joined).
    """

    src: np.ndarray
    dst: np.ndarray
    L: np.ndarray
    margin: np.ndarray
    variant: np.ndarray
    joint_src: np.ndarray
    joint_dst: np.ndarray
    joint_box_mask: np.ndarray
    box_tested: np.ndarray

    @property
    def n_box_tested(self) -> int:
        """Pairs whose bounding box was tested against the obstacles."""
        return int(self.box_tested.sum())

    def of_sources(self, start: int, stop: int) -> "JoinedEdges":
        """What the join of the source cells ``[start, stop)`` gives: these rows, in their order."""
        e = (self.src >= start) & (self.src < stop)
        j = (self.joint_src >= start) & (self.joint_src < stop)
        tested = np.zeros_like(self.box_tested)
        tested[start:stop] = self.box_tested[start:stop]
        return JoinedEdges(self.src[e], self.dst[e], self.L[e], self.margin[e], self.variant[e], self.joint_src[j],
                           self.joint_dst[j], self.joint_box_mask[j], tested)


def lowest_bit(mask: np.ndarray) -> np.ndarray:
    """Index of the lowest set bit of each ``uint64`` (``-1`` for 0), shape like ``mask``."""
    mask = np.asarray(mask, dtype=np.uint64)
    low = mask & (~mask + np.uint64(1))
    out = np.full(mask.shape, -1, dtype=np.int64)
    nz = low != 0
    out[nz] = np.round(np.log2(low[nz].astype(np.float64))).astype(np.int64)   # powers of two: exact
    return out


class _BoxObstacles:
    """Box obstacles for the bounding-box test; other obstacles through the overlap LP."""

    def __init__(self, obstacles, dim: int):
        self.obstacles = tuple(obstacles)
        polys = [o for o in self.obstacles if isinstance(o, Polytope)]
        shapes = [o for o in self.obstacles if not isinstance(o, Polytope)]
        if any(o.dim != dim for o in polys) or (shapes and dim != 2):
            raise ValueError(f"the product path needs {dim}-D Polytope obstacles (or 2-D polygons)")
        lo = [o.bounding_box()[0] for o in polys]
        hi = [o.bounding_box()[1] for o in polys]
        self.is_box = [o.is_box for o in polys]
        self.union = None                    # 2-D polygons that are not unions of rectangles
        if shapes:
            union = shapely.union_all(shapes)
            rects = rectangles_of(union)
            if rects is None:
                self.union = union
                shapely.prepare(union)
            else:                            # rectilinear walls: rectangles with exact corners
                lo += list(rects[:, :2])
                hi += list(rects[:, 2:])
                self.is_box += [True] * len(rects)
                polys += [None] * len(rects)
        self.polys = polys
        self.lo = np.array(lo, dtype=float).reshape(-1, dim)
        self.hi = np.array(hi, dtype=float).reshape(-1, dim)
        self.is_box = np.array(self.is_box, dtype=bool)
        self.tree = (shapely.STRtree(shapely.box(self.lo[:, 0], self.lo[:, 1], self.hi[:, 0], self.hi[:, 1]))
                     if dim >= 2 and len(self.lo) else None)

    def cases(self, p_lo: np.ndarray, p_hi: np.ndarray) -> np.ndarray:
        """Whether the interior of each box ``[p_lo[k], p_hi[k]]`` meets an obstacle's, shape ``(K,)``."""
        K, dim = p_lo.shape
        out = np.zeros(K, dtype=bool)
        if K == 0:
            return out
        if self.union is not None:           # interiors meet in a 2-D set (DE-9IM), GEOS's robust predicates
            out |= shapely.relate_pattern(shapely.box(p_lo[:, 0], p_lo[:, 1], p_hi[:, 0], p_hi[:, 1]), self.union,
                                          "2********")
        if not len(self.lo):
            return out
        if self.tree is not None:
            qk, qo = self.tree.query(shapely.box(p_lo[:, 0], p_lo[:, 1], p_hi[:, 0], p_hi[:, 1]),
                                     predicate="intersects")
        else:
            qk, qo = (x.ravel() for x in np.meshgrid(np.arange(K), np.arange(len(self.lo)), indexing="ij"))
        # bounding boxes' interiors meet iff on every axis max(lo) < min(hi): exact float comparisons
        meet = np.all(np.maximum(p_lo[qk], self.lo[qo]) < np.minimum(p_hi[qk], self.hi[qo]), axis=1)
        out[qk[meet & self.is_box[qo]]] = True
        other = meet & ~self.is_box[qo]
        for k, o in zip(qk[other].tolist(), qo[other].tolist()):
            if not out[k] and interiors_intersect(Polytope.box(p_lo[k], p_hi[k]), self.polys[o]):
                out[k] = True
        return out


class _GridObstacles:
    """Box obstacles on the grid of their and the cells' coordinates: a summed-volume table.

    Axes on which every obstacle covers all cells (a lifted map's look-ahead axes) are dropped: there
    a pair's box meets every obstacle's interior iff it has positive width. On the other axes the
    coordinates of the obstacles and cells cut space into elementary boxes; the interior of a pair's
    box (with cell coordinates) meets an obstacle's iff it contains an elementary box covered by one,
    counted exactly (integers) by inclusion-exclusion over the table's corners.
    """

    def __init__(self, o_lo: np.ndarray, o_hi: np.ndarray, free: np.ndarray, coords: list):
        self.free = free
        self.axes = np.setdiff1d(np.arange(o_lo.shape[1]), free)
        self.coords = coords
        occupied = np.zeros([len(c) - 1 for c in coords], dtype=np.int64)
        for a, b in zip(o_lo[:, self.axes], o_hi[:, self.axes]):
            occupied[tuple(slice(np.searchsorted(c, x), np.searchsorted(c, y)) for c, x, y in zip(coords, a, b))] = 1
        table = np.pad(occupied, [(1, 0)] * occupied.ndim)
        for k in range(table.ndim):
            table = np.cumsum(table, axis=k)
        self.table = table

    @classmethod
    def build(cls, o_lo: np.ndarray, o_hi: np.ndarray, c_lo: np.ndarray, c_hi: np.ndarray):
        """The table of obstacles ``[o_lo, o_hi]`` ``(k, dim)`` for cells ``[c_lo, c_hi]`` ``(N, dim)``;
        ``None`` if it would have more than :data:`GRID_TABLE_MAX` entries."""
        covers = np.all((o_lo <= c_lo.min(axis=0)) & (o_hi >= c_hi.max(axis=0)), axis=0)      # (dim,)
        coords = [np.unique(np.concatenate([o_lo[:, k], o_hi[:, k], c_lo[:, k], c_hi[:, k]]))
                  for k in np.flatnonzero(~covers)]
        if np.prod([float(len(c)) for c in coords]) > GRID_TABLE_MAX:
            return None
        return cls(o_lo, o_hi, np.flatnonzero(covers), coords)

    def cases(self, p_lo: np.ndarray, p_hi: np.ndarray) -> np.ndarray:
        """Whether the interior of each box ``[p_lo[k], p_hi[k]]`` (cell coordinates) meets an obstacle's."""
        wide = np.all(p_lo[:, self.free] < p_hi[:, self.free], axis=1)
        lo = [np.searchsorted(c, p_lo[:, k]) for c, k in zip(self.coords, self.axes)]
        hi = [np.searchsorted(c, p_hi[:, k]) for c, k in zip(self.coords, self.axes)]
        total = np.zeros(len(p_lo), dtype=np.int64)
        for corner in np.ndindex(*(2,) * len(self.axes)):
            idx = tuple(h if c else l for c, l, h in zip(corner, lo, hi))
            sign = -1 if (len(corner) - sum(corner)) % 2 else 1
            total += sign * self.table[idx]
        return wide & (total > 0)


def _obstacle_index(decomp: CellDecomposition):
    """The cached bounding-box obstacle test of ``decomp``: a :class:`_GridObstacles` when every
    obstacle is a box and the table is small, else :class:`_BoxObstacles`."""
    index = decomp._cache.get("product_box_obstacles")
    if index is None:
        index = _BoxObstacles(decomp.obstacles, decomp.dim)
        lo, hi = decomp.cell_boxes()
        if len(index.lo) and index.union is None and bool(np.all(index.is_box)):
            index = _GridObstacles.build(index.lo, index.hi, lo, hi) or index
        decomp._cache["product_box_obstacles"] = index
    return index


def box_obstacle_cases(decomp: CellDecomposition, src, dst) -> np.ndarray:
    """Whether the interior of the bounding box of ``P_i u P_j`` meets ``int O``, shape ``(K,)``.

    Box obstacles are decided exactly: by a summed-volume table over the grid of the obstacles' and
    cells' coordinates (:class:`_GridObstacles`), or by comparisons of the boxes' coordinates
    (interiors meet iff ``max(lo) < min(hi)`` on every axis); other polytopes by
    :func:`~tubejax.model.geometry.interiors_intersect`.
    """
    src = np.asarray(src, dtype=int).reshape(-1)
    dst = np.asarray(dst, dtype=int).reshape(-1)
    lo, hi = decomp.cell_boxes()
    return _obstacle_index(decomp).cases(np.minimum(lo[src], lo[dst]), np.maximum(hi[src], hi[dst]))


def hull_obstacle_cases(decomp: CellDecomposition, src, dst) -> np.ndarray:
    """Whether ``int co(P_i u P_j)`` meets ``int O`` (:meth:`CellDecomposition.obstacle_cases`), shape ``(K,)``.

    On a lifted map (:func:`~tubejax.model.workspace.lookahead.position_view`) its obstacles are the
    map's times the whole look-ahead range, so the hull meets one iff its position projection, the
    hull of the two map cells, meets the map obstacle: tested once per distinct pair of map cells.
    """
    src = np.asarray(src, dtype=int).reshape(-1)
    dst = np.asarray(dst, dtype=int).reshape(-1)
    view = position_view(decomp)
    if view is None or not len(src):
        return decomp.obstacle_cases(src, dst)
    nb = np.int64(view.base.n_cells)
    keys, inv = np.unique(view.base_cell[src] * nb + view.base_cell[dst], return_inverse=True)
    return view.base.obstacle_cases(keys // nb, keys % nb)[inv.reshape(-1)]


class _Reach:
    """Per group, the factor cells reachable in the ``'box'`` variant (CSR of ``mask[0] != 0``), and
    the cells by their factor cells (sorted keys)."""

    def __init__(self, cf: np.ndarray, masks):
        self.box = [M[0] for M in masks]
        nz = [B != 0 for B in self.box]
        self.indptr = [np.concatenate([[0], np.cumsum(z.sum(axis=1))]).astype(np.int64) for z in nz]
        self.indices = [np.nonzero(z)[1].astype(np.int64) for z in nz]
        self.stride = np.cumprod([1] + [B.shape[0] for B in self.box][::-1])[-2::-1].astype(np.int64)  # C order
        key = cf @ self.stride
        self.order = np.argsort(key, kind="stable")
        self.keys = key[self.order]
        if np.any(self.keys[1:] == self.keys[:-1]):
            raise ValueError("two cells have the same factor cells in every group")
        self.count = np.ones(len(cf), dtype=np.int64)
        for g, ptr in enumerate(self.indptr):
            self.count *= (ptr[1:] - ptr[:-1])[cf[:, g]]

    def candidates(self, cf: np.ndarray, I: np.ndarray):
        """The pairs ``(i, j)``, ``i`` in ``I``, ``j != i``, nonzero ``'box'`` mask in every group:
        ``(ii, jj, box mask)`` sorted by ``(i, j)``."""
        c = self.count[I]
        rep = np.repeat(I, c)
        t = np.arange(len(rep), dtype=np.int64) - np.repeat(np.cumsum(c) - c, c)
        key = np.zeros(len(rep), dtype=np.int64)
        box = np.full(len(rep), ~np.uint64(0), dtype=np.uint64)
        for g in reversed(range(len(self.box))):
            a = cf[rep, g]
            n = self.indptr[g][a + 1] - self.indptr[g][a]
            b = self.indices[g][self.indptr[g][a] + t % n]
            t //= n
            key += b * self.stride[g]
            box &= self.box[g][a, b]
        pos = np.minimum(np.searchsorted(self.keys, key), len(self.keys) - 1)
        jj = self.order[pos]
        keep = (self.keys[pos] == key) & (jj != rep) & (box != 0)
        ii, jj, box = rep[keep], jj[keep], box[keep]
        s = np.argsort(jj + ii * len(self.count), kind="stable")
        return ii[s], jj[s], box[s]

    def blocks(self, budget: int, sources: tuple[int, int] | None = None):
        """Consecutive source ranges ``(start, stop)`` of at most ``budget`` candidates (or one source),
        covering ``sources`` (``[start, stop)``; default: every cell)."""
        csum = np.cumsum(self.count)
        start, N = (0, len(self.count)) if sources is None else (int(sources[0]), int(sources[1]))
        if not 0 <= start <= N <= len(self.count):
            raise ValueError(f"source range {sources} is not within the {len(self.count)} cells")
        while start < N:
            base = csum[start - 1] if start else 0
            stop = max(start + 1, int(np.searchsorted(csum, base + budget, side="right")))
            yield start, min(stop, N)
            start = stop


def join_weights(structure: ProductStructure, tables) -> np.ndarray:
    """The pairs the join enumerates per source cell, shape ``(N,)`` (part of :func:`shard_weights`)."""
    return _Reach(np.asarray(structure.cell_factor, dtype=np.int64), [t.mask for t in tables]).count


def shard_weights(structure: ProductStructure, tables, joint_src: np.ndarray) -> np.ndarray:
    """The work of each source cell, shape ``(N,)``: the pairs the join enumerates from it
    (:func:`join_weights`) plus :data:`JOINT_PAIR_WEIGHT` per pair of it left to the joint LP
    (``joint_src`` of the whole join); what the shards of a product run balance
    (:func:`tubejax.abstraction.shards.source_range`)."""
    w = join_weights(structure, tables)
    return w + JOINT_PAIR_WEIGHT * np.bincount(np.asarray(joint_src, dtype=np.int64), minlength=len(w))


def join_factors(decomp: CellDecomposition, structure: ProductStructure, tables, memory_mb: float = 256.0,
                 progress=None, sources: tuple[int, int] | None = None) -> JoinedEdges:
    """Join the factor tables into the full pairs' edges, streamed by blocks of source cells.

    Only the pairs within reach are enumerated: for a source with factor cells ``(a_1, .., a_G)``
    the cells whose factor cell ``b_g`` has a nonzero ``'box'`` mask ``M_g[a_g, b_g]`` in every group
    (the product of the groups' reach lists, looked up among the cells).

    Parameters
    ----------
    decomp : CellDecomposition
    structure : ProductStructure
    tables : sequence of FactorTable, one per group
    memory_mb : float
        Budget of one block's working arrays (about :data:`BYTES_PER_CANDIDATE` per candidate pair).
    progress : tqdm, optional
        Advanced by the source cells of each block.
    sources : (int, int), optional
        Join only the pairs whose source cell is in ``[start, stop)`` (a shard's range; default: all).

    Returns
    -------
    JoinedEdges
    """
    cf = np.asarray(structure.cell_factor, dtype=np.int64)
    masks = [t.mask for t in tables]                  # (2, F_g, F_g) uint64 each
    margins = [t.margin for t in tables]              # (2, L_max, F_g, F_g)
    reach = _Reach(cf, masks)
    out = {k: [] for k in ("src", "dst", "L", "margin", "variant", "jsrc", "jdst", "jmask")}
    tested = np.zeros(len(cf), dtype=np.int64)
    for start, stop in reach.blocks(int(max(1, memory_mb * 2 ** 20 // BYTES_PER_CANDIDATE)), sources):
        ii, jj, box = reach.candidates(cf, np.arange(start, stop))
        tested[start:stop] = np.bincount(ii - start, minlength=stop - start)
        _join_block(decomp, cf, masks, margins, (ii, jj, box), out)
        if progress is not None:
            progress.update(stop - start)

    def cat(key, dtype):
        return np.concatenate(out[key]).astype(dtype) if out[key] else np.zeros(0, dtype)

    return JoinedEdges(cat("src", np.int64), cat("dst", np.int64), cat("L", np.int64), cat("margin", float),
                       cat("variant", np.int64), cat("jsrc", np.int64), cat("jdst", np.int64),
                       cat("jmask", np.uint64), tested)


def _join_block(decomp, cf, masks, margins, candidates, out: dict) -> None:
    """The safe-set variant, horizon and margin of a block's candidate pairs, appended to ``out``."""
    ii, jj, box = candidates
    obstacle = box_obstacle_cases(decomp, ii, jj)
    m_src = np.full(len(ii), ~np.uint64(0), dtype=np.uint64)
    for g, M in enumerate(masks):
        m_src &= M[1][cf[ii, g], cf[jj, g]]
    mask = np.where(obstacle, m_src, box)
    if obstacle.any():                                # the paper's free case with a blocked bounding box
        # only horizons below the source variant's least L can improve the edge
        low = m_src & (~m_src + np.uint64(1))
        below = np.where(m_src != 0, low - np.uint64(1), ~np.uint64(0))
        k = np.flatnonzero(obstacle & ((box & below) != 0))
        free_hull = ~hull_obstacle_cases(decomp, ii[k], jj[k])
        out["jsrc"].append(ii[k[free_hull]])
        out["jdst"].append(jj[k[free_hull]])
        out["jmask"].append((box & below)[k[free_hull]])
    bit = lowest_bit(mask)
    keep = bit >= 0
    ii, jj, bit, var = ii[keep], jj[keep], bit[keep], obstacle[keep].astype(np.int64)
    marg = np.full(len(ii), np.inf)
    for g, Mg in enumerate(margins):
        marg = np.minimum(marg, Mg[var, bit, cf[ii, g], cf[jj, g]])
    for key, val in (("src", ii), ("dst", jj), ("L", bit + 1), ("margin", marg), ("variant", var)):
        out[key].append(val)
