"""The verdict (sign) mode of the batched engine: :meth:`PdhgBatchSolver.__call__
<tubejax.lp.solvers.batched.PdhgBatchSolver.__call__>`.

:func:`sign_batch` groups the problems by static shape and streams each group through the
pool (:func:`stream_group`, :func:`~tubejax.lp.solvers.pool.stream_pool`): chunks of
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
from .pdhg import FEASIBLE, INFEASIBLE, NEAR_ZERO, STATUS_NAMES, PdhgOptions
from .pool import bucket_width as _bucket, stream_pool
from .workers import BACKGROUND, URGENT

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


def stream_group(solver, probs: Sequence, key, on_done, opts: PdhgOptions):
    """PDHG on one shape group, streamed.

    The group is set up in chunks of ``solver.chunk`` instances as the pool needs them;
    each stopped instance's certificates are re-checked on the host at once
    (``formulation.certificates`` on its columns) and nothing of it is kept here.

    With ``solver.reuse_duals`` and a formulation ``dual_key``, the last certified dual of each
    key is kept, and each new chunk's instances are first checked against their key's dual on
    the host (the same ``formulation.certificates`` re-check): an instance whose own bound is
    below ``-margin_safety`` enters already ``INFEASIBLE`` with that dual as its certificate,
    and takes no place in the pool. Instances are streamed every key's first one first.

    Parameters
    ----------
    solver : PdhgBatchSolver
    probs : sequence of problems, one shape group (``B`` of them)
    key : tuple
        ``(L_pad, shape_key, ...)``: the group's padded horizon and static shape.
    on_done : callable
        ``on_done(instances, status, iterations, viol, bound)``: indices into ``probs`` and,
        per instance, its PDHG status, iteration count, the host-checked primal violation
        and the rigorous upper bound on its optimum; arrays of equal length.
    opts : PdhgOptions
    """
    L_pad, shape_key = key[0], key[1]
    f_pad = solver.facet_padding(L_pad, shape_key, probs)
    setups: dict = {}                                  # offset -> [shape, data, n, n_left]
    C = max(int(solver.chunk), 1)
    dual_key = solver.formulation.dual_key if getattr(solver, "reuse_duals", False) else None
    keys = [dual_key(p) for p in probs] if dual_key is not None else None
    perm = _first_of_each_key_first(keys) if keys is not None else np.arange(len(probs))
    duals: dict = {}                                   # dual key -> the last certified dual (m,)

    def reuse(shape, data, state, idx):
        """``state`` with the instances ``idx`` (into ``probs``) that their key's dual refutes
        already stopped, ``INFEASIBLE``."""
        have = np.array([a for a, k in enumerate(idx.tolist()) if keys[k] in duals], np.int64)
        if not have.size:
            return state
        Y = np.stack([duals[keys[idx[a]]] for a in have], axis=1)
        _, hb = solver.formulation.certificates(shape, _columns(data, have, len(idx)),
                                                np.asarray(state.x_best)[:, have], Y)
        ok = np.asarray(hb) < -opts.margin_safety
        hit = have[ok]
        status, y_cert, bound = (np.array(a, copy=True) for a in (state.status, state.y_cert, state.bound))
        status[hit] = INFEASIBLE
        y_cert[:, hit] = Y[:, ok]
        bound[hit] = np.asarray(hb)[ok]
        solver.stats["duals_reused"] += int(hit.size)
        return state._replace(status=status, y_cert=y_cert, bound=bound)

    def chunks():
        for c0 in range(0, len(probs), C):
            idx = perm[c0:c0 + C]
            shape, data, prob, state = solver.formulation.setup([probs[k] for k in idx], L_pad, f_pad, opts,
                                                              solver.share)
            setups[c0] = [shape, data, len(idx), len(idx)]
            if duals:
                state = reuse(shape, data, state, idx)
            if solver.dtype != np.float64:              # iterate in lower precision
                prob, state = jax.tree_util.tree_map(solver._cast, (prob, state))
            yield prob, state

    def done(inst, status, cols, lay):
        st = lay.unpack(cols)
        z = np.asarray(st.x_best, np.float64)
        y = np.asarray(st.y_cert, np.float64)
        for c0 in sorted(setups):
            info = setups[c0]
            sel = np.flatnonzero((inst >= c0) & (inst < c0 + info[2]))
            if not sel.size:
                continue
            viol, hb = solver.formulation.certificates(info[0], _columns(info[1], inst[sel] - c0, info[2]),
                                                     z[:, sel], y[:, sel])
            viol, hb = np.asarray(viol), np.asarray(hb)
            if keys is not None:
                for a in np.flatnonzero((status[sel] == INFEASIBLE) & (hb < -opts.margin_safety)).tolist():
                    duals[keys[perm[inst[sel[a]]]]] = y[:, sel[a]].copy()
            on_done(perm[inst[sel]], status[sel], np.asarray(st.it)[sel], viol, hb)
            info[3] -= sel.size
            if info[3] == 0:
                del setups[c0]

    def get_run(width, layouts):
        shape = next(iter(setups.values()))[0]
        return solver._runner(shape, width, None, None, opts, layouts=layouts)

    width = min(solver.pool, _bucket(len(probs), solver.min_bucket))
    tw = solver.tail_width
    stream_pool(get_run, chunks(), width, done, stats=solver.stats,
                tail=tw if tw and tw < width else None, put=solver._put)


#: At most this many translates go to HiGHS in one job (jobs spread over the helpers). Each job
#: solves and proves its class's canonical problem once (:mod:`tubejax.lp.evidence.translates`),
#: so larger jobs spread that over more members: on a ~1,000-cell map 256 instead of 64 took the
#: helpers' time for the translates from 6.2 to 4.7 s (identical verdicts).
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


def sign_batch(solver, problems: Sequence, progress=None, defer: bool = False, likely_edges=()) -> list:
    """The verdicts of :meth:`PdhgBatchSolver.__call__
    <tubejax.lp.solvers.batched.PdhgBatchSolver.__call__>` (see there; run in float64)."""
    sign = solver.options if solver.options.mode == "sign" else solver.options._replace(mode="sign")
    st = solver.stats
    lock = solver._lock
    st["n_lps"] += len(problems)
    out: list = [None] * len(problems)
    groups = defaultdict(list)
    groups_direct = _direct_groups(likely_edges, solver.formulation.verdicts is not None)
    direct = sorted(k for g in groups_direct for k in g)       # translates of likely edges: HiGHS alone
    skip = set(direct)
    for k, p in enumerate(problems):
        if k in skip:
            continue
        if not solver.formulation.batched(p):
            groups[None].append(k)
        else:
            groups[(solver._l_pad(int(p.L)),) + tuple(solver.formulation.group_key(p))].append(k)
    counts = defaultdict(int, st["status_counts"])
    fallback = list(groups.pop(None, []))
    futures: dict = {}
    near_zero: set = set()

    def count_seconds(f):
        with lock:
            st["highs_cpu_seconds"] += getattr(f, "seconds", 0.0)

    def submit(jobs):
        """Hand ``(k, priority)`` jobs to the HiGHS workers (one message); with the formulation's
        ``verdicts``, each as a group of one, so that every HiGHS answer of this solver is made
        the same way (:mod:`tubejax.lp.evidence.translates`: it depends on the problem alone)."""
        if solver.formulation.verdicts is not None:
            submit_groups([[k] for k, _ in jobs], [pri for _, pri in jobs])
            return
        fn = solver.formulation.verdict
        futs = solver._workers.submit_many([(pri, fn, (problems[k], "highs")) for k, pri in jobs])
        for (k, _), f in zip(jobs, futs):
            futures[k] = f
            f.add_done_callback(count_seconds)

    def submit_groups(gs, priorities=None):
        """Hand groups of translates to the HiGHS workers, one job per group (edges proved by
        exact translation where that holds and ``solver.translation_proofs``,
        :mod:`tubejax.lp.evidence.translates`)."""
        fn = solver.formulation.verdicts
        pri = [BACKGROUND] * len(gs) if priorities is None else priorities
        if fn is None:
            submit([(k, p) for g, p in zip(gs, pri) for k in g])
            return
        futs = solver._workers.submit_many([(p, fn, (ProblemPack([problems[k] for k in g]), "highs",
                                                     solver.translation_proofs)) for g, p in zip(gs, pri)])
        for g, f in zip(gs, futs):
            f.add_done_callback(count_seconds)
            for k, part in zip(g, split_future(f, len(g))):
                futures[k] = part

    submit([(k, URGENT) for k in fallback])
    submit_groups(groups_direct)
    for k in direct:
        out[k] = TRANSLATE_EDGE
        near_zero.add(k)                                    # likely edges: deferred like near-zero ones
    st["translated_to_highs"] += len(direct)
    safety, feas_tol = solver.options.margin_safety, solver.options.feas_tol
    for key, ks in groups.items():
        t0 = time.perf_counter()
        c0 = st["compile_seconds"]

        def finished(inst, status, its, viol, hb, ks=ks):
            """Verdicts of instances PDHG stopped: certified, or handed to HiGHS at once."""
            solver._iters += its.tolist()
            jobs = []
            for a, s_, v_, b_ in zip(inst.tolist(), status.tolist(), viol.tolist(), hb.tolist()):
                k = ks[a]
                counts[STATUS_NAMES[s_]] += 1
                if s_ == INFEASIBLE and b_ < -safety:
                    st["certified_infeasible"] += 1
                    out[k] = Verdict("infeasible", float(b_), None, "pdhg-certificate", None,
                                     Refutation("dual", float(b_)))
                    continue
                jobs.append((k, BACKGROUND if s_ in (FEASIBLE, NEAR_ZERO) else URGENT))
                if s_ == FEASIBLE and v_ <= feas_tol:
                    st["certified_feasible"] += 1
                    out[k] = "pdhg+highs"
                else:
                    out[k] = "highs-fallback"
                    if s_ == NEAR_ZERO:                 # t* >= -zero_tol: likely an edge
                        near_zero.add(k)
            submit(jobs)
            if progress is not None:
                progress.update(len(inst))

        stream_group(solver, [problems[k] for k in ks], key, finished, sign)
        st["pdhg_seconds"] += time.perf_counter() - t0 - (st["compile_seconds"] - c0)
    for k in fallback:
        out[k] = "highs-fallback"
    if progress is not None and direct:
        progress.update(len(direct))

    def confirmed(v):
        st["highs_confirmations"] += 1
        st["highs_disagreements"] += v.status != "edge"

    def decided(v):
        st["sent_to_highs"] += 1

    t0 = time.perf_counter()
    for k, f in futures.items():
        if defer and (out[k] == "pdhg+highs" or k in near_zero):
            out[k] = Pending(f, out[k], confirmed if out[k] == "pdhg+highs" else decided)
            continue
        v = stamped(f.result(), out[k])
        if out[k] == "pdhg+highs":
            confirmed(v)
        else:
            st["sent_to_highs"] += 1
        out[k] = v
        if progress is not None and k in fallback:
            progress.update(1)
    st["highs_wait_seconds"] += time.perf_counter() - t0
    if solver.exact:
        for k, v in enumerate(out):
            if v.provenance == "pdhg-certificate":
                ref = solver._verdict(problems[k], "highs")
                if ref.status == "edge":
                    st["highs_disagreements"] += 1
                    out[k] = ref
    st["status_counts"] = dict(counts)
    if solver._iters:
        st["iterations_median"] = float(np.median(solver._iters))
        st["iterations_p99"] = float(np.percentile(solver._iters, 99))
    return out

