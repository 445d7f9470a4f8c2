"""The variables of the tube LP (Problem 2, docs/math/tube-lp.md): where each sits in ``x``
(:class:`TubeIndex`), a candidate tube (:class:`Tube`) and the finite bounds Problem 2 implies on each.

The bounds on ``p`` and ``eps`` are implied by C2-C4 at ``t >= 0``, so they change neither feasibility nor
nonnegative margins; they box every variable, which the weak-duality certificates of
:mod:`tubejax.lp.engines.certify` need. C1 and a box ``U`` (C5) are variable bounds (:data:`BOUND_FAMILIES`).
:func:`implied_bounds` derives them once, in any arithmetic: the float LP's (:func:`tube_variable_bounds`)
and the exact ones of a certificate (:func:`~tubejax.lp.evidence.rows.implied_tube_bounds`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ...model.geometry import Polytope
from ...model.problem import TubeProblem
from ...model.zshape.kinds import source_points
from .row_families import FamilyDataError, role_names
from .tube_families import TUBE_FAMILIES, implied_eps_bounds, region_sets, step_regions, system_regions

__all__ = ["TubeIndex", "Tube", "tube_index", "axis_widths", "within_box", "implied_bounds", "input_bounds",
           "tube_variable_bounds", "tube_variable_bounds_batch", "BOUND_FAMILIES", "check_bound_families"]


class TubeIndex(NamedTuple):
    """Layout of ``x`` for given ``L, n, n_v, m``."""

    L: int
    n: int
    n_v: int
    m: int

    @property
    def size(self) -> int:
        return self.L * self.n + self.L + self.L * self.n_v * self.m

    @property
    def p(self) -> slice:
        return slice(0, self.L * self.n)

    @property
    def eps(self) -> slice:
        return slice(self.L * self.n, self.L * self.n + self.L)

    @property
    def u(self) -> slice:
        return slice(self.L * self.n + self.L, self.size)

    def p_col(self, ell: int, d: int) -> int:
        """Column of ``p_ell[d]``, ``ell = 1..L``."""
        return (ell - 1) * self.n + d

    def eps_col(self, ell: int) -> int:
        """Column of ``eps_ell``, ``ell = 1..L``."""
        return self.L * self.n + ell - 1

    def u_col(self, ell: int, k: int, d: int) -> int:
        """Column of ``u_k(ell)[d]``, ``ell = 0..L-1``."""
        return self.L * self.n + self.L + (ell * self.n_v + k) * self.m + d

    def split(self, x) -> "Tube":
        """``x`` of shape ``(size,)`` (a trailing ``t`` is ignored) -> :class:`Tube`."""
        x = np.asarray(x, float)
        return Tube(x[self.p].reshape(self.L, self.n), x[self.eps].copy(),
                    x[self.u].reshape(self.L, self.n_v, self.m))

    def pack(self, tube: "Tube") -> np.ndarray:
        """:class:`Tube` -> ``x`` of shape ``(size,)``."""
        return np.concatenate([np.ravel(tube.p), np.ravel(tube.eps), np.ravel(tube.u)])


class Tube(NamedTuple):
    """A candidate tube: ``p (L, n)``, ``eps (L,)``, ``u (L, n_v, m)``."""

    p: np.ndarray
    eps: np.ndarray
    u: np.ndarray

    def vertices(self, Z: Polytope, source: Polytope) -> np.ndarray:
        """Tube vertices ``q_k(l)``, shape ``(L + 1, n_v, n)`` (``l = 0``: the source cell's points
        that ``Z``'s vertices pair with, :func:`~tubejax.model.zshape.kinds.source_points`)."""
        q = self.p[:, None, :] + self.eps[:, None, None] * Z.vertices[None, :, :]
        return np.concatenate([source_points(source, Z.n_vertices).vertices[None], q], axis=0)


def tube_index(prob: TubeProblem) -> TubeIndex:
    """The :class:`TubeIndex` of ``prob``'s variables."""
    return TubeIndex(int(prob.L), prob.system.n, prob.source.n_vertices, prob.system.m)


def axis_widths(S) -> np.ndarray:
    """The widths ``sigma_S(e_i) + sigma_S(-e_i)`` of a set along the axes, shape ``(n,)``, in its own
    arithmetic: ``2 r`` for a ball (``radius`` a float or a Fraction), else its bounding box's
    (a :class:`~tubejax.model.geometry.Polytope`, or an exact polytope's rational box)."""
    if hasattr(S, "radius"):
        return np.full(S.dim, 2 * S.radius)
    lo, hi = S.bounding_box()
    return hi - lo


def within_box(lo, hi, box_lo, box_hi) -> tuple:
    """A set's bounding box ``lo, hi`` (float arrays, shape ``(..., n)``) within a pair's box: the float
    LP's box of ``p_l``; where the two miss, the upper is raised to the lower."""
    lo, hi = np.maximum(lo, box_lo), np.minimum(hi, box_hi)
    return lo, np.maximum(hi, lo)


def implied_bounds(ix: TubeIndex, boxes: dict, w_Z, w_W, eps_min, u_box, L: int | None = None,
                   meet: bool = False) -> tuple:
    """The bounds Problem 2 implies on every variable of the layout ``ix``, in the arithmetic of the data
    (float64 with leading batch axes ``...``, or Fractions in object arrays): the one derivation of the
    float LP's bounds and the exact ones a certificate uses.

    Since ``0`` lies in ``Z``, ``p_l`` lies in its step's set (:func:`~.tube_families.step_regions`,
    steps beyond ``L`` that of step 1): its bounds are that set's box; ``eps``'s are
    :func:`~.tube_families.implied_eps_bounds` of the box's widths; ``u`` lies in ``U``'s box (C5).

    Parameters
    ----------
    ix : TubeIndex
    boxes : dict of str to (lo, hi)
        The box of each set :func:`~.tube_families.step_regions` names, arrays of shape ``(..., n)``.
    w_Z, w_W : arrays, shape (..., n)
        The axis widths of ``Z`` and ``W`` (:func:`axis_widths`).
    eps_min : scalar or array, shape (...)
    u_box : (lo, hi), arrays of shape (m,)
        ``U``'s bounding box.
    L : int, optional
        The problem's horizon, ``<= ix.L`` (default ``ix.L``).
    meet : bool
        Where ``eps``'s bounds cross (Problem 2 infeasible, ``t* < 0``), make them meet, as the float
        LP must (:func:`~.tube_families.implied_eps_bounds`); the exact bounds stay crossed, a refutation.

    Returns
    -------
    lb, ub : arrays, shape (..., ix.size)
    """
    L = ix.L if L is None else int(L)
    regions = step_regions(L) + step_regions(ix.L)[:1] * (ix.L - L)
    eps = {r: implied_eps_bounds(hi - lo, w_Z, w_W, eps_min, meet=meet) for r, (lo, hi) in boxes.items()}
    lb = np.empty(np.shape(eps_min) + (ix.size,), np.asarray(w_Z).dtype)
    ub = np.empty_like(lb)
    for ell, r in enumerate(regions, start=1):
        p = slice(ix.p_col(ell, 0), ix.p_col(ell, 0) + ix.n)
        lb[..., p], ub[..., p] = boxes[r]
        lb[..., ix.eps_col(ell)], ub[..., ix.eps_col(ell)] = eps[r]
    lb[..., ix.u], ub[..., ix.u] = input_bounds(ix, u_box)
    return lb, ub


def input_bounds(ix, u_box) -> tuple:
    """C5 for a box ``U``: ``U``'s box ``(lo, hi)`` (arrays of shape ``(m,)``, any arithmetic) over the
    inputs of a tube or open-loop layout ``ix``, each of shape ``(ix.L * ix.n_v * m,)``."""
    return tuple(np.tile(b, ix.L * ix.n_v) for b in u_box)


def tube_variable_bounds(prob: TubeProblem, L_pad: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The float LP's bounds on every variable: :func:`implied_bounds`, each implied by Problem 2 with
    margin ``t >= 0``, the box of ``p_l`` within ``prob.box`` (:func:`within_box`).

    Parameters
    ----------
    prob : TubeProblem
    L_pad : int, optional
        Horizon of the layout (``>= prob.L``; steps beyond ``L`` get the bounds of ``S``).

    Returns
    -------
    lb, ub : ndarray, shape ``(TubeIndex(L_pad, n, n_v, m).size,)``
    """
    lb, ub = tube_variable_bounds_batch([prob], L_pad)
    return lb[0], ub[0]


def tube_variable_bounds_batch(problems, L_pad: int | None = None,
                               disturbance: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """:func:`tube_variable_bounds` of problems sharing ``(n, m, n_v)``, shape ``(B, n_x)`` each.

    ``disturbance=False`` drops the one bound that depends on ``W`` (``eps_l >= width(W) / width(Z)``):
    the rest holds for every disturbance, e.g. every ``rho >= 0`` of the radius form ``W = rho W_0``.
    """
    p0 = problems[0]
    Ls = np.array([int(p.L) for p in problems])
    ix = TubeIndex(int(Ls.max()) if L_pad is None else int(L_pad), p0.system.n, p0.source.n_vertices, p0.system.m)
    distinct = {id(S): S for p in problems for S in (p.Z, p.system.W)}         # usually one Z per cell shape
    width = {k: axis_widths(S) for k, S in distinct.items()}
    lb = np.empty((len(problems), ix.size))
    ub = np.empty_like(lb)
    for L in np.unique(Ls).tolist():
        at = np.flatnonzero(Ls == L)
        group = [problems[b] for b in at]
        box = [np.array([p.box[k] for p in group], float) for k in (0, 1)]
        sets = [region_sets(p) for p in group]
        boxes = {}
        for r in set(step_regions(L) + step_regions(ix.L)[:1]):
            lo, hi = (np.array(b) for b in zip(*(s[r].bounding_box() for s in sets)))      # (B_L, n) each
            boxes[r] = within_box(lo, hi, *box)
        w_Z = np.array([width[id(p.Z)] for p in group])
        w_W = np.array([width[id(p.system.W)] for p in group]) if disturbance else np.zeros_like(w_Z)
        lb[at], ub[at] = implied_bounds(ix, boxes, w_Z, w_W, np.array([float(p.eps_min) for p in group]),
                                        p0.system.u_box(), L, meet=True)
    return lb, ub


#: The families with the ``bound`` role that :func:`tube_variable_bounds` writes as variable bounds
#: (C1 and a box ``U``'s C5). Another family with that role is refused (:func:`check_bound_families`).
BOUND_FAMILIES = ("eps_min", "input")


def check_bound_families(system, families=None) -> None:
    """Refuse (:class:`FamilyDataError`, naming it) a family with the ``bound`` role that the
    variable bounds do not model: the LP would be built without it."""
    fams = TUBE_FAMILIES if families is None else families
    extra = [nm for nm in role_names(fams, system_regions(system), system.u_is_box).get("bound", ())
             if nm not in BOUND_FAMILIES]
    if extra:
        raise FamilyDataError(f"row family {extra[0]!r}: its role is 'bound', but the tube LP's variable bounds "
                              f"model only {', '.join(BOUND_FAMILIES)}; give it the 'hard' role or write its bounds "
                              "in tube_variable_bounds_batch")
