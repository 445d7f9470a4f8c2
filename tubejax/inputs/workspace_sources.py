"""Workspace sources of the input model: a grid map file, a polygon workspace file, an n-D box grid.

A :class:`FileRef` holds the path as given, the absolute path found and the SHA-256 of its bytes.
Paths are looked up as given, then relative to each of the validation context's ``search_dirs``. A
``FileRef`` read back from a record is accepted only if the file found has exactly those bytes.
"""

from __future__ import annotations

import stat
from pathlib import Path
from typing import Annotated, Literal, Union

import numpy as np
from pydantic import Field, ValidationInfo, model_validator

from ..errors import InputError
from ..files import decode_utf8, read_bytes, sha256_hex
from ..model.workspace import CellDecomposition
from ..model.workspace.boxgrid import _MAX_CELLS, box_grid
from ..model.workspace.gridmap import GridMapError
from ..model.workspace.lookahead import VelocityDivisionsError, lift_lookahead, velocity_division_count
from ..model.workspace.voxelmap import check_separators, is_voxel_map, parse_map
from ..model.workspace.polygon import PolygonWorkspaceError, parse_polygon_workspace_text
from .values import StrictModel, integer, label, problem, register_tags, short, vector

__all__ = ["FileRef", "GridMapSource", "PolygonFileSource", "BoxGridSource", "WorkspaceSource"]


def _candidates(path: str, resolved: str | None, search_dirs) -> list[Path]:
    p = Path(path).expanduser()
    cands = [Path(resolved)] if resolved else []
    if p.is_absolute():
        cands.append(p)
    else:
        cands += [Path.cwd() / p] + [Path(d) / p for d in search_dirs]
    return list(dict.fromkeys(cands))                   # each place once, in order


