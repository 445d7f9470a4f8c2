"""The tube LP (Problem 2, docs/math/tube-lp.md) declared once, as an ordered list of row families.

A *row family* is one named constraint of Problem 2 over a tube ``x = (p, eps, u)``,
written as ``lhs(d, x) <= rhs(d)`` row by row, where ``lhs`` is linear in ``x`` and ``d``
holds the problem's data (:class:`TubeTerms`). Both are written with ``+``, ``-``, ``*``,
``@`` and indexing only, so the one declaration runs

* on float64 NumPy arrays and on rational :class:`~tubejax.lp.evidence.rational.QArray`
  data (the float and the exact checks: :func:`tube_residuals`);
* with a leading batch axis on ``x`` and on the data (the batched checks);
* on the identity as a batch of tubes (the dense LP rows: :func:`dense_rows`).

Families, in the order of the LP's rows (:data:`TUBE_FAMILIES`):

==========  =======================================================  ================  =====
name        rows (``q_k(l) = p_l + eps_l z_k``, ``q_k(0) = v_k``)      grid              LP
==========  =======================================================  ================  =====
``safe``    C2: ``H_S q_k(l) <= h_S``, ``l = 1..L-1``                ``(L-1, n_v, f)``  margin
``target``  C3: ``H_j q_k(L) <= h_j``                                ``(1, n_v, f)``    margin
``X``       ``H_x q_k(l) <= h_x``, ``l = 1..L`` (the system's state    ``(L, n_v, f)``    margin
            constraint, when it has one)
``dynamics`` C4: ``H_z (A q_k(l) + B u_k(l) - p_{l+1}) - eps_{l+1} h_z  ``(L, n_v, f_z)``  margin
            <= -sigma_W(H_z)``, ``l = 0..L-1``
``eps_min`` C1: ``-eps_l <= -eps_min``                               ``(L,)``           bound
``input``   C5: ``H_u u_k(l) <= h_u``                                ``(L, n_v, f_u)``  bound
                                                                                        (box U)
                                                                                        or hard
==========  =======================================================  ================  =====

``safe`` and ``target`` are *compressed* in the LP: their rows differ across the vertex
axis only in the coefficient of ``eps_l`` (``H z_k``), and ``eps_l >= eps_min >= 0``, so the
largest of them, ``H p_l + sigma_Z(H) eps_l <= h``, is equivalent to all of them. The checks
keep every vertex.

Row scales: a residual is reported per unit of its state-space normal (``H_S``, ``H_z``,
``H_u`` rows; 1 for C1): 2-norms in float64, the max-norm of the primitive integer rows in
rationals (:mod:`tubejax.lp.evidence.check`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, NamedTuple

import numpy as np

from ....model.geometry import support
from ....model.system import free_axes

__all__ = ["TubeVars", "TubeTerms", "SetRows", "RowFamily", "VertexIn", "Dynamics", "EpsMin", "InputIn",
           "TUBE_FAMILIES", "step_indices", "system_regions", "active", "translation_axes", "RowLayout", "tube_residuals", "lp_blocks", "state_lengths", "dense_rows", "dense_rhs",
           "float_terms", "region_sets"]


class TubeVars(NamedTuple):
    """A tube, or a batch of tubes (leading axes ``...``).

    Attributes
    ----------
    p : array, shape (..., L, n)          centres ``p_1 .. p_L``
    eps : array, shape (..., L)           scales ``eps_1 .. eps_L``
    u : array, shape (..., L, n_v, m)     vertex inputs ``u_k(0) .. u_k(L-1)``
    """

    p: object
    eps: object
    u: object


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


class TubeTerms(NamedTuple):
    """The data of one tube problem (or of a batch sharing everything but positions), in one
    arithmetic: float64 NumPy arrays or :class:`~tubejax.lp.evidence.rational.QArray`.

    Attributes
    ----------
    L : int
    V : array, shape (..., n_v, n)      source vertices ``q_k(0) = v_k``
    Zv : array, shape (n_v, n)          vertices of ``Z`` (``Zv[k]`` pairs with ``V[k]``)
    A, B : arrays, shapes (n, n), (n, m)
    Z : SetRows                         facets of ``Z`` (``H_z``, ``h_z``)
    sigma_w : array, shape (f_z,)       ``sigma_W(H_z)`` (an upper bound, in rationals)
    sets : dict of str to SetRows       ``'safe'`` (``S``), ``'target'`` (``P_j``), ``'input'`` (``U``),
                                        and the system's state constraints (``'X'``) where set
    eps_min : array, shape (1,)
    concat : callable                   ``concat(arrays, axis)`` in this arithmetic
    """

    L: int
    V: object
    Zv: object
    A: object
    B: object
    Z: SetRows
    sigma_w: object
    sets: dict
    eps_min: object
    concat: Callable


class RowFamily:
    """A named family of rows ``lhs(d, x) <= rhs(d)`` of the tube LP (see the module doc).

    Attributes
    ----------
    name : str
        The family's name in the row layout (:class:`RowLayout`) and in messages.
    compress_vertices : bool
        The LP keeps the largest row over the vertex axis (axis ``-2`` of the grid).
    """

    def grid(self, d: TubeTerms) -> tuple:
        """The row grid's shape; the last axis indexes the facets of :meth:`rows_of`."""
        raise NotImplementedError

    def applies(self, regions) -> bool:
        """Whether the family has rows for a problem whose sets are named ``regions`` (the keys of
        :attr:`TubeTerms.sets`, or :func:`system_regions`): a family over a set the problem does not
        have (a state constraint the system leaves unset) has none."""
        return True

    def lp_role(self, d: TubeTerms, u_is_box: bool) -> str:
        """``'margin'`` (rows ``G x + t <= g``), ``'hard'`` (rows without ``t``) or ``'bound'``
        (kept as variable bounds by the LP builder; checked like every family)."""
        return "margin"

    def lhs(self, d: TubeTerms, x: TubeVars):
        """The linear part, shape ``(..., *grid)``."""
        raise NotImplementedError

    def rhs(self, d: TubeTerms):
        """The right-hand side, broadcastable to ``(..., *grid)``."""
        raise NotImplementedError

    def scale(self, d: TubeTerms) -> np.ndarray:
        """The length of each row's state-space normal, shape ``(grid[-1],)`` (float: 2-norm;
        rational: the max-norm of the primitive integer normal, what the exact check divides by)."""
        raise NotImplementedError

    def normals(self, d: TubeTerms):
        """The state-space normal of each row, shape ``(grid[-1], n)``: the facet row the
        constraint comes from (the margin is measured along it, docs/math/margins.md)."""
        raise NotImplementedError

    def invariant_axes(self, system) -> np.ndarray:
        """Axes ``j`` along which translating the pair (source, target and safe set by ``c``,
        ``p_l -> p_l + c``; ``eps`` and ``u`` unchanged) maps these rows exactly onto the
        translated problem's rows, shape ``(n,)`` of bool (:func:`translation_axes`)."""
        return np.ones(system.n, dtype=bool)


