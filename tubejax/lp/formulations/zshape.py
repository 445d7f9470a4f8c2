"""Shapes of the tube cross-section ``Z`` and their pairing with cell vertices.

``Z = co{z_1 .. z_{n_i}}`` must have as many vertices as the source cell
``P_i``, with 0 in its interior. Vertex ``z_k`` is paired with vertex
``v_{i,k}`` after both are put in canonical order
(:func:`tubejax.geometry.canonical_vertex_order`: counter-clockwise from the
bottom-left vertex in 2-D, lexicographic with the last coordinate most
significant otherwise). For a square cell and the box ``Z`` this pairs each
corner of the cell with the same corner of ``Z``.

**More vertices than the cell** (``chamfer``, beyond docs/math/tube-lp.md#vertex-pairing): a 2-D ``Z`` with
``r n_i`` vertices pairs with the cell's *generating points* (:func:`source_points`): its
vertices with ``r - 1`` evenly spaced points on each edge, counter-clockwise from the canonical
first vertex. Their hull is still ``P_i``, so Lemma 1 holds as before (``x in P_i`` is a convex
combination of them); the extra points only add rows C4 at ``l = 0``. Every problem built by
:func:`tubejax.problem.pair_problems` (and so every solver, check, proof, ``verify`` and the
controller) uses these points as ``q_k(0)``. The tube class grows with the vertex count: on the
1-norm maps a 4-vertex ``Z`` cannot certify exact2d's two-cell moves (``scripts/learned_z_limit.py``),
an 8-vertex one can.

Kinds
-----
``box``       ``[-s, s]^n`` (cells with ``2^n`` vertices).
``diamond``   the 2-D cross-polytope ``co{(±s,0),(0,±s)}`` (4-vertex cells).
``cell``      the source cell itself, centred on its vertex mean and scaled so
              that its largest vertex norm is ``s`` (any cell).
``regular``   the regular ``n_i``-gon of circumradius ``s`` with a vertex at
              angle ``-3π/4`` rotated so its canonical order starts bottom-left
              (2-D, any vertex count).
``chamfer``   ``cell`` with every corner cut off at :data:`CHAMFER_CUT` of its two edges:
              ``2 n_i`` vertices (2-D, any cell), paired with :func:`source_points`.
``learned``   the ``Z`` learned for the cell's shape (:mod:`tubejax.zshape`), read from a
              :class:`~tubejax.zshape.table.ZTable`: the ``table`` argument, else the one made
              active by :func:`~tubejax.zshape.table.use_z_table`; times ``s``.
``learned_pair`` one ``Z`` per ordered pair: not a per-cell kind (``ZTable.z_for_pair``; runs
              give it to the abstraction as a :class:`~tubejax.zassignment.ZAssignment`,
              :func:`tubejax.zshape.build.assignment_from_table`).
"""

from __future__ import annotations

import weakref

import numpy as np

from ...geometry import Polytope

__all__ = ["ZSHAPES", "LEARNED_ZSHAPES", "CHAMFER_CUT", "make_z", "source_points", "cross_sections"]

ZSHAPES = ("box", "diamond", "cell", "regular", "chamfer")
#: The fraction of each edge that ``chamfer`` cuts off at both of its ends (a box's corners lose
#: 0.3 of its half-width 1): inside the range where the 1-norm maps' two-cell moves are certified.
CHAMFER_CUT = 0.15
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
        ``Z`` with exactly ``n_i`` vertices (``chamfer``: ``2 n_i``), in canonical order.
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
    elif kind == "chamfer":
        if n != 2:
            raise ValueError(f"zshape 'chamfer' is 2-D only, got n={n}")
        V = cell.vertices - cell.vertices.mean(axis=0)
        V = V / np.max(np.linalg.norm(V, axis=1))
        E = np.roll(V, -1, axis=0) - V                                   # edge k: V[k] -> V[k+1]
        cut = np.stack([V + CHAMFER_CUT * E, V + (1 - CHAMFER_CUT) * E], axis=1).reshape(-1, 2)
        Z = Polytope.from_vertices(scale * cut)
        nv = 2 * nv
    elif kind == "regular":
        if n != 2:
            raise ValueError(f"zshape 'regular' is 2-D only, got n={n}")
        ang = -0.75 * np.pi + 2 * np.pi * np.arange(nv) / nv
        Z = Polytope.from_vertices(scale * np.stack([np.cos(ang), np.sin(ang)], axis=1))
    else:
        raise ValueError(f"unknown zshape {kind!r}; expected one of {ZSHAPES + LEARNED_ZSHAPES}")
    if Z.n_vertices != nv:
        raise ValueError(f"zshape {kind!r} gave {Z.n_vertices} vertices, expected {nv}")
    return Z


_POINTS: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()     # cell -> {n_z: its generating points}


def source_points(cell: Polytope, n_z: int) -> Polytope:
    """``P_i`` with the points that ``Z``'s ``n_z`` vertices pair with as its vertex list.

    ``n_z = n_i``: ``cell`` itself. 2-D, ``n_z = r n_i``: the cell's vertices with ``r - 1``
    evenly spaced points on each edge in between (``((r - s) v_k + s v_{k+1}) / r``,
    ``s = 1 .. r-1``; for ``r = 2`` the midpoints, rounded), counter-clockwise from the canonical
    first vertex, the vertices themselves bit for bit; ``H`` and ``h`` are the cell's. Their hull
    is ``P_i`` (the vertices are among them), so any tube from them is a tube from ``P_i``; the
    other points need not be exact (each one only adds constraints). Memoised.

    Parameters
    ----------
    cell : Polytope
        A cell with ``n_i`` vertices in canonical order.
    n_z : int
        ``Z``'s vertex count.

    Returns
    -------
    Polytope
        ``vertices`` of shape ``(n_z, n)``.

    Raises
    ------
    ValueError
        ``n_z`` is not ``n_i``, or (2-D) a multiple of it.
    """
    nv = cell.n_vertices
    if n_z == nv:
        return cell
    hit = _POINTS.get(cell, {}).get(n_z)
    if hit is not None:
        return hit
    if cell.dim != 2 or n_z % nv:
        raise ValueError(f"Z has {n_z} vertices, the source cell {nv}: expected {nv}, or in 2-D a multiple of it")
    r = n_z // nv
    V = cell.vertices
    W = np.roll(V, -1, axis=0)
    s = np.arange(r, dtype=float)[None, :, None]
    pts = (((r - s) * V[:, None, :] + s * W[:, None, :]) / r).reshape(-1, 2)     # s = 0: the vertices, bit for bit
    P = Polytope(pts, cell.H, cell.h)
    _POINTS.setdefault(cell, {})[n_z] = P
    return P


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


def cross_sections(decomp, zshape: str, z_scale: float) -> tuple:
    """``Z`` of each cell (:func:`~tubejax.lp.formulations.zshape.make_z`), built once per cell shape.

    Two cells share one ``Z`` object when their vertices about the vertex mean are equal bit
    for bit, so the result is the same as calling ``make_z`` per cell.
    """
    out, seen = [], {}
    for c in decomp.cells:
        key = (c.vertices - c.vertices.mean(axis=0)).tobytes() + bytes(str(c.vertices.shape), "ascii")
        if key not in seen:
            seen[key] = make_z(zshape, c, z_scale)
        out.append(seen[key])
    return tuple(out)
