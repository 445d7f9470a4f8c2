"""The open-loop LP (docs/math/open-loop.md) on the one batched, certified PDHG engine.

:data:`OPENLOOP_PDHG` plugs it into :class:`~tubejax.lp.batch.batch_solver.PdhgBatchSolver`; only
the operator (:mod:`tubejax.lp.declarations.openloop_operator`) and the evidence differ from the
tube LP. An instance is certified infeasible only by a host float64 weak-duality bound on ``t*``
below ``-margin_safety``; every other is solved by
:func:`~tubejax.lp.evidence.verdict.highs_verdict` (``form='openloop'``), whose
:class:`~tubejax.lp.declarations.openloop_lp.OpenLoopPlan` is the stored evidence. A non-box ``U``
stays batched (its rows are the operator's hard rows); a problem with a family the operator does
not model (:func:`~tubejax.lp.declarations.openloop_operator_data.openloop_unmodelled`) goes to
HiGHS whole. The edges and horizons are those of
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


def openloop_setup(probs: Sequence[TubeProblem], L_pad: int, f_pad: tuple, options, share: bool = True):
    """``(shape, data, prob, state)`` of one shape group, scaled on the host (``share`` is
    unused: the shared ``A^s B`` blocks are a compile-time constant of the shape)."""
    f_s, f_t = f_pad
    shape, data = build_openloop_data(probs, L_pad=L_pad, f_s=f_s, f_t=f_t)
    # C2, C3 have t's column, the hard input rows do not
    prob, z0 = margin_start((openloop_matvec, openloop_rhs, openloop_bounds), (pack_x, pack_y), shape, data,
                                 rows_with_t=2)
    # scaling on the host through explicit coefficients (|K|, K o K)
    coef = openloop_coef_data(shape, data)
    cmv, crmv = openloop_coef_ops(shape)
    state = pdhg_init(ScalingOperator(cmv, crmv, coef.apply(np.abs), coef.apply(np.square)), prob, z0, options, np)
    return shape, data, prob, state


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