def step_indices(kind: str, L: int) -> np.ndarray:
    """Indices ``l - 1`` of the steps a :class:`VertexIn` family covers at horizon ``L``."""
    return {"interior": np.arange(L - 1), "last": np.array([L - 1]), "all": np.arange(L)}[kind]


@dataclass(frozen=True)
class VertexIn(RowFamily):
    """``H q_k(l) <= h`` for every vertex ``k`` and every step ``l`` in ``steps``.

    Parameters
    ----------
    name : str
    region : str        the key of :attr:`TubeTerms.sets`
    steps : str         ``'interior'`` (``l = 1..L-1``), ``'last'`` (``l = L``) or ``'all'``
    """

    name: str
    region: str
    steps: str
    compress_vertices: bool = True
    moves_with_pair: bool = True

    def applies(self, regions):
        return self.region in regions

    def invariant_axes(self, system):
        # H (q + c) <= h + H c: the set moves with the pair; a fixed set (moves_with_pair=False), a
        # state constraint, only along the axes its rows do not involve (H c = 0)
        if self.moves_with_pair:
            return np.ones(system.n, dtype=bool)
        return np.all(np.asarray(system.state_constraints[self.region].H) == 0.0, axis=0)

    def grid(self, d):
        return (len(step_indices(self.steps, d.L)), d.Zv.shape[0], d.sets[self.region].H.shape[0])

    def lhs(self, d, x):
        s = step_indices(self.steps, d.L)
        q = x.p[..., s, None, :] + x.eps[..., s, None, None] * d.Zv          # (..., S, n_v, n)
        return q @ d.sets[self.region].H.T

    def rhs(self, d):
        h = d.sets[self.region].h
        return h[..., None, None, :]

    def scale(self, d):
        return d.sets[self.region].scale

    def normals(self, d):
        return d.sets[self.region].H


