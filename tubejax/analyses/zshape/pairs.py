"""Learned ``Z`` as tables, per-pair learning, and Algorithm 2 with one ``Z`` per ordered pair.

:func:`pair_abstraction` runs Algorithm 2 with ``z_of_pair(i, j)`` (Lemma 1 holds pair by pair), one
HiGHS solve at a time: the reference :func:`tubejax.abstraction.build_abstraction` with
``zshape=learned_pair`` is tested against. Every edge is decided, verified and proved as there;
:meth:`PairAbstraction.verify` re-checks them.
"""

from __future__ import annotations

import time
from typing import Callable, NamedTuple

import numpy as np

from ...lp.evidence.safe_set import prove_safe_set
from ...lp.evidence.verdict import VERIFY_TOL, highs_verdict
from ...lp.declarations.tube_lp import tube_violation
from ...model.zshape.kinds import make_z
from ...model.problem import pair_problem
from ...transitions.transition_system import Edge
from .learn import LearnedZ, LearnOptions, candidate_pairs, learn_z
from ...model.zshape.z_table import ZTable

__all__ = ["table_from_learned", "learn_pair_z", "pair_abstraction", "PairAbstraction"]


def table_from_learned(result: LearnedZ, decomp, extra: dict | None = None) -> ZTable:
    """The :class:`ZTable` of a learning result (with its history as provenance)."""
    learning = {"mode": result.mode, "family": result.family.kind, "seconds": result.seconds,
                "n_lps": result.n_lps, "history": result.history, **(extra or {})}
    P = result.polytopes()
    if result.mode == "learned":
        shapes = [(decomp.cells[i].vertices, p.vertices) for i, p in zip(result.group_cells, P)]
        return ZTable("learned", result.family.n, shapes, None, learning)
    pairs = {(int(i), int(j)): P[g].vertices for (i, j), g in zip(result.pairs, result.group_of_pair)}
    return ZTable("learned_pair", result.family.n, (), pairs, learning)


def learn_pair_z(decomp, system, *, init="box", options: LearnOptions = LearnOptions(), progress: bool = True,
                 pairs=None) -> dict:
    """One ``Z`` per candidate pair, all optimised at once: ``{(i, j): Polytope}``.

    Parameters as :func:`~tubejax.analyses.zshape.learn.learn_z` (``mode='learned_pair'``); e.g.
    ``init=lambda i, j: table.z_for_cell(decomp.cells[i])`` starts from a shared learned ``Z``.
    """
    res = learn_z(decomp, system, mode="learned_pair", init=init, options=options, progress=progress, pairs=pairs)
    P = res.polytopes()
    return {(int(i), int(j)): P[g] for (i, j), g in zip(res.pairs, res.group_of_pair)}


class PairAbstraction(NamedTuple):
    """Algorithm 2's result with one ``Z`` per pair.

    Attributes
    ----------
    edges : list of Edge          sorted by ``(src, dst)``; ``proof`` is ``'exact'`` or ``'float'``
    tubes : list of Tube          HiGHS's tubes (float64; the rational one's rounding when proved)
    Z : dict (i, j) -> Polytope   the cross-section of every pair that was solved
    problems : list               the TubeProblem of each edge
    stats : dict                  ``n_edges``, ``n_lps``, ``seconds``, ``proof`` counts
    """

    edges: list
    tubes: list
    Z: dict
    problems: list
    stats: dict

    def verify(self, tol: float = VERIFY_TOL) -> np.ndarray:
        """Re-check every stored tube in float64; returns the violations ``(n_edges,)``.

        Raises
        ------
        AssertionError
            An edge whose tube violates Problem 2 by more than ``tol``.
        """
        v = np.array([tube_violation(p, t) for p, t in zip(self.problems, self.tubes)])
        bad = np.flatnonzero(~(v <= tol))
        if bad.size:
            e = self.edges[bad[0]]
            raise AssertionError(f"{bad.size} edges fail re-verification, e.g. {e.src}->{e.dst} (L={e.L}) "
                                 f"with violation {v[bad[0]]:.3e}")
        return v


def pair_abstraction(decomp, system, z_of_pair: Callable, *, L_max: int = 10, eps_min: float = 0.0,
                     pruning: bool = True, fallback: str | None = "box") -> PairAbstraction:
    """Algorithm 2 with ``Z = z_of_pair(i, j)`` for the pair ``(i, j)`` (see the module docstring).

    Parameters
    ----------
    z_of_pair : callable or dict
        ``(i, j) -> Polytope``; a dict may miss pairs, which then use ``make_z(fallback, P_i)``
        (``fallback=None``: such pairs are skipped).
    """
    t0 = time.perf_counter()
    get = z_of_pair.get if isinstance(z_of_pair, dict) else z_of_pair
    _, keep = candidate_pairs(decomp, system, L_max, pruning)
    N = decomp.n_cells
    found = np.zeros((N, N), dtype=bool)
    Z: dict = {}
    edges, tubes, probs = [], [], []
    n_lps = 0
    for L in range(1, L_max + 1):
        for i, j in np.argwhere(keep[:, :, L - 1] & ~found):
            i, j = int(i), int(j)
            if (i, j) not in Z:
                z = get((i, j)) if isinstance(z_of_pair, dict) else get(i, j)
                if z is None and fallback is not None:
                    z = make_z(fallback, decomp.cells[i])
                Z[(i, j)] = z
            if Z[(i, j)] is None:
                continue
            prob = pair_problem(decomp, system, Z[(i, j)], i, j, L, eps_min)
            v = highs_verdict(prob)
            n_lps += 1
            if v.status != "edge":
                continue
            e = Edge.from_verdict(i, j, L, v)
            if e.proof == "exact" and not prove_safe_set(prob.safe, decomp.obstacles)[0]:
                e = Edge(e.src, e.dst, e.L, e.margin, e.provenance, "float", float(tube_violation(prob, v.tube)),
                         e.exact)
            found[i, j] = True
            edges.append(e)
            tubes.append(v.tube)
            probs.append(prob)
    order = sorted(range(len(edges)), key=lambda k: (edges[k].src, edges[k].dst))
    proof = {lvl: sum(edges[k].proof == lvl for k in order) for lvl in ("exact", "float")}
    stats = {"n_edges": len(edges), "n_lps": n_lps, "seconds": time.perf_counter() - t0, "proof": proof,
             "L_max": int(L_max), "zshape": "learned_pair"}
    return PairAbstraction([edges[k] for k in order], [tubes[k] for k in order], Z,
                           [probs[k] for k in order], stats)
