"""Vectorised closed-loop simulation of Algorithm 3 (docs/math/control.md#closed-loop-simulation):
:func:`simulate` and its :class:`SimulationResult`.

:func:`simulate` rolls out every run at once (:func:`~tubejax.analyses.control.closed_loop.rollout`,
a jitted ``lax.scan`` ``vmap``-ed over runs) and checks every state on the host
(:mod:`~tubejax.analyses.control.run_checks`), in chunks of :data:`CHUNK_RUNS` runs, which never
changes a result. :func:`summary_violations` says what a summary shows going wrong.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

from tqdm.auto import tqdm

import jax
import jax.numpy as jnp
import numpy as np

from .closed_loop import MODES, rollout, sample_polytope
from .controller import EdgeController, plan_controller
from .planner import Plan, plan_edge
from .run_checks import _check_runs, _violation

__all__ = ["SimulationResult", "SimulationRuns", "simulate", "simulate_edge", "summary_violations",
           "CHUNK_RUNS"]

#: Runs whose states :func:`simulate` checks at a time (its progress bar advances per chunk).
CHUNK_RUNS = 1000


@dataclass
class SimulationResult:
    """Closed-loop runs and their checks (:mod:`~tubejax.analyses.control.run_checks`).

    Attributes
    ----------
    trajectories : (runs, S+1, n);  inputs : (runs, S, m);  disturbances : (runs, S, n)
    violation : (runs, S+1)   ``max(H x - h)`` of the current tube set (``<= 0`` inside)
    outside : (runs, S)       barycentric outside amount at control time
    obstacle_entry, tube_exit, reached_all : (runs,) bool
    first_obstacle_time, first_exit_time : (runs,) int, ``-1`` if never
    targets_reached : (runs, K) bool    per segment
    workspace_exit : (runs,) bool       a state outside the workspace: outside its ``domain``
                                        when it has one, else in no cell and in no obstacle
    input_violation : (runs,)           ``max(H_u u - h_u)`` (``<= 0``: in ``U``)
    state_constraints : dict            ``{name: Halfspaces}`` checked (``system.state_constraints``)
    outside_state_constraints : dict    ``{name: (runs,) int}``: states of each run outside it by more
                                        than ``tol``; :attr:`state_constraint_exit` flags such runs
    """

    trajectories: np.ndarray
    inputs: np.ndarray
    disturbances: np.ndarray
    violation: np.ndarray
    outside: np.ndarray
    obstacle_entry: np.ndarray
    first_obstacle_time: np.ndarray
    tube_exit: np.ndarray
    first_exit_time: np.ndarray
    targets_reached: np.ndarray
    reached_all: np.ndarray
    workspace_exit: np.ndarray
    input_violation: np.ndarray
    plan: Plan
    mode: str
    seed: int
    tol: float
    meta: dict = field(default_factory=dict)
    state_constraints: dict = field(default_factory=dict)
    outside_state_constraints: dict = field(default_factory=dict)

    @property
    def n_runs(self) -> int:
        return int(self.trajectories.shape[0])

    @property
    def state_constraint_exit(self) -> np.ndarray:
        """``(runs,)`` bool: runs with a state outside some state constraint (such a run is unsafe)."""
        out = np.zeros(self.n_runs, bool)
        for c in self.outside_state_constraints.values():
            out |= np.asarray(c) > 0
        return out

    def summary(self) -> dict:
        """Counts over runs (plain Python types); ``outside_state_constraints`` counts *states*
        (over all runs and steps) outside each state constraint, ``{}`` when the system has none."""
        return {
            "runs": self.n_runs,
            "steps": int(self.inputs.shape[1]),
            "mode": self.mode,
            "seed": self.seed,
            "obstacle_entries": int(self.obstacle_entry.sum()),
            "tube_exits": int(self.tube_exit.sum()),
            "workspace_exits": int(self.workspace_exit.sum()),
            "runs_reaching_all_targets": int(self.reached_all.sum()),
            "targets_reached_per_segment": [int(c) for c in self.targets_reached.sum(0)],
            "max_tube_violation": float(np.max(self.violation)) if self.violation.size else 0.0,
            "max_outside": float(np.max(self.outside)) if self.outside.size else 0.0,
            "max_input_violation": float(np.max(self.input_violation)) if self.n_runs else 0.0,
            "tol": self.tol,
            "outside_state_constraints": {k: int(np.sum(c)) for k, c in self.outside_state_constraints.items()},
        }


class SimulationRuns(NamedTuple):
    """How :func:`simulate` draws its runs and checks them.

    Attributes
    ----------
    n_runs : int
        Runs when ``x0`` is not given (initial states uniform in the first cell).
    mode : {'uniform', 'boundary', 'adversarial', 'none'}
        How the disturbance is drawn (:data:`~tubejax.analyses.control.closed_loop.MODES`).
    seed : int
        ``jax.random.PRNGKey(seed)`` drives initial states and disturbances.
    W : Ball or Polytope, optional
        Disturbance set of the simulation (default: the design ``ts.system.W``);
        a larger one shows that violations are detected.
    tol : float
        Violation above which a tube exit is counted.
    chunk_runs : int
        Runs checked at a time (:data:`CHUNK_RUNS`); the result does not depend on it.
    """

    n_runs: int = 100
    mode: str = "uniform"
    seed: int = 0
    W: object = None            # Ball, Polytope or None (the design W)
    tol: float = 1e-9
    chunk_runs: int = CHUNK_RUNS


def simulate(ts, plan: Plan, runs: SimulationRuns = SimulationRuns(), *, x0=None,
             ctrl: EdgeController | None = None, progress=False) -> SimulationResult:
    """Simulate Algorithm 3 along ``plan`` for many runs and check every run.

    Parameters
    ----------
    ts : TransitionSystem
    plan : Plan
    runs : SimulationRuns
        How many runs, their disturbance mode, seed and set, the tube-exit tolerance and how
        many runs are checked at a time.
    x0 : array (runs, n), optional
        The initial states (then ``runs.n_runs`` is not used).
    ctrl : EdgeController, optional
        Precomputed :func:`plan_controller` (e.g. a modified tube); it must hold float64 data.
    progress : bool or tqdm-like
        ``True``: a tqdm bar on stderr whose total is the number of runs, advancing as
        chunks of runs are checked; a tqdm-like object (``update(k)``) is advanced instead.

    Returns
    -------
    SimulationResult
        The same for every ``progress`` and ``runs.chunk_runs``.

    Notes
    -----
    Everything here reports safety, so it always runs in float64 (inside
    ``jax.enable_x64(True)``, whatever the global ``jax_enable_x64``): in float32 the
    rounding of a state on a tube facet alone exceeds ``1e-9`` and shows up as false alarms.
    """
    if not isinstance(runs, SimulationRuns):
        raise TypeError(f"runs: expected a SimulationRuns, got {type(runs).__name__}")
    if runs.mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {runs.mode!r}")
    chunk_runs = runs.chunk_runs
    if isinstance(chunk_runs, bool) or not isinstance(chunk_runs, (int, np.integer)) or chunk_runs < 1:
        raise ValueError(f"chunk_runs must be an integer >= 1, got {chunk_runs!r}")
    runs = runs._replace(tol=float(runs.tol), chunk_runs=int(chunk_runs))
    with jax.enable_x64(True):
        return _simulate(ts, plan, runs, x0, ctrl, progress)


def _simulate(ts, plan, runs: SimulationRuns, x0, ctrl, progress) -> SimulationResult:
    """:func:`simulate` with x64 enabled."""
    n_runs, mode, seed, W, tol, chunk_runs = runs
    if ctrl is None:
        ctrl = plan_controller(ts, plan, jnp.float64)
    dtype = ctrl.H.dtype
    if dtype != jnp.float64:
        raise ValueError(f"the simulation computes in float64; the controller data is {dtype}")
    key = jax.random.PRNGKey(seed)
    kx, kw = jax.random.split(key)
    decomp, sysm = ts.decomposition, ts.system
    if x0 is None:
        x0 = sample_polytope(kx, decomp.cells[plan.cells[0]], int(n_runs), dtype)
    x0 = jnp.atleast_2d(jnp.asarray(x0, dtype))
    own_bar = not hasattr(progress, "update")
    bar = tqdm(total=int(x0.shape[0]), desc=f"simulating ({mode})", unit="run", disable=not progress,
               leave=False) if own_bar else progress
    try:
        out = rollout(ctrl, sysm.A, sysm.B, x0, kw, sysm.W if W is None else W, mode)
        X, U, Wt, outside, viol = (np.asarray(out[k], float)
                                   for k in ("x", "u", "w", "outside", "violation"))
        parts = []
        for a in range(0, max(len(X), 1), chunk_runs):          # the checks: most of the time
            parts.append(_check_runs(decomp, plan, X[a:a + chunk_runs], viol[a:a + chunk_runs], tol,
                                     sysm.state_constraints))
            bar.update(len(X[a:a + chunk_runs]))
    finally:
        if own_bar:
            bar.close()
    flags = {k: np.concatenate([p_[k] for p_ in parts], axis=0) for k in parts[0]}
    uviol = np.max(_violation(sysm.U, U), axis=1) if U.shape[1] else np.full(len(X), -np.inf)
    return SimulationResult(
        trajectories=X, inputs=U, disturbances=Wt, violation=viol, outside=outside,
        obstacle_entry=flags["obstacle_entry"], first_obstacle_time=flags["first_obstacle_time"],
        tube_exit=flags["tube_exit"], first_exit_time=flags["first_exit_time"],
        targets_reached=flags["targets_reached"], reached_all=flags["targets_reached"].all(1),
        workspace_exit=flags["workspace_exit"], input_violation=uviol, plan=plan, mode=mode, seed=int(seed),
        tol=float(tol), state_constraints=dict(sysm.state_constraints),
        outside_state_constraints={k: flags[f"outside_{k}"] for k in sysm.state_constraints})


def simulate_edge(ts, k: int, runs: SimulationRuns = SimulationRuns(), **options) -> SimulationResult:
    """:func:`simulate` along the single edge ``k`` (target: its destination cell); ``options`` are
    :func:`simulate`'s keywords."""
    return simulate(ts, plan_edge(ts, k), runs, **options)