@dataclass(frozen=True)
class Dynamics(RowFamily):
    """C4: the successor of every tube vertex lies in the next cross-section, for every ``w``."""

    name: str = "dynamics"
    compress_vertices: bool = False

    def grid(self, d):
        return (d.L, d.Zv.shape[0], d.Z.H.shape[0])

    def lhs(self, d, x):
        L = d.L
        q = x.p[..., :L - 1, None, :] + x.eps[..., :L - 1, None, None] * d.Zv   # q_k(1..L-1)
        q = d.concat([x.p[..., :1, None, :] * 0 + d.Zv * 0, q], -3)      # q_k(0) = v_k: data, in rhs
        nxt = q @ d.A.T + x.u @ d.B.T - x.p[..., :, None, :]                      # (..., L, n_v, n)
        return nxt @ d.Z.H.T - x.eps[..., :, None, None] * d.Z.h

    def rhs(self, d):
        first = np.zeros((d.L, 1, 1))
        first[0] = 1.0
        vz = (d.V @ d.A.T) @ d.Z.H.T                                             # (..., n_v, f_z)
        return -(vz[..., None, :, :] * first) - d.sigma_w

    def scale(self, d):
        return d.Z.scale

    def normals(self, d):
        return d.Z.H

    def invariant_axes(self, system):
        # H_z (A (q + c) + B u - (p + c)) = H_z (A q + B u - p) + H_z (A - I) c
        return free_axes(system.A)


@dataclass(frozen=True)
class EpsMin(RowFamily):
    """C1: ``eps_l >= eps_min``."""

    name: str = "eps_min"
    compress_vertices: bool = False

    def grid(self, d):
        return (d.L,)

    def lp_role(self, d, u_is_box):
        return "bound"

    def lhs(self, d, x):
        return -x.eps

    def rhs(self, d):
        return -d.eps_min

    def scale(self, d):
        return d.Z.scale[:1] * 0 + 1


@dataclass(frozen=True)
class InputIn(RowFamily):
    """C5: ``u_k(l) in U``; variable bounds for a box ``U``, hard rows otherwise."""

    name: str = "input"
    compress_vertices: bool = False

    def grid(self, d):
        return (d.L, d.Zv.shape[0], d.sets["input"].H.shape[0])

    def lp_role(self, d, u_is_box):
        return "bound" if u_is_box else "hard"

    def lhs(self, d, x):
        return x.u @ d.sets["input"].H.T

    def rhs(self, d):
        return d.sets["input"].h

    def scale(self, d):
        return d.sets["input"].scale

    def normals(self, d):
        return d.sets["input"].H


#: Problem 2, in the LP's row order.
TUBE_FAMILIES: tuple = (VertexIn("safe", "safe", "interior"), VertexIn("target", "target", "last"),
                        VertexIn("X", "X", "all", moves_with_pair=False), Dynamics(), EpsMin(), InputIn())


