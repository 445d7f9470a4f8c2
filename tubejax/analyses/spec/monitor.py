"""Closed-loop monitoring of simulated trajectories against the specification (float64).

Every state becomes its letter (the propositions whose closed region holds it within
:data:`REGION_TOL`) and the DFA reads them; a run satisfies the specification when the DFA ends
accepting. An *avoided-region entry* is a step whose letter takes the DFA from a live state to a dead
one. An LTL plan (``kind='ltl'``) is checked by Spot instead, independently of the planner
(docs/math/control.md#ltl-over-infinite-runs).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import spot

from ..control.simulate import SimulationResult, SimulationRuns, simulate
from .dfa import DFA
from .regions import region_pieces

__all__ = ["region_letters", "MonitorResult", "monitor", "monitor_lasso", "SpecSimulation", "simulate_spec",
           "REGION_TOL", "lasso_words_satisfy", "word_text"]

#: A state within this (unit-row) violation of a closed cell is in its region.
REGION_TOL = 1e-9


def region_letters(decomp, labels, X, tol: float = REGION_TOL) -> np.ndarray:
    """Letters (bit masks over ``labels``) of points ``X (..., n)`` -> ``(...)`` int64."""
    X = np.asarray(X, dtype=np.float64)
    out = np.zeros(X.shape[:-1], np.int64)
    for b, P in region_pieces(decomp, labels):
        out[P.violation(X) <= tol] |= np.int64(1) << b
    return out


@dataclass
class MonitorResult:
    """Per-run verdicts of the monitor.

    Attributes
    ----------
    letters : (runs, T+1) int64      letter of every state
    states : (runs, T+1) int64       DFA state after each letter
    satisfied : (runs,) bool         accepted at the end
    avoided_entry : (runs,) bool     some step entered an avoided region
    first_entry_time : (runs,) int   first such step, ``-1`` if none
    first_dead_time : (runs,) int    first step after which the spec cannot be met, ``-1`` if none
    """

    letters: np.ndarray
    states: np.ndarray
    satisfied: np.ndarray
    avoided_entry: np.ndarray
    first_entry_time: np.ndarray
    first_dead_time: np.ndarray


def _first(F):
    return np.where(F.any(-1), np.argmax(F, axis=-1), -1)


def monitor(dfa: DFA, decomp, X, avoid=(), tol: float = REGION_TOL) -> MonitorResult:
    """Run the DFA over the trajectories ``X (runs, T+1, n)`` (module docstring).

    Parameters
    ----------
    dfa : DFA
    decomp : CellDecomposition
    X : array, shape (runs, T+1, n)
    avoid : sequence of str
        Labels whose closed regions count as avoided-region entries in any case (patrol).
    tol : float

    Returns
    -------
    MonitorResult
    """
    X = np.asarray(X, dtype=np.float64)
    letters = region_letters(decomp, dfa.labels, X, tol)
    states = dfa.run(letters)
    prev = np.concatenate([np.full(states.shape[:-1] + (1,), dfa.initial), states[..., :-1]], -1)
    live = dfa.live()
    killed = live[prev] & ~live[states]
    caused = np.zeros_like(killed)
    for b in range(len(dfa.labels)):
        has = (letters >> b & 1).astype(bool)
        caused |= killed & has & live[dfa.delta[prev, letters & ~(np.int64(1) << b)]]
    if avoid:
        caused |= region_letters(decomp, list(avoid), X, tol) != 0
    return MonitorResult(letters, states, dfa.accepting[states[..., -1]], caused.any(-1),
                         _first(caused), _first(~live[states]))


def monitor_lasso(spec_plan, decomp, X, tol: float = REGION_TOL) -> MonitorResult:
    """Check the runs ``X (runs, T+1, n)`` of an LTL lasso plan with Spot (module docstring).

    ``states`` is ``-1`` (no automaton is run); ``first_dead_time`` is ``-1``.
    """
    X = np.asarray(X, dtype=np.float64)
    b, info = spec_plan.dfa, spec_plan.lasso
    letters = region_letters(decomp, b.labels, X, tol)
    ok = lasso_words_satisfy(b.formula, b.propositions, letters, info["prefix_steps"], info["cycle_steps"],
                             spec_plan.stats["cycles"])
    entry = (region_letters(decomp, list(spec_plan.avoid), X, tol) != 0 if spec_plan.avoid
             else np.zeros(letters.shape, bool))
    none = np.full(letters.shape[:-1], -1)
    return MonitorResult(letters, np.full(letters.shape, -1), ok, entry.any(-1), _first(entry), none)


def word_text(propositions, prefix, cycle) -> str:
    """Spot's text of the ultimately periodic word ``prefix; cycle{cycle}`` of bit-mask letters."""
    def letter(s):
        if not propositions:
            return "1"
        return " & ".join(p if s >> b & 1 else f"!{p}" for b, p in enumerate(propositions))

    head = "; ".join(letter(int(s)) for s in prefix)
    loop = "; ".join(letter(int(s)) for s in cycle)
    return (head + "; " if head else "") + f"cycle{{{loop}}}"


