"""The reference of the translation-class rule: Algorithm 2 with every instance decided on its own.

A run settles the translates of a class from one solve (:mod:`tubejax.abstraction.translation_classes`).
:func:`assert_each_instance_on_its_own` walks the run's candidates as Algorithm 2 does -- each pair's
unpruned horizons in increasing order, up to its first edge -- and decides every instance with its own
HiGHS verdict (:func:`~tubejax.lp.evidence.verdict.highs_verdict`), then demands the run's edges,
horizons and refused instances to be exactly those.
"""

from tubejax.abstraction.candidates import build_candidates
from tubejax.lp.evidence.verdict import highs_verdict
from tubejax.model.problem import pair_problem


def one_by_one(decomp, system, Z, L_max: int, method: str = "tube", eps_min: float = 0.0):
    """``(edges, refused)`` of Algorithm 2 on the pruned candidates, each instance solved alone:
    ``{(src, dst): L}`` and the set of ``(src, dst, L)`` refused on the way."""
    cand = build_candidates(decomp, system, int(L_max))
    edges, refused = {}, set()
    for i, j, keep in zip(cand.src.tolist(), cand.dst.tolist(), cand.keep):
        for L in (int(x) + 1 for x in keep.nonzero()[0]):
            v = highs_verdict(pair_problem(decomp, system, Z[i], i, j, L, eps_min), form=method)
            if v.status == "edge":
                edges[(i, j)] = L
                break
            refused.add((i, j, L))
    return edges, refused


def assert_each_instance_on_its_own(ts, decomp, system, Z, L_max: int, method: str = "tube",
                                    eps_min: float = 0.0) -> None:
    """The run ``ts`` has the edges, horizons and refused instances of :func:`one_by_one`."""
    edges, refused = one_by_one(decomp, system, Z, L_max, method, eps_min)
    assert {(e.src, e.dst): e.L for e in ts.edges} == edges
    assert set(ts.nonedges.index()) == refused
