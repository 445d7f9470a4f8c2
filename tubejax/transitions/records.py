"""The records of verdicts: an edge (:class:`Edge`) and the evidence of non-edges, stored compactly
beside the edges (docs/math/evidence.md#recorded-evidence).

Every (pair, ``L``) that reached a solver and was refused keeps its
:class:`~tubejax.lp.evidence.decide.Refutation`; :class:`NonEdges` holds them for a system and
:func:`pack`, :func:`unpack` convert them to and from flat arrays
(docs/reference/formats.md#transitionsnpz). Pruned instances have no record:
:func:`tubejax.abstraction.candidates.build_candidates` re-derives them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from fractions import Fraction
from typing import NamedTuple

import numpy as np

from ..lp.evidence.decide import REFUTATION_KINDS, Refutation

__all__ = ["Edge", "EdgeArrays", "NonEdges", "pack", "unpack"]

@dataclass(frozen=True)
class Edge:
    """A confirmed transition ``src -> dst`` in ``L`` steps with margin ``t*``.

    Attributes
    ----------
    proof : str or None
        ``'exact'``, ``'float'``, or ``None`` when unknown (an old file, or ``exact2d``).
    violation : float or None
        Float64 max violation of the stored evidence (unit rows) for ``'float'``;
        ``0.0`` for ``'exact'``.
    exact : ExactTube, ExactPlan or None
        Rational evidence that replaced the float one (the stored float evidence is its
        rounding); not part of equality or ``repr``.
    rho_star : float or None
        The transition's critical disturbance (docs/math/radius.md): the largest ``rho`` with
        ``src -> dst`` an edge at some ``L <= L_max`` under ``W = rho W_0``, in the units of
        the system's own ``W`` (:func:`~tubejax.lp.declarations.radius_disturbance.unit_disturbance`:
        a ball's radius, a cube's half-width, a polytope's scale factor, so ``1`` is the
        polytope itself); at least the system's own radius, since the edge exists there.
        ``None`` when not computed (every run but :mod:`tubejax.analyses.radius_analysis`).
    """

    src: int
    dst: int
    L: int
    margin: float
    provenance: str
    proof: str | None = None
    violation: float | None = None
    exact: object = field(default=None, compare=False, repr=False)
    rho_star: float | None = None

    @classmethod
    def from_verdict(cls, src: int, dst: int, L: int, verdict) -> "Edge":
        """The edge of a confirmed :class:`~tubejax.lp.evidence.verdict.Verdict` (its proof level included)."""
        pr = verdict.proof
        if pr is None:
            return cls(int(src), int(dst), int(L), float(verdict.margin), verdict.provenance)
        return cls(int(src), int(dst), int(L), float(verdict.margin), verdict.provenance, pr.level,
                   0.0 if pr.level == "exact" else float(pr.violation), pr.exact)

    def to_json(self) -> dict:
        d = {"from": self.src, "to": self.dst, "L": self.L, "margin": self.margin,
             "provenance": self.provenance}
        if self.proof is not None:
            d["proof"] = self.proof
            if self.proof != "exact":
                d["violation"] = self.violation
        if self.rho_star is not None:
            d["rho_star"] = self.rho_star
        return d


class EdgeArrays(NamedTuple):
    """A system's edges as arrays, with a sorted key to find a pair's edge by binary search.

    Attributes
    ----------
    src, dst, L : ndarray of int64, shape (E,)
        Edge ``k``'s source, target and horizon, in edge order.
    key : ndarray of int64, shape (E,)
        ``src * n_cells + dst``, sorted.
    order : ndarray of int64, shape (E,)
        The edge of each ``key`` (a stable sort: of edges of one pair, the lowest index first).
    n_cells : int
    """

    src: np.ndarray
    dst: np.ndarray
    L: np.ndarray
    key: np.ndarray
    order: np.ndarray
    n_cells: int

    @classmethod
    def of(cls, edges, n_cells: int) -> "EdgeArrays":
        """The arrays of ``edges``: a sequence of :class:`Edge`, or an object with ``src``, ``dst``, ``L`` arrays
        (:class:`~tubejax.abstraction.product_transitions.ProductEdges`), read without making edge records."""
        if all(hasattr(edges, a) for a in ("src", "dst", "L")):     # read-only views, copies only to int64
            src, dst, L = (np.asarray(getattr(edges, a), dtype=np.int64).view() for a in ("src", "dst", "L"))
        else:
            rows = np.array([(e.src, e.dst, e.L) for e in edges], dtype=np.int64).reshape(-1, 3)
            src, dst, L = (np.ascontiguousarray(rows[:, c]) for c in range(3))
        key = src * np.int64(n_cells) + dst
        order = np.argsort(key, kind="stable").astype(np.int64)
        key = key[order]
        for a in (src, dst, L, key, order):
            a.flags.writeable = False
        return cls(src, dst, L, key, order, int(n_cells))

    def find(self, sources, targets) -> np.ndarray:
        """The edge ``sources[i] -> targets[i]`` of each pair (broadcast together), ``-1`` where there is none
        (a cell id out of range included); of several edges of one pair the lowest index. Same shape as the
        broadcast pairs, int64."""
        i, j = np.broadcast_arrays(np.asarray(sources, dtype=np.int64), np.asarray(targets, dtype=np.int64))
        N = np.int64(self.n_cells)
        q = i * N + j
        at = np.searchsorted(self.key, q)
        ok = np.array((0 <= i) & (i < N) & (0 <= j) & (j < N) & (at < len(self.key)))
        ok[ok] = self.key[at[ok]] == q[ok]
        out = np.full(q.shape, -1, np.int64)
        out[ok] = self.order[at[ok]]
        return out


class NonEdges(NamedTuple):
    """The refused instances of a run with their evidence.

    Attributes
    ----------
    src, dst, L : ndarray of int, shape (F,)
    refutations : list of Refutation, length F
    """

    src: np.ndarray
    dst: np.ndarray
    L: np.ndarray
    refutations: list

    @classmethod
    def empty(cls) -> "NonEdges":
        z = np.zeros(0, dtype=np.int64)
        return cls(z, z.copy(), z.copy(), [])

    def __len__(self) -> int:
        return len(self.refutations)

    def sorted(self) -> "NonEdges":
        """Ordered by ``(src, dst, L)`` (a run's order does not depend on how it was scheduled)."""
        o = np.lexsort((self.L, self.dst, self.src))
        return NonEdges(self.src[o], self.dst[o], self.L[o], [self.refutations[k] for k in o.tolist()])

    def index(self) -> dict:
        """``{(src, dst, L): Refutation}``."""
        return {(int(i), int(j), int(L)): r for i, j, L, r in zip(self.src, self.dst, self.L, self.refutations)}

    def counts(self) -> dict:
        """How many non-edges each kind of evidence settled."""
        out: dict = {}
        for r in self.refutations:
            k = "none" if r is None else r.kind
            out[k] = out.get(k, 0) + 1
        return out

    def arrays(self, prefix: str = "nonedge_") -> dict:
        """Flat arrays for an npz (``<prefix>src``, ``dst``, ``L`` and :func:`pack`'s)."""
        return {f"{prefix}src": np.asarray(self.src, np.int64), f"{prefix}dst": np.asarray(self.dst, np.int64),
                f"{prefix}L": np.asarray(self.L, np.int64), **pack(self.refutations, prefix)}

    @classmethod
    def from_arrays(cls, arrays: dict, prefix: str = "nonedge_") -> "NonEdges":
        """The inverse of :meth:`arrays`; an npz without them gives an empty record.

        Raises
        ------
        ValueError
            Arrays of inconsistent lengths or unknown codes (the message names the array).
        """
        if f"{prefix}src" not in arrays:
            return cls.empty()
        src, dst, L = (np.asarray(arrays[f"{prefix}{n}"]) for n in ("src", "dst", "L"))
        if not (src.shape == dst.shape == L.shape and src.ndim == 1):
            raise ValueError(f"{prefix}src/dst/L: expected three equal 1-D arrays")
        return cls(src.astype(np.int64), dst.astype(np.int64), L.astype(np.int64),
                   unpack(arrays, prefix, len(src)))


def pack(refs: list, prefix: str) -> dict:
    """Arrays of ``refs`` (Refutation or ``None``, length F): ``kind`` int8 (an index into
    :data:`~tubejax.lp.evidence.decide.REFUTATION_KINDS`, ``-1`` for ``None``), ``bound`` float64,
    ``rep`` int64 ``(F, 2)`` (``-1`` unless a translate), and the exact certificates."""
    F = len(refs)
    kind = np.full(F, -1, np.int8)
    bound = np.full(F, np.nan)
    rep = np.full((F, 2), -1, np.int64)
    ptr, rows, ys = [0], [], []
    for a, r in enumerate(refs):
        if r is not None:
            kind[a] = REFUTATION_KINDS.index(r.kind)
            bound[a] = r.bound
            if r.kind == "translate" and r.certificate is not None:
                rep[a] = r.certificate
            if r.kind == "exact" and r.certificate:
                for i in sorted(r.certificate):
                    rows.append(int(i))
                    v = Fraction(r.certificate[i])
                    ys.append(f"{v.numerator}/{v.denominator}")
        ptr.append(len(rows))
    return {f"{prefix}kind": kind, f"{prefix}bound": bound, f"{prefix}rep": rep,
            f"{prefix}cert_ptr": np.array(ptr, np.int64), f"{prefix}cert_rows": np.array(rows, np.int64),
            f"{prefix}cert_y": np.array(ys, dtype=str)}


def unpack(arrays: dict, prefix: str, F: int) -> list:
    """The refutations :func:`pack` wrote for ``F`` instances.

    Raises
    ------
    ValueError
        A missing array, a wrong length, an unknown kind code or a malformed rational.
    """
    try:
        kind, bound, rep = (np.asarray(arrays[f"{prefix}{n}"]) for n in ("kind", "bound", "rep"))
        ptr, rows, ys = (np.asarray(arrays[f"{prefix}{n}"]) for n in ("cert_ptr", "cert_rows", "cert_y"))
    except KeyError as exc:
        raise ValueError(f"array {exc.args[0]!r} is missing") from None
    if kind.shape != (F,) or bound.shape != (F,) or rep.shape != (F, 2) or ptr.shape != (F + 1,):
        raise ValueError(f"{prefix}kind/bound/rep/cert_ptr: expected {F} instances")
    if len(rows) != len(ys) or (F and (ptr[0] != 0 or ptr[-1] != len(rows) or np.any(np.diff(ptr) < 0))):
        raise ValueError(f"{prefix}cert_ptr/cert_rows/cert_y are inconsistent")
    out = []
    for a in range(F):
        k = int(kind[a])
        if k == -1:
            out.append(None)
            continue
        if not 0 <= k < len(REFUTATION_KINDS):
            raise ValueError(f"{prefix}kind[{a}] = {k} is not a known kind")
        name = REFUTATION_KINDS[k]
        cert = None
        if name == "translate":
            cert = (int(rep[a, 0]), int(rep[a, 1]))
        elif name == "exact":
            cert = {}
            for i, s in zip(rows[ptr[a]:ptr[a + 1]].tolist(), ys[ptr[a]:ptr[a + 1]].tolist()):
                try:
                    cert[int(i)] = Fraction(str(s))
                except (ValueError, ZeroDivisionError):
                    raise ValueError(f"{prefix}cert_y: {s!r} is not a rational") from None
        out.append(Refutation(name, float(bound[a]), cert))
    return out
