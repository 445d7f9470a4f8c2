"""Row families: one declaration of an LP, every form derived from it (generic over the LP).

A *row family* is one named constraint ``lhs(d, x) <= rhs(d)`` of an LP over its variables ``x``,
``lhs`` linear in ``x`` and ``d`` the LP's *terms*, written with ``+ - * @`` and indexing only, so
one declaration runs on float64, on rational :class:`~tubejax.lp.evidence.rational.QArray` data,
with a batch axis and on the identity (the coefficients). From an ordered list of families this
module derives the rows (:func:`sparse_rows`, :func:`dense_rows`, :func:`dense_rhs`), the margin's
unit (:func:`state_lengths`), rows by name (:class:`RowLayout`), the families a problem has
(:func:`families_in`; a declared set missing is a :class:`FamilyDataError`) and the zero-row rule
(:func:`zero_rows`, :func:`kept_rows`, :func:`zero_row_rule`). Used by the tube and open-loop LPs
(docs/explanation/implementation.md#problem-2-as-row-families).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.sparse as sp

from .sparse_blocks import csr_dense, family_csr, take

__all__ = ["SetRows", "RowFamily", "RegionRows", "FamilyDataError", "step_indices", "active", "families_in",
           "require_families", "role_names", "RowLayout", "lp_blocks", "state_lengths", "sparse_rows", "dense_rows",
           "dense_rhs", "ZERO_ROW", "zero_rows", "kept_rows", "zero_row_rule"]


class FamilyDataError(LookupError):
    """A row family that applies to a problem, but whose set or data a consumer lacks (exact data,
    certificate rows, the PDHG operator, ...): the message names the family and the consumer. Raised
    instead of leaving the family out, which would check, prove or record the LP without its rows.
    Not a ``ValueError``: the paths that turn a failed exact decision into an unconfirmed verdict
    (``except ValueError``) let it through, so a declaration out of step with a consumer stops the run."""


class SetRows(NamedTuple):
    """A polytope ``{x : H x <= h}`` in one arithmetic.

    Attributes
    ----------
    H : array, shape (f, n)          facet normals (float unit rows, or QArray integer rows)
    h : array, shape (..., f)        offsets (a leading batch axis for translated problems)
    scale : ndarray, shape (f,)      the length of each normal (float 2-norm, or object-int max-norm)
    """

    H: object
    h: object
    scale: np.ndarray


class RowFamily:
    """A named family of rows ``lhs(d, x) <= rhs(d)`` of the tube LP (see the module doc).

    Attributes
    ----------
    name : str
        The family's name in the row layout (:class:`RowLayout`) and in messages.
    compress_vertices : bool
        The LP keeps the largest row over the vertex axis (axis ``-2`` of the grid).
    """

    def grid(self, d) -> tuple:
        """The row grid's shape; the last axis indexes the facets of :meth:`rows_of`."""
        raise NotImplementedError

    #: The names of the sets (keys of the terms' ``sets``) the family's rows are over.
    regions: tuple = ()

    #: Whether ``sigma_W`` of each row's normal (:meth:`normals`) is subtracted in the right-hand
    #: side (a disturbance enters the row): the radius form ``W = rho W_0`` moves it into ``rho``'s
    #: column (:mod:`tubejax.lp.declarations.radius_rows`).
    disturbed: bool = False

    def applies(self, regions) -> bool:
        """Whether the family has rows for a problem whose system declares the sets named ``regions``
        (:func:`~tubejax.lp.declarations.tube_families.system_regions`): a family over a set the
        system does not have (a state constraint it leaves unset) has none. Never decided from a
        consumer's data (:func:`families_in`)."""
        return all(r in regions for r in self.regions)

    def lp_role(self, d, u_is_box: bool) -> str:
        """``'margin'`` (rows ``G x + t <= g``), ``'hard'`` (rows without ``t``) or ``'bound'``
        (kept as variable bounds by the LP builder; checked like every family)."""
        return "margin"

    def lhs(self, d, x):
        """The linear part, shape ``(..., *grid)``."""
        raise NotImplementedError

    def rhs(self, d):
        """The right-hand side, broadcastable to ``(..., *grid)``."""
        raise NotImplementedError

    def scale(self, d) -> np.ndarray:
        """The length of each row's state-space normal, shape ``(grid[-1],)`` (float: 2-norm;
        rational: the max-norm of the primitive integer normal, what the exact check divides by)."""
        raise NotImplementedError

    def normals(self, d):
        """The state-space normal of each row, shape ``(grid[-1], n)``: the facet row the
        constraint comes from (the margin is measured along it, docs/math/margins.md)."""
        raise NotImplementedError

    def invariance_rows(self, system) -> np.ndarray:
        """Rows ``K``, shape ``(k, n)``: translating the pair by ``c`` with ``K c = 0`` (source,
        target and safe set by ``c``, ``p_l -> p_l + c``; ``eps`` and ``u`` unchanged) maps these
        rows exactly onto the translated problem's rows
        (:func:`~tubejax.lp.declarations.tube_families.translation_groups`). None by default:
        rows over sets that move with the pair are invariant under every translation."""
        return np.zeros((0, system.n))


