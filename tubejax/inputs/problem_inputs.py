"""The whole problem as the user gave it: :class:`ProblemInputs`, and its provenance record
(docs/reference/formats.md#the-inputs-record).

``ProblemInputs.from_dict(data, search_dirs)`` validates a plain dict and raises one
:class:`~tubejax.errors.InputModelError` naming every bad field; ``record()`` gives a JSON-safe dict
from which :func:`from_record` rebuilds the same model, refusing files whose bytes changed. Nothing
derived is recorded: a verifier rebuilds the problem and never trusts copied data.
"""

from __future__ import annotations

from typing import Iterable

import numpy as np
import pydantic
from pydantic import model_validator

from ..errors import InputError, InputModelError
from ..lp.evidence.registry import (FORMULATIONS, formulation, modelling_methods, tube_methods,
                                    unmodelled_state_constraints)
from ..model.system import STATE_CONSTRAINTS, LinearSystem
from ..model.workspace import CellDecomposition
from ..model.workspace.gridmap import GridMapError
from ..model.zshape.kinds import ZKINDS, cross_sections, z_kind_problem
from ..model.zshape.z_table import ZTableError, assignment_from_table, load_z_table
from .dynamics import BoxDisturbance, Disturbance, PolytopeDisturbance, SystemModel, check_vertex_form
from .settings import AbstractionSettings, SimulationSettings, SpecSettings, ZShapeSettings, without_retired_keys
from .workspace_sources import WorkspaceSource
from .values import StrictModel, input_error, problem

__all__ = ["RECORD_VERSION", "ProblemInputs", "from_record", "validate_section", "app_problem_dict"]

#: Version of :meth:`ProblemInputs.record`'s format.
RECORD_VERSION = 1


def validate_section(model: type[pydantic.BaseModel], data, field: str = "", search_dirs: Iterable = (), rename=None):
    """Validate ``data`` as ``model``; a failure is an :class:`InputModelError` with paths below ``field``
    (each mapped by ``rename``, e.g. to the argument names of :mod:`tubejax.api`)."""
    try:
        return model.model_validate(data, context={"search_dirs": [str(d) for d in search_dirs]})
    except pydantic.ValidationError as exc:
        raise input_error(exc, prefix=field, rename=rename, model=model) from None
    except RecursionError:
        raise InputModelError([(field or "input", "nested too deeply")]) from None


