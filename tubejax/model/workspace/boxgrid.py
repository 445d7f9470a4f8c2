"""n-D box grids (docs/math/problem-data.md), e.g. for a double integrator's state space.

The box ``[lower, upper]`` in ``R^n`` is cut into ``divisions[d]`` equal slabs along each axis
``d`` (``linspace`` edges, so shared faces have bit-identical coordinates); free cells are
numbered in C (row-major) order of their multi-index.

A label box names a region exactly (docs/reference/formats.md#n-d-box-grid): a free cell carries the
label only when inside the box, so a target is never reached by a cell that sticks out of it, and the
box itself is kept (``_cache[LABEL_REGIONS]``, read by :mod:`tubejax.analyses.spec`), so a set that
meets it even partly counts as possibly in it and an avoided region is never entered. A box that cuts
free cells without containing them gives a :class:`LabelCoverageWarning`.
"""

from __future__ import annotations

import numbers
import warnings
from typing import Mapping, Sequence

import numpy as np

from ...errors import InputError
from ..geometry import Polytope
from .decomposition import CellDecomposition

__all__ = ["BoxGridError", "LabelCoverageWarning", "box_grid", "LABEL_REGIONS"]

_MAX_CELLS = 1_000_000
#: Overlap (a length) at or below which a cell and an obstacle box only touch.
_TOUCH = 1e-9
#: Key of ``CellDecomposition._cache`` holding ``{label: (box Polytope,)}``, the labelled
#: regions exactly as given (module docstring).
LABEL_REGIONS = "label_regions"


class BoxGridError(InputError):
    """Bad box-grid arguments; the message names the argument and the value."""


class LabelCoverageWarning(UserWarning):
    """A label box cuts free cells it does not contain: they stay unlabelled (module docstring)."""


def _vector(value, arg: str, n: int | None = None) -> np.ndarray:
    try:
        v = np.atleast_1d(np.asarray(value, dtype=float))
    except (TypeError, ValueError, OverflowError):
        raise BoxGridError(f"{arg} must be a sequence of numbers, got {value!r}") from None
    if v.ndim != 1 or v.size == 0:
        raise BoxGridError(f"{arg} must be a non-empty 1-D sequence of numbers, got {value!r}")
    if n is not None and v.size != n:
        raise BoxGridError(f"{arg} must have {n} entries (one per dimension), got {v.size}: {value!r}")
    if not np.all(np.isfinite(v)):
        raise BoxGridError(f"{arg} must be finite, got {value!r}")
    return v


def _box(value, arg: str, n: int) -> tuple[np.ndarray, np.ndarray]:
    """An ``(lo, hi)`` pair or a box :class:`Polytope` as two arrays of shape ``(n,)``."""
    if isinstance(value, Polytope):
        lo, hi = value.bounding_box()
        if value.dim != n or value.n_vertices != 2 ** n:
            raise BoxGridError(f"{arg} must be an axis-aligned box in R^{n}, got {value!r}")
    else:
        if not isinstance(value, (Sequence, np.ndarray)) or len(value) != 2:
            raise BoxGridError(f"{arg} must be a (lower, upper) pair, got {value!r}")
        lo, hi = _vector(value[0], f"{arg} lower", n), _vector(value[1], f"{arg} upper", n)
    if np.any(hi <= lo):
        raise BoxGridError(f"{arg} needs lower < upper in every dimension, got {lo.tolist()} and {hi.tolist()}")
    return lo, hi


def _divisions(value, n: int) -> np.ndarray:
    vals = [value] * n if isinstance(value, numbers.Integral) else value
    try:
        items = list(vals)
    except TypeError:
        raise BoxGridError(f"divisions must be a positive integer per dimension, got {value!r}") from None
    if len(items) != n:
        raise BoxGridError(f"divisions must have {n} entries (one per dimension), got {len(items)}: {value!r}")
    for v in items:
        if isinstance(v, bool) or not isinstance(v, numbers.Integral) or v < 1:
            raise BoxGridError(f"divisions must be positive integers, got {value!r}")
    return np.array(items, dtype=int)


