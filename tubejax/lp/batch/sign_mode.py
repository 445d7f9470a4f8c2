"""The verdict (sign) mode of the batched engine: :meth:`PdhgBatchSolver.__call__
<tubejax.lp.batch.batch_solver.PdhgBatchSolver.__call__>`.

:func:`sign_batch` groups the problems by static shape and streams each group through the
pool (:func:`stream_group`, :func:`~tubejax.lp.engines.pool.stream_pool`): chunks of
``solver.chunk`` instances are set up as the pool needs them, and each instance that stops
is settled at once -- a dual bound re-checked on the host below ``-margin_safety`` certifies
it infeasible, anything else goes to HiGHS in the helper processes (fallbacks before
confirmations). Nothing per instance is kept beyond its verdict.
"""

from __future__ import annotations

import time
from collections import defaultdict
from concurrent.futures import Future
from typing import Sequence

import jax
import numpy as np

from ..evidence.decide import Refutation
from ...model.problem_pack import ProblemPack
from ..evidence.verdict import TRANSLATE_EDGE, Pending, Verdict, stamped
from ..engines.pdhg import FEASIBLE, INFEASIBLE, NEAR_ZERO, STATUS_NAMES, PdhgOptions
from ..engines.pdhg_adapters import host_flat_certificates, pdhg_setup
from ..engines.pool import stream_pool
from ..engines.workers import BACKGROUND, URGENT

__all__ = ["sign_batch", "stream_group"]


def _columns(data, idx: np.ndarray, n: int):
    """The instances ``idx`` of host data with the batch axis last (``n`` instances; a leaf of
    width 1 is shared by all of them when ``n > 1`` and is kept whole)."""
    return jax.tree_util.tree_map(lambda a: a if (n > 1 and a.shape[-1] == 1) else a[..., idx], data)


def _first_of_each_key_first(keys: list) -> np.ndarray:
    """A stable order of ``keys``' indices: every key's first instance, then every key's second,
    ..., so that the first chunks refute what the later ones can reuse. Shape ``(B,)``."""
    seen: dict = defaultdict(int)
    rank = np.empty(len(keys), np.int64)
    for a, k in enumerate(keys):
        rank[a] = seen[k]
        seen[k] += 1
    return np.argsort(rank, kind="stable")


class _GroupStream:
    """The state of one shape group streamed through the pool (:func:`stream_group`): the chunks
    set up and not yet settled, and the last certified dual of each dual key."""

    def __init__(self, solver, probs: Sequence, key, on_done, opts: PdhgOptions):
        self.solver, self.probs, self.on_done, self.opts = solver, probs, on_done, opts
        self.fm = solver.form
        self.L_pad = key[0]
        self.f_pad = solver.facet_padding(key[0], key[1], probs)
        self.setups: dict = {}                     # offset -> [shape, data, n, n_left]
        self.keys = [self.fm.dual_key(p) for p in probs] if self.fm.dual_key is not None else None
        self.perm = _first_of_each_key_first(self.keys) if self.keys is not None else np.arange(len(probs))
        self.duals: dict = {}                      # dual key -> the last certified dual (m,)

    def reuse(self, shape, data, state, idx):
        """``state`` with the instances ``idx`` (into ``probs``) that their key's dual refutes
        already stopped, ``INFEASIBLE``."""
        keys, duals = self.keys, self.duals
        have = np.array([a for a, k in enumerate(idx.tolist()) if keys[k] in duals], np.int64)
        if not have.size:
            return state
        Y = np.stack([duals[keys[idx[a]]] for a in have], axis=1)
        _, hb = host_flat_certificates(self.fm.operator, shape, _columns(data, have, len(idx)), np.asarray(state.x_best)[:, have], Y)
        ok = np.asarray(hb) < -self.opts.margin_safety
        hit = have[ok]
        status, y_cert, bound = (np.array(a, copy=True) for a in (state.status, state.y_cert, state.bound))
        status[hit] = INFEASIBLE
        y_cert[:, hit] = Y[:, ok]
        bound[hit] = np.asarray(hb)[ok]
        self.solver.tally.add("duals_reused", int(hit.size))
        return state._replace(status=status, y_cert=y_cert, bound=bound)

    def chunks(self):
        """``(prob, state)`` of each chunk of ``pooling.chunk`` instances, set up when asked for."""
        solver, C = self.solver, self.solver.pooling.chunk
        for c0 in range(0, len(self.probs), C):
            idx = self.perm[c0:c0 + C]
            shape, data, prob, state = pdhg_setup(self.fm, [self.probs[k] for k in idx], self.L_pad, self.f_pad,
                                                   self.opts, solver.pooling.share)
            self.setups[c0] = [shape, data, len(idx), len(idx)]
            if self.duals:
                state = self.reuse(shape, data, state, idx)
            if solver.dtype != np.float64:              # iterate in lower precision
                prob, state = jax.tree_util.tree_map(solver.cast, (prob, state))
            yield prob, state

    def done(self, inst, status, cols, lay) -> None:
        """Re-check the stopped instances' certificates on the host and hand them to ``on_done``."""
        st = lay.unpack(cols)
        z = np.asarray(st.x_best, np.float64)
        y = np.asarray(st.y_cert, np.float64)
        for c0 in sorted(self.setups):
            info = self.setups[c0]
            sel = np.flatnonzero((inst >= c0) & (inst < c0 + info[2]))
            if not sel.size:
                continue
            viol, hb = host_flat_certificates(self.fm.operator, info[0], _columns(info[1], inst[sel] - c0, info[2]),
                                              z[:, sel], y[:, sel])
            viol, hb = np.asarray(viol), np.asarray(hb)
            if self.keys is not None:
                for a in np.flatnonzero((status[sel] == INFEASIBLE) & (hb < -self.opts.margin_safety)).tolist():
                    self.duals[self.keys[self.perm[inst[sel[a]]]]] = y[:, sel[a]].copy()
            self.on_done(self.perm[inst[sel]], status[sel], np.asarray(st.it)[sel], viol, hb)
            info[3] -= sel.size
            if info[3] == 0:
                del self.setups[c0]

    def get_run(self, width, layouts):
        shape = next(iter(self.setups.values()))[0]
        return self.solver.runner(shape, width, None, None, self.opts, layouts=layouts)


