"""The system ``x+ = A x + B u + w`` of the input model: ``A``, ``B``, ``U`` and the disturbance ``W``.

Every entry is finite, at most :data:`~tubejax.inputs.values.MAX_MAGNITUDE` in magnitude. A polytope
``U`` must have 0 in its interior, a polytope ``W`` contain 0, and both have volume, checked here so a
qhull failure never reaches the user (:func:`check_vertex_form`). A ball ``W``'s radius is in
``[0, 1e6]``.
"""

from __future__ import annotations

from typing import Annotated, ClassVar, Literal, Union

import numpy as np
from pydantic import BeforeValidator, Field, model_validator

from ..errors import GeometryError
from ..model.geometry import Ball, Halfspaces, Polytope
from ..model.system import LinearSystem, box_input_set, one_norm_input_set
from ..model.system_kinds import SYSTEM_KINDS, SystemKindError
from .values import (MAX_MAGNITUDE, StrictModel, _fail, _num, _number, integer, matrix, problem, real,
                     register_tags, short, vector)

__all__ = ["UBox", "UOneNorm", "UPolytope", "InputSet", "StateConstraint", "SystemModel", "check_vertex_form",
           "BallDisturbance", "BoxDisturbance", "PolytopeDisturbance", "Disturbance"]

_POSITIVE = f"a finite number in (0, {_num(MAX_MAGNITUDE)}]"


def _box_bound(value):
    """A positive number, or a list of positive numbers (one per input)."""
    expected = f"{_POSITIVE}, or a list of such numbers (one per input)"
    items = value if isinstance(value, (list, tuple)) else [value]
    if isinstance(value, (list, tuple)) and not value:
        raise _fail(expected)
    out = [_number(x, expected) for x in items]
    if any(not (0 < x <= MAX_MAGNITUDE) for x in out):
        raise _fail(expected)
    return out[0] if not isinstance(value, (list, tuple)) else out


def _same_matrix(given, value) -> bool:
    """Whether ``given`` (as the user wrote it) is the matrix ``value`` (floats), entry for entry."""
    try:
        return np.array_equal(np.asarray(given, float), np.asarray(value, float))
    except (TypeError, ValueError, OverflowError):
        return False


def _polytope(vertices, what: str) -> Polytope:
    try:
        return Polytope.from_vertices(np.asarray(vertices, float))
    except GeometryError as exc:
        raise problem("vertices", f"{what}: {exc}") from None


#: Largest dimension in which :func:`check_vertex_form` runs qhull on all ``2^n`` corners of a box
#: (milliseconds; 8-D takes seconds); a larger box is checked through its 6-D face of the same half-widths.
VERTEX_CHECK_MAX_DIM = 6


def check_vertex_form(lower, upper, field: str, what: str, size: str) -> None:
    """Refuse a box too small for its vertices to have volume in floating point.

    Files store ``U`` and ``W`` by their vertices and the verifier rebuilds them with
    :meth:`Polytope.from_vertices`, so a box qhull cannot tell from a flat set (half-width ``1e-300``)
    is refused here, as a polytope given by its vertices would be (:func:`_polytope`). Above
    :data:`VERTEX_CHECK_MAX_DIM` dimensions the face through the smallest half-widths is checked.

    Parameters
    ----------
    lower, upper : array_like, shape (n,)
        The box ``[lower, upper]``.
    field, what, size : str
        The field refused (``half_width``), the set (``W``) and its size as the user gave it.
    """
    lo, hi = np.atleast_1d(np.asarray(lower, float)), np.atleast_1d(np.asarray(upper, float))
    n = lo.size
    keep = np.sort(np.argsort(hi - lo, kind="stable")[:VERTEX_CHECK_MAX_DIM])
    try:
        Polytope.from_vertices(Polytope.box(lo[keep], hi[keep]).vertices)
    except GeometryError:
        raise problem(field, f"{what} must have volume: {size} is too small for its box to have volume in floating "
                             f"point (qhull finds none in its {2 ** n} vertices in R^{n}; a polytope {what} with "
                             f"these vertices is refused the same way)") from None


class UBox(StrictModel):
    """``U = {u : |u_i| <= bound_i}``; a scalar bound applies to every input."""

    kind: Literal["box"]
    bound: Annotated[float | list[float], BeforeValidator(_box_bound)]

    def build(self, m: int) -> Polytope:
        return box_input_set(self.bound, m)


