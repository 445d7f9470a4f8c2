"""An LP's adapters to the batched PDHG engine, reached through its record.

A :class:`~tubejax.lp.declarations.formulation.Formulation` lives below this layer (in
:mod:`tubejax.lp.evidence.records`), so it names its adapters -- ``pdhg`` for sign decisions,
``radius.pdhg`` for the radius form's optimise mode -- as ``'module:NAME'`` of this package, and
this module imports them on first use. Nothing here is written per method: a new LP with a
batched form names its adapter in its record.
"""

from __future__ import annotations

import importlib

from ..declarations.formulation import Formulation
from ..declarations.pdhg_formulation import PdhgFormulation

__all__ = ["pdhg_adapter", "radius_adapter"]


def _resolve(ref: str) -> PdhgFormulation:
    module, name = ref.split(":")
    return getattr(importlib.import_module(f"{__package__}.{module}"), name)


def pdhg_adapter(record: Formulation) -> PdhgFormulation | None:
    """The batched PDHG form of ``record``'s LP (``record.pdhg``), or ``None`` when it has none."""
    return None if record.pdhg is None else _resolve(record.pdhg)


def radius_adapter(record: Formulation) -> PdhgFormulation | None:
    """The batched PDHG form of ``record``'s radius LP (``record.radius.pdhg``), or ``None``."""
    radius = record.radius
    return None if radius is None or radius.pdhg is None else _resolve(radius.pdhg)
