"""Checks that a cell decomposition is one (docs/math/problem-data.md), and where a disturbance fits.

:func:`validate_decomposition` runs whenever a :class:`~tubejax.model.workspace.CellDecomposition`
is built and raises a :class:`~tubejax.errors.DecompositionError` naming the cells for non-finite
cells, cells violating their own H-representation, cells without volume (:data:`VOLUME_RTOL`), a
non-simple 2-D polygon, and interiors of two cells, or of a cell and an obstacle, that overlap by more
than :data:`~tubejax.model.geometry.obstacles.TOUCH_TOL` (the obstacle case's rule). Candidate pairs
come from a spatial index. :func:`disturbance_fits` says where ``P_j ⊖ W`` is non-empty (elsewhere
no transition can end in ``P_j``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import shapely
from scipy.spatial import ConvexHull

from ...errors import DecompositionError
from ..geometry import Polytope, interior_overlap_depth, support, to_shapely
from ..geometry.obstacles import TOUCH_TOL
from ..geometry.polytope import chebyshev_ball

if TYPE_CHECKING:  # pragma: no cover
    from .decomposition import CellDecomposition

__all__ = ["VOLUME_RTOL", "FIT_TOL", "validate_decomposition", "disturbance_fits", "box_overlap_pairs"]

#: A cell whose volume is at most this times ``extent^n`` has no volume (collinear points
#: give ~1e-16; a triangle of the polygon workspaces' smallest area 1e-12 and extent 8, 1.6e-14).
VOLUME_RTOL = 1e-15
#: ``P ⊖ W`` counts as empty only when its Chebyshev depth is below ``-FIT_TOL`` (a length),
#: far outside the LP's tolerances, so a cell reported as not fitting certainly does not.
FIT_TOL = 1e-7
#: The most vertex (or facet) coordinates of the cells stacked at once by the checks (16 MiB of float64).
_BLOCK_NUMBERS = 1 << 21
#: A vertex may lie this far (relative to the cell's extent) outside its own H-representation.
_HREP_RTOL = 1e-9


def _cell_name(decomp, i: int) -> str:
    parts = []
    if decomp.labels[i] is not None:
        parts.append(f"label {str(decomp.labels[i])!r}")
    if decomp.grid is not None:
        parts.append(f"grid {np.asarray(decomp.grid[i]).tolist()}")
    return f"cell {i}" + (f" ({', '.join(parts)})" if parts else "")


def _where(decomp) -> str:
    return f"decomposition {decomp.name!r}" if decomp.name else "decomposition"


def _cell_error(decomp, i: int, what: str, sep: str = " ") -> DecompositionError:
    """The error naming cell ``i`` of ``decomp``, then ``what``."""
    return DecompositionError(f"{_where(decomp)}: {_cell_name(decomp, int(i))}{sep}{what}")


def _overlap_error(decomp, i: int, j: int, amount: str, obstacle: bool) -> DecompositionError:
    """Cell ``i`` overlaps cell ``j``, or obstacle ``j``, by ``amount`` (``'common area 0.5'``, ``'depth 0.1'``)."""
    if obstacle:
        return _cell_error(decomp, i, f"meets the interior of obstacle {j} ({amount}; cells may only touch obstacles)")
    return _cell_error(decomp, i, f"and {_cell_name(decomp, int(j))} overlap ({amount}; cells may only share faces)")


def _box_mask(V: np.ndarray, H: np.ndarray) -> np.ndarray:
    """Which of G polytopes (vertices ``V`` (G, k, n), normals ``H`` (G, f, n)) are axis-aligned boxes
    whose vertices are exactly their corners in canonical order."""
    G, f, n = H.shape
    if f != 2 * n or V.shape[1] != 2 ** n:
        return np.zeros(G, dtype=bool)
    A = np.abs(H)
    axis = np.all(np.sum(A > 1e-12, axis=2) == 1, axis=1) & np.all(np.abs(A.max(axis=2) - 1.0) <= 1e-12, axis=1)
    lo, hi = V.min(axis=1), V.max(axis=1)                                    # (G, n)
    bits = Polytope.box(np.zeros(n), np.ones(n)).vertices                   # (2^n, n) canonical corner order
    corners = lo[:, None, :] + bits[None] * (hi - lo)[:, None, :]
    return axis & np.all(np.abs(V - corners) <= 1e-12 * (1.0 + np.abs(corners)), axis=(1, 2))


def _groups(cells) -> dict:
    """Cell ids grouped by ``(n_vertices, n_facets)``, so their arrays stack."""
    groups: dict = {}
    for i, P in enumerate(cells):
        groups.setdefault((P.n_vertices, P.H.shape[0]), []).append(i)
    return {k: np.array(v) for k, v in groups.items()}


def _blocks(cells):
    """``(ids, V, H, h)`` of the cells by :func:`_groups`, each group cut into blocks of at most
    :data:`_BLOCK_NUMBERS` vertex or facet coordinates in ids order, so that memory stays bounded
    (a 6-D box has 64 vertices: 1,000,000 of them stacked at once take 3 GB).

    Yields
    ------
    ids : ndarray of int, shape (G,)
    V : ndarray, shape (G, k, n)
    H : ndarray, shape (G, f, n)
    h : ndarray, shape (G, f)
    """
    for (k, f), ids in _groups(cells).items():
        n = cells[int(ids[0])].dim
        step = max(1, _BLOCK_NUMBERS // (max(k, f) * n))
        for s in range(0, len(ids), step):
            b = ids[s:s + step]
            yield (b, np.stack([cells[i].vertices for i in b]), np.stack([cells[i].H for i in b]),
                   np.stack([cells[i].h for i in b]))


# --------------------------------------------------------------------- cells one by one
def _check_cells(decomp) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """Finite data, vertices inside their own facets, volume (and simple polygons in 2-D).

    Returns the bounding boxes ``lo, hi`` (each of shape ``(N, n)``), which cells are
    axis-aligned boxes (shape ``(N,)``) and, in 2-D, the cells as shapely polygons (``(N,)``).
    """
    N, n = decomp.n_cells, decomp.dim
    lo, hi = np.empty((N, n)), np.empty((N, n))
    is_box = np.zeros(N, dtype=bool)
    violation = np.zeros(N)
    volume = np.zeros(N)
    for ids, V, H, h in _blocks(decomp.cells):                                # (G, k, n), (G, f, n), (G, f)
        finite = np.all(np.isfinite(V), axis=(1, 2)) & np.all(np.isfinite(H), axis=(1, 2)) \
            & np.all(np.isfinite(h), axis=1)
        if not finite.all():
            i = int(ids[np.argmin(finite)])
            raise _cell_error(decomp, i, "holds NaN or infinity")
        lo[ids], hi[ids] = V.min(axis=1), V.max(axis=1)
        violation[ids] = np.max(np.einsum("gkn,gfn->gkf", V, H) - h[:, None, :], axis=(1, 2))
        is_box[ids] = _box_mask(V, H)
        volume[ids] = np.prod(hi[ids] - lo[ids], axis=1)                   # right for boxes
    extent = np.max(hi - lo, axis=1)                                        # (N,)
    bad = np.flatnonzero(violation > _HREP_RTOL * np.maximum(extent, 1.0))
    if bad.size:
        i = int(bad[0])
        raise _cell_error(decomp, i, f"its vertices violate its own facets by {violation[i]:.3g} (vertex and "
                          "half-space representations disagree)", ": ")
    other = np.flatnonzero(~is_box)
    all_polys = _cell_polygons(decomp) if n == 2 else None
    polys = all_polys[other] if n == 2 else None
    if n == 2 and other.size:
        volume[other] = np.abs(shapely.area(polys))
    elif other.size:
        volume[other] = [_hull_volume(decomp.cells[i].vertices) for i in other]
    flat = np.flatnonzero(~(volume > VOLUME_RTOL * extent ** n))
    if flat.size:
        i = int(flat[0])
        raise _cell_error(decomp, i, f"has no volume (volume {volume[i]:.3g} for extent {extent[i]:.3g}; every cell "
                          "must be full-dimensional)")
    if n == 2 and other.size:
        invalid = np.flatnonzero(~shapely.is_valid(polys))
        if invalid.size:
            i = int(other[invalid[0]])
            raise _cell_error(decomp, i, f"is not a simple polygon ({shapely.is_valid_reason(polys[invalid[0]])})")
    return lo, hi, is_box, all_polys


def _hull_volume(V: np.ndarray) -> float:
    try:
        return float(ConvexHull(V).volume)
    except Exception:  # qhull: flat point set
        return 0.0


def _cell_polygons(decomp) -> np.ndarray:
    """The 2-D cells as shapely polygons, shape ``(N,)``."""
    out = np.empty(decomp.n_cells, dtype=object)
    for (k, _), ids in _groups(decomp.cells).items():
        out[ids] = shapely.polygons(np.stack([decomp.cells[i].vertices for i in ids]))
    return out


# --------------------------------------------------------------------- spatial index, n-D
def box_overlap_pairs(lo: np.ndarray, hi: np.ndarray, tol: float = TOUCH_TOL) -> np.ndarray:
    """Pairs of boxes whose interiors overlap by more than ``tol`` along every axis.

    A uniform hash grid (bucket size: the median extent per axis; boxes far larger than
    the median make it coarser, so a few huge boxes cannot blow up the bucket count)
    proposes pairs sharing a bucket, and the exact overlap filters them.

    Parameters
    ----------
    lo, hi : ndarray, shape (N, n)
        Box corners.
    tol : float
        Overlap (a length) at or below which boxes only touch.

    Returns
    -------
    ndarray of int, shape (K, 2)
        ``(i, j)`` with ``i < j``, sorted.
    """
    lo = np.asarray(lo, float)
    hi = np.asarray(hi, float)
    N, n = lo.shape
    if N < 2:
        return np.zeros((0, 2), dtype=np.int64)
    origin = lo.min(axis=0)
    for size in (np.median(hi - lo, axis=0), np.max(hi - lo, axis=0)):
        size = np.maximum(size, 1e-300)
        a = np.floor((lo + tol - origin) / size).astype(np.int64)
        b = np.maximum(np.floor((hi - tol - origin) / size).astype(np.int64), a)
        span = b - a + 1
        count = np.prod(span, axis=1)
        if count.sum() <= 64 * N + 1_000_000:
            break
    total = int(count.sum())
    owner = np.repeat(np.arange(N), count)
    rem = np.arange(total) - np.repeat(np.cumsum(count) - count, count)
    coords = np.empty((total, n), dtype=np.int64)
    for d in range(n - 1, -1, -1):                         # mixed radix over each box's bucket span
        s = span[owner, d]
        coords[:, d] = a[owner, d] + rem % s
        rem //= s
    _, bucket = np.unique(coords, axis=0, return_inverse=True)
    order = np.lexsort((owner, bucket.ravel()))
    bucket, owner = bucket.ravel()[order], owner[order]
    starts = np.flatnonzero(np.r_[True, bucket[1:] != bucket[:-1]])
    ends = np.r_[starts[1:], total]
    group_end = np.repeat(ends, ends - starts)
    k = group_end - np.arange(total) - 1                   # partners after each member of its bucket
    P = np.repeat(np.arange(total), k)
    Q = P + 1 + (np.arange(int(k.sum())) - np.repeat(np.cumsum(k) - k, k))
    i, j = np.minimum(owner[P], owner[Q]), np.maximum(owner[P], owner[Q])
    keep = i != j
    key = np.unique(i[keep].astype(np.int64) * N + j[keep])
    i, j = key // N, key % N
    depth = np.min(np.minimum(hi[i], hi[j]) - np.maximum(lo[i], lo[j]), axis=1)
    return np.stack([i, j], axis=1)[depth > tol]


def _overlap_depth(P, Q, P_box: bool, Q_box: bool) -> float:
    """Depth of ``int P ∩ int Q`` (a length; > 0 iff the interiors meet)."""
    if P_box and Q_box:
        lo1, hi1 = P.bounding_box()
        lo2, hi2 = Q.bounding_box()
        return float(np.min(np.minimum(hi1, hi2) - np.maximum(lo1, lo2)) / 2)
    return interior_overlap_depth(P, Q)


# --------------------------------------------------------------------- pairs
def _check_pairs_2d(decomp, polys: np.ndarray, lo: np.ndarray, hi: np.ndarray, is_box: np.ndarray) -> None:
    tree = shapely.STRtree(polys)
    a, b = tree.query(polys, predicate="intersects")
    keep = a < b
    a, b = a[keep], b[keep]
    area = np.zeros(a.size)
    boxes = is_box[a] & is_box[b]                          # box pairs: the overlap is a box
    area[boxes] = np.prod(np.clip(np.minimum(hi[a[boxes]], hi[b[boxes]]) - np.maximum(lo[a[boxes]], lo[b[boxes]]),
                                  0.0, None), axis=1)
    rest = np.flatnonzero(~boxes)
    rest = rest[~shapely.touches(polys[a[rest]], polys[b[rest]])]   # exact: the interiors meet
    area[rest] = shapely.area(shapely.intersection(polys[a[rest]], polys[b[rest]]))
    hit = np.flatnonzero(area > TOUCH_TOL)
    if hit.size:
        k = hit[0]
        raise _overlap_error(decomp, a[k], b[k], f"common area {area[k]:.3g}", False)
    pieces, owner = [], []
    for k, o in enumerate(decomp.obstacles):
        if isinstance(o, Polytope):
            if o.dim != 2:
                raise DecompositionError(f"{_where(decomp)}: obstacle {k} lives in R^{o.dim}, the cells in R^2")
            geom = to_shapely(o)
        elif isinstance(o, shapely.Geometry):
            geom = o
        else:
            raise DecompositionError(f"{_where(decomp)}: obstacle {k} is a {type(o).__name__}, expected a "
                                     "Polytope or a shapely polygon")
        if not shapely.is_valid(geom):
            raise DecompositionError(f"{_where(decomp)}: obstacle {k} is not a valid polygon "
                                     f"({shapely.is_valid_reason(geom)})")
        parts = shapely.get_parts(geom)
        pieces.extend(parts)
        owner.extend([k] * len(parts))
    if not pieces:
        return
    pieces = np.array(pieces, dtype=object)
    shapely.prepare(pieces)
    p, c = tree.query(pieces, predicate="intersects")
    inner = ~shapely.touches(pieces[p], polys[c])
    p, c = p[inner], c[inner]
    if p.size:
        area = shapely.area(shapely.intersection(polys[c], pieces[p]))
        hit = np.flatnonzero(area > TOUCH_TOL)
        if hit.size:
            k = hit[0]
            raise _overlap_error(decomp, c[k], owner[p[k]], f"common area {area[k]:.3g}", True)


def _check_pairs_nd(decomp, lo: np.ndarray, hi: np.ndarray, cell_is_box: np.ndarray) -> None:
    N, n = lo.shape
    obstacles = list(decomp.obstacles)
    for k, o in enumerate(obstacles):
        if not isinstance(o, Polytope) or o.dim != n:
            raise DecompositionError(f"{_where(decomp)}: obstacle {k} must be a Polytope in R^{n}, got {o!r}")
    items = list(decomp.cells) + obstacles
    is_box = list(cell_is_box) + [o.is_box for o in obstacles]
    if obstacles:
        o_lo, o_hi = zip(*(o.bounding_box() for o in obstacles))
        lo, hi = np.vstack([lo, np.array(o_lo)]), np.vstack([hi, np.array(o_hi)])
    for i, j in box_overlap_pairs(lo, hi, TOUCH_TOL):
        if i >= N:                                         # obstacle-obstacle pairs may overlap
            continue
        depth = _overlap_depth(items[i], items[j], is_box[i], is_box[j])
        if depth > TOUCH_TOL:
            raise _overlap_error(decomp, i, j if j < N else j - N, f"depth {depth:.3g}", j >= N)


def validate_decomposition(decomp: "CellDecomposition") -> None:
    """Raise :class:`DecompositionError` unless ``decomp`` is a valid cell decomposition.

    See the module docstring for the rules; cost is near-linear in the number of cells.
    """
    for i, P in enumerate(decomp.cells):
        if not isinstance(P, Polytope):
            raise _cell_error(decomp, i, f"is a {type(P).__name__}, expected a Polytope")
    lo, hi, is_box, polys = _check_cells(decomp)
    if decomp.dim == 2:
        _check_pairs_2d(decomp, polys, lo, hi, is_box)
    else:
        _check_pairs_nd(decomp, lo, hi, is_box)


# --------------------------------------------------------------------- disturbance
def disturbance_fits(decomp: "CellDecomposition", W) -> np.ndarray:
    """Whether ``P_j ⊖ W = {x : H_j x <= h_j - σ_W(H_j)}`` is non-empty, per cell.

    Parameters
    ----------
    decomp : CellDecomposition
        ``N`` cells in ``R^n``.
    W : Ball or Polytope
        The disturbance set in ``R^n``.

    Returns
    -------
    ndarray of bool, shape (N,)
        ``False`` only where ``P_j ⊖ W`` is certainly empty (its Chebyshev depth is below
        ``-FIT_TOL``): no transition can end in ``P_j``. Box cells are decided in closed
        form (``upper - lower >= σ_W(e_d) + σ_W(-e_d)`` per axis); other cells by one LP
        per distinct shape (cells equal up to translation share it).
    """
    if W.dim != decomp.dim:
        raise DecompositionError(f"W lives in R^{W.dim} but the cells in R^{decomp.dim}")
    n = decomp.dim
    out = np.ones(decomp.n_cells, dtype=bool)
    E = np.vstack([np.eye(n), -np.eye(n)])
    width_needed = support(W, E[:n]) + support(W, E[n:])               # (n,)
    shapes: dict = {}
    for ids, V, H, _ in _blocks(decomp.cells):                            # (G, k, n), (G, f, n)
        box = _box_mask(V, H)
        width = V[box].max(axis=1) - V[box].min(axis=1)                # (G_box, n)
        out[ids[box]] = np.all(width - width_needed >= -2 * FIT_TOL, axis=1)
        for i in ids[~box]:
            P = decomp.cells[i]
            c = P.centroid
            key = (np.round(P.H, 12).tobytes(), np.round(P.h - P.H @ c, 12).tobytes())
            if key not in shapes:
                _, depth = chebyshev_ball(P.H, P.h - P.H @ c - support(W, P.H), cap=1e9)
                if depth == -np.inf:
                    raise DecompositionError(f"the fit LP of {_cell_name(decomp, int(i))} failed")
                shapes[key] = depth >= -FIT_TOL
            out[i] = shapes[key]
    return out
