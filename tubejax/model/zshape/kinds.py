"""Shapes of the tube cross-section ``Z`` and their pairing with cell vertices.

``Z = co{z_1 .. z_{n_i}}`` has as many vertices as the source cell ``P_i`` and 0 in its interior;
``z_k`` pairs with ``v_{i,k}`` in canonical order (docs/math/tube-lp.md#vertex-pairing). A 2-D ``Z``
with ``r n_i`` vertices (``chamfer``) pairs with the cell's *generating points*
(:func:`source_points`), whose hull is still ``P_i``, so Lemma 1 holds
(docs/howto/learned-z.md#more-vertices-than-the-cell-chamfer). The fixed kinds are :data:`ZKINDS`
(docs/reference/configuration.md#zshape); all but ``cell`` lie on a dyadic grid
(:func:`on_z_grid`), so one rounded polytope serves the float and the exact paths.
"""

from __future__ import annotations

import contextvars
import math
import weakref
from typing import Callable, NamedTuple

import numpy as np

from ...errors import ZShapeError
from ..geometry import Polytope

__all__ = ["ZKind", "ZKINDS", "ZSHAPES", "LEARNED_ZSHAPES", "CHAMFER_CUT", "FIXED_KINDS", "make_z", "z_kind_problem",
           "z_vertex_count_problem", "on_z_grid", "Z_GRID_BITS", "source_points", "cross_sections", "start_kinds",
           "fallback_kind"]

#: The fraction of each edge that ``chamfer`` cuts off at both of its ends (a box's corners lose
#: 0.3 of its half-width 1): inside the range where the 1-norm maps' two-cell moves are certified.
CHAMFER_CUT = 0.15
#: Learned kinds (:mod:`tubejax.analyses.zshape`): their ``Z`` comes from a learned-Z table.
LEARNED_ZSHAPES = ("learned", "learned_pair")


class ZKind(NamedTuple):
    """A fixed kind of cross-section ``Z``, chosen by name (``zshape.kind``).

    Attributes
    ----------
    name : str
    build : callable
        ``build(V, n_v, scale) -> Polytope``: ``Z`` for a cell whose vertices about their mean are
        ``V (n_v, n)``, in the canonical order that pairs them with :func:`source_points`.
    dims : tuple of int or None
        The state dimensions it exists in (``None``: any).
    fits : callable
        ``fits(n, n_v) -> str or None``: why it does not fit a cell of ``n_v`` vertices in ``R^n``.
    per_vertex : int
        ``Z``'s vertex count over the cell's (2 for ``chamfer``: vertices and edge points); a ``Z`` with
        more vertices than the cell is for methods with tubes only (:func:`z_kind_problem`).
    learn_rank : int
        Order among the starts of learning (:data:`FIXED_KINDS`; ties of ``best`` go to the lower).
    rounded : bool
        Whether its vertices go through :func:`on_z_grid` (not ``cell``: rounding would change its shape).
    """

    name: str
    build: Callable
    dims: tuple | None
    fits: Callable
    per_vertex: int = 1
    learn_rank: int = 0
    rounded: bool = True


#: The fixed kinds' vertices are multiples of ``2^(e - Z_GRID_BITS)``, ``2^e <= scale < 2^(e+1)``
#: (:func:`on_z_grid`): dyadic rationals with short denominators, the same numbers in float64 and
#: in exact arithmetic, so that exact decisions on them stay fast.
Z_GRID_BITS = 10


def on_z_grid(Z: Polytope, scale: float) -> Polytope:
    """``Z`` with its vertices rounded to the grid of :data:`Z_GRID_BITS` (``Z`` itself when on it).

    Any ``Z`` with 0 in its interior is a valid cross-section (Lemma 1 needs nothing else), so the
    rounded polytope is used everywhere (float LPs, exact checks, proofs, files, ``verify``) and no
    soundness hangs on the rounding's direction; unrounded ``cos``/``sin`` floats would be rationals
    with denominators near ``2^53``, slow in the exact decisions of zero-margin pairs.
    """
    step = 2.0 ** (math.floor(math.log2(scale)) - Z_GRID_BITS)
    V = np.round(Z.vertices / step) * step
    return Z if np.array_equal(V, Z.vertices) else Polytope.from_vertices(V)


def _centred_unit(V):
    """``V`` over the power of two at or above its largest norm (that norm in ``(1/2, 1]``): the
    cell's exact shape, with no rounding (a norm would be irrational)."""
    return V / 2.0 ** math.ceil(math.log2(np.max(np.linalg.norm(V, axis=1))))


def _points(f):
    """A ``build`` from a function of ``(V, n_v)`` giving the vertices at scale 1."""
    return lambda V, nv, scale: Polytope.from_vertices(scale * np.asarray(f(V, nv), dtype=float))