def lasso_words_satisfy(formula, propositions, letters, prefix_steps: int, cycle_steps: int,
                        cycles: int) -> np.ndarray:
    """``(runs,)`` bool: each run's words satisfy ``formula`` for every simulated turn (module docstring).

    Parameters
    ----------
    formula : spot.formula or str
    propositions : sequence of str
        Proposition of each letter bit.
    letters : ndarray of int, shape (runs, T + 1)
        The float64 region letters, ``T = prefix_steps + cycles * cycle_steps``.
    prefix_steps, cycle_steps, cycles : int
    """
    letters = np.asarray(letters, np.int64)
    P, C = int(prefix_steps), int(cycle_steps)
    if letters.shape[-1] != P + cycles * C + 1 or C < 1:
        raise ValueError(f"letters: expected {P + cycles * C + 1} time steps (prefix {P}, {cycles} x cycle {C}), "
                         f"got {letters.shape[-1]}")
    f = spot.formula(str(formula))
    neg = spot.translate(spot.formula.Not(f))
    d = neg.get_dict()
    seen = {}
    out = np.ones(letters.shape[0], bool)
    for r in range(letters.shape[0]):
        for k in range(cycles):
            head = letters[r, :P + k * C + 1]
            loop = letters[r, P + k * C + 1:P + (k + 1) * C + 1]
            key = (head.tobytes(), loop.tobytes())
            if key not in seen:
                w = spot.parse_word(word_text(propositions, head, loop), d)
                seen[key] = not neg.intersects(w.as_automaton())
            if not seen[key]:
                out[r] = False
                break
    return out


@dataclass
class SpecSimulation:
    """A :class:`~tubejax.analyses.control.simulate.SimulationResult` with the monitor's verdicts."""

    result: SimulationResult
    check: MonitorResult
    spec_plan: object

    @property
    def trajectories(self):
        return self.result.trajectories

    def summary(self) -> dict:
        """The simulation's counts plus ``runs_satisfying_spec`` and ``avoided_region_entries``."""
        s = self.result.summary()
        sp = self.spec_plan
        s.update({
            "spec": sp.spec, "spec_kind": sp.kind, "plan_steps": int(sp.plan.cost),
            "runs_satisfying_spec": int(self.check.satisfied.sum()),
            "avoided_region_entries": int(self.check.avoided_entry.sum()),
            "avoided_labels": list(sp.avoid),
        })
        if sp.lasso is not None:
            s["lasso"] = {"prefix": [int(c) for c in sp.lasso["prefix"]], "cycle": [int(c) for c in sp.lasso["cycle"]],
                          "prefix_steps": int(sp.lasso["prefix_steps"]), "cycle_steps": int(sp.lasso["cycle_steps"]),
                          "cycles": int(sp.stats["cycles"])}
        return s


def simulate_spec(ts, spec_plan, runs: SimulationRuns = SimulationRuns(), **options) -> SpecSimulation:
    """Simulate ``spec_plan.plan`` (:func:`tubejax.analyses.control.simulate`, float64) and monitor every run.

    ``runs`` and ``options`` are :func:`~tubejax.analyses.control.simulate`'s (``runs``: a
    :class:`~tubejax.analyses.control.simulate.SimulationRuns`; ``options``: ``x0``, ``ctrl``, ``progress``).

    Returns
    -------
    SpecSimulation
        ``summary()`` holds ``runs``, ``obstacle_entries``, ``tube_exits``,
        ``workspace_exits``, ``runs_satisfying_spec``, ``avoided_region_entries``, ...
    """
    res = simulate(ts, spec_plan.plan, runs, **options)
    if spec_plan.kind == "ltl":
        chk = monitor_lasso(spec_plan, ts.decomposition, res.trajectories)
    else:
        chk = monitor(spec_plan.dfa, ts.decomposition, res.trajectories,
                      spec_plan.avoid if spec_plan.kind == "patrol" else ())
    return SpecSimulation(res, chk, spec_plan)
