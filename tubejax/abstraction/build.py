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

from tqdm.auto import tqdm

from ..lp.evidence.verdict import Verdict, highs_solve_batch
from ..model.zshape.kinds import cross_sections
from ..lp.evidence.method_families import check_state_constraints
from ..lp.evidence.registry import FORMULATIONS, formulation
from .methods import METHODS, check_solver, method_solver, solver_method
from .candidates import build_candidates
from .options import AbstractionOptions, RunIO
from .rounds import ZERO_MARGIN_TOL, Rounds, lp_rates, numeric_stats
from .runstore import candidates_fingerprint
from .schedule import MemoryBudget
from .shards import select_shard
from ..model.system import LinearSystem
from ..transitions.transition_system import TransitionSystem
from .translation_classes import TRANSLATE_PROVENANCE
from ..model.workspace.decomposition import CellDecomposition
from ..model.zassignment import ZAssignment

__all__ = ["Verdict", "highs_solve_batch", "build_abstraction", "AbstractionOptions", "RunIO", "cross_sections", "ZERO_MARGIN_TOL",
           "TRANSLATE_PROVENANCE", "METHODS", "method_solver", "solver_method"]

log = logging.getLogger("tubejax")

BatchSolver = Callable[..., list]


def build_abstraction(decomp: CellDecomposition, system: LinearSystem, options: AbstractionOptions | None = None, *,
                      z: ZAssignment | tuple | None = None, solve_batch: BatchSolver | None = None,
                      io: RunIO | None = None, progress: bool = True, **fields) -> TransitionSystem:
    """Run Algorithm 2.

    Parameters
    ----------
    decomp : CellDecomposition
    system : LinearSystem
    options : AbstractionOptions, optional
        The run's settings (:class:`~tubejax.abstraction.options.AbstractionOptions`: ``L_max``,
        ``eps_min``, ``min_margin``, ``method``, ``zshape``, ``z_scale``, ``pruning``,
        ``translations``, ``memory_budget_mb``, ``shard``); default: its defaults.
    z : ZAssignment or sequence of Polytope, optional
        The cross-sections themselves instead of ``options.zshape``: one per cell (length ``N``), or a
        :class:`~tubejax.model.zassignment.ZAssignment` whose per-pair ``Z`` replace the source
        cell's for those pairs (``learned_pair``; Lemma 1 holds pair by pair). Every pair is
        decided and verified as with a per-cell ``Z``; the result's ``Z`` is this assignment
        and its files store the ``Z`` of every edge that has its own.
    solve_batch : callable, optional
        ``solve_batch(problems, progress=bar) -> list[Verdict]``; default: the method's own
        reference solver (:func:`method_solver`); one of another method (:func:`solver_method`)
        is refused. One with ``supports_deferred = True`` is called with ``defer=True`` in the
        first sweep and may return a :class:`~tubejax.lp.evidence.verdict.Pending` for a likely
        edge: the pair waits while HiGHS confirms it beside the later rounds (if HiGHS disagrees,
        the pair's later horizons are solved in order after all: the result is Algorithm 2's).
    io : RunIO, optional
        ``store``: write every finished step to that :class:`~tubejax.abstraction.runstore.RunStore`,
        and first replay the steps already there (resume); ``on_round``: called as
        ``on_round(L, new_edges, new_tubes)`` after each step (a chunk of round ``L``) with the
        edges confirmed since the last call (an edge carries its own ``L``).
    progress : bool
        Show a progress bar.
    **fields
        Fields of :class:`AbstractionOptions` (``L_max=5``, ``method='openloop'``) replacing those
        of ``options``, and ``store`` / ``on_round`` replacing those of ``io``.

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
    io = (io or RunIO())._replace(**{k: fields.pop(k) for k in ("store", "on_round") if k in fields})
    opt = (options or AbstractionOptions()).replace(**fields)
    if decomp.dim != system.n:
        raise ValueError(f"the workspace is {decomp.dim}-D but the system state is {system.n}-D")
    solve_batch = check_solver(opt.method, solve_batch)
    check_state_constraints(opt.method, system)
    t0 = time.perf_counter()
    Z = _cross_sections(decomp, opt, z)
    cand = build_candidates(decomp, system, int(opt.L_max), opt.pruning)
    count, index = (int(opt.shard[0]), int(opt.shard[1]))
    if count != 1 or index != 0:
        cand = select_shard(cand, decomp.n_cells, count, index)
    budget = MemoryBudget(opt.memory_budget_mb, decomp, system, Z)
    solver_stats0 = numeric_stats(getattr(solve_batch, "stats", None))
    with tqdm(total=cand.n_instances, desc="tube LPs", unit="LP", disable=not progress, leave=False) as bar:
        run = Rounds(decomp, system, Z, cand, opt, solve_batch, io._replace(bar=bar, t0=t0))
        if io.store is not None:
            run.replay(io.store.bind(candidates_fingerprint(cand, opt.L_max, opt.method)))
            bar.update(run.n_settled)
        _sweep(run, budget, int(opt.L_max), bool(getattr(solve_batch, "supports_deferred", False)))
    return run.result(cand, opt.pruning, opt.zshape, solver_stats0, lp_rates)


def _cross_sections(decomp: CellDecomposition, opt: AbstractionOptions, z):
    """The run's cross-sections: ``z`` when given (one per cell), else ``opt.zshape`` on every cell."""
    N = decomp.n_cells
    if z is None:
        Z = cross_sections(decomp, opt.zshape, opt.z_scale)
    else:
        Z = z if isinstance(z, ZAssignment) else tuple(z)
        if len(Z) != N:
            raise ValueError(f"z: expected one cross-section per cell ({N}), got {len(Z)}")
    if not formulation(opt.method).tubes and any(z.n_vertices != c.n_vertices for z, c in zip(Z, decomp.cells)):
        able = " or ".join(repr(n) for n, f in FORMULATIONS.items() if f.tubes)
        raise ValueError(f"a Z with more vertices than its cell (zshape 'chamfer') applies to method {able}, "
                         f"got method {opt.method!r}")
    return Z


def _sweep(run: Rounds, budget: MemoryBudget, L_max: int, supports_defer: bool) -> None:
    """The rounds ``L = 1 .. L_max`` over every open pair, in chunks that fit ``budget``, sweep after
    sweep until no pair is open and no confirmation waits."""
    while True:
        L0 = run.sched.min_open()
        if L0 is not None:
            run.sweep += 1                   # the first sweep defers; later ones solve refusals' horizons
            for L in range(L0, L_max + 1):
                ks = run.sched.open_at(L)
                size = budget.chunk_size(L) or max(len(ks), 1)
                for c in range(0, len(ks), size):
                    run.solve(L, ks[c:c + size], defer=supports_defer and run.sweep == 1)
                    run.harvest(block=False, limit=budget.max_pending())
                    run.write_step(L)
        elif not run.pending and not run.held:
            return
        run.harvest(block=True)              # every refusal known before the next sweep starts
        run.write_step(None)
        run.release_held()
