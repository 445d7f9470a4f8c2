"""The open-loop LP (the baseline of docs/math/open-loop.md) as one record."""

from __future__ import annotations

from functools import partial

import numpy as np

from ..check import ExactPlan, exact_openloop_violation, exact_plan_terms
from ..rational import QArray
from ...engines.openloop_pdhg import OPENLOOP_PDHG, RADIUS_OPENLOOP_PDHG
from ..rows import openloop_bounds, rational_openloop_lp
from ...declarations.formulation import Formulation
from ...declarations.radius_rows import RadiusForm, openloop_radius_reference, openloop_radius_rows
from ...declarations.openloop_lp import OpenLoopLP, OpenLoopPlan, build_openloop_lp, openloop_violation
from ...declarations.openloop_families import OPENLOOP_FAMILIES, float_plan_terms
from . import SeriesStyle

__all__ = ["FORMULATION", "STYLE"]


def _from_point(lp: OpenLoopLP, x: list) -> ExactPlan:
    ix = lp.index
    return ExactPlan(QArray.from_fractions(np.array(x, dtype=object)[ix.u].reshape(ix.L, ix.n_v, ix.m)))


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
