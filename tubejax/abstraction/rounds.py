"""The state of one run of Algorithm 2 (:func:`~tubejax.abstraction.build.build_abstraction`): its
schedule of pair horizons, the HiGHS confirmations still waiting, the settled facts not yet written
to the run store, the edges and non-edges found, and the run's statistics."""

from __future__ import annotations

import logging
import time
from collections import Counter
from collections.abc import Mapping

import numpy as np

from ..lp.evidence.verdict import TRANSLATE_EDGE, Pending
from ..lp.evidence.registry import formulation
from ..model.problem import Pairs, RoundProblems, pair_problems
from ..transitions.records import NonEdges
from ..transitions.transition_system import Edge, TransitionSystem
from .options import AbstractionOptions, RunIO
from .runstore import Facts, RunStoreError
from .schedule import PairSchedule, format_seconds
from .translation_classes import TranslationClasses, solve_by_class

__all__ = ["Rounds", "ZERO_MARGIN_TOL", "lp_rates", "numeric_stats"]

log = logging.getLogger("tubejax")

#: Edges with ``|t*|`` at or below this are flagged as zero-margin (valid, but only an exact solver confirms them).
ZERO_MARGIN_TOL = 1e-9


class Rounds:
    """The state of one run: schedule, waiting confirmations, settled facts not yet written, edges."""

    def __init__(self, decomp, system, Z, cand, options: AbstractionOptions, solve_batch, io: RunIO):
        """``options``: the run's settings; ``io``: its store, per-step callback, bar and start time."""
        self.decomp, self.system, self.Z, self.cand = decomp, system, Z, cand
        self.min_margin = float(options.min_margin)
        self.L_max, self.eps_min, self.method = int(options.L_max), float(options.eps_min), options.method
        self.solve_batch = solve_batch
        self.store, self.on_round, self.t0 = io.store, io.on_round, io.t0
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
        self.bar = io.bar
        # the class rule is sound for every method with an exact translation symmetry (its record says)
        by_class = bool(options.pruning) and formulation(options.method).translation_classes
        self.classes = TranslationClasses(decomp, system) if by_class else None
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
                probs = pair_problems(self.decomp, self.system, self.Z, Pairs(c.src[kk], c.dst[kk], c.obstacle[kk]),
                                      L, self.eps_min, min_margin=self.min_margin)
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
        pairs = Pairs(c.src[ks], c.dst[ks], c.obstacle[ks])
        if self.classes is not None:         # built as needed: most translates are settled by class
            probs = RoundProblems(self.decomp, self.system, self.Z, pairs, L, self.eps_min, min_margin=self.min_margin)
        else:
            probs = pair_problems(self.decomp, self.system, self.Z, pairs, L, self.eps_min, min_margin=self.min_margin)
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
        (:func:`~tubejax.abstraction.translation_classes.solve_by_class`; without classes: all in one call)."""
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
        times = Counter(map(id, vs))                # translates of a class share one verdict object
        for v in {id(v): v for v in vs}.values():
            c = times[id(v)]
            self.verdicts[v.status] += c
            self.provenance[v.provenance] += c
            how = _decided_how(v)
            if how is not None:
                self.exact_step[how] += c
            self.exact_step["seconds"] += c * getattr(v, "exact_seconds", 0.0)
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
        stats.update(lp_rates(solver_stats0, numeric_stats(getattr(self.solve_batch, "stats", None)),
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


def numeric_stats(stats) -> dict:
    """The numeric entries of a solver's ``stats`` mapping (a copy), or ``{}``."""
    if not isinstance(stats, Mapping):
        return {}
    return {k: v for k, v in stats.items() if isinstance(v, (int, float)) and not isinstance(v, bool)}


def lp_rates(before: dict, after: dict, timing: dict) -> dict:
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
