"""The open-loop LP (docs/math/open-loop.md) on the batched PDHG engine.

:data:`OPENLOOP_PDHG` (its record's ``pdhg``) differs from the tube LP's form only in the operator
(:data:`~tubejax.lp.declarations.openloop_operator.OPENLOOP_OPERATOR`) and the evidence: an instance is certified
infeasible only by a host float64 weak-duality bound below ``-margin_safety``; every other is
solved by HiGHS, whose :class:`~tubejax.lp.declarations.openloop_lp.OpenLoopPlan` is stored. A family
the operator does not model (:func:`~tubejax.lp.declarations.openloop_operator_data.openloop_unmodelled`)
sends the problem to HiGHS. :data:`RADIUS_OPENLOOP_PDHG` is its radius form (docs/math/radius.md).
"""

from __future__ import annotations

from functools import partial
from typing import Sequence

import numpy as np

from ..declarations.formulation import PdhgForm
from ..declarations.radius_disturbance import unit_disturbance
from ...model.problem import TubeProblem
from ..declarations.openloop_lp import OpenLoopPlan
from ..declarations.openloop_operator import OPENLOOP_OPERATOR, OpenLoopX, unpack_x
from ..declarations.openloop_operator_data import build_openloop_data, openloop_unmodelled
from .objective_bounds import host_objective_certificates
from .pdhg_adapters import flat_ops, host_flat_certificates, margin_setup, radius_setup

__all__ = ["OPENLOOP_PDHG", "RADIUS_OPENLOOP_PDHG", "openloop_setup", "radius_openloop_setup"]

#: :func:`~tubejax.lp.engines.pdhg_adapters.flat_ops` of the open-loop operator: ``ops(shape, xp)``.
_flat_ops = partial(flat_ops, OPENLOOP_OPERATOR)


def openloop_setup(probs: Sequence[TubeProblem], L_pad: int, f_pad: tuple, options, share: bool = True):
    """``(shape, data, prob, state)`` of one shape group, scaled on the host (``share`` is
    unused: the shared ``A^s B`` blocks are a compile-time constant of the shape)."""
    f_s, f_t = f_pad
    shape, data = build_openloop_data(probs, L_pad=L_pad, f_s=f_s, f_t=f_t)
    return margin_setup(OPENLOOP_OPERATOR, shape, data, options)


def _group_key(p: TubeProblem):
    return (p.source.n_vertices, p.system.n, p.system.m), id(p.system)


def _facet_counts(p: TubeProblem):
    return p.safe.H.shape[0], p.target.H.shape[0]


def _batched(p: TubeProblem) -> bool:
    """Every family of the problem's LP is one the operator models (:func:`~tubejax.lp.declarations.openloop_operator_data.openloop_unmodelled`,
    read from the declaration); else HiGHS."""
    return not openloop_unmodelled(p.system)


#: The open-loop LP on the batched engine: ``pdhg_solver('openloop')``.
#: Executables are keyed by the padded shape and the system's ``A^s B`` blocks (a
#: compile-time constant), so repeated rounds, abstractions and disturbance radii reuse them.
#: Its certificates: ``u`` boxed by ``U``'s bounding box, the hard rows of a non-box ``U``.
OPENLOOP_PDHG = PdhgForm(_group_key, _facet_counts, openloop_setup, _flat_ops,
                         partial(host_flat_certificates, OPENLOOP_OPERATOR), _batched)


def radius_openloop_setup(probs: Sequence[TubeProblem], L_pad: int, f_pad: tuple, options,
                          share: bool = True):
    """``(shape, host_problem, device_problem, state)`` of one group of the radius open-loop LP, started at
    the reference ``u = 0``."""
    W0 = unit_disturbance(probs[0].system.W)[0]
    f_s, f_t = f_pad
    shape, data = build_openloop_data(probs, L_pad=L_pad, f_s=f_s, f_t=f_t, W0=W0)
    x_ref = OpenLoopX(np.zeros((shape.L, shape.n_v, shape.m, len(probs))), np.zeros(len(probs)))
    return radius_setup(OPENLOOP_OPERATOR, shape, data, x_ref, options, probs)


def _radius_point(shape, z, problem: TubeProblem) -> OpenLoopPlan:
    x = unpack_x(shape, np.asarray(z, float)[:, None])
    return OpenLoopPlan(x.u[:int(problem.L), ..., 0].copy())


#: The radius form of the open-loop LP on the batched engine: the margin form's groups, facet counts,
#: operator and choice of the batched path (every family modelled; the reference ``u = 0`` is strictly
#: inside every row); ``certificates`` take the host problem that ``setup`` returns as its data.
RADIUS_OPENLOOP_PDHG = PdhgForm(_group_key, _facet_counts, radius_openloop_setup, _flat_ops,
                                partial(host_objective_certificates, _flat_ops), _batched, radius=True,
                                point=_radius_point)
