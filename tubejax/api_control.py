"""Controllers from a computed system: :func:`plan` (a sequence of regions, an LTLf or an LTL formula),
:func:`simulate` (the closed loop, checked run by run) and :func:`export_controller` (the plan's controller
as dependency-free code). ``tj.plan``, ``tj.simulate`` and ``tj.export_controller``; the evidence of every
edge a plan uses is re-checked before it is simulated or exported.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .analyses.control import Plan, SimulationRuns, plan_sequence, simulate as simulate_plan
from .analyses.control.export import LANGUAGES, Lasso, export_controller as _export_controller
from .analyses.control.simulate import summary_violations
from .analyses.spec import SpecPlan, plan_formula, plan_ltl, plan_sequence_spec, sequence_spec_plan, simulate_spec
from .errors import InputError
from .inputs import SimulationSettings, SpecSettings, validate_section
from .lp.evidence.registry import tube_methods
from .transitions.transition_system import TransitionSystem
from .verify.verifier import check_edges

__all__ = ["plan", "simulate", "export_controller", "SimulationReport", "EVIDENCE_FAILS"]

#: How the error of :func:`export_controller` for a plan over an edge that fails its check begins.
EVIDENCE_FAILS = "the plan uses edges whose evidence fails the check"

def _check_system(ts) -> None:
    if not isinstance(ts, TransitionSystem):
        raise InputError(f"ts: expected a TransitionSystem (tj.abstract or tj.load), got {type(ts).__name__}")


def _start_cell(ts, start, first_label) -> int:
    if start is None and first_label is None:
        raise InputError("start: a formula needs a start cell (a cell id, or a region label as a string)")
    if start is None or isinstance(start, str):
        cells = ts.decomposition.cells_with_label(first_label if start is None else start)
        if not cells:
            raise InputError(f"spec: no cell carries the start label {first_label!r}" if start is None
                             else f"start: no cell carries the label {start!r}")
        return cells[0]
    if isinstance(start, bool) or not isinstance(start, (int, np.integer)) or not 0 <= start < ts.n_cells:
        raise InputError(f"start: expected a cell id in [0, {ts.n_cells - 1}] or a region label (a string), "
                         f"got {start!r}")
    return int(start)


def plan(ts: TransitionSystem, spec=None, *, ltl: str | None = None, start=None, planner: str = "exact",
         cycles: int = 1) -> SpecPlan:
    """Plan over ``ts`` (Dijkstra, cost ``L``) for a sequence of regions, an LTLf formula or an LTL formula.

    Parameters
    ----------
    ts : TransitionSystem
    spec : sequence of labels, or str
        A sequence ``[1, 3, 4, 5, 6]``: start in region 1, then visit 3, 4, 5 and 6 in order.
        A string is an LTLf formula over the propositions ``l<label>``, e.g.
        ``"F(l3 & F l5) & G(!l4)"`` (needs ``start``).
    ltl : str, optional
        Instead of ``spec``: an LTL formula over infinite runs, e.g. ``"GF l3 & GF l6 & G !l4"``
        (needs ``start``): the cheapest accepting lasso of the sound product with Spot's Büchi
        automaton (``.lasso``: prefix and cycle), its cycle ``cycles`` times in ``.plan``.
    start : int or str, optional
        The start cell: a cell id, or a region label (its first cell). Default: the first
        cell of the sequence's first region; with a start cell, that cell must carry it.
    planner : {'exact', 'greedy', 'product'}
        For a sequence: least total steps, segment by segment (the paper), or through the
        sound product with the tubes' labels (as formulas are). Formulas always use the product.
    cycles : int
        With ``ltl``: turns of the lasso's cycle in ``.plan`` (what :func:`simulate` runs).

    Returns
    -------
    SpecPlan
        ``.plan`` (the cell path: ``cells``, ``edges``, ``cost``), the automaton every run is
        monitored against, and ``.stats``.

    Raises
    ------
    InputError
        A bad label, start cell or planner.
    PlanningError
        No plan meets the specification (the message names the part that cannot be met).
    """
    _check_system(ts)
    if (spec is None) == (ltl is None):
        raise InputError("give exactly one of spec (a sequence of labels or an LTLf formula) and ltl (an LTL formula)")
    if (ltl is not None or isinstance(spec, str)) and planner not in ("exact", "product"):
        raise InputError(f"planner: a formula is planned through the product (planner 'exact' or 'product'), "
                         f"got {planner!r}")
    if ltl is not None:
        return plan_ltl(ts, _start_cell(ts, start, None), ltl, cycles=cycles, key="ltl")
    if isinstance(spec, str):
        return plan_formula(ts, _start_cell(ts, start, None), spec)
    s = validate_section(SpecSettings, {"sequence": spec, "planner": planner})
    labels = s.labels
    cell = _start_cell(ts, start, labels[0])
    if ts.decomposition.labels[cell] is None or str(ts.decomposition.labels[cell]) != labels[0]:
        raise InputError(f"start: cell {cell} does not carry the sequence's first label {labels[0]!r}")
    if s.planner == "product":
        return plan_sequence_spec(ts, cell, labels[1:])
    return sequence_spec_plan(ts, plan_sequence(ts, cell, labels[1:], method=s.planner))


@dataclass(frozen=True)
class SimulationReport:
    """Closed-loop runs of a plan and what they show (:func:`simulate`).

    Attributes
    ----------
    summary : dict
        ``runs``, ``steps``, ``obstacle_entries``, ``tube_exits``, ``workspace_exits``,
        ``runs_reaching_all_targets`` and, for a specification, ``runs_satisfying_spec`` and
        ``avoided_region_entries``.
    findings : list of str
        What went wrong (empty: every run stayed safe and met the specification).
    result : SimulationResult
        The runs: ``trajectories`` ``(runs, steps + 1, n)``, ``inputs`` ``(runs, steps, m)``,
        ``disturbances`` ``(runs, steps, n)`` and per-run checks (``tubejax.analyses.plot`` draws it).
    spec : SpecSimulation or None
        The runs with the automaton's verdicts (for a :class:`SpecPlan`).
    """

    summary: dict
    findings: list = field(default_factory=list)
    result: object = None
    spec: object = None

    @property
    def ok(self) -> bool:
        """Every run safe (no obstacle entry, tube or workspace exit) and meeting every target."""
        return not self.findings

    @property
    def trajectories(self) -> np.ndarray:
        """States of every run, shape ``(runs, steps + 1, n)``."""
        return self.result.trajectories


def simulate(ts: TransitionSystem, plan, *, runs: int = 100, disturbance: str = "uniform",
             seed: int = 0, progress: bool = False) -> SimulationReport:
    """Simulate the closed loop (Algorithm 1 along the plan) for many runs, in float64, and check each.

    The evidence of every edge the plan uses is re-checked first (float64, margin, exact proof).

    Parameters
    ----------
    ts : TransitionSystem
    plan : SpecPlan or Plan
        From :func:`plan`.
    runs : int
        Runs, in ``[1, 10**7]``; initial states uniform in the start cell.
    disturbance : {'uniform', 'boundary', 'adversarial', 'none'}
        ``w`` uniform in ``W``, on its boundary, pushing toward the nearest facet of the next
        tube set, or zero.
    seed : int
        Seeds the initial states and the disturbances (the same seed gives the same runs).
    progress : bool
        Show a progress bar over the runs.

    Returns
    -------
    SimulationReport
        ``.ok``, ``.findings``, ``.summary`` and the runs (``.result``).

    Raises
    ------
    InputError
        A bad ``runs``, ``disturbance`` or ``seed``, or a plan that is not one.
    """
    s = validate_section(SimulationSettings, {"runs": runs, "mode": disturbance, "seed": seed},
                         rename=lambda f: f.replace("mode", "disturbance"))
    if not isinstance(plan, (SpecPlan, Plan)):
        raise InputError(f"plan: expected a plan from tj.plan, got {type(plan).__name__}")
    cells_plan = plan.plan if isinstance(plan, SpecPlan) else plan
    findings = [f"evidence: {f}" for f in check_edges(ts, cells_plan.edges)]
    runs = SimulationRuns(s.runs, s.mode, s.seed)
    spec = simulate_spec(ts, plan, runs, progress=bool(progress)) if isinstance(plan, SpecPlan) else None
    result = spec.result if spec is not None else simulate_plan(ts, plan, runs, progress=bool(progress))
    summary = spec.summary() if spec is not None else result.summary()
    return SimulationReport(summary, findings + summary_violations(summary), result, spec)


def export_controller(ts: TransitionSystem, plan, directory, languages=LANGUAGES, *, cycles: int | None = None,
                      tol: float = 1e-9, weights: str = "triangulation") -> list:
    """Write the controller of ``plan`` as dependency-free code (``python -m tubejax export-controller``).

    The evidence of every edge the plan uses is re-checked first; an edge that fails is not exported. Written
    (docs/howto/export.md): C99 needing only libm, a NumPy-only module, the JSON description of the data, and
    a README saying what the controller guarantees under which ``W``.

    Parameters
    ----------
    ts : TransitionSystem
        Of method ``'tube'``.
    plan : SpecPlan, Plan or Lasso
        From :func:`plan`; a patrol exports its prefix and its cycle, which repeats.
    directory : str or Path
    languages : sequence of {'c', 'python'}, or one of them
    cycles : int, optional
        How often a patrol's cycle runs: ``None`` (default) forever.
    tol : float
        Membership tolerance of the controller's checks (a distance).
    weights : {'triangulation', 'multilinear'}
        The library's weights (a fixed triangulation; the same inputs as :func:`simulate`), or the
        multilinear weights of the corners on every set that is an axis-aligned box.

    Returns
    -------
    list of Path
        The files written.

    Raises
    ------
    InputError
        A bad argument, a plan that is not one, or an edge whose evidence fails the check.
    """
    _check_system(ts)
    if not isinstance(plan, (SpecPlan, Plan, Lasso)):
        raise InputError(f"plan: expected a plan from tj.plan (or a Lasso), got {type(plan).__name__}")
    edges = (list(plan.prefix) + list(plan.cycle) if isinstance(plan, Lasso)
             else (plan.plan if isinstance(plan, SpecPlan) else plan).edges)
    if ts.method in tube_methods():
        bad = check_edges(ts, edges)
        if bad:
            raise InputError(f"{EVIDENCE_FAILS}, so no controller is exported: "
                             + "; ".join(bad[:5]) + (f" (and {len(bad) - 5} more)" if len(bad) > 5 else ""))
    return _export_controller(ts, plan, directory, languages, cycles=cycles, tol=tol, weights=weights)
