"""Translation classes: pairs whose problems are equal up to an exact translation
(docs/explanation/solvers.md#translation-classes).

If ``A c = c``, translating a tube by ``c`` maps the rows C1-C5 of one problem onto the other's
exactly: same feasible horizons, same margin. :class:`TranslationClasses` keys pairs *exactly* (cell
shapes, offset, the source's place up to the translations ``A`` fixes, the case and ``Z``; every
difference by Knuth's two-sum), so pairs share a key only if exact translates. :func:`solve_by_class`
solves one representative per class; a *clearly* infeasible one (bound below ``-TRANSFER_MARGIN``)
settles its class, a likely edge's translates go to HiGHS, and edges are never transferred (a solver may
prove a translate's edge by the representative's exact tube, translated and checked exactly against the
translate's own data: :func:`~tubejax.lp.evidence.translate_verdicts.translated_proofs`). A
transferred non-edge rests on the representative's verdict: the members' exact problems are its
translates, and their float data differ by rounding only, far below ``TRANSFER_MARGIN``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..lp.evidence.decide import Refutation
from ..lp.evidence.verdict import Pending, Verdict
from ..lp.declarations.tube_families import translation_groups
from ..model.system import group_shift

if TYPE_CHECKING:
    from ..model.problem import TubeProblem

__all__ = ["TranslationClasses", "exact_difference", "solve_by_class", "pair_classes",
           "TRANSFER_MARGIN", "TRANSLATE_PROVENANCE"]

#: A representative's verdict settles its class only when its margin is below ``-TRANSFER_MARGIN``
#: (float rounding of the members' own data stays far below it).
TRANSFER_MARGIN = 1e-6
#: Provenance of a non-edge settled by its class's representative.
TRANSLATE_PROVENANCE = "translate"


def exact_difference(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``a - b`` exactly as ``s = fl(a - b)`` plus its rounding error ``err`` (Knuth's two-sum), and
    whether both are finite: two differences are equal as reals iff their ``(s, err)`` are (an exact key)."""
    a, nb = np.asarray(a, dtype=float), -np.asarray(b, dtype=float)
    with np.errstate(all="ignore"):
        s = a + nb
        bp = s - a
        ap = s - bp
        err = (a - ap) + (nb - bp)
    return s, err, np.isfinite(s) & np.isfinite(err)


class TranslationClasses:
    """Keys of exact translation classes for the pairs of a decomposition and a system.

    Attributes
    ----------
    groups : ndarray of int, shape (n,)
        The groups of axes that move together by translations ``A`` fixes (``-1``: an axis that does not).
    """

    def __init__(self, decomp, system):
        self.groups = translation_groups(system)
        cells = decomp.cells
        self.origin = np.array([c.vertices[0] for c in cells], dtype=float)            # (N, n)
        # each source's place up to the translations, exactly: (s, err) and whether finite
        self.place, self.place_err, place_ok = exact_difference(self.origin, group_shift(self.origin, self.groups))
        self.place_ok = place_ok.all(axis=1)
        shape_ids: dict = {}
        self.shape = np.empty(len(cells), dtype=np.int64)
        for i, c in enumerate(cells):
            rel, err, ok = exact_difference(c.vertices, c.vertices[0][None, :])
            key = (c.vertices.shape, rel.tobytes(), err.tobytes()) if ok.all() else ("non-finite", i)
            self.shape[i] = shape_ids.setdefault(key, len(shape_ids))
        self._z: dict = {}                                   # id(Z) -> (Z, its id)
        self._z_ids: dict = {}                               # Z's vertex bytes -> id

    def _z_key(self, z) -> int:
        """A small int per distinct ``Z`` (by its vertices' bytes), cached by object."""
        hit = self._z.get(id(z))
        if hit is None or hit[0] is not z:
            v = np.ascontiguousarray(z.vertices, dtype=float)
            key = (v.shape, v.tobytes())
            n = self._z_ids.setdefault(key, len(self._z_ids))
            hit = self._z[id(z)] = (z, n)
        return hit[1]

    def representatives_of_round(self, rp) -> np.ndarray:
        """:meth:`representatives` of a :class:`~tubejax.model.problem.RoundProblems` (no problem is built)."""
        K = len(rp)
        zk = np.array([self._z_key(z) for z in rp.zs], dtype=np.int64)
        return self.group(rp.src, rp.dst, rp.obstacle, np.column_stack([zk, np.full(K, rp.L)]),
                          np.column_stack([np.full(K, rp.eps_min), np.full(K, rp.min_margin)]))

    def representatives(self, src, dst, obstacle, problems: list["TubeProblem"]) -> np.ndarray:
        """For the pairs ``(src[a], dst[a])``, ``obstacle[a]`` of one round, the index of their class's
        representative (its first pair), shape ``(K,)``; the ``problems``' ``Z``, ``L``, margins enter the key."""
        zk = np.array([self._z_key(p.Z) for p in problems], dtype=np.int64)
        Ls = np.array([int(p.L) for p in problems], dtype=np.int64)
        em = np.array([float(p.eps_min) for p in problems])
        mm = np.array([float(p.min_margin) for p in problems])
        return self.group(src, dst, obstacle, np.column_stack([zk, Ls]), np.column_stack([em, mm]))

    def group(self, src, dst, obstacle, ints=None, floats=None) -> np.ndarray:
        """:meth:`representatives` with the rest of the key given: pairs share a class when they are
        exact translates with equal rows of ``ints`` (shape ``(K, a)``) and ``floats`` (``(K, b)``)."""
        src, dst = np.asarray(src, dtype=int), np.asarray(dst, dtype=int)
        K = len(src)
        if K == 0:
            return np.zeros(0, dtype=np.int64)
        off, err, ok = exact_difference(self.origin[dst], self.origin[src])  # o_j - o_i, exactly
        exact = ok.all(axis=1) & self.place_ok[src]
        ints = np.column_stack([self.shape[src], self.shape[dst], np.asarray(obstacle, dtype=np.int64)]
                               + ([np.asarray(ints, dtype=np.int64).reshape(K, -1)] if ints is not None else []))
        fl = np.column_stack([self.place[src], self.place_err[src], off, err]
                             + ([np.asarray(floats, dtype=float).reshape(K, -1)] if floats is not None else []))
        key = [(ints[a].tobytes(), fl[a].tobytes()) if exact[a] else ("own", a) for a in range(K)]   # own: non-finite
        rep = np.arange(K)
        first: dict = {}
        for a, k in enumerate(key):
            rep[a] = first.setdefault(k, a)
        return rep


