"""The open-loop LP (docs/math/open-loop.md) declared once, as an ordered list of row families.

The variables are the vertex input sequences ``u`` ``(L, n_v, m)``; the nominal state is
``xbar_k(l) = A^l v_k + w_k(l)``, ``w_k(l) = sum_{t<l} A^{l-1-t} B u_k(t)`` (the linear ``lhs``;
``A^l v_k`` and the tightening :attr:`PlanTerms.sigma_d` are the right-hand side).
:data:`OPENLOOP_FAMILIES`: ``safe`` (``H_S xbar_k(l) <= h_S - sigma_{D_l}(H_S)``, ``l < L``),
``target`` (the same at ``l = L``) and ``input`` (``H_u u_k(l) <= h_u``). Like the tube LP's
families, the one declaration gives the dense rows (:func:`~.openloop_lp.build_openloop_lp`), the
checks (:func:`plan_residuals`), the rational rows, the radius form's rows, the operator's
coefficients and the vertex-LP rows (:func:`step_rows`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable, NamedTuple

import numpy as np

from ...model.geometry import support
from .tube_families import InputIn, system_regions
from .row_families import RegionRows, SetRows, dense_rhs, dense_rows, families_in, step_indices

__all__ = ["PlanVars", "PlanTerms", "NominalIn", "OPENLOOP_FAMILIES", "plan_residuals",
           "plan_identity", "disturbance_sums", "disturbance_support", "float_plan_terms", "step_rows"]


class PlanVars(NamedTuple):
    """An open-loop plan, or a batch of plans: ``u`` of shape ``(..., L, n_v, m)``."""

    u: object


class PlanTerms(NamedTuple):
    """The data of one open-loop problem (or a batch sharing everything but the source), in one
    arithmetic (float64 NumPy arrays or rational QArrays).

    Attributes
    ----------
    L : int
    V : array, shape (..., n_v, n)          source vertices ``v_k``
    A, B : arrays, shapes (n, n), (n, m)
    sets : dict of str to SetRows           ``'safe'`` (``S``), ``'target'`` (``P_j``), ``'input'`` (``U``)
    sigma_d : dict of str to array          per state region, ``sigma_{D_l}(H)`` for ``l = 0..L``,
                                            shape ``(L + 1, f)`` (upper or lower bounds in rationals)
    concat : callable                       ``concat(arrays, axis)`` in this arithmetic
    regions : frozenset of str              the sets the problem's system declares (which families
                                            have rows; each must be in ``sets``)
    """

    L: int
    V: object
    A: object
    B: object
    sets: dict
    sigma_d: dict
    concat: Callable
    regions: frozenset


def _stack_steps(d: PlanTerms, first, step) -> object:
    """``[s_1, .., s_L]`` with ``s_1 = first``, ``s_{l+1} = step(s_l, l)``, stacked on axis ``-3``."""
    out = [first]
    for ell in range(1, d.L):
        out.append(step(out[-1], ell))
    return d.concat([s[..., None, :, :] for s in out], -3)


@dataclass(frozen=True)
class NominalIn(RegionRows):
    """``H xbar_k(l) <= h - sigma_{D_l}(H)`` for every vertex ``k`` and step ``l`` in ``steps``
    (``'interior'``: ``l = 1..L-1``, ``'last'``: ``l = L``)."""

    name: str
    region: str
    steps: str
    compress_vertices: bool = False

    def grid(self, d):
        return (len(step_indices(self.steps, d.L)), d.V.shape[-2], d.sets[self.region].H.shape[0])

    def lhs(self, d, x):
        s = step_indices(self.steps, d.L)
        w = _stack_steps(d, x.u[..., 0, :, :] @ d.B.T,
                         lambda w, ell: w @ d.A.T + x.u[..., ell, :, :] @ d.B.T)      # w_k(1..L)
        return w[..., s, :, :] @ d.sets[self.region].H.T

    def rhs(self, d):
        s = step_indices(self.steps, d.L)
        P = d.sets[self.region]
        free = _stack_steps(d, d.V @ d.A.T, lambda f, ell: f @ d.A.T)                 # A^l v_k, l = 1..L
        return P.h[..., None, None, :] - d.sigma_d[self.region][s + 1][:, None, :] - free[..., s, :, :] @ P.H.T


#: The open-loop LP, in its row order.
OPENLOOP_FAMILIES: tuple = (NominalIn("safe", "safe", "interior"), NominalIn("target", "target", "last"),
                            InputIn())


def plan_residuals(d: PlanTerms, x: PlanVars, families=OPENLOOP_FAMILIES) -> list:
    """``(name, lhs - rhs, scale)`` of every family: a row holds iff its residual is ``<= 0``."""
    return [(f.name, f.lhs(d, x) - f.rhs(d), f.scale(d)) for f in families_in(families, d)]


def plan_identity(d: PlanTerms, m: int) -> PlanVars:
    """Every unit vector of the ``OpenLoopIndex(L, n_v, m)`` layout as a batch of plans, in the
    arithmetic of ``d`` (:func:`~tubejax.lp.declarations.row_families.lp_blocks`' ``identity``)."""
    nv = d.V.shape[-2]
    size = d.L * nv * m
    eye = np.eye(size)
    if not isinstance(d.A, np.ndarray):
        eye = type(d.A)(np.eye(size, dtype=np.int64).astype(object), 1)
    return PlanVars(eye.reshape(size, d.L, nv, m))


def disturbance_sums(H, A, L: int, sigma_w, zero, stack, reduce=lambda a: a):
    """``sigma_{D_l}(H) = sum_{t<l} sigma_W((A^t)^T H_f)`` for ``l = 0 .. L`` in the arithmetic of
    ``H`` and ``A`` (float64, or rational QArrays): the one definition of the open-loop tightening.

    Parameters
    ----------
    H : array, shape (f, n)            facet normals
    A : array, shape (n, n)
    sigma_w : callable                 ``sigma_w(rows (f, n)) -> (f,)``: ``sigma_W`` of each row (in
                                       rationals an upper or a lower bound)
    zero : array, shape (f,)           ``sigma_{D_0}``
    stack : callable                   ``stack(list of (f,)) -> (L + 1, f)``
    reduce : callable                  applied to every product and sum (rationals: lowest terms)

    Returns
    -------
    array, shape (L + 1, f)            row 0 is ``zero``
    """
    acc, P = [zero], None                                     # P = A^t (None: the identity)
    for _ in range(L):
        acc.append(reduce(acc[-1] + sigma_w(H if P is None else reduce(H @ P))))
        P = A if P is None else reduce(A @ P)
    return stack(acc)


def disturbance_support(system, H, L: int, W=None) -> np.ndarray:
    """:func:`disturbance_sums` in float64, shape ``(L + 1, n_f)``, for the system's ``W`` or the
    given ``W``."""
    W = system.W if W is None else W
    H = np.asarray(H, float)
    return disturbance_sums(H, system.A, L, lambda rows: support(W, rows), np.zeros(H.shape[0]), np.stack)


def float_plan_terms(prob, W="system") -> PlanTerms:
    """:class:`PlanTerms` of a :class:`~tubejax.model.problem.TubeProblem` in float64.

    ``W``: the disturbance of ``sigma_D`` (default the system's; ``None``: no disturbance, the
    radius form's right-hand side).
    """
    sysm, L = prob.system, int(prob.L)
    sets = {name: SetRows(P.H, P.h, P.row_norms) for name, P in
            (("safe", prob.safe), ("target", prob.target), ("input", sysm.U))}
    sig = {r: (np.zeros((L + 1, sets[r].H.shape[0])) if W is None else
               disturbance_support(sysm, sets[r].H, L, None if isinstance(W, str) else W))
           for r in ("safe", "target")}
    return PlanTerms(L, prob.source.vertices, sysm.A, sysm.B, sets, sig, np.concatenate, system_regions(sysm))


def step_rows(H: np.ndarray, A: np.ndarray, B: np.ndarray, L: int) -> tuple[np.ndarray, np.ndarray]:
    """The open-loop LP's rows over the facets ``H`` at every step ``l = 1 .. L``, for one source vertex
    and no disturbance tightening: the ``safe`` family taken over all steps, dense, with its right-hand
    side on the state's unit vectors. The vertex LPs (:mod:`tubejax.abstraction.vertex_screen`) read
    their rows here (steps ``< L'`` over ``S ⊖ W``, step ``L'`` over ``P_j ⊖ W``).

    Parameters
    ----------
    H : ndarray, shape (f, n)     facet normals (taken as given: pass unit rows for unit rows)
    A, B : ndarrays, shapes (n, n), (n, m)
    L : int                       the last step

    Returns
    -------
    C : ndarray, shape (L, f, L, m)
        ``C[l - 1, f, t, j]``: the coefficient of ``u(t)[j]`` in the row of facet ``f`` at step
        ``l`` (``H_f A^{l-1-t} B e_j`` for ``t < l``, else 0).
    M : ndarray, shape (L, f, n)
        ``M[l - 1]``: ``H A^l``, the source vertex's coefficient in the row, moved to the
        right-hand side (the row is ``C u <= h - M v``).
    """
    H = np.asarray(H, float)
    n, m, f = A.shape[0], B.shape[1], H.shape[0]
    fams = tuple(replace(fam, steps="all") for fam in OPENLOOP_FAMILIES if fam.name == "safe")
    sets = {"safe": SetRows(H, np.zeros(f), np.ones(f))}
    d = PlanTerms(L, np.zeros((1, n)), A, B, sets, {"safe": np.zeros((L + 1, f))}, np.concatenate,
                  frozenset(sets))
    G, _, _ = dense_rows(d, m, "margin", True, fams, plan_identity)            # rows (l, 1, f), columns (t, 1, j)
    free = dense_rhs(d._replace(V=np.eye(n)), "margin", True, fams)           # (l, vertex e_i, f)
    return G.reshape(L, f, L, m), -free.reshape(L, n, f).swapaxes(1, 2)