def system_regions(system) -> frozenset:
    """The region names a problem of ``system`` has: ``'safe'``, ``'target'``, ``'input'`` and the
    state constraints the system sets (:attr:`~tubejax.model.system.LinearSystem.state_constraints`)."""
    return frozenset(("safe", "target", "input", *system.state_constraints))


def active(families, regions) -> tuple:
    """The families that have rows for a problem with sets named ``regions`` (:meth:`RowFamily.applies`)."""
    return tuple(f for f in families if f.applies(regions))


def translation_axes(system, families=TUBE_FAMILIES) -> np.ndarray:
    """The axes along which translated pairs have the same problem up to the translation: those
    every family is invariant along (:meth:`RowFamily.invariant_axes`), shape ``(n,)`` of bool.

    For Problem 2 as declared these are the axes ``A`` leaves fixed
    (:func:`~tubejax.model.system.free_axes`); a family over a set that does not move with the pair
    removes every axis, and the translation classes then hold one pair each.
    """
    axes = np.ones(system.n, dtype=bool)
    for f in active(families, system_regions(system)):
        axes &= np.asarray(f.invariant_axes(system), dtype=bool)
    return axes


def tube_residuals(d: TubeTerms, x: TubeVars, families=TUBE_FAMILIES) -> list:
    """``(name, lhs - rhs, scale)`` of every family: a row holds iff its residual is ``<= 0``.

    Residuals have shape ``(..., *grid)``; ``scale`` has shape ``(grid[-1],)``.
    """
    return [(f.name, f.lhs(d, x) - f.rhs(d), f.scale(d)) for f in active(families, d.sets)]


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


def _identity_tube(d: TubeTerms, m: int) -> TubeVars:
    """Every unit vector of the ``TubeIndex(L, n, n_v, m)`` layout as a batch of tubes, in the
    arithmetic of ``d``."""
    L, (nv, n) = d.L, d.Zv.shape
    size = L * n + L + L * nv * m
    eye = np.eye(size)
    if not isinstance(d.A, np.ndarray):
        eye = type(d.A)(np.eye(size, dtype=np.int64).astype(object), 1)
    return TubeVars(eye[:, :L * n].reshape(size, L, n), eye[:, L * n:L * n + L],
                    eye[:, L * n + L:].reshape(size, L, nv, m))


def lp_blocks(d: TubeTerms, m: int, role: str, u_is_box: bool, families=TUBE_FAMILIES, identity=None) -> list:
    """Each family's LP rows with ``lp_role == role``, in declaration order, unnormalised, in
    the arithmetic of ``d`` (float64 or rational).

    ``lhs`` applied to the identity gives each row's coefficients; a family with
    ``compress_vertices`` keeps the largest coefficient over the vertex axis (its rows differ
    there only in ``eps``'s coefficient, see the module doc). ``identity(d, m)`` gives the unit
    vectors of the LP's variables as a batch (default: the tube's; the open-loop LP passes its own).

    Returns
    -------
    list of ``(name, grid, G, g)``: ``G`` of shape ``(n_x, R)``, ``g`` of shape ``(R,)``, with
    ``R = prod(grid)`` rows in the family's grid order (after compression).
    """
    fams = [f for f in active(families, d.sets) if f.lp_role(d, u_is_box) == role]
    if not fams:
        return []
    x = (identity or _identity_tube)(d, m)
    n_x = x[0].shape[0]
    out = []
    for f in fams:
        grid = f.grid(d)
        G = _map(f.lhs(d, x), lambda a: np.broadcast_to(a, (n_x,) + grid))
        g = _map(f.rhs(d), lambda a: np.broadcast_to(a, grid))
        if f.compress_vertices:
            G, g, grid = _map(G, lambda a: a.max(axis=-2)), g[..., 0, :], grid[:-2] + grid[-1:]
        out.append((f.name, tuple(grid), _map(G, lambda a: a.reshape(n_x, -1)), _map(g, np.ravel)))
    return out


