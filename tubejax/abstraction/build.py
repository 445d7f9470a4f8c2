"""Algorithm 2: every ordered pair x horizon -> a verified transition system.

The pairs and horizons come from :func:`tubejax.abstraction.candidates.build_candidates` as sparse
arrays (a k-d tree over reach boxes, then the sound pruning rules; no all-pairs step).
Horizons run in rounds ``L = 1, 2, ..., L_max``; in each round every candidate pair
still without an edge (and not pruned at that ``L``) is handed to a batch solver, in chunks
that fit a memory budget (:class:`~tubejax.abstraction.schedule.MemoryBudget`). Each pair's horizons are
solved strictly in increasing order (:class:`~tubejax.abstraction.schedule.PairSchedule`), so its edge cost
is the minimal ``L`` (docs/math/tube-lp.md#paper-slips, slip 2). A batched solver may let the HiGHS confirmations
of likely edges run on into later rounds (``Pending``): the pair waits meanwhile, and if HiGHS
refuses, its later horizons are solved in a second sweep over the rounds. A solver returns one
:class:`Verdict` per problem; only ``status == 'edge'`` verdicts, whose tube passed
:func:`tube_violation` ``<= 1e-9``, enter the transition system.

With a :class:`~tubejax.abstraction.runstore.RunStore`, every finished step (a chunk and the
confirmations settled with it) is written to disk with its tubes, and a run interrupted at any
point resumes from those files to the identical result. ``shard=(K, k)`` solves only the pairs
whose source cell shard ``k`` owns (:mod:`tubejax.abstraction.shards`).
"""

from __future__ import annotations

import logging
import time
from collections import Counter
from typing import Callable

import numpy as np
from tqdm.auto import tqdm

from ..lp.evidence.verdict import TRANSLATE_EDGE, Pending, Verdict, highs_solve_batch
from ..model.zshape.kinds import cross_sections
from .methods import METHODS, check_solver, check_state_constraints, method_solver, solver_method
from .candidates import build_candidates
from ..model.problem import RoundProblems, pair_problems
from ..transitions.records import NonEdges
from .runstore import Facts, RunStore, RunStoreError, candidates_fingerprint
from .schedule import MemoryBudget, PairSchedule, format_seconds
from .shards import select_shard
from ..model.system import LinearSystem
from ..transitions.transition_system import Edge, TransitionSystem
from .translations import TRANSLATE_PROVENANCE, TranslationClasses, solve_by_class
from ..model.workspace.decomposition import CellDecomposition
from ..model.zassignment import ZAssignment

__all__ = ["Verdict", "highs_solve_batch", "build_abstraction", "cross_sections", "ZERO_MARGIN_TOL",
           "TRANSLATE_PROVENANCE", "METHODS", "method_solver", "solver_method"]

log = logging.getLogger("tubejax")

#: Edges with ``|t*|`` at or below this are flagged as zero-margin (valid, but only an exact solver confirms them).
ZERO_MARGIN_TOL = 1e-9


BatchSolver = Callable[..., list]


