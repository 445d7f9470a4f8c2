"""The project's error types for bad input: every error caused by what a user gives is an
:class:`InputError` (a ``ValueError``) naming the file or field, the value and what was expected.
Callers catch this one type; anything else that escapes is a bug.
"""

from __future__ import annotations

__all__ = ["InputError", "GeometryError", "DecompositionError", "InputModelError", "ZShapeError", "short"]


def short(value, limit: int = 80) -> str:
    """``repr(value)``, cut to ``limit`` characters, for a message."""
    s = repr(value)
    return s if len(s) <= limit else s[: limit - 3] + "..."


class InputError(ValueError):
    """Bad user input; the message names the file or field, the value and what was expected."""


class GeometryError(InputError):
    """A set (polytope, polygon) is degenerate or malformed: no volume, duplicate or non-finite points."""


class DecompositionError(InputError):
    """A cell decomposition is invalid: a cell without volume, overlapping cells, a cell meeting an obstacle."""


class ZShapeError(InputError):
    """A learned ``Z`` that breaks an invariant (vertex count, 0 interior, pairing)."""


class InputModelError(InputError):
    """A value of the typed input model (:mod:`tubejax.inputs`) is missing or malformed.

    Attributes
    ----------
    problems : list of (str, str)
        ``(field, message)`` for every problem found, the field as a dotted path
        (``system.A``, ``abstraction.L_max``); ``str(error)`` is the first one.
    """

    def __init__(self, problems: list[tuple[str, str]]):
        self.problems = list(problems)
        first = self.problems[0] if self.problems else ("input", "invalid")
        more = f" (and {len(self.problems) - 1} more)" if len(self.problems) > 1 else ""
        super().__init__(f"{first[0]}: {first[1]}{more}")
