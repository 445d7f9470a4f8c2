"""The methods of Algorithm 2 and the batch solvers that belong to each.

A transition system records its method (``'tube'``, ``'openloop'``, ``'exact2d'``), and every
edge's evidence is checked as that method's (a tube, an open-loop plan, nothing). A solver of
another method would store the wrong evidence under the right name -- e.g. the tube LP's
edges labelled ``openloop`` -- so :func:`check_solver` refuses it, and a method without a
solver gets its own (:func:`method_solver`).
"""

from __future__ import annotations

from typing import Callable

from ..errors import InputError
from ..lp.solvers.exact2d import exact2d_solve_batch
from ..lp.evidence.verdict import highs_solve_batch
from ..lp.evidence.verdict import openloop_solve_batch

__all__ = ["METHODS", "method_solver", "solver_method", "check_solver"]

BatchSolver = Callable[..., list]

#: The methods Algorithm 2 runs (docs/math/tube-lp.md and docs/math/open-loop.md, and the exact polygon computation).
METHODS = ("tube", "openloop", "exact2d")
#: Each method's own reference solver: one HiGHS solve (tube, open-loop LP) or polygon computation per problem.
_OWN_SOLVERS = {"tube": highs_solve_batch, "openloop": openloop_solve_batch, "exact2d": exact2d_solve_batch}


def method_solver(method: str) -> BatchSolver:
    """The reference batch solver of ``method``: the one :func:`build_abstraction` uses by default.

    Parameters
    ----------
    method : {'tube', 'openloop', 'exact2d'}

    Returns
    -------
    callable
        :data:`~tubejax.lp.evidence.verdict.highs_solve_batch` (tube LP),
        :data:`~tubejax.lp.evidence.verdict.openloop_solve_batch` (open-loop LP) or
        :data:`~tubejax.lp.solvers.exact2d.exact2d_solve_batch` (exact polygon computation).

    Raises
    ------
    InputError
        An unknown method.
    """
    if method not in _OWN_SOLVERS:
        raise InputError(f"method: expected one of {', '.join(METHODS)}, got {method!r}")
    return _OWN_SOLVERS[method]


def solver_method(solve_batch) -> str | None:
    """The method whose problems ``solve_batch`` solves, when the solver tells.

    A solver tells by a ``method`` attribute (a string); the library's solvers are known:
    the sequential HiGHS solvers of the tube and open-loop LPs, the exact2d computation, and
    :class:`~tubejax.lp.solvers.batched.PdhgBatchSolver` (its formulation's name: ``'tube'``,
    or ``'openloop'`` from :func:`~tubejax.lp.formulations.openloop.pdhg.openloop_pdhg_solver`).

    Returns
    -------
    str or None
        ``'tube'``, ``'openloop'`` or ``'exact2d'``; ``None`` for a solver that does not say
        (a wrapper, a test double): :func:`build_abstraction` then trusts the caller.
    """
    declared = getattr(solve_batch, "method", None)
    if isinstance(declared, str):
        return declared
    for method, own in _OWN_SOLVERS.items():
        if solve_batch is own:
            return method
    name = getattr(getattr(solve_batch, "formulation", None), "name", None)
    return name if name in METHODS else None


def check_solver(method: str, solve_batch) -> BatchSolver:
    """``solve_batch``, or ``method``'s own solver when it is ``None``; a solver of another method is refused."""
    if solve_batch is None:
        return method_solver(method)
    method_solver(method)                            # the method is known
    owner = solver_method(solve_batch)
    if owner is not None and owner != method:
        raise InputError(f"solve_batch: {_describe(solve_batch)} solves the problems of method {owner!r}, but method "
                         f"is {method!r} (its verdicts and evidence would be recorded as {method!r}'s); leave "
                         f"solve_batch out, so that method {method!r} uses its own solver, or pass one of method "
                         f"{method!r}")
    return solve_batch


def _describe(solve_batch) -> str:
    """A name for ``solve_batch`` in messages."""
    names = {id(highs_solve_batch): "highs_solve_batch", id(openloop_solve_batch): "openloop_solve_batch",
             id(exact2d_solve_batch): "exact2d_solve_batch"}
    if id(solve_batch) in names:
        return names[id(solve_batch)]
    formulation = getattr(getattr(solve_batch, "formulation", None), "name", None)
    if formulation is not None:
        return f"{type(solve_batch).__name__} (formulation {formulation!r})"
    return getattr(solve_batch, "__name__", type(solve_batch).__name__)
