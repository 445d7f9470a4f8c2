"""A planned flight in 3-D (``fig10_flight3d``): the whole map, the plan's cells and the runs.

Where ``fig9_tubes3d`` zooms onto the plan's tube sets, this shows where the flight goes in the building
(docs/math/drone.md#a-flight-through-two-storeys): every obstacle lightly (a slab shows its stairwells
as holes), the voxel of every cell of the plan numbered in plan order, and the runs by their positions.
"""

from __future__ import annotations

import numpy as np
from matplotlib.colors import to_rgba

from ...model.geometry import Polytope
from .figures import _cell_name
from .layers import drawn_space
from .style import PALETTE
from .trajectories import RunsStyle
from .view3d import (_OBSTACLE, _START, _TARGET, _ZORDER, VIEW, SolidStyle, _axes3d, _polytope_solid, _key,
                     _runs_and_finish, _start_and_targets)

__all__ = ["plot_flight_3d"]

#: The map's obstacles in the flight figure: lighter than in the zoomed tube figures.
_LIGHT_OBSTACLE = SolidStyle(_OBSTACLE, 0.06, 0.18, linewidth=0.3)
#: The voxels of the cells between the plan's start and its end (numbered in plan order).
_PLAN_CELL = SolidStyle(PALETTE["sky"], 0.2, 0.9, linewidth=0.9)


def plot_flight_3d(ts, plan, result=None, ax=None, runs: RunsStyle = RunsStyle(max_runs=30), size=(8.0, 6.5),
                   view=VIEW):
    """The plan's flight through the whole map in 3-D, with some closed-loop runs.

    Parameters
    ----------
    ts : TransitionSystem
        Over a 3-D decomposition of boxes or one lifted from it (``workspace.velocity_divisions``).
    plan : Plan
        Its cells are drawn as their voxels, numbered ``0 .. len(plan.cells) - 1`` along the plan.
    result : SimulationResult, optional
        ``trajectories (runs, T+1, n)``: the runs ``runs`` chooses are drawn by their positions.
    ax, runs, size, view :
        As in :func:`~tubejax.analyses.plot.view3d.plot_plan_tubes_3d`.

    Returns
    -------
    Axes3D
        Its collections with gid ``'obstacle'`` are the map's obstacles, those with gid ``'hull'``
        the voxels of the plan's cells between its start and its end (in plan order).
    """
    ax = _axes3d(ax, size)
    d, axes, cell_of = drawn_space(ts.decomposition)
    lo, hi = (np.asarray(b, float) for b in d.bounds())
    for o in d.obstacles:
        a, b = o.bounding_box()
        _polytope_solid(ax, Polytope.box(a, b), _LIGHT_OBSTACLE, "obstacle")
    voxels = [int(cell_of[int(c)]) for c in plan.cells]
    n = len(voxels)
    for k, v in enumerate(voxels):
        a, b = d.cells[v].bounding_box()
        if 0 < k < n - 1:
            _polytope_solid(ax, Polytope.box(a, b), _PLAN_CELL, "hull")
        c = 0.5 * (np.asarray(a) + np.asarray(b))
        ax.text(c[0], c[1], c[2], str(k), fontsize=7, ha="center", va="center", color="black",
                zorder=_ZORDER["text"])
    _start_and_targets(ax, d, [voxels[0], voxels[-1]] if n > 1 else voxels)
    handles = [_key(_START, "start" + _cell_name(ts.decomposition, int(plan.cells[0]))), _key(_TARGET, "target"),
               _key(PALETTE["sky"], "planned cells"), _key(_OBSTACLE, "obstacle", 0.15, to_rgba(_OBSTACLE, 0.4))]
    title = f"planned flight: {len(plan.edges)} transitions, {plan.cost} steps"
    return _runs_and_finish(ax, (lo, hi), title, handles, result, runs, axes, view)
