"""Algorithm 2: every ordered pair x horizon -> a verified transition system.

Candidates come from :func:`~tubejax.abstraction.candidates.build_candidates`. Rounds
``L = 1 .. L_max`` hand every open pair to a batch solver in chunks that fit a
:class:`~tubejax.abstraction.schedule.MemoryBudget`; each pair's horizons are solved in increasing
order, so its edge cost is the minimal ``L`` (docs/math/tube-lp.md#paper-slips, slip 2). HiGHS
confirmations may run into later rounds (``Pending``); a refused pair's later horizons are solved in a
second sweep. Only ``status == 'edge'`` verdicts enter the system. With a
:class:`~tubejax.abstraction.runstore.RunStore` an interrupted run resumes to the identical result.
"""

from __future__ import annotations

import logging
import time
from typing import Callable

from tqdm.auto import tqdm

from ..lp.evidence.verdict import Verdict, highs_solve_batch
from ..model.zshape.kinds import cross_sections
from ..lp.evidence.registry import FORMULATIONS, check_state_constraints, formulation
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
        The run's settings (default: its defaults).
    z : ZAssignment or sequence of Polytope, optional
        The cross-sections instead of ``options.zshape``: one per cell, or a
        :class:`~tubejax.model.zassignment.ZAssignment` whose per-pair ``Z`` replace the source
        cell's for those pairs (Lemma 1 holds pair by pair); the files store each edge's own ``Z``.
    solve_batch : callable, optional
        ``solve_batch(problems, progress=bar) -> list[Verdict]``; default: the method's reference
        solver (:func:`method_solver`); another method's is refused. One with ``supports_deferred``
        gets ``defer=True`` in the first sweep and may return a ``Pending`` for a likely edge (the
        result is still Algorithm 2's).
    io : RunIO, optional
        ``store``: a :class:`~tubejax.abstraction.runstore.RunStore` to replay (resume) and write each
        step to; ``on_round(L, new_edges, new_tubes)``: called after each step with the new edges.
    progress : bool
        Show a progress bar.
    **fields
        Fields of :class:`AbstractionOptions` (``L_max=5``, ``method='openloop'``) replacing those
        of ``options``, and ``store`` / ``on_round`` replacing those of ``io``.

    Returns
    -------
    TransitionSystem
        Its ``stats`` hold the counts of pairs (``n_pairs``, ``n_candidate_pairs``, ``n_tested_pairs``),
        LPs (``n_lps``: every instance settled, ``resumed_lps``, ``n_translated``) and verdicts,
        ``pruned`` per reason, the timings (``seconds_*``, ``*_lps_per_second``) and ``shard``.
        An ``InputError`` for an unknown ``method`` or another method's ``solve_batch``; a
        ``RunStoreError`` for a store of other instances, damaged or inconsistent.
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
