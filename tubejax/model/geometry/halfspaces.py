"""A polyhedron ``{x : H x <= h}``, bounded or not (a state constraint such as a speed limit need
not be bounded, so it cannot be a vertex-built ``Polytope``). Rows are kept as given, not normalised:
the exact arithmetic reads the decimals the configuration and the file hold (docs/math/problem-data.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ...errors import InputError

__all__ = ["Halfspaces", "HalfspacesError"]


class HalfspacesError(InputError):
    """Invalid inequality data; the message names the field."""


@dataclass(frozen=True, eq=False)
class Halfspaces:
    """``{x : H x <= h}`` in ``R^n``.

    Attributes
    ----------
    H : ndarray, shape (f, n)      rows as given (finite, none zero)
    h : ndarray, shape (f,)        offsets as given (finite)
    name : str                     the field the set comes from, for messages (e.g. ``'system.X'``)
    """

    H: np.ndarray
    h: np.ndarray
    name: str = "halfspaces"

    def __post_init__(self):
        try:
            H = np.array(self.H, dtype=float, ndmin=2)
            h = np.array(self.h, dtype=float, ndmin=1)
        except (TypeError, ValueError, OverflowError):
            raise HalfspacesError(f"{self.name}: expected H (a list of rows of numbers) and h (a list of numbers), "
                                  f"got H = {self.H!r}, h = {self.h!r}") from None
        if H.ndim != 2 or H.shape[0] == 0 or H.shape[1] == 0:
            raise HalfspacesError(f"{self.name}.H: expected a non-empty list of rows, got shape {H.shape}")
        if h.shape != (H.shape[0],):
            raise HalfspacesError(f"{self.name}.h: expected {H.shape[0]} numbers (one per row of H), "
                                  f"got shape {h.shape}")
        if not (np.all(np.isfinite(H)) and np.all(np.isfinite(h))):
            raise HalfspacesError(f"{self.name}: H and h must be finite (they hold NaN or infinity)")
        zero = np.flatnonzero(~np.any(H != 0, axis=1))
        if zero.size:
            raise HalfspacesError(f"{self.name}.H: row {int(zero[0])} is zero (every row must be a direction)")
        H.setflags(write=False)
        h.setflags(write=False)
        object.__setattr__(self, "H", H)
        object.__setattr__(self, "h", h)

    dim = property(lambda self: int(self.H.shape[1]), doc="Ambient dimension ``n``.")

    @cached_property
    def row_norms(self) -> np.ndarray:
        """The 2-norms of the rows of ``H``, shape ``(f,)``."""
        nrm = np.linalg.norm(self.H, axis=1)
        nrm.setflags(write=False)
        return nrm

    def violation(self, x) -> np.ndarray:
        """The largest ``(H x - h) / ||H_i||`` (the distance outside, along the worst row; ``<= 0``
        inside), shape ``(...)`` for ``x`` of shape ``(..., n)``, in float64."""
        x = np.asarray(x, dtype=float)
        return np.max((x @ self.H.T - self.h) / self.row_norms, axis=-1)

    def contains(self, x, tol: float = 0.0) -> np.ndarray:
        """Whether points ``(..., n)`` satisfy every row up to ``tol`` (a distance), shape ``(...)``."""
        return self.violation(x) <= tol

    def record(self) -> dict:
        """``{"H": rows, "h": offsets}`` (lists of floats), as files store it."""
        return {"H": self.H.tolist(), "h": self.h.tolist()}

    @classmethod
    def from_record(cls, rec, name: str) -> "Halfspaces":
        """The set of a :meth:`record` (or a configuration's ``{H, h}``); a ``HalfspacesError`` naming
        ``name`` for anything but a mapping with exactly the keys ``H`` and ``h`` of valid rows."""
        if not isinstance(rec, dict) or set(rec) != {"H", "h"}:
            got = sorted(rec) if isinstance(rec, dict) else type(rec).__name__
            raise HalfspacesError(f"{name}: expected a mapping with the keys H and h, got {got}")
        return cls(rec["H"], rec["h"], name)

    def same_as(self, other) -> bool:
        """Equal bit for bit as recorded (rows and offsets in the same order)."""
        return (isinstance(other, Halfspaces) and self.H.shape == other.H.shape
                and np.array_equal(self.H, other.H) and np.array_equal(self.h, other.h))
