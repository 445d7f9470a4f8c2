"""Control: high-level planning (Dijkstra over the transition system), the
low-level tube controller (Algorithm 1) and vectorised closed-loop simulation.

Modules: :mod:`~tubejax.analyses.control.planner` (the plans),
:mod:`~tubejax.analyses.control.controller` (the controller),
:mod:`~tubejax.analyses.control.closed_loop` (disturbance sampling and the jitted rollout),
:mod:`~tubejax.analyses.control.run_checks` (the host checks of the runs' states),
:mod:`~tubejax.analyses.control.state_constraints` (states outside the state constraints),
:mod:`~tubejax.analyses.control.simulate` (:func:`simulate`: rollout and checks,
:class:`SimulationResult`) and :mod:`~tubejax.analyses.control.chunks` (many runs in chunks).
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
