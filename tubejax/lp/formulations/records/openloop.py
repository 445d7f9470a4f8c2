"""The open-loop LP (the baseline of docs/math/open-loop.md) as one record."""

from __future__ import annotations

from functools import partial

import numpy as np

from ...evidence.check import ExactPlan, exact_openloop_violation, exact_plan_terms
from ...evidence.rational import QArray
from ...evidence.rows import openloop_bounds, rational_openloop_lp
from ..formulation import Formulation
from ..openloop.dense import OpenLoopLP, OpenLoopPlan, build_openloop_lp, openloop_violation
from ..openloop.families import OPENLOOP_FAMILIES, float_plan_terms

__all__ = ["FORMULATION"]


def _from_point(lp: OpenLoopLP, x: list) -> ExactPlan:
    ix = lp.index
    return ExactPlan(QArray.from_fractions(np.array(x, dtype=object)[ix.u].reshape(ix.L, ix.n_v, ix.m)))


FORMULATION = Formulation(
    "openloop", OPENLOOP_FAMILIES, rank=1, evidence_type=OpenLoopPlan, exact_type=ExactPlan, lp_type=OpenLoopLP,
    build=build_openloop_lp, violation=openloop_violation, exact_violation=exact_openloop_violation,
    terms={"float": float_plan_terms, "exact": partial(exact_plan_terms, upper=True)},
    rational_lp=rational_openloop_lp, bounds=openloop_bounds, from_point=_from_point, evidence_names=("u",),
    provenance="openloop-highs")
