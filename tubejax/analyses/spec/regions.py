"""Labelled regions as convex pieces: where a proposition ``l<label>`` holds.

``l<label>`` holds at a point of the *closed region* of that label, the union of
its pieces:

* a decomposition that records the regions the user named (an n-D box grid: the
  label boxes given to :func:`tubejax.model.workspace.box_grid`, stored under
  :data:`~tubejax.model.workspace.boxgrid.LABEL_REGIONS`) -- those boxes exactly,
  whatever the cells;
* otherwise the cells carrying the label (grid maps, polygon workspaces, whose
  regions are made of whole cells).

A cell's own label (``decomp.labels``) always marks a cell that lies inside its
region, so a state in it satisfies the proposition (a visit). The planners test
"can meet" against the pieces (exact polytope intersection) and "surely in" by
containment in a piece, so a box that cuts through cells is neither rounded away
(never crossed when avoided) nor rounded up (never visited by a cell that sticks
out of it).
"""

from __future__ import annotations

import numpy as np

from ...model.workspace.boxgrid import LABEL_REGIONS

__all__ = ["region_pieces", "inside_mask", "INSIDE_TOL"]

#: A cell whose vertices are within this (unit-row) violation of a piece lies inside it
#: (the box grid's own tolerance for grid lines that are meant to coincide).
INSIDE_TOL = 1e-9


def region_pieces(decomp, labels) -> list:
    """``[(bit, Polytope), ...]``: the convex pieces of the regions of ``labels`` (module docstring).

    Parameters
    ----------
    decomp : CellDecomposition
    labels : sequence of str
        Region label of each proposition bit.

    Returns
    -------
    list of (int, Polytope)
        Bit of the label and one closed convex piece of its region; a label whose
        region has several pieces appears several times.
    """
    bit = {str(l): b for b, l in enumerate(labels)}
    regions = decomp._cache.get(LABEL_REGIONS)
    if regions is not None:
        return [(bit[str(l)], P) for l, pieces in regions.items() if str(l) in bit for P in pieces]
    return [(bit[str(l)], decomp.cells[c]) for c, l in enumerate(decomp.labels)
            if l is not None and str(l) in bit]


def inside_mask(pieces, P) -> int:
    """Bit mask of the pieces that contain the closed polytope ``P`` (within :data:`INSIDE_TOL`)."""
    out = 0
    for b, Q in pieces:
        if float(np.max(Q.violation(P.vertices))) <= INSIDE_TOL:
            out |= 1 << b
    return out
