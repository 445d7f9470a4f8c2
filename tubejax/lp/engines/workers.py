"""Workers that run the exact (HiGHS) solves by priority: threads or helper processes.

The batched solvers hand instances to HiGHS while PDHG goes on: a *fallback* gates the next
horizon round, a *confirmation* only the final system; lower priority numbers run first, equal ones
in submission order. :class:`ProcessWorkers` runs the same jobs in helper processes, since building
LPs and re-checking tubes holds the GIL (docs/explanation/performance.md#highs-worker-processes);
jobs travel in batches, results come back one by one. The helper's side is
:mod:`tubejax.lp.engines.helper_process`.
"""

from __future__ import annotations

import heapq
import itertools
import logging
import os
import queue
import subprocess
import sys
import threading
import time
import weakref
from concurrent.futures import Future
from multiprocessing.connection import Connection
from typing import Callable

try:
    import fcntl                       # POSIX only: widening the helpers' pipes
except ImportError:                    # pragma: no cover
    fcntl = None

__all__ = ["PriorityWorkers", "ProcessWorkers", "shared_process_workers", "helper_counts", "URGENT", "BACKGROUND"]

log = logging.getLogger("tubejax")

#: Priority of a solve that the next round waits for.
URGENT = 0
#: Priority of a confirmation that only the final result waits for.
BACKGROUND = 1


class PriorityWorkers:
    """``n`` daemon threads taking ``(priority, fn, args)`` jobs from one priority queue.

    Each future gets an attribute ``seconds`` (time spent in ``fn``) before its result.

    Parameters
    ----------
    n : int
        Number of worker threads (started on the first :meth:`submit`).
    """

    def __init__(self, n: int = 1):
        if n < 1:
            raise ValueError(f"need at least one worker thread, got {n}")
        self.n = int(n)
        self._q: queue.PriorityQueue = queue.PriorityQueue()
        self._seq = itertools.count()
        self._threads: list[threading.Thread] = []
        self._lock = threading.Lock()

    def submit_many(self, jobs) -> list[Future]:
        """Queue ``(priority, fn, args)`` jobs; returns their futures."""
        return [self.submit(pri, fn, *args) for pri, fn, args in jobs]

    def submit(self, priority: int, fn: Callable, *args) -> Future:
        """Queue ``fn(*args)``; returns its :class:`~concurrent.futures.Future`."""
        with self._lock:
            if not self._threads:
                for k in range(self.n):
                    t = threading.Thread(target=self._loop, name=f"tubejax-highs-{k}", daemon=True)
                    t.start()
                    self._threads.append(t)
        fut: Future = Future()
        self._q.put((int(priority), next(self._seq), fut, fn, args))
        return fut

    def _loop(self):
        while True:
            _, _, fut, fn, args = self._q.get()
            if not fut.set_running_or_notify_cancel():
                continue
            t0 = time.perf_counter()
            try:
                res, exc = fn(*args), None
            except BaseException as e:               # noqa: BLE001 -- handed to the caller
                res, exc = None, e
            fut.seconds = time.perf_counter() - t0
            if exc is None:
                fut.set_result(res)
            else:
                fut.set_exception(exc)


class _BoostFuture(Future):
    """A future whose :meth:`result` lets the pool use its extra helpers while the caller waits
    (the caller's core is idle then)."""

    def __init__(self, pool: "ProcessWorkers"):
        super().__init__()
        self._pool = weakref.ref(pool)

    def result(self, timeout=None):
        pool = self._pool()
        if pool is None or self.done():
            return super().result(timeout)
        with pool.boosting():
            return super().result(timeout)


class _Helper:
    """One helper process: its pipe, a sender thread (sends never block the caller) and the
    number of jobs handed to it and not yet answered."""

    def __init__(self, proc, send: Connection):
        self.proc = proc
        self.send = send
        self.outstanding = 0
        self.queue: queue.SimpleQueue = queue.SimpleQueue()
        threading.Thread(target=self._send_loop, name="tubejax-highs-send", daemon=True).start()

    def _send_loop(self):
        while True:
            msg = self.queue.get()
            if msg is None:
                return
            try:
                self.send.send(msg)
            except (OSError, ValueError, BrokenPipeError):
                return                                # the helper is gone; its receiver fails the jobs


