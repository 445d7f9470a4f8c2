"""The HiGHS helper process survives requests and results larger than a pipe buffer.

Sending a request used to hold the lock that the result reader needs: with a request
larger than the pipe buffer and the helper blocked sending results, both sides waited
forever (seen in experiments/scaling.py at ~1,000 cells).
"""

import threading

from tubejax.lp.engines.workers import ProcessWorkers


def test_large_requests_and_results_do_not_deadlock():
    workers = ProcessWorkers()
    payload = b"x" * 100_000                          # > a 64 KiB pipe buffer, each way
    futures, done = [], threading.Event()

    def submit():
        for _ in range(30):
            futures.extend(workers.submit_many([(1, bytes, (payload,)) for _ in range(20)]))
        done.set()

    t = threading.Thread(target=submit, daemon=True)
    t.start()
    assert done.wait(30), "submit_many blocked: request and result pipes deadlocked"
    assert all(f.result(timeout=60) == payload for f in futures)
