"""The registry of LPs: every :class:`~tubejax.lp.declarations.formulation.Formulation` in :mod:`.records`, by name.

Every module of :mod:`.records` contributes its ``FORMULATION``, so adding an LP is adding its file
(docs/howto/extending.md#a-new-lp). A step that depends on the method asks :func:`formulation` or
:func:`formulation_of` instead of testing types (tests/lp/test_formulation_registry.py checks).
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import MutableMapping

from ...errors import InputError
from ..declarations.formulation import Formulation
from .records import SeriesStyle

#: The package whose every module is one LP's record (imported on first use, like its modules).
RECORDS_PACKAGE = __name__.rsplit(".", 1)[0] + ".records"

__all__ = ["FORMULATIONS", "formulation", "formulation_of", "formulation_of_form", "method_names", "lp_names",
           "radius_forms", "tube_methods", "method_families", "exact_references", "product_methods", "series_name",
           "SeriesStyle", "series_style", "ignored_settings", "unmodelled_state_constraints", "modelling_methods",
           "check_state_constraints"]


class _Registry(MutableMapping):
    """The records by name, in rank order, read from :mod:`.records` on first use.

    Not at import: a record's module imports modules that import this one (the evidence checks
    import :mod:`tubejax.lp.evidence`, whose package imports the proofs, which read the registry),
    so the records are complete only once every import has finished.
    """

    def __init__(self):
        self._records: dict | None = None
        self._types: dict = {}
        self._styles: dict = {}

    def _loaded(self) -> dict:
        if self._records is None:
            records = importlib.import_module(RECORDS_PACKAGE)
            modules = [importlib.import_module(f"{RECORDS_PACKAGE}.{info.name}")
                       for info in sorted(pkgutil.iter_modules(records.__path__), key=lambda m: m.name)]
            found = [m.FORMULATION for m in modules]
            names = [f.name for f in found]
            if len(set(names)) != len(names):
                raise RuntimeError(f"two LP records share a name: {sorted(names)}")
            self._records = {f.name: f for f in sorted(found, key=lambda f: (f.rank, f.name))}
            self._types = {t: f.name for f in found for t in (f.evidence_type, f.exact_type, f.lp_type)
                           if t is not None}
            self._styles = {m.FORMULATION.name: getattr(m, "STYLE", SeriesStyle()) for m in modules}
        return self._records

    def style(self, name) -> SeriesStyle:
        """The :class:`SeriesStyle` of the record ``name`` (the default one for an unknown name)."""
        self._loaded()
        return self._styles.get(str(name), SeriesStyle())

    def name_of_type(self, t: type) -> str:
        """The name of the record whose evidence or LP type ``t`` is (``KeyError`` if none)."""
        self._loaded()
        return self._types[t]

    def __getitem__(self, name):
        return self._loaded()[name]

    def __setitem__(self, name, record):                 # tests declare a changed record
        self._loaded()[name] = record

    def __delitem__(self, name):
        del self._loaded()[name]

    def __iter__(self):
        return iter(self._loaded())

    def __len__(self):
        return len(self._loaded())


#: Every LP by its name, in rank order (read from :mod:`.records` on first use).
FORMULATIONS = _Registry()


def _forms(record: Formulation) -> tuple:
    """The batched forms ``record`` holds: its margin form (``pdhg``) and its radius form (``radius.pdhg``)."""
    radius = None if record.radius is None else record.radius.pdhg
    return tuple(form for form in (record.pdhg, radius) if form is not None)


def method_names() -> tuple:
    """The methods a config may choose (``abstraction.method``), in rank order."""
    return tuple(FORMULATIONS)


def lp_names() -> tuple:
    """The methods that solve an LP (all but ``exact2d``)."""
    return tuple(name for name, f in FORMULATIONS.items() if f.solves_lp)


def radius_forms() -> tuple:
    """The methods whose LP has a radius-parametric form (``Formulation.radius``, docs/math/radius.md)."""
    return tuple(name for name, f in FORMULATIONS.items() if f.radius is not None)


def tube_methods() -> tuple:
    """The methods whose evidence is a tube per step (``Formulation.tubes``): the ones Algorithm 1 controls,
    whose ``Z`` shapes the LP and whose tubes the temporal-logic labels read."""
    return tuple(name for name, f in FORMULATIONS.items() if f.tubes)


def exact_references() -> tuple:
    """The methods whose result is the most any feedback can achieve (``Formulation.exact_reference``):
    the reference of the conservatism of the others."""
    return tuple(name for name, f in FORMULATIONS.items() if f.exact_reference)


def product_methods() -> tuple:
    """The methods the product path solves (``Formulation.product_path``)."""
    return tuple(name for name, f in FORMULATIONS.items() if f.product_path)


def series_name(method, zshape=None) -> str:
    """How results and plots name a method's series: ``'tube (box)'`` for a method whose tubes depend on
    ``Z`` (:func:`tube_methods`), else the method's name (``'openloop'``, ``'exact2d'``)."""
    return f"{method} ({zshape})" if str(method) in tube_methods() else str(method)


