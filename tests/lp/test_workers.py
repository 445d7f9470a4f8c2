"""The HiGHS workers: threads and the helper process run jobs by priority and hand back results."""

import math
import time

import pytest

from tubejax.lp.engines.workers import BACKGROUND, URGENT, PriorityWorkers, ProcessWorkers, shared_process_workers


@pytest.fixture(scope="module", params=["threads", "process"])
def workers(request):
    return PriorityWorkers(1) if request.param == "threads" else shared_process_workers()


def test_results_and_errors_come_back(workers):
    futs = workers.submit_many([(URGENT, math.sqrt, (4.0,)), (BACKGROUND, math.sqrt, (-1.0,)),
                                (URGENT, math.hypot, (3.0, 4.0))])
    assert futs[0].result(timeout=60) == 2.0
    with pytest.raises(ValueError):
        futs[1].result(timeout=60)
    assert futs[2].result(timeout=60) == 5.0
    assert all(f.seconds >= 0.0 for f in futs)


def test_urgent_jobs_run_first(workers):
    # one batch: the background job was queued first but the urgent ones run before it
    # (time.monotonic is system-wide, so the helper's clock readings compare)
    blocker = workers.submit(URGENT, time.sleep, 0.2)      # keeps the worker busy meanwhile
    futs = workers.submit_many([(BACKGROUND, time.monotonic, ()), (URGENT, time.monotonic, ()),
                                (URGENT, time.monotonic, ())])
    blocker.result(timeout=60)
    t_bg, t_u1, t_u2 = (f.result(timeout=60) for f in futs)
    assert t_u1 <= t_u2 < t_bg


def test_a_dead_helper_fails_its_jobs_and_restarts():
    w = ProcessWorkers()
    assert w.submit(URGENT, math.sqrt, 9.0).result(timeout=60) == 3.0
    pending = w.submit(URGENT, time.sleep, 30.0)
    w._proc.kill()
    with pytest.raises(RuntimeError, match="helper process ended"):
        pending.result(timeout=60)
    assert w.submit(URGENT, math.sqrt, 16.0).result(timeout=60) == 4.0


def test_no_worker_threads_is_an_error():
    with pytest.raises(ValueError, match="at least one worker"):
        PriorityWorkers(0)


def test_a_helper_that_cannot_start_falls_back_to_a_thread(monkeypatch):
    w = ProcessWorkers()

    def fail():
        raise OSError("no processes here")
    monkeypatch.setattr(w, "_start", fail)
    assert w.submit(URGENT, math.sqrt, 25.0).result(timeout=60) == 5.0
    assert isinstance(w._fallback, PriorityWorkers)


def test_the_boost_helper_works_only_while_a_result_is_awaited():
    w = ProcessWorkers(helpers=1, boost_helpers=1)
    n = 4 * ProcessWorkers.CAP
    futs = w.submit_many([(BACKGROUND, time.sleep, (0.005,)) for _ in range(n)])
    time.sleep(0.1)                                   # nobody waits: one helper, at most CAP jobs
    handed = w.stats["jobs"]
    assert w.stats["jobs_on_boost_helpers"] == 0 and len(w.processes()) == 1
    assert handed <= ProcessWorkers.CAP + sum(f.done() for f in futs) + 1     # + one being answered
    futs[-1].result(timeout=60)                       # waiting: the second helper joins
    assert [f.result(timeout=60) for f in futs] == [None] * n
    assert len(w.processes()) == 2 and w.stats["jobs_on_boost_helpers"] > 0
    assert w.stats["jobs"] == n
    # urgent jobs skip the queue even while the helper is full
    futs = w.submit_many([(BACKGROUND, time.sleep, (0.005,)) for _ in range(n)])
    t_urgent = w.submit(URGENT, time.monotonic).result(timeout=60)
    assert sum(f.done() for f in futs) < n and t_urgent > 0
    assert [f.result(timeout=60) for f in futs] == [None] * n


def test_helper_counts_keep_a_core_for_the_caller():
    from tubejax.lp.engines.workers import helper_counts
    assert helper_counts(1) == (1, 0)
    assert helper_counts(2) == (1, 1)
    assert helper_counts(4) == (3, 1)
    assert helper_counts(64) == (8, 1)


def test_a_batch_of_urgent_jobs_is_shared_with_the_boost_helper():
    """Urgent jobs beyond URGENT_CAP stay queued, so the extra helper takes part of them while
    the caller waits (handed all to one helper, they left the second core idle)."""
    w = ProcessWorkers(helpers=1, boost_helpers=1)
    n = 6 * ProcessWorkers.URGENT_CAP
    futs = w.submit_many([(URGENT, time.sleep, (0.005,)) for _ in range(n)])
    assert w.stats["jobs"] <= ProcessWorkers.URGENT_CAP and len(w.processes()) == 1
    assert [f.result(timeout=60) for f in futs] == [None] * n
    assert len(w.processes()) == 2 and w.stats["jobs_on_boost_helpers"] > 0 and w.stats["jobs"] == n
