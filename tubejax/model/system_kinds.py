"""Systems chosen by name (``system.kind``): their ``A`` and ``B`` derived exactly from a few parameters.

:data:`SYSTEM_KINDS` is the one registry. A kind maps its parameters to ``A``, ``B`` in exact
rationals; the input model rounds each entry once, so they are the floats nearest the exact
derivation, not the result of float arithmetic.

``double_integrator``: ``axes`` decoupled double integrators, zero-order hold ``dt``, in look-ahead
coordinates ``s = p + beta v`` per axis, state ``(p_1, s_1, ..., p_axes, s_axes)``, input
``(a_1, ..., a_axes)``; the derivation, and why not ``(p, v)``: docs/math/drone.md#the-system-look-ahead-coordinates.
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction
from typing import Callable

import numpy as np

from ..errors import InputError

__all__ = ["SystemKind", "SYSTEM_KINDS", "SystemKindError", "exact_number", "double_integrator_lookahead",
           "lookahead_to_velocity"]


class SystemKindError(InputError):
    """Bad parameters of a named system; the message names the parameter and the value."""


def exact_number(value) -> Fraction:
    """A number as the user wrote it, exactly: a float by its shortest decimal (``0.1`` is ``1/10``)."""
    if isinstance(value, Fraction):
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise SystemKindError(f"expected a number, got {value!r}")
    if not np.isfinite(value):
        raise SystemKindError(f"expected a finite number, got {value!r}")
    return Fraction(repr(float(value))) if isinstance(value, (float, np.floating)) else Fraction(int(value))


def double_integrator_lookahead(axes: int, dt, beta) -> tuple[np.ndarray, np.ndarray]:
    """``A (2 axes, 2 axes)``, ``B (2 axes, axes)`` (Fraction) of ``axes >= 1`` double integrators in
    look-ahead coordinates, exactly (module doc); ``dt``, ``beta > 0`` (a float as its shortest decimal)."""
    if isinstance(axes, bool) or not isinstance(axes, (int, np.integer)) or axes < 1:
        raise SystemKindError(f"system.axes: expected a positive integer (the number of axes), got {axes!r}")
    exact = {}
    for name, value in (("dt", dt), ("beta", beta)):
        try:
            exact[name] = exact_number(value)
        except SystemKindError as exc:
            raise SystemKindError(f"system.{name}: {exc}") from None
        if exact[name] <= 0:
            raise SystemKindError(f"system.{name}: expected a number > 0, got {value!r}")
    h, b = exact["dt"], exact["beta"]
    A_axis = [[1 - h / b, h / b], [-h / b, 1 + h / b]]
    B_axis = [h * h / 2, h * h / 2 + b * h]
    A = np.full((2 * axes, 2 * axes), Fraction(0), dtype=object)
    B = np.full((2 * axes, axes), Fraction(0), dtype=object)
    for k in range(axes):
        A[2 * k:2 * k + 2, 2 * k:2 * k + 2] = A_axis
        B[2 * k:2 * k + 2, k] = B_axis
    return A, B


def lookahead_to_velocity(x: np.ndarray, beta: float) -> tuple[np.ndarray, np.ndarray]:
    """Positions ``p`` and velocities ``v = (s - p) / beta``, each ``(..., axes)``, of states
    ``x = (p_1, s_1, ..., p_axes, s_axes)`` of shape ``(..., 2 axes)``."""
    x = np.asarray(x, float)
    p, s = x[..., 0::2], x[..., 1::2]
    return p, (s - p) / float(beta)


@dataclass(frozen=True)
class SystemKind:
    """A named system: its parameters (required, with what each is) and its exact derivation."""

    parameters: dict
    derive: Callable[..., tuple[np.ndarray, np.ndarray]]
    doc: str


#: The systems chosen by ``system.kind``, by name.
SYSTEM_KINDS: dict[str, SystemKind] = {
    "double_integrator": SystemKind(
        parameters={"axes": "a positive integer (3 for a drone)", "dt": "the sample time, > 0",
                    "beta": "the look-ahead s = p + beta v, > 0"},
        derive=double_integrator_lookahead,
        doc="axes double integrators in look-ahead coordinates (p, s) per axis"),
}
