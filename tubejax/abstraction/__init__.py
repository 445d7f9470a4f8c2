"""Algorithm 2: candidates, pruning, translation classes, the rounds and their run store.

:func:`build_abstraction` (``build``, with its settings in ``options``) turns every ordered pair and
horizon into a verified transition system; ``candidates``, ``pruning``, ``safe_reach`` and
``vertex_lp`` drop instances soundly before any solver; ``translation_classes``, ``schedule``, ``methods``,
``runstore`` and ``shards`` are described in their modules. ``__all__`` is ``build``'s.
"""

from .build import (METHODS, TRANSLATE_PROVENANCE, ZERO_MARGIN_TOL, AbstractionOptions, RunIO, Verdict,
                    build_abstraction, cross_sections, highs_solve_batch, method_solver, solver_method)

__all__ = ["Verdict", "highs_solve_batch", "build_abstraction", "AbstractionOptions", "RunIO", "cross_sections",
           "ZERO_MARGIN_TOL", "TRANSLATE_PROVENANCE", "METHODS", "method_solver", "solver_method"]
