"""An independent exact checker for the tests, written straight from docs/math/tube-lp.md and docs/math/open-loop.md.

Plain Fractions and loops, no numpy arithmetic, no code from ``tubejax.lp.evidence`` or
``tubejax.lp.declarations.tube_lp``: facets come from the polygons' counter-clockwise vertex order
(2-D) or the end points (1-D). Each row ``a . x <= b`` is reported as
``(a . x - b) / max|a|``, a value that does not depend on how the row is scaled, so it
must equal :func:`tubejax.lp.evidence.exact_tube_violation` exactly.
"""

import math
from fractions import Fraction

from tubejax.model.geometry import Ball


def dec(x) -> Fraction:
    return Fraction(repr(float(x)))


def exact(x) -> Fraction:
    return Fraction(float(x))


def facets(vertices, rational=exact):
    """``[(a, b)]`` of the convex polygon / interval with these vertices (CCW in 2-D)."""
    V = [[rational(c) for c in v] for v in vertices]
    if len(V[0]) == 1:
        xs = [v[0] for v in V]
        return [([Fraction(-1)], -min(xs)), ([Fraction(1)], max(xs))]
    out = []
    for a, b in zip(V, V[1:] + V[:1]):
        nrm = [b[1] - a[1], a[0] - b[0]]
        out.append((nrm, nrm[0] * a[0] + nrm[1] * a[1]))
    return out


def row(a, x, b) -> Fraction:
    return (sum(ai * xi for ai, xi in zip(a, x)) - b) / max(abs(v) for v in a)


def sigma_w(W, a) -> Fraction:
    if isinstance(W, Ball):
        sq = Fraction(sum(v * v for v in a))
        rn, rd = math.isqrt(sq.numerator), math.isqrt(sq.denominator)
        if rn * rn != sq.numerator or rd * rd != sq.denominator:
            raise ValueError("the reference checker handles ball rows with rational norms only")
        return dec(W.radius) * Fraction(rn, rd)
    return max(sum(ai * dec(w) for ai, w in zip(a, v)) for v in W.vertices)


def matvec(M, x):
    return [sum(M[i][j] * x[j] for j in range(len(x))) for i in range(len(M))]


def tube_violation(prob, p, eps, u) -> Fraction:
    """Max over C1-C5 (docs/math/tube-lp.md) for a tube given as nested lists of Fractions."""
    s = prob.system
    A = [[dec(v) for v in r] for r in s.A]
    B = [[dec(v) for v in r] for r in s.B]
    L = int(prob.L)
    V = [[exact(c) for c in v] for v in prob.source.vertices]
    Zv = [[exact(c) for c in v] for v in prob.Z.vertices]
    q = [V] + [[[p[ell][d] + eps[ell] * z[d] for d in range(len(z))] for z in Zv] for ell in range(L)]
    out = [dec(prob.eps_min) - e for e in eps]                                  # C1
    for ell in range(1, L):                                                     # C2
        out += [row(a, qk, b) for qk in q[ell] for a, b in facets(prob.safe.vertices)]
    out += [row(a, qk, b) for qk in q[L] for a, b in facets(prob.target.vertices)]  # C3
    for ell in range(L):                                                        # C4
        for k, qk in enumerate(q[ell]):
            nxt = [x + y - z for x, y, z in zip(matvec(A, qk), matvec(B, u[ell][k]), p[ell])]
            for a, b in facets(prob.Z.vertices):
                lhs = sum(ai * xi for ai, xi in zip(a, nxt)) - eps[ell] * b + sigma_w(s.W, a)
                out.append(lhs / max(abs(v) for v in a))
    for ell in range(L):                                                        # C5
        out += [row(a, u[ell][k], b) for k in range(len(V)) for a, b in facets(s.U.vertices, dec)]
    return max(out)


def openloop_violation(prob, u) -> Fraction:
    """Max over the open-loop constraints (docs/math/open-loop.md), ``u[l][k]`` lists of Fractions."""
    s = prob.system
    A = [[dec(v) for v in r] for r in s.A]
    B = [[dec(v) for v in r] for r in s.B]
    L = int(prob.L)
    n = len(A)
    x = [[[exact(c) for c in v] for v in prob.source.vertices]]
    for ell in range(L):
        x.append([[a + b for a, b in zip(matvec(A, xk), matvec(B, u[ell][k]))] for k, xk in enumerate(x[-1])])

    def sigma_d(a, ell):                  # sum_{t<ell} sigma_W((A^t)^T a), with a A^t as a row
        total, r = Fraction(0), list(a)
        for _ in range(ell):
            total += sigma_w(s.W, r)
            r = [sum(r[i] * A[i][j] for i in range(n)) for j in range(n)]
        return total

    out = [row(a, u[ell][k], b) for ell in range(L) for k in range(len(x[0]))
           for a, b in facets(s.U.vertices, dec)]
    for ell in range(1, L):
        out += [row(a, xk, b - sigma_d(a, ell)) for xk in x[ell] for a, b in facets(prob.safe.vertices)]
    out += [row(a, xk, b - sigma_d(a, L)) for xk in x[L] for a, b in facets(prob.target.vertices)]
    return max(out)


def as_lists(tube):
    """A Tube / ExactTube -> nested lists of Fractions ``(p, eps, u)``."""
    from tubejax.lp.evidence import ExactTube

    t = ExactTube.coerce(tube)
    return (t.p.to_fractions().tolist(), t.eps.to_fractions().tolist(), t.u.to_fractions().tolist())