def _kind_of(path: Path) -> str:
    """What a path that exists but is no regular file or directory is, in words."""
    mode = path.stat().st_mode
    for test, what in ((stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISFIFO, "a named pipe"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return what
    return "not a regular file"


class FileRef(StrictModel):
    """A user file: ``path`` as given, ``resolved`` (absolute) and ``sha256`` of its bytes.

    Validate it from a path string, or from a record's ``{"path", "resolved", "sha256"}``
    (then the bytes must still hash to ``sha256``).
    """

    path: str
    resolved: str | None = None
    sha256: str | None = None

    @model_validator(mode="before")
    @classmethod
    def _from_string(cls, data):
        if isinstance(data, str):
            return {"path": data}
        if not isinstance(data, dict):
            raise problem("", f"expected a file path (a string), got {short(data)}")
        return data

    @model_validator(mode="after")
    def _find_and_hash(self, info: ValidationInfo):
        if not self.path.strip():
            raise problem("", "expected a file path, got an empty string")
        search = list((info.context or {}).get("search_dirs", ()))
        cands = _candidates(self.path, self.resolved, search)
        found = next((c for c in cands if c.is_file()), None)
        if found is None:
            dirs = [c for c in cands if c.is_dir()]
            if dirs:
                raise problem("", f"expected a file, got the directory {str(dirs[0])!r}")
            special = [c for c in cands if c.exists()]          # a device, a pipe or a socket: never read
            if special:
                raise problem("", f"expected a regular file, got {str(special[0])!r}, which is "
                                  f"{_kind_of(special[0])} (a map or workspace file is read whole and hashed)")
            raise problem("", f"file {self.path!r} not found (looked in {', '.join(map(str, cands))})")
        try:
            digest = sha256_hex(read_bytes(found, "file"))
        except InputError as exc:
            raise problem("", str(exc)) from None
        if self.sha256 is not None and digest != self.sha256:
            raise problem("", f"the file {str(found)!r} changed since it was recorded (sha256 {digest[:12]}..., "
                              f"recorded {str(self.sha256)[:12]}...)")
        return self.model_copy(update={"resolved": str(found.resolve()), "sha256": digest})

    def read(self, what: str, error: type[InputError]) -> bytes:
        """The file's bytes, refused unless they still hash to :attr:`sha256`."""
        data = read_bytes(self.resolved, what, error)
        if sha256_hex(data) != self.sha256:
            raise error(f"{self.resolved}: the {what} changed while it was being used (sha256 differs)")
        return data


class GridMapSource(StrictModel):
    """A grid map file (docs/reference/formats.md#grid-map), 3-D when it has layers
    (docs/reference/formats.md#voxel-map). With ``velocity_divisions`` (one, or one per axis) the map is
    lifted to double integrators in look-ahead coordinates
    (:func:`~tubejax.model.workspace.lookahead.lift_lookahead`, docs/math/drone.md)."""

    kind: Literal["grid"]
    map_file: FileRef
    velocity_divisions: integer(1, 10 ** 6) | list[integer(1, 10 ** 6)] | None = None

    def _text(self) -> str:
        return decode_utf8(self.map_file.read("grid map", GridMapError), self.map_file.resolved, GridMapError)

    @property
    def map_dim(self) -> int:
        """2, or 3 for a voxel map (a mistyped layer separator is a :class:`GridMapError` naming its line)."""
        text = self._text()
        check_separators(text, self.map_file.resolved)
        return 3 if is_voxel_map(text) else 2

    @property
    def dim(self) -> int:
        """The map's dimension, twice that with ``velocity_divisions`` (positions and look-aheads)."""
        return self.map_dim * (1 if self.velocity_divisions is None else 2)

    @property
    def cells_per_map_cell(self) -> int:
        """Cells over each map cell: the product of the velocity divisions (1 without them)."""
        if self.velocity_divisions is None:
            return 1
        return int(np.prod(self._divisions(), dtype=object))

    def _divisions(self) -> np.ndarray:
        try:
            return velocity_division_count(self.velocity_divisions, self.map_dim)
        except VelocityDivisionsError as exc:
            raise problem("velocity_divisions", str(exc).partition(": ")[2]) from None

    @model_validator(mode="after")
    def _divisions_fit(self):
        if self.velocity_divisions is not None:
            self._divisions()
        return self

    def build(self, name: str | None = None) -> CellDecomposition:
        """Parse the map (its bytes verified against the SHA-256) into a :class:`CellDecomposition` named
        ``name`` (default: the file), lifted by the velocity divisions when they are given."""
        base = parse_map(self._text(), name=name or self.map_file.resolved)
        return base if self.velocity_divisions is None else lift_lookahead(base, self.velocity_divisions)


class PolygonFileSource(StrictModel):
    """A YAML polygon workspace file, 2-D, decomposed by constrained triangulation."""

    kind: Literal["polygon"]
    file: FileRef

    @property
    def dim(self) -> int:
        return 2

    def build(self, name: str | None = None) -> CellDecomposition:
        """Read and triangulate the workspace (bytes verified against the SHA-256), named ``name``
        (default: the file)."""
        path = self.file.resolved
        text = decode_utf8(self.file.read("polygon workspace", PolygonWorkspaceError), path, PolygonWorkspaceError)
        return parse_polygon_workspace_text(text, name=name or path)


_Corner = vector("a list of coordinates")
_Box = Annotated[list[_Corner], Field(min_length=2, max_length=2)]


class BoxGridSource(StrictModel):
    """A uniform box grid over ``[lower, upper]`` in ``R^n`` (:func:`tubejax.model.workspace.box_grid`)."""

    kind: Literal["boxgrid"]
    name: str = "box grid"
    lower: _Corner
    upper: _Corner
    divisions: integer(1, _MAX_CELLS) | list[integer(1, _MAX_CELLS)]
    obstacles: list[_Box] = []
    labels: dict[label, _Box] = {}

    @property
    def dim(self) -> int:
        return len(self.lower)

    @model_validator(mode="after")
    def _consistent(self):
        n = len(self.lower)
        if len(self.upper) != n:
            raise problem("upper", f"expected {n} numbers (like lower), got {len(self.upper)}")
        if any(u <= l for l, u in zip(self.lower, self.upper)):
            raise problem("upper", f"expected upper > lower in every dimension, got lower {self.lower} "
                                   f"and upper {self.upper}")
        if isinstance(self.divisions, list) and len(self.divisions) != n:
            raise problem("divisions", f"expected {n} integers (one per dimension), got {self.divisions}")
        for where, boxes in (("obstacles", enumerate(self.obstacles)), ("labels", self.labels.items())):
            for key, (lo, hi) in boxes:
                field = f"{where}[{key!r}]" if where == "labels" else f"{where}[{key}]"
                if len(lo) != n or len(hi) != n:
                    raise problem(field, f"expected two corners of {n} numbers, got {[lo, hi]}")
                if any(h <= l for l, h in zip(lo, hi)):
                    raise problem(field, f"expected lower < upper in every dimension, got {[lo, hi]}")
        return self

    def build(self) -> CellDecomposition:
        """The box grid's :class:`CellDecomposition`."""
        return box_grid(self.lower, self.upper, self.divisions,
                        obstacles=[(lo, hi) for lo, hi in self.obstacles],
                        labels={str(k): (lo, hi) for k, (lo, hi) in self.labels.items()}, name=self.name)


register_tags("workspace", "grid", "polygon", "boxgrid")

#: Any workspace source, chosen by ``kind``.
WorkspaceSource = Annotated[Union[GridMapSource, PolygonFileSource, BoxGridSource], Field(discriminator="kind")]
