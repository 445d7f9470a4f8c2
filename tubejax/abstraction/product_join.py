"""The join of the factor abstractions into the full transition system (docs/math/product.md#the-join).

For an ordered pair of distinct cells ``(i, j)`` with factor cells ``a_g = f_g(i)``, ``b_g = f_g(j)``:

* the safe-set variant is ``'box'`` when the interior of the bounding box of ``P_i u P_j`` meets no
  obstacle's interior (:func:`box_obstacle_cases`, exact comparisons), ``'source'`` otherwise;
* the product tube LP at ``L`` is feasible iff every group's factor LP ``(a_g, b_g, L, variant)`` is,
  so the pair's edge is at the smallest ``L`` feasible in every group, its margin the least of theirs.

The feasible horizons of a factor pair are the bits of a ``uint64`` (:attr:`FactorTable.mask`), so the
join is a bitwise AND of gathered masks, streamed over blocks of source cells whose ``(block, N)``
arrays fit ``memory_mb``. Pairs in the ``'source'`` variant whose pair hull ``co(P_i u P_j)`` is
nevertheless obstacle-free (the paper's free case) are listed for the joint LP with the paper's safe
set (:func:`tubejax.abstraction.product_abstraction.build_product_abstraction` solves them).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely

from ..model.geometry import Polytope, interiors_intersect
from ..model.product_structure import ProductStructure
from ..model.workspace.decomposition import CellDecomposition
from ..model.workspace.rectilinear import rectangles_of

__all__ = ["JoinedEdges", "box_obstacle_cases", "join_factors", "lowest_bit"]


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
    n_box_tested : int                      pairs whose bounding box was tested against the obstacles
    """

    src: np.ndarray
    dst: np.ndarray
    L: np.ndarray
    margin: np.ndarray
    variant: np.ndarray
    joint_src: np.ndarray
    joint_dst: np.ndarray
    joint_box_mask: np.ndarray
    n_box_tested: int


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
        self.is_box = [o.H.shape[0] == 2 * dim and bool(np.all(np.sum(o.H != 0, axis=1) == 1)) for o in polys]
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


def box_obstacle_cases(decomp: CellDecomposition, src, dst) -> np.ndarray:
    """Whether the interior of the bounding box of ``P_i u P_j`` meets ``int O``, shape ``(K,)``.

    Box obstacles are decided by exact comparisons of the boxes' coordinates (interiors meet iff
    ``max(lo) < min(hi)`` on every axis); other polytopes by
    :func:`~tubejax.model.geometry.interiors_intersect`.
    """
    src = np.asarray(src, dtype=int).reshape(-1)
    dst = np.asarray(dst, dtype=int).reshape(-1)
    lo, hi = decomp.cell_boxes()
    index = decomp._cache.get("product_box_obstacles")
    if index is None:
        index = decomp._cache["product_box_obstacles"] = _BoxObstacles(decomp.obstacles, decomp.dim)
    return index.cases(np.minimum(lo[src], lo[dst]), np.maximum(hi[src], hi[dst]))


def join_factors(decomp: CellDecomposition, structure: ProductStructure, tables, memory_mb: float = 256.0,
                 progress=None) -> JoinedEdges:
    """Join the factor tables into the full pairs' edges, streamed by blocks of source cells.

    Parameters
    ----------
    decomp : CellDecomposition
    structure : ProductStructure
    tables : sequence of FactorTable, one per group
    memory_mb : float
        Budget of one block's ``(block, N)`` working arrays (about 24 bytes per entry).
    progress : tqdm, optional
        Advanced by the source cells of each block.

    Returns
    -------
    JoinedEdges
    """
    N = decomp.n_cells
    cf = structure.cell_factor
    masks = [t.mask for t in tables]                  # (2, F_g, F_g) uint64 each
    margins = [t.margin for t in tables]              # (2, L_max, F_g, F_g)
    block = int(max(1, min(N, memory_mb * 2 ** 20 // (24 * N))))
    out = {k: [] for k in ("src", "dst", "L", "margin", "variant", "jsrc", "jdst", "jmask")}
    n_tested = 0
    for start in range(0, N, block):
        I = np.arange(start, min(N, start + block))
        m_box = np.full((len(I), N), ~np.uint64(0), dtype=np.uint64)
        for g, M in enumerate(masks):
            m_box &= M[0][cf[I, g][:, None], cf[None, :, g]]
        m_box[np.arange(len(I)), I] = 0               # self-pairs are not transitions
        li, jj = np.nonzero(m_box)
        ii = I[li]
        box = m_box[li, jj]
        del m_box
        n_tested += len(ii)
        obstacle = box_obstacle_cases(decomp, ii, jj)
        m_src = np.full(len(ii), ~np.uint64(0), dtype=np.uint64)
        for g, M in enumerate(masks):
            m_src &= M[1][cf[ii, g], cf[jj, g]]
        mask = np.where(obstacle, m_src, box)
        if obstacle.any():                            # the paper's free case with a blocked bounding box
            # only horizons below the source variant's least L can improve the edge
            low = m_src & (~m_src + np.uint64(1))
            below = np.where(m_src != 0, low - np.uint64(1), ~np.uint64(0))
            k = np.flatnonzero(obstacle & ((box & below) != 0))
            free_hull = ~decomp.obstacle_cases(ii[k], jj[k])
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
        if progress is not None:
            progress.update(len(I))

    def cat(key, dtype):
        return np.concatenate(out[key]).astype(dtype) if out[key] else np.zeros(0, dtype)

    return JoinedEdges(cat("src", np.int64), cat("dst", np.int64), cat("L", np.int64), cat("margin", float),
                       cat("variant", np.int64), cat("jsrc", np.int64), cat("jdst", np.int64),
                       cat("jmask", np.uint64), n_tested)