class RegionRows(RowFamily):
    """A family over one named set of the terms (``self.region``, a key of ``d.sets``): it has rows
    only where the problem has that set, and each row is measured along that set's facet normal."""

    @property
    def regions(self) -> tuple:
        return (self.region,)

    def scale(self, d):
        return d.sets[self.region].scale

    def normals(self, d):
        return d.sets[self.region].H


def step_indices(kind: str, L: int) -> np.ndarray:
    """Indices ``l - 1`` of the steps a :class:`VertexIn` family covers at horizon ``L``."""
    return {"interior": np.arange(L - 1), "last": np.array([L - 1]), "all": np.arange(L)}[kind]


def active(families, regions) -> tuple:
    """The families that have rows for a problem whose system declares the sets named ``regions``
    (:meth:`RowFamily.applies`)."""
    return tuple(f for f in families if f.applies(regions))


def require_families(families, regions, have, where: str) -> tuple:
    """The families active for ``regions`` (:func:`active`), each with every set it is over in
    ``have`` (the set names a consumer holds data for).

    Raises
    ------
    FamilyDataError
        Naming the first family whose set ``where`` (the consumer, in words) lacks.
    """
    fams = active(families, regions)
    for f in fams:
        missing = [r for r in f.regions if r not in have]
        if missing:
            raise FamilyDataError(f"row family {f.name!r}: {where} has no data for its set {missing[0]!r} "
                                  f"(it has {', '.join(sorted(have)) or 'none'}); the family applies to this "
                                  "problem, so it cannot be left out")
    return fams


def role_names(families, regions, u_is_box: bool) -> dict:
    """``{role: names}`` of the families active for ``regions``, in declaration order: what a
    consumer that models only some families by name (an operator, the variable bounds) compares
    against, so that a family it does not know is refused by name, never ignored."""
    out: dict = {}
    for f in active(families, regions):
        out.setdefault(f.lp_role(None, u_is_box), []).append(f.name)
    return {k: tuple(v) for k, v in out.items()}


def families_in(families, d) -> tuple:
    """The families with rows in the terms ``d``: those its system declares (``d.regions``), each
    with its sets in ``d.sets`` (:func:`require_families`, else :class:`FamilyDataError`)."""
    return require_families(families, d.regions, d.sets, "these terms")


class RowLayout(NamedTuple):
    """Where each family's rows sit in an LP's row vector: rows are found by name.

    Attributes
    ----------
    names : tuple of str
    shapes : tuple of tuple     each family's row grid in the LP (after compression)
    """

    names: tuple
    shapes: tuple

    def slice(self, name: str) -> slice:
        """The rows of family ``name``."""
        start = 0
        for nm, sh in zip(self.names, self.shapes):
            size = int(np.prod(sh))
            if nm == name:
                return slice(start, start + size)
            start += size
        raise KeyError(f"no row family {name!r} in this LP (it has {', '.join(self.names)})")

    def shape(self, name: str) -> tuple:
        """The row grid of family ``name``."""
        return self.shapes[self.names.index(name)]

    def split(self, y) -> dict:
        """A row vector ``(n_rows, ...)`` -> ``{name: (*grid, ...)}``."""
        return {nm: y[self.slice(nm)].reshape(sh + y.shape[1:]) for nm, sh in zip(self.names, self.shapes)}

    @property
    def n_rows(self) -> int:
        return int(sum(int(np.prod(sh)) for sh in self.shapes))


