"""The tube LP (Problem 2, docs/math/tube-lp.md) declared once, as an ordered list of row families.

A *row family* (:mod:`tubejax.lp.declarations.row_families`) is one named constraint
``lhs(d, x) <= rhs(d)`` over a tube ``x = (p, eps, u)``, linear in ``x``, with ``d`` the problem's
data (:class:`TubeTerms`). The one declaration runs on float64 and on rational data
(:func:`tube_residuals`, with a leading batch axis) and on the identity (:func:`tube_identity`: the
dense LP rows). :data:`TUBE_FAMILIES` lists ``safe`` (C2), ``target`` (C3), ``X``, ``dynamics`` (C4),
``eps_min`` (C1) and ``input`` (C5), in the LP's row order (docs/explanation/implementation.md#problem-2-as-row-families).
``safe`` and ``target`` are compressed in the LP to ``H p_l + sigma_Z(H) eps_l <= h``, equivalent
since ``eps_l >= 0`` (docs/math/tube-lp.md#lp-size); the checks keep every vertex. Residuals are per
unit of the row's state-space normal (:mod:`tubejax.lp.evidence.check`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Callable, NamedTuple

import numpy as np

from ...model.geometry import support
from ...model.system import exact_matrix, translation_groups as kernel_groups
from .row_families import FamilyDataError, RegionRows, RowFamily, SetRows, active, families_in, step_indices

__all__ = ["TubeVars", "TubeTerms", "VertexIn", "Dynamics", "EpsMin", "InputIn", "TUBE_FAMILIES", "PAIR_REGIONS",
           "system_sets", "system_regions",
           "translation_groups", "tube_residuals", "tube_identity", "float_terms", "region_sets",
           "step_regions", "implied_eps_bounds"]


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
    regions : frozenset of str          the sets the problem's system declares (:func:`system_regions`):
                                        which families have rows; each must be in ``sets``
                                        (:func:`~tubejax.lp.declarations.row_families.families_in`)
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
    regions: frozenset


@dataclass(frozen=True)
class VertexIn(RegionRows):
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

    def invariance_rows(self, system):
        # H (q + c) <= h + H c: the set moves with the pair; a fixed set (moves_with_pair=False), a
        # state constraint, only along the translations its rows do not see (H c = 0)
        if self.moves_with_pair:
            return np.zeros((0, system.n))
        return np.asarray(system.state_constraints[self.region].H, dtype=float)

    def grid(self, d):
        return (len(step_indices(self.steps, d.L)), d.Zv.shape[0], d.sets[self.region].H.shape[0])

    def lhs(self, d, x):
        s = step_indices(self.steps, d.L)
        q = x.p[..., s, None, :] + x.eps[..., s, None, None] * d.Zv          # (..., S, n_v, n)
        return q @ d.sets[self.region].H.T

    def rhs(self, d):
        h = d.sets[self.region].h
        return h[..., None, None, :]


@dataclass(frozen=True)
class Dynamics(RowFamily):
    """C4: the successor of every tube vertex lies in the next cross-section, for every ``w``."""

    name: str = "dynamics"
    compress_vertices: bool = False
    disturbed = True                     # rhs: -sigma_W(H_z)

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

    def invariance_rows(self, system):
        # H_z (A (q + c) + B u - (p + c)) = H_z (A q + B u - p) + H_z (A - I) c
        return exact_matrix(system.A, minus_identity=True)


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
class InputIn(RegionRows):
    """C5: ``u_k(l) in U``; variable bounds for a box ``U``, hard rows otherwise. The tube's and the
    open loop's family alike (``V``: the source vertices, one input sequence each)."""

    name: str = "input"
    region: str = "input"
    compress_vertices: bool = False

    def grid(self, d):
        return (d.L, d.V.shape[-2], d.sets["input"].H.shape[0])

    def lp_role(self, d, u_is_box):
        return "bound" if u_is_box else "hard"

    def lhs(self, d, x):
        return x.u @ d.sets["input"].H.T

    def rhs(self, d):
        return d.sets["input"].h


#: Problem 2, in the LP's row order.
TUBE_FAMILIES: tuple = (VertexIn("safe", "safe", "interior"), VertexIn("target", "target", "last"),
                        VertexIn("X", "X", "all", moves_with_pair=False), Dynamics(), EpsMin(), InputIn())


#: The sets of every problem that come from the pair, not from the system (:func:`region_sets`).
PAIR_REGIONS = ("safe", "target")


def system_sets(system) -> dict:
    """The sets of ``system`` the families' ``region`` names stand for: ``'input'`` (``U``) and
    the state constraints it sets, by field name
    (:attr:`~tubejax.model.system.LinearSystem.state_constraints`). The one place a system's sets
    are named: :func:`system_regions` and :func:`region_sets` both read it."""
    return {"input": system.U, **system.state_constraints}


def system_regions(system) -> frozenset:
    """The region names a problem of ``system`` has: :data:`PAIR_REGIONS` and the keys of
    :func:`system_sets` (``'input'`` and the state constraints the system sets)."""
    return frozenset((*PAIR_REGIONS, *system_sets(system)))


def translation_groups(system, families=TUBE_FAMILIES) -> np.ndarray:
    """The groups of axes along which translated pairs have the same problem up to the translation,
    shape ``(n,)`` of int (:func:`~tubejax.model.system.translation_groups`): the translations every
    family is invariant under (:meth:`RowFamily.invariance_rows`). For Problem 2 these are the ones
    ``A`` fixes, less those a state constraint's rows see."""
    rows = [np.asarray(f.invariance_rows(system), dtype=object).reshape(-1, system.n)
            for f in active(families, system_regions(system))]
    return kernel_groups(np.concatenate(rows) if rows else np.zeros((0, system.n), dtype=object))


