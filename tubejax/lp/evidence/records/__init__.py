"""The LPs, one :class:`~tubejax.lp.declarations.formulation.Formulation` per module.

Each module here defines ``FORMULATION`` and, for the plots, ``STYLE`` (a :class:`SeriesStyle`);
:mod:`tubejax.lp.evidence.registry` imports every module of this package, so a new LP is one new
file (docs/howto/extending.md#a-new-lp).
"""

from typing import NamedTuple

__all__ = ["SeriesStyle"]


class SeriesStyle(NamedTuple):
    """How every plot draws a method's series: a record module's ``STYLE`` (grey, ``'-'``, ``'o'`` without one).

    A method with tubes (:func:`~tubejax.lp.evidence.registry.tube_methods`) is drawn per kind of ``Z``: its colour and marker stand for
    a series without a ``Z`` kind only.
    """

    colour: str = "#777777"
    line: str = "-"
    marker: str = "o"

