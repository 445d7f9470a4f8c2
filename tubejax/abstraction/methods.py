"""The methods of Algorithm 2 and the batch solvers that belong to each.

Every edge's evidence is checked as its system's method's; a solver of another method would store
the wrong evidence under the right name, so :func:`check_solver` refuses it. :func:`batch_solver` is
the one factory from validated settings to a solver (:func:`tubejax.abstract`, the apps).
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Callable

import jax

from ..errors import InputError
from ..inputs import AbstractionSettings
from ..lp.declarations.formulation import Formulation, PdhgForm
from ..lp.evidence.registry import FORMULATIONS, formulation, formulation_of_form, method_names
from ..lp.batch.batch_solver import pdhg_solver
from ..reachability.reference_solvers import reference_solver

__all__ = ["METHODS", "method_solver", "solver_method", "check_solver", "batch_solver", "compilation_cache_dir",
           "enable_compilation_cache"]

BatchSolver = Callable[..., list]

#: The methods Algorithm 2 runs (docs/math/tube-lp.md and docs/math/open-loop.md, and the exact polygon computation):
#: the registered LPs (:mod:`tubejax.lp.evidence.registry`).
METHODS = method_names()


def method_solver(method: str) -> BatchSolver:
    """The reference batch solver of ``method`` (:func:`build_abstraction`'s default,
    :func:`~tubejax.reachability.reference_solvers.reference_solver`): ``highs_solver(method)`` for an LP,
    ``exact2d_solve_batch`` for the exact polygon computation; an ``InputError`` if unknown."""
    return reference_solver(method)


def solver_method(solve_batch) -> str | None:
    """The method whose problems ``solve_batch`` solves, told by its ``method`` attribute (a str) or its LP's
    record (its ``record``, or the one holding its PDHG ``form``:
    :func:`~tubejax.lp.evidence.registry.formulation_of_form`, the object itself); ``None`` for a solver that
    does not say (a wrapper, a test double: :func:`build_abstraction` then trusts the caller)."""
    declared = getattr(solve_batch, "method", None)
    if isinstance(declared, str):
        return declared
    record = _form_record(solve_batch)
    return None if record is None else record.name


def _form_record(solve_batch):
    """The LP ``solve_batch`` solves: its ``record`` (a batched solver's, found by its form when it was made), else
    the record holding its PDHG ``form``; ``None`` without either, or for a form no record holds."""
    record = getattr(solve_batch, "record", None)
    if isinstance(record, Formulation):
        return record
    form = getattr(solve_batch, "form", None)
    if not isinstance(form, PdhgForm):
        return None
    try:
        return formulation_of_form(form)
    except TypeError:
        return None


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
    if getattr(solve_batch, "method", None) is not None and getattr(solve_batch, "__name__", None):
        return solve_batch.__name__
    record = _form_record(solve_batch)
    if record is not None:
        return f"{type(solve_batch).__name__} (form {record.name!r})"
    return getattr(solve_batch, "__name__", type(solve_batch).__name__)


#: Batched solvers made by :func:`batch_solver` with ``reuse=True``, by settings, so later calls reuse compiled code.
_REUSED: dict = {}


def batch_solver(settings: AbstractionSettings, *, reuse: bool = False) -> BatchSolver:
    """The batch solver of validated abstraction settings: the one factory of the API and the apps.

    ``exact2d`` and ``solver.name='highs'`` give :func:`method_solver`; ``'pdhg'`` the method's batched
    :class:`~tubejax.lp.batch.batch_solver.PdhgBatchSolver` (``verify='all'``: every certified verdict
    re-solved with HiGHS), with JAX in float64 and its compilation cache on (:func:`enable_compilation_cache`).

    Parameters
    ----------
    settings : AbstractionSettings
        Validated settings (``method``, ``verify``, ``solver``).
    reuse : bool
        Keep the PDHG solver and give the same object to a later call with equal settings (its compiled
        code is reused; its ``stats`` then add up over the calls).
    """
    if not formulation(settings.method).solves_lp or settings.solver.name == "highs":
        return method_solver(settings.method)
    jax.config.update("jax_enable_x64", True)        # PDHG data and certificates in float64
    enable_compilation_cache(settings.solver.compilation_cache)
    key = (settings.method, settings.verify, tuple(sorted(settings.solver.options().items())))
    if reuse and key in _REUSED:
        return _REUSED[key]
    if formulation(settings.method).pdhg is None:
        raise InputError(f"solver.name: method {settings.method!r} has no batched PDHG form; expected "
                         f"solver.name 'highs' (its own HiGHS solver), or a method of "
                         f"{', '.join(n for n, f in FORMULATIONS.items() if f.pdhg is not None)}")
    solver = pdhg_solver(settings.method, exact=settings.verify == "all", **settings.solver.options())
    if reuse:
        _REUSED[key] = solver
    return solver


def compilation_cache_dir(directory, key: str = "solver.compilation_cache") -> Path | None:
    """The compilation cache directory ``directory`` (``~`` expanded), created if needed and checked by
    writing a file into it; ``None``/empty: None (no cache). An ``InputError`` names ``key`` and the
    path where no file can be created (a file, a path below one, no permission, read-only)."""
    if not directory:
        return None
    path = Path(str(directory)).expanduser()
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path, prefix=".tubejax-write-check-"):
            pass
    except OSError as exc:
        blocker = next((p for p in [path, *path.parents] if p.exists() and not p.is_dir()), None)
        why = (("it is a file" if blocker == path else f"{blocker} is a file") if blocker is not None
               else f"no file can be created there: {(exc.strerror or type(exc).__name__).lower()}")
        raise InputError(f"{key}: cannot keep JAX's compiled code in {str(directory)!r} ({why}); expected a "
                         "directory where files can be written, or null to switch the cache off") from None
    return path


def enable_compilation_cache(directory) -> None:
    """JAX's persistent compilation cache in ``directory`` (a second run skips most compiling); ``None``/empty:
    off (an ``InputError`` as :func:`compilation_cache_dir`)."""
    path = compilation_cache_dir(directory)
    if path is None:
        return
    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