class ProblemInputs(StrictModel):
    """Workspace, system, disturbance, ``Z``, abstraction settings, and optionally simulation and spec."""

    workspace: WorkspaceSource
    system: SystemModel
    disturbance: Disturbance
    zshape: ZShapeSettings = ZShapeSettings()
    abstraction: AbstractionSettings = AbstractionSettings()
    simulation: SimulationSettings | None = None
    spec: SpecSettings | None = None

    @model_validator(mode="after")
    def _dimensions(self):
        n = self.system.n
        try:
            d = self.workspace.dim
        except GridMapError as exc:                 # a mistyped layer separator: the map's line, not system.A
            raise problem("workspace.map_file", str(exc)) from None
        if n != d:
            raise problem("system.A", f"expected a {d} x {d} matrix (the workspace is {d}-D), got {n} x {n}")
        if isinstance(self.disturbance, BoxDisturbance):         # as a polytope W of the same vertices
            hw = self.disturbance.half_width
            check_vertex_form(-hw * np.ones(n), hw * np.ones(n), "disturbance.half_width", "W",
                              f"the half-width {hw:g}")
        if isinstance(self.disturbance, PolytopeDisturbance) and len(self.disturbance.vertices[0]) != n:
            raise problem("disturbance.vertices", f"expected points in R^{n} (the state space), got points with "
                                                  f"{len(self.disturbance.vertices[0])} coordinates")
        method = self.abstraction.method
        tubes = method in tube_methods()
        for key, kind in (("zshape.kind", self.zshape.kind), ("zshape.init", self.zshape.init)):
            if kind in ZKINDS:                   # the registry says where a fixed kind applies
                why = z_kind_problem(kind, n, tubes or key != "zshape.kind")
                if why is not None:
                    fit = [k for k in ZKINDS if z_kind_problem(k, n, tubes) is None]
                    raise problem(key, f"expected {' or '.join(fit)} for a {n}-D state with method {method} ({why})")
        constraints = [c for c in STATE_CONSTRAINTS if getattr(self.system, c, None) is not None]
        missing = unmodelled_state_constraints(method, constraints)
        if missing:
            able = modelling_methods(constraints)
            raise problem("abstraction.method", f"expected {' or '.join(able)} for a system with "
                                                f"{', '.join(missing)} ({method} does not model state constraints)")
        record = formulation(method)
        if record.dimensions and n not in record.dimensions:
            able = [m for m, f in FORMULATIONS.items() if not f.dimensions or n in f.dimensions]
            raise problem("abstraction.method", f"expected {' or '.join(able)} for a {n}-D state ({method} is "
                                                f"{' or '.join(f'{d}-D' for d in record.dimensions)} only)")
        if not record.solves_lp and self.abstraction.min_margin != 0:
            raise problem("abstraction.min_margin", f"expected 0 with method {method} (it has no margin), got "
                                                    f"{self.abstraction.min_margin}")
        return self

    @classmethod
    def from_dict(cls, data, search_dirs: Iterable = ()) -> "ProblemInputs":
        """Validate a plain dict; relative file paths are also looked up in ``search_dirs``.

        Raises
        ------
        InputModelError
            Every bad field, named by its dotted path (``system.A``, ``abstraction.L_max``).
        """
        return validate_section(cls, data, "", search_dirs)

    # ----------------------------------------------------------------- library objects
    def build_decomposition(self) -> CellDecomposition:
        """The workspace's :class:`CellDecomposition` (the file's bytes checked against its SHA-256)."""
        return self.workspace.build()

    def build_disturbance(self):
        """``W`` in ``R^n``: a :class:`~tubejax.model.geometry.Ball` or :class:`~tubejax.model.geometry.Polytope`."""
        try:
            return self.disturbance.build(self.system.n)
        except InputError as exc:
            raise InputModelError([("disturbance", str(exc))]) from None

    def build_system(self) -> LinearSystem:
        """The :class:`LinearSystem` ``(A, B, U, W)``."""
        W = self.build_disturbance()
        try:
            return self.system.build(W)
        except InputError as exc:
            raise InputModelError([("system", str(exc))]) from None

    def build_cross_sections(self, decomp: CellDecomposition):
        """The cross-sections of ``decomp``'s pairs (:func:`tubejax.abstraction.build_abstraction`'s ``z``).

        A fixed kind: ``make_z(kind, cell, scale)`` per cell. A learned kind: the table of
        ``zshape.file`` (its bytes checked against the recorded SHA-256, its mode against the
        kind) through :func:`tubejax.model.zshape.z_table.assignment_from_table`.

        Returns
        -------
        tuple of Polytope (length N), or a ZAssignment for ``learned_pair``

        Raises
        ------
        InputError
            A kind or ``init`` that does not fit the cells, no ``zshape.file`` for a learned
            kind, or a learned-Z file that is missing, changed, damaged or of the other mode
            (naming the file).
        """
        z = self.zshape
        if not z.learned:
            try:
                return cross_sections(decomp, z.kind, z.scale)
            except ValueError as exc:
                raise InputModelError([("zshape.kind", str(exc))]) from None
        if z.file is None:
            raise InputModelError([("zshape.file", f"zshape={z.kind} needs a learned Z file (learned_z.json): "
                                                   "experiments/abstract.py learns and records one")])
        table = load_z_table(z.file.resolved, sha256=z.file.sha256)
        if table.mode != z.kind:
            raise ZTableError(f"{z.file.resolved}: mode: the file holds {table.mode!r} Z, zshape.kind is {z.kind!r}")
        try:
            return assignment_from_table(decomp, table, z.init, z.scale)
        except ZTableError:
            raise
        except ValueError as exc:
            raise InputModelError([("zshape.init", str(exc).removeprefix("zshape.init: "))]) from None

    def abstraction_kwargs(self) -> dict:
        """Keyword arguments of :func:`tubejax.abstraction.build_abstraction` fixed by these inputs."""
        a = self.abstraction
        return {"zshape": self.zshape.kind, "z_scale": self.zshape.scale, "L_max": a.L_max,
                "eps_min": a.eps_min, "min_margin": a.min_margin, "pruning": a.pruning, "method": a.method}

    # ----------------------------------------------------------------- provenance
    def record(self) -> dict:
        """A JSON-safe, versioned record of these inputs (see the module docstring)."""
        body = self.model_dump(mode="json", exclude_none=False)
        return {"version": RECORD_VERSION, **{k: v for k, v in body.items() if v is not None}}

    @classmethod
    def from_record(cls, record, search_dirs: Iterable = ()) -> "ProblemInputs":
        """Rebuild the model from :meth:`record`'s dict, verifying every file's SHA-256.

        Raises
        ------
        InputModelError
            An unknown version, a bad field, a missing file, or a file whose bytes changed.
        """
        if not isinstance(record, dict):
            raise InputModelError([("record", f"expected a mapping, got {type(record).__name__}")])
        if record.get("version") != RECORD_VERSION or isinstance(record.get("version"), bool):
            raise InputModelError([("version", f"expected {RECORD_VERSION} (the record format this tubejax "
                                               f"reads), got {record.get('version')!r}")])
        body = without_retired_keys({k: v for k, v in record.items() if k != "version"})
        return cls.from_dict(body, search_dirs)


def _pick(section, *keys) -> dict:
    return {k: section[k] for k in keys if isinstance(section, dict) and k in section}


def app_problem_dict(c: dict) -> dict:
    """The input model's dict (for :meth:`ProblemInputs.from_dict`) from an app's resolved config as plain
    containers (only the keys the config holds): the apps build their inputs with it, and
    :mod:`tubejax.verify.run_config` compares a run's saved config with its inputs record through it."""
    method = c.get("method")
    abstraction = _pick(c, "L_max", "eps_min", "min_margin", "pruning", "seed", "verify", "solver", "memory_budget_mb",
                        "shard")
    if "method" in c:
        abstraction["method"] = method.get("name") if isinstance(method, dict) else method
    data = _pick(c, "workspace", "system", "disturbance", "zshape")
    data["abstraction"] = abstraction
    return data


def from_record(record, search_dirs: Iterable = ()) -> ProblemInputs:
    """:meth:`ProblemInputs.from_record`."""
    return ProblemInputs.from_record(record, search_dirs)