def stream_group(solver, probs: Sequence, key, on_done, opts: PdhgOptions) -> None:
    """PDHG on one shape group, streamed.

    The group is set up in chunks of ``solver.pooling.chunk`` instances as the pool needs them;
    each stopped instance's certificates are re-checked on the host at once
    (:func:`~tubejax.lp.engines.pdhg_adapters.host_flat_certificates` of ``form.operator``) and nothing of it is kept here. With a form's ``dual_key``,
    each new chunk's instances are first checked on the host against the last certified dual of
    their key: one whose own bound is below ``-margin_safety`` enters ``INFEASIBLE`` with that dual
    as its certificate and takes no place in the pool (only instances PDHG could certify are).

    Parameters
    ----------
    solver : PdhgBatchSolver
    probs : sequence of problems, one shape group (``B`` of them)
    key : tuple
        ``(L_pad, shape_key, ...)``: the group's padded horizon and static shape.
    on_done : callable
        ``on_done(instances, status, iterations, viol, bound)``: indices into ``probs`` and, per
        instance, its PDHG status, iteration count, host-checked primal violation and rigorous
        upper bound on its optimum.
    opts : PdhgOptions
    """
    group = _GroupStream(solver, probs, key, on_done, opts)
    width = solver.width(len(probs))
    tw = solver.pooling.tail_width
    stream_pool(group.get_run, group.chunks(), width, group.done, stats=solver.tally,
                tail=tw if tw and tw < width else None, put=solver.put)


#: At most this many translates go to HiGHS in one job (jobs spread over the helpers; each solves and
#: proves its class's canonical problem once: docs/explanation/performance.md#translates-per-highs-job).
DIRECT_GROUP = 256


def _direct_groups(likely_edges, grouped: bool) -> list:
    """``likely_edges`` (ints, or sequences of ints) as a list of groups of at most
    :data:`DIRECT_GROUP` indices (each index its own group unless ``grouped``)."""
    out, seen = [], set()
    for item in likely_edges:
        g = [int(item)] if np.ndim(item) == 0 else [int(k) for k in item]
        g = [k for k in g if not (k in seen or seen.add(k))]
        if not grouped:
            out += [[k] for k in g]
            continue
        out += [g[a:a + DIRECT_GROUP] for a in range(0, len(g), DIRECT_GROUP)]
    return out


