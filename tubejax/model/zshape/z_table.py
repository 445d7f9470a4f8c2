"""Learned cross-sections on disk: the ``learned_z.json`` file, its checks, the ``make_z`` hook, and
the cross-sections of a run from a table.

A :class:`ZTable` holds learned ``Z`` per cell shape (``'learned'``) or per ordered pair
(``'learned_pair'``), as ``learned_z.json`` (docs/reference/formats.md#learned_zjson), reloaded bit
for bit and re-checked (:func:`~tubejax.model.zshape.params.polytope_from_z`). :func:`use_z_table`
makes a table the one ``make_z('learned', cell)`` reads; :func:`assignment_from_table` gives a run's
cross-sections, falling back to ``fallback_kind`` (or, per pair, to the source cell's ``Z``).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
from pathlib import Path

import numpy as np

from ...errors import InputError
from ..zassignment import ZAssignment
from .kinds import ACTIVE_Z_TABLE, fallback_kind, make_z, z_vertex_count_problem
from .params import ZShapeError, family_of, polytope_from_z

__all__ = ["ZTable", "ZTableError", "use_z_table", "active_z_table", "load_z_table", "file_sha256",
           "assignment_from_table", "cell_shape_key", "FORMAT", "VERSION"]

FORMAT = "tubejax.learned_z"
VERSION = 1

_ACTIVE = ACTIVE_Z_TABLE


class ZTableError(InputError):
    """A learned-Z file or table that is missing, damaged or inconsistent (file and field named)."""


def cell_shape_key(V) -> bytes:
    """A key equal for cells equal up to translation (vertices ``(n_v, n)`` about their mean, 9 decimals)."""
    V = np.asarray(V, float)
    return np.round(V - V.mean(axis=0), 9).tobytes() + bytes(str(V.shape), "ascii")


class ZTable:
    """Learned ``Z`` by cell shape and / or by ordered pair.

    Parameters
    ----------
    mode : {'learned', 'learned_pair'}
    dim : int
    shapes : list of (cell_vertices (n_v, n), z (n_v, n))
    pairs : dict (i, j) -> z (n_v, n)
    learning : dict
        Provenance (JSON-safe).
    where : str
        How errors name the table (a file path); a ``ZTableError`` for a ``Z`` that breaks an
        invariant or two entries for the same key.
    """

    def __init__(self, mode: str, dim: int, shapes=(), pairs=None, learning: dict | None = None,
                 where: str = "<learned Z table>"):
        if mode not in ("learned", "learned_pair"):
            raise ZTableError(f"{where}: mode: expected 'learned' or 'learned_pair', got {mode!r}")
        self.mode, self.dim, self.where = mode, int(dim), where
        self.learning = dict(learning or {})
        self._shapes: dict = {}
        self._shape_list = []
        for k, (cell, z) in enumerate(shapes):
            cell = np.asarray(cell, float)
            P = self._checked(z, f"shapes[{k}].vertices")
            if cell.ndim != 2 or cell.shape[1] != self.dim or z_vertex_count_problem(P.n_vertices, cell.shape[0],
                                                                                      self.dim) is not None:
                raise ZTableError(f"{where}: shapes[{k}].cell: expected {P.n_vertices} vertices in R^{self.dim} "
                                  f"like its Z (in 2-D: or a divisor of it, >= 3), got shape {cell.shape}")
            key = cell_shape_key(cell)
            if key in self._shapes:
                raise ZTableError(f"{where}: shapes[{k}]: a second Z for the same cell shape")
            self._shapes[key] = P
            self._shape_list.append((cell - cell.mean(axis=0), P))
        self._pairs: dict = {}
        for (i, j), z in (pairs or {}).items():
            if not (isinstance(i, (int, np.integer)) and isinstance(j, (int, np.integer))) or i == j or i < 0 or j < 0:
                raise ZTableError(f"{where}: pairs: expected distinct cell ids >= 0, got ({i!r}, {j!r})")
            self._pairs[(int(i), int(j))] = self._checked(z, f"pairs[({i}, {j})].vertices")

    def _checked(self, z, field: str):
        try:
            z = np.asarray(z, dtype=np.float64)
        except (TypeError, ValueError):
            raise ZTableError(f"{self.where}: {field}: expected an array of numbers, got {z!r}") from None
        if z.ndim != 2 or z.shape[1] != self.dim or z.shape[0] < self.dim + 1:
            raise ZTableError(f"{self.where}: {field}: expected shape (n_v, {self.dim}) with n_v > {self.dim}, "
                              f"got {z.shape}")
        if self.dim != 2 and z.shape[0] != 2 ** self.dim:
            raise ZTableError(f"{self.where}: {field}: a {self.dim}-D learned Z is a parallelotope with "
                              f"{2 ** self.dim} vertices, got {z.shape[0]}")
        try:
            return polytope_from_z(family_of(self.dim, z.shape[0]), z)
        except ZShapeError as exc:
            raise ZTableError(f"{self.where}: {field}: {exc}") from None

    @property
    def n_shapes(self) -> int:
        return len(self._shapes)

    @property
    def pairs(self) -> dict:
        """``{(i, j): Polytope}`` (a copy)."""
        return dict(self._pairs)

    def z_for_cell(self, cell, scale: float = 1.0):
        """The learned ``Z`` of ``cell``'s shape times ``scale`` (checked again when ``scale != 1``); a
        ``ZShapeError`` when the shape has none or the scaled ``Z`` breaks an invariant."""
        P = self._shapes.get(cell_shape_key(cell.vertices))
        if P is None:
            raise ZShapeError(f"{self.where}: no learned Z for a cell of shape "
                              f"{np.round(cell.vertices - cell.vertices.mean(axis=0), 6).tolist()} "
                              f"({self.n_shapes} shapes in the table)")
        if scale == 1.0:
            return P
        return polytope_from_z(family_of(self.dim, P.n_vertices), scale * P.vertices)

    def z_for_pair(self, i: int, j: int):
        """The learned ``Z`` of the pair ``(i, j)``; ``KeyError`` when it has none."""
        return self._pairs[(int(i), int(j))]

    def to_json(self) -> dict:
        return {"format": FORMAT, "version": VERSION, "mode": self.mode, "dim": self.dim,
                "shapes": [{"cell": c.tolist(), "vertices": P.vertices.tolist()} for c, P in self._shape_list],
                "pairs": [{"from": i, "to": j, "vertices": P.vertices.tolist()}
                          for (i, j), P in sorted(self._pairs.items())],
                "learning": self.learning}

    def save(self, path) -> str:
        """Write the table as JSON; returns the SHA-256 of the bytes written."""
        data = json.dumps(self.to_json(), indent=1, allow_nan=False).encode()
        path = Path(path)
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_bytes(data)
        tmp.replace(path)
        return hashlib.sha256(data).hexdigest()


def file_sha256(path) -> str:
    """SHA-256 of a file's bytes (hex)."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _require(doc: dict, key: str, kind, where: str):
    if key not in doc:
        raise ZTableError(f"{where}: {key}: missing")
    v = doc[key]
    if not isinstance(v, kind) or isinstance(v, bool):
        raise ZTableError(f"{where}: {key}: expected {getattr(kind, '__name__', kind)}, got {v!r}")
    return v