def _chamfer(V, nv):
    V = _centred_unit(V)
    E = np.roll(V, -1, axis=0) - V                                   # edge k: V[k] -> V[k+1]
    return np.stack([V + CHAMFER_CUT * E, V + (1 - CHAMFER_CUT) * E], axis=1).reshape(-1, 2)


def _regular(V, nv):
    ang = -0.75 * np.pi + 2 * np.pi * np.arange(nv) / nv
    return np.stack([np.cos(ang), np.sin(ang)], axis=1)


def _box(V, nv, scale):
    n = V.shape[1]
    return Polytope.box(-scale * np.ones(n), scale * np.ones(n))


def _needs(count, what):
    return lambda n, nv: None if nv == count(n) else f"needs cells with {what(n)} vertices, got a cell with {nv}"


#: The fixed kinds by name. A new kind is one entry here (and its ``conf/zshape/<name>.yaml``).
ZKINDS = {k.name: k for k in (
    ZKind("box", _box, None, _needs(lambda n: 2 ** n, lambda n: f"2^n = {2 ** n}"), learn_rank=0),
    ZKind("diamond", _points(lambda V, nv: [[0.0, -1], [1, 0], [0, 1], [-1, 0]]), (2,),
          _needs(lambda n: 4, lambda n: "4"), learn_rank=2),
    ZKind("cell", _points(lambda V, nv: _centred_unit(V)), None, lambda n, nv: None, learn_rank=1, rounded=False),
    ZKind("regular", _points(_regular), (2,), lambda n, nv: None, learn_rank=3),
    ZKind("chamfer", _points(_chamfer), (2,), lambda n, nv: None, per_vertex=2, learn_rank=4),
)}
#: Their names, in registry order.
ZSHAPES = tuple(ZKINDS)
#: The fixed kinds ``init='best'`` starts learning from (those that fit the cells), in this order of
#: preference (``chamfer``, 2-D: ``Z`` with twice the cell's vertices, learned as its own family).
FIXED_KINDS = tuple(sorted(ZKINDS, key=lambda k: ZKINDS[k].learn_rank))


def z_vertex_count_problem(n_z: int, n_v: int, n: int) -> str | None:
    """Why a ``Z`` with ``n_z`` vertices cannot pair with a source cell of ``n_v`` vertices in ``R^n``
    (``None``: it can): the one rule every reader of a ``Z`` applies (as many, or in 2-D a multiple)."""
    if n_z == n_v or (n == 2 and n_v >= 3 and n_z > 0 and n_z % n_v == 0):
        return None
    return f"Z has {n_z} vertices, the source cell {n_v} in R^{n}: expected {n_v}, or in 2-D a multiple of it"


def z_kind_problem(kind: str, n: int, tubes: bool = True) -> str | None:
    """Why the fixed kind ``kind`` cannot serve an ``n``-D state (and a method without ``tubes``), or ``None``."""
    k = ZKINDS.get(kind)
    if k is None:
        return f"unknown zshape {kind!r}; expected one of {ZSHAPES + LEARNED_ZSHAPES}"
    if k.dims is not None and n not in k.dims:
        return f"{kind!r} is {'/'.join(map(str, k.dims))}-D only"
    if not tubes and k.per_vertex > 1:
        return f"{kind!r} has {k.per_vertex} times the cell's vertices, for a method with tubes only"
    return None


def make_z(kind: str, cell: Polytope, scale: float = 1.0, table=None) -> Polytope:
    """The cross-section ``Z`` for tubes leaving ``cell``.

    Parameters
    ----------
    kind : str
        A fixed kind of :data:`ZKINDS` or a learned one (:data:`LEARNED_ZSHAPES`).
    cell : Polytope
        The source cell ``P_i`` with ``n_i`` vertices in ``R^n``.
    scale : float
        Size ``s > 0``; with ``eps_min = 0`` only the shape matters (``epsilon`` scales it).
    table : ZTable, optional
        The learned ``Z`` for ``kind='learned'`` (default: the active one, ``use_z_table``).

    Returns
    -------
    Polytope
        ``Z`` with ``per_vertex * n_i`` vertices, canonical order; a ``ValueError`` says why a kind is
        unknown or does not fit the cell.
    """
    if scale <= 0:
        raise ValueError(f"zshape.scale must be > 0, got {scale}")
    n, nv = cell.dim, cell.n_vertices
    if kind in LEARNED_ZSHAPES:
        return _learned_z(kind, cell, scale, table)
    why = z_kind_problem(kind, n)
    k = ZKINDS.get(kind)
    if why is None:
        why = k.fits(n, nv)
        why = None if why is None else f"zshape {kind!r} {why}"
    elif k is not None:
        why = f"zshape {why}, got n={n}"
    if why is not None:
        raise ValueError(why)
    Z = k.build(cell.vertices - cell.vertices.mean(axis=0), nv, scale)
    if k.rounded:
        Z = on_z_grid(Z, scale)
    if Z.n_vertices != k.per_vertex * nv:
        raise ValueError(f"zshape {kind!r} gave {Z.n_vertices} vertices, expected {k.per_vertex * nv}")
    return Z


