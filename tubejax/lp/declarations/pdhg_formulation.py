"""LP formulations. Each LP (method) is one :class:`~.formulation.Formulation` record in
:mod:`tubejax.lp.evidence.records`, found by :mod:`tubejax.lp.evidence.registry` (docs/howto/extending.md#a-new-lp). Each one (``tube``,
``openloop``; ``radius``: the radius-parametric form of both, docs/math/radius.md) provides the same
pieces:

* a dense builder (``build_*_lp``: unit rows for HiGHS, margin form, docs/math/margins.md);
* a matrix-free batched operator (``*_matvec`` / ``*_rmatvec`` on geometry stacked with
  the batch axis last);
* a float64 checker of the evidence it stores (``*_violation``);

and one :class:`PdhgFormulation` that plugs them into the single batched engine
(:class:`tubejax.lp.batch.batch_solver.PdhgBatchSolver`), which the LP's record names
(``Formulation.pdhg``, ``RadiusForm.pdhg``: :mod:`tubejax.lp.batch.adapters`).
"""

from __future__ import annotations

from typing import Callable, NamedTuple

__all__ = ["PdhgFormulation"]


class PdhgFormulation(NamedTuple):
    """What the batched PDHG engine needs from a formulation (all module-level functions).

    Attributes
    ----------
    name : str
        ``'tube'``, ``'openloop'``, ...
    group_key : callable
        ``group_key(problem) -> tuple``: the static shape without the horizon; equal keys and
        padded horizons share one compiled executable.
    facet_counts : callable
        ``facet_counts(problem) -> tuple of int``: facets of the sets the rows constrain, padded by
        the engine to the largest seen so far, so executables are reused.
    setup : callable
        ``setup(problems, L_pad, f_pad, options, share) -> (shape, data, prob, state)``: the group's
        shape, host data (float64, unscaled, batch axis last), the flat
        :class:`~tubejax.lp.engines.pdhg.PdhgProblem` and the scaled initial
        :class:`~tubejax.lp.engines.pdhg.PdhgState`.
    ops : callable
        ``ops(shape, xp) -> (matvec, rmatvec, certify)`` on flat ``(n, B)`` vectors
        (:func:`tubejax.lp.batch.adapters.flat_ops`).
    certificates : callable
        ``certificates(shape, data, z, y) -> (viol, bound)``, each ``(B,)``: the host float64
        re-check on the unscaled data, which the engine trusts.
    verdict : callable or None
        ``verdict(problem, provenance) -> Verdict``: the HiGHS verdict whose evidence is stored;
        ``None`` for a formulation that only computes optima (the radius form).
    batched : callable
        ``batched(problem) -> bool``: False sends the problem to HiGHS whole (a row family the
        operator does not model).
    optimum : callable, optional
        ``optimum(problem) -> (value, point)``: the HiGHS optimum of a problem that is not batched,
        for :meth:`~tubejax.lp.batch.batch_solver.PdhgBatchSolver.optimise`.
    point : callable, optional
        ``point(shape, z, problem)``: one instance's flat primal ``z`` (``(n,)``, ``t`` last) as the
        formulation's evidence type; without it ``optimise`` returns ``z``.
    verdicts : callable, optional
        ``verdicts(problems, provenance, translated) -> list[Verdict]``: ``verdict`` of a group of
        exact translates of one problem, done together; without it each is confirmed on its own.
    dual_key : callable, optional
        ``dual_key(problem) -> hashable``: equal keys have the same rows up to right-hand sides, so
        the engine tries a refuting dual on them before they enter the pool
        (:func:`~tubejax.lp.batch.sign_mode.stream_group`).
    """

    name: str
    group_key: Callable
    facet_counts: Callable
    setup: Callable
    ops: Callable
    certificates: Callable
    verdict: Callable | None
    batched: Callable
    optimum: Callable | None = None
    point: Callable | None = None
    verdicts: Callable | None = None
    dual_key: Callable | None = None