def build_abstraction(decomp: CellDecomposition, system: LinearSystem, *, zshape: str = "box",
                      z_scale: float = 1.0, L_max: int = 10, eps_min: float = 0.0,
                      pruning: bool = True, solve_batch: BatchSolver | None = None,
                      progress: bool = True, on_round: Callable | None = None,
                      method: str = "tube", memory_budget_mb: float | None = None,
                      shard: tuple[int, int] = (1, 0), store: RunStore | None = None,
                      min_margin: float = 0.0,
                      z: ZAssignment | tuple | None = None,
                      translations: bool | None = None) -> TransitionSystem:
    """Run Algorithm 2.

    Parameters
    ----------
    decomp : CellDecomposition
    system : LinearSystem
    zshape : str
        Cross-section kind (:func:`tubejax.model.zshape.kinds.make_z`); with ``z`` given,
        only the name recorded in ``stats['zshape']``.
    z_scale : float
        The size of ``Z`` (``make_z``'s ``scale``); ignored with ``z``.
    z : ZAssignment or sequence of Polytope, optional
        The cross-sections themselves instead of ``zshape``: one per cell (length ``N``), or a
        :class:`~tubejax.model.zassignment.ZAssignment` whose per-pair ``Z`` replace the source
        cell's for those pairs (``learned_pair``; Lemma 1 holds pair by pair). Every pair is
        decided and verified as with a per-cell ``Z``; the result's ``Z`` is this assignment
        and its files store the ``Z`` of every edge that has its own.
    L_max : int
        Largest horizon tried, ``>= 1``.
    pruning : bool
        Apply the sound necessary conditions of :mod:`tubejax.abstraction.pruning`, and settle the pairs of a
        round that are exact translates of a clearly infeasible one (:mod:`tubejax.abstraction.translations`;
        tube and open-loop methods: one representative per class is solved first, and the
        translates of a likely edge go straight to HiGHS).
    translations : bool, optional
        The translation-class rule alone (default: as ``pruning``); the result does not
        depend on it.
    solve_batch : callable, optional
        ``solve_batch(problems, progress=bar) -> list[Verdict]``; default: ``method``'s own
        reference solver (:func:`method_solver`: HiGHS on the tube or open-loop LP, or the exact
        polygon computation). A solver of another method (:func:`solver_method`) is refused. A
        solver with
        ``supports_deferred = True`` is called with ``defer=True`` in the first sweep and may
        return a :class:`~tubejax.lp.evidence.verdict.Pending` for a likely edge: the pair waits
        while its HiGHS confirmation runs on beside the later rounds, and the edge enters the
        result only once confirmed (if HiGHS disagrees, the pair's later horizons are solved in
        order after all, so the result is Algorithm 2's).
    method : {'tube', 'openloop', 'exact2d'}
        The problem solved for each pair (docs/math/tube-lp.md and docs/math/open-loop.md; exact2d: exact polygon
        backward reachability, 2-D), recorded in the result. It decides the default
        ``solve_batch``; a ``solve_batch`` of another method is refused (the evidence each
        one stores differs).
    on_round : callable, optional
        Called as ``on_round(L, new_edges, new_tubes)`` after each step (a chunk of round ``L``)
        with the edges confirmed since the last call (an edge carries its own ``L``).
    memory_budget_mb : float, optional
        Budget of the rounds' working set (:class:`~tubejax.abstraction.schedule.MemoryBudget`): rounds are
        solved in chunks that fit it, and the rounds pause while too many confirmations wait.
        ``None``: one chunk per round. The result does not depend on it.
    shard : (int, int)
        ``(count, index)``: solve only the pairs whose source cell shard ``index`` of ``count``
        owns (:func:`tubejax.abstraction.shards.select_shard`).
    store : RunStore, optional
        Write every finished step there, and first replay the steps already there (resume).
    min_margin : float
        The robustness margin an edge must have, in ``[0, 1)``: ``(i, j)`` gets the least ``L``
        whose margin ``t*`` (docs/math/margins.md) is at least ``min_margin``, and the stored tube
        achieves it (:func:`~tubejax.lp.evidence.verdict.confirm_with_highs`). 0 (the
        default) is Problem 2 itself. Not for ``method='exact2d'``, which has no margin.

    Returns
    -------
    TransitionSystem
        Its ``stats`` hold, besides the counts of edges, LPs and verdicts: ``n_pairs``
        (``N (N-1)``), ``n_candidate_pairs`` (from the spatial index), ``n_tested_pairs`` and
        ``n_obstacle_case_candidates`` / ``n_free_case_candidates`` (pairs whose obstacle case
        was computed), ``pruned`` (instances per reason of :data:`tubejax.abstraction.pruning.PRUNE_REASONS`),
        ``seconds_before_first_lp``, ``problem_seconds`` and ``solve_seconds`` (and per solver
        call in ``rounds``), the ``seconds_*`` of the candidate steps, ``pdhg_lps_per_second`` /
        ``highs_lps_per_second`` when the solver's counters (or a solver without them, all
        HiGHS) tell them, ``shard`` for a shard, and ``resumed_lps`` (instances read back from
        the store), and ``n_translated`` (non-edges settled by their translation class's
        representative, not solved). ``n_lps`` counts every instance settled, resumed and
        translated ones included.

    Raises
    ------
    InputError
        An unknown ``method``, or a ``solve_batch`` that solves another method's problems.
    RunStoreError
        The store's files belong to other instances, or are damaged or inconsistent.
    """
    if not isinstance(L_max, (int, np.integer)) or L_max < 1:
        raise ValueError(f"L_max must be an integer >= 1, got {L_max!r}")
    if decomp.dim != system.n:
        raise ValueError(f"the workspace is {decomp.dim}-D but the system state is {system.n}-D")
    if not (isinstance(min_margin, (int, float, np.floating)) and 0.0 <= float(min_margin) < 1.0):
        raise ValueError(f"min_margin must be a number in [0, 1), got {min_margin!r}")
    if float(min_margin) > 0 and method == "exact2d":
        raise ValueError("min_margin applies to the tube and open-loop methods; exact2d has no margin")
    solve_batch = check_solver(method, solve_batch)
    check_state_constraints(method, system)
    t0 = time.perf_counter()
    N = decomp.n_cells
    if z is None:
        Z = cross_sections(decomp, zshape, z_scale)
    else:
        Z = z if isinstance(z, ZAssignment) else tuple(z)
        if len(Z) != N:
            raise ValueError(f"z: expected one cross-section per cell ({N}), got {len(Z)}")
    if method != "tube" and any(z.n_vertices != c.n_vertices for z, c in zip(Z, decomp.cells)):
        raise ValueError(f"a Z with more vertices than its cell (zshape 'chamfer') applies to method 'tube', "
                         f"got method {method!r}")
    cand = build_candidates(decomp, system, int(L_max), pruning)
    count, index = (int(shard[0]), int(shard[1]))
    if count != 1 or index != 0:
        cand = select_shard(cand, N, count, index)
    budget = MemoryBudget(memory_budget_mb, decomp, system, Z)
    solver_stats0 = _numeric(getattr(solve_batch, "stats", None))
    supports_defer = bool(getattr(solve_batch, "supports_deferred", False))
    with tqdm(total=cand.n_instances, desc="tube LPs", unit="LP", disable=not progress, leave=False) as bar:
        by_class = bool(pruning) if translations is None else bool(translations)
        run = _Rounds(decomp, system, Z, cand, int(L_max), float(eps_min), solve_batch, method, store, on_round,
                      t0, bar, float(min_margin), translations=by_class)
        if store is not None:
            run.replay(store.bind(candidates_fingerprint(cand, L_max, method)))
            bar.update(run.n_settled)
        while True:
            L0 = run.sched.min_open()
            if L0 is not None:
                run.sweep += 1                   # the first sweep defers; later ones solve refusals' horizons
                for L in range(L0, int(L_max) + 1):
                    ks = run.sched.open_at(L)
                    size = budget.chunk_size(L) or max(len(ks), 1)
                    for c in range(0, len(ks), size):
                        run.solve(L, ks[c:c + size], defer=supports_defer and run.sweep == 1)
                        run.harvest(block=False, limit=budget.max_pending())
                        run.write_step(L)
            elif not run.pending and not run.held:
                break
            run.harvest(block=True)              # every refusal known before the next sweep starts
            run.write_step(None)
            run.release_held()
    return run.result(cand, pruning, zshape, solver_stats0, _lp_rates)


