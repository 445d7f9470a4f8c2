"""Control: high-level planning (Dijkstra over the transition system, :mod:`.planner`), the low-level
tube controller (Algorithm 1, :mod:`.controller`) and vectorised closed-loop simulation
(:mod:`.simulate`, with :mod:`.closed_loop`, :mod:`.run_checks`, :mod:`.state_monitor`,
:mod:`.chunks`).
"""

from .controller import (EdgeController, Triangulation, barycentric, control_step,
                         controller_step_at, edge_controller, plan_controller, set_violation,
                         stack_controllers, triangulate)
from .planner import Plan, PlanningError, plan_edge, plan_sequence, plan_to_label
from .closed_loop import MODES, rollout, sample_polytope, trace_count
from .run_checks import in_cells, in_obstacle_interior
from .simulate import SimulationResult, SimulationRuns, simulate, simulate_edge

__all__ = [
    "EdgeController", "MODES", "Plan", "PlanningError", "SimulationResult", "SimulationRuns", "Triangulation",
    "barycentric", "control_step", "controller_step_at", "edge_controller", "in_cells",
    "in_obstacle_interior", "plan_controller", "plan_edge", "plan_sequence", "plan_to_label",
    "rollout", "sample_polytope", "set_violation", "simulate", "simulate_edge",
    "stack_controllers", "trace_count", "triangulate",
]