class UOneNorm(StrictModel):
    """``U = {u : ||u||_1 <= radius}``."""

    kind: Literal["one_norm"]
    radius: real(0.0, MAX_MAGNITUDE, lo_open=True)

    def build(self, m: int) -> Polytope:
        return one_norm_input_set(self.radius, m)


class _VertexSet(StrictModel):
    """The set ``NAME = co(vertices)``: with volume, holding 0 (in its interior with ``INTERIOR``)."""

    NAME: ClassVar[str]
    INTERIOR: ClassVar[bool]

    @model_validator(mode="after")
    def _volume_and_zero(self):
        P = _polytope(self.vertices, f"{self.NAME} must have volume")
        if not (np.all(P.h > 1e-12) if self.INTERIOR else np.all(P.h >= -1e-12)):
            raise problem("vertices", f"{self.NAME} must contain 0{' in its interior' if self.INTERIOR else ''}, "
                                      f"got vertices {short(self.vertices)}")
        return self

    def build(self, dim: int) -> Polytope:
        return Polytope.from_vertices(np.asarray(self.vertices, float))


class UPolytope(_VertexSet):
    """``U = co(vertices)``, vertices of shape ``(k, m)``, 0 in the interior."""

    NAME, INTERIOR = "U", True
    kind: Literal["polytope"]
    vertices: matrix("a list of input vectors [u_1, ..., u_m]")


register_tags("U", "box", "one_norm", "polytope")
register_tags("disturbance", "ball", "box", "polytope")

#: ``U``, chosen by ``kind``.
InputSet = Annotated[Union[UBox, UOneNorm, UPolytope], Field(discriminator="kind")]


class StateConstraint(StrictModel):
    """``X = {x : H x <= h}``: ``H`` a list of rows of ``n`` numbers, ``h`` one number per row.

    It need not be bounded (a speed limit leaves the positions free); the tube method keeps
    every tube vertex in it, the other methods refuse it.
    """

    H: matrix("a list of rows (one per inequality) of n numbers")
    h: vector("a list of numbers (one per row of H)")


