"""Settings of the input model: the cross-section ``Z``, the abstraction, the solver, the simulation
and the specification. Each field is refused outside its documented range, with the reason
(the ranges: docs/reference/configuration.md#ranges).
"""

from __future__ import annotations

from typing import Annotated, Literal, Union

import numpy as np

from pydantic import BeforeValidator, Field, model_serializer, model_validator

from ..lp.evidence.registry import method_names
from ..model.zshape.kinds import LEARNED_ZSHAPES, ZSHAPES
from .sources import FileRef
from .values import Flag, StrictModel, _fail, choice, integer, integer_or, label, problem, real, register_tags

__all__ = ["ZSHAPE_SCALE_RANGE", "LEARNED_KINDS", "ZShapeSettings", "HighsSolverSettings", "PdhgSolverSettings",
           "SolverSettings", "ShardSettings", "AbstractionSettings", "SimulationSettings", "SpecSettings",
           "RadiusSettings", "FigureSettings", "RadiusFigureSettings", "figure_section", "ConservatismSettings",
           "CONSERVATISM_METHODS", "RETIRED_SOLVER_KEYS", "without_retired_keys"]

ZSHAPE_SCALE_RANGE = (1e-3, 1e3)
_SEED = integer(0, 2 ** 32 - 1)


#: Kinds whose ``Z`` is learned (:mod:`tubejax.analyses.zshape`); the others are fixed shapes.
LEARNED_KINDS = LEARNED_ZSHAPES
#: Defaults of the learned kinds' own fields (``None`` for the fixed kinds).
#: ``init='best'`` and the step size are those of ``scripts/learned_z_table.py`` (docs/howto/learned-z.md#the-comparison-sweep).
LEARNED_DEFAULTS = {"init": "best", "steps": 30, "learning_rate": 0.05, "horizon": "last", "patience": 5,
                    "seed": 0}


class ZShapeSettings(StrictModel):
    """The tube cross-section ``Z`` (:func:`tubejax.model.zshape.kinds.make_z`).

    ``learned``: one learned ``Z`` per cell shape; ``learned_pair``: one per ordered pair,
    learned from the shared one (:mod:`tubejax.analyses.zshape`). Their own fields (refused with a fixed
    kind): ``file``, a ``learned_z.json`` to use (``None``: learn one now, with ``steps``,
    ``learning_rate``, ``horizon``, ``patience`` and ``seed`` from the start ``init``; ``init='best'`` starts
    each cell shape from the fixed kind that fits its cells and certifies most of its pairs,
    :func:`tubejax.model.zshape.kinds.start_kinds`); ``init`` is also the ``Z`` of a cell whose shape
    the table lacks (``best``: box where it fits, else cell), and for ``learned_pair`` a pair
    without its own ``Z`` takes the shape's learned ``Z``. The record lists only the fields that are set, so a fixed kind's
    record stays ``{"kind", "scale"}``.
    """

    kind: choice(*ZSHAPES, *LEARNED_KINDS) = "box"
    scale: real(*ZSHAPE_SCALE_RANGE, why="with eps_min = 0 only the shape of Z decides feasibility, eps scales it; far from "
                "the cell size the LP is badly scaled") = 1.0
    file: FileRef | None = None
    init: choice("best", *ZSHAPES) | None = None
    steps: integer(0, 10 ** 4) | None = None
    learning_rate: real(1e-6, 10.0, why="vertices have RMS radius sqrt(n): larger steps are all rejected") | None = None
    horizon: choice("last", "best") | None = None
    patience: integer(1, 10 ** 4) | None = None
    seed: _SEED | None = None

    @model_validator(mode="after")
    def _learned_fields(self):
        if self.kind not in LEARNED_KINDS:
            for name in ("file", *LEARNED_DEFAULTS):
                if getattr(self, name) is not None:
                    raise problem(name, f"applies to zshape=learned and zshape=learned_pair only (zshape.kind is "
                                        f"{self.kind!r})")
            return self
        missing = {k: v for k, v in LEARNED_DEFAULTS.items() if getattr(self, k) is None}
        return self.model_copy(update=missing) if missing else self

    @model_serializer(mode="wrap")
    def _set_fields_only(self, handler):
        return {k: v for k, v in handler(self).items() if v is not None}

    @property
    def learned(self) -> bool:
        """Whether ``Z`` is learned (``kind`` in :data:`LEARNED_KINDS`)."""
        return self.kind in LEARNED_KINDS