def _map(a, fn):
    """``fn`` applied to a float array, or to a rational array's numerators (one common
    denominator: indexing, broadcasting, reshaping and maxima keep it)."""
    return fn(a) if isinstance(a, np.ndarray) else type(a)(fn(a.num), a.den)


def lp_blocks(d, m: int, role: str, u_is_box: bool, families, identity) -> list:
    """Each family's LP rows with ``lp_role == role``, in declaration order, unnormalised, in the
    arithmetic of ``d``: ``lhs`` applied to ``identity(d, m)`` (the unit vectors of the LP's variables),
    a ``compress_vertices`` family keeping the largest coefficient over the vertex axis.

    Returns
    -------
    list of ``(name, grid, G, g)``: ``G`` of shape ``(n_x, R)``, ``g`` of shape ``(R,)``, with
    ``R = prod(grid)`` rows in the family's grid order (after compression).
    """
    fams = _role_families(d, role, u_is_box, families)
    if not fams:
        return []
    x = identity(d, m)
    return [(f.name,) + _family_block(d, f, x) for f in fams]


def _role_families(d, role: str, u_is_box: bool, families) -> list:
    """The families with rows in ``d`` (:func:`families_in`) whose ``lp_role`` is ``role``."""
    return [f for f in families_in(families, d) if f.lp_role(d, u_is_box) == role]


def _family_block(d, f, x) -> tuple:
    """Family ``f``'s rows on the batch of ``B`` variable vectors ``x``: its grid (after
    compression), ``lhs`` of shape ``(B, R)`` and ``rhs`` of shape ``(R,)``, in ``d``'s arithmetic."""
    n_b = x[0].shape[0]
    grid = f.grid(d)
    G = _map(f.lhs(d, x), lambda a: np.broadcast_to(a, (n_b,) + grid))
    g = _map(f.rhs(d), lambda a: np.broadcast_to(a, grid))
    if f.compress_vertices:
        G, g, grid = _map(G, lambda a: a.max(axis=-2)), g[..., 0, :], grid[:-2] + grid[-1:]
    return tuple(grid), _map(G, lambda a: a.reshape(n_b, int(np.prod(grid)))), _map(g, np.ravel)


def state_lengths(d, role: str, u_is_box: bool, length, families) -> np.ndarray:
    """The length of each LP row's state-space normal, in :func:`lp_blocks`' row order, shape
    ``(n_rows,)``: the margin form divides every row by it, so that the margin ``t`` is a
    distance in the state space (docs/math/margins.md#state-space-distances).

    Parameters
    ----------
    length : callable
        ``length(normals) -> (f,)``: the 2-norms of a family's normals in ``d``'s arithmetic
        (float64, or floats of the rational normals for the rational rows).
    """
    out = []
    for f in families_in(families, d):
        if f.lp_role(d, u_is_box) != role:
            continue
        grid = f.grid(d)
        if f.compress_vertices:
            grid = grid[:-2] + grid[-1:]
        lens = np.asarray(length(f.normals(d)))
        out.append(np.broadcast_to(lens, grid).ravel())
    return np.concatenate(out) if out else np.zeros(0)


def sparse_rows(d, m: int, role: str, u_is_box: bool, families, identity):
    """The float64 LP rows of the families with ``lp_role == role``, unnormalised, as a CSR matrix:
    :func:`lp_blocks`' rows, each family's coefficients evaluated only on the variables it reads
    (:func:`~tubejax.lp.declarations.sparse_blocks.family_csr`), never as a dense block.

    Parameters
    ----------
    d : the LP's terms in float64, without a batch axis
    m : int            the input dimension
    role : str         ``'margin'`` or ``'hard'``
    identity : callable   as in :func:`lp_blocks`

    Returns
    -------
    G : scipy.sparse.csr_matrix, shape (n_rows, n_x)
        Columns sorted in each row; its nonzeros, and each ``-0.0`` of an evaluated column as an
        explicit entry.
    g : ndarray, shape (n_rows,)
    layout : RowLayout
    """
    x = identity(d, m)
    n_x = x[0].shape[0]
    mats, gs, names, shapes = [], [], [], []
    for f in _role_families(d, role, u_is_box, families):
        grid, _, g = _family_block(d, f, take(x, slice(0, 0)))
        mats.append(family_csr(lambda b, f=f: _family_block(d, f, b)[1], x, n_x, int(np.prod(grid))))
        gs.append(np.asarray(g, float))
        names.append(f.name)
        shapes.append(grid)
    G = sp.vstack(mats, format="csr") if mats else sp.csr_matrix((0, n_x))
    G.has_sorted_indices = True
    return G, np.concatenate(gs) if gs else np.zeros(0), RowLayout(tuple(names), tuple(shapes))