def pair_classes(decomp, system, src, dst, ints=None, floats=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The translation classes of the pairs ``(src[a], dst[a])`` (:meth:`TranslationClasses.group`,
    the obstacle case from ``decomp``; ``ints (K, a)`` and ``floats (K, b)`` complete the key).

    Returns
    -------
    first : ndarray of int, shape (R,)
        The position of each class's representative (its first pair), increasing.
    of : ndarray of int, shape (K,)
        The class of each pair (an index into ``first``).
    size : ndarray of int, shape (R,)
        How many pairs each class has.
    """
    src, dst = np.asarray(src, dtype=int).reshape(-1), np.asarray(dst, dtype=int).reshape(-1)
    rep = TranslationClasses(decomp, system).group(src, dst, decomp.obstacle_cases(src, dst), ints, floats)
    return np.unique(rep, return_inverse=True, return_counts=True)      # rep[a] <= a: the firsts, in order


def solve_by_class(solve_batch, classes: TranslationClasses, probs, src, dst, obstacle, progress=None,
                   **kw) -> tuple[list, int]:
    """Verdicts (Verdict or Pending, length K) of ``probs`` (a list, or a ``RoundProblems`` that builds
    only the problems solved), and how many were settled by translation: representatives first (module
    docstring), then the rest, a likely edge's translates as ``likely_edges`` straight to HiGHS (and, to a
    solver with ``proves_from_representatives``, each group's representative as ``representatives``,
    ``(problem, verdict)``: it may prove their edges by translating the representative's exact tube,
    :func:`~tubejax.lp.evidence.translate_verdicts.translated_proofs`)."""
    K = len(probs)
    if isinstance(probs, list):
        rep = classes.representatives(src, dst, obstacle, probs)
        take = lambda idx: [probs[a] for a in idx]          # noqa: E731
    else:
        rep = classes.representatives_of_round(probs)
        take = probs.take
    first = np.flatnonzero(rep == np.arange(K))
    out: list = [None] * K
    for a, v in zip(first.tolist(), solve_batch(take(first), progress=progress, **kw)):
        out[a] = v
    rest, likely, moved = [], {}, {}
    for a in np.flatnonzero(rep != np.arange(K)).tolist():
        r = int(rep[a])
        v = out[r]
        if isinstance(v, Verdict) and v.status == "infeasible" and v.margin < -TRANSFER_MARGIN:
            w = moved.get(r)
            if w is None:                       # one (immutable) verdict for all translates of r
                bound = v.refutation.bound if v.refutation is not None else v.margin
                w = moved[r] = Verdict("infeasible", v.margin, None, TRANSLATE_PROVENANCE, None,
                                       Refutation("translate", bound, (int(src[r]), int(dst[r]))))
            out[a] = w
            continue
        if isinstance(v, Pending) or (isinstance(v, Verdict) and v.status == "edge"):
            likely.setdefault(r, []).append(len(rest))
        rest.append(a)
    n = K - len(first) - len(rest)
    if progress is not None and n:
        progress.update(n)
    if rest:
        if likely and getattr(solve_batch, "supports_likely_edges", False):
            kw = dict(kw, likely_edges=list(likely.values()))     # one group per class
            if getattr(solve_batch, "proves_from_representatives", False):    # each group's representative
                kw["representatives"] = [(take([r])[0], out[r]) for r in likely]
        for a, v in zip(rest, solve_batch(take(rest), progress=progress, **kw)):
            out[a] = v
    return out, n
