"""The margin-form LPs in rationals, row for row in the order of the float LPs.

:func:`rational_tube_lp` and :func:`rational_openloop_lp` mirror the float builders with every
coefficient from the rational problem data (facets in the float order, else :class:`BasisError`;
``sigma_W`` rounded outward). Rows are not normalised: the margin's coefficient is the float 2-norm
of the row's normal, and :func:`check_against_float` asserts ``row / c`` is the float LP's row, so a
basis computed for the float LP applies to the same constraints. These rows only *propose* a
vertex; the proof is the exact check of :mod:`tubejax.lp.evidence.check`.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np

from .basis import BasisError, RationalLP
from ..declarations.openloop_families import OPENLOOP_FAMILIES, plan_identity
from ..declarations.tube_lp import rows_key
from ..declarations.tube_families import TUBE_FAMILIES, region_sets, step_regions, tube_identity
from ..declarations.tube_variables import axis_widths, implied_bounds, input_bounds
from ..declarations.row_families import families_in, kept_rows, lp_blocks, state_lengths, zero_rows
from .check import exact_plan_terms, exact_terms
from .exact_geometry import ExactPolytope
from .rational import snap_rational
from .exact_problem import (_cached, _fkey, _pkey, _w_key, disturbance_support_upper, exact_system, exact_tube_data,
                            in_float_order)

__all__ = ["rational_tube_lp", "rational_openloop_lp", "check_against_float",
           "tube_bounds", "implied_tube_bounds", "openloop_bounds"]

#: Each rational row over its float norm must equal the float LP's unit row to this.
ROW_TOL = 1e-7


def _require_float_order(prob, regions, with_input: bool, with_z: bool) -> None:
    """Raise :class:`BasisError` unless the exact facets of every polytope the LP's rows come from
    (``regions`` of :func:`region_sets`, and ``U`` / ``Z`` if ``with_input`` / ``with_z``) are its
    float rows (:func:`~tubejax.lp.evidence.exact_problem.in_float_order`; a nearly collinear vertex
    kept by one hull and dropped by the other fails). The exact checks still use ``co(V)``."""
    given = region_sets(prob)
    sets = [(r, given[r], False) for r in regions] + [("Z", prob.Z, False)] * with_z + \
        [("input", prob.system.U, True)] * with_input
    for name, P, decimals in sets:
        if not in_float_order(P, decimals):
            raise BasisError(f"the float facets of {name} are not its exact facets: no rational rows in "
                             f"the float LP's order")


def _frac_rows(P: ExactPolytope) -> tuple[list, list]:
    """Facets as lists of Fractions: ``a`` (n_f lists of n) and ``b`` (n_f)."""
    return ([[Fraction(v) for v in r] for r in P.H.tolist()], list(P.h.to_fractions().tolist()))


def rational_tube_lp(prob, lp) -> RationalLP:
    """The rational counterpart of ``lp = build_tube_lp(prob)`` (same rows, same columns), from the same
    row families on the rational data; the ``relaxed`` right-hand sides have ``sigma_W`` rounded down.
    Coefficients are derived once per :func:`~tubejax.lp.declarations.tube_lp.rows_key` and exact facets.

    Raises
    ------
    BasisError
        When a float H-rep is not its polytope's exact facets (:func:`_require_float_order`).
    """
    d = exact_tube_data(prob)
    sysm = prob.system
    _require_float_order(prob, d.sets, not sysm.u_is_box, True)
    terms = exact_terms(d)
    low = terms._replace(sigma_w=_cached(("sigw_lo",) + _pkey(prob.Z) + _w_key(sysm.W),
                                         lambda: disturbance_support_upper(d.system.W, d.Z.H, upper=False)))

    # the float rows' key, and the exact facets: a problem whose float data rounds the same
    # (a canonical problem of :mod:`~tubejax.lp.evidence.translate_verdicts`, say) may have other exact facets
    key = rows_key(prob) + _fkey(sysm.U.vertices) + tuple(
        (name, P.H.shape, tuple(P.H.ravel().tolist())) for name, P in sorted(d.sets.items()))
    hit = _RATIONAL_ROWS.pop(key, None)
    rows, t_coef, hard = hit if hit is not None else (
        _matrix(terms, sysm, "margin", TUBE_FAMILIES, tube_identity), _lengths(terms, sysm, TUBE_FAMILIES),
        _matrix(terms, sysm, "hard", TUBE_FAMILIES, tube_identity))
    _RATIONAL_ROWS[key] = (rows, t_coef, hard)                      # most recent last
    if len(_RATIONAL_ROWS) > RATIONAL_ROWS_CACHED:
        _RATIONAL_ROWS.pop(next(iter(_RATIONAL_ROWS)))
    rhs, relaxed, hard_rhs = (_rhs(t, sysm, role) for t, role in ((terms, "margin"), (low, "margin"),
                                                                 (terms, "hard")))
    lb, ub = tube_bounds(prob, lp)
    return RationalLP(rows, t_coef, rhs, hard, hard_rhs, lb, ub, Fraction(float(lp.t_max)),
                      None if relaxed == rhs else relaxed)


#: How many rational row matrices :func:`rational_tube_lp` keeps (least recently used dropped;
#: translates share one, and a matrix of a 10-step 2-D tube is ~0.3 MB of Fractions).
RATIONAL_ROWS_CACHED = 64
_RATIONAL_ROWS: dict = {}


def _matrix(terms, sysm, role: str, families, identity) -> list:
    """Rows ``{column: Fraction}`` (nonzero entries) of the ``role`` blocks of :func:`lp_blocks`, in order."""
    out = []
    for _, _, G, _ in lp_blocks(terms, sysm.m, role, sysm.u_is_box, families, identity):
        num, den = G.num, G.den                                     # shape (n_x, R)
        out += [{c: Fraction(int(num[c, r]), den) for c in np.flatnonzero(num[:, r] != 0).tolist()}
                for r in range(num.shape[1])]
    return out


def _lengths(terms, sysm, families) -> list:
    """The margin rows' state-space lengths (``t``'s coefficients): float 2-norms, as rationals."""
    return list(state_lengths(terms, "margin", sysm.u_is_box,
                              lambda H: np.array([_norm(r) for r in H.to_fractions().tolist()], dtype=object),
                              families))


def _rhs(terms, sysm, role: str, families=TUBE_FAMILIES) -> list:
    """The right-hand sides of the ``role`` rows of :func:`lp_blocks`, as Fractions."""
    out = []
    for f in families_in(families, terms):
        if f.lp_role(terms, sysm.u_is_box) != role:
            continue
        g = f.rhs(terms)
        num = np.broadcast_to(g.num, f.grid(terms))
        if f.compress_vertices:
            num = num[..., 0, :]
        out += [Fraction(int(v), g.den) for v in num.ravel().tolist()]
    return out


def _norm(values) -> Fraction:
    """The float 2-norm of a row (a dict or a list of Fractions), as a rational (``1`` if zero)."""
    vals = values.values() if isinstance(values, dict) else values
    s = math.sqrt(sum(float(v) ** 2 for v in vals))
    return Fraction(s) if s > 0 else Fraction(1)


def _exactly(values, conv=Fraction) -> list:
    """Float bounds as rationals (``conv``), ``None`` where infinite."""
    return [conv(v) if math.isfinite(v) else None for v in values]


def tube_bounds(prob, lp) -> tuple[list, list]:
    """Rational bounds of ``build_tube_lp(prob)``'s variables, where its basis puts a vertex: the float
    bounds taken exactly (``p``'s, coordinates of cell vertices), ``eps``'s snapped (ratios of typed data:
    :func:`~tubejax.lp.evidence.rational.snap_rational`, so ``0.2`` becomes ``1/5``) and at least
    ``eps_min`` (C1, data), ``U``'s exact box for the inputs (data)."""
    ix, eps_min = lp.index, exact_tube_data(prob).eps_min
    lb, ub = _exactly(lp.lb.tolist()), _exactly(lp.ub.tolist())
    lb[ix.eps], ub[ix.eps] = (_exactly(b[ix.eps].tolist(), snap_rational) for b in (lp.lb, lp.ub))
    lb[ix.eps] = [eps_min if v is None or v < eps_min else v for v in lb[ix.eps]]
    lb[ix.u], ub[ix.u] = (b.tolist() for b in input_bounds(ix, exact_system(prob.system).U.bounding_box()))
    return lb, ub


def implied_tube_bounds(prob, lp) -> tuple[list, list]:
    """The bounds on ``build_tube_lp(prob)``'s variables that Problem 2 implies *exactly*
    (:func:`~tubejax.lp.declarations.tube_variables.implied_bounds` of the rational data of
    :func:`~tubejax.lp.evidence.exact_problem.exact_tube_data`), so never tighter than the truth: the
    bounds of a certificate of infeasibility. They cross where Problem 2 is infeasible on these grounds.

    Returns
    -------
    lb, ub : list of Fraction, length ``lp.index.size``
    """
    d, ix = exact_tube_data(prob), lp.index
    boxes = {r: d.sets[r].bounding_box() for r in set(step_regions(ix.L))}
    lb, ub = implied_bounds(ix, boxes, axis_widths(d.Z), axis_widths(d.system.W), d.eps_min,
                            d.system.U.bounding_box())
    return lb.tolist(), ub.tolist()


def openloop_bounds(prob, lp) -> tuple[list, list]:
    """Rational bounds of ``build_openloop_lp(prob)``'s variables: ``U``'s exact box (data), at once the
    bounds of its basis's vertex and of a certificate."""
    return tuple(b.tolist() for b in input_bounds(lp.index, exact_system(prob.system).U.bounding_box()))


def rational_openloop_lp(prob, lp) -> RationalLP:
    """The rational counterpart of ``lp = build_openloop_lp(prob)`` (same rows, same columns).

    As :func:`rational_tube_lp`, from
    :data:`~tubejax.lp.declarations.openloop_families.OPENLOOP_FAMILIES` (``relaxed``: ``sigma_D``
    rounded down). Rows without input dependence are dropped or kept by the float builder's rule
    (:func:`~tubejax.lp.declarations.row_families.kept_rows`).
    """
    sysm = prob.system
    _require_float_order(prob, ("safe", "target"), True, False)
    terms, low = exact_plan_terms(prob, True), exact_plan_terms(prob, False)
    fams = OPENLOOP_FAMILIES
    rows, rhs = _matrix(terms, sysm, "margin", fams, plan_identity), _rhs(terms, sysm, "margin", fams)
    keep = np.flatnonzero(kept_rows(zero_rows(rows), np.array(rhs, dtype=object)))
    rows, t_coef, rhs, relaxed = ([v[k] for k in keep] for v in (rows, _lengths(terms, sysm, fams), rhs,
                                                                  _rhs(low, sysm, "margin", fams)))
    lb, ub = openloop_bounds(prob, lp)
    return RationalLP(rows, t_coef, rhs, _matrix(terms, sysm, "hard", fams, plan_identity),
                      _rhs(terms, sysm, "hard", fams), lb, ub, Fraction(float(lp.t_max)),
                      None if relaxed == rhs else relaxed)


def check_against_float(rlp: RationalLP, lp) -> None:
    """Assert that ``rlp`` is ``lp`` row for row (to :data:`ROW_TOL` after scaling); ``BasisError``
    otherwise."""
    nr, nh = lp.G.shape[0], lp.G_hard.shape[0]
    if len(rlp.rows) != nr or len(rlp.hard_rows) != nh:
        raise BasisError(f"the rational LP has {len(rlp.rows)}+{len(rlp.hard_rows)} rows, "
                         f"the float LP {nr}+{nh}")

    def dense(row: dict, width: int) -> np.ndarray:
        out = np.zeros(width)
        out[list(row)] = [float(v) for v in row.values()]
        return out

    for k, (r, c, g) in enumerate(zip(rlp.rows, rlp.t_coef, rlp.rhs)):
        cf = float(c)
        if not (np.max(np.abs(dense(r, lp.G.shape[1]) / cf - lp.G[k])) <= ROW_TOL
                and abs(float(g) / cf - lp.g[k]) <= ROW_TOL):
            raise BasisError(f"rational row {k} does not match the float LP's row")
    for k, r in enumerate(rlp.hard_rows):
        row = dense(r, lp.G_hard.shape[1])
        nrm = float(np.linalg.norm(row)) or 1.0
        ref = lp.G_hard[k] / (np.linalg.norm(lp.G_hard[k]) or 1.0)
        if not (np.max(np.abs(row / nrm - ref)) <= ROW_TOL):
            raise BasisError(f"rational hard row {k} does not match the float LP's row")
