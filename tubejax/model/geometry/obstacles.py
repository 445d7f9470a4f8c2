"""Does a convex polytope meet the *interior* of an obstacle set?

Touching an obstacle's boundary does not count (docs/math/problem-data.md: the free case
allows ``P_ij`` to touch ``O``). Convex obstacles work in any dimension (one
small LP each); non-convex obstacles are 2-D polygons handled by shapely.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
import shapely
from scipy.optimize import linprog

from .polytope import Polytope

__all__ = ["interiors_intersect", "interior_overlap_depth", "meets_obstacles", "to_shapely"]

#: Overlap depth (convex case, a length) or area (polygon case) at or below which
#: two sets are taken to touch only. Both are far below any cell size.
TOUCH_TOL = 1e-9


def interior_overlap_depth(P: Polytope, Q: Polytope) -> float:
    """Largest ``s`` such that a point lies ``s`` deep inside both ``P`` and ``Q``.

    ``s > 0`` iff the interiors meet; ``s = 0`` when they only touch; ``s < 0``
    when they are apart. Solved as one LP: ``max s : H_P x + s <= h_P, H_Q x + s <= h_Q``
    (rows are unit-normalised).
    """
    if P.dim != Q.dim:
        raise ValueError(f"dimension mismatch: {P.dim} vs {Q.dim}")
    n = P.dim
    A = np.vstack([np.hstack([P.H, np.ones((len(P.h), 1))]),
                   np.hstack([Q.H, np.ones((len(Q.h), 1))])])
    b = np.concatenate([P.h, Q.h])
    c = np.zeros(n + 1)
    c[-1] = -1.0
    res = linprog(c, A_ub=A, b_ub=b, bounds=[(None, None)] * n + [(None, 1e6)], method="highs")
    if res.status != 0:
        raise RuntimeError(f"overlap LP failed: {res.message}")
    return float(res.x[-1])


def to_shapely(P: Polytope) -> shapely.Polygon:
    """A 2-D polytope as a shapely polygon."""
    if P.dim != 2:
        raise ValueError(f"shapely needs a 2-D polytope, got dimension {P.dim}")
    return shapely.Polygon(P.vertices)


def interiors_intersect(P: Polytope, obstacle) -> bool:
    """Whether ``int P`` meets ``int obstacle``.

    Parameters
    ----------
    P : Polytope
        Convex, any dimension.
    obstacle : Polytope or shapely geometry
        A convex polytope (any dimension) or a 2-D (multi)polygon, possibly
        non-convex.
    """
    if isinstance(obstacle, Polytope):
        lo1, hi1 = P.bounding_box()
        lo2, hi2 = obstacle.bounding_box()
        if np.any(lo1 >= hi2 - TOUCH_TOL) or np.any(lo2 >= hi1 - TOUCH_TOL):
            return False
        return interior_overlap_depth(P, obstacle) > TOUCH_TOL
    geom = obstacle
    poly = to_shapely(P)
    if not shapely.intersects(poly, geom):
        return False
    return float(shapely.area(shapely.intersection(poly, geom))) > TOUCH_TOL


def meets_obstacles(P: Polytope, obstacles: Sequence) -> bool:
    """Whether ``int P`` meets the interior of any obstacle (the obstacle case)."""
    return any(interiors_intersect(P, o) for o in obstacles)
