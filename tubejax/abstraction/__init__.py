"""Algorithm 2: candidates, pruning, translation classes, the rounds and their run store.

``build``, ``options``
    :func:`build_abstraction`: every ordered pair x horizon -> a verified transition system, in
    horizon rounds, with its typed settings (:class:`AbstractionOptions`, :class:`RunIO`).
``candidates``, ``pruning``, ``safe_reach``, ``vertex_lp``
    The candidate instances ``(i, j, L)`` and the sound rules that drop them before any solver.
``translations``
    Pairs whose problems are equal up to an exact translation, solved once per class.
``schedule``
    The per-pair state machine of the rounds and their memory budget.
``methods``
    The methods (tube, open-loop, exact 2-D) and the batch solver that belongs to each.
``runstore``
    The on-disk state of a run, step by step, for resuming.
``shards``
    Sharding a run over its source cells (merged by :mod:`tubejax.verify.shard_merge`).

The names of ``__all__`` are :mod:`tubejax.abstraction.build`'s.
"""

from .build import (METHODS, TRANSLATE_PROVENANCE, ZERO_MARGIN_TOL, AbstractionOptions, RunIO, Verdict,
                    build_abstraction, cross_sections, highs_solve_batch, method_solver, solver_method)

__all__ = ["Verdict", "highs_solve_batch", "build_abstraction", "AbstractionOptions", "RunIO", "cross_sections",
           "ZERO_MARGIN_TOL", "TRANSLATE_PROVENANCE", "METHODS", "method_solver", "solver_method"]
