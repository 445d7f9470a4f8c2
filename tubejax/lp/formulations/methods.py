"""Which row families each method's LP declares, and so which state constraints it models.

A method models a state constraint of the system (:attr:`~tubejax.model.system.LinearSystem.state_constraints`)
when its LP declares a family over that constraint's region: the tube LP's ``VertexIn("X", ...)``.
The open-loop LP declares none, and ``exact2d`` solves no LP, so both refuse a system with one
(their transitions would ignore it). Nothing here is written per constraint: a new one is modelled
by the methods that declare a family for it.
"""

from __future__ import annotations

from ...errors import InputError
from .openloop.families import OPENLOOP_FAMILIES
from .tube.families import TUBE_FAMILIES

__all__ = ["METHOD_FAMILIES", "unmodelled_state_constraints", "check_state_constraints"]

#: The row families of each method's LP (``exact2d``: none, it is an exact polygon computation).
METHOD_FAMILIES = {"tube": TUBE_FAMILIES, "openloop": OPENLOOP_FAMILIES, "exact2d": ()}


def unmodelled_state_constraints(method: str, names) -> list:
    """The state constraints among ``names`` that ``method``'s LP has no family for, in order."""
    regions = {getattr(f, "region", None) for f in METHOD_FAMILIES.get(method, ())}
    return [name for name in names if name not in regions]


def check_state_constraints(method: str, system) -> None:
    """Refuse a method that does not model ``system``'s state constraints.

    Raises
    ------
    InputError
        A state constraint the method's LP has no rows for (the message names it and the methods
        that model it).
    """
    names = list(system.state_constraints)
    missing = unmodelled_state_constraints(method, names)
    if missing:
        able = [m for m in METHOD_FAMILIES if not unmodelled_state_constraints(m, names)]
        raise InputError(f"system.{missing[0]}: method {method!r} does not model state constraints (its transitions "
                         f"would ignore {', '.join(missing)}); use method {' or '.join(map(repr, able))}, or leave "
                         f"the system without {', '.join(missing)}")
