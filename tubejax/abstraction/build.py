"""Algorithm 2: every ordered pair x horizon -> a verified transition system.

The pairs and horizons come from :func:`tubejax.abstraction.candidates.build_candidates` as sparse
arrays (a k-d tree over reach boxes, then the sound pruning rules; no all-pairs step).
Horizons run in rounds ``L = 1, 2, ..., L_max``; in each round every candidate pair
still without an edge (and not pruned at that ``L``) is handed to a batch solver, in chunks
that fit a memory budget (:class:`~tubejax.abstraction.schedule.MemoryBudget`). Each pair's horizons are
solved strictly in increasing order (:class:`~tubejax.abstraction.schedule.PairSchedule`), so its edge cost
is the minimal ``L`` (docs/math/tube-lp.md#paper-slips, slip 2). A batched solver may let the HiGHS confirmations
of likely edges run on into later rounds (``Pending``): the pair waits meanwhile, and if HiGHS
refuses, its later horizons are solved in a second sweep over the rounds. A solver returns one
:class:`Verdict` per problem; only ``status == 'edge'`` verdicts, whose tube passed
:func:`tube_violation` ``<= 1e-9``, enter the transition system.

With a :class:`~tubejax.abstraction.runstore.RunStore`, every finished step (a chunk and the
confirmations settled with it) is written to disk with its tubes, and a run interrupted at any
point resumes from those files to the identical result. ``shard=(K, k)`` solves only the pairs
whose source cell shard ``k`` owns (:mod:`tubejax.abstraction.shards`).
"""

from __future__ import annotations

import logging
import time
from typing import Callable

import numpy as np
from tqdm.auto import tqdm

from ..lp.evidence.verdict import Verdict, highs_solve_batch
from ..model.zshape.kinds import cross_sections
from ..lp.formulations.methods import check_state_constraints
from .methods import METHODS, check_solver, method_solver, solver_method
from .candidates import build_candidates
from .rounds import ZERO_MARGIN_TOL, Rounds, lp_rates, numeric_stats
from .runstore import RunStore, candidates_fingerprint
from .schedule import MemoryBudget
from .shards import select_shard
from ..model.system import LinearSystem
from ..transitions.transition_system import TransitionSystem
from .translations import TRANSLATE_PROVENANCE
from ..model.workspace.decomposition import CellDecomposition
from ..model.zassignment import ZAssignment

__all__ = ["Verdict", "highs_solve_batch", "build_abstraction", "cross_sections", "ZERO_MARGIN_TOL",
           "TRANSLATE_PROVENANCE", "METHODS", "method_solver", "solver_method"]

log = logging.getLogger("tubejax")

BatchSolver = Callable[..., list]


