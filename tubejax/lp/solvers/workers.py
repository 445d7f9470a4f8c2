"""Workers that run the exact (HiGHS) solves by priority: threads or a helper process.

The batched solvers hand instances to HiGHS while PDHG goes on. Two kinds of
solve differ in urgency: a *fallback* (PDHG could not decide) gates the next
horizon round of Algorithm 2, while a *confirmation* of a likely edge (PDHG's own
primal point already satisfies Problem 2 in float64) only gates the final
transition system. Lower priority numbers run first; equal priorities run in
submission order, so the order of solves is deterministic for one worker.
HiGHS releases the GIL while it solves, so the workers overlap the PDHG run.

:class:`ProcessWorkers` runs the same jobs in a helper process instead. Building
each LP and re-checking its tube is NumPy work that holds the GIL in short
bursts; in a thread it competes with the host side of the PDHG loop (measured on
a 2-core CPU: a HiGHS verdict took ~3.4 ms in the worker thread during a run
against ~1.3 ms alone). A process has its own interpreter, so the two never wait
for each other. Jobs travel in batches (one pickle per batch, so the shared
system and ``Z`` are sent once per batch) and results come back one by one.
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

__all__ = ["PriorityWorkers", "ProcessWorkers", "shared_process_workers", "URGENT", "BACKGROUND"]

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


def _serve(requests, results):
    """The helper process: run queued jobs, the lowest ``(priority, seq)`` first."""
    heap: list = []
    while True:
        if not heap or requests.poll():
            try:
                msg = requests.recv()
            except EOFError:
                return
            if msg is None:
                return
            for job in msg:
                heapq.heappush(heap, job)
            continue
        _, seq, fn, args = heapq.heappop(heap)
        t0 = time.perf_counter()
        try:
            out = (seq, True, fn(*args), time.perf_counter() - t0)
        except BaseException as exc:                 # noqa: BLE001 -- handed to the caller
            out = (seq, False, exc, time.perf_counter() - t0)
        try:
            results.send(out)
        except Exception as exc:                     # noqa: BLE001 -- e.g. an unpicklable result
            results.send((seq, False, RuntimeError(f"result not transferable: {exc!r}"), 0.0))


class ProcessWorkers:
    """One helper process running ``(priority, fn, args)`` jobs, lowest priority first.

    ``fn`` and ``args`` must be picklable (``fn`` a module-level function). The
    process (``python -m tubejax.lp.solvers.workers``: a fresh interpreter, so it is safe
    next to XLA's threads and never re-runs the caller's script) is started on the
    first :meth:`submit_many` and stopped when this object is collected or at exit.
    If it dies, every pending future gets the error and the next submission
    starts a new process; if it cannot start at all, the jobs run on a worker
    thread (:class:`PriorityWorkers`) instead. Each future gets an attribute
    ``seconds`` (time spent in ``fn`` in the helper) before its result.
    """

    def __init__(self):
        self._lock = threading.Lock()
        self._send_lock = threading.Lock()
        self._seq = itertools.count()
        self._pending: dict[int, Future] = {}
        self._proc = None
        self._send = None
        self._fallback: PriorityWorkers | None = None

    def _start(self):
        # a plain ``python -m tubejax.lp.solvers.workers`` child talking over two pipes: unlike
        # multiprocessing's spawn, it never re-imports the user's ``__main__`` module
        req_r, req_w = os.pipe()
        res_r, res_w = os.pipe()
        proc = subprocess.Popen([sys.executable, "-m", "tubejax.lp.solvers.workers", str(req_r), str(res_w)],
                                pass_fds=(req_r, res_w), stdin=subprocess.DEVNULL)
        os.close(req_r)
        os.close(res_w)
        self._proc, self._send = proc, Connection(req_w, readable=False)
        threading.Thread(target=self._receive, args=(Connection(res_r, writable=False), proc),
                         name="tubejax-highs-results", daemon=True).start()
        weakref.finalize(self, _stop, proc, self._send)

    def _receive(self, conn, proc):
        while True:
            try:
                seq, ok, value, seconds = conn.recv()
            except (EOFError, OSError):
                break
            with self._lock:
                fut = self._pending.pop(seq, None)
            if fut is None:
                continue
            fut.seconds = seconds
            if ok:
                fut.set_result(value)
            else:
                fut.set_exception(value)
        err = RuntimeError(f"the HiGHS helper process ended (exit code {proc.poll()})")
        with self._lock:
            lost, self._pending = list(self._pending.values()), {}
            if self._proc is proc:
                self._proc = None
        for fut in lost:
            fut.set_exception(err)

    def submit_many(self, jobs) -> list[Future]:
        """Queue ``(priority, fn, args)`` jobs (sent as one message); returns their futures."""
        futs, msg = [], []
        with self._lock:
            if self._fallback is None and self._proc is None:
                try:
                    self._start()
                except OSError as exc:                # e.g. no pass_fds off POSIX: use threads
                    log.warning("HiGHS helper process could not start (%s); using a worker thread", exc)
                    self._fallback = PriorityWorkers(1)
            if self._fallback is not None:
                return self._fallback.submit_many(jobs)
            for pri, fn, args in jobs:
                seq = next(self._seq)
                fut: Future = Future()
                fut.set_running_or_notify_cancel()
                self._pending[seq] = fut
                futs.append(fut)
                msg.append((int(pri), seq, fn, args))
            send = self._send
        if msg:
            # outside self._lock: a large message can block until the helper reads it, and the
            # helper only reads once the receiver thread (which takes self._lock) drains results
            with self._send_lock:
                send.send(msg)
        return futs

    def submit(self, priority: int, fn: Callable, *args) -> Future:
        """Queue one job; returns its future."""
        return self.submit_many([(priority, fn, args)])[0]


def _stop(proc, conn):
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


def shared_process_workers() -> ProcessWorkers:
    """The helper process shared by every solver of this interpreter (started on first use)."""
    if not _SHARED:
        _SHARED.append(ProcessWorkers())
    return _SHARED[0]


if __name__ == "__main__":                            # the helper process of ProcessWorkers
    _serve(Connection(int(sys.argv[1]), writable=False), Connection(int(sys.argv[2]), readable=False))