class HighsSolverSettings(StrictModel):
    """One exact HiGHS solve per LP (the reference)."""

    name: Literal["highs"]

    def options(self) -> dict:
        return {}


#: Solver keys that no longer exist, each with what replaced it. An inputs record written before
#: carries them and still loads (:func:`without_retired_keys`); a config that sets one is refused.
RETIRED_SOLVER_KEYS = {"reuse_duals": "the last refuting dual of pairs at the same offset is always tried on the "
                                      "next ones (the verdicts never depended on it)"}


def without_retired_keys(record: dict) -> dict:
    """``record`` (an inputs record) without the retired solver keys (:data:`RETIRED_SOLVER_KEYS`) of an
    older release, so that it loads; anything else is left for validation to judge."""
    a = record.get("abstraction")
    s = a.get("solver") if isinstance(a, dict) else None
    if not isinstance(s, dict) or not RETIRED_SOLVER_KEYS.keys() & s.keys():
        return record
    solver = {k: v for k, v in s.items() if k not in RETIRED_SOLVER_KEYS}
    return {**record, "abstraction": {**a, "solver": solver}}


class PdhgSolverSettings(StrictModel):
    """The batched PDHG solver (:class:`tubejax.lp.batch.batch_solver.PdhgBatchSolver`); see conf/solver/pdhg.yaml."""

    name: Literal["pdhg"]
    pool: integer(1, 1 << 16) = 128
    min_bucket: integer(1, 1 << 16) = 16
    tail_width: integer(1, 1 << 16) | None = None
    check_every: integer(1, 10_000) = 16
    max_iters: integer(1, 1_000_000) = 1024
    cap_tol: real(0.0, 1.0) = 0.01
    ruiz_iters: integer_or(0, 100, "auto") = "auto"
    dtype: choice("float32", "float64") = "float32"
    highs_process: Flag = True
    highs_workers: integer(1, 256) = 1
    share: Flag = True
    compilation_cache: str | None = None

    @model_validator(mode="before")
    @classmethod
    def _retired(cls, data):
        for key in RETIRED_SOLVER_KEYS.keys() & (data.keys() if isinstance(data, dict) else set()):
            raise problem(key, f"this key was removed: {RETIRED_SOLVER_KEYS[key]}; delete it from the config")
        return data

    @model_validator(mode="after")
    def _powers_of_two(self):
        for field in ("pool", "min_bucket"):
            v = getattr(self, field)
            if v & (v - 1):
                raise problem(field, f"expected a power of two, got {v}")
        if self.min_bucket > self.pool:
            raise problem("min_bucket", f"expected at most pool = {self.pool}, got {self.min_bucket}")
        return self

    def options(self) -> dict:
        """Keyword arguments of the solver class (everything but ``name`` and ``compilation_cache``)."""
        return self.model_dump(exclude={"name", "compilation_cache"})


register_tags("solver", "highs", "pdhg")

#: The solver, chosen by ``name``.
SolverSettings = Annotated[Union[HighsSolverSettings, PdhgSolverSettings], Field(discriminator="name")]


class ShardSettings(StrictModel):
    """Which share of the source cells a job solves (:mod:`tubejax.abstraction.shards`); ``count = 1``: all of them."""

    count: integer(1, 10 ** 5) = 1
    index: integer(0, 10 ** 5 - 1) = 0

    @model_validator(mode="after")
    def _index_below_count(self):
        if self.index >= self.count:
            raise problem("index", f"expected an integer in [0, {self.count - 1}] (shard.count = {self.count}), "
                                   f"got {self.index}")
        return self