def build_abstraction(decomp: CellDecomposition, system: LinearSystem, *, zshape: str = "box",
                      z_scale: float = 1.0, L_max: int = 10, eps_min: float = 0.0,
                      pruning: bool = True, solve_batch: BatchSolver | None = None,
                      progress: bool = True, on_round: Callable | None = None,
                      method: str = "tube", memory_budget_mb: float | None = None,
                      shard: tuple[int, int] = (1, 0), store: RunStore | None = None,
                      min_margin: float = 0.0,
                      z: ZAssignment | tuple | None = None,
                      translations: bool | None = None) -> TransitionSystem:
    """Run Algorithm 2.

    Parameters
    ----------
    decomp : CellDecomposition
    system : LinearSystem
    zshape : str
        Cross-section kind (:func:`tubejax.model.zshape.kinds.make_z`); with ``z`` given,
        only the name recorded in ``stats['zshape']``.
    z_scale : float
        The size of ``Z`` (``make_z``'s ``scale``); ignored with ``z``.
    z : ZAssignment or sequence of Polytope, optional
        The cross-sections themselves instead of ``zshape``: one per cell (length ``N``), or a
        :class:`~tubejax.model.zassignment.ZAssignment` whose per-pair ``Z`` replace the source
        cell's for those pairs (``learned_pair``; Lemma 1 holds pair by pair). Every pair is
        decided and verified as with a per-cell ``Z``; the result's ``Z`` is this assignment
        and its files store the ``Z`` of every edge that has its own.
    L_max : int
        Largest horizon tried, ``>= 1``.
    pruning : bool
        Apply the sound necessary conditions of :mod:`tubejax.abstraction.pruning`, and settle the pairs of a
        round that are exact translates of a clearly infeasible one (:mod:`tubejax.abstraction.translations`;
        tube and open-loop methods: one representative per class is solved first, and the
        translates of a likely edge go straight to HiGHS).
    translations : bool, optional
        The translation-class rule alone (default: as ``pruning``); the result does not
        depend on it.
    solve_batch : callable, optional
        ``solve_batch(problems, progress=bar) -> list[Verdict]``; default: ``method``'s own
        reference solver (:func:`method_solver`: HiGHS on the tube or open-loop LP, or the exact
        polygon computation). A solver of another method (:func:`solver_method`) is refused. A
        solver with
        ``supports_deferred = True`` is called with ``defer=True`` in the first sweep and may
        return a :class:`~tubejax.lp.evidence.verdict.Pending` for a likely edge: the pair waits
        while its HiGHS confirmation runs on beside the later rounds, and the edge enters the
        result only once confirmed (if HiGHS disagrees, the pair's later horizons are solved in
        order after all, so the result is Algorithm 2's).
    method : {'tube', 'openloop', 'exact2d'}
        The problem solved for each pair (docs/math/tube-lp.md and docs/math/open-loop.md; exact2d: exact polygon
        backward reachability, 2-D), recorded in the result. It decides the default
        ``solve_batch``; a ``solve_batch`` of another method is refused (the evidence each
        one stores differs).
    on_round : callable, optional
        Called as ``on_round(L, new_edges, new_tubes)`` after each step (a chunk of round ``L``)
        with the edges confirmed since the last call (an edge carries its own ``L``).
    memory_budget_mb : float, optional
        Budget of the rounds' working set (:class:`~tubejax.abstraction.schedule.MemoryBudget`): rounds are
        solved in chunks that fit it, and the rounds pause while too many confirmations wait.
        ``None``: one chunk per round. The result does not depend on it.
    shard : (int, int)
        ``(count, index)``: solve only the pairs whose source cell shard ``index`` of ``count``
        owns (:func:`tubejax.abstraction.shards.select_shard`).
    store : RunStore, optional
        Write every finished step there, and first replay the steps already there (resume).
    min_margin : float
        The robustness margin an edge must have, in ``[0, 1)``: ``(i, j)`` gets the least ``L``
        whose margin ``t*`` (docs/math/margins.md) is at least ``min_margin``, and the stored tube
        achieves it (:func:`~tubejax.lp.evidence.verdict.confirm_with_highs`). 0 (the
        default) is Problem 2 itself. Not for ``method='exact2d'``, which has no margin.

    Returns
    -------
    TransitionSystem
        Its ``stats`` hold, besides the counts of edges, LPs and verdicts: ``n_pairs``
        (``N (N-1)``), ``n_candidate_pairs`` (from the spatial index), ``n_tested_pairs`` and
        ``n_obstacle_case_candidates`` / ``n_free_case_candidates`` (pairs whose obstacle case
        was computed), ``pruned`` (instances per reason of :data:`tubejax.abstraction.pruning.PRUNE_REASONS`),
        ``seconds_before_first_lp``, ``problem_seconds`` and ``solve_seconds`` (and per solver
        call in ``rounds``), the ``seconds_*`` of the candidate steps, ``pdhg_lps_per_second`` /
        ``highs_lps_per_second`` when the solver's counters (or a solver without them, all
        HiGHS) tell them, ``shard`` for a shard, and ``resumed_lps`` (instances read back from
        the store), and ``n_translated`` (non-edges settled by their translation class's
        representative, not solved). ``n_lps`` counts every instance settled, resumed and
        translated ones included.

    Raises
    ------
    InputError
        An unknown ``method``, or a ``solve_batch`` that solves another method's problems.
    RunStoreError
        The store's files belong to other instances, or are damaged or inconsistent.
    """
    if not isinstance(L_max, (int, np.integer)) or L_max < 1:
        raise ValueError(f"L_max must be an integer >= 1, got {L_max!r}")
    if decomp.dim != system.n:
        raise ValueError(f"the workspace is {decomp.dim}-D but the system state is {system.n}-D")
    if not (isinstance(min_margin, (int, float, np.floating)) and 0.0 <= float(min_margin) < 1.0):
        raise ValueError(f"min_margin must be a number in [0, 1), got {min_margin!r}")
    if float(min_margin) > 0 and method == "exact2d":
        raise ValueError("min_margin applies to the tube and open-loop methods; exact2d has no margin")
    solve_batch = check_solver(method, solve_batch)
    check_state_constraints(method, system)
    t0 = time.perf_counter()
    N = decomp.n_cells
    if z is None:
        Z = cross_sections(decomp, zshape, z_scale)
    else:
        Z = z if isinstance(z, ZAssignment) else tuple(z)
        if len(Z) != N:
            raise ValueError(f"z: expected one cross-section per cell ({N}), got {len(Z)}")
    if method != "tube" and any(z.n_vertices != c.n_vertices for z, c in zip(Z, decomp.cells)):
        raise ValueError(f"a Z with more vertices than its cell (zshape 'chamfer') applies to method 'tube', "
                         f"got method {method!r}")
    cand = build_candidates(decomp, system, int(L_max), pruning)
    count, index = (int(shard[0]), int(shard[1]))
    if count != 1 or index != 0:
        cand = select_shard(cand, N, count, index)
    budget = MemoryBudget(memory_budget_mb, decomp, system, Z)
    solver_stats0 = numeric_stats(getattr(solve_batch, "stats", None))
    supports_defer = bool(getattr(solve_batch, "supports_deferred", False))
    with tqdm(total=cand.n_instances, desc="tube LPs", unit="LP", disable=not progress, leave=False) as bar:
        by_class = bool(pruning) if translations is None else bool(translations)
        run = Rounds(decomp, system, Z, cand, int(L_max), float(eps_min), solve_batch, method, store, on_round,
                      t0, bar, float(min_margin), translations=by_class)
        if store is not None:
            run.replay(store.bind(candidates_fingerprint(cand, L_max, method)))
            bar.update(run.n_settled)
        while True:
            L0 = run.sched.min_open()
            if L0 is not None:
                run.sweep += 1                   # the first sweep defers; later ones solve refusals' horizons
                for L in range(L0, int(L_max) + 1):
                    ks = run.sched.open_at(L)
                    size = budget.chunk_size(L) or max(len(ks), 1)
                    for c in range(0, len(ks), size):
                        run.solve(L, ks[c:c + size], defer=supports_defer and run.sweep == 1)
                        run.harvest(block=False, limit=budget.max_pending())
                        run.write_step(L)
            elif not run.pending and not run.held:
                break
            run.harvest(block=True)              # every refusal known before the next sweep starts
            run.write_step(None)
            run.release_held()
    return run.result(cand, pruning, zshape, solver_stats0, lp_rates)
