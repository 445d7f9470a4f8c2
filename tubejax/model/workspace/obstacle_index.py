"""The obstacle case of many pairs at once: does ``int P_ij`` meet ``int O``? (docs/math/problem-data.md).

The rule is :func:`tubejax.model.geometry.interiors_intersect`'s, pair by pair. In 2-D,
``area(P_ij ∩ O) > TOUCH_TOL``: the obstacles' union is cut into pieces with disjoint interiors in an
``STRtree``, a hull meets only the pieces whose interior its interior meets, and a sum within a
factor 2 of ``TOUCH_TOL`` is recomputed against the whole union. In n-D only obstacles whose box
overlaps the pair's by more than ``TOUCH_TOL`` are tested: box against box in closed form
(:func:`_box_pair_depth_bound`), else the overlap LP
:func:`~tubejax.model.geometry.interior_overlap_depth` on the pair hull.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from typing import Callable

import numpy as np
import shapely

from ..geometry import Polytope, interior_overlap_depth, to_shapely
from ..geometry.obstacles import TOUCH_TOL
from .rectilinear import convex_box_areas, polygon_vertices, rectangles_of

#: Threads of the 2-D obstacle test (shapely's vectorised calls release the GIL), at most this many
#: and at least :data:`_MIN_PER_THREAD` pairs each.
_CASE_THREADS = min(4, os.cpu_count() or 1)
_MIN_PER_THREAD = 2048

__all__ = ["ObstacleIndex"]

#: A union polygon with more coordinates than this is clipped into tiles.
_MAX_PIECE_COORDS = 64
#: Bisection steps of the closed-form box test (the bracket ends below 1e-19 of [0, 1]).
_BISECT = 64


def _box_pair_depth_bound(lo_i, hi_i, lo_j, hi_j, o_lo, o_hi) -> np.ndarray:
    """``s* = max_{λ in [0,1]} ρ(λ)`` for box cells ``i, j`` against a box obstacle, shape ``(C,)``.

    ``co(P_i u P_j)`` is the union over ``λ`` of the boxes ``B(λ) = λ P_i + (1-λ) P_j``, and
    ``ρ(λ)`` is half the smallest side of ``B(λ) ∩ O`` (negative when they are apart):
    the minimum of ``4 n`` linear functions of ``λ``, so concave; ``s*`` is found by bisection on
    the slope of the active line. A ball of radius ``ρ(λ)`` fits in ``B(λ) ∩ O``, so the overlap
    depth ``δ`` of ``P_ij`` and ``O`` is ``>= s*``; conversely each ``B(λ)`` is at least
    ``w = min cell width`` wide along every axis, so ``s* >= min(w, δ) / 2``.

    Parameters
    ----------
    lo_i, hi_i, lo_j, hi_j, o_lo, o_hi : ndarray, shape (C, n)

    Returns
    -------
    s : ndarray, shape (C,)
        A lower bound on ``s*`` within ``1e-17`` of it (bracket width times the largest slope).
    slack : ndarray, shape (C,)
        That bracket error bound.
    """
    # lines a λ + b, shape (C, 4 n): hi - lo, hi - O_lo, O_hi - lo, O_hi - O_lo
    a = np.concatenate([(hi_i - hi_j) - (lo_i - lo_j), hi_i - hi_j, -(lo_i - lo_j), 0 * o_lo], axis=1)
    b = np.concatenate([hi_j - lo_j, hi_j - o_lo, o_hi - lo_j, o_hi - o_lo], axis=1)
    left = np.zeros(len(a))
    right = np.ones(len(a))
    for _ in range(_BISECT):
        mid = 0.5 * (left + right)
        k = np.argmin(a * mid[:, None] + b, axis=1)
        up = np.take_along_axis(a, k[:, None], axis=1)[:, 0] > 0
        left = np.where(up, mid, left)
        right = np.where(up, right, mid)
    vals = [np.min(a * lam[:, None] + b, axis=1) for lam in (left, right)]
    s = 0.5 * np.maximum(*vals)
    slack = 0.5 * np.max(np.abs(a), axis=1) * (right - left) + 1e-300
    return s, slack


class ObstacleIndex:
    """Obstacles prepared for the obstacle-case test of many pairs.

    Parameters
    ----------
    obstacles : tuple
        :class:`Polytope` obstacles (any dimension) and/or 2-D shapely geometries.
    dim : int
        Dimension of the cells.
    tile : float
        Side of the tiles that cut large 2-D obstacle polygons (a few cell sizes).
    """

    def __init__(self, obstacles, dim: int, tile: float):
        self.dim = int(dim)
        self.obstacles = tuple(obstacles)
        if not self.obstacles:
            return
        if self.dim == 2:
            self.union = shapely.union_all([to_shapely(o) if isinstance(o, Polytope) else o
                                            for o in self.obstacles])
            self.pieces = self._pieces(self.union, float(tile))
            self.tree = shapely.STRtree(self.pieces)
            self.rects = rectangles_of(self.union)       # rectilinear walls: areas in NumPy
            if self.rects is not None:
                self.rect_tree = shapely.STRtree(shapely.box(*self.rects.T))
        else:
            bad = [k for k, o in enumerate(self.obstacles) if not isinstance(o, Polytope) or o.dim != dim]
            if bad:
                raise ValueError(f"obstacles[{bad[0]}]: a {dim}-D decomposition needs {dim}-D Polytope "
                                 f"obstacles, got {self.obstacles[bad[0]]!r}")
            self.o_lo = np.array([o.bounding_box()[0] for o in self.obstacles])
            self.o_hi = np.array([o.bounding_box()[1] for o in self.obstacles])
            self.o_box = np.array([o.is_box for o in self.obstacles])
            # the obstacles' bounding boxes projected on the first two axes, for the pairs' boxes
            # to find the few they may meet (see _meeting)
            self.box_tree = shapely.STRtree(shapely.box(self.o_lo[:, 0], self.o_lo[:, 1],
                                                        self.o_hi[:, 0], self.o_hi[:, 1])) if dim >= 2 else None

    @staticmethod
    def _pieces(union, tile: float) -> np.ndarray:
        """Polygons with disjoint interiors whose union is ``union`` (large ones clipped by tiles)."""
        out = []
        for part in shapely.get_parts(union):
            if shapely.get_num_coordinates(part) <= _MAX_PIECE_COORDS:
                out.append(part)
                continue
            x0, y0, x1, y1 = part.bounds
            xs = np.arange(x0, x1, tile)
            ys = np.arange(y0, y1, tile)
            gx, gy = np.meshgrid(xs, ys, indexing="ij")
            tiles = shapely.box(gx.ravel(), gy.ravel(), np.minimum(gx.ravel() + tile, x1),
                                np.minimum(gy.ravel() + tile, y1))
            shapely.prepare(part)
            clipped = shapely.intersection(part, tiles[shapely.intersects(part, tiles)])
            polys = shapely.get_parts(clipped)
            out.extend(polys[(shapely.get_type_id(polys) == 3) & (shapely.area(polys) > 0)])
        return np.array(out, dtype=object)

    def pair_cases(self, cells, cell_lo, cell_hi, src, dst, hulls: Callable) -> np.ndarray:
        """Whether each pair ``(src[k], dst[k])`` is in the obstacle case, shape ``(K,)``.

        Parameters
        ----------
        cells : sequence of Polytope
        cell_lo, cell_hi : ndarray, shape (N, n)
            Bounding boxes of the cells.
        src, dst : ndarray of int, shape (K,)
        hulls : callable
            ``hulls(src, dst)`` -> shapely polygons (2-D) or :class:`Polytope` (n-D) of ``P_ij``.
        """
        src, dst = np.asarray(src, int), np.asarray(dst, int)
        out = np.zeros(len(src), dtype=bool)
        if not self.obstacles or len(src) == 0:
            return out
        if self.dim == 2:
            p_lo = np.minimum(cell_lo[src], cell_lo[dst])      # bounding box of P_ij, shape (K, n)
            p_hi = np.maximum(cell_hi[src], cell_hi[dst])
            return self._cases_2d(src, dst, p_lo, p_hi, hulls)
        return self._cases_nd(cells, cell_lo, cell_hi, src, dst, hulls)

    def _cases_2d(self, src, dst, p_lo, p_hi, hulls):
        out = np.zeros(len(src), dtype=bool)
        # P_ij lies in its bounding box; shrunk by d on each side, the box still meets every piece
        # that P_ij overlaps by more than the frame's area 2 d (w + h) = TOUCH_TOL / 4, so the
        # pairs it misses sum at most that (flag: > TOUCH_TOL; recomputed only above TOUCH_TOL / 2)
        d = (0.125 * TOUCH_TOL) / np.sum(p_hi - p_lo, axis=1)
        boxes = shapely.box(p_lo[:, 0] + d, p_lo[:, 1] + d, p_hi[:, 0] - d, p_hi[:, 1] - d)
        near = np.unique(self.tree.query(boxes, predicate="intersects")[0])
        if near.size == 0:
            return out
        n_threads = min(_CASE_THREADS, max(1, near.size // _MIN_PER_THREAD))
        if n_threads > 1:           # shapely releases the GIL: the chunks run side by side
            parts = np.array_split(near, n_threads)
            with ThreadPoolExecutor(n_threads) as ex:
                flags = list(ex.map(lambda k: self._near_cases_2d(src[k], dst[k], hulls), parts))
            out[near] = np.concatenate(flags)
        else:
            out[near] = self._near_cases_2d(src[near], dst[near], hulls)
        return out

    def _near_cases_2d(self, src, dst, hulls) -> np.ndarray:
        """The obstacle case of pairs whose bounding box meets some piece, shape ``(K,)``."""
        geoms = hulls(src, dst)
        if self.rects is not None:
            # the union split into rectangles with disjoint interiors: the areas add up
            qi, ri = self.rect_tree.query(geoms, predicate="intersects")
            V, cnt = polygon_vertices(geoms)
            area = convex_box_areas(V[qi], cnt[qi], self.rects[ri, :2], self.rects[ri, 2:])
        else:
            qi, pi = self.tree.query(geoms, predicate="intersects")
            # interiors of two polygons meet in an open set, empty or 2-D: only then is the area > 0
            deep = shapely.relate_pattern(geoms[qi], self.pieces[pi], "2********") if qi.size else qi > 0
            qi, pi = qi[deep], pi[deep]
            area = shapely.area(shapely.intersection(geoms[qi], self.pieces[pi])) if qi.size else np.zeros(0)
        total = np.bincount(qi, weights=area, minlength=len(src))
        flag = total > TOUCH_TOL
        unsure = np.flatnonzero((total > 0.5 * TOUCH_TOL) & (total <= 2 * TOUCH_TOL))
        if unsure.size:                                        # the union's own area decides
            flag[unsure] = shapely.area(shapely.intersection(geoms[unsure], self.union)) > TOUCH_TOL
        return flag

    def _meeting(self, lo, hi):
        """``(k, m)``, sorted: the boxes ``[lo[k], hi[k]]`` (shape ``(C, n)``) and the obstacles ``m`` whose
        bounding boxes overlap by more than ``TOUCH_TOL`` along every axis (index arrays): an ``STRtree`` on
        the first two axes proposes, the strict test on all axes decides, without a ``(C, M)`` array."""
        if self.box_tree is None:
            meet = ~(np.any(lo[:, None, :] >= self.o_hi[None] - TOUCH_TOL, axis=2)
                     | np.any(self.o_lo[None] >= hi[:, None, :] - TOUCH_TOL, axis=2))    # (C, M)
            return np.nonzero(meet)
        k, m = self.box_tree.query(shapely.box(lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1]))
        meet = ~(np.any(lo[k] >= self.o_hi[m] - TOUCH_TOL, axis=1)
                 | np.any(self.o_lo[m] >= hi[k] - TOUCH_TOL, axis=1))
        k, m = k[meet], m[meet]
        order = np.lexsort((m, k))
        return k[order], m[order]

    def _cases_nd(self, cells, cell_lo, cell_hi, src, dst, hulls, chunk: int = 65536):
        """:meth:`pair_cases` in n-D: the obstacles whose boxes meet each pair's bounding box, decided
        by box depth bounds where the cells are boxes, else by the overlap LP, ``chunk`` pairs at a time."""
        out = np.zeros(len(src), dtype=bool)
        p_lo = np.minimum(cell_lo[src], cell_lo[dst])          # bounding box of P_ij, shape (K, n)
        p_hi = np.maximum(cell_hi[src], cell_hi[dst])
        box_cells = all(c.is_box for c in cells)
        w_min = float(np.min(cell_hi - cell_lo))
        lp_pairs: list = []                                    # (pair, obstacle) for the overlap LP
        for c0 in range(0, len(src), chunk):
            sl = slice(c0, c0 + chunk)
            k, m = self._meeting(p_lo[sl], p_hi[sl])
            k = k + c0
            if box_cells and w_min > 2 * TOUCH_TOL:
                quick = self.o_box[m]
                kq, mq = k[quick], m[quick]
                i, j = src[kq], dst[kq]
                s, slack = _box_pair_depth_bound(cell_lo[i], cell_hi[i], cell_lo[j], cell_hi[j],
                                                 self.o_lo[mq], self.o_hi[mq])
                hit = s > TOUCH_TOL                            # depth >= s*
                free = s + slack <= 0.5 * TOUCH_TOL            # depth <= 2 s* (cells wider than 1e-9)
                out[kq[hit]] = True
                unsure = ~hit & ~free
                lp_pairs += list(zip(kq[unsure], mq[unsure])) + list(zip(k[~quick], m[~quick]))
            else:
                lp_pairs += list(zip(k, m))
        lp_pairs = [(kk, mm) for kk, mm in lp_pairs if not out[kk]]
        if lp_pairs:
            ks = np.unique([kk for kk, _ in lp_pairs])
            hull_of = dict(zip(ks.tolist(), hulls(src[ks], dst[ks])))
            for kk, mm in lp_pairs:
                if not out[kk]:
                    out[kk] = interior_overlap_depth(hull_of[int(kk)], self.obstacles[mm]) > TOUCH_TOL
        return out
