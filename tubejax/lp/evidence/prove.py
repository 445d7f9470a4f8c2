"""Proof levels of stored evidence (docs/math/evidence.md#proof-levels): ``'exact'`` (every
constraint holds in rational arithmetic against the rational data, :mod:`tubejax.lp.evidence.check`)
or ``'float'`` (in float64 to ``1e-9`` on unit rows).

:func:`prove_with_basis` is what an edge confirmation runs: zero-margin tubes miss tight rows by an
ulp, so points rebuilt from HiGHS's basis are tried (:mod:`tubejax.lp.evidence.basis`). The first
that passes the exact check becomes the evidence and the float evidence its rounding
(:func:`settle`); otherwise the level stays ``'float'`` and the note says why.
"""

from __future__ import annotations

from fractions import Fraction
from typing import NamedTuple

import numpy as np

from .registry import formulation_of
from ..engines.highs import solve_margin_lp
from .basis import basis_vertex, reconstructed_vertex, snapped_floats, snapped_vertex
from .exact_problem import exact_system
from .rational import QArray
from .rows import _frac_rows, check_against_float

__all__ = ["Proof", "PROOF_LEVELS", "TIGHT_MARGIN", "prove_with_basis", "prove_evidence",
           "settle", "inputs_into_u", "snapped_float_candidate", "exact_violation", "float_violation",
           "rational_lp"]

#: The proof levels an edge can carry, strongest first.
PROOF_LEVELS = ("exact", "float")


class Proof(NamedTuple):
    """The proof level of one piece of evidence.

    Attributes
    ----------
    level : str             ``'exact'`` or ``'float'``
    violation : float       float64 max violation (unit rows) of the float evidence
    exact_violation : Fraction or None
        Exact max violation (max-norm unit rows; ``<= 0`` for ``'exact'``) of the evidence
        that was checked last; ``None`` when the exact check could not run.
    exact : ExactTube, ExactPlan, float evidence or None
            Evidence that replaced the given one: rational, or floats (exact as they are;
        :func:`settle` stores it). ``None``: the given evidence itself is exact, or no proof.
    note : str              how the level was reached, or why not ``'exact'``
    """

    level: str
    violation: float
    exact_violation: Fraction | None
    exact: object
    note: str


def exact_violation(prob, evidence, form=None) -> Fraction:
    """The exact check of ``evidence`` (float or rational) by its LP's record ``form`` (default:
    :func:`~tubejax.lp.evidence.registry.formulation_of` ``evidence``); ``<= 0``: a proof."""
    return (form or formulation_of(evidence)).exact_violation(prob, evidence)


def float_violation(prob, evidence, form=None) -> float:
    """The float64 check of ``evidence`` (rational evidence rounded first) by its LP's record (``form``,
    as in :func:`exact_violation`)."""
    f = form or formulation_of(evidence)
    return f.violation(prob, f.floats(evidence))


def _prove_stored(prob, evidence) -> Proof:
    f = formulation_of(evidence)
    viol = float_violation(prob, evidence, f)
    try:
        ev = exact_violation(prob, evidence, f)
    except (ValueError, ArithmeticError) as exc:
        return Proof("float", viol, None, None, f"exact check could not run: {exc}")
    exact = evidence if f.is_exact(evidence) else None
    if ev <= 0:
        return Proof("exact", viol, ev, exact, "exact check")
    return Proof("float", viol, ev, None, f"exact check fails by {float(ev):.3e}")


def inputs_into_u(prob, evidence):
    """``evidence`` with every input outside ``U`` (exactly) scaled toward 0 until it is inside.

    A non-box ``U`` is a set of hard rows without margin: HiGHS may leave an input a few ulps
    outside it, where snapping to bounds cannot help. With ``0`` in ``U`` (every ``h_f >= 0``),
    ``lambda u`` with ``lambda = min_f h_f / (a_f . u)`` over the facets it leaves is exactly on
    ``U``'s boundary; rows with slack keep it up to that tiny move. The exact check decides.

    Returns
    -------
    ExactTube, ExactPlan or None
        ``None`` when no input leaves ``U``, or ``0`` is not in ``U``.
    """
    ex = _exact_of(evidence)
    a_u, b_u = _frac_rows(exact_system(prob.system).U)
    if any(b < 0 for b in b_u):
        return None
    u = ex.u.to_fractions()
    flat = u.reshape(-1, u.shape[-1])
    moved = False
    for r in range(flat.shape[0]):
        s = [sum((a[d] * flat[r, d] for d in range(len(a))), Fraction(0)) for a in a_u]
        out = [b / v for v, b in zip(s, b_u) if v > b]
        if out:
            lam = min(out)
            flat[r] = [lam * x for x in flat[r]]
            moved = True
    if not moved:
        return None
    uq = QArray.from_fractions(flat.reshape(u.shape))
    return ex._replace(u=uq)