_POINTS: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()     # cell -> {n_z: its generating points}


def source_points(cell: Polytope, n_z: int) -> Polytope:
    """``P_i`` with the points that ``Z``'s ``n_z`` vertices pair with as its vertices ``(n_z, n)``.

    ``n_z = n_i``: ``cell`` itself. 2-D, ``n_z = r n_i``: the cell's vertices (bit for bit) with
    ``r - 1`` evenly spaced points on each edge, counter-clockwise; ``H``, ``h`` are the cell's.
    Their hull is ``P_i``, so any tube from them is a tube from ``P_i``; the edge points need not
    be exact (each only adds constraints). Memoised; a ``ValueError`` for any other ``n_z``.
    """
    nv = cell.n_vertices
    if n_z == nv:
        return cell
    hit = _POINTS.get(cell, {}).get(n_z)
    if hit is not None:
        return hit
    why = z_vertex_count_problem(n_z, nv, cell.dim)
    if why is not None:
        raise ValueError(why)
    r = n_z // nv
    V = cell.vertices
    W = np.roll(V, -1, axis=0)
    s = np.arange(r, dtype=float)[None, :, None]
    pts = (((r - s) * V[:, None, :] + s * W[:, None, :]) / r).reshape(-1, 2)     # s = 0: the vertices, bit for bit
    P = Polytope(pts, cell.H, cell.h)
    _POINTS.setdefault(cell, {})[n_z] = P
    return P


#: The learned ``Z`` table ``make_z('learned', ...)`` reads when none is passed (``use_z_table``; a
#: context variable: threads and tasks each see their own).
ACTIVE_Z_TABLE: contextvars.ContextVar = contextvars.ContextVar("tubejax_z_table", default=None)


def _learned_z(kind: str, cell: Polytope, scale: float, table) -> Polytope:
    """``make_z`` for the learned kinds (a ``ValueError`` names what is missing)."""
    if kind == "learned_pair":
        raise ValueError("zshape 'learned_pair' gives one Z per ordered pair, not per cell: the "
                         "abstraction must take it from ZTable.z_for_pair(i, j)")
    table = ACTIVE_Z_TABLE.get() if table is None else table
    if table is None:
        raise ValueError("zshape 'learned' needs a learned Z table (tubejax.model.zshape.z_table.use_z_table, "
                         "or make_z(..., table=...))")
    try:
        return table.z_for_cell(cell, scale)
    except ZShapeError as exc:
        raise ValueError(str(exc)) from None


def cross_sections(decomp, zshape: str, z_scale: float) -> tuple:
    """``Z`` of each cell (:func:`make_z`), built once per cell shape (vertices about their mean
    equal bit for bit), so the same as calling ``make_z`` per cell."""
    out, seen = [], {}
    for c in decomp.cells:
        key = (c.vertices - c.vertices.mean(axis=0)).tobytes() + bytes(str(c.vertices.shape), "ascii")
        if key not in seen:
            seen[key] = make_z(zshape, c, z_scale)
        out.append(seen[key])
    return tuple(out)


def start_kinds(init: str, cell) -> list:
    """The fixed kinds (non-empty list of str) learning starts from for source cells shaped like
    ``cell``: for ``init='best'`` every kind of :data:`FIXED_KINDS` that fits, else ``[init]`` (a
    ``ValueError`` naming ``zshape.init`` when it does not fit)."""
    if init == "best":
        kinds = []
        for k in FIXED_KINDS:
            try:
                make_z(k, cell)
            except ValueError:
                continue
            kinds.append(k)
        return kinds
    try:
        make_z(init, cell)
    except ValueError as exc:
        raise ValueError(f"zshape.init: {init!r} does not fit the source cells with {cell.n_vertices} "
                         f"vertices ({exc}); cell fits any cell") from None
    return [init]


def fallback_kind(init: str, cell) -> str:
    """The fixed kind of a cell without a learned ``Z``: ``init``, or for ``'best'`` the first of
    :data:`FIXED_KINDS` that fits ``cell`` (such a cell is the source of no candidate pair, so its
    ``Z`` decides no edge)."""
    return start_kinds(init, cell)[0] if init == "best" else init
