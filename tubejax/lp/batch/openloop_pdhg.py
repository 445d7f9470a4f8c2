"""The open-loop baseline (docs/math/open-loop.md) on the batched, certified PDHG engine.

:data:`OPENLOOP_PDHG` plugs the open-loop LP into the one batched engine,
:class:`~tubejax.lp.batch.batch_solver.PdhgBatchSolver` (shape groups with padded horizons and
facet counts, a fixed-width pool compiled once per shape, HiGHS solves overlapping the PDHG
run, ``stats``); only the operator and the verdicts differ from the tube LP:

* the operator is :mod:`tubejax.lp.declarations.openloop_operator` (shared ``A^s B`` blocks as a
  compile-time constant, per-instance normalised facet rows);
* an instance is certified infeasible (provenance ``'pdhg-certificate'``) only by a
  weak-duality bound on ``t*`` recomputed on the host in NumPy float64 from the
  unscaled data (``u`` boxed by ``U``'s bounding box) below ``-margin_safety``;
* every other instance is solved by :func:`~tubejax.lp.evidence.verdict.highs_verdict` (``form='openloop'``),
  whose :class:`~tubejax.lp.declarations.openloop_lp.OpenLoopPlan` (re-checked by
  :func:`~tubejax.lp.declarations.openloop_lp.openloop_violation`) is the stored evidence:
  ``'pdhg+highs'`` when PDHG's own primal point already satisfied the constraints to
  ``1e-9``, ``'highs-fallback'`` otherwise.

A non-box ``U`` stays on the batched path: its ``C5`` rows are hard rows of the operator, read
off the declaration (:func:`~tubejax.lp.declarations.openloop_operator_data.openloop_unmodelled` names any family the operator does
not model; a problem with one goes to HiGHS whole).

Use it as ``build_abstraction(decomp, system, solve_batch=openloop_pdhg_solver(),
method="openloop")``; it gives the same edges and horizons as
:func:`~tubejax.lp.evidence.verdict.highs_solver` ``('openloop')``.
"""

from __future__ import annotations

from functools import partial
from typing import Sequence

import numpy as np

from ..declarations.pdhg_formulation import PdhgFormulation
from .batch_solver import PdhgBatchSolver
from ..engines.certify import host_certificates
from ...model.problem import TubeProblem
from ..declarations.openloop_operator import (OpenLoopData, openloop_bounds, openloop_coef_data,
                                              openloop_coef_ops, openloop_matvec,
                                              openloop_rhs, openloop_rmatvec, openloop_transpose, pack_x, pack_y,
                                              unpack_x, unpack_y)
from ..declarations.openloop_operator_data import build_openloop_data, openloop_unmodelled
from ..declarations.tube_operator import OperatorShape
from .adapters import flat_ops, margin_start
from ..engines.pdhg import ScalingOperator, pdhg_init
from ..evidence.verdict import Verdict, highs_verdict

__all__ = ["OPENLOOP_PDHG", "openloop_pdhg_solver", "openloop_pdhg_solve_batch", "openloop_setup",
           "host_openloop_certificates"]

def _flat_ops(shape: OperatorShape, xp):
    """:func:`tubejax.lp.batch.adapters.flat_ops` for the open-loop operator."""
    return flat_ops(shape, xp, openloop_matvec, openloop_transpose(xp), pack_x, unpack_x, pack_y, unpack_y)


def host_openloop_certificates(shape: OperatorShape, data: OpenLoopData, z,
                               y) -> tuple[np.ndarray, np.ndarray]:
    """:func:`~tubejax.lp.engines.certify.host_certificates` of the open-loop operator, flat points
    ``z (n_x + 1, B)``, ``y (n_rows, B)`` (``u`` boxed by ``U``'s bounding box, hard rows of a non-box ``U``)."""
    data = OpenLoopData(*[None if a is None else np.asarray(a, float) for a in data])
    zx, yy = unpack_x(shape, np.asarray(z, float)), unpack_y(shape, np.asarray(y, float))
    return host_certificates((openloop_matvec, openloop_rmatvec, openloop_rhs, openloop_bounds), shape, data, zx, yy)


def _start(shape: OperatorShape, data: OpenLoopData):
    """Flat margin-form problem and a feasible start (:func:`~tubejax.lp.engines.pdhg.margin_start`:
    C2, C3 have ``t``'s column, the hard input rows do not)."""
    prob, z0 = margin_start((openloop_matvec, openloop_rhs, openloop_bounds), shape, data, rows_with_t=2)
    flat = lambda a: np.ascontiguousarray(pack_x(a))             # noqa: E731
    return prob._replace(c=flat(prob.c), g=np.ascontiguousarray(pack_y(prob.g)), lo=flat(prob.lo),
                         hi=flat(prob.hi), mask=np.ascontiguousarray(pack_y(prob.mask))), flat(z0)


def openloop_setup(probs: Sequence[TubeProblem], L_pad: int, f_pad: tuple, options, share: bool = True):
    """``(shape, data, prob, state)`` of one shape group, scaled on the host (``share`` is
    unused: the shared ``A^s B`` blocks are a compile-time constant of the shape)."""
    f_s, f_t = f_pad
    shape, data = build_openloop_data(probs, L_pad=L_pad, f_s=f_s, f_t=f_t)
    prob, z0 = _start(shape, data)
    # scaling on the host through explicit coefficients (|K|, K o K)
    coef = openloop_coef_data(shape, data)
    cmv, crmv = openloop_coef_ops(shape)
    state = pdhg_init(ScalingOperator(cmv, crmv, coef.apply(np.abs), coef.apply(np.square)), prob, z0, options, np)
    # the device copy holds only what K reads
    return shape, data, prob._replace(data=data.lean()), state


def _group_key(p: TubeProblem):
    return (p.source.n_vertices, p.system.n, p.system.m), id(p.system)


def _facet_counts(p: TubeProblem):
    return p.safe.H.shape[0], p.target.H.shape[0]


def _batched(p: TubeProblem) -> bool:
    """Every family of the problem's LP is one the operator models (:func:`~tubejax.lp.declarations.openloop_operator_data.openloop_unmodelled`,
    read from the declaration); else HiGHS."""
    return not openloop_unmodelled(p.system)


#: The open-loop LP on the batched engine: ``PdhgBatchSolver(formulation=OPENLOOP_PDHG)``.
#: Executables are keyed by the padded shape and the system's ``A^s B`` blocks (a
#: compile-time constant), so repeated rounds, abstractions and disturbance radii reuse them.
OPENLOOP_PDHG = PdhgFormulation("openloop", _group_key, _facet_counts, openloop_setup, _flat_ops,
                                host_openloop_certificates, partial(highs_verdict, form="openloop"), _batched)


def openloop_pdhg_solver(**options) -> PdhgBatchSolver:
    """The batched engine on the open-loop LP (same options, ``stats`` and protocol as
    :class:`~tubejax.lp.batch.batch_solver.PdhgBatchSolver`; the evidence is an
    :class:`~tubejax.lp.declarations.openloop_lp.OpenLoopPlan`)."""
    return PdhgBatchSolver(formulation=OPENLOOP_PDHG, **options)


def openloop_pdhg_solve_batch(problems: Sequence[TubeProblem], progress=None, **options) -> list[Verdict]:
    """One-shot functional form of :func:`openloop_pdhg_solver` (compiles afresh each call)."""
    return openloop_pdhg_solver(**options)(problems, progress=progress)