def rational_lp(prob, lp):
    """The rational counterpart of the dense LP ``lp`` of ``prob`` (same rows and columns), by its record."""
    return formulation_of(lp).rational_lp(prob, lp)


def _to_evidence(lp, x: list):
    """A rational point ``x`` (length ``n_x``) -> rational evidence in ``lp``'s layout."""
    return formulation_of(lp).from_point(lp, x)


def _exact_of(evidence):
    """Float evidence as rational evidence (exact values)."""
    return formulation_of(evidence).exact(evidence)


def settle(proof: Proof, evidence):
    """The float evidence to store with ``proof``, and the proof to record.

    Rational evidence that replaced ``evidence`` is stored as its rounding, with no rational
    copy (``exact=None``) when that rounding *is* it; float evidence that replaced it as it is.

    Returns
    -------
    (evidence, Proof)
    """
    if proof.exact is None:
        return evidence, proof
    if not formulation_of(proof.exact).is_exact(proof.exact):     # float evidence, exact as it is
        return proof.exact, proof._replace(exact=None)
    rounded = proof.exact.to_float()
    back = _exact_of(rounded)
    if all(np.array_equal(a.num, b.num) and a.den == b.den for a, b in zip(back, proof.exact)):
        return rounded, proof._replace(exact=None)
    return rounded, proof


#: A HiGHS margin at or below this leaves rows tight at the optimum: the float point misses
#: them by rounding, so the rational reconstruction of the vertex is tried first.
TIGHT_MARGIN = 1e-9


