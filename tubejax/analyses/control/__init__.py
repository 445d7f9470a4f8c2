"""Control: high-level planning (Dijkstra over the transition system), the
low-level tube controller (Algorithm 1) and vectorised closed-loop simulation."""

from .controller import (EdgeController, Triangulation, barycentric, control_step,
                         controller_step_at, edge_controller, plan_controller, set_violation,
                         stack_controllers, triangulate)
from .planner import Plan, PlanningError, plan_edge, plan_sequence, plan_to_label
from .simulate import (MODES, SimulationResult, in_cells, in_obstacle_interior, rollout,
                       sample_polytope, simulate, simulate_edge, trace_count)

__all__ = [
    "EdgeController", "MODES", "Plan", "PlanningError", "SimulationResult", "Triangulation",
    "barycentric", "control_step", "controller_step_at", "edge_controller", "in_cells",
    "in_obstacle_interior", "plan_controller", "plan_edge", "plan_sequence", "plan_to_label",
    "rollout", "sample_polytope", "set_violation", "simulate", "simulate_edge",
    "stack_controllers", "trace_count", "triangulate",
]
