"""Grid map files (docs/reference/formats.md#grid-map).

One line per row, top row first: ``#`` obstacle, ``.`` free, ``0-9A-Za-z`` a
free cell carrying that region label. Cell ``(r, c)`` is the unit square
``[c, c+1] x [R-1-r, R-r]`` (``R`` rows, origin at the bottom-left corner).
Cells are numbered row-major over the free cells, top row first.

A map has at most :data:`MAX_GRID_CELLS` characters (rows x columns, obstacles
included); files must be UTF-8 text.
"""

from __future__ import annotations

import string
from pathlib import Path

import numpy as np
import shapely

from ...errors import InputError
from ...files import decode_utf8, read_bytes
from ..geometry import Polytope
from .decomposition import CellDecomposition

__all__ = ["GridMapError", "MAX_GRID_CELLS", "LABEL_CHARS", "scan_row", "parse_grid_map", "load_grid_map"]

#: The characters that label a free square.
LABEL_CHARS = frozenset(string.digits + string.ascii_letters)

#: Largest map accepted, in grid squares (rows x columns, obstacles included).
MAX_GRID_CELLS = 1_000_000


class GridMapError(InputError):
    """A grid map is malformed; the message names the file, line and column."""


def scan_row(line: str, name: str, number: int) -> tuple[list, list]:
    """The squares of one map row (line ``number`` of the file ``name``): ``free``, a list of
    ``(column, label or None)``, and ``runs``, a list of ``(start, stop)`` columns of each run of ``#``;
    a ``GridMapError`` naming the line and column of an unknown character."""
    free, runs, start = [], [], None                      # start: the open run of '#'
    for c, ch in enumerate(line):
        if ch == "#":
            start = c if start is None else start
            continue
        if start is not None:
            runs.append((start, c))
            start = None
        if ch != "." and ch not in LABEL_CHARS:
            raise GridMapError(f"{name}, line {number}, column {c + 1}: unknown character {ch!r} "
                               "(expected '#', '.', or a label 0-9A-Za-z)")
        free.append((c, None if ch == "." else ch))
    if start is not None:
        runs.append((start, len(line)))
    return free, runs


def parse_grid_map(text: str, name: str = "<string>") -> CellDecomposition:
    """Parse grid-map ``text`` (trailing blank lines and ``\\r`` ignored) into a :class:`CellDecomposition`;
    a ``GridMapError`` naming ``name`` (the file), line and column for anything malformed."""
    lines = [ln.rstrip("\r") for ln in text.split("\n")]
    while lines and lines[-1].strip() == "":
        lines.pop()
    if not lines:
        raise GridMapError(f"{name}: the map is empty (expected at least one row of '#', '.', or labels 0-9A-Za-z)")
    width = len(lines[0])
    if width == 0:
        raise GridMapError(f"{name}, line 1: the first row is empty")
    R = len(lines)
    if R * width > MAX_GRID_CELLS:
        raise GridMapError(f"{name}: the map has {R} rows x {width} columns = {R * width} squares, "
                           f"more than the limit of {MAX_GRID_CELLS}")
    cells, labels, grid, obstacles = [], [], [], []
    for r, line in enumerate(lines):
        if len(line) != width:
            raise GridMapError(
                f"{name}, line {r + 1}: ragged row of length {len(line)}, expected {width} like line 1")
        free, runs = scan_row(line, name, r + 1)
        obstacles += [shapely.box(c, R - 1 - r, c + 1, R - r) for start, stop in runs for c in range(start, stop)]
        for c, label in free:
            cells.append(Polytope.box((c, R - 1 - r), (c + 1, R - r)))
            labels.append(label)
            grid.append((r, c))
    if not cells:
        raise GridMapError(f"{name}: the map has no free cell (every character is '#')")
    obs = (shapely.union_all(obstacles),) if obstacles else ()
    return CellDecomposition(tuple(cells), tuple(labels), obs, np.array(grid, dtype=int), name)


def load_grid_map(path) -> CellDecomposition:
    """Read and parse a UTF-8 grid map file (:func:`parse_grid_map`); errors name the file."""
    p = Path(path)
    return parse_grid_map(decode_utf8(read_bytes(p, "grid map", GridMapError), str(p), GridMapError),
                          name=str(p))