def box_grid(lower, upper, divisions, obstacles=(), labels: Mapping | None = None,
             name: str = "box grid") -> CellDecomposition:
    """A uniform box grid over ``[lower, upper]``, any dimension ``n``.

    Parameters
    ----------
    lower, upper : array_like, shape (n,)
        Corners of the gridded box, ``lower < upper`` elementwise.
    divisions : int or sequence of int, shape (n,)
        Number of cells along each axis (an int is used for every axis).
    obstacles : sequence of (lo, hi) pairs or box Polytopes
        Obstacle boxes; a cell whose interior meets one's interior is removed (touching is allowed).
    labels : mapping label -> (lo, hi), optional
        The closed region of ``str(label)``: free cells inside it (up to ``1e-9``) get the label, the
        box is recorded (module docstring). Each must contain a whole free cell; no cell two boxes.
    name : str
        The decomposition's name.

    Returns
    -------
    CellDecomposition
        ``N`` free cells (``vertices (2**n, n)``) in C order of their multi-index ``grid (N, n)``;
        ``domain`` the box ``[lower, upper]``; ``_cache[LABEL_REGIONS]`` the label boxes. A
        ``BoxGridError`` names any bad argument, or says no free cell is left.
    """
    lo = _vector(lower, "lower")
    n = lo.size
    hi = _vector(upper, "upper", n)
    if np.any(hi <= lo):
        raise BoxGridError(f"upper must exceed lower in every dimension, got lower={lo.tolist()}, "
                         f"upper={hi.tolist()}")
    div = _divisions(divisions, n)
    total = int(np.prod(div, dtype=float))
    if total > _MAX_CELLS:
        raise BoxGridError(f"divisions={div.tolist()} gives {total} cells, more than {_MAX_CELLS}")
    obs = [_box(o, f"obstacles[{k}]", n) for k, o in enumerate(obstacles)]
    edges = [np.linspace(lo[d], hi[d], div[d] + 1) for d in range(n)]
    idx = np.indices(tuple(div)).reshape(n, -1).T                       # (total, n), C order
    c_lo = np.stack([edges[d][idx[:, d]] for d in range(n)], axis=1)    # (total, n)
    c_hi = np.stack([edges[d][idx[:, d] + 1] for d in range(n)], axis=1)
    free = np.ones(total, dtype=bool)
    for o_lo, o_hi in obs:
        overlap = np.minimum(c_hi, o_hi) - np.maximum(c_lo, o_lo)       # (total, n)
        free &= ~np.all(overlap > _TOUCH, axis=1)
    if not free.any():
        raise BoxGridError(f"{name}: the obstacles cover every cell; no free cell is left")
    idx, c_lo, c_hi = idx[free], c_lo[free], c_hi[free]
    cell_labels, regions = _label_cells(labels or {}, n, idx, c_lo, c_hi, edges)
    cells = tuple(Polytope.box(a, b) for a, b in zip(c_lo, c_hi))
    obstacles_out = tuple(Polytope.box(a, b) for a, b in obs)
    return CellDecomposition(cells, tuple(cell_labels), obstacles_out, idx.astype(int), name,
                             domain=Polytope.box(lo, hi), _cache={LABEL_REGIONS: regions})


def _label_cells(labels: Mapping, n: int, idx, c_lo, c_hi, edges) -> tuple[list, dict]:
    """Cell labels (cells inside a label box) and the label boxes as ``{label: (Polytope,)}``."""
    cell_labels: list = [None] * len(idx)
    regions: dict = {}
    for label, box in labels.items():
        arg = f"labels[{label!r}]"
        l_lo, l_hi = _box(box, arg, n)
        inside = np.flatnonzero(np.all((c_lo >= l_lo - _TOUCH) & (c_hi <= l_hi + _TOUCH), axis=1))
        if inside.size == 0:
            lines = "; ".join(f"axis {d}: {_grid_lines(edges[d])}" for d in range(n))
            raise BoxGridError(f"{arg}: the box {l_lo.tolist()}..{l_hi.tolist()} contains no whole free "
                               "cell; a labelled region is visited in the free cells inside it, so it must "
                               f"contain at least one (grid lines {lines})")
        _warn_cut_cells(arg, l_lo, l_hi, inside, idx, c_lo, c_hi, edges)
        for k in inside:
            if cell_labels[k] is not None:
                raise BoxGridError(f"{arg}: cell {idx[k].tolist()} is already labelled {cell_labels[k]!r} "
                                   "(it lies inside both boxes; a cell carries one label)")
            cell_labels[k] = str(label)
        regions[str(label)] = regions.get(str(label), ()) + (Polytope.box(l_lo, l_hi),)   # 1 and '1' alike
    return cell_labels, regions


def _warn_cut_cells(arg: str, l_lo, l_hi, inside, idx, c_lo, c_hi, edges) -> None:
    """Warn about the free cells the label box covers in part (a share of their volume above 1e-9)."""
    overlap = np.prod(np.clip(np.minimum(c_hi, l_hi) - np.maximum(c_lo, l_lo), 0.0, None), axis=1)
    share = overlap / np.prod(c_hi - c_lo, axis=1)
    share[inside] = 0.0
    cut = np.flatnonzero(share > 1e-9)
    if cut.size == 0:
        return
    k = cut[np.argmax(share[cut])]
    lines = "; ".join(f"axis {d}: {_grid_lines(edges[d])}" for d in range(len(l_lo)))
    warnings.warn(LabelCoverageWarning(
        f"{arg}: the box {l_lo.tolist()}..{l_hi.tolist()} covers {cut.size} free cell{'s' if cut.size > 1 else ''} "
        f"only in part (e.g. cell {idx[k].tolist()}, {100 * share[k]:.0f} % of it): "
        f"{'they carry' if cut.size > 1 else 'it carries'} no label, so a plan never visits the region there "
        f"(avoiding it still keeps out of the whole box); align the box with the grid lines ({lines})"),
        stacklevel=4)


def _grid_lines(e: np.ndarray) -> str:
    """The grid lines of one axis, e.g. ``0, 1, ..., 5`` (``e`` from ``linspace``)."""
    pts = [f"{v:g}" for v in e]
    return ", ".join(pts) if len(pts) <= 6 else f"{pts[0]}, {pts[1]}, ..., {pts[-1]}"