class SystemModel(StrictModel):
    """``A`` (n x n), ``B`` (n x m), ``U`` in ``R^m`` and, optionally, the state constraint ``X``.

    ``name`` is free text. Without ``kind``, ``dt`` and ``beta`` (a sample time and a look-ahead,
    e.g. for the double integrator preset) are descriptive only: ``A`` and ``B`` are what is used.
    With ``kind`` (a name of :data:`~tubejax.model.system_kinds.SYSTEM_KINDS`), ``A`` and ``B`` are
    derived exactly from the kind's parameters (``double_integrator``: ``axes``, ``dt``, ``beta``)
    and rounded once to floats; given as well, they must equal the derivation.
    """

    name: str | None = None
    kind: str | None = None
    axes: integer(1, 1000) | None = None
    dt: real(0.0, MAX_MAGNITUDE, lo_open=True) | None = None
    beta: real(0.0, MAX_MAGNITUDE, lo_open=True) | None = None
    A: matrix("a square matrix (a list of n rows of n numbers)")
    B: matrix("a matrix (a list of n rows of m numbers)")
    U: InputSet
    X: StateConstraint | None = None

    @model_validator(mode="before")
    @classmethod
    def _derive_kind(cls, data):
        """``A`` and ``B`` of a named ``kind``, derived exactly from its parameters (checked against
        ``A`` and ``B`` when those are given too)."""
        if not isinstance(data, dict) or data.get("kind") is None:
            return data
        kind = data["kind"]
        if not isinstance(kind, str) or kind not in SYSTEM_KINDS:
            raise problem("kind", f"expected one of {', '.join(sorted(SYSTEM_KINDS))} (or no kind, with A and B "
                                  f"given), got {short(kind)}")
        spec = SYSTEM_KINDS[kind]
        missing = [p for p in spec.parameters if data.get(p) is None]
        if missing:
            raise problem(missing[0], f"system kind {kind!r} needs {missing[0]}: "
                                      f"{spec.parameters[missing[0]]}")
        try:
            A, B = spec.derive(**{p: data[p] for p in spec.parameters})
        except SystemKindError as exc:
            field, _, why = str(exc).partition(": ")
            raise problem(field.removeprefix("system."), why) from None
        derived = {"A": [[float(x) for x in row] for row in A.tolist()],
                   "B": [[float(x) for x in row] for row in B.tolist()]}
        for name, value in derived.items():
            given = data.get(name)
            if given is not None and not _same_matrix(given, value):
                raise problem(name, f"system kind {kind!r} derives {name} = {short(value)} from "
                                    + ", ".join(f"{p} = {data[p]!r}" for p in spec.parameters)
                                    + f"; got {short(given)} (leave {name} out to use the derivation)")
        return {**data, **derived}

    @property
    def n(self) -> int:
        return len(self.A)

    @property
    def m(self) -> int:
        return len(self.B[0])

    @model_validator(mode="after")
    def _shapes(self):
        n = len(self.A)
        if len(self.A[0]) != n:
            raise problem("A", f"expected a square matrix, got {n} rows of {len(self.A[0])} numbers")
        if len(self.B) != n:
            raise problem("B", f"expected {n} rows (one per state, like A), got {len(self.B)}")
        m = self.m
        X = self.X
        if X is not None and any(len(row) != n for row in X.H):
            raise problem("X.H", f"expected rows of {n} numbers (the state is in R^{n}), got {short(X.H)}")
        if X is not None and len(X.h) != len(X.H):
            raise problem("X.h", f"expected {len(X.H)} numbers (one per row of X.H), got {len(X.h)}")
        if X is not None and not all(any(v != 0 for v in row) for row in X.H):
            raise problem("X.H", f"expected no zero row (each row is a direction), got {short(X.H)}")
        U = self.U
        if isinstance(U, UBox) and isinstance(U.bound, list) and len(U.bound) not in (1, m):
            raise problem("U.bound", f"expected one number or {m} (one per input: B has {m} columns), "
                                     f"got {len(U.bound)}")
        if isinstance(U, UPolytope) and len(U.vertices[0]) != m:
            raise problem("U.vertices", f"expected points in R^{m} (B has {m} columns), "
                                        f"got points with {len(U.vertices[0])} coordinates")
        if isinstance(U, UBox):
            b = np.broadcast_to(np.asarray(U.bound, float), (m,))
            check_vertex_form(-b, b, "U.bound", "U", f"the bound {short(U.bound)}")
        if isinstance(U, UOneNorm):
            try:
                U.build(m)
            except GeometryError:
                raise problem("U.radius", f"U must have volume: the radius {_num(U.radius)} is too small for it to "
                                          f"have volume in floating point (qhull finds none in its {2 * m} vertices "
                                          f"in R^{m}; a polytope U with these vertices is refused the same way)"
                              ) from None
        return self

    def build(self, W: Ball | Polytope) -> LinearSystem:
        """The :class:`LinearSystem` with disturbance set ``W``."""
        X = None if self.X is None else Halfspaces(self.X.H, self.X.h, "system.X")
        return LinearSystem(A=np.asarray(self.A, float), B=np.asarray(self.B, float), U=self.U.build(self.m), W=W, X=X)


class BallDisturbance(StrictModel):
    """``W = {w : ||w||_2 <= radius}``."""

    kind: Literal["ball"]
    radius: real(0.0, MAX_MAGNITUDE)

    def build(self, n: int) -> Ball:
        return Ball(n, self.radius)


class BoxDisturbance(StrictModel):
    """``W = {w : |w_i| <= half_width}``."""

    kind: Literal["box"]
    half_width: real(0.0, MAX_MAGNITUDE, lo_open=True, why="for no disturbance use the ball with radius 0")

    def build(self, n: int) -> Polytope:
        return Polytope.box(-self.half_width * np.ones(n), self.half_width * np.ones(n))


class PolytopeDisturbance(_VertexSet):
    """``W = co(vertices)``, vertices of shape ``(k, n)``, containing 0, with volume."""

    NAME, INTERIOR = "W", False
    kind: Literal["polytope"]
    vertices: matrix("a list of disturbance vectors [w_1, ..., w_n]")


#: ``W``, chosen by ``kind``.
Disturbance = Annotated[Union[BallDisturbance, BoxDisturbance, PolytopeDisturbance], Field(discriminator="kind")]
