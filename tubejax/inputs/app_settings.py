"""Settings of the apps beyond the problem (:mod:`tubejax.inputs.settings`): the run budget, the radius and
conservatism studies, and the figures. Each field is refused outside its documented range, with the reason
(docs/reference/configuration.md#ranges); none of them changes an edge.
"""

from __future__ import annotations

from typing import Annotated

import numpy as np
from pydantic import BeforeValidator, model_validator

from ..lp.evidence.registry import method_names, radius_forms
from .values import Flag, StrictModel, _fail, choice, integer, label, problem, real, sized_list

__all__ = ["BudgetSettings", "ConservatismSettings", "CONSERVATISM_METHODS", "RadiusSettings", "figure_section",
           "FigureSettings", "RadiusFigureSettings"]


class BudgetSettings(StrictModel):
    """The largest run the apps start without asking (``budget.*``; ``None``: no limit on that count);
    :mod:`tubejax.abstraction.preflight` estimates a run and refuses one beyond it. Not part of
    the inputs record: it never changes a result."""

    max_cells: integer(1, 10 ** 9) | None = 250_000
    max_lps: integer(1, 10 ** 15) | None = 10_000_000
    max_lp_size: integer(1, 10 ** 12) | None = 25_000


#: The methods ``experiments/conservatism.py`` compares with the reach-avoid limit: every registered one.
CONSERVATISM_METHODS = method_names()


def _abstraction_dirs(value):
    if value is None:
        return value
    if not isinstance(value, dict) or any(k not in CONSERVATISM_METHODS or not isinstance(v, str) or not v
                                          for k, v in value.items()):
        raise _fail(f"null or a mapping from {', '.join(CONSERVATISM_METHODS)} to a directory holding "
                    "transitions.json|npz, e.g. {tube: out/run1}")
    return dict(value)


class ConservatismSettings(StrictModel):
    """``experiments/conservatism.py`` (:mod:`tubejax.analyses.conservatism`): the ``target`` label and
    the ``avoid`` labels, the ``methods`` compared with the limit (each abstraction run into
    ``<method>/``, or read from ``abstraction_dirs``), the ``sides`` of the polygon inscribed in a
    ball ``W``, the iteration cap ``max_iterations``, the convergence ``area_tol`` (a fraction of
    the safe area) and ``figures``."""

    target: label
    avoid: Annotated[list[label], sized_list(0, 1000, "a list of at most 1000 region labels, e.g. [4]")] = []
    methods: Annotated[list[choice(*CONSERVATISM_METHODS)],
                       sized_list(1, len(CONSERVATISM_METHODS), f"a list of 1 to {len(CONSERVATISM_METHODS)} distinct "
                                  f"methods of {', '.join(CONSERVATISM_METHODS)}, e.g. [tube, exact2d, openloop]",
                                  distinct=True)] = list(CONSERVATISM_METHODS)
    abstraction_dirs: Annotated[dict[str, str] | None, BeforeValidator(_abstraction_dirs)] = None
    sides: integer(3, 4096) = 32
    max_iterations: integer(1, 10 ** 6) = 10_000
    area_tol: real(1e-15, 1e-3) = 1e-9
    figures: Flag = True

    @model_validator(mode="after")
    def _target_not_avoided(self):
        if str(self.target) in {str(a) for a in self.avoid}:
            raise problem("avoid", f"the target {str(self.target)!r} is also avoided")
        return self


class RadiusSettings(StrictModel):
    """``experiments/radius.py`` (:mod:`tubejax.analyses.radius_analysis`): ``radii`` at which the verified
    transition system is written, ``radius_methods`` whose ``rho*`` and ``n_edges(rho)`` are
    computed, the batched engine's ``gap_tol``, and ``exact_curve`` (HiGHS makes every pair's
    critical disturbance exact)."""

    radii: Annotated[list[real(0.0, 1e6)], sized_list(0, 1000, "a list of at most 1000 radii, e.g. [0.05, 0.2]")] = []
    radius_methods: Annotated[list[choice(*radius_forms())],
                              sized_list(1, len(radius_forms()), f"a list of 1 to {len(radius_forms())} of "
                                         f"{', '.join(radius_forms())}, e.g. [tube, openloop]")] = list(radius_forms())
    gap_tol: real(1e-9, 1e-2, why="below 1e-9 is HiGHS's own accuracy") = 1e-4
    exact_curve: Flag = True

    @model_validator(mode="after")
    def _distinct(self):
        for name in ("radii", "radius_methods"):
            v = getattr(self, name)
            dup = next((x for k, x in enumerate(v) if x in v[:k]), None)
            if dup is not None:
                raise problem(name, f"expected distinct values, got {dup!r} twice")
        return self


