"""A small pool of worker threads that runs the exact (HiGHS) solves by priority.

The batched solvers hand instances to HiGHS while PDHG goes on. Two kinds of
solve differ in urgency: a *fallback* (PDHG could not decide) gates the next
horizon round of Algorithm 2, while a *confirmation* of a likely edge (PDHG's own
primal point already satisfies Problem 2 in float64) only gates the final
transition system. Lower priority numbers run first; equal priorities run in
submission order, so the order of solves is deterministic for one worker.
HiGHS releases the GIL while it solves, so the workers overlap the PDHG run.
"""

from __future__ import annotations

import itertools
import queue
import threading
from concurrent.futures import Future
from typing import Callable

__all__ = ["PriorityWorkers", "URGENT", "BACKGROUND"]

#: Priority of a solve that the next round waits for.
URGENT = 0
#: Priority of a confirmation that only the final result waits for.
BACKGROUND = 1


class PriorityWorkers:
    """``n`` daemon threads taking ``(priority, fn, args)`` jobs from one priority queue.

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
            try:
                fut.set_result(fn(*args))
            except BaseException as exc:             # noqa: BLE001 -- handed to the caller
                fut.set_exception(exc)
