"""Issue 21 (runtime): a HiGHS helper process whose caller dies exits quietly.

A PDHG run killed with SIGKILL left its helper (``python -m tubejax.lp.engines.workers``)
printing a ``BrokenPipeError`` traceback when it finished its job and could not send the
result; Ctrl-C (SIGINT to the whole process group) reached the helper as well.
"""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

CALLER = """
import os, signal, sys, time
from tubejax.lp.engines.workers import ProcessWorkers
w = ProcessWorkers()
futs = w.submit_many([(1, abs, (-1,))] + [(1, time.sleep, (1.5,)) for _ in range(3)])
futs[0].result(timeout=60)                  # the helper runs
time.sleep(0.3)                             # ... and is inside the next job (1.5 s)
print(w.processes()[0].pid, flush=True)
os.kill(os.getpid(), signal.SIGKILL)
"""


def _gone(pid: int) -> bool:
    """The process has exited (no such process, or a zombie nobody reaps)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0] in ("Z", "X")
    except OSError:
        return True


def test_helper_exits_quietly_when_its_caller_is_killed(tmp_path):
    err = tmp_path / "stderr.txt"
    with open(err, "w") as f:
        p = subprocess.Popen([sys.executable, "-c", CALLER], stdout=subprocess.PIPE, stderr=f, text=True)
        helper = int(p.stdout.readline())
        assert p.wait(timeout=60) == -signal.SIGKILL
    deadline = time.monotonic() + 30
    while not _gone(helper) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert _gone(helper), "the helper outlived its caller by 30 s"
    text = err.read_text()
    assert "Traceback" not in text and "BrokenPipeError" not in text, text
    assert text == "", text


def test_helper_ignores_ctrl_c_and_still_answers():
    from tubejax.lp.engines.workers import ProcessWorkers

    w = ProcessWorkers()
    assert w.submit(1, abs, -1).result(timeout=60) == 1      # the helper runs
    fut = w.submit(1, time.sleep, 1.0)
    time.sleep(0.3)                                           # the helper is inside time.sleep
    os.kill(w.processes()[0].pid, signal.SIGINT)
    assert fut.result(timeout=60) is None
    assert w.submit(1, abs, -3).result(timeout=60) == 3