def dense_rows(d, m: int, role: str, u_is_box: bool, families, identity):
    """:func:`sparse_rows` as a dense array (its entries written back, a ``-0.0`` with its sign).

    Returns
    -------
    G : ndarray, shape (n_rows, n_x)
    g : ndarray, shape (n_rows,)
    layout : RowLayout
    """
    if not _role_families(d, role, u_is_box, families):                  # no rows (a box U's hard rows)
        return np.zeros((0, identity(d, m)[0].shape[0])), np.zeros(0), RowLayout((), ())
    G, g, layout = sparse_rows(d, m, role, u_is_box, families, identity)
    return csr_dense(G), g, layout


def dense_rhs(d, role: str, u_is_box: bool, families) -> np.ndarray:
    """The right-hand sides of :func:`dense_rows`'s rows, shape ``(..., n_rows)``, unnormalised.

    ``d`` may carry a leading batch axis (translated problems: :func:`float_terms` with ``V``, ``h``).
    """
    batch = tuple(np.shape(d.V)[:-2])
    gs = []
    for f in families_in(families, d):
        if f.lp_role(d, u_is_box) != role:
            continue
        g = np.broadcast_to(f.rhs(d), batch + f.grid(d))
        if f.compress_vertices:
            g = g[..., 0, :]
        gs.append(g.reshape(batch + (-1,)))
    return np.concatenate(gs, axis=-1) if gs else np.zeros(batch + (0,))


#: A float row whose coefficients have at most this 2-norm is a zero row (:func:`zero_rows`).
ZERO_ROW = 1e-12


def zero_rows(G) -> np.ndarray:
    """Which rows are zero rows, shape ``(R,)``: of a float block ``G (R, n_x)``, those of 2-norm at most
    :data:`ZERO_ROW`; of rational rows (a list of ``{column: coefficient}``, nonzeros only), the empty ones."""
    if isinstance(G, list):
        return np.array([not r for r in G], bool)
    return np.linalg.norm(G, axis=1) <= ZERO_ROW


def kept_rows(zero, g, c=None) -> np.ndarray:
    """The zero-row rule: which rows stay in the LP, shape ``np.broadcast(zero, g).shape``.

    A row with coefficients always stays. A zero row ``0 . x + c t <= g`` (possible in the open-loop
    LP where ``H A^s B = 0``) stays only where it binds: ``g < 0`` (it bounds the margin below
    zero) or, in the radius form, ``c > 0`` (it bounds ``rho``); otherwise it cannot decide
    whether the margin is nonnegative, and is dropped as redundant.

    Parameters
    ----------
    zero : array of bool, shape (R,)      :func:`zero_rows`
    g : array, shape (..., R)             right-hand sides (float, or Fractions)
    c : array, shape (R,), optional       the radius column (``None``: the margin form)
    """
    keep = ~np.asarray(zero, bool) | np.asarray(np.asarray(g) < 0, bool)
    if c is not None:
        keep = keep | np.asarray(np.asarray(c) > 0, bool)
    return keep


def zero_row_rule(G, g, c=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The zero-row rule on a float block: which rows are zero rows, which stay, and the block with a
    zero row's coefficients (at most :data:`ZERO_ROW` in 2-norm) set to exactly 0.

    Parameters
    ----------
    G : ndarray, shape (R, n_x)
    g, c : as in :func:`kept_rows`

    Returns
    -------
    zero : ndarray of bool, shape (R,)      :func:`zero_rows`
    keep : ndarray of bool                  :func:`kept_rows`, shape ``np.broadcast(zero, g).shape``
    G0 : ndarray, shape (R, n_x)            ``G`` with its zero rows 0
    """
    zero = zero_rows(G)
    return zero, kept_rows(zero, g, c), np.where(zero[:, None], 0.0, G)
