"""Voxel map files: 3-D grid maps (docs/reference/formats.md#voxel-map).

A stack of 2-D grid maps (:mod:`.gridmap`) of equal size separated by lines ``---``, bottom layer
first. Voxel ``(k, r, c)`` is the unit cube ``[c, c+1] x [R-1-r, R-r] x [k, k+1]`` (``R`` rows);
cells are numbered layer by layer, row-major within one (top row first). Each run of ``#`` along a
row is one obstacle box; ``domain`` is the whole block ``[0, C] x [0, R] x [0, K]``.

A map has at most :data:`~.gridmap.MAX_GRID_CELLS` characters in all (layers x rows x columns).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...files import decode_utf8, read_bytes
from ..geometry import Polytope
from .decomposition import CellDecomposition
from .gridmap import MAX_GRID_CELLS, GridMapError, parse_grid_map, scan_row

__all__ = ["LAYER_SEPARATOR", "is_voxel_map", "check_separators", "parse_voxel_map", "parse_map", "load_map"]

#: The line that separates two layers of a voxel map.
LAYER_SEPARATOR = "---"
#: Characters a typed or pasted separator is made of (hyphens, dashes, minus signs, box-drawing lines).
_DASHES = frozenset("-\u2010\u2011\u2012\u2013\u2014\u2015\u2212\u2500\u2501\ufe58\ufe63\uff0d_=")


def check_separators(text: str, name: str) -> None:
    """Refuse (``GridMapError`` naming the line) a line that looks like a layer separator but is not
    exactly ``---``: a mistyped one would make the map 2-D, and the error would blame the system's dimension."""
    for number, line in enumerate(text.split("\n"), start=1):
        s = line.strip()
        if s and s != LAYER_SEPARATOR and set(s) - {" ", "\t"} <= _DASHES:
            raise GridMapError(f"{name}, line {number}: {s[:20]!r} is not a layer separator (a voxel map separates "
                               f"its layers with a line of exactly three hyphens {LAYER_SEPARATOR!r}, U+002D)")


def is_voxel_map(text: str) -> bool:
    """Whether map text has layers (a line ``---``): a voxel map, else a 2-D grid map."""
    return any(ln.strip() == LAYER_SEPARATOR for ln in text.split("\n"))


def _layers(text: str, name: str) -> list[list[tuple[int, str]]]:
    """The layers as lists of ``(line number, row text)``. Blank lines next to a separator and at
    either end are ignored; one between two rows of a layer is an error."""
    blocks: list = [[]]
    for number, line in enumerate(text.split("\n"), start=1):
        line = line.rstrip("\r")
        if line.strip() == LAYER_SEPARATOR:
            blocks.append([])
        else:
            blocks[-1].append((number, line))
    layers = []
    for k, block in enumerate(blocks):
        rows = [i for i, (_, line) in enumerate(block) if line.strip()]
        if not rows:
            where = f"line {block[0][0]}" if block else "the end of the file"
            raise GridMapError(f"{name}, {where}: layer {k + 1} is empty (expected rows of '#', '.', or labels "
                               "0-9A-Za-z between the separators '---')")
        inner = block[rows[0]:rows[-1] + 1]
        for number, line in inner:
            if not line.strip():
                raise GridMapError(f"{name}, line {number}: a blank line inside layer {k + 1} (layers are "
                                   "separated by a line '---')")
        layers.append(inner)
    return layers


def parse_voxel_map(text: str, name: str = "<string>") -> CellDecomposition:
    """Parse voxel-map text into a 3-D :class:`CellDecomposition` (module doc): ``N`` free unit cubes
    (``vertices (8, 3)``), ``grid (N, 3)`` of ``(layer, row, column)``, box obstacles, ``domain`` the block.
    A ``GridMapError`` names ``name`` (the file), the line and column of anything malformed.
    """
    layers = _layers(text, name)
    K, R, C = len(layers), len(layers[0]), len(layers[0][0][1])
    if K * R * C > MAX_GRID_CELLS:
        raise GridMapError(f"{name}: the map has {K} layers x {R} rows x {C} columns = {K * R * C} voxels, "
                           f"more than the limit of {MAX_GRID_CELLS}")
    cells, labels, grid, obstacles = [], [], [], []
    for k, layer in enumerate(layers):
        if len(layer) != R:
            raise GridMapError(f"{name}, line {layer[0][0]}: layer {k + 1} has {len(layer)} rows, expected {R} "
                               "like layer 1")
        for r, (number, line) in enumerate(layer):
            if len(line) != C:
                raise GridMapError(f"{name}, line {number}: ragged row of length {len(line)}, expected {C} "
                                   "like the first row")
            free, runs = scan_row(line, name, number)
            obstacles += [Polytope.box((start, R - 1 - r, k), (stop, R - r, k + 1)) for start, stop in runs]
            for c, label in free:
                cells.append(Polytope.box((c, R - 1 - r, k), (c + 1, R - r, k + 1)))
                labels.append(label)
                grid.append((k, r, c))
    if not cells:
        raise GridMapError(f"{name}: the map has no free voxel (every character is '#')")
    return CellDecomposition(tuple(cells), tuple(labels), tuple(obstacles), np.array(grid, dtype=int), name,
                             domain=Polytope.box((0, 0, 0), (C, R, K)))


def parse_map(text: str, name: str = "<string>") -> CellDecomposition:
    """A map file's text: a voxel map (3-D) when it has layers, else a 2-D grid map
    (:func:`~.gridmap.parse_grid_map`)."""
    check_separators(text, name)
    return parse_voxel_map(text, name) if is_voxel_map(text) else parse_grid_map(text, name)


def load_map(path) -> CellDecomposition:
    """Read and parse a UTF-8 map file, 2-D or voxel (:func:`parse_map`); errors name the file."""
    p = Path(path)
    return parse_map(decode_utf8(read_bytes(p, "grid map", GridMapError), str(p), GridMapError), name=str(p))