def load_z_table(path, sha256: str | None = None) -> ZTable:
    """Read and check a ``learned_z.json`` (module docstring) whose bytes have the SHA-256 ``sha256``
    if given; a ``ZTableError`` naming the file and the field for anything wrong."""
    path = Path(path)
    where = str(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ZTableError(f"{where}: cannot read the learned Z file ({exc.strerror})") from None
    if sha256 is not None and hashlib.sha256(data).hexdigest() != sha256:
        raise ZTableError(f"{where}: the file's SHA-256 differs from the one recorded ({sha256}): it changed")
    try:
        doc = json.loads(data, parse_constant=lambda c: (_ for _ in ()).throw(ValueError(c)))
    except ValueError as exc:
        raise ZTableError(f"{where}: not valid JSON ({exc})") from None
    if not isinstance(doc, dict):
        raise ZTableError(f"{where}: expected a JSON object at the top, got {type(doc).__name__}")
    if doc.get("format") != FORMAT:
        raise ZTableError(f"{where}: format: expected {FORMAT!r}, got {doc.get('format')!r}")
    if doc.get("version") != VERSION:
        raise ZTableError(f"{where}: version: expected {VERSION}, got {doc.get('version')!r}")
    mode = _require(doc, "mode", str, where)
    dim = _require(doc, "dim", int, where)
    if not 1 <= dim <= 16:
        raise ZTableError(f"{where}: dim: expected an integer in [1, 16], got {dim}")
    shapes = []
    for k, e in enumerate(_require(doc, "shapes", list, where)):
        if not isinstance(e, dict) or set(e) != {"cell", "vertices"}:
            raise ZTableError(f"{where}: shapes[{k}]: expected an object with 'cell' and 'vertices'")
        shapes.append((_numbers(e["cell"], f"{where}: shapes[{k}].cell"), e["vertices"]))
    pairs = {}
    for k, e in enumerate(_require(doc, "pairs", list, where)):
        if not isinstance(e, dict) or set(e) != {"from", "to", "vertices"}:
            raise ZTableError(f"{where}: pairs[{k}]: expected an object with 'from', 'to' and 'vertices'")
        i, j = e["from"], e["to"]
        if not (type(i) is int and type(j) is int):
            raise ZTableError(f"{where}: pairs[{k}].from/to: expected integers, got {i!r}, {j!r}")
        if (i, j) in pairs:
            raise ZTableError(f"{where}: pairs[{k}]: a second Z for the pair ({i}, {j})")
        pairs[(i, j)] = e["vertices"]
    learning = doc.get("learning", {})
    if not isinstance(learning, dict):
        raise ZTableError(f"{where}: learning: expected an object, got {learning!r}")
    return ZTable(mode, dim, shapes, pairs, learning, where=where)


def _numbers(v, where: str) -> np.ndarray:
    try:
        a = np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError):
        raise ZTableError(f"{where}: expected an array of numbers, got {v!r}") from None
    if a.ndim != 2 or not all(math.isfinite(x) for x in a.ravel()):
        raise ZTableError(f"{where}: expected a finite array of shape (n_v, n), got {v!r}")
    return a


