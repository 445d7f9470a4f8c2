"""The tube LP (Problem 2, docs/math/tube-lp.md) as one record."""

from __future__ import annotations

import numpy as np

from ..check import ExactTube, exact_terms, exact_tube_violation
from ..exact_problem import exact_tube_data
from ..rational import QArray
from ..rows import implied_tube_bounds, rational_tube_lp, tube_bounds
from ...engines.tube_pdhg import RADIUS_TUBE_PDHG, TUBE_PDHG
from ...declarations.formulation import Formulation
from ...declarations.radius_rows import RadiusForm, tube_radius_reference, tube_radius_rows
from ...declarations.tube_lp import TubeLP, build_tube_lp, tube_violation
from ...declarations.tube_variables import Tube
from ...declarations.tube_families import TUBE_FAMILIES, float_terms
from . import SeriesStyle

__all__ = ["FORMULATION", "STYLE"]


def _exact_terms(prob):
    return exact_terms(exact_tube_data(prob))


def _from_point(lp: TubeLP, x: list) -> ExactTube:
    ix = lp.index
    arr = np.array(x, dtype=object)
    return ExactTube(QArray.from_fractions(arr[ix.p].reshape(ix.L, ix.n)),
                     QArray.from_fractions(arr[ix.eps]),
                     QArray.from_fractions(arr[ix.u].reshape(ix.L, ix.n_v, ix.m)))


FORMULATION = Formulation(
    "tube", TUBE_FAMILIES, rank=0, evidence_type=Tube, exact_type=ExactTube, lp_type=TubeLP,
    build=build_tube_lp, violation=tube_violation, exact_violation=exact_tube_violation,
    terms={"float": float_terms, "exact": _exact_terms}, rational_lp=rational_tube_lp, bounds=tube_bounds,
    implied_bounds=implied_tube_bounds, from_point=_from_point, evidence_names=("p", "eps", "u"), provenance="highs",
    pdhg=TUBE_PDHG, radius=RadiusForm(tube_radius_rows, tube_radius_reference, RADIUS_TUBE_PDHG),
    tubes=True, translation_classes=True, product_path=True)
#: How the plots draw its series (:func:`~tubejax.lp.evidence.registry.series_style`).
STYLE = SeriesStyle("#0072B2")                  # Okabe-Ito blue; its series go by Z kind
