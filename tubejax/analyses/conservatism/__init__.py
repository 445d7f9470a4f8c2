"""How conservative is an abstraction? The whole-problem limit of robust reach-avoid in 2-D (:mod:`.limit`,
with the set operations of :mod:`.polygons`) and every method's winning set beside it (:mod:`.winning`);
docs/math/limit.md.
"""

from .limit import AREA_TOL, MAX_ITERATIONS, ReachAvoidLimit, reach_avoid_limit, safe_and_target
from .polygons import DEFAULT_SIDES, SLACK, disturbance_polygon, input_polygon, minkowski_sum, \
    pontryagin_difference, robust_pre
from .winning import WinningSet, allowed_edges, cells_outside, winning_set

__all__ = ["AREA_TOL", "DEFAULT_SIDES", "MAX_ITERATIONS", "ReachAvoidLimit", "SLACK", "disturbance_polygon",
           "input_polygon", "minkowski_sum", "pontryagin_difference", "reach_avoid_limit", "robust_pre",
           "safe_and_target", "WinningSet", "allowed_edges", "cells_outside", "winning_set"]
