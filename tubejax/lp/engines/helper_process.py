"""The helper process of :class:`~tubejax.lp.engines.workers.ProcessWorkers`: its side of the pipes.
It runs batches of ``(priority, seq, fn, args)`` jobs from the request pipe, lowest first, sends each
result (or exception) back, and ends quietly when its caller stops it or is gone.
"""

from __future__ import annotations

import heapq
import os
import signal
import sys
import time
from multiprocessing.connection import Connection

__all__: list = []          # no public names: the module is run, not imported from


def _serve(requests, results):
    """The helper process: run queued jobs, the lowest ``(priority, seq)`` first.

    Returns (quietly) when the caller stops it (``None``) or is gone: its end of the request
    pipe is closed (EOF) or a result cannot be sent (a broken pipe), e.g. after ``kill -9`` of
    the caller. The jobs still queued are dropped: nobody waits for them.
    """
    heap: list = []
    while True:
        if not heap or requests.poll():
            try:
                msg = requests.recv()
            except (EOFError, OSError):              # the caller is gone
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
        if not _send_result(results, out):
            return


def _send_result(results, out) -> bool:
    """Send one result (an unpicklable one as an error); False when the caller is gone."""
    try:
        results.send(out)
        return True
    except OSError:                                  # BrokenPipeError, ConnectionResetError: no caller
        return False
    except Exception as exc:                         # noqa: BLE001 -- e.g. an unpicklable result
        err = (out[0], False, RuntimeError(f"result not transferable: {exc!r}"), 0.0)
    try:
        results.send(err)
        return True
    except OSError:
        return False


def _helper_main(argv: list[str]) -> int:
    """Entry point of a helper process (``python -m tubejax.lp.engines.helper_process REQ_FD RES_FD``).
    It ignores Ctrl-C and ends when its caller closes the pipes (also after ``kill -9``: status 0, no
    output, once its current job ends), so an interrupted run prints the caller's message only."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        _serve(Connection(int(argv[0]), writable=False), Connection(int(argv[1]), readable=False))
    except (BrokenPipeError, EOFError):              # a pipe closed anywhere else: the caller is gone
        pass
    try:                                             # stdout may be a pipe whose reader died with the caller
        sys.stdout.flush()
    except OSError:
        try:                                         # so that the flush at exit prints no BrokenPipeError
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        except OSError:
            pass
    return 0


if __name__ == "__main__":                            # the helper process of ProcessWorkers
    sys.exit(_helper_main(sys.argv[1:]))
