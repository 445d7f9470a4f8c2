"""Each method's reference solver: HiGHS for an LP, the exact polygon computation for ``exact2d``. The
one place that tells the two apart; it sits here because the LP records cannot name
:mod:`tubejax.reachability.exact2d`, which is above them.
"""

from __future__ import annotations

from typing import Callable

from ..lp.evidence.registry import formulation
from ..lp.evidence.verdict import highs_solver
from .exact2d import exact2d_solve_batch

__all__ = ["reference_solver", "reference_verdict"]


def reference_solver(method: str) -> Callable:
    """The reference batch solver of ``method``: ``highs_solver(method)`` for an LP (its record
    ``solves_lp``), ``exact2d_solve_batch`` for the exact polygon computation; an ``InputError`` if
    unknown.

    Returns
    -------
    callable
        ``solve_batch(problems, progress=None) -> list[Verdict]`` (a
        :func:`~tubejax.lp.evidence.verdict.sequential_solver`); the same object for the same ``method``.
    """
    return highs_solver(method) if formulation(method).solves_lp else exact2d_solve_batch


def reference_verdict(method: str) -> Callable:
    """The verdict of one problem of ``method`` that :func:`reference_solver` gives per problem:
    ``verdict(prob) -> Verdict``; an ``InputError`` if ``method`` is unknown."""
    return reference_solver(method).verdict
