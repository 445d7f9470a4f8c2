"""The disturbed linear system ``x+ = A x + B u + w`` with ``u in U``, ``w in W``."""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

import flint
import numpy as np

from ..errors import InputError
from .geometry import Ball, Halfspaces, HalfspacesError, Polytope

__all__ = ["LinearSystem", "STATE_CONSTRAINTS", "box_input_set", "one_norm_input_set", "SystemError_",
           "translation_groups", "group_shift", "exact_matrix"]


class SystemError_(InputError):
    """Inconsistent system data; the message names the field (``A``, ``B``, ``U``, ``W``)."""


def _matrix(value, name: str) -> np.ndarray:
    try:
        return np.asarray(value, float)
    except (TypeError, ValueError, OverflowError):
        raise SystemError_(f"{name}: expected a matrix of numbers, got {value!r}") from None


def box_input_set(bound, m: int | None = None) -> Polytope:
    """The box ``U = {u : |u_i| <= bound_i}``, vertices ``(2**m, m)``; ``bound``: finite ``> 0``, a
    float (then give the input dimension ``m``) or shape ``(m,)``."""
    b = np.atleast_1d(_matrix(bound, "U.bound"))
    if b.ndim != 1:
        raise SystemError_(f"U.bound: expected a number or a vector of numbers, got {bound!r}")
    if b.size == 1 and m is not None:
        b = np.full(m, float(b[0]))
    if not np.all(np.isfinite(b)) or np.any(b <= 0):
        raise SystemError_(f"U: box bounds must be > 0 and finite so that 0 is interior, got {b.tolist()}")
    return Polytope.box(-b, b)


def one_norm_input_set(radius: float, m: int) -> Polytope:
    """``U = {u : ||u||_1 <= radius}``, vertices ``(2m, m)``: the named alternative to the box
    (docs/math/tube-lp.md#paper-slips)."""
    if not np.isfinite(radius) or radius <= 0:
        raise SystemError_(f"U: 1-norm radius must be finite and > 0, got {radius}")
    V = np.vstack([radius * np.eye(m), -radius * np.eye(m)])
    return Polytope.from_vertices(V)


#: The optional state constraints of :class:`LinearSystem` by field name (each a ``Halfspaces`` every
#: tube vertex must satisfy, or ``None``); all readers go through :attr:`LinearSystem.state_constraints`.
STATE_CONSTRAINTS: tuple = ("X",)