def prove_with_basis(prob, lp, res, evidence, violation: float | None = None,
                     snapped_check: tuple | None = None, first: tuple | None = None) -> Proof:
    """The proof level of HiGHS's evidence, rebuilt from its basis where needed
    (docs/math/evidence.md#exact-decisions).

    With a basis, the first candidate that passes the exact check wins (each only proposes):
    ``'snapped floats'``, ``'snapped'`` (nonbasic variables onto the float, then exact bounds),
    ``'inputs pulled into U'`` (:func:`inputs_into_u`), ``'reconstructed'``
    (:func:`~.basis.reconstructed_vertex`) and ``'basis'`` (:func:`~.basis.basis_vertex`); at a margin
    ``<= TIGHT_MARGIN``, where rounding misses tight rows, ``'reconstructed'`` comes first. Without a
    basis only the evidence is checked.

    Parameters
    ----------
    prob : TubeProblem
    lp : TubeLP or OpenLoopLP        the float LP HiGHS solved
    res : HighsResult                with ``col_status`` / ``row_status`` (else no rebuild)
    evidence : Tube or OpenLoopPlan  ``lp.index.split(res.x)``
    violation : float, optional      the evidence's float check, when the caller has it
    snapped_check : (Fraction, float or None), optional
        The exact and float checks of the ``'snapped floats'`` candidate, when the caller has them
        (:func:`snapped_float_candidate`, checked in a batch).
    first : (ExactTube, Fraction, str, float or None), optional
        A candidate from elsewhere (a translated proof), its exact check, a note and its float
        check, tried before all others.

    Returns
    -------
    Proof
        ``exact`` is set when a vertex other than ``evidence`` proved the edge; ``violation`` is
        then that vertex's float check (what :func:`settle` stores).
    """
    notes = []
    if first is not None:
        cand, ev, note, fv = first
        if ev <= 0:
            return Proof("exact", float_violation(prob, cand) if fv is None else float(fv), ev, cand, note)
        notes.append(f"{note}: fails by {float(ev):.3e}")
    if res.col_status is None:
        stored = _prove_stored(prob, evidence)
        return stored._replace(note="; ".join([stored.note] + notes + ["no basis"]))
    viol = float_violation(prob, evidence) if violation is None else float(violation)
    bounds: list = []
    rational: list = []

    def lp_bounds():
        if not bounds:
            bounds.extend(formulation_of(lp).bounds(prob, lp))
        return bounds

    def snapped_floats_():
        xf = snapped_floats(lp, res.x, res.col_status)
        cand = lp.index.split(xf)
        if np.array_equal(xf, res.x):
            return cand, None, "exact check"
        return cand, cand, "nonbasic variables snapped to their float bounds"   # floats: exact as they are

    def snapped():
        ev = _to_evidence(lp, snapped_vertex(*lp_bounds(), res.x, res.col_status))
        return ev, ev, "nonbasic variables snapped to their bounds"

    def reconstructed():
        ev = _to_evidence(lp, reconstructed_vertex(*lp_bounds(), res.x, res.col_status))
        return ev, ev, "basic values reconstructed as rationals"

    def basis():
        rational.append(rlp := rational_lp(prob, lp))
        ev = _to_evidence(lp, basis_vertex(rlp, res.col_status, res.row_status)[0])
        return ev, ev, "basis vertex solved in rationals"

    def into_u():
        ev = inputs_into_u(prob, lp.index.split(snapped_floats(lp, res.x, res.col_status)))
        if ev is None:
            raise ValueError("no input outside U")
        return ev, ev, "inputs pulled into U"

    order = [snapped_floats_, snapped, into_u, reconstructed, basis]
    if not res.margin > TIGHT_MARGIN:
        order = [reconstructed, snapped_floats_, snapped, into_u, basis]
    for attempt in order:
        try:
            cand, exact, note = attempt()
            known = attempt is snapped_floats_ and snapped_check is not None
            ev = snapped_check[0] if known else exact_violation(prob, cand)
        except (ValueError, ArithmeticError) as exc:      # BasisError, ExactGeometryError
            notes.append(f"{attempt.__name__.strip('_')}: {exc}")
            continue
        if ev <= 0:
            if exact is None:
                fv = viol
            elif known and snapped_check[1] is not None:
                fv = float(snapped_check[1])
            else:
                fv = float_violation(prob, cand)
            return Proof("exact", fv, ev, exact, note)
        notes.append(f"{note}: fails by {float(ev):.3e}")
        if attempt is basis:
            try:
                check_against_float(rational[-1], lp)       # explains a mismatch, if any
            except ValueError as exc:
                notes.append(str(exc))
    stored = _prove_stored(prob, evidence)
    if stored.level == "exact":
        return stored
    return stored._replace(note="; ".join([stored.note] + notes))


def snapped_float_candidate(lp, res):
    """The ``'snapped floats'`` candidate of :func:`prove_with_basis` (the evidence with its
    nonbasic variables on the float LP's bounds), or ``None`` where that is not its first
    candidate (no basis, or a margin ``<= TIGHT_MARGIN``)."""
    if res.col_status is None or not res.margin > TIGHT_MARGIN:
        return None
    return lp.index.split(snapped_floats(lp, res.x, res.col_status))


def prove_evidence(prob, evidence, *, resolve: bool = True) -> Proof:
    """The strongest proof level reachable for stored evidence.

    The evidence is checked exactly; if that fails and ``resolve``, a fresh HiGHS instance
    re-solves the problem (a reused one may end in another, even nearly singular, optimal
    basis) and its basis is rebuilt in rationals (:func:`prove_with_basis`).

    Parameters
    ----------
    prob : TubeProblem
    evidence : Tube, ExactTube, OpenLoopPlan or ExactPlan
    resolve : bool
    """
    first = _prove_stored(prob, evidence)
    if first.level == "exact" or not resolve:
        return first
    lp = formulation_of(evidence).build(prob)
    res = solve_margin_lp(lp, options={"random_seed": 0}, basis_min_margin=-np.inf)
    if res.status != "Optimal":
        return first._replace(note=first.note + f"; HiGHS re-solve: {res.status}")
    pr = prove_with_basis(prob, lp, res, lp.index.split(res.x))
    if pr.level != "exact":
        return first._replace(note=first.note + "; " + pr.note)
    return pr
