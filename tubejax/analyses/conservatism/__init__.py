"""How conservative is an abstraction? The whole-problem limit of robust reach-avoid in 2-D and the
winning set of every method beside it (docs/math/limit.md).

:mod:`.polygons` (Minkowski sums and Pontryagin differences of non-convex polygons with convex
ones, the robust predecessor), :mod:`.limit` (:func:`reach_avoid_limit`, the fixed point) and
:mod:`.winning` (:func:`winning_set`: the cells of a transition system with a path to a target
cell, and where they leave the limit).
"""

from .limit import AREA_TOL, MAX_ITERATIONS, ReachAvoidLimit, reach_avoid_limit, safe_and_target
from .polygons import DEFAULT_SIDES, SLACK, disturbance_polygon, input_polygon, minkowski_sum, \
    pontryagin_difference, robust_pre
from .winning import WinningSet, allowed_edges, cells_outside, winning_set

__all__ = ["AREA_TOL", "DEFAULT_SIDES", "MAX_ITERATIONS", "ReachAvoidLimit", "SLACK", "disturbance_polygon",
           "input_polygon", "minkowski_sum", "pontryagin_difference", "reach_avoid_limit", "robust_pre",
           "safe_and_target", "WinningSet", "allowed_edges", "cells_outside", "winning_set"]