class AbstractionSettings(StrictModel):
    """Algorithm 2's settings (:func:`tubejax.abstraction.build_abstraction`).

    ``memory_budget_mb`` (``None``: unbounded) and ``shard`` change how a run is executed,
    never the edges it finds.
    """

    L_max: integer(1, 1000) = 10
    eps_min: real(0.0, 1e3) = 0.0
    min_margin: real(0.0, 0.5) = 0.0
    pruning: Flag = True
    method: choice(*method_names()) = "tube"
    seed: _SEED = 0
    verify: choice("none", "all") = "none"
    solver: SolverSettings = HighsSolverSettings(name="highs")
    memory_budget_mb: integer(1, 10 ** 7) | None = 2048
    shard: ShardSettings = ShardSettings()


class BudgetSettings(StrictModel):
    """The largest run the apps start without asking (``budget.*``; ``None``: no limit on that count);
    :mod:`tubejax.abstraction.preflight` estimates a run and refuses one beyond it. Not part of
    the inputs record: it never changes a result."""

    max_cells: integer(1, 10 ** 9) | None = 250_000
    max_lps: integer(1, 10 ** 15) | None = 10_000_000
    max_lp_size: integer(1, 10 ** 12) | None = 25_000


class SimulationSettings(StrictModel):
    """Closed-loop runs (:func:`tubejax.analyses.control.simulate`); ``cycles``: patrol cycles simulated."""

    runs: integer(1, 10 ** 7) = 50
    mode: choice("uniform", "boundary", "adversarial", "none") = "uniform"
    seed: _SEED = 0
    cycles: integer(1, 10 ** 4) = 1


def _label_list(value):
    if not isinstance(value, (list, tuple)) or not 1 <= len(value) <= 1000:
        raise _fail("a list of 1 to 1000 region labels, e.g. [1, 3]")
    return list(value)


def _short_label_list(value):
    if not isinstance(value, (list, tuple)) or len(value) > 1000:
        raise _fail("a list of at most 1000 region labels, e.g. [4]")
    return list(value)


#: Longest ``spec.formula`` accepted (characters): far beyond any formula whose automaton can be built.
MAX_FORMULA_LENGTH = 10_000


def _formula(value):
    if isinstance(value, str) and len(value) > MAX_FORMULA_LENGTH:
        raise _fail(f"an LTLf formula of at most {MAX_FORMULA_LENGTH:,} characters (the limit on its length; "
                    f"this one has {len(value):,})")
    if not isinstance(value, str) or not value.strip():
        raise _fail("an LTLf formula as a string (quote it on the command line: "
                    "'spec.formula=\"F(l3) & G(!l4)\"')")
    return value


def _ltl(value):
    if not isinstance(value, str) or not value.strip() or len(value) > 10_000:
        raise _fail("an LTL formula over infinite runs as a string (quote it on the command line: "
                    "'spec.ltl=\"GF l3 & GF l6 & G !l4\"')")
    return value