def summary_violations(s: dict) -> list[str]:
    """What a simulation summary (:meth:`SimulationResult.summary`, or a specification run's) shows
    going wrong, one phrase each (obstacle entries, tube and workspace exits, inputs outside ``U`` by
    more than ``tol``, missed targets, ...); empty when every run was safe and met every target."""
    bad = [f"{s[k]} runs with {k.replace('_', ' ')}" for k in ("obstacle_entries", "tube_exits", "workspace_exits")
           if s[k]]
    if not s.get("max_input_violation", -np.inf) <= s.get("tol", 1e-9):     # a NaN input too
        bad.append(f"inputs outside U (by up to {s['max_input_violation']:.3g})")
    if s["runs_reaching_all_targets"] != s["runs"]:
        bad.append(f"{s['runs'] - s['runs_reaching_all_targets']} runs missing a target")
    bad += [f"{c} states outside the state constraint {k}" for k, c in s.get("outside_state_constraints", {}).items()
            if c]
    if s.get("avoided_region_entries"):
        bad.append(f"{s['avoided_region_entries']} runs entering an avoided region")
    if "runs_satisfying_spec" in s and s["runs_satisfying_spec"] != s["runs"]:
        bad.append(f"{s['runs'] - s['runs_satisfying_spec']} runs violating the specification")
    return bad