class _Part:
    """The ``k``-th answer of a job that answers a list, as much of a future as its users need
    (``done``, ``result``, ``exception``, ``seconds``); waiting on it waits on the job's future
    (so a pool that lends extra helpers to a waiting caller does so). Far lighter than a
    ``Future`` each: a group's members share the job's."""

    __slots__ = ("_whole", "_k", "_n")
    seconds = 0.0                     # the job's time is counted once, on the job's future

    def __init__(self, whole: Future, k: int, n: int):
        self._whole, self._k, self._n = whole, k, n

    def done(self) -> bool:
        return self._whole.done()

    def _outcome(self, timeout=None) -> tuple:
        """``(exception or None, the job's list)``, worked out once per job and kept on its future
        (a group's members all ask for it)."""
        whole = self._whole
        hit = getattr(whole, "_tubejax_outcome", None)
        if hit is not None:
            return hit
        try:
            whole.result(timeout)                   # the pool's futures lend helpers while waited on
        except Exception:                          # noqa: BLE001 -- returned below
            pass
        exc = whole.exception(timeout)             # raises TimeoutError if still running: nothing kept
        r = None
        if exc is None:
            r = whole.result()
            if not isinstance(r, list) or len(r) != self._n:
                exc = RuntimeError(f"a group job answered {type(r).__name__}, expected a list of {self._n}")
        whole._tubejax_outcome = (exc, r)
        return exc, r

    def exception(self, timeout=None):
        return self._outcome(timeout)[0]

    def result(self, timeout=None):
        exc, r = self._outcome(timeout)
        if exc is not None:
            raise exc
        return r[self._k]


def split_future(whole: Future, n: int) -> list:
    """``n`` future-like parts, the ``k``-th resolving to ``whole.result()[k]`` (or raising
    ``whole``'s exception, or a ``RuntimeError`` when ``whole`` answers no list of ``n``)."""
    return [_Part(whole, k, n) for k in range(n)]


class _HighsJobs:
    """The HiGHS answers of one call: jobs handed to the solver's workers, one future per problem.

    With the solver's ``verdicts`` every problem goes as a group (of one, or of exact
    translates), so that every HiGHS answer is made the same way
    (:mod:`tubejax.lp.evidence.translate_verdicts`: it depends on the problem alone)."""

    def __init__(self, solver, problems: Sequence):
        self.workers, self.tally = solver.workers, solver.tally
        self.verdict, self.verdicts = solver.verdict, solver.verdicts
        self.problems = problems
        self.futures: dict = {}                    # problem index -> future (or a part of a group's)

    def _count_seconds(self, f) -> None:
        with self.tally.lock:
            self.tally.add("highs_cpu_seconds", getattr(f, "seconds", 0.0))

    def submit(self, jobs) -> None:
        """Hand ``(k, priority)`` jobs to the HiGHS workers (one message)."""
        if self.verdicts is not None:
            self.submit_groups([[k] for k, _ in jobs], [pri for _, pri in jobs])
            return
        fn = self.verdict
        futs = self.workers.submit_many([(pri, fn, (self.problems[k], "highs")) for k, pri in jobs])
        for (k, _), f in zip(jobs, futs):
            self.futures[k] = f
            f.add_done_callback(self._count_seconds)

    def submit_groups(self, groups, priorities=None) -> None:
        """Hand groups of translates to the HiGHS workers, one job per group."""
        fn = self.verdicts
        pri = [BACKGROUND] * len(groups) if priorities is None else priorities
        if fn is None:
            self.submit([(k, p) for g, p in zip(groups, pri) for k in g])
            return
        futs = self.workers.submit_many([(p, fn, (ProblemPack([self.problems[k] for k in g]), "highs"))
                                         for g, p in zip(groups, pri)])
        for g, f in zip(groups, futs):
            f.add_done_callback(self._count_seconds)
            for k, part in zip(g, split_future(f, len(g))):
                self.futures[k] = part


def _shape_groups(solver, problems: Sequence, skip: set) -> tuple[dict, list]:
    """``({(L_pad, shape...): [k, ...]}, fallback)``: the problems PDHG takes, by padded horizon and
    static shape, and those the form does not batch (to HiGHS); ``skip`` left out."""
    groups, fallback = defaultdict(list), []
    for k, p in enumerate(problems):
        if k in skip:
            continue
        if not solver.form.batched(p):
            fallback.append(k)
        else:
            groups[(solver.l_pad(int(p.L)),) + tuple(solver.form.group_key(p))].append(k)
    return groups, fallback