def step_regions(L: int, families=TUBE_FAMILIES) -> tuple:
    """The set that holds the cross-section ``Q_l = co{q_k(l)}`` for ``l = 1 .. L``, by name: the
    region of the family over a pair's set (a :class:`VertexIn` that moves with the pair) covering
    step ``l`` -- ``'safe'`` for ``l < L``, ``'target'`` at ``l = L`` in :data:`TUBE_FAMILIES`. Its
    bounding box bounds ``p_l`` (``0`` lies in ``Z``, so ``p_l`` lies in ``Q_l``) and its axis widths
    ``eps_l`` (:func:`implied_eps_bounds`): the variable bounds every arithmetic derives."""
    out = [None] * L
    for f in families:
        if isinstance(f, VertexIn) and f.moves_with_pair:
            for i in step_indices(f.steps, L):
                out[i] = out[i] or f.region
    if None in out:
        raise FamilyDataError(f"no family over a pair's set covers step {out.index(None) + 1} of {L}: "
                              "the tube LP's variable bounds need one")
    return tuple(out)


def implied_eps_bounds(w_set, w_Z, w_W, eps_min, xp=np, meet: bool = False) -> tuple:
    """The bounds on ``eps_l`` that Problem 2 implies, from axis widths ``w = sigma(e_i) + sigma(-e_i)``:
    ``Q_l = p_l + eps_l Z`` holds a translate of ``W`` (C4) and fits in its set
    (:func:`step_regions`), so along each axis ``w_W <= eps_l w_Z <= w_set``, and ``eps_l >= eps_min``
    (C1). The one formula of the float LP's bounds, the exact bounds and the learned ``Z``'s
    Lagrangian, in the arithmetic of the widths (``xp``: NumPy, also for object arrays of
    Fractions, or ``jax.numpy``).

    Parameters
    ----------
    w_set, w_Z, w_W : arrays, shape (..., n)
    eps_min : scalar or array, shape (...)
    meet : bool
        Where the bounds cross, raise the upper to ``eps_min`` and lower the lower to the upper: the
        bounds of a float LP, which must have a point (its margin is then negative).

    Returns
    -------
    lo, hi : arrays, shape (...)
        ``max(eps_min, max_i w_W,i / w_Z,i)`` and ``min_i w_set,i / w_Z,i``; they cross (``lo > hi``)
        exactly when Problem 2 is infeasible on these grounds.
    """
    lo, hi = xp.maximum(eps_min, xp.max(w_W / w_Z, axis=-1)), xp.min(w_set / w_Z, axis=-1)
    if meet:
        hi = xp.maximum(hi, eps_min)
        lo = xp.minimum(lo, hi)
    return lo, hi


def tube_residuals(d: TubeTerms, x: TubeVars, families=TUBE_FAMILIES) -> list:
    """``(name, lhs - rhs, scale)`` of every family: a row holds iff its residual is ``<= 0``.

    Residuals have shape ``(..., *grid)``; ``scale`` has shape ``(grid[-1],)``.
    """
    return [(f.name, f.lhs(d, x) - f.rhs(d), f.scale(d)) for f in families_in(families, d)]


def tube_identity(d: TubeTerms, m: int) -> TubeVars:
    """Every unit vector of the ``TubeIndex(L, n, n_v, m)`` layout as a batch of tubes, in the
    arithmetic of ``d`` (float64: read-only and shared, the last few layouts' kept)."""
    L, (nv, n) = d.L, d.Zv.shape
    if isinstance(d.A, np.ndarray):
        return _float_identity(int(L), int(n), int(nv), int(m))
    size = L * n + L + L * nv * m
    eye = type(d.A)(np.eye(size, dtype=np.int64).astype(object), 1)
    return _identity_vars(eye, L, n, nv, m)


@lru_cache(maxsize=8)
def _float_identity(L: int, n: int, nv: int, m: int) -> TubeVars:
    eye = np.eye(L * n + L + L * nv * m)
    eye.setflags(write=False)
    return _identity_vars(eye, L, n, nv, m)


def _identity_vars(eye, L: int, n: int, nv: int, m: int) -> TubeVars:
    size = L * n + L + L * nv * m
    return TubeVars(eye[:, :L * n].reshape(size, L, n), eye[:, L * n:L * n + L],
                    eye[:, L * n + L:].reshape(size, L, nv, m))


def region_sets(prob) -> dict:
    """The sets the families' ``region`` names stand for in ``prob``: ``'safe'`` (``S``),
    ``'target'`` (``P_j``), ``'input'`` (``U``), each a :class:`~tubejax.model.geometry.Polytope`,
    and the system's state constraints by field name (:class:`~tubejax.model.geometry.Halfspaces`):
    its keys are :func:`system_regions` ``(prob.system)``."""
    return {"safe": prob.safe, "target": prob.target, **system_sets(prob.system)}


def float_terms(prob, V=None, h=None) -> TubeTerms:
    """:class:`TubeTerms` of a :class:`~tubejax.model.problem.TubeProblem` in float64.

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
                     rows(Z, "Z"), support(sysm.W, Z.H), sets, np.array([float(prob.eps_min)]), np.concatenate,
                     system_regions(sysm))
