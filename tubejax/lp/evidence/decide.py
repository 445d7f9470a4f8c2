"""Exact decisions where floating point cannot decide (docs/math/evidence.md#exact-decisions).

A margin ``t* = 0`` is an edge, and the sign of HiGHS's ``+-1e-17`` must never decide it.
:func:`decide_exactly` settles such an instance, and any whose float evidence is inconclusive, in
rational arithmetic: an exact primal proof, else an exact dual certificate from HiGHS's basis, else
an exact LP solve (:func:`~tubejax.lp.evidence.simplex.exact_simplex`). Certificates refute the
*relaxed* rational problem over bounds Problem 2 implies exactly (:func:`~.rows.implied_tube_bounds`); primal
proofs hold with ``sigma_W`` rounded up; an irrational tie stays ``'unconfirmed'`` (why this is sound:
the page above). Every refusal carries a :class:`Refutation`.
"""

from __future__ import annotations

import logging
import math
from fractions import Fraction
from typing import NamedTuple

import numpy as np

from ..declarations.tube_families import system_regions
from .registry import formulation_of, method_families
from ..declarations.row_families import active
from ..declarations.tube_lp import with_dense_rows
from .basis import BasisError
from .prove import Proof, _to_evidence, exact_violation, float_violation, prove_with_basis, rational_lp
from .simplex import _duals, _columns, _start_from, crossed_column, exact_lp, exact_simplex, farkas_value

__all__ = ["Refutation", "Decision", "certificate_rows", "decide_exactly", "float_dual_bound",
           "float_dual_bound_at_most", "recheck_refutation",
           "EXACT_BAND", "REFUTATION_KINDS"]

log = logging.getLogger("tubejax")

#: HiGHS or PDHG margins with ``|t*|`` at or below this are decided in exact arithmetic.
EXACT_BAND = 1e-9

#: What a non-edge's evidence can be: a float64-checked weak-duality bound (of HiGHS's or the
#: batched solver's duals), an exact rational certificate, exact implied bounds that cross, the
#: refused class representative it translates, or none (an undecided instance, not an edge).
REFUTATION_KINDS = ("dual", "exact", "bounds", "translate", "none")


class Refutation(NamedTuple):
    """Why a (pair, ``L``) is not an edge.

    Attributes
    ----------
    kind : str          one of :data:`REFUTATION_KINDS`
    bound : float       an upper bound of ``t*`` the evidence proves (``< 0``; ``nan`` for
                        ``'none'``; for ``'exact'`` the certificate's value rounded up)
    certificate : object
        ``'exact'``: ``{row: Fraction}``, the multipliers ``y >= 0`` of the margin LP's rows
        (margin rows first, then the hard rows, in the float LP's order); ``'translate'``:
        ``(src, dst)`` of the class representative; else ``None``.
    note : str
    """

    kind: str
    bound: float
    certificate: object = None
    note: str = ""


class Decision(NamedTuple):
    """The outcome of :func:`decide_exactly`: ``status`` ``'edge'``, ``'infeasible'`` or
    ``'unconfirmed'``; an edge's ``evidence`` (float) and ``proof``; a refusal's ``refutation``;
    ``how`` it was decided (``'primal proof'``, ``'dual certificate'``, ``'exact solve'``)."""

    status: str
    evidence: object
    proof: Proof | None
    refutation: Refutation | None
    how: str


def float_dual_bound(lp, res) -> float:
    """The weak-duality bound on ``t*`` of HiGHS's duals ``y = res.y``, ``z = res.y_hard`` (both ``>= 0``),
    in float64 on the float LP, valid for any such ``y, z`` (:mod:`tubejax.lp.engines.certify`);
    ``inf`` when it cannot be formed."""
    y = np.maximum(np.nan_to_num(np.asarray(res.y, float), nan=0.0), 0.0)
    z = getattr(res, "y_hard", None)
    z = np.zeros(lp.G_hard.shape[0]) if z is None else np.maximum(np.nan_to_num(np.asarray(z, float), nan=0.0), 0.0)
    if y.shape != (lp.G.shape[0],) or z.shape != (lp.G_hard.shape[0],):
        return float("inf")
    c = getattr(lp, "t_coef", None)
    s = float(np.sum(y) if c is None else np.dot(np.asarray(c, float), y))
    a = lp.G.T @ y + lp.G_hard.T @ z
    with np.errstate(all="ignore"):
        num = float(lp.g @ y + lp.g_hard @ z + np.sum(np.maximum(-a * lp.lb, -a * lp.ub)))
    if not (s > 1e-300 and np.isfinite(num)):
        return float("inf")
    return num / s


