"""The schema of a job's ``metrics.json`` (one flat row per run), checked before a sweep is aggregated
(docs/reference/formats.md#metricsjson).

:func:`read_metrics_row` reads one row and checks every field it knows: its type (a string where a
number belongs is refused), its range and what the row says of itself (``n_edges`` is the length of
``edges``). Only ``method`` is required; unknown keys are kept as they are.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Annotated, Literal

import pydantic
from pydantic import ConfigDict, Field, model_validator

from ..lp.evidence.registry import method_names

__all__ = ["MetricsRow", "MetricsRowError", "read_metrics_row"]

#: The methods a metrics row may name: the registered LPs.
METHOD_NAMES = method_names()
_Count = Annotated[int, Field(ge=0, strict=True)]
_Seconds = Annotated[float, Field(ge=0.0, allow_inf_nan=False)]
_Name = Annotated[str, Field(min_length=1, max_length=4096)]

#: What each field must be, for the messages.
EXPECTED = {
    "method": "tube, openloop or exact2d", "L_max": "an integer in [1, 1000]", "pruning": "true or false",
    "radius": "a number >= 0 (NaN for a polytope W)", "mean_L": "a number in [1, L_max], or NaN without edges",
    "mean_margin": "a finite number, or NaN without edges", "edges": "a list of [from, to, L] integer triples",
    **{k: "a non-negative integer" for k in ("n_cells", "n_edges", "n_lps", "n_pruned", "n_translated",
                                             "n_zero_margin")},
    **{k: "a finite number >= 0" for k in ("seconds", "compile_seconds", "learn_seconds")},
    **{k: "a non-empty string" for k in ("solver", "system", "workspace", "disturbance", "zshape")},
}


class MetricsRowError(ValueError):
    """A ``metrics.json`` that cannot be read or does not fit :class:`MetricsRow` (the message names the field)."""


class MetricsRow(pydantic.BaseModel):
    """One job's metrics row; every field but ``method`` optional, each checked when present."""

    model_config = ConfigDict(strict=True, extra="allow", frozen=True)

    method: Literal[METHOD_NAMES]
    solver: _Name | None = None
    system: _Name | None = None
    workspace: _Name | None = None
    disturbance: _Name | None = None
    zshape: _Name | None = None
    radius: float | None = None
    L_max: Annotated[int, Field(ge=1, le=1000, strict=True)] | None = None
    pruning: bool | None = None
    n_cells: _Count | None = None
    n_edges: _Count | None = None
    n_lps: _Count | None = None
    n_pruned: _Count | None = None
    n_translated: _Count | None = None
    n_zero_margin: _Count | None = None
    mean_L: float | None = None
    mean_margin: float | None = None
    seconds: _Seconds | None = None
    compile_seconds: _Seconds | None = None
    learn_seconds: _Seconds | None = None
    edges: list[Annotated[list[_Count], Field(min_length=3, max_length=3)]] | None = None

    @model_validator(mode="after")
    def _consistent(self):
        def bad(field, why):
            raise ValueError(f"{field}: {why}")

        if self.radius is not None and not (math.isnan(self.radius) or 0.0 <= self.radius < math.inf):
            bad("radius", f"expected {EXPECTED['radius']}, got {self.radius!r}")
        if self.mean_margin is not None and math.isinf(self.mean_margin):
            bad("mean_margin", f"expected {EXPECTED['mean_margin']}, got {self.mean_margin!r}")
        if self.edges is not None and any(e[2] < 1 for e in self.edges):
            k = next(k for k, e in enumerate(self.edges) if e[2] < 1)
            bad(f"edges[{k}]", f"expected L >= 1, got {self.edges[k]}")
        n = self.n_edges if self.n_edges is not None else (len(self.edges) if self.edges is not None else None)
        if self.edges is not None and self.n_edges is not None and len(self.edges) != self.n_edges:
            bad("n_edges", f"is {self.n_edges}, but the row lists {len(self.edges)} edges")
        if self.n_cells is not None and n is not None and n > self.n_cells * max(self.n_cells - 1, 0):
            bad("n_edges", f"is {n}, more than the {self.n_cells * max(self.n_cells - 1, 0)} pairs of "
                           f"{self.n_cells} cells")
        if self.mean_L is not None:
            nan, top = math.isnan(self.mean_L), self.L_max if self.L_max is not None else math.inf
            if (n is not None and (n == 0) != nan) or (not nan and not 1.0 <= self.mean_L <= top):
                bad("mean_L", f"expected {EXPECTED['mean_L']} ({n} edges), got {self.mean_L!r}")
        return self


def _message(exc: pydantic.ValidationError, path: Path) -> str:
    lines = []
    for e in exc.errors():
        loc = [str(x) for x in e["loc"]]
        field = loc[0] if loc else ""
        if e["type"] == "value_error":
            lines.append(str(e["msg"]).removeprefix("Value error, "))
            continue
        where = field + "".join(f"[{x}]" for x in loc[1:])
        got = e.get("input")
        lines.append(f"{where}: expected {EXPECTED.get(field, e['msg'].lower())}, got {json.dumps(got)[:80]}"
                     if got is not None else f"{where}: {e['msg'].lower()}")
    more = f" (and {len(lines) - 1} more: {'; '.join(lines[1:4])})" if len(lines) > 1 else ""
    return f"{path}: {lines[0]}{more}"


def read_metrics_row(path) -> dict:
    """The validated row of ``path`` as a plain dict (the file's keys, unknown ones kept).

    Raises
    ------
    MetricsRowError
        The file cannot be read (damaged, cut, not UTF-8), is not a JSON object, or a field has
        the wrong type or range -- naming the file and the field.
    """
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise MetricsRowError(f"{path}: cannot read it ({exc})") from None
    except ValueError as exc:
        raise MetricsRowError(f"{path}: not valid JSON ({str(exc).splitlines()[0]}); the file is damaged or "
                              "cut: rerun the job") from None
    if not isinstance(data, dict):
        raise MetricsRowError(f"{path}: expected a JSON object (one row of run metrics), got {type(data).__name__}")
    try:
        MetricsRow.model_validate(data)
    except pydantic.ValidationError as exc:
        raise MetricsRowError(_message(exc, path)) from None
    return data