class _SignCall:
    """One call of :func:`sign_batch`: its verdicts (or provenances waiting for HiGHS), the HiGHS
    jobs, the likely edges, and the solver's counters it adds to."""

    def __init__(self, solver, problems: Sequence, progress):
        self.solver, self.problems, self.progress = solver, problems, progress
        self.tally = solver.tally
        self.out: list = [None] * len(problems)
        self.jobs = _HighsJobs(solver, problems)
        self.near_zero: set = set()               # likely edges: deferred with ``defer``
        self.counts = defaultdict(int, self.tally["status_counts"])

    def finished(self, ks, inst, status, its, viol, hb) -> None:
        """Verdicts of instances PDHG stopped (``inst`` into the group ``ks``): certified, or handed
        to HiGHS at once (fallbacks before likely edges)."""
        safety, feas_tol = self.solver.options.margin_safety, self.solver.options.feas_tol
        self.tally.iterations += its.tolist()
        jobs = []
        for a, s_, v_, b_ in zip(inst.tolist(), status.tolist(), viol.tolist(), hb.tolist()):
            k = ks[a]
            self.counts[STATUS_NAMES[s_]] += 1            # the enumeration's names
            if s_ == INFEASIBLE and b_ < -safety:
                self.tally.add("certified_infeasible", 1)
                self.out[k] = Verdict("infeasible", float(b_), None, "pdhg-certificate", None,
                                      Refutation("dual", float(b_)))
                continue
            jobs.append((k, BACKGROUND if s_ in (FEASIBLE, NEAR_ZERO) else URGENT))
            if s_ == FEASIBLE and v_ <= feas_tol:
                self.tally.add("certified_feasible", 1)
                self.out[k] = "pdhg+highs"
            else:
                self.out[k] = "highs-fallback"
                if s_ == NEAR_ZERO:                 # t* >= -zero_tol: likely an edge
                    self.near_zero.add(k)
        self.jobs.submit(jobs)
        if self.progress is not None:
            self.progress.update(len(inst))

    def run_group(self, key, ks, opts: PdhgOptions) -> None:
        """PDHG on one shape group, its stopped instances settled as they stop."""
        t0, c0 = time.perf_counter(), self.tally["compile_seconds"]
        stream_group(self.solver, [self.problems[k] for k in ks], key,
                     lambda *a: self.finished(ks, *a), opts)
        self.tally.add("pdhg_seconds", time.perf_counter() - t0 - (self.tally["compile_seconds"] - c0))

    def _confirmed(self, v) -> None:
        self.tally.add("highs_confirmations", 1)
        self.tally.add("highs_disagreements", int(v.status != "edge"))

    def _decided(self, v) -> None:
        self.tally.add("sent_to_highs", 1)

    def collect(self, defer: bool, fallback: set) -> None:
        """Wait for the HiGHS answers (or, with ``defer``, leave a likely edge's pending)."""
        t0, out = time.perf_counter(), self.out
        for k, f in self.jobs.futures.items():
            if defer and (out[k] == "pdhg+highs" or k in self.near_zero):
                out[k] = Pending(f, out[k], self._confirmed if out[k] == "pdhg+highs" else self._decided)
                continue
            v = stamped(f.result(), out[k])
            if out[k] == "pdhg+highs":
                self._confirmed(v)
            else:
                self.tally.add("sent_to_highs", 1)
            out[k] = v
            if self.progress is not None and k in fallback:
                self.progress.update(1)
        self.tally.add("highs_wait_seconds", time.perf_counter() - t0)

    def check_exactly(self) -> None:
        """Re-solve every certified non-edge with HiGHS and count disagreements (``solver.exact``)."""
        for k, v in enumerate(self.out):
            if v.provenance == "pdhg-certificate":
                ref = self.solver.verdict(self.problems[k], "highs")
                if ref.status == "edge":
                    self.tally.add("highs_disagreements", 1)
                    self.out[k] = ref


def sign_batch(solver, problems: Sequence, progress=None, defer: bool = False, likely_edges=()) -> list:
    """The verdicts of :meth:`PdhgBatchSolver.__call__
    <tubejax.lp.batch.batch_solver.PdhgBatchSolver.__call__>` (see there; run in float64)."""
    sign = solver.options if solver.options.mode == "sign" else solver.options._replace(mode="sign")
    call = _SignCall(solver, problems, progress)
    call.tally.add("n_lps", len(problems))
    groups_direct = _direct_groups(likely_edges, solver.verdicts is not None)
    direct = sorted(k for g in groups_direct for k in g)       # translates of likely edges: HiGHS alone
    groups, fallback = _shape_groups(solver, problems, set(direct))
    call.jobs.submit([(k, URGENT) for k in fallback])
    call.jobs.submit_groups(groups_direct)
    for k in direct:
        call.out[k] = TRANSLATE_EDGE
        call.near_zero.add(k)                               # likely edges: deferred like near-zero ones
    call.tally.add("translated_to_highs", len(direct))
    for key, ks in groups.items():
        call.run_group(key, ks, sign)
    for k in fallback:
        call.out[k] = "highs-fallback"
    if progress is not None and direct:
        progress.update(len(direct))
    call.collect(defer, set(fallback))
    if solver.exact:
        call.check_exactly()
    call.tally["status_counts"] = dict(call.counts)
    return call.out
