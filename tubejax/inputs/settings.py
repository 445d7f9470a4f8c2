"""Settings of the input model: the cross-section ``Z``, the abstraction, the solver, the simulation
and the specification (the apps' other settings: :mod:`tubejax.inputs.app_settings`). Each field is
refused outside its documented range, with the reason (docs/reference/configuration.md#ranges).
"""

from __future__ import annotations

from typing import Annotated, Literal, Union

from pydantic import BeforeValidator, Field, model_serializer, model_validator

from ..lp.evidence.registry import method_names
from ..model.zshape.kinds import LEARNED_ZSHAPES, ZSHAPES
from .workspace_sources import FileRef
from .values import (Flag, StrictModel, _fail, choice, integer, integer_or, label, problem, real, register_tags,
                     sized_list)

__all__ = ["ZSHAPE_SCALE_RANGE", "LEARNED_KINDS", "ZShapeSettings", "HighsSolverSettings", "PdhgSolverSettings",
           "SolverSettings", "ShardSettings", "AbstractionSettings", "SimulationSettings", "SpecSettings",
           "RETIRED_SOLVER_KEYS", "without_retired_keys"]

ZSHAPE_SCALE_RANGE = (1e-3, 1e3)
_SEED = integer(0, 2 ** 32 - 1)


#: Kinds whose ``Z`` is learned (:mod:`tubejax.analyses.zshape`); the others are fixed shapes.
LEARNED_KINDS = LEARNED_ZSHAPES
#: Defaults of the learned kinds' own fields (``None`` for the fixed kinds).
#: ``init='best'`` and the step size are those of ``scripts/learned_z_table.py``
#: (docs/howto/learned-z.md#the-comparison-sweep).
LEARNED_DEFAULTS = {"init": "best", "steps": 30, "learning_rate": 0.05, "horizon": "last", "patience": 5,
                    "seed": 0}


class ZShapeSettings(StrictModel):
    """The tube cross-section ``Z`` (:func:`tubejax.model.zshape.kinds.make_z`;
    docs/reference/configuration.md#zshape).

    ``learned`` (one ``Z`` per cell shape) and ``learned_pair`` (one per ordered pair, from the shared
    one) have their own fields, refused with a fixed kind: ``file`` (``None``: learn now, with ``steps``,
    ``learning_rate``, ``horizon``, ``patience``, ``seed`` from ``init``, see
    :func:`tubejax.model.zshape.kinds.start_kinds`); ``init`` is also the ``Z`` of a cell whose shape the
    table lacks. The record lists only the fields that are set."""

    kind: choice(*ZSHAPES, *LEARNED_KINDS) = "box"
    scale: real(*ZSHAPE_SCALE_RANGE, why="with eps_min = 0 only the shape of Z decides feasibility, eps scales it; "
                "far from the cell size the LP is badly scaled") = 1.0
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


class SimulationSettings(StrictModel):
    """Closed-loop runs (:func:`tubejax.analyses.control.simulate`); ``cycles``: patrol cycles simulated."""

    runs: integer(1, 10 ** 7) = 50
    mode: choice("uniform", "boundary", "adversarial", "none") = "uniform"
    seed: _SEED = 0
    cycles: integer(1, 10 ** 4) = 1


_LABELS = sized_list(0, 1000, "a list of at most 1000 region labels, e.g. [4]")
#: Longest formula accepted (characters): far beyond any formula whose automaton can be built.
MAX_FORMULA_LENGTH = 10_000


def _formula(what: str, example: str) -> BeforeValidator:
    """A non-empty formula ``what`` of at most :data:`MAX_FORMULA_LENGTH` characters."""
    def check(value):
        if isinstance(value, str) and len(value) > MAX_FORMULA_LENGTH:
            raise _fail(f"{what} of at most {MAX_FORMULA_LENGTH:,} characters (the limit on its length; "
                        f"this one has {len(value):,})")
        if not isinstance(value, str) or not value.strip():
            raise _fail(f"{what} as a string (quote it on the command line: '{example}')")
        return value

    return BeforeValidator(check)


class SpecSettings(StrictModel):
    """The specification: a sequence of region labels (start in the first, then visit the
    others in order), or an LTLf ``formula`` over the labels (finite runs), or an ``ltl``
    formula (infinite runs: a lasso, its cycle simulated ``sim.cycles`` times), or a ``patrol``
    cycle (avoiding ``avoid``); formula, ltl and patrol plans start in the first cell of the region
    ``start``, or in ``start_cell``, or else in the first cell of ``sequence[0]`` (a one-label
    sequence is just that start)."""

    sequence: Annotated[list[label], sized_list(1, 1000, "a list of 1 to 1000 region labels, e.g. [1, 3]")]
    start: label | None = None
    start_cell: integer(0, 10 ** 9) | None = None
    planner: choice("exact", "greedy", "product") = "exact"
    formula: Annotated[str, _formula("an LTLf formula", 'spec.formula="F(l3) & G(!l4)"')] | None = None
    ltl: Annotated[str, _formula("an LTL formula over infinite runs", 'spec.ltl="GF l3 & GF l6 & G !l4"')] | None = None
    patrol: Annotated[list[label], _LABELS] | None = None
    avoid: Annotated[list[label], _LABELS] = []

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