_FIGURE_KEYS = {"simulate": "enabled, width, height, dpi, edge, runs_drawn, density, style, columns, view",
                "radius": "enabled, width, height, dpi"}


def figure_section(kind: str = "simulate"):
    """A ``BeforeValidator`` for a ``figures`` field: ``true``/``false`` stand for the section's defaults
    with ``enabled`` set (``figures=false`` on the command line), a mapping is the section itself."""
    keys = _FIGURE_KEYS[kind]

    def check(value):
        if isinstance(value, bool):
            return {"enabled": value}
        if isinstance(value, dict):
            return value
        raise _fail(f"true or false, or a section with keys {keys}")

    return BeforeValidator(check)


def _view_angles(value):
    ok = (isinstance(value, (list, tuple)) and len(value) == 2
          and all(isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v) and -360 <= v <= 360
                  for v in value))
    if not ok:
        raise _fail("two angles [elevation, azimuth] in degrees, each in [-360, 360], e.g. [25, -60]")
    return [float(v) for v in value]


def _columns(value):
    if value is not None and (isinstance(value, bool) or value not in (1, 2)):
        raise _fail("null (width and height as given), 1 or 2 (journal columns)")
    return value


def _cell_pair(value):
    ok = (isinstance(value, (list, tuple)) and len(value) == 2
          and all(isinstance(v, int) and not isinstance(v, bool) and 0 <= v <= 10 ** 9 for v in value))
    if not ok:
        raise _fail("null or two cell ids [i, j] (integers >= 0), e.g. [0, 2]")
    return list(value)


class _FigureCommon(StrictModel):
    """What every ``figures`` section holds: ``enabled`` and the PNG resolution (the PDFs are vector graphics)."""

    enabled: Flag = True
    dpi: integer(20, 2400) = 150

    def __bool__(self) -> bool:
        """``enabled``: ``if settings:`` reads as ``if settings.enabled:`` (a model is otherwise always true)."""
        return bool(self.enabled)


class RadiusFigureSettings(_FigureCommon):
    """The figure of ``experiments/radius.py`` (``fig_radius``): whether it is written, its size in
    inches (all three panels together) and the PNG resolution."""

    width: real(1.0, 100.0) = 16.0
    height: real(1.0, 100.0) = 4.2


class FigureSettings(_FigureCommon):
    """The figures of ``experiments/simulate.py`` and ``experiments/paper.py`` (Figs. 5-8 and the
    transition graph).

    Attributes
    ----------
    width, height : float
        Size of each figure in inches.
    edge : [int, int] or None
        The edge ``P_i -> P_j`` Fig. 6 draws, by cell ids; ``None``: region 1 -> region 2 as in
        the paper when that edge exists, else the plan's first edge.
    runs_drawn : int
        How many runs Figs. 7 and 8 draw as lines; with more runs, this many are chosen from the
        simulation's seed (runs violating the guarantee first).
    density : bool
        Shade where all runs went (a light 2-D histogram) when not every run is drawn.
    style : {'paper', 'draft'}
        ``paper``: one-line titles without run logs, journal font sizes
        (:func:`tubejax.analyses.plot.style.figure_style`); ``draft``: titles with the run's counts.
    columns : {1, 2} or None
        Size the figures for one or two journal columns (3.5 or 7.16 inches wide, the height in
        the proportion of ``height / width``); ``None``: ``width`` and ``height`` as given.
    view : [float, float]
        Elevation and azimuth in degrees of the 3-D figures (Fig. 6 of a 3-D workspace, ``fig9_tubes3d``).
    """

    width: real(1.0, 100.0) = 6.0
    height: real(1.0, 100.0) = 6.0
    edge: Annotated[list[int], BeforeValidator(_cell_pair)] | None = None
    runs_drawn: integer(0, 10 ** 5) = 50
    density: Flag = True
    style: choice("paper", "draft") = "paper"
    columns: Annotated[int | None, BeforeValidator(_columns)] = None
    view: Annotated[list[float], BeforeValidator(_view_angles)] = [25.0, -60.0]

    @property
    def size(self) -> tuple[float, float]:
        """``(width, height)`` in inches: ``columns`` journal columns wide when set, else as given."""
        if self.columns is None:
            return float(self.width), float(self.height)
        w = {1: 3.5, 2: 7.16}[self.columns]
        return w, w * float(self.height) / float(self.width)
