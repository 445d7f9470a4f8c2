"""The variables of the tube LP (Problem 2, docs/math/tube-lp.md): where each sits in ``x``
(:class:`TubeIndex`), a candidate tube (:class:`Tube`) and the finite bounds Problem 2 implies on each.

The bounds on ``p`` and ``eps`` (:func:`tube_variable_bounds`) are implied by C2-C4 at ``t >= 0``, so they
change neither feasibility nor nonnegative margins; they box every variable, which the weak-duality
certificates of :mod:`tubejax.lp.engines.certify` need. C1 and a box ``U`` (C5) are variable bounds
(:data:`BOUND_FAMILIES`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ...model.geometry import Polytope, support
from ...model.problem import TubeProblem
from ...model.zshape.kinds import source_points
from .row_families import FamilyDataError, role_names
from .tube_families import TUBE_FAMILIES, implied_eps_bounds, region_sets, step_regions, system_regions

__all__ = ["TubeIndex", "Tube", "tube_index", "tube_variable_bounds", "tube_variable_bounds_batch",
           "BOUND_FAMILIES", "check_bound_families"]


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


def tube_variable_bounds(prob: TubeProblem, L_pad: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Finite bounds on every variable, each implied by Problem 2 with margin ``t >= 0``.

    Since ``0`` lies in ``Z``, ``p_l`` lies in its step's set (:func:`~.tube_families.step_regions`):
    its bounds are that set's bounding box (within ``prob.box``); ``eps``'s are
    :func:`~.tube_families.implied_eps_bounds`, ``u`` is boxed by ``U``. Where bounds cross (then
    ``t* < 0``) the lower is lowered to the upper.

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


def _axis_width(S, n: int) -> np.ndarray:
    """Widths ``sigma_S(e_i) + sigma_S(-e_i)`` along the axes, shape ``(n,)``."""
    if isinstance(S, Polytope):
        lo, hi = S.bounding_box()
        return hi - lo
    I = np.eye(n)
    return support(S, I) + support(S, -I)


def tube_variable_bounds_batch(problems, L_pad: int | None = None,
                               disturbance: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """:func:`tube_variable_bounds` of problems sharing ``(n, m, n_v)``, shape ``(B, n_x)`` each.

    ``disturbance=False`` drops the one bound that depends on ``W`` (``eps_l >= width(W) / width(Z)``):
    the rest holds for every disturbance, e.g. every ``rho >= 0`` of the radius form ``W = rho W_0``.
    """
    p0 = problems[0]
    sysm = p0.system
    n, m, nv = sysm.n, sysm.m, p0.source.n_vertices
    Ls = np.array([int(p.L) for p in problems])
    Lp = int(Ls.max()) if L_pad is None else int(L_pad)
    ix = TubeIndex(Lp, n, nv, m)
    B = len(problems)
    blo = np.array([p.box[0] for p in problems], float)
    bhi = np.array([p.box[1] for p in problems], float)
    width: dict = {}                        # per distinct set object (usually one Z per cell shape)

    def widths(S):
        if id(S) not in width:
            width[id(S)] = _axis_width(S, n)
        return width[id(S)]

    wz = np.array([widths(p.Z) for p in problems])                              # (B, n)
    ww = np.array([widths(p.system.W) for p in problems]) if disturbance else np.zeros((B, n))
    emin = np.array([float(p.eps_min) for p in problems])
    steps = {L: step_regions(L) for L in set(Ls.tolist()) | {Lp}}
    names = sorted({r for regs in steps.values() for r in regs})
    sets = [region_sets(p) for p in problems]
    out = []                                # per region: p's box and eps's bounds, (B, n) (B, n) (B,) (B,)
    for name in names:
        bb = [s[name].bounding_box() for s in sets]
        lo = np.maximum(np.array([b[0] for b in bb]), blo)
        hi = np.minimum(np.array([b[1] for b in bb]), bhi)
        hi = np.maximum(hi, lo)
        e_lo, e_hi = implied_eps_bounds(hi - lo, wz, ww, emin)
        e_hi = np.maximum(e_hi, emin)       # where they cross (then t* < 0) the lower is lowered to the upper
        out.append((lo, hi, np.minimum(e_lo, e_hi), e_hi))
    # step l of problem b: its set (step_regions); steps beyond its L get an interior step's (S)
    region = np.array([[names.index(r) for r in steps[L] + steps[Lp][:1] * (Lp - L)] for L in Ls.tolist()])

    def pick(k):
        return np.stack([o[k] for o in out])[region, np.arange(B)[:, None]]         # (B, Lp, ...)

    lb = np.empty((B, ix.size))
    ub = np.empty((B, ix.size))
    lb[:, ix.p] = pick(0).reshape(B, Lp * n)
    ub[:, ix.p] = pick(1).reshape(B, Lp * n)
    lb[:, ix.eps] = pick(2)
    ub[:, ix.eps] = pick(3)
    ulo, uhi = sysm.u_box()
    lb[:, ix.u] = np.tile(ulo, Lp * nv)
    ub[:, ix.u] = np.tile(uhi, Lp * nv)
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
