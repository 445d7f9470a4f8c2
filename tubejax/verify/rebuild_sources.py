"""Step 2 of :mod:`tubejax.verify.verifier`: :func:`rebuild` builds the problem of an inputs record
(files by path and SHA-256) and :func:`check_sources` compares every datum copied into a transitions
file with it. ``TransitionSystem.load`` runs it by default.
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np
import shapely

from ..errors import InputError
from ..model.geometry import Ball, Polytope
from ..model.system import LinearSystem
from ..transitions.file_format import TransitionFile
from ..model.zassignment import compare_pair_z
from ..inputs import ProblemInputs

__all__ = ["Rebuilt", "rebuild", "check_sources"]


class Rebuilt(NamedTuple):
    """The problem rebuilt from an inputs record."""

    inputs: object            # ProblemInputs
    decomposition: object     # CellDecomposition
    system: object            # LinearSystem
    Z: tuple                  # Polytope per cell, or a ZAssignment (per-pair Z)
    eps_min: float
    method: str
    L_max: int
    solver: str
    min_margin: float = 0.0


def rebuild(record: dict, directory: Path) -> Rebuilt:
    """The problem of an inputs record (files looked up as recorded, then beside ``directory``); an
    ``InputError`` for an invalid record, or a file missing or changed (SHA-256)."""
    inputs = ProblemInputs.from_record(_run_files_beside(record, directory), search_dirs=[directory])
    decomp = inputs.build_decomposition()
    system = inputs.build_system()
    try:
        Z = inputs.build_cross_sections(decomp)          # a learned Z: its file checked by SHA-256
    except InputError:
        raise
    except ValueError as exc:
        raise InputError(f"zshape: {exc}") from None
    a = inputs.abstraction
    return Rebuilt(inputs, decomp, system, Z, float(a.eps_min), a.method, int(a.L_max), a.solver.name,
                   float(a.min_margin))


def _run_files_beside(record, directory: Path):
    """``record`` with a learned-Z file saved with the run (recorded by a bare file name,
    ``learned_z.json``) resolved beside the transitions files: a copied or moved run checks its
    own copy, and a run whose copy is missing is refused (never checked against the file it was
    once copied from, or one in the working directory): an ``InputError`` if it is not there."""
    z = record.get("zshape") if isinstance(record, dict) else None
    f = z.get("file") if isinstance(z, dict) else None
    if not (isinstance(f, dict) and isinstance(f.get("path"), str) and f["path"]
            and Path(f["path"]).name == f["path"]):
        return record
    own = Path(directory) / f["path"]
    if not own.is_file():
        raise InputError(f"zshape.file: {own}: no such file (the run's learned Z is saved beside its transitions "
                         "files and recorded with its SHA-256; restore it from the run, or rerun the abstraction)")
    return {**record, "zshape": {**z, "file": {**f, "resolved": str(own.resolve())}}}


def _same(a, b) -> bool:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return a.shape == b.shape and bool(np.array_equal(a, b))


def _compare(doc: TransitionFile, arrays: dict, rb: Rebuilt) -> list[str]:
    """Every datum copied into the file that differs from the rebuilt problem."""
    out = []
    d = rb.decomposition
    if doc.method != rb.method:
        out.append(f"method: the file says {doc.method!r}, its inputs record says {rb.method!r}")
    if float(doc.eps_min) != rb.eps_min:
        out.append(f"eps_min: the file says {doc.eps_min!r}, its inputs record says {rb.eps_min!r}")
    if float(doc.min_margin) != rb.min_margin:
        out.append(f"min_margin: the file says {doc.min_margin!r}, its inputs record says {rb.min_margin!r}")
    if len(doc.cells) != d.n_cells:
        out.append(f"cells: the file lists {len(doc.cells)} cells, the workspace has {d.n_cells}")
        return out
    for i, c in enumerate(doc.cells):
        if c.id != i:
            out.append(f"cells[{i}].id: expected {i}, got {c.id}")
        if not _same(c.vertices, d.cells[i].vertices):
            out.append(f"cells[{i}].vertices: differ from cell {i} of the workspace")
        lab = None if c.label is None else str(c.label)
        if lab != d.labels[i]:
            out.append(f"cells[{i}].label: the file says {lab!r}, the workspace says {d.labels[i]!r}")
        if d.grid is not None and (c.grid is None or list(c.grid) != d.grid[i].tolist()):
            out.append(f"cells[{i}].grid: the file says {c.grid!r}, the workspace says {d.grid[i].tolist()}")
        if f"Z_{i}" in arrays and not _same(arrays[f"Z_{i}"], rb.Z[i].vertices):
            out.append(f"Z_{i} (npz): differs from the cross-section {rb.inputs.zshape.kind!r} rebuilt for cell {i}"
                       + _z_source(rb))
    out += compare_pair_z(doc.edges, arrays, rb.Z, _z_source(rb))
    out += _compare_obstacles(doc, d)
    s, sysm = doc.system, rb.system
    try:
        differ = LinearSystem.from_record(s.model_dump()).differences(sysm)
    except (ValueError, TypeError):                        # SystemError_ is a ValueError
        differ = ["A", "B", "U", "W"]
    for name in differ:
        if name != "W":
            out.append(f"system.{name}: differs from the inputs record")
        elif isinstance(sysm.W, Ball):
            out.append(f"system.W: the file says {s.W.model_dump()}, the inputs record gives a ball of radius "
                       f"{sysm.W.radius}")
        else:
            out.append("system.W: differs from the polytope of the inputs record")
    st = doc.stats
    if "n_edges" in st and st["n_edges"] != len(doc.edges):
        out.append(f"stats.n_edges: says {st['n_edges']}, the file lists {len(doc.edges)} edges")
    if "n_cells" in st and st["n_cells"] != d.n_cells:
        out.append(f"stats.n_cells: says {st['n_cells']}, the workspace has {d.n_cells} cells")
    return out


def _z_source(rb: Rebuilt) -> str:
    f = rb.inputs.zshape.file if rb.inputs is not None else None
    return "" if f is None else f" from {f.resolved}"


def _compare_obstacles(doc: TransitionFile, d) -> list[str]:
    if len(doc.obstacles) != len(d.obstacles):
        return [f"obstacles: the file lists {len(doc.obstacles)}, the workspace has {len(d.obstacles)}"]
    out = []
    for k, (o, r) in enumerate(zip(doc.obstacles, d.obstacles)):
        if isinstance(r, Polytope):
            ok = o.kind == "polytope" and _same(Polytope.from_vertices(o.vertices).vertices, r.vertices)
        else:
            try:
                ok = o.kind == "wkt" and bool(shapely.equals(shapely.from_wkt(o.wkt), r))
            except shapely.errors.GEOSException:
                ok = False
        if not ok:
            out.append(f"obstacles[{k}]: differs from obstacle {k} of the workspace")
    return out


def check_sources(ts, doc: TransitionFile, arrays: dict, directory: Path) -> tuple[list[str], Rebuilt | None]:
    """The cheap part of verification: rebuild the problem from ``doc.inputs`` and compare.

    Returns
    -------
    findings : list of str (empty when every copied datum equals the rebuilt one)
    rebuilt : Rebuilt or None (None when the sources could not be rebuilt)
    """
    if doc.inputs is None:
        return ["inputs: the file has no inputs record, so the problem cannot be rebuilt from its sources"], None
    try:
        rb = rebuild(doc.inputs, Path(directory))
    except InputError as exc:
        return [f"inputs: cannot rebuild the problem from the recorded sources: {exc}"], None
    return _compare(doc, arrays, rb), rb
