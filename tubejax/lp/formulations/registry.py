"""The registry of LPs: every :class:`~.formulation.Formulation` in :mod:`.records`, by name.

Every module of :mod:`.records` is imported here and contributes its ``FORMULATION``, so adding an
LP is adding its file (docs/howto/extending.md#a-new-lp). Nothing else in the library dispatches on
a method's name or on the type of an LP or its evidence: it asks :func:`formulation` or
:func:`formulation_of` (tests/lp/test_formulation_registry.py checks that).
"""

from __future__ import annotations

import importlib
import pkgutil

from ...errors import InputError
from . import records
from .formulation import Formulation

__all__ = ["FORMULATIONS", "formulation", "formulation_of", "method_names", "lp_names", "method_families"]


#: Every LP by its name, in rank order (filled below, once the functions exist: the records import
#: modules that import this one).
FORMULATIONS: dict = {}
#: The name of the record of each evidence type and LP type (float and rational), for :func:`formulation_of`.
_BY_TYPE: dict = {}


def method_names() -> tuple:
    """The methods a config may choose (``abstraction.method``), in rank order."""
    return tuple(FORMULATIONS)


def lp_names() -> tuple:
    """The methods that solve an LP (all but ``exact2d``)."""
    return tuple(name for name, f in FORMULATIONS.items() if f.solves_lp)


def method_families(name: str) -> tuple:
    """The row families of the method ``name``'s LP; ``()`` for a method without an LP or an unknown name."""
    f = FORMULATIONS.get(name)
    return () if f is None else f.families


def formulation(name: str) -> Formulation:
    """The record of the LP (method) ``name``.

    Raises
    ------
    InputError
        An unknown name (the message lists the known ones).
    """
    try:
        return FORMULATIONS[name]
    except (KeyError, TypeError):
        raise InputError(f"method: expected one of {', '.join(FORMULATIONS)}, got {name!r}") from None


def formulation_of(thing) -> Formulation:
    """The record whose evidence (float or rational) or dense LP ``thing`` is.

    Raises
    ------
    TypeError
        ``thing`` is none of the registered types.
    """
    try:
        return FORMULATIONS[_BY_TYPE[type(thing)]]
    except KeyError:
        raise TypeError(f"{type(thing).__name__} is the evidence or LP of no registered formulation "
                        f"({', '.join(FORMULATIONS)})") from None


def _discover() -> None:
    """Import every module of :mod:`.records` and register its ``FORMULATION``."""
    found = [importlib.import_module(f"{records.__name__}.{info.name}").FORMULATION
             for info in sorted(pkgutil.iter_modules(records.__path__), key=lambda m: m.name)]
    names = [f.name for f in found]
    if len(set(names)) != len(names):
        raise RuntimeError(f"two LP records share a name: {sorted(names)}")
    FORMULATIONS.update((f.name, f) for f in sorted(found, key=lambda f: (f.rank, f.name)))
    _BY_TYPE.update((t, f.name) for f in FORMULATIONS.values() for t in (f.evidence_type, f.exact_type, f.lp_type)
                    if t is not None)


_discover()