def float_dual_bound_at_most(lp, res, threshold: float, strict: bool = False) -> bool:
    """Whether ``float_dual_bound(lp, res) <= threshold`` (``strict``: ``<``), the answer the dense rows give, read from
    ``lp.G_csr`` where that cannot differ (an LP whose dense ``G`` is not written: a
    :class:`~tubejax.lp.declarations.tube_lp.DenseOnDemand`).

    The sparse and the dense ``G^T y`` add the same products in other orders. Each of the two bounds is
    within ``2 gamma_N (|g|.y + sum_j w_j (|G|^T y)_j) / sum(y)`` of the exact value of the formula over
    the same floats (``gamma_N = N u / (1 - N u)``, ``N`` the rows plus the columns plus 2, ``w`` the larger
    of ``|lb|``, ``|ub|``; Higham's bound for sums in any order): where the sparse bound lies further than
    twice that (plus the division's rounding) from ``threshold``, the dense one is on the same side.
    Elsewhere, and wherever the formula is not the plain one (hard rows, a ``t`` column, a non-finite
    term), the dense rows decide (:func:`float_dual_bound`).
    """
    M = getattr(lp, "G_csr", None)
    y = np.maximum(np.nan_to_num(np.asarray(res.y, float), nan=0.0), 0.0)
    if (M is not None and y.shape == (M.shape[0],) and lp.G_hard.shape[0] == 0
            and getattr(lp, "t_coef", None) is None and getattr(res, "y_hard", None) is not None
            and np.asarray(res.y_hard).size == 0):
        s = float(np.sum(y))
        a = M.T @ y
        with np.errstate(all="ignore"):
            num = float(lp.g @ y + np.sum(np.maximum(-a * lp.lb, -a * lp.ub)))
            w = np.maximum(np.abs(lp.lb), np.abs(lp.ub))
            mag = float(np.abs(lp.g) @ y + np.sum(w * (abs(M).T @ y)))
        n = M.shape[0] + M.shape[1] + 2
        gamma = n * _U / (1.0 - n * _U)
        if s > 1e-300 and math.isfinite(num) and math.isfinite(mag):
            b = num / s
            slack = 4.0 * gamma * mag / s * (1.0 + 4.0 * gamma) + 4.0 * abs(float(np.spacing(b)))
            if b - slack > threshold:
                return False
            if b + slack < threshold:
                return True
    b = float_dual_bound(with_dense_rows(lp), res)
    return b < threshold if strict else b <= threshold


#: The unit roundoff of float64.
_U = 2.0 ** -53


def _exact_rational_lp(prob, lp):
    """The rational margin LP with the bounds its record says a certificate may use
    (:attr:`~tubejax.lp.declarations.formulation.Formulation.implied_bounds`: exact, never tighter than the truth)."""
    rlp = rational_lp(prob, lp)
    lb, ub = formulation_of(lp).implied_bounds(prob, lp)
    return rlp._replace(lb=lb, ub=ub)


def _certificate(y: dict, value: Fraction, s: Fraction | None) -> Refutation:
    """The ``'exact'`` refutation of multipliers ``y`` whose Farkas value is ``value < 0``; its bound
    ``value / s`` (``s = c . y``) rounded up to a float, so that the recorded bound is one."""
    if not s:
        bound = float("-inf")
    else:
        q = value / s
        bound = float(q)
        if Fraction(bound) < q:                  # float() rounds to nearest: step up to an upper bound
            bound = math.nextafter(bound, math.inf)
    return Refutation("exact", bound, {int(i): v for i, v in y.items() if v}, f"value {float(value):.3e}")


def _refute(elp, y: dict, relaxed) -> Refutation | None:
    """The certificate ``y`` (clipped at 0) against the relaxed right-hand sides, or ``None``."""
    yp = {i: v for i, v in y.items() if v > 0}
    if not yp:
        return None
    val = farkas_value(elp, yp, relaxed)
    if val is None or not val < 0:
        return None
    s = sum((v * elp.rows[i][elp.n_x] for i, v in yp.items()), Fraction(0))
    return _certificate(yp, val, s)


