"""Which state constraints each method models, read from the row families its LP record declares.

A method models a state constraint of the system (:attr:`~tubejax.model.system.LinearSystem.state_constraints`)
when its LP declares a family over that constraint's region (the tube LP's ``VertexIn("X", ...)``).
The open-loop LP declares none and ``exact2d`` solves no LP, so both refuse a system with one
(their transitions would ignore it). Nothing here is written per constraint or per method.
"""

from __future__ import annotations

from ...errors import InputError
from .registry import FORMULATIONS, method_families

__all__ = ["unmodelled_state_constraints", "modelling_methods", "check_state_constraints"]


def unmodelled_state_constraints(method: str, names) -> list:
    """The state constraints among ``names`` that ``method``'s LP (its record's families) has no family for,
    in order."""
    regions = {getattr(f, "region", None) for f in method_families(method)}
    return [name for name in names if name not in regions]


def modelling_methods(names) -> list:
    """The methods whose LPs model every state constraint in ``names``, in the registry's order."""
    return [m for m in FORMULATIONS if not unmodelled_state_constraints(m, names)]


def check_state_constraints(method: str, system) -> None:
    """Refuse a method that does not model ``system``'s state constraints: ``InputError`` naming
    the constraint and the methods that model it."""
    names = list(system.state_constraints)
    missing = unmodelled_state_constraints(method, names)
    if missing:
        able = modelling_methods(names)
        raise InputError(f"system.{missing[0]}: method {method!r} does not model state constraints (its transitions "
                         f"would ignore {', '.join(missing)}); use method {' or '.join(map(repr, able))}, or leave "
                         f"the system without {', '.join(missing)}")
