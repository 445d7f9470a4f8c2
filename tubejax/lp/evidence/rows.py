"""The margin-form LPs in rationals, row for row in the order of the float LPs.

:func:`rational_tube_lp` mirrors :func:`tubejax.lp.formulations.tube.dense.build_tube_lp` and
:func:`rational_openloop_lp` mirrors :func:`tubejax.lp.formulations.openloop.dense.build_openloop_lp`,
but every coefficient comes from the rational problem data: each float facet row is
matched to the exact facet with the same direction (:func:`match_facets`), ``sigma_W``
is the outward-rounded bound. Rows are not normalised (irrelevant for a vertex); the
margin's coefficient ``c`` is the row's float 2-norm, so ``row / c`` is the float LP's
unit row. :func:`check_against_float` asserts exactly that, so that a basis computed for
the float LP is applied to the same constraints. These rows only *propose* a vertex;
the proof is the exact check of :mod:`tubejax.lp.evidence.check`.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np

from .basis import BasisError, RationalLP, rational_bounds
from .check import openloop_support_upper
from .geometry import ExactPolytope, disturbance_support_upper
from .problem import _cached, _fkey, _w_key, exact_polytope, exact_system, exact_tube_data

__all__ = ["match_facets", "rational_tube_lp", "rational_openloop_lp", "check_against_float",
           "tube_bounds", "openloop_bounds"]

#: A float facet matches an exact facet when their unit normals and offsets agree to this.
MATCH_TOL = 1e-9
#: Each rational row over its float norm must equal the float LP's unit row to this.
ROW_TOL = 1e-7


def match_facets(P: ExactPolytope, H: np.ndarray, h: np.ndarray) -> list[int]:
    """For each float facet ``(H[f], h[f])`` (unit rows), the index of the exact facet of ``P``.

    Raises
    ------
    BasisError
        When a float facet has no exact counterpart (the float H-rep differs from the
        exact hull, e.g. a nearly collinear vertex kept by one and dropped by the other).
    """
    En = np.array([[float(v) for v in r] for r in P.H.tolist()])
    nrm = np.linalg.norm(En, axis=1)
    Eu = En / nrm[:, None]
    eh = P.h.to_float() / nrm
    out = []
    for f in range(H.shape[0]):
        k = int(np.argmax(Eu @ H[f]))
        if not (np.max(np.abs(Eu[k] - H[f])) <= MATCH_TOL and abs(eh[k] - h[f]) <= MATCH_TOL * (1 + abs(h[f]))):
            raise BasisError(f"float facet {f} ({H[f]} . x <= {h[f]}) has no exact counterpart")
        out.append(k)
    return out


def _frac_rows(P: ExactPolytope) -> tuple[list, list]:
    """Facets as lists of Fractions: ``a`` (n_f lists of n) and ``b`` (n_f)."""
    return ([[Fraction(v) for v in r] for r in P.H.tolist()], list(P.h.to_fractions().tolist()))


def _vec_mat(a: list, M: list) -> list:
    """Row vector ``a`` (length n) times matrix ``M`` (n lists of m)."""
    return [sum((a[i] * M[i][j] for i in range(len(a))), Fraction(0)) for j in range(len(M[0]))]


def _dot(a, b) -> Fraction:
    return sum((x * y for x, y in zip(a, b)), Fraction(0))


def rational_tube_lp(prob, lp) -> RationalLP:
    """The rational counterpart of ``lp = build_tube_lp(prob)`` (same rows, same columns).

    Raises
    ------
    BasisError
        When a float facet has no exact counterpart (see :func:`match_facets`).
    """
    d = exact_tube_data(prob)
    sysx = d.system
    ix = lp.index
    L, n, nv, m = ix.L, ix.n, ix.n_v, ix.m
    Zv = [list(r) for r in d.Z.V.to_fractions().tolist()]
    rows, rhs = [], []
    for P, Pf, ells in ((d.safe, prob.safe, range(1, L)), (d.target, prob.target, [L])):
        a_all, b_all = _frac_rows(P)
        idx = match_facets(P, Pf.H, Pf.h)
        sz = [max(_dot(a_all[f], z) for z in Zv) for f in idx]     # sigma_Z(a_f)
        for ell in ells:
            for f, s in zip(idx, sz):
                r = {ix.p_col(ell, dd): a_all[f][dd] for dd in range(n) if a_all[f][dd]}
                if s:
                    r[ix.eps_col(ell)] = s
                rows.append(r)
                rhs.append(b_all[f])
    tpl = _c4_template(prob, d)
    t_coef = [_norm(r) for r in rows]
    relaxed = list(rhs)
    for ell in range(L):
        for k in range(nv):
            for aA, aAz, aB, na, nb, sig, rhs0, c1, c0, dsig in tpl[k]:
                r = {}
                if ell >= 1:
                    for dd in range(n):
                        if aA[dd]:
                            r[ix.p_col(ell, dd)] = aA[dd]
                    if aAz:
                        r[ix.eps_col(ell)] = aAz
                for dd in range(m):
                    if aB[dd]:
                        r[ix.u_col(ell, k, dd)] = aB[dd]
                for dd in range(n):
                    if na[dd]:
                        r[ix.p_col(ell + 1, dd)] = na[dd]
                if nb:
                    r[ix.eps_col(ell + 1)] = nb
                rows.append(r)
                rhs.append(rhs0 if ell == 0 else sig)
                relaxed.append(rhs[-1] + dsig)
                t_coef.append(c0 if ell == 0 else c1)
    hard, hard_rhs = _hard_u_rows(prob, lp, sysx, [(ix.u_col(ell, k, 0)) for ell in range(L) for k in range(nv)])
    lb, ub = tube_bounds(prob, lp)
    return RationalLP(rows, t_coef, rhs, hard, hard_rhs, lb, ub, Fraction(float(lp.t_max)),
                      None if relaxed == rhs else relaxed)


def _norm(values) -> Fraction:
    """The float 2-norm of a row (a dict or a list of Fractions), as a rational (``1`` if zero)."""
    vals = values.values() if isinstance(values, dict) else values
    s = math.sqrt(sum(float(v) ** 2 for v in vals))
    return Fraction(s) if s > 0 else Fraction(1)


def _c4_template(prob, d) -> list:
    """Per source vertex ``k``, per float facet of ``Z`` (in ``prob.Z.H``'s order), the C4 row's
    pieces: ``a A``, ``a A z_k``, ``a B``, ``-a``, ``-b``, ``-sigma_W(a)`` (rhs for ``l >= 1``),
    the rhs for ``l = 0`` (``- sigma_W(a) - a A v_k``), the float norms of both rows, and how
    much the relaxed problem's rhs exceeds it (``sigma_W(a)`` rounded up minus rounded down).
    Cached (the key includes ``Z``'s float H-rep, whose row order the template follows):
    every edge leaving the same cell shares it."""
    key = ("c4tpl",) + _fkey(prob.Z.vertices) + _fkey(prob.Z.H) + _fkey(prob.Z.h) + \
        _fkey(prob.source.vertices) + _fkey(prob.system.A) + _fkey(prob.system.B) + _w_key(prob.system.W)

    def make():
        sysx = d.system
        A = [list(r) for r in sysx.A.to_fractions().tolist()]
        B = [list(r) for r in sysx.B.to_fractions().tolist()]
        Zv = [list(r) for r in d.Z.V.to_fractions().tolist()]
        Vv = [list(r) for r in d.V.to_fractions().tolist()]
        sig_w = list(d.sigma_w.to_fractions().tolist())
        sig_lo = list(disturbance_support_upper(sysx.W, d.Z.H, upper=False).to_fractions().tolist())
        a_z, b_z = _frac_rows(d.Z)
        zidx = match_facets(d.Z, prob.Z.H, prob.Z.h)
        out = []
        for k in range(len(Vv)):
            per = []
            for f in zidx:
                aA, aB = _vec_mat(a_z[f], A), _vec_mat(a_z[f], B)
                aAz = _dot(aA, Zv[k])
                na, nb = [-v for v in a_z[f]], -b_z[f]
                tail = aB + na + [nb]
                per.append((aA, aAz, aB, na, nb, -sig_w[f], -sig_w[f] - _dot(aA, Vv[k]),
                            _norm(aA + [aAz] + tail), _norm(tail), sig_w[f] - sig_lo[f]))
            out.append(per)
        return out

    return _cached(key, make)


def _u_box(sysx, ix) -> dict:
    """``{column of u_k(l)[d]: (lo, hi)}``: the exact bounding box of ``U`` (problem data)."""
    m = len(sysx.u_lo)
    return {ix.u_col(ell, k, dd): (sysx.u_lo[dd], sysx.u_hi[dd])
            for ell in range(ix.L) for k in range(ix.n_v) for dd in range(m)}


def tube_bounds(prob, lp) -> tuple[list, list]:
    """Rational bounds of ``build_tube_lp(prob)``'s variables: ``U``'s exact box for the
    inputs, at least ``eps_min`` (C1) for ``eps``, the implied bounds snapped otherwise."""
    d = exact_tube_data(prob)
    ix = lp.index
    lb, ub = rational_bounds(lp, _u_box(d.system, ix), frozenset(range(ix.eps.start, ix.eps.stop)))
    for ell in range(1, ix.L + 1):                    # C1 is data: eps >= eps_min
        c = ix.eps_col(ell)
        if lb[c] is None or lb[c] < d.eps_min:
            lb[c] = d.eps_min
    return lb, ub


def openloop_bounds(prob, lp) -> tuple[list, list]:
    """Rational bounds of ``build_openloop_lp(prob)``'s variables (``U``'s exact box)."""
    return rational_bounds(lp, _u_box(exact_system(prob.system), lp.index))


def _hard_u_rows(prob, lp, sysx, starts: list) -> tuple[list, list]:
    """C5 rows ``H_u u_k(l) <= h_u`` for a non-box ``U`` (one block per ``(l, k)``, in order)."""
    if lp.G_hard.shape[0] == 0:
        return [], []
    U = sysx.U
    a_u, b_u = _frac_rows(U)
    uidx = match_facets(U, prob.system.U.H, prob.system.U.h)
    rows, rhs = [], []
    for c0 in starts:
        for f in uidx:
            rows.append({c0 + dd: a_u[f][dd] for dd in range(len(a_u[f])) if a_u[f][dd]})
            rhs.append(b_u[f])
    return rows, rhs


def rational_openloop_lp(prob, lp) -> RationalLP:
    """The rational counterpart of ``lp = build_openloop_lp(prob)`` (same rows, same columns).

    Rows without input dependence are dropped or kept as the float builder does
    (kept iff their right-hand side is negative); the row count is checked by
    :func:`check_against_float`.
    """
    sysx = exact_system(prob.system)
    ix = lp.index
    L, nv, m = ix.L, ix.n_v, ix.m
    A = [list(r) for r in sysx.A.to_fractions().tolist()]
    B = [list(r) for r in sysx.B.to_fractions().tolist()]
    n = len(A)
    Vv = [list(r) for r in exact_tube_data_vertices(prob)]
    Ap = [[[Fraction(int(i == j)) for j in range(n)] for i in range(n)]]
    for _ in range(L):
        Ap.append([_vec_mat(row, A) for row in Ap[-1]])          # A^{t+1} = A^t A
    rows, rhs, relaxed = [], [], []
    S, T = exact_polytope(prob.safe), exact_polytope(prob.target)
    for P, Pf, ells, Ls in ((S, prob.safe, range(1, L), max(L - 1, 1)), (T, prob.target, [L], L)):
        a_all, b_all = _frac_rows(P)
        idx = match_facets(P, Pf.H, Pf.h)
        sigf = openloop_support_upper(prob, P, Ls).to_fractions()
        sig_lo = openloop_support_upper(prob, P, Ls, upper=False).to_fractions()
        for ell in ells:
            for k in range(nv):
                for f in idx:
                    a = a_all[f]
                    r = {}
                    for t in range(ell):                           # a A^{ell-1-t} B on u_k(t)
                        coef = _vec_mat(_vec_mat(a, Ap[ell - 1 - t]), B)
                        for dd in range(m):
                            if coef[dd]:
                                r[ix.u_col(t, k, dd)] = coef[dd]
                    g = b_all[f] - sigf[ell][f] - _dot(_vec_mat(a, Ap[ell]), Vv[k])
                    if r or g < 0:
                        rows.append(r)
                        rhs.append(g)
                        relaxed.append(g + sigf[ell][f] - sig_lo[ell][f])
    hard, hard_rhs = _hard_u_rows(prob, lp, sysx, [ix.u_col(ell, k, 0) for ell in range(L) for k in range(nv)])
    lb, ub = openloop_bounds(prob, lp)
    return RationalLP(rows, [_norm(r) for r in rows], rhs, hard, hard_rhs, lb, ub, Fraction(float(lp.t_max)),
                      None if relaxed == rhs else relaxed)


def exact_tube_data_vertices(prob) -> list:
    """The source cell's vertices as lists of Fractions (exact float values)."""
    return [[Fraction(float(v)) for v in row] for row in np.asarray(prob.source.vertices, float)]


def check_against_float(rlp: RationalLP, lp) -> None:
    """Assert that ``rlp`` is ``lp`` row for row (to :data:`ROW_TOL` after scaling).

    Raises
    ------
    BasisError
    """
    nr, nh = lp.G.shape[0], lp.G_hard.shape[0]
    if len(rlp.rows) != nr or len(rlp.hard_rows) != nh:
        raise BasisError(f"the rational LP has {len(rlp.rows)}+{len(rlp.hard_rows)} rows, "
                         f"the float LP {nr}+{nh}")
    for k, (r, c, g) in enumerate(zip(rlp.rows, rlp.t_coef, rlp.rhs)):
        cf = float(c)
        dense = np.zeros(lp.G.shape[1])
        for col, v in r.items():
            dense[col] = float(v) / cf
        if not (np.max(np.abs(dense - lp.G[k])) <= ROW_TOL and abs(float(g) / cf - lp.g[k]) <= ROW_TOL):
            raise BasisError(f"rational row {k} does not match the float LP's row")
    for k, (r, g) in enumerate(zip(rlp.hard_rows, rlp.hard_rhs)):
        dense = np.zeros(lp.G_hard.shape[1])
        for col, v in r.items():
            dense[col] = float(v)
        nrm = float(np.linalg.norm(dense)) or 1.0
        ref = lp.G_hard[k] / (np.linalg.norm(lp.G_hard[k]) or 1.0)
        if not (np.max(np.abs(dense / nrm - ref)) <= ROW_TOL):
            raise BasisError(f"rational hard row {k} does not match the float LP's row")
