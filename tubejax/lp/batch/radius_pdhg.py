"""The radius form (docs/math/radius.md) on the one batched PDHG engine: :func:`radius_pdhg_solver`.

Each LP's record holds its radius form's form on the engine (``RadiusForm.pdhg``:
:data:`~tubejax.lp.engines.tube_pdhg.RADIUS_TUBE_PDHG`,
:data:`~tubejax.lp.engines.openloop_pdhg.RADIUS_OPENLOOP_PDHG`, beside its margin form's), which reuses
the margin form's operator in its ``'radius'`` form (``t``'s all-ones column becomes ``rho``'s
coefficients) and runs in the optimise mode: per instance an estimate of ``rho*``, a rigorous upper
bound, a lower estimate (:mod:`tubejax.lp.engines.objective_bounds`), the status and the primal point.
Bounds, ``rho_min``, ``rho_max`` and the reference point are those of
:mod:`~tubejax.lp.evidence.radius_lp` (:func:`~tubejax.lp.engines.pdhg_adapters.radius_start`). A group
is one system (any radius of one shape shares the executables). A non-box ``U``'s rows are hard rows (no ``rho``; the reference ``u = 0`` satisfies them
strictly). Problems with a family an operator does not model, or whose reference point violates C2 / C3
(only with ``eps_min > 0``), go to HiGHS.
"""

from __future__ import annotations

from ..evidence.registry import FORMULATIONS, radius_forms
from .batch_solver import PdhgBatchSolver
from ..engines.pdhg import PdhgOptions

__all__ = ["radius_pdhg_solver", "RADIUS_OPTIONS"]

#: Defaults of :func:`radius_pdhg_solver`: the optimise mode, a duality gap of 1e-4 in radius
#: units (rho* to about four decimals on unit cells; a requested radius within the gap of rho* is
#: HiGHS's to decide anyway), a high cap and a check every 8 iterations
#: (docs/explanation/performance.md#radius-optimise-mode).
RADIUS_OPTIONS = PdhgOptions(mode="optimise", gap_tol=1e-4, max_iters=4096, check_every=8, checks_per_call=16)


def radius_pdhg_solver(form: str = "tube", options: PdhgOptions | None = None, **kw) -> PdhgBatchSolver:
    """The batched engine on the radius form: call ``.radius.optimise(problems)``.

    Parameters
    ----------
    form : str
        An LP whose record has a batched radius form (``'tube'``, ``'openloop'``: ``radius.pdhg``).
    options : PdhgOptions, optional
        Default :data:`RADIUS_OPTIONS`; ``**kw`` override its fields or set
        :class:`~tubejax.lp.batch.batch_solver.PdhgBatchSolver` arguments.

    Raises
    ------
    ValueError
        ``form`` has no batched radius form (the message lists those that have one).
    """
    record = FORMULATIONS.get(form) if isinstance(form, str) else None
    fm = None if record is None or record.radius is None else record.radius.pdhg
    if fm is None:
        raise ValueError(f"form: expected one of {radius_forms()}, got {form!r}")
    return PdhgBatchSolver(options=options or RADIUS_OPTIONS, formulation=fm, **kw)
