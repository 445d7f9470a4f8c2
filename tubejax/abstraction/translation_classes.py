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

With ``reflections`` (:func:`system_reflections`: sign flips of whole axis groups that leave ``A``,
``B``, ``U`` and ``W`` exactly unchanged), pairs of box cells are keyed up to those reflections too
(docs/explanation/solvers.md#translation-classes): a reflection maps a problem's rows onto its mirror
image's, so the two have the same feasible horizons and margin. Only non-edges are transferred that way
(:class:`~tubejax.abstraction.joint_projections.ProjectionScreen`); an edge's proof is never moved
across a reflection.
"""

from __future__ import annotations

import itertools
from typing import TYPE_CHECKING

import numpy as np

from ..lp.evidence.decide import Refutation
from ..lp.evidence.verdict import Pending, Verdict
from ..lp.declarations.tube_families import translation_groups
from ..model.geometry import Ball
from ..model.system import group_shift

if TYPE_CHECKING:
    from ..model.problem import TubeProblem

__all__ = ["TranslationClasses", "exact_difference", "solve_by_class", "pair_classes", "system_reflections",
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


def _closed_under(V: np.ndarray, sign: np.ndarray) -> bool:
    """Whether the point set ``V (k, d)`` is mapped onto itself by ``x -> sign * x``, exactly."""
    V = np.asarray(V, dtype=float) + 0.0
    return {tuple(v) for v in V.tolist()} == {tuple(v) for v in (V * sign + 0.0).tolist()}


def system_reflections(system, axis_groups, input_groups) -> np.ndarray:
    """The sign flips of whole groups that leave ``system`` exactly unchanged, shape ``(r, n)`` of +-1 (the
    identity first).

    Flipping a set of groups (their axes, ``S``, and their inputs, ``T``, as given by ``axis_groups (n,)`` and
    ``input_groups (m,)``) is kept when ``S A S = A`` and ``S B T = B`` exactly, ``T U = U`` and ``S W = W`` as
    point sets, and the system has no state constraint. Then a tube of a pair maps to a tube of the flipped
    pair (``p -> S p``, ``u -> T u``) with the same margin, for any ``Z`` with ``S Z = Z``.
    """
    axis_groups, input_groups = np.asarray(axis_groups), np.asarray(input_groups)
    groups = np.unique(axis_groups).tolist()
    out = []
    for flip in itertools.product([False, True], repeat=len(groups)):
        flipped = [g for g, f in zip(groups, flip) if f]
        S, T = np.where(np.isin(axis_groups, flipped), -1.0, 1.0), np.where(np.isin(input_groups, flipped), -1.0, 1.0)
        if not flipped or (not system.state_constraints
                           and np.array_equal(S[:, None] * system.A * S[None, :], system.A)
                           and np.array_equal(S[:, None] * system.B * T[None, :], system.B)
                           and _closed_under(system.U.vertices, T)
                           and (isinstance(system.W, Ball) or _closed_under(system.W.vertices, S))):
            out.append(S)
    return np.array(out)


class TranslationClasses:
    """Keys of exact translation classes for the pairs of a decomposition and a system.

    Parameters
    ----------
    decomp
        Anything with ``cells`` (a sequence of Polytope).
    system : LinearSystem
    reflections : ndarray of +-1, shape (r, n), optional
        :func:`system_reflections` of ``system``: pairs of box cells whose ``Z`` each reflection maps onto
        itself are keyed up to these too (module docstring). Default: translations only.

    Attributes
    ----------
    groups : ndarray of int, shape (n,)
        The groups of axes that move together by translations ``A`` fixes (``-1``: an axis that does not).
    """

    def __init__(self, decomp, system, reflections=None):
        self.groups = translation_groups(system)
        cells = decomp.cells
        self.origin = np.array([c.vertices[0] for c in cells], dtype=float)            # (N, n)
        # each source's place up to the translations, exactly: (s, err) and whether finite
        self.place, self.place_err, place_ok = exact_difference(self.origin, group_shift(self.origin, self.groups))
        self.place_ok = place_ok.all(axis=1)
        self.reflections = (np.asarray(reflections, dtype=float)[1:] if reflections is not None
                            else np.zeros((0, len(self.groups))))
        if len(self.reflections):               # boxes whose first and last vertices are their lo and hi corners
            self.far = np.array([c.vertices[-1] for c in cells], dtype=float)
            self.is_box = np.array([c.is_box and np.array_equal(c.vertices[0], c.bounding_box()[0])
                                    and np.array_equal(c.vertices[-1], c.bounding_box()[1]) for c in cells], dtype=bool)
        self._z_flip: dict = {}                                                    # Z id -> closed under each
        self._mirror_places: dict = {}                                             # reflection -> _mirrored
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
            if len(self.reflections) and n not in self._z_flip:
                self._z_flip[n] = np.array([_closed_under(z.vertices, S) for S in self.reflections], dtype=bool)
        return hit[1]

    def representatives_of_round(self, rp) -> np.ndarray:
        """:meth:`representatives` of a :class:`~tubejax.model.problem.RoundProblems` (no problem is built)."""
        K = len(rp)
        zk = np.array([self._z_key(z) for z in rp.zs], dtype=np.int64)
        return self.group(rp.src, rp.dst, rp.obstacle, np.column_stack([zk, np.full(K, rp.L)]),
                          np.column_stack([np.full(K, rp.eps_min), np.full(K, rp.min_margin)]), z_ids=zk)

    def representatives(self, src, dst, obstacle, problems: list["TubeProblem"]) -> np.ndarray:
        """For the pairs ``(src[a], dst[a])``, ``obstacle[a]`` of one round, the index of their class's
        representative (its first pair), shape ``(K,)``; the ``problems``' ``Z``, ``L``, margins enter the key."""
        zk = np.array([self._z_key(p.Z) for p in problems], dtype=np.int64)
        Ls = np.array([int(p.L) for p in problems], dtype=np.int64)
        em = np.array([float(p.eps_min) for p in problems])
        mm = np.array([float(p.min_margin) for p in problems])
        return self.group(src, dst, obstacle, np.column_stack([zk, Ls]), np.column_stack([em, mm]), z_ids=zk)

    def group(self, src, dst, obstacle, ints=None, floats=None, z_ids=None) -> np.ndarray:
        """:meth:`representatives` with the rest of the key given: pairs share a class when they are
        exact translates with equal rows of ``ints`` (shape ``(K, a)``) and ``floats`` (``(K, b)``); with
        ``reflections``, also exact reflections of translates, where ``z_ids (K,)`` (ids of :meth:`_z_key`,
        also part of ``ints``) says each pair's ``Z`` is mapped onto itself (without it: translations only)."""
        src, dst = np.asarray(src, dtype=int), np.asarray(dst, dtype=int)
        K = len(src)
        if K == 0:
            return np.zeros(0, dtype=np.int64)
        ints = np.column_stack([self.shape[src], self.shape[dst], np.asarray(obstacle, dtype=np.int64)]
                               + ([np.asarray(ints, dtype=np.int64).reshape(K, -1)] if ints is not None else []))
        rest = [np.asarray(floats, dtype=float).reshape(K, -1)] if floats is not None else []
        fl, exact = self._placed(self.origin, self.place, self.place_err, self.place_ok, src, dst, rest)
        key = [(ints[a].tobytes(), fl[a].tobytes()) if exact[a] else ("own", a) for a in range(K)]   # own: non-finite
        if len(self.reflections) and z_ids is not None:
            key = self._least_reflected(key, ints, np.asarray(z_ids), src, dst, rest)
        rep = np.arange(K)
        first: dict = {}
        for a, k in enumerate(key):
            rep[a] = first.setdefault(k, a)
        return rep

    @staticmethod
    def _placed(origin, place, place_err, place_ok, src, dst, rest) -> tuple[np.ndarray, np.ndarray]:
        """The float part of the pairs' keys, shape ``(K, f)``: the source's place, ``o_j - o_i`` (each with its
        rounding error) and ``rest``; and whether it is exact, shape ``(K,)``."""
        off, err, ok = exact_difference(origin[dst], origin[src])          # o_j - o_i, exactly
        return np.column_stack([place[src], place_err[src], off, err] + rest), ok.all(axis=1) & place_ok[src]

    def _least_reflected(self, key: list, ints: np.ndarray, z_ids: np.ndarray, src, dst, rest) -> list:
        """``key`` with each pair's key replaced by the least of its keys under the reflections that apply to
        it: both cells boxes and its ``Z`` (id ``z_ids[a]``) mapped onto itself."""
        box = self.is_box[src] & self.is_box[dst]
        z_ok = np.stack([self._z_flip[z] for z in z_ids.tolist()])
        key = list(key)
        for r in range(len(self.reflections)):
            use = np.flatnonzero(box & z_ok[:, r])
            if use.size == 0:
                continue
            fl, exact = self._placed(*self._mirrored(r), src[use], dst[use], [x[use] for x in rest])
            for k, a in enumerate(use.tolist()):
                if exact[k] and key[a][0] != "own":
                    key[a] = min(key[a], (ints[a].tobytes(), fl[k].tobytes()))
        return key

    def _mirrored(self, r: int) -> tuple:
        """The cells' lower corners under reflection ``r`` (flipped boxes' ``lo`` is ``-hi`` on the flipped
        axes), shape ``(N, n)``, with their exact places and whether finite, as :meth:`_placed` takes them
        (made on first use)."""
        if r not in self._mirror_places:
            origin = np.where(self.reflections[r] < 0, -self.far, self.origin) + 0.0
            place, place_err, ok = exact_difference(origin, group_shift(origin, self.groups))
            self._mirror_places[r] = (origin, place, place_err, ok.all(axis=1))
        return self._mirror_places[r]


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