def series_style(method) -> SeriesStyle:
    """The colour, line style and marker of ``method``'s series in every plot (its record's ``STYLE``)."""
    return FORMULATIONS.style(method)


def ignored_settings(method) -> tuple:
    """The settings ``method``'s result does not depend on; ``()`` for an unknown method.

    ``zshape`` and ``eps_min`` for a method without tubes (open-loop reachability fixes the inputs at
    time 0: no cross-section ``Z``), also ``solver`` for one that solves no LP (exact2d, a polygon
    computation). A sweep runs such a method once over them (``experiments/sweep_jobs.py``).
    """
    f = FORMULATIONS.get(str(method))
    if f is None:
        return ()
    return (() if f.tubes else ("zshape", "eps_min")) + (() if f.solves_lp else ("solver",))


def method_families(name: str) -> tuple:
    """The row families of the method ``name``'s LP; ``()`` for a method without an LP or an unknown name."""
    f = FORMULATIONS.get(name)
    return () if f is None else f.families


def unmodelled_state_constraints(method: str, names) -> list:
    """The state constraints among ``names`` that ``method``'s families have no family over (a family's
    ``region``), in order: a method models a constraint iff its LP declares rows over it."""
    regions = {getattr(f, "region", None) for f in method_families(method)}
    return [name for name in names if name not in regions]


def modelling_methods(names) -> list:
    """The methods whose LPs model every state constraint in ``names``, in rank order."""
    return [m for m in FORMULATIONS if not unmodelled_state_constraints(m, names)]


def check_state_constraints(method: str, system) -> None:
    """Refuse a method that does not model ``system``'s state constraints (its transitions would ignore
    them): ``InputError`` naming the constraint and the methods that model it."""
    names = list(system.state_constraints)
    missing = unmodelled_state_constraints(method, names)
    if missing:
        able = modelling_methods(names)
        raise InputError(f"system.{missing[0]}: method {method!r} does not model state constraints (its transitions "
                         f"would ignore {', '.join(missing)}); use method {' or '.join(map(repr, able))}, or leave "
                         f"the system without {', '.join(missing)}")


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


def formulation_of_form(form) -> Formulation:
    """The record that holds ``form`` (a :class:`~tubejax.lp.declarations.formulation.PdhgForm`) as its margin
    form (``pdhg``) or its radius form (``radius.pdhg``): this very object, not an equal one.

    Raises
    ------
    TypeError
        ``form`` is no registered record's (a copy made with ``_replace``, a form of an unregistered LP), or
        several records hold it (which LP's verdicts it gives would be a guess).
    """
    holders = [f for f in FORMULATIONS.values() if any(held is form for held in _forms(f))]
    if len(holders) > 1:
        raise TypeError(f"{type(form).__name__}: held by the records {', '.join(f.name for f in holders)}; "
                        "expected each LP to hold its own batched forms")
    if not holders:
        raise TypeError(f"{type(form).__name__}: held by no registered formulation ({', '.join(FORMULATIONS)}); "
                        "expected a record's own pdhg or radius.pdhg, the object itself")
    return holders[0]


def formulation_of(thing) -> Formulation:
    """The record whose evidence (float or rational) or dense LP ``thing`` is.

    Raises
    ------
    TypeError
        ``thing`` is none of the registered types.
    """
    try:
        return FORMULATIONS[FORMULATIONS.name_of_type(type(thing))]
    except KeyError:
        raise TypeError(f"{type(thing).__name__} is the evidence or LP of no registered formulation "
                        f"({', '.join(FORMULATIONS)})") from None

