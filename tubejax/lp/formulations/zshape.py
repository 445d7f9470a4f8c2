"""Shapes of the tube cross-section ``Z`` and their pairing with cell vertices.

``Z = co{z_1 .. z_{n_i}}`` must have as many vertices as the source cell
``P_i``, with 0 in its interior. Vertex ``z_k`` is paired with vertex
``v_{i,k}`` after both are put in canonical order
(:func:`tubejax.geometry.canonical_vertex_order`: counter-clockwise from the
bottom-left vertex in 2-D, lexicographic with the last coordinate most
significant otherwise). For a square cell and the box ``Z`` this pairs each
corner of the cell with the same corner of ``Z``.

Kinds
-----
``box``       ``[-s, s]^n`` (cells with ``2^n`` vertices).
``diamond``   the 2-D cross-polytope ``co{(±s,0),(0,±s)}`` (4-vertex cells).
``cell``      the source cell itself, centred on its vertex mean and scaled so
              that its largest vertex norm is ``s`` (any cell).
``regular``   the regular ``n_i``-gon of circumradius ``s`` with a vertex at
              angle ``-3π/4`` rotated so its canonical order starts bottom-left
              (2-D, any vertex count).
``learned``   the ``Z`` learned for the cell's shape (:mod:`tubejax.zshape`), read from a
              :class:`~tubejax.zshape.table.ZTable`: the ``table`` argument, else the one made
              active by :func:`~tubejax.zshape.table.use_z_table`; times ``s``.
``learned_pair`` one ``Z`` per ordered pair: not a per-cell kind (``ZTable.z_for_pair``; runs
              give it to the abstraction as a :class:`~tubejax.zassignment.ZAssignment`,
              :func:`tubejax.zshape.build.assignment_from_table`).
"""

from __future__ import annotations

import numpy as np

from ...geometry import Polytope

__all__ = ["ZSHAPES", "LEARNED_ZSHAPES", "make_z"]

ZSHAPES = ("box", "diamond", "cell", "regular")
#: Learned kinds (:mod:`tubejax.zshape`): their ``Z`` comes from a learned-Z table.
LEARNED_ZSHAPES = ("learned", "learned_pair")


def make_z(kind: str, cell: Polytope, scale: float = 1.0, table=None) -> Polytope:
    """The cross-section ``Z`` for tubes leaving ``cell``.

    Parameters
    ----------
    kind : {'box', 'diamond', 'cell', 'regular', 'learned'}
    cell : Polytope
        The source cell ``P_i`` with ``n_i`` vertices in ``R^n``.
    scale : float
        Size ``s > 0``; only the shape matters for feasibility (``epsilon``
        scales it), so the default 1 is fine.
    table : ZTable, optional
        The learned ``Z`` for ``kind='learned'`` (default: the active one,
        :func:`tubejax.zshape.table.use_z_table`).

    Returns
    -------
    Polytope
        ``Z`` with exactly ``n_i`` vertices, in canonical order.
    """
    if scale <= 0:
        raise ValueError(f"zshape.scale must be > 0, got {scale}")
    n, nv = cell.dim, cell.n_vertices
    if kind in LEARNED_ZSHAPES:
        return _learned_z(kind, cell, scale, table)
    if kind == "box":
        if nv != 2 ** n:
            raise ValueError(f"zshape 'box' needs cells with 2^n = {2 ** n} vertices, got a cell with {nv}")
        Z = Polytope.box(-scale * np.ones(n), scale * np.ones(n))
    elif kind == "diamond":
        if n != 2 or nv != 4:
            raise ValueError(f"zshape 'diamond' needs 2-D cells with 4 vertices, got n={n}, {nv} vertices")
        Z = Polytope.from_vertices(scale * np.array([[0.0, -1], [1, 0], [0, 1], [-1, 0]]))
    elif kind == "cell":
        V = cell.vertices - cell.vertices.mean(axis=0)
        Z = Polytope.from_vertices(scale * V / np.max(np.linalg.norm(V, axis=1)))
    elif kind == "regular":
        if n != 2:
            raise ValueError(f"zshape 'regular' is 2-D only, got n={n}")
        ang = -0.75 * np.pi + 2 * np.pi * np.arange(nv) / nv
        Z = Polytope.from_vertices(scale * np.stack([np.cos(ang), np.sin(ang)], axis=1))
    else:
        raise ValueError(f"unknown zshape {kind!r}; expected one of {ZSHAPES + LEARNED_ZSHAPES}")
    if Z.n_vertices != nv:
        raise ValueError(f"zshape {kind!r} gave {Z.n_vertices} vertices for a cell with {nv}")
    return Z


def _learned_z(kind: str, cell: Polytope, scale: float, table) -> Polytope:
    """``make_z`` for the learned kinds (a ``ValueError`` names what is missing)."""
    from ...zshape.params import ZShapeError
    from ...zshape.table import active_z_table

    if kind == "learned_pair":
        raise ValueError("zshape 'learned_pair' gives one Z per ordered pair, not per cell: the "
                         "abstraction must take it from ZTable.z_for_pair(i, j)")
    table = active_z_table() if table is None else table
    if table is None:
        raise ValueError("zshape 'learned' needs a learned Z table (tubejax.zshape.table.use_z_table, "
                         "or make_z(..., table=...))")
    try:
        return table.z_for_cell(cell, scale)
    except ZShapeError as exc:
        raise ValueError(str(exc)) from None