def decide_exactly(prob, lp, res, evidence=None, violation: float | None = None, snapped_check=None,
                   first=None) -> Decision:
    """Decide Problem 2 for ``prob`` exactly (see the module doc); ``min_margin`` 0 only.

    Parameters
    ----------
    prob : TubeProblem
    lp : TubeLP or OpenLoopLP        the float LP HiGHS solved
    res : HighsResult                its answer (any status; its basis, if any, seeds every step)
    evidence, violation, snapped_check, first
        As for :func:`~tubejax.lp.evidence.prove.prove_with_basis` (``evidence``: HiGHS's point).
    """
    notes = []
    optimal = res.status == "Optimal" and np.all(np.isfinite(res.x))
    if optimal:                                                         # 1. exact primal proof
        ev = lp.index.split(res.x) if evidence is None else evidence
        pr = prove_with_basis(prob, lp, res, ev, violation, snapped_check, first)
        if pr.level == "exact":
            return Decision("edge", ev, pr, None, "primal proof")
        notes.append(pr.note)
    elif first is not None and first[1] <= 0:
        cand, ev_, note, fv = first
        pr = Proof("exact", float_violation(prob, cand) if fv is None else float(fv), ev_, cand, note)
        return Decision("edge", cand.to_float(), pr, None, "primal proof")
    try:
        rlp = _exact_rational_lp(prob, lp)
    except (ValueError, ArithmeticError) as exc:                       # BasisError, ExactGeometryError
        return _undecided(f"no rational LP: {exc}", notes)
    j = crossed_column(rlp.lb, rlp.ub)
    if j is not None:                                                   # implied bounds cross
        return Decision("infeasible", None, None,
                        Refutation("bounds", float("-inf"), None, f"implied bounds of column {j} cross "
                                   f"({float(rlp.lb[j]):.6g} > {float(rlp.ub[j]):.6g})"), "dual certificate")
    elp = exact_lp(rlp)
    relaxed = None if rlp.rhs_relaxed is None else list(rlp.rhs_relaxed) + list(rlp.hard_rhs)
    cs, rs = (res.col_status, res.row_status) if optimal else (None, None)
    start = _start_from(elp, cs, rs)
    if start is not None:                                               # 2. dual certificate of HiGHS's basis
        try:
            ref = _refute(elp, _duals(elp, _columns(elp), start), relaxed)
        except BasisError as exc:
            ref = None
            notes.append(f"basis duals: {exc}")
        if ref is not None:
            return Decision("infeasible", None, None, ref._replace(note="dual certificate of HiGHS's basis"),
                            "dual certificate")
    try:                                                                # 3. exact LP solve
        sol = exact_simplex(elp, cs, rs, near=res.x if optimal else None)
    except BasisError as exc:
        return _undecided(f"exact simplex: {exc}", notes)
    how = f"exact solve ({sol.pivots} pivots, {'warm' if sol.warm else 'cold'})"
    if sol.feasible:
        cand = _to_evidence(lp, sol.x)
        try:
            ev = exact_violation(prob, cand)
        except (ValueError, ArithmeticError) as exc:
            return _undecided(f"exact check of the exact vertex: {exc}", notes)
        if ev <= 0:
            return Decision("edge", cand.to_float(), Proof("exact", float_violation(prob, cand), ev, cand, how), None,
                            "exact solve")
        return _undecided(f"the exact vertex fails the exact check by {float(ev):.3e}", notes)
    ref = _refute(elp, sol.y, relaxed)
    if ref is None and relaxed is not None:                            # refute the relaxed problem itself
        try:
            sol2 = exact_simplex(elp._replace(rhs=relaxed), near=res.x if optimal else None)
        except BasisError as exc:
            return _undecided(f"exact simplex (relaxed): {exc}", notes)
        if sol2.feasible:
            return _undecided("an irrational tie: infeasible with sigma_W rounded up, feasible rounded down", notes)
        ref = _refute(elp, sol2.y, relaxed)
    if ref is None:
        return _undecided("the exact optimum's duals refute nothing", notes)
    return Decision("infeasible", None, None, ref._replace(note=how), "exact solve")


def _undecided(why: str, notes: list) -> Decision:
    log.warning("exact decision failed: %s", "; ".join([why] + [n for n in notes if n]))
    return Decision("unconfirmed", None, None, Refutation("none", float("nan"), None, why), "none")


def certificate_rows(method: str, system) -> tuple:
    """The row families an exact certificate of ``method``'s margin LP indexes, in row order
    (margin rows, then hard rows; empty for ``exact2d``): what a certificate's row numbers mean.
    Transition files record it, so a later change of the declaration cannot silently change them."""
    fams = active(method_families(method), system_regions(system))
    return tuple(f.name for role in ("margin", "hard") for f in fams if f.lp_role(None, system.u_is_box) == role)


def recheck_refutation(prob, lp, ref: Refutation) -> tuple[bool, str]:
    """Re-check an ``'exact'`` or ``'bounds'`` refutation of ``prob`` against its own rational
    data (no solver): ``(holds, why not)``. Other kinds need a solve (``(False, ...)``)."""
    try:
        rlp = _exact_rational_lp(prob, lp)
    except (ValueError, ArithmeticError) as exc:
        return False, f"no rational LP ({exc})"
    if ref.kind == "bounds":
        return (True, "") if crossed_column(rlp.lb, rlp.ub) is not None else (False, "no implied bounds cross")
    if ref.kind != "exact" or not isinstance(ref.certificate, dict) or not ref.certificate:
        return False, f"a {ref.kind!r} refutation is not an exact certificate"
    elp = exact_lp(rlp)
    if any(not (isinstance(i, int) and 0 <= i < len(elp.rows)) for i in ref.certificate):
        return False, f"the certificate names rows outside 0..{len(elp.rows) - 1}"
    try:
        y = {i: Fraction(v) for i, v in ref.certificate.items()}
        val = farkas_value(elp, y, None if rlp.rhs_relaxed is None else list(rlp.rhs_relaxed) + list(rlp.hard_rhs))
    except (ValueError, TypeError) as exc:
        return False, f"the certificate is malformed ({exc})"
    if val is None:
        return False, "the certificate leaves an unbounded column"
    if not val < 0:
        return False, f"the certificate's value is {float(val):.3e}, not negative"
    return True, ""