@dataclass(frozen=True, eq=False, kw_only=True)
class LinearSystem:
    """``x(k+1) = A x(k) + B u(k) + w(k)``, built by keyword: ``LinearSystem(A=..., B=..., U=..., W=...)``.

    It owns its file record (:meth:`record`, :meth:`from_record`) and its comparison
    (:meth:`differences`); its exact form is :func:`tubejax.lp.evidence.exact_problem.exact_system`.

    Attributes
    ----------
    A : ndarray, shape (n, n)
    B : ndarray, shape (n, m)
    U : Polytope
        Input set in ``R^m`` with 0 in its interior.
    W : Ball or Polytope
        Bounded disturbance set in ``R^n`` containing 0.
    X : Halfspaces or None
        The state constraint ``X = {x : H_x x <= h_x}`` (bounded or not): every tube vertex
        ``q_k(l)``, ``l = 1..L``, lies in it (docs/math/tube-lp.md#state-constraint); ``None``: none.
        Given as ``{"H": rows, "h": offsets}`` (e.g. ``{"H": [[0, 1]], "h": [5.5]}``) it is made a
        :class:`Halfspaces`.
    """

    A: np.ndarray
    B: np.ndarray
    U: Polytope
    W: Ball | Polytope
    X: Halfspaces | None = None

    def __post_init__(self):
        self._check_dynamics()
        for name, S in self.state_constraints.items():
            if isinstance(S, dict):                 # {"H": rows, "h": offsets}, as in the config and the file
                if set(S) != {"H", "h"}:
                    raise SystemError_(f"system.{name}: expected a Halfspaces or a mapping with the keys H and h "
                                       f"({{x : H x <= h}}), got the keys {sorted(map(str, S))}")
                S = Halfspaces(S["H"], S["h"], name=f"system.{name}")
                object.__setattr__(self, name, S)
            if not isinstance(S, Halfspaces):
                raise SystemError_(f"system.{name} must be a Halfspaces {{x : H x <= h}}, got {type(S).__name__}")
            if S.dim != self.n:
                raise SystemError_(f"system.{name}.H: rows live in R^{S.dim}, but the state is in R^{self.n}")

    @property
    def state_constraints(self) -> dict:
        """The state constraints that are set, ``{field name: Halfspaces}`` in
        :data:`STATE_CONSTRAINTS` order (empty when there are none)."""
        return {name: getattr(self, name) for name in STATE_CONSTRAINTS if getattr(self, name) is not None}

    def _check_dynamics(self):
        """Check ``A``, ``B``, ``U``, ``W`` (messages name the field) and store ``A``, ``B`` as float arrays."""
        A = _matrix(self.A, "A")
        B = _matrix(self.B, "B")
        if A.ndim != 2 or A.shape[0] != A.shape[1] or A.shape[0] == 0:
            raise SystemError_(f"A must be a square (n, n) matrix, got shape {A.shape}")
        n = A.shape[0]
        if B.ndim == 1 and n == 1:
            B = B.reshape(1, -1)
        if B.ndim != 2 or B.shape[0] != n:
            raise SystemError_(f"B must have shape ({n}, m) to match A of shape {A.shape}, got {B.shape}")
        if B.shape[1] == 0:
            raise SystemError_(f"B must have at least one column, got shape {B.shape}")
        if not (np.all(np.isfinite(A)) and np.all(np.isfinite(B))):
            raise SystemError_("A and B must be finite (they hold NaN or infinity)")
        m = B.shape[1]
        if not isinstance(self.U, Polytope):
            raise SystemError_(f"U must be a Polytope, got {type(self.U).__name__}")
        if self.U.dim != m:
            raise SystemError_(f"U lives in R^{self.U.dim} but B has m = {m} columns")
        if not (np.all(np.isfinite(self.U.vertices)) and np.all(np.isfinite(self.U.h))):
            raise SystemError_("U must be finite (its vertices or facets hold NaN or infinity)")
        if np.any(self.U.h <= 1e-12):
            raise SystemError_("U must contain 0 in its interior (some facet offset h_u <= 0)")
        if not isinstance(self.W, (Ball, Polytope)):
            raise SystemError_(f"W must be a Ball or a bounded Polytope, got {type(self.W).__name__}")
        if self.W.dim != n:
            where = "is a ball" if isinstance(self.W, Ball) else "lives"
            raise SystemError_(f"W {where} in R^{self.W.dim}, but the state is in R^{n}")
        if isinstance(self.W, Polytope):
            if not (np.all(np.isfinite(self.W.vertices)) and np.all(np.isfinite(self.W.h))):
                raise SystemError_("W must be finite (its vertices or facets hold NaN or infinity)")
            if np.any(self.W.h < -1e-12):
                raise SystemError_("W must contain 0 (some facet offset is negative)")
        object.__setattr__(self, "A", A)
        object.__setattr__(self, "B", B)

    n = property(lambda self: int(self.A.shape[0]), doc="State dimension.")
    m = property(lambda self: int(self.B.shape[1]), doc="Input dimension.")

    @property
    def u_is_box(self) -> bool:
        """True when ``U`` is an axis-aligned box, decided exactly (:attr:`Polytope.is_box`, no
        tolerance): then C5 becomes variable bounds."""
        return self.U.is_box

    def u_box(self) -> tuple[np.ndarray, np.ndarray]:
        """The bounding box of ``U``, ``(lower, upper)`` each of shape ``(m,)``."""
        return self.U.bounding_box()

    def record(self) -> dict:
        """The system as a transitions file records it: ``A``, ``B`` (lists), ``U`` by its vertices,
        ``W`` as ``{"kind": "ball", "radius", "dim"}`` or ``{"kind": "polytope", "vertices"}``."""
        W = self.W
        Wj = ({"kind": "ball", "radius": W.radius, "dim": W.dim} if isinstance(W, Ball)
              else {"kind": "polytope", "vertices": W.vertices.tolist()})
        rec = {"A": self.A.tolist(), "B": self.B.tolist(), "U": {"vertices": self.U.vertices.tolist()}, "W": Wj}
        rec.update({name: S.record() for name, S in self.state_constraints.items()})
        return rec

    @classmethod
    def from_record(cls, rec: dict) -> "LinearSystem":
        """The system of a :meth:`record` (validated by the file reader); a ``SystemError_`` naming the
        part for a record that gives no valid system."""
        unknown = sorted(set(rec) - {"A", "B", "U", "W", *STATE_CONSTRAINTS})
        if unknown:
            raise SystemError_(f"system.{unknown[0]}: not a part of the system (expected A, B, U, W"
                               + "".join(f", {c}" for c in STATE_CONSTRAINTS) + ")")
        W = rec["W"]
        W = Ball(int(W["dim"]), float(W["radius"])) if W["kind"] == "ball" else Polytope.from_vertices(W["vertices"])
        try:
            X = {c: Halfspaces.from_record(rec[c], f"system.{c}") for c in STATE_CONSTRAINTS
                 if rec.get(c) is not None}
        except HalfspacesError as exc:
            raise SystemError_(str(exc)) from None
        return cls(A=np.array(rec["A"], dtype=float), B=np.array(rec["B"], dtype=float),
                   U=Polytope.from_vertices(rec["U"]["vertices"]), W=W, **X)

    def differences(self, other: "LinearSystem") -> list[str]:
        """The parts (``'A'``, ``'B'``, ``'U'``, ``'W'`` and the state constraints) in which ``other``
        differs, bit for bit as recorded (``U`` and a polytope ``W`` by their vertices, a ball by its
        radius and dimension, a state constraint by its rows; one set on one side only differs)."""
        def same(a, b):
            a, b = np.asarray(a, float), np.asarray(b, float)
            return a.shape == b.shape and np.array_equal(a, b)

        out = [name for name, a, b in (("A", self.A, other.A), ("B", self.B, other.B),
                                       ("U", self.U.vertices, other.U.vertices)) if not same(a, b)]
        W, V = self.W, other.W
        if isinstance(W, Ball) != isinstance(V, Ball) or (
                isinstance(W, Ball) and (W.radius != V.radius or W.dim != V.dim)) or (
                not isinstance(W, Ball) and not same(W.vertices, V.vertices)):
            out.append("W")
        for name in STATE_CONSTRAINTS:
            S, T = getattr(self, name), getattr(other, name)
            if (S is None) != (T is None) or (S is not None and not S.same_as(T)):
                out.append(name)
        return out


