"""Settings of the input model: the cross-section ``Z``, the abstraction, the solver, the simulation
and the specification.

Documented ranges (each refused outside, with the reason):

=====================  =================================  ==========================================
field                  range                              why
=====================  =================================  ==========================================
``zshape.scale``       ``[1e-3, 1e3]``                    only ``Z``'s shape decides feasibility
                                                          (``eps`` scales it); far from the cell size
                                                          the LP is badly scaled and its 1e-9
                                                          tolerances decide instead of the geometry
``zshape.steps``       integer ``[0, 10**4]``             learned kinds only: Adam steps
``zshape.init``        ``best``, ``box``, ``cell``,       learned kinds only: the start (``best``: the
                       ``diamond``, ``regular``,          fitting fixed kind certifying most pairs)
                       ``chamfer``
``zshape.horizon``     ``last`` or ``best``               learned kinds only: the horizon each pair
                                                          is learned at
``zshape.patience``    integer ``[1, 10**4]``             learned kinds only: stop after this many
                                                          steps without a better iterate
``zshape.learning_rate`` ``[1e-6, 10]``                   learned kinds only (vertices of RMS radius
                                                          ``sqrt(n)``: above 10 every step is rejected)
``zshape.seed``        integer ``[0, 2**32 - 1]``         learned kinds only
``L_max``              integer ``[1, 1000]``
``eps_min``            ``[0, 1e3]``                       C1, in units of ``Z``
``min_margin``         ``[0, 0.5]``                       the robustness margin ``t*`` an edge
                                                          must have (docs/math/margins.md, unit rows;
                                                          ``t <= 1`` in the margin form)
``seed``               integer ``[0, 2**32 - 1]``
``memory_budget_mb``   integer ``[1, 10**7]`` or null        the rounds' working set; never changes
                                                          the result (:mod:`tubejax.abstraction.schedule`)
``shard.count``        integer ``[1, 10**5]``
``shard.index``        integer ``[0, shard.count - 1]``
``sim.runs``           integer ``[1, 10**7]``
``spec.sequence``      2 to 1000 region labels
``spec.formula``       at most 10,000 characters          the length limit is named when exceeded
``budget.max_cells``   integer ``[1, 10**9]`` or null     the apps' budget (:class:`BudgetSettings`):
``budget.max_lps``     integer ``[1, 10**15]`` or null    a run beyond it is refused before it starts
``budget.max_lp_size`` integer ``[1, 10**12]`` or null    (:mod:`tubejax.abstraction.preflight`)
``radii``              at most 1000 distinct numbers in   radii of ``experiments/radius.py``, in the
                       ``[0, 1e6]``                       units of ``W`` (as ``disturbance.radius``)
``gap_tol``            ``[1e-9, 1e-2]``                   the batched engine's duality gap (radius
                                                          units); below 1e-9 is HiGHS's own accuracy
``figures``            ``true``, ``false`` or a section   ``true``/``false``: the section's defaults
                                                          with ``enabled`` set
``figures.width``      ``[1, 100]`` (inches)              also ``figures.height``
``figures.dpi``        integer ``[20, 2400]``             of the PNG files (PDFs are vector graphics)
``figures.edge``       null or ``[i, j]``, two cell ids   the edge of Fig. 6 (null: region 1 -> 2 as
                                                          in the paper, else the plan's first edge)
``figures.runs_drawn`` integer ``[0, 10**5]``             runs drawn as lines (chosen from the seed);
                                                          the others as a density (``figures.density``)
=====================  =================================  ==========================================
"""

from __future__ import annotations

from typing import Annotated, Literal, Union

from pydantic import BeforeValidator, Field, model_serializer, model_validator

from ..model.zshape.kinds import LEARNED_ZSHAPES, ZSHAPES
from .sources import FileRef
from .values import Flag, StrictModel, _fail, choice, integer, integer_or, label, problem, real, register_tags

__all__ = ["ZSHAPE_SCALE_RANGE", "LEARNED_KINDS", "ZShapeSettings", "HighsSolverSettings", "PdhgSolverSettings",
           "SolverSettings", "ShardSettings", "AbstractionSettings", "SimulationSettings", "SpecSettings",
           "RadiusSettings", "FigureSettings", "RadiusFigureSettings", "figure_section"]

ZSHAPE_SCALE_RANGE = (1e-3, 1e3)
_SEED = integer(0, 2 ** 32 - 1)


#: Kinds whose ``Z`` is learned (:mod:`tubejax.analyses.zshape`); the others are fixed shapes.
LEARNED_KINDS = LEARNED_ZSHAPES
#: Defaults of the learned kinds' own fields (``None`` for the fixed kinds).
#: ``init='best'`` and the step size are those of ``scripts/learned_z_table.py`` (README, learned Z).
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
    scale: real(*ZSHAPE_SCALE_RANGE, why="only the shape of Z decides feasibility, eps scales it; far from "
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


class PdhgSolverSettings(StrictModel):
    """The batched PDHG solver (:class:`tubejax.lp.solvers.batched.PdhgBatchSolver`); see conf/solver/pdhg.yaml."""

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
    reuse_duals: Flag = True
    highs_workers: integer(1, 256) = 1
    share: Flag = True
    compilation_cache: str | None = None

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
    method: choice("tube", "openloop", "exact2d") = "tube"
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
    if not isinstance(value, (list, tuple)) or not 2 <= len(value) <= 1000:
        raise _fail("a list of 2 to 1000 region labels, e.g. [1, 3]")
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


class SpecSettings(StrictModel):
    """The specification: a sequence of region labels (start in the first, then visit the
    others in order), or an LTLf ``formula`` over the labels, or a ``patrol`` cycle (avoiding
    ``avoid``); formula and patrol plans start in ``start_cell`` or the first cell of
    ``sequence[0]``."""

    sequence: Annotated[list[label], BeforeValidator(_label_list)]
    start_cell: integer(0, 10 ** 9) | None = None
    planner: choice("exact", "greedy", "product") = "exact"
    formula: Annotated[str, BeforeValidator(_formula)] | None = None
    patrol: Annotated[list[label], BeforeValidator(_short_label_list)] | None = None
    avoid: Annotated[list[label], BeforeValidator(_short_label_list)] = []

    @model_validator(mode="after")
    def _one_kind(self):
        if self.formula is not None and self.patrol is not None:
            raise problem("formula", "give spec.formula or spec.patrol, not both")
        if self.patrol is not None and not self.patrol:
            raise problem("patrol", "expected at least one region label, e.g. [3, 5, 6]")
        if self.avoid and self.patrol is None:
            raise problem("avoid", "applies to spec.patrol only; in a formula write G(!l<label>)")
        return self

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


_FIGURE_KEYS = {"simulate": "enabled, width, height, dpi, edge, runs_drawn, density",
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
    """

    width: real(1.0, 100.0) = 6.0
    height: real(1.0, 100.0) = 6.0
    edge: Annotated[list[int], BeforeValidator(_cell_pair)] | None = None
    runs_drawn: integer(0, 10 ** 5) = 50
    density: Flag = True
