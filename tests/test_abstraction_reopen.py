"""A likely edge that HiGHS refuses after later rounds skipped its pair: Algorithm 2's L all the same.

Found by the property tests (tests/properties): with deferred confirmations, a pair whose
likely edge at ``L0`` was refused only after round ``L > L0`` re-entered the rounds at
``L + 1``, so horizons ``L0 + 1 .. L`` were never solved and the edge could get a larger
``L`` than the minimal one -- depending on when the helper process answered. The fake
solver below fixes that timing, so the test is deterministic.
"""

from concurrent.futures import Future

import numpy as np
import pytest

from tubejax.abstraction import build_abstraction
from tubejax.model.geometry import Ball
from tubejax.lp.evidence.verdict import Pending, Verdict
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.workspace import box_grid


class _HelperFuture(Future):
    """The helper's answer: a refusal, given at the latest when someone waits for it."""

    def result(self, timeout=None):
        if not self.done():
            self.set_result(REFUSAL)
        return super().result(timeout)


REFUSAL = Verdict("infeasible", -1e-3, None, "highs")


class DeferringSolver:
    """Pair ``(0, 2)`` is an edge from ``L = 2`` on; at ``L = 1`` it is a likely edge whose
    confirmation (a refusal) arrives ``delay`` rounds later. Every other instance is infeasible."""

    supports_deferred = True

    def __init__(self, decomp, delay: int):
        self.cell = {id(c): i for i, c in enumerate(decomp.cells)}
        self.delay = delay
        self.waiting: list = []                   # (rounds left, future)
        self.solved: list = []                    # (i, j, L) of every instance solved

    def __call__(self, problems, progress=None, defer=False):
        for item in self.waiting:
            item[0] -= 1
        for rounds, fut in self.waiting:
            if rounds <= 0 and not fut.done():
                fut.set_result(REFUSAL)
        out = []
        for p in problems:
            i, j, L = self.cell[id(p.source)], self.cell[id(p.target)], int(p.L)
            self.solved.append((i, j, L))
            if (i, j) == (0, 2) and L == 1 and defer:
                fut = _HelperFuture()
                self.waiting.append([self.delay, fut])
                if self.delay == 0:
                    fut.set_result(REFUSAL)
                out.append(Pending(fut, "highs-fallback"))
            elif (i, j) == (0, 2) and L >= 2:
                out.append(Verdict("edge", 0.1, None, "pdhg+highs"))
            else:
                out.append(Verdict("infeasible", -1.0, None, "pdhg-certificate"))
        return out


@pytest.mark.parametrize("delay", [0, 1, 2, 5])
def test_refused_likely_edge_keeps_the_minimal_horizon(delay):
    d = box_grid([0.0, 0.0], [3.0, 1.0], [3, 1])
    s = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.1))
    solver = DeferringSolver(d, delay)
    ts = build_abstraction(d, s, L_max=4, pruning=False, solve_batch=solver, progress=False)
    assert [(e.src, e.dst, e.L) for e in ts.edges] == [(0, 2, 2)]
    # every horizon of the pair up to its edge is solved exactly once, in order
    assert [L for i, j, L in solver.solved if (i, j) == (0, 2)] == [1, 2]
    assert len(solver.solved) == len(set(solver.solved)) == ts.stats["n_lps"]
