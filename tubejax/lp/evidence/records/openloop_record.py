"""The open-loop LP (the baseline of docs/math/open-loop.md) as one record."""

from __future__ import annotations

from functools import partial

import numpy as np

from ..check import ExactPlan, exact_openloop_violation, exact_plan_terms
from ..rational import QArray
from ..rows import openloop_bounds, rational_openloop_lp
from ...declarations.formulation import Formulation, PdhgForm, RadiusForm
from ...declarations.radius_rows import openloop_radius_reference, openloop_radius_rows
from ...declarations.openloop_lp import OpenLoopLP, OpenLoopPlan, build_openloop_lp, openloop_violation
from ...declarations.openloop_families import OPENLOOP_FAMILIES, float_plan_terms
from ...declarations.openloop_operator import OPENLOOP_OPERATOR, OpenLoopX, unpack_x
from ...declarations.openloop_operator_data import build_openloop_data, openloop_unmodelled
from ....model.problem import TubeProblem
from . import SeriesStyle

__all__ = ["FORMULATION", "STYLE", "OPENLOOP_PDHG", "RADIUS_OPENLOOP_PDHG"]


def _from_point(lp: OpenLoopLP, x: list) -> ExactPlan:
    ix = lp.index
    return ExactPlan(QArray.from_fractions(np.array(x, dtype=object)[ix.u].reshape(ix.L, ix.n_v, ix.m)))


# ----------------------------------------------------------------------------- on the batched PDHG engine
def _data(probs, L_pad: int, f_pad: tuple, share: bool, W0):
    # share is unused: the shared ``A^s B`` blocks are a compile-time constant of the shape
    return build_openloop_data(probs, L_pad=L_pad, f_s=f_pad[0], f_t=f_pad[1], W0=W0)


def _group_key(p: TubeProblem):
    return (p.source.n_vertices, p.system.n, p.system.m), id(p.system)


def _facet_counts(p: TubeProblem):
    return p.safe.H.shape[0], p.target.H.shape[0]


def _batched(p: TubeProblem) -> bool:
    """Every family of the problem's LP is one the operator models (:func:`~tubejax.lp.declarations.openloop_operator_data.openloop_unmodelled`,
    read from the declaration); else HiGHS."""
    return not openloop_unmodelled(p.system)


def _radius_reference(shape, probs) -> OpenLoopX:
    """The radius form's start ``u = 0`` (strictly inside every row), batch axis last."""
    return OpenLoopX(np.zeros((shape.L, shape.n_v, shape.m, len(probs))), np.zeros(len(probs)))


def _radius_point(shape, z, problem: TubeProblem) -> OpenLoopPlan:
    return OpenLoopPlan(unpack_x(shape, np.asarray(z, float)[:, None]).u[:int(problem.L), ..., 0].copy())


#: The open-loop LP on the batched engine (``pdhg_solver('openloop')``): an instance is certified
#: infeasible only by a host float64 weak-duality bound below ``-margin_safety``; every other is solved
#: by HiGHS, whose plan is stored. Executables are keyed by the padded shape and the system's ``A^s B``
#: blocks (a compile-time constant), so repeated rounds, abstractions and disturbance radii reuse them.
OPENLOOP_PDHG = PdhgForm(OPENLOOP_OPERATOR, _group_key, _facet_counts, _data, _batched)
#: Its radius form (docs/math/radius.md): the margin form's groups, facet counts and choice of the
#: batched path (the reference ``u = 0`` is strictly inside every row).
RADIUS_OPENLOOP_PDHG = OPENLOOP_PDHG._replace(radius=_radius_reference, point=_radius_point)

FORMULATION = Formulation(
    "openloop", OPENLOOP_FAMILIES, rank=1, evidence_type=OpenLoopPlan, exact_type=ExactPlan, lp_type=OpenLoopLP,
    build=build_openloop_lp, violation=openloop_violation, exact_violation=exact_openloop_violation,
    terms={"float": float_plan_terms, "exact": partial(exact_plan_terms, upper=True)},
    rational_lp=rational_openloop_lp, bounds=openloop_bounds, implied_bounds=openloop_bounds, from_point=_from_point,
    evidence_names=("u",), provenance="openloop-highs", pdhg=OPENLOOP_PDHG,
    radius=RadiusForm(openloop_radius_rows, openloop_radius_reference, RADIUS_OPENLOOP_PDHG),
    translation_classes=True)
#: How the plots draw its series (:func:`~tubejax.lp.evidence.registry.series_style`).
STYLE = SeriesStyle("#D55E00", ":", "v")       # Okabe-Ito vermillion
