"""What the matrix-free margin-form operators share: the tube LP's (:mod:`.tube_operator`) and the
open loop's (:mod:`.openloop_operator`).

An operator is a :class:`MarginOperator` record of functions on pytrees (NamedTuples of arrays, batch
axis ``B`` LAST, ``t`` the primal's last field). What is not an LP's own is here: the static
:class:`OperatorShape`, flat vectors (:func:`pack`, :func:`unpack`), box bounds
(:meth:`MarginOperator.bounds`), the padded horizon and its masks (:func:`padded_horizon`), and the
hard rows of an input family (:class:`InputBlock`), read off the dense rows (:func:`input_block`) the
same way for both LPs. Nothing here imports JAX: the helper processes that re-check evidence read it.
"""

from __future__ import annotations

from typing import Callable, NamedTuple, Sequence

import numpy as np

from .row_families import FamilyDataError, active
from .tube_families import TUBE_FAMILIES, InputIn, system_regions

__all__ = ["OperatorShape", "MarginOperator", "InputBlock", "tree_leaves", "sum_left", "pack", "unpack",
           "padded_horizon", "over_batch", "hard_families", "input_facets", "input_block", "batched_input_block",
           "input_rows_matvec", "input_rows_rhs"]


class OperatorShape(NamedTuple):
    """Static shape of a group of one matrix-free operator (hashable: it keys the compiled executables),
    the tube's and the open loop's; each leaves the other's fields at their defaults.

    Attributes
    ----------
    L, n, m, n_v : int      padded horizon, state and input dimensions, the source cell's vertex count
    form : {'margin', 'radius'}
    f_u : int               row count of the hard input family at one step and vertex (0: none, a
                            box ``U`` is variable bounds)
    f_z : int               tube: facets of ``Z``
    f_v, v_steps : tuple    tube: the ``VertexIn`` families' (padded) facet counts and step kinds, in
                            declaration order
    f_s, f_t : int          open loop: (padded) facet counts of ``S`` and of the target
    ab : tuple of float     open loop: ``A^s B`` for ``s = 0 .. L-1`` flattened (shape ``(L, n, m)``),
                            the operator's shared data, a compile-time constant
    """

    L: int
    n: int
    m: int
    n_v: int
    form: str = "margin"
    f_u: int = 0
    f_z: int = 0
    f_v: tuple = ()
    v_steps: tuple = ()
    f_s: int = 0
    f_t: int = 0
    ab: tuple = ()


class MarginOperator(NamedTuple):
    """One LP's matrix-free operator ``K`` of ``max t  s.t.  K (x, t) <= g,  lo <= x <= hi``: what the
    engines (:mod:`tubejax.lp.engines.pdhg_adapters`) derive the flat operator, the start, the scaling
    and the certificates from. ``X``, ``Y`` are the LP's primal and row pytrees; its data ``d`` holds
    the bounds as ``d.x_lower``, ``d.x_upper`` (flat ``(n_x, B)``, ``t`` excluded).

    Attributes
    ----------
    matvec : ``matvec(shape, d, x: X, xp) -> Y``
    rmatvec : ``rmatvec(shape, d, y: Y, xp) -> X``, ``K^T`` (in JAX what the device runs)
    rhs : ``rhs(shape, d, xp) -> (g, mask)``, row right-hand sides and row mask (1 = real row), as ``Y``
    unpack_x, unpack_y : ``unpack_*(shape, v, xp)``: flat ``(n, B)`` -> ``X`` / ``Y`` (:func:`pack`
        is the inverse of both)
    scaling : callable or None
        ``scaling(shape, d) -> ((matvec, rmatvec), coefficients)`` on flat vectors, where
        ``coefficients.map_coefficients(np.abs)`` gives ``|K|`` and ``np.square`` ``K o K``; ``None``:
        the operator's own data is such coefficients (every entry of ``K`` is one of them).
    rows_with_t : int or None
        The start's margin is taken over the first ``rows_with_t`` row blocks (``None``: all).
    """

    matvec: Callable
    rmatvec: Callable
    rhs: Callable
    unpack_x: Callable
    unpack_y: Callable
    scaling: Callable | None = None
    rows_with_t: int | None = None

    def bounds(self, shape: OperatorShape, d, xp=np) -> tuple:
        """Box bounds ``(lo, hi)`` of ``x`` as ``X``; ``t``'s are ``-inf, inf`` (set by the caller)."""
        inf = xp.full((1, d.x_lower.shape[-1]), np.inf)
        return (self.unpack_x(shape, xp.concatenate([d.x_lower, -inf], axis=0), xp),
                self.unpack_x(shape, xp.concatenate([d.x_upper, inf], axis=0), xp))


class InputBlock(NamedTuple):
    """The hard rows of an input family, ``H u_k(l) <= g`` at every step and vertex, batch axis ``B`` last.

    Attributes
    ----------
    H : (f_u, m, B)         unit rows
    g : (f_u, B) or None    right-hand sides (``None`` in a ``lean()`` copy)
    """

    H: np.ndarray
    g: np.ndarray | None


def tree_leaves(tree) -> list:
    """The arrays of a row or primal pytree (NamedTuples and tuples, any nesting; ``None`` skipped),
    in order."""
    if tree is None:
        return []
    if isinstance(tree, tuple):
        return [a for t in tree for a in tree_leaves(t)]
    return [tree]


def sum_left(terms: Sequence):
    """Left-to-right sum of a sequence of arrays (the order the jitted operators fix)."""
    acc = terms[0]
    for t in terms[1:]:
        acc = acc + t
    return acc


def pack(tree, xp=np):
    """A primal or row pytree -> flat ``(n, B)``: its leaves, each flattened, in order."""
    leaves = tree_leaves(tree)
    B = leaves[0].shape[-1]
    return xp.concatenate([a.reshape(-1, B) for a in leaves], axis=0)


