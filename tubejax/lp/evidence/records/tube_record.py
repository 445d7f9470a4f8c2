"""The tube LP (Problem 2, docs/math/tube-lp.md) as one record."""

from __future__ import annotations

import numpy as np

from ..check import ExactTube, exact_terms, exact_tube_violation
from ..exact_problem import exact_tube_data
from ..rational import QArray
from ..rows import implied_tube_bounds, rational_tube_lp, tube_bounds
from ...declarations.formulation import Formulation, PdhgForm, RadiusForm
from ...declarations.radius_rows import tube_radius_reference, tube_radius_rows
from ...declarations.tube_lp import TubeLP, build_tube_lp, tube_violation
from ...declarations.tube_variables import Tube
from ...declarations.tube_operator import TUBE_OPERATOR, TubeX, unpack_x
from ...declarations.tube_operator_data import build_tube_data, facet_counts, unmodelled_families, vertex_families
from ....model.problem import TubeProblem
from ...declarations.tube_families import TUBE_FAMILIES, float_terms
from . import SeriesStyle

__all__ = ["FORMULATION", "STYLE", "TUBE_PDHG", "RADIUS_TUBE_PDHG"]


def _exact_terms(prob):
    return exact_terms(exact_tube_data(prob))


def _from_point(lp: TubeLP, x: list) -> ExactTube:
    ix = lp.index
    arr = np.array(x, dtype=object)
    return ExactTube(QArray.from_fractions(arr[ix.p].reshape(ix.L, ix.n)),
                     QArray.from_fractions(arr[ix.eps]),
                     QArray.from_fractions(arr[ix.u].reshape(ix.L, ix.n_v, ix.m)))


# ----------------------------------------------------------------------------- on the batched PDHG engine
def _data(probs, L_pad: int, f_v: tuple, share: bool, W0):
    return build_tube_data(probs, f_v=f_v, L_pad=L_pad, share=share, W0=W0)


def _group_key(p: TubeProblem):
    # the static shape names its VertexIn families: their facet counts are padded per family
    families = tuple(f.name for f in vertex_families(p.system))
    return (p.source.n_vertices, p.Z.H.shape[0], p.system.n, families), id(p.system)


def _dual_key(p: TubeProblem):
    # the same horizon, offset between the cells, case (facets of S) and Z: the same rows up to
    # the right-hand side on a grid (pairs that differ by a translation A does not fix)
    offset = np.round(p.target.centroid - p.source.centroid, 9) + 0.0
    return int(p.L), offset.tobytes(), p.safe.H.shape[0], p.Z.H.tobytes()


def _batched(p: TubeProblem) -> bool:
    return not unmodelled_families(p.system)


def _radius_reference(shape, probs) -> TubeX:
    """The radius form's start, batch axis last: each instance's
    :func:`~tubejax.lp.declarations.radius_rows.tube_radius_reference` at the padded horizon, ``t = 0``."""
    return unpack_x(shape, np.stack([np.append(tube_radius_reference(p, shape.L), 0.0) for p in probs], axis=-1))


def _radius_point(shape, z, problem: TubeProblem) -> Tube:
    x = unpack_x(shape, np.asarray(z, float)[:, None])
    L = int(problem.L)
    u = np.concatenate([x.u0[None], x.u], axis=0)[:L, ..., 0]
    return Tube(x.p[:L, :, 0].copy(), x.eps[:L, 0].copy(), u)


def _radius_batched(p: TubeProblem) -> bool:
    """Every family modelled by the operator (:func:`~tubejax.lp.declarations.tube_operator_data.unmodelled_families`,
    the hard rows of a non-box ``U`` included) and a reference point strictly inside C2 / C3 (with
    ``eps_min = 0`` the reference is the vertex mean of a full-dimensional polytope: interior)."""
    if unmodelled_families(p.system):
        return False
    e = float(p.eps_min)
    return e == 0.0 or not any(np.any(P.H @ P.vertices.mean(axis=0) + e * p.Z.support(P.H) - P.h >= 0)
                               for P in (p.safe, p.target))


def _radius_key(p: TubeProblem):
    return (p.source.n_vertices, p.Z.H.shape[0], p.system.n), id(p.system)


#: The tube LP on the batched engine (its record's ``pdhg``; the default of ``PdhgBatchSolver``): a
#: family the operator does not model sends the system to HiGHS, whose tube is the stored evidence.
TUBE_PDHG = PdhgForm(TUBE_OPERATOR, _group_key, facet_counts, _data, _batched, translates=True,
                     dual_key=_dual_key, ruiz=True)
#: Its radius form (docs/math/radius.md; optimise mode only).
RADIUS_TUBE_PDHG = PdhgForm(TUBE_OPERATOR, _radius_key, facet_counts, _data, _radius_batched,
                            radius=_radius_reference, point=_radius_point)

FORMULATION = Formulation(
    "tube", TUBE_FAMILIES, rank=0, evidence_type=Tube, exact_type=ExactTube, lp_type=TubeLP,
    build=build_tube_lp, violation=tube_violation, exact_violation=exact_tube_violation,
    terms={"float": float_terms, "exact": _exact_terms}, rational_lp=rational_tube_lp, bounds=tube_bounds,
    implied_bounds=implied_tube_bounds, from_point=_from_point, evidence_names=("p", "eps", "u"), provenance="highs",
    pdhg=TUBE_PDHG, radius=RadiusForm(tube_radius_rows, tube_radius_reference, RADIUS_TUBE_PDHG),
    tubes=True, translation_classes=True, product_path=True)
#: How the plots draw its series (:func:`~tubejax.lp.evidence.registry.series_style`).
STYLE = SeriesStyle("#0072B2")                  # Okabe-Ito blue; its series go by Z kind