class ProcessWorkers:
    """Helper processes running ``(priority, fn, args)`` jobs, lowest priority first.

    ``fn`` and ``args`` must be picklable (``fn`` a module-level function). Each helper (``python -m
    tubejax.lp.engines.helper_process``, a fresh interpreter) starts on first use and stops when this
    object is collected or at exit; ``helpers`` always take work, ``boost_helpers`` more only while a
    caller's thread waits on a future. Each helper holds at most :attr:`CAP` jobs (urgent ones up to
    :attr:`URGENT_CAP`); a batch travels as one pickle. If a helper dies, its jobs' futures get the error
    and the next dispatch starts a new one; if none can start, jobs run on a thread
    (:class:`PriorityWorkers`). Each future gets an attribute ``seconds`` (time in ``fn``).

    Parameters
    ----------
    helpers : int
        Helpers that always take work (``>= 1``).
    boost_helpers : int
        Extra helpers used only while the caller waits for a result (``>= 0``).
    """

    #: Jobs a helper holds at most (docs/explanation/performance.md#highs-options).
    CAP = 16
    #: Urgent jobs join a helper's queue up to this many outstanding jobs (ahead of its background
    #: jobs); the rest wait here, so that an extra helper finds them once the caller waits.
    URGENT_CAP = 2 * CAP

    def __init__(self, helpers: int = 1, boost_helpers: int = 0):
        if int(helpers) < 1 or int(boost_helpers) < 0:
            raise ValueError(f"need at least one helper and no negative extras, got {helpers}, {boost_helpers}")
        self.n_helpers = int(helpers)
        self.n_boost = int(boost_helpers)
        self._lock = threading.Lock()
        self._seq = itertools.count()
        self._heap: list = []                          # (priority, seq, fn, args, future)
        self._pending: dict[int, tuple] = {}           # seq -> (future, helper)
        self._helpers: list = [None] * (self.n_helpers + self.n_boost)
        self._boost = 0
        self._fallback: PriorityWorkers | None = None
        self.stats = {"jobs": 0, "jobs_on_boost_helpers": 0, "helpers_started": 0}

    @property
    def _proc(self):
        """The first helper's process (None before it starts)."""
        h = self._helpers[0]
        return None if h is None else h.proc

    def processes(self) -> list:
        """The running helper processes (``subprocess.Popen`` objects)."""
        return [h.proc for h in self._helpers if h is not None]

    def _start(self) -> _Helper:
        # a plain ``python -m tubejax.lp.engines.helper_process`` child talking over two pipes: unlike
        # multiprocessing's spawn, it never re-imports the user's ``__main__`` module
        req_r, req_w = os.pipe()
        res_r, res_w = os.pipe()
        _widen_pipe(req_w)
        _widen_pipe(res_w)
        proc = subprocess.Popen([sys.executable, "-m", "tubejax.lp.engines.helper_process", str(req_r), str(res_w)],
                                pass_fds=(req_r, res_w), stdin=subprocess.DEVNULL)
        os.close(req_r)
        os.close(res_w)
        helper = _Helper(proc, Connection(req_w, readable=False))
        threading.Thread(target=self._receive, args=(Connection(res_r, writable=False), helper),
                         name="tubejax-highs-results", daemon=True).start()
        weakref.finalize(self, _stop, proc, helper.send, helper.queue)
        self.stats["helpers_started"] += 1
        return helper

    def _plan(self) -> list:
        """Hand queued jobs to helpers (caller holds the lock); returns ``[(helper, batch)]``."""
        if not self._heap:
            return []
        usable = self.n_helpers + (self.n_boost if self._boost > 0 else 0)
        for k in range(usable):
            if self._helpers[k] is None:
                self._helpers[k] = self._start()
        active = self._helpers[:usable]
        batches: dict = {}
        while self._heap:
            h = min(active, key=lambda a: a.outstanding)
            if h.outstanding >= (self.CAP if self._heap[0][0] > URGENT else self.URGENT_CAP):
                break
            pri, seq, fn, args, fut = heapq.heappop(self._heap)
            self._pending[seq] = (fut, h)
            h.outstanding += 1
            batches.setdefault(id(h), (h, []))[1].append((pri, seq, fn, args))
            self.stats["jobs"] += 1
            self.stats["jobs_on_boost_helpers"] += active.index(h) >= self.n_helpers
        return list(batches.values())

    @staticmethod
    def _post(batches):
        for h, batch in batches:
            h.queue.put(batch)

    def _receive(self, conn, helper: _Helper):
        while True:
            try:
                seq, ok, value, seconds = conn.recv()
            except (EOFError, OSError):
                break
            with self._lock:
                fut, _ = self._pending.pop(seq, (None, None))
                helper.outstanding -= 1
                batches = self._plan() if helper.outstanding <= self.CAP // 2 else []
            self._post(batches)
            if fut is None:
                continue
            fut.seconds = seconds
            if ok:
                fut.set_result(value)
            else:
                fut.set_exception(value)
        err = RuntimeError(f"the HiGHS helper process ended (exit code {helper.proc.poll()})")
        with self._lock:
            lost = [seq for seq, (_, h) in self._pending.items() if h is helper]
            futs = [self._pending.pop(seq)[0] for seq in lost]
            for k, h in enumerate(self._helpers):
                if h is helper:
                    self._helpers[k] = None
        helper.queue.put(None)
        for fut in futs:
            fut.set_exception(err)

    class _Boost:
        def __init__(self, pool):
            self.pool = pool

        def __enter__(self):
            p = self.pool
            with p._lock:
                p._boost += 1
                batches = p._plan() if p.n_boost else []
            p._post(batches)

        def __exit__(self, *exc):
            with self.pool._lock:
                self.pool._boost -= 1

    def boosting(self):
        """Context manager: while inside, the extra helpers take work too."""
        return ProcessWorkers._Boost(self)

    def submit_many(self, jobs) -> list[Future]:
        """Queue ``(priority, fn, args)`` jobs; returns their futures."""
        with self._lock:
            if self._fallback is None and self._helpers[0] is None:
                try:
                    self._helpers[0] = self._start()
                except OSError as exc:                # e.g. no pass_fds off POSIX: use threads
                    log.warning("HiGHS helper process could not start (%s); using a worker thread", exc)
                    self._fallback = PriorityWorkers(1)
            if self._fallback is not None:
                fallback = self._fallback
            else:
                fallback = None
                futs = []
                for pri, fn, args in jobs:
                    fut = _BoostFuture(self)
                    fut.set_running_or_notify_cancel()
                    heapq.heappush(self._heap, (int(pri), next(self._seq), fn, args, fut))
                    futs.append(fut)
                batches = self._plan()
        if fallback is not None:
            return fallback.submit_many(jobs)
        self._post(batches)
        return futs

    def submit(self, priority: int, fn: Callable, *args) -> Future:
        """Queue one job; returns its future."""
        return self.submit_many([(priority, fn, args)])[0]