class SpecSettings(StrictModel):
    """The specification: a sequence of region labels (start in the first, then visit the
    others in order), or an LTLf ``formula`` over the labels (finite runs), or an ``ltl``
    formula (infinite runs: a lasso, its cycle simulated ``sim.cycles`` times), or a ``patrol``
    cycle (avoiding ``avoid``); formula, ltl and patrol plans start in the first cell of the region
    ``start``, or in ``start_cell``, or else in the first cell of ``sequence[0]`` (a one-label
    sequence is just that start)."""

    sequence: Annotated[list[label], BeforeValidator(_label_list)]
    start: label | None = None
    start_cell: integer(0, 10 ** 9) | None = None
    planner: choice("exact", "greedy", "product") = "exact"
    formula: Annotated[str, BeforeValidator(_formula)] | None = None
    ltl: Annotated[str, BeforeValidator(_ltl)] | None = None
    patrol: Annotated[list[label], BeforeValidator(_short_label_list)] | None = None
    avoid: Annotated[list[label], BeforeValidator(_short_label_list)] = []

    @model_validator(mode="after")
    def _one_kind(self):
        given = [k for k in ("formula", "ltl", "patrol") if getattr(self, k) is not None]
        if len(given) > 1:
            raise problem(given[1], f"give one of spec.formula, spec.ltl and spec.patrol, not both "
                                    f"{' and '.join('spec.' + k for k in given)}")
        if self.patrol is not None and not self.patrol:
            raise problem("patrol", "expected at least one region label, e.g. [3, 5, 6]")
        if self.avoid and self.patrol is None:
            raise problem("avoid", "applies to spec.patrol only; in a formula write G(!l<label>), "
                                   "in spec.ltl G !l<label>")
        if self.start is not None and self.start_cell is not None:
            raise problem("start", "give spec.start (a region label) or spec.start_cell (a cell id), not both")
        plain = self.formula is None and self.ltl is None and self.patrol is None
        if plain and len(self.sequence) < 2:
            raise problem("sequence", f"[{self.sequence[0]}] names a start and no region to visit: give the regions "
                                      "to visit after it (e.g. [1, 3]), or a spec.formula, spec.ltl or spec.patrol")
        if plain and self.start is not None and str(self.start) != str(self.sequence[0]):
            raise problem("start", f"a sequence starts in its first region ({self.sequence[0]!r}), got "
                                   f"{self.start!r}: leave spec.start out, or make it the sequence's first label")
        return self

    @property
    def start_label(self) -> str:
        """The region a plan starts in when no ``start_cell`` is given: ``start``, else ``sequence[0]``."""
        return str(self.start if self.start is not None else self.sequence[0])

    @property
    def labels(self) -> list[str]:
        """The sequence as strings (labels compare as strings)."""
        return [str(x) for x in self.sequence]


def _radius_list(value):
    if not isinstance(value, (list, tuple)) or len(value) > 1000:
        raise _fail("a list of at most 1000 radii, e.g. [0.05, 0.2]")
    return list(value)


def _method_list(value):
    if not isinstance(value, (list, tuple)) or not 1 <= len(value) <= 2:
        raise _fail("a list of 1 or 2 of tube, openloop, e.g. [tube, openloop]")
    return list(value)


#: The methods ``experiments/conservatism.py`` compares with the reach-avoid limit.
CONSERVATISM_METHODS = ("tube", "exact2d", "openloop")


def _conservatism_methods(value):
    if not isinstance(value, (list, tuple)) or not 1 <= len(value) <= 3 or len(set(map(str, value))) != len(value):
        raise _fail("a list of 1 to 3 distinct methods of tube, exact2d, openloop, e.g. [tube, exact2d, openloop]")
    return list(value)


def _abstraction_dirs(value):
    if value is None:
        return value
    if not isinstance(value, dict) or any(k not in CONSERVATISM_METHODS or not isinstance(v, str) or not v
                                          for k, v in value.items()):
        raise _fail("null or a mapping from tube, exact2d, openloop to a directory holding transitions.json|npz, "
                    "e.g. {tube: out/run1}")
    return dict(value)


class ConservatismSettings(StrictModel):
    """``experiments/conservatism.py`` (:mod:`tubejax.analyses.conservatism`): the ``target`` label and
    the ``avoid`` labels, the ``methods`` compared with the limit (each abstraction run into
    ``<method>/``, or read from ``abstraction_dirs``), the ``sides`` of the polygon inscribed in a
    ball ``W``, the iteration cap ``max_iterations``, the convergence ``area_tol`` (a fraction of
    the safe area) and ``figures``."""

    target: label
    avoid: Annotated[list[label], BeforeValidator(_short_label_list)] = []
    methods: Annotated[list[choice(*CONSERVATISM_METHODS)], BeforeValidator(_conservatism_methods)] = \
        list(CONSERVATISM_METHODS)
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

    radii: Annotated[list[real(0.0, 1e6)], BeforeValidator(_radius_list)] = []
    radius_methods: Annotated[list[choice("tube", "openloop")], BeforeValidator(_method_list)] = ["tube", "openloop"]
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
    """What every ``figures`` section holds: ``enabled`` and the PNG resolution."""

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
    enabled : bool
        Write them at all.
    width, height : float
        Size of each figure in inches.
    dpi : int
        Resolution of the PNG files (the PDFs are vector graphics).
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
