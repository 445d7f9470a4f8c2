"""Grid map files (SPEC section 6).

One line per row, top row first: ``#`` obstacle, ``.`` free, ``0-9A-Za-z`` a
free cell carrying that region label. Cell ``(r, c)`` is the unit square
``[c, c+1] x [R-1-r, R-r]`` (``R`` rows, origin at the bottom-left corner).
Cells are numbered row-major over the free cells, top row first.
"""

from __future__ import annotations

import string
from pathlib import Path

import numpy as np
import shapely

from ..geometry import Polytope
from .decomposition import CellDecomposition

__all__ = ["GridMapError", "parse_grid_map", "load_grid_map"]

_LABEL_CHARS = set(string.digits + string.ascii_letters)


class GridMapError(ValueError):
    """A grid map is malformed; the message names the file, line and column."""


def parse_grid_map(text: str, name: str = "<string>") -> CellDecomposition:
    """Parse grid-map text into a :class:`CellDecomposition`.

    Parameters
    ----------
    text : str
        The map. Trailing blank lines and trailing ``\\r`` are ignored.
    name : str
        Used in error messages (normally the file path).

    Raises
    ------
    GridMapError
        Ragged rows, an unknown character, an empty map, or no free cell.
    """
    lines = [ln.rstrip("\r") for ln in text.split("\n")]
    while lines and lines[-1].strip() == "":
        lines.pop()
    if not lines:
        raise GridMapError(f"{name}: the map is empty (expected at least one row of '#', '.', or labels 0-9A-Za-z)")
    width = len(lines[0])
    if width == 0:
        raise GridMapError(f"{name}, line 1: the first row is empty")
    R = len(lines)
    cells, labels, grid, obstacles = [], [], [], []
    for r, line in enumerate(lines):
        if len(line) != width:
            raise GridMapError(
                f"{name}, line {r + 1}: ragged row of length {len(line)}, expected {width} like line 1")
        for c, ch in enumerate(line):
            box = ((c, R - 1 - r), (c + 1, R - r))
            if ch == "#":
                obstacles.append(shapely.box(box[0][0], box[0][1], box[1][0], box[1][1]))
            elif ch == "." or ch in _LABEL_CHARS:
                cells.append(Polytope.box(box[0], box[1]))
                labels.append(None if ch == "." else ch)
                grid.append((r, c))
            else:
                raise GridMapError(
                    f"{name}, line {r + 1}, column {c + 1}: unknown character {ch!r} "
                    "(expected '#', '.', or a label 0-9A-Za-z)")
    if not cells:
        raise GridMapError(f"{name}: the map has no free cell (every character is '#')")
    obs = (shapely.union_all(obstacles),) if obstacles else ()
    return CellDecomposition(tuple(cells), tuple(labels), obs, np.array(grid, dtype=int), name)


def load_grid_map(path) -> CellDecomposition:
    """Read and parse a grid map file (see :func:`parse_grid_map`)."""
    p = Path(path)
    try:
        text = p.read_text()
    except OSError as exc:
        raise GridMapError(f"{p}: cannot read the grid map ({exc.strerror})") from None
    return parse_grid_map(text, name=str(p))