#: Pipe capacity asked for (Linux; capped by ``/proc/sys/fs/pipe-max-size``, 1 MiB by default).
#: A batch of jobs or results is often several 100 kB; through the default 64 kB pipe it takes
#: many reads, each waiting for the GIL, while the helper stands still.
PIPE_BYTES = 1 << 22


def _widen_pipe(fd: int) -> None:
    """Enlarge the pipe of ``fd`` towards :data:`PIPE_BYTES` where the OS allows (else leave it)."""
    op = getattr(fcntl, "F_SETPIPE_SZ", None) if fcntl is not None else None
    if op is None:
        return
    try:
        with open("/proc/sys/fs/pipe-max-size") as f:
            size = min(PIPE_BYTES, int(f.read().strip()))
    except (OSError, ValueError):
        size = 1 << 20
    try:
        fcntl.fcntl(fd, op, size)
    except OSError:
        pass


def _stop(proc, conn, sendq=None):
    if sendq is not None:
        sendq.put(None)
    try:
        conn.send(None)
        conn.close()
    except Exception:                                # noqa: BLE001 -- already gone
        pass
    try:
        proc.wait(timeout=1.0)
    except subprocess.TimeoutExpired:
        proc.kill()


_SHARED: list[ProcessWorkers] = []


def helper_counts(cpus: int | None = None) -> tuple[int, int]:
    """``(helpers, boost_helpers)`` for a machine with ``cpus`` usable cores.

    The caller's process (the batched solver) keeps one core; the others run helpers, at
    least one and at most 8; one more helper runs while the caller waits for results.
    """
    if cpus is None:
        cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    helpers = max(1, min(int(cpus) - 1, 8))
    return helpers, (1 if int(cpus) > helpers else 0)


def shared_process_workers() -> ProcessWorkers:
    """The helper processes shared by every solver of this interpreter (started on first use;
    sized by :func:`helper_counts`)."""
    if not _SHARED:
        _SHARED.append(ProcessWorkers(*helper_counts()))
    return _SHARED[0]