def state_lengths(d: TubeTerms, role: str, u_is_box: bool, length, families=TUBE_FAMILIES) -> np.ndarray:
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
    for f in active(families, d.sets):
        if f.lp_role(d, u_is_box) != role:
            continue
        grid = f.grid(d)
        if f.compress_vertices:
            grid = grid[:-2] + grid[-1:]
        lens = np.asarray(length(f.normals(d)))
        out.append(np.broadcast_to(lens, grid).ravel())
    return np.concatenate(out) if out else np.zeros(0)


def dense_rows(d: TubeTerms, m: int, role: str, u_is_box: bool, families=TUBE_FAMILIES, identity=None):
    """The float64 LP rows of the families with ``lp_role == role`` (:func:`lp_blocks`), unnormalised.

    Parameters
    ----------
    d : TubeTerms in float64, without a batch axis
    m : int            the input dimension
    role : str         ``'margin'`` or ``'hard'``
    identity : callable, optional   as in :func:`lp_blocks`

    Returns
    -------
    G : ndarray, shape (n_rows, n_x)
    g : ndarray, shape (n_rows,)
    layout : RowLayout
    """
    blocks = lp_blocks(d, m, role, u_is_box, families, identity)
    G = (np.concatenate([b[2].T for b in blocks], axis=0) if blocks
         else np.zeros((0, (identity or _identity_tube)(d, m)[0].shape[0])))
    g = np.concatenate([b[3] for b in blocks]) if blocks else np.zeros(0)
    return (np.ascontiguousarray(G), g.astype(float),
            RowLayout(tuple(b[0] for b in blocks), tuple(b[1] for b in blocks)))


def dense_rhs(d: TubeTerms, role: str, u_is_box: bool, families=TUBE_FAMILIES) -> np.ndarray:
    """The right-hand sides of :func:`dense_rows`'s rows, shape ``(..., n_rows)``, unnormalised.

    ``d`` may carry a leading batch axis (translated problems: :func:`float_terms` with ``V``, ``h``).
    """
    batch = tuple(np.shape(d.V)[:-2])
    gs = []
    for f in active(families, d.sets):
        if f.lp_role(d, u_is_box) != role:
            continue
        g = np.broadcast_to(f.rhs(d), batch + f.grid(d))
        if f.compress_vertices:
            g = g[..., 0, :]
        gs.append(g.reshape(batch + (-1,)))
    return np.concatenate(gs, axis=-1) if gs else np.zeros(batch + (0,))


def region_sets(prob) -> dict:
    """The sets the families' ``region`` names stand for in ``prob``: ``'safe'`` (``S``),
    ``'target'`` (``P_j``), ``'input'`` (``U``), each a :class:`~tubejax.model.geometry.Polytope`,
    and the system's state constraints by field name (:class:`~tubejax.model.geometry.Halfspaces`)."""
    return {"safe": prob.safe, "target": prob.target, "input": prob.system.U, **prob.system.state_constraints}


def float_terms(prob, V=None, h=None) -> TubeTerms:
    """:class:`TubeTerms` of a :class:`~tubejax.lp.formulations.tube.dense.TubeProblem` in float64.

    Parameters
    ----------
    prob : TubeProblem
    V : ndarray, shape (K, n_v, n), optional
        Source vertices of a batch of problems sharing everything else (default ``prob``'s).
    h : dict of str to ndarray (K, f), optional
        Their ``'safe'`` and ``'target'`` offsets (default ``prob``'s).
    """
    sysm, Z, h = prob.system, prob.Z, h or {}

    def rows(P, name):
        return SetRows(P.H, h.get(name, P.h), P.row_norms)

    sets = {name: rows(P, name) for name, P in region_sets(prob).items()}
    return TubeTerms(int(prob.L), prob.source.vertices if V is None else V, Z.vertices, sysm.A, sysm.B,
                     rows(Z, "Z"), support(sysm.W, Z.H), sets, np.array([float(prob.eps_min)]), np.concatenate)