def unpack(v, shapes: Sequence) -> list:
    """Flat ``v (n, B)`` -> its consecutive blocks, block ``i`` of shape ``shapes[i] + (B,)`` (a
    ``None`` shape: a block the LP does not have, ``None``)."""
    B, out, o = v.shape[-1], [], 0
    for s in shapes:
        size = None if s is None else int(np.prod(s))
        out.append(None if s is None else v[o:o + size].reshape(tuple(s) + (B,)))
        o += size or 0
    return out


def padded_horizon(problems: Sequence, L_pad: int | None) -> tuple:
    """The padded horizon ``L`` of a group (default: the largest ``L_b``) and the masks of its steps.

    Returns
    -------
    L : int
    last_step : (L, B)          one-hot of the instance's own horizon (``l = L_b - 1``)
    before_horizon : (L-1, B)   1 where ``l <= L_b - 2``
    within_horizon : (L, B)     1 where ``l <= L_b - 1``

    Raises
    ------
    ValueError
        When ``L_pad`` is below a problem's horizon.
    """
    Ls = np.array([int(p.L) for p in problems])
    L = int(Ls.max()) if L_pad is None else int(L_pad)
    if Ls.max() > L:
        raise ValueError(f"L_pad = {L} is below a problem's horizon {Ls.max()}")
    steps = np.arange(L)[:, None]
    return L, (steps == Ls - 1).astype(float), (steps[:-1] <= Ls - 2).astype(float), (steps <= Ls - 1).astype(float)


def over_batch(a: np.ndarray, B: int) -> np.ndarray:
    """``a`` repeated along a new last (batch) axis of length ``B``, contiguous."""
    return np.ascontiguousarray(np.broadcast_to(a[..., None], a.shape + (B,)))


def hard_families(system, families=TUBE_FAMILIES) -> tuple:
    """The ``hard`` families of ``system``'s LP over ``families`` (default the tube's), in declaration order."""
    return tuple(f for f in active(families, system_regions(system)) if f.lp_role(None, system.u_is_box) == "hard")


def input_facets(system, families=TUBE_FAMILIES) -> int:
    """The row count of the hard input family (an ``InputIn``) of ``system``'s LP over ``families`` (the
    tube's, or the open loop's) at one step and vertex: 0 for none (a box ``U`` is variable bounds)."""
    return int(system.U.H.shape[0]) if any(isinstance(f, InputIn) for f in hard_families(system, families)) else 0


def input_block(G: np.ndarray, g: np.ndarray, ix, f_u: int, lp: str) -> tuple:
    """One ``(f_u, m)`` block of unit rows on ``u_k(l)`` and its right-hand sides, read off the
    dense hard rows ``G (2 n_v f_u, n_x)``, ``g`` of an LP at horizon 2 whose index ``ix`` places
    ``u_k(l)`` at ``ix.u_col(l, k, 0)`` (the tube's and the open-loop LP's).

    Returns
    -------
    H : (f_u, m)    g : (f_u,)   -- the rows divided by their 2-norms

    Raises
    ------
    FamilyDataError
        When the hard rows are not one ``(f_u, m)`` block on ``u_k(l)`` repeated at every step
        and vertex (the structure the operators' input rows model), naming ``lp``.
    """
    m, nv = ix.m, ix.n_v
    if G.shape[0] != 2 * nv * f_u:
        raise FamilyDataError(f"the {lp} LP's hard rows are {G.shape[0]}, not the input family's 2 x {nv} x {f_u}")
    nrm = np.linalg.norm(G, axis=1)
    nrm[nrm == 0] = 1.0
    G, g = G / nrm[:, None], g / nrm
    H = G[:f_u, ix.u_col(0, 0, 0):ix.u_col(0, 0, 0) + m]
    want = np.zeros_like(G).reshape(2, nv, f_u, -1)
    for ell in range(2):
        for k in range(nv):
            want[ell, k, :, ix.u_col(ell, k, 0):ix.u_col(ell, k, 0) + m] = H
    if not (np.array_equal(want.reshape(G.shape), G) and np.array_equal(g, np.tile(g[:f_u], 2 * nv))):
        raise FamilyDataError(f"row family 'input': its hard rows are not one block on u_k(l) at every step "
                              f"and vertex; the {lp} operator cannot model them")
    return H, g[:f_u]


def batched_input_block(G: np.ndarray, g: np.ndarray, ix, f_u: int, lp: str, B: int) -> InputBlock:
    """:func:`input_block` of one ``U`` as the :class:`InputBlock` of a batch of ``B`` instances."""
    H, gu = input_block(G, g, ix, f_u, lp)
    return InputBlock(over_batch(H, B), over_batch(gu, B))


def input_rows_matvec(blk: InputBlock, u):
    """The hard input rows ``H u_k(l)`` of inputs ``u (L, n_v, m, B)``: ``(L, n_v, f_u, B)``, unmasked."""
    H = blk.H
    return sum_left([H[None, None, :, j] * u[:, :, None, j] for j in range(H.shape[1])])


def input_rows_rhs(blk: InputBlock, within_horizon: np.ndarray, n_v: int, xp=np) -> tuple:
    """Right-hand sides and row mask of the hard input rows, ``(L, n_v, f_u, B)`` each (rows at steps
    within the instance's horizon, ``within_horizon (L, B)``, are real)."""
    L, (f_u, B) = within_horizon.shape[0], blk.g.shape
    return (xp.broadcast_to(blk.g, (L, n_v, f_u, B)) + 0.0,
            xp.broadcast_to(within_horizon[:, None, None], (L, n_v, f_u, B)) + 0.0)