@contextlib.contextmanager
def use_z_table(table: ZTable):
    """Within the block, ``make_z('learned', cell, scale)`` reads ``table``
    (``with use_z_table(t): build_abstraction(decomp, system, zshape="learned")``)."""
    if not isinstance(table, ZTable):
        raise TypeError(f"use_z_table needs a ZTable, got {type(table).__name__}")
    token = _ACTIVE.set(table)
    try:
        yield table
    finally:
        _ACTIVE.reset(token)


def active_z_table() -> ZTable | None:
    """The table set by the innermost :func:`use_z_table`, or ``None``."""
    return _ACTIVE.get()


def assignment_from_table(decomp, table: ZTable, init: str = "box", scale: float = 1.0):
    """The cross-sections of a run with learned ``Z`` (see the module docstring).

    ``init``: the kind of a cell whose shape the table lacks (``'best'``: ``fallback_kind``); ``scale``:
    every ``Z``'s size.

    Returns
    -------
    tuple of Polytope (length N) for ``learned``, ZAssignment for ``learned_pair``
        A ``ZTableError`` for a table of the wrong dimension or a pair that does not fit
        ``decomp``; a ``ValueError`` when ``init`` does not fit a cell the table lacks.
    """
    N = decomp.n_cells
    if table.dim != decomp.dim:
        raise ZTableError(f"{table.where}: dim: the table is {table.dim}-D, the workspace {decomp.dim}-D")
    per_cell, seen = [], {}
    for c in decomp.cells:
        key = cell_shape_key(c.vertices)
        if key not in seen:
            try:
                seen[key] = table.z_for_cell(c, scale)
            except ZShapeError:
                try:
                    seen[key] = make_z(fallback_kind(init, c), c, scale)
                except ValueError as exc:
                    shape = np.round(c.vertices - c.vertices.mean(axis=0), 6).tolist()
                    raise ValueError(f"zshape.init: a cell of shape {shape} has no learned Z in {table.where} "
                                     f"and {exc}") from None
        per_cell.append(seen[key])
    if table.mode == "learned":
        return tuple(per_cell)
    pairs = {}
    for (i, j), P in sorted(table.pairs.items()):
        if i >= N or j >= N:
            raise ZTableError(f"{table.where}: pairs ({i}, {j}): not a pair of cells of this workspace ({N} cells)")
        why = z_vertex_count_problem(P.n_vertices, decomp.cells[i].n_vertices, decomp.dim)
        if why is not None:
            raise ZTableError(f"{table.where}: pairs ({i}, {j}): {why}")
        pairs[(i, j)] = P if scale == 1.0 else polytope_from_z(family_of(table.dim, P.n_vertices), scale * P.vertices)
    return ZAssignment(per_cell, pairs)