class _Rounds:
    """The state of one run: schedule, waiting confirmations, settled facts not yet written, edges."""

    def __init__(self, decomp, system, Z, cand, L_max, eps_min, solve_batch, method, store, on_round, t0, bar,
                 min_margin=0.0, translations=True):
        self.decomp, self.system, self.Z, self.cand = decomp, system, Z, cand
        self.min_margin = min_margin
        self.L_max, self.eps_min, self.solve_batch, self.method = L_max, eps_min, solve_batch, method
        self.store, self.on_round, self.t0 = store, on_round, t0
        self.sched = PairSchedule(cand.keep)
        self.pending: dict = {}                  # pair -> (L, Pending), oldest first
        self.held: set = set()                   # pairs whose likely edge was refused: wait for the next sweep
        self.sweep = 0
        self.buffer: list = []                   # settled (pair, L, Verdict) not yet written
        self.edges, self.tubes = [], []
        self.refused: list = []                  # (src, dst, L, Refutation) of every settled non-edge
        self.verdicts, self.provenance = Counter(), Counter()
        self.exact, self.exact_step = Counter(), Counter()     # exact decisions: run so far, this step
        self.n_settled = self.n_resumed = 0
        self.timing = {"problem_seconds": 0.0, "solve_seconds": 0.0, "first_lp": None, "confirm_wait": 0.0}
        self.rounds: list = []
        self.n_solved_in_step = 0
        self.bar = bar
        # the class rule is sound for every method with an exact translation symmetry (tube, open loop)
        self.classes = TranslationClasses(decomp, system) if translations and method in ("tube", "openloop") \
            else None
        self.n_translated = 0

    # -- resume ------------------------------------------------------------------------------
    def replay(self, steps) -> None:
        """Apply the facts of the steps on disk, in order (the state they were written from).

        The likely edges the last step lists as still waiting for HiGHS are confirmed again as
        they were (:meth:`confirm_later` of a solver that has it), with their provenance, and
        wait as they did; a solver without it solves them again in the rounds."""
        waiting, held = [], []
        for name, f in steps:
            where = f"{self.store.rounds / name}"
            if len(f.pair) and (f.pair.max() >= len(self.cand.src) or
                                not (np.array_equal(self.cand.src[f.pair], f.src)
                                     and np.array_equal(self.cand.dst[f.pair], f.dst))):
                raise RunStoreError(f"{where}: its pairs are not this run's candidate pairs")
            try:
                self.sched.settle(f.pair, f.L, [s == "edge" for s in f.status])
            except ValueError as exc:
                raise RunStoreError(f"{where}: {exc}: the step files are inconsistent") from None
            self.verdicts.update(f.status)
            self.provenance.update(f.provenance)
            self.edges += f.edges
            self.tubes += f.tubes
            refs = f.refutations or [None] * len(f.pair)
            self.refused += [(int(a), int(b), int(L), r) for a, b, L, s, r in zip(f.src, f.dst, f.L, f.status, refs)
                             if s != "edge"]
            self.n_settled += len(f.pair)
            waiting, held = f.pending or [], f.held or []
            # the loop starts by counting a sweep: continue the step's sweep, or start the next one
            # after a sweep's closing (confirmation) step
            self.sweep = max((f.sweep or 1) - (0 if name.endswith("-confirm.npz") else 1), 0)
        self.n_resumed = self.n_settled
        for entry in self.store.manifest()["steps"] if steps else ():     # exact decisions of the steps read back
            self.exact.update(entry.get("exact_decisions") or {})
        if steps and held:
            self.sched.suspend(held)
            self.held.update(held)
        confirm = getattr(self.solve_batch, "confirm_later", None)
        if waiting and confirm is not None:
            c = self.cand
            ks = np.array([k for k, _, _ in waiting], dtype=np.int64)
            for L in sorted({L for _, L, _ in waiting}):
                sel = [a for a, (_, Lk, _) in enumerate(waiting) if Lk == L]
                kk = ks[sel]
                probs = pair_problems(self.decomp, self.system, self.Z, c.src[kk], c.dst[kk], L, c.obstacle[kk],
                                      self.eps_min, min_margin=self.min_margin)
                for k, pv in zip(kk.tolist(), confirm(probs, [waiting[a][2] for a in sel])):
                    self.pending[k] = (L, pv)
            self.sched.suspend(ks)
        if steps:
            log.info("resumed %d settled instances (%d edges) from %d steps in %s", self.n_settled,
                     len(self.edges), len(steps), self.store.rounds)

    # -- solving -----------------------------------------------------------------------------
    def solve(self, L: int, ks: np.ndarray, defer: bool) -> None:
        """Solve horizon ``L`` of the pairs ``ks`` (indices into the candidates) in one solver call."""
        c = self.cand
        tp = time.perf_counter()
        if self.classes is not None:         # built as needed: most translates are settled by class
            probs = RoundProblems(self.decomp, self.system, self.Z, c.src[ks], c.dst[ks], L, c.obstacle[ks],
                                  self.eps_min, min_margin=self.min_margin)
        else:
            probs = pair_problems(self.decomp, self.system, self.Z, c.src[ks], c.dst[ks], L, c.obstacle[ks],
                                  self.eps_min, min_margin=self.min_margin)
        ts = time.perf_counter()
        if self.timing["first_lp"] is None:
            self.timing["first_lp"] = ts - self.t0
        n_tr0 = self.n_translated
        res = self._solve_by_class(probs, c.src[ks], c.dst[ks], c.obstacle[ks], defer)
        lazy = getattr(probs, "seconds", 0.0)            # problems built inside the solve
        del probs
        te = time.perf_counter()
        self.timing["problem_seconds"] += ts - tp + lazy
        self.timing["solve_seconds"] += te - ts - lazy
        self.rounds.append({"L": int(L), "n_lps": len(ks), "n_translated": self.n_translated - n_tr0,
                            "problem_seconds": ts - tp + lazy, "solve_seconds": te - ts - lazy})
        self.n_solved_in_step += len(ks)
        done = []
        for k, v in zip(ks.tolist(), res):
            if isinstance(v, Pending):
                self.pending[k] = (L, v)
            else:
                done.append((k, L, v))
        self.sched.suspend([k for k, v in zip(ks.tolist(), res) if isinstance(v, Pending)])
        self._settle(done)
        log.info("L=%d: %d LPs, %d edges so far, %.0f LP/s; %s", L, len(ks),
                 len(self.edges) + sum(v.status == "edge" for _, _, v in self.buffer) + len(self.pending),
                 len(ks) / max(te - tp, 1e-9), self.sched.progress(te - self.t0 - self.timing["first_lp"]))

    def _solve_by_class(self, probs: list, src, dst, obstacle, defer: bool) -> list:
        """Verdicts of ``probs``, one representative per translation class first
        (:func:`~tubejax.abstraction.translations.solve_by_class`; without classes: all in one call)."""
        kw = {"defer": True} if defer else {}
        if self.classes is None or len(probs) < 2:
            probs = probs if isinstance(probs, list) else probs.take(range(len(probs)))
            return self.solve_batch(probs, progress=self.bar, **kw)
        out, n = solve_by_class(self.solve_batch, self.classes, probs, src, dst, obstacle, self.bar, **kw)
        self.n_translated += n
        return out

    def harvest(self, block: bool, limit: int | None = None) -> None:
        """Settle the confirmations that are done (all when ``block``; the oldest ones beyond ``limit``)."""
        tw = time.perf_counter()
        must = max(0, len(self.pending) - limit // 2) if limit is not None and len(self.pending) > limit else 0
        done, items, t_log = [], list(self.pending.items()), tw
        for n, (k, (L, pv)) in enumerate(items):
            if block or n < must or pv.done():
                done.append((k, L, pv.result()))
                del self.pending[k]
                if block and time.perf_counter() - t_log >= 10.0:       # a long wait shows its progress
                    t_log = time.perf_counter()
                    log.info("waiting for HiGHS: %d of %d likely edges confirmed, ~%s left", n + 1, len(items),
                             format_seconds((t_log - tw) / (n + 1) * (len(items) - n - 1)))
        self.timing["confirm_wait"] += time.perf_counter() - tw
        self._settle(done)
        refused = [k for k, _, v in done if v.status != "edge"]
        if refused:                              # held until the sweep ends: when HiGHS answered never
            self.sched.suspend(refused)          # changes which pairs a later chunk of this sweep holds
            self.held.update(refused)
        for k, L, v in done:
            if v.status != "edge":               # its later horizons are solved after all
                # a PDHG tube that HiGHS refuses was never seen; a near-zero margin may be < 0
                level = logging.INFO if v.provenance in ("highs-fallback", TRANSLATE_EDGE) else logging.WARNING
                log.log(level, "pair (%d, %d) at L=%d: likely edge but HiGHS says %s; its later horizons "
                        "are solved in the next sweep", self.cand.src[k], self.cand.dst[k], L, v.status)

    def release_held(self) -> None:
        """End of a sweep: the pairs whose likely edge HiGHS refused may be solved again."""
        if self.held:
            self.sched.release(sorted(self.held))
            self.held.clear()

    def _settle(self, done: list) -> None:
        if not done:
            return
        ks, Ls, vs = zip(*done)
        self.sched.settle(np.array(ks), np.array(Ls), np.array([v.status == "edge" for v in vs]))
        self.buffer += done
        self.verdicts.update(v.status for v in vs)
        self.provenance.update(v.provenance for v in vs)
        for v in vs:
            how = _decided_how(v)
            if how is not None:
                self.exact_step[how] += 1
        self.exact_step["seconds"] += sum(getattr(v, "exact_seconds", 0.0) for v in vs)
        if any(v.status == "edge" for v in vs):  # their later horizons are skipped
            self.bar.total = max(self.bar.n, self.n_settled + len(self.buffer) + self.sched.remaining())

    def write_step(self, L: int | None) -> None:
        """Commit the facts settled since the last step (to the store, then to ``on_round``)."""
        if not self.buffer:
            return
        c = self.cand
        new_e, new_t = [], []
        for k, Lk, v in self.buffer:
            if v.status == "edge":
                new_e.append(Edge.from_verdict(int(c.src[k]), int(c.dst[k]), Lk, v))
                new_t.append(v.tube)
            else:
                self.refused.append((int(c.src[k]), int(c.dst[k]), int(Lk), v.refutation))
        if self.store is not None:
            ks, Ls, vs = zip(*self.buffer)
            facts = Facts(np.array(ks), np.array(Ls), [v.status for v in vs], [v.provenance for v in vs],
                          new_e, new_t, refutations=[None if v.status == "edge" else v.refutation for v in vs],
                          pending=[(int(k), int(Lk), pv.provenance) for k, (Lk, pv) in self.pending.items()],
                          held=sorted(int(k) for k in self.held), sweep=self.sweep)
            self.store.append(L, facts, c.src, c.dst, self.method,
                              {"n_solved": self.n_solved_in_step, "seconds": time.perf_counter() - self.t0,
                               "exact_decisions": dict(self.exact_step)})
        self.n_settled += len(self.buffer)
        self.buffer, self.n_solved_in_step = [], 0
        self.exact.update(self.exact_step)
        self.exact_step = Counter()
        self.edges += new_e
        self.tubes += new_t
        if self.on_round is not None:
            self.on_round(self.L_max if L is None else L, new_e, new_t)

    # -- the result --------------------------------------------------------------------------
    def result(self, cand, pruning, zshape, solver_stats0, lp_rates) -> TransitionSystem:
        order = sorted(range(len(self.edges)), key=lambda k: (self.edges[k].src, self.edges[k].dst))
        edges = [self.edges[k] for k in order]
        tubes = [self.tubes[k] for k in order]
        N = self.decomp.n_cells
        t = self.timing
        seconds = time.perf_counter() - self.t0
        pruned = cand.pruned
        stats = {
            "n_cells": N, "n_edges": len(edges), "n_lps": self.n_settled, "seconds": seconds,
            "n_pairs": N * (N - 1), **cand.stats,
            "pruning": bool(pruning), "pruned": pruned, "n_pruned": int(sum(pruned.values())),
            "verdicts": dict(self.verdicts), "provenance": dict(self.provenance),
            "n_zero_margin": int(sum(abs(e.margin) <= ZERO_MARGIN_TOL for e in edges)),
            "n_unconfirmed": int(self.verdicts.get("unconfirmed", 0)),
            "L_max": int(self.L_max), "zshape": zshape, "confirm_wait_seconds": t["confirm_wait"],
            "seconds_before_first_lp": seconds if t["first_lp"] is None else t["first_lp"],
            "problem_seconds": t["problem_seconds"], "solve_seconds": t["solve_seconds"],
            "rounds": self.rounds, "resumed_lps": self.n_resumed,
            "n_translated": self.n_translated,
        }
        n_solved = sum(r["n_lps"] - r["n_translated"] for r in self.rounds)
        stats.update(lp_rates(solver_stats0, _numeric(getattr(self.solve_batch, "stats", None)),
                              {"n_lps": n_solved, "solve_seconds": t["solve_seconds"]}))
        stats["method"] = self.method
        stats["min_margin"] = self.min_margin
        nonedges = NonEdges(*(np.array([r[c] for r in self.refused], dtype=np.int64) for c in range(3)),
                            [r[3] for r in self.refused]).sorted() if self.refused else NonEdges.empty()
        stats["nonedge_evidence"] = nonedges.counts()
        stats["n_decided_exactly"] = {k: int(self.exact.get(k, 0)) for k in ("primal proof", "dual certificate",
                                                                            "exact solve")}
        stats["exact_decision_seconds"] = float(self.exact.get("seconds", 0.0))   # CPU s, wherever HiGHS ran
        ts = TransitionSystem(self.decomp, self.system, self.Z, edges, tubes, self.eps_min, self.method, stats,
                              min_margin=self.min_margin, nonedges=nonedges)
        ts.prove()              # proof levels: the verdicts proved the tubes, this the safe sets
        return ts


def _decided_how(v) -> str | None:
    """How a verdict was decided in exact arithmetic (:mod:`tubejax.lp.evidence.decide`), or ``None``."""
    if v.status == "edge" and v.proof is not None and v.proof.note.startswith("decided exactly ("):
        return "exact solve" if v.proof.note.startswith("decided exactly (exact solve") else "primal proof"
    r = getattr(v, "refutation", None)
    if v.status != "edge" and r is not None and r.kind in ("exact", "bounds"):
        return "exact solve" if (r.note or "").startswith("exact solve") else "dual certificate"
    return None


def _numeric(stats) -> dict:
    """The numeric entries of a solver's ``stats`` dict (a copy), or ``{}``."""
    if not isinstance(stats, dict):
        return {}
    return {k: v for k, v in stats.items() if isinstance(v, (int, float)) and not isinstance(v, bool)}


def _lp_rates(before: dict, after: dict, timing: dict) -> dict:
    """LP/s of the PDHG and HiGHS paths over this run (from the solver's counters when it has them).

    ``pdhg_lps_per_second``: LPs through PDHG over PDHG seconds (compile excluded);
    ``highs_lps_per_second``: HiGHS solves (confirmations + undecided) over the seconds spent
    inside HiGHS. A solver without counters (sequential HiGHS) is all HiGHS.
    """
    d = {k: after[k] - before.get(k, 0) for k in after}
    if "pdhg_seconds" not in d:
        if not after:
            return {"highs_lps_per_second": timing["n_lps"] / max(timing["solve_seconds"], 1e-9)}
        return {}
    n_highs = d.get("sent_to_highs", 0) + d.get("highs_confirmations", 0)
    n_pdhg = d.get("n_lps", 0) - d.get("translated_to_highs", 0)       # those went to HiGHS alone
    return {"pdhg_lps_per_second": n_pdhg / max(d["pdhg_seconds"], 1e-9),
            "highs_lps_per_second": n_highs / max(d.get("highs_cpu_seconds", 0.0), 1e-9),
            "n_highs_solves": int(n_highs)}
