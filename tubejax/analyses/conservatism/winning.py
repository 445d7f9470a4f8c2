"""The winning set of a transition system: the cells with a path of usable edges to a target cell
(docs/math/limit.md#winning-sets). Every state in it lies in the reach-avoid limit of :mod:`.limit`,
which :func:`cells_outside` checks cell by cell.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import shapely
from scipy.sparse.csgraph import breadth_first_order

from ...model.geometry.obstacles import TOUCH_TOL
from ...lp.evidence.registry import tube_methods
from ..spec.labelling import edge_letters
from .limit import labelled_cells
from .polygons import polygonal

__all__ = ["WinningSet", "winning_set", "allowed_edges", "cells_outside"]


@dataclass(frozen=True, eq=False)
class WinningSet:
    """The winning cells of one transition system for one target.

    Attributes
    ----------
    cells : tuple of int
        Winning cell ids (those of the system's ``transitions.json``), ascending.
    area : float
        Area of their union.
    geometry : shapely (Multi)Polygon
        Their union.
    method : str
        The transition system's method.
    target : str
    avoid : tuple of str
    n_edges_used : int
        Edges allowed with the avoided labels (all edges without any).
    """

    cells: tuple
    area: float
    geometry: object
    method: str
    target: str
    avoid: tuple = ()
    n_edges_used: int = 0

    def summary(self, limit_area: float | None = None) -> dict:
        """``{"winning_area", "winning_cells", "fraction_of_limit"}`` (``None`` without a limit area)."""
        frac = None if not limit_area else float(self.area) / float(limit_area)
        return {"winning_area": float(self.area), "winning_cells": [int(c) for c in self.cells],
                "fraction_of_limit": frac}


def allowed_edges(ts, avoid) -> np.ndarray:
    """``(E,)`` bool: the edges usable with the avoided labels, none into an avoided cell. The tube method uses no
    edge whose tube may meet an avoided region's closure (:func:`~tubejax.analyses.spec.labelling.edge_letters`),
    the others none whose safe set (``P_ij``, or ``P_i`` in the obstacle case) meets its interior
    (docs/math/limit.md#winning-sets)."""
    d = ts.decomposition
    avoid = [str(a) for a in avoid]
    ok = np.ones(ts.n_edges, bool)
    if not avoid or ts.n_edges == 0:
        return ok
    bad_cells = {c for a in avoid for c in d.cells_with_label(a)}
    src = np.array([e.src for e in ts.edges], int)
    dst = np.array([e.dst for e in ts.edges], int)
    ok &= ~np.isin(src, list(bad_cells)) & ~np.isin(dst, list(bad_cells))
    if ts.method in tube_methods():
        ok &= ~(edge_letters(ts, avoid).may != 0).any(axis=1)
        return ok
    region = shapely.union_all([shapely.Polygon(d.cells[c].vertices) for c in sorted(bad_cells)])
    for k in np.flatnonzero(ok):
        i, j = int(src[k]), int(dst[k])
        safe = d.cells[i] if d.obstacle_case(i, j) else d.pair_hull(i, j)
        if float(shapely.intersection(shapely.Polygon(safe.vertices), region).area) > TOUCH_TOL:
            ok[k] = False
    return ok


def winning_set(ts, target, avoid=()) -> WinningSet:
    """The cells of ``ts`` with a path of :func:`allowed_edges` to a cell labelled ``target``; a cell of an
    avoided label is never winning.

    Parameters
    ----------
    ts : TransitionSystem
        2-D (the union is a planar area).
    target : str
        A label carried by some cell.
    avoid : sequence of str
        Labels whose regions no used edge may enter.

    Returns
    -------
    WinningSet

    Raises
    ------
    ValueError
        Not 2-D, an unknown label, or the target among the avoided labels.
    """
    d = ts.decomposition
    if d.dim != 2:
        raise ValueError(f"ts: winning sets are areas of 2-D cells, got a {d.dim}-D decomposition")
    target, avoid, goals, _ = labelled_cells(d, target, avoid)
    ok = allowed_edges(ts, avoid)
    N = ts.n_cells
    src = np.array([ts.edges[k].src for k in np.flatnonzero(ok)], int)
    dst = np.array([ts.edges[k].dst for k in np.flatnonzero(ok)], int)
    # reversed edges dst -> src, and a virtual node N -> every target cell
    rows = np.concatenate([dst, np.full(len(goals), N)])
    cols = np.concatenate([src, goals])
    G = sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(N + 1, N + 1))
    order = breadth_first_order(G, N, directed=True, return_predecessors=False)
    cells = tuple(sorted(int(c) for c in order if c != N))
    geom = polygonal(shapely.union_all([shapely.Polygon(d.cells[c].vertices) for c in cells]))
    return WinningSet(cells, float(geom.area), geom, str(ts.method), target, avoid, int(ok.sum()))


def cells_outside(win: WinningSet, limit_geometry, decomp, rel_tol: float = 1e-9) -> list:
    """``[(cell, area outside), ...]``: the winning cells of which more than ``rel_tol`` of the area
    lies outside ``limit_geometry`` (each one is a bug in the limit or in the method)."""
    out = []
    for c in win.cells:
        P = shapely.Polygon(decomp.cells[c].vertices)
        gap = float(shapely.difference(P, limit_geometry).area)
        if gap > rel_tol * float(P.area):
            out.append((int(c), gap))
    return out