def translation_groups(K: np.ndarray) -> np.ndarray:
    """Groups of axes that move together by translations ``c`` with ``K c = 0`` exactly, shape
    ``(n,)`` of int: ``-1`` for an axis that does not move, else its group's first axis.

    The translations meant are ``c = Σ_g a_g 1_g`` (any amount on every axis of group ``g`` alike):
    for ``K = A - I`` (:mod:`tubejax.abstraction.translation_classes`) an axis ``A`` fixes is a group,
    and the double integrator in look-ahead coordinates moves ``p`` and ``s`` together. Found in
    rationals: axes on which every vector of the exact null space of ``K`` agrees form a candidate
    group, kept only if ``K 1_g = 0`` exactly, so every translation meant is in ``ker K``.

    Parameters
    ----------
    K : ndarray of float or Fraction, shape (k, n)
        Taken at its exact values (:func:`exact_matrix`; ``A - I`` rounded in floats would not be).

    Returns
    -------
    ndarray of int, shape (n,)
    """
    K = np.asarray(K, dtype=object)
    k, n = K.shape
    qs = [Fraction(x) for x in K.ravel().tolist()]
    R, rank = flint.fmpq_mat(k, n, [flint.fmpq(q.numerator, q.denominator) for q in qs]).rref()   # exactly
    rows = [[R[i, c] for c in range(n)] for i in range(rank)]
    pivots = [next(c for c in range(n) if r[c] != 0) for r in rows]
    free = [c for c in range(n) if c not in pivots]
    basis = {c: [int(c == f) for f in free] for c in free}  # null space: one vector per free axis
    for k, c in enumerate(pivots):
        basis[c] = [-rows[k][f] for f in free]
    out = np.full(n, -1, dtype=np.int64)
    for c in range(n):
        if out[c] >= 0 or not any(basis[c]):
            continue
        group = [d for d in range(n) if basis[d] == basis[c]]
        if all(sum(r[d] for d in group) == 0 for r in rows):   # K 1_g = 0 exactly
            out[group] = c
    return out


def exact_matrix(M, minus_identity: bool = False) -> np.ndarray:
    """``M`` (floats) as exact Fractions, less the identity exactly if asked, shape like ``M`` (object)."""
    M = np.asarray(M, dtype=float)
    out = np.array([[Fraction(x) for x in r] for r in M.tolist()], dtype=object).reshape(M.shape)
    if minus_identity:
        for k in range(min(M.shape)):
            out[k, k] -= 1
    return out


def group_shift(points: np.ndarray, groups: np.ndarray) -> np.ndarray:
    """The translation of :func:`translation_groups` that takes ``points (..., n)`` to their place up to
    those translations, negated: on each group's axes the coordinate on its first axis, 0 elsewhere."""
    points = np.asarray(points, dtype=float)
    return np.where(groups >= 0, points[..., np.maximum(groups, 0)], 0.0)
