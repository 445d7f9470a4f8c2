"""The open-loop operator's data: which families it models, and the group's rows read off the declaration.

:func:`build_openloop_data` stacks problems of one system as :class:`~.openloop_operator.OpenLoopData`
from the dense rows the families derive (and, for a non-box ``U``,
:func:`~.margin_operator.input_block`). :func:`openloop_unmodelled` names any family the operator
does not model; a problem with one goes to HiGHS whole.
"""

from __future__ import annotations

import dataclasses
from typing import Sequence

import numpy as np

from .row_families import FamilyDataError, active, dense_rhs, dense_rows, state_lengths, zero_row_rule
from ...model.problem import TubeProblem
from .tube_families import InputIn, system_regions
from .margin_operator import InputBlock, OperatorShape, batched_input_block, input_facets, over_batch, padded_horizon
from .openloop_lp import OpenLoopIndex
from .tube_variables import input_bounds
from .openloop_families import OPENLOOP_FAMILIES, NominalIn, float_plan_terms, plan_identity
from .openloop_operator import OpenLoopData

__all__ = ["openloop_shape", "build_openloop_data", "openloop_unmodelled"]


def _powers(A: np.ndarray, L: int) -> list[np.ndarray]:
    out = [np.eye(A.shape[0])]
    for _ in range(L):
        out.append(A @ out[-1])
    return out


#: The families the open-loop operator models, by role and kind, in declaration order.
_MODELLED = {"margin": ((NominalIn, "safe"), (NominalIn, "target")), "bound": ((InputIn, "input"),),
             "hard": ((InputIn, "input"),)}


def openloop_unmodelled(system) -> tuple:
    """The families of ``system``'s open-loop LP that the operator does not model, by name (read
    from the declaration, :data:`~.openloop_families.OPENLOOP_FAMILIES`): the operator models the ``safe``
    and ``target`` margin families and the ``input`` family as bounds (a box ``U``) or as hard rows.
    A problem with another family goes to HiGHS whole, never to an operator without its rows."""
    out, seen = [], {}
    for f in active(OPENLOOP_FAMILIES, system_regions(system)):
        role = f.lp_role(None, system.u_is_box)
        want = _MODELLED.get(role, ())
        k = seen.get(role, 0)
        seen[role] = k + 1
        if k >= len(want) or not (isinstance(f, want[k][0]) and f.name == want[k][1]):
            out.append(f.name)
    return tuple(out)


def _input_rows(p0: TubeProblem, B: int) -> InputBlock:
    """The hard input rows of ``p0``'s system for a batch of ``B``, read off the declaration's dense
    hard rows at horizon 2 (:func:`~.margin_operator.input_block`)."""
    sysm = p0.system
    d = float_plan_terms(dataclasses.replace(p0, L=2))
    G, g, _ = dense_rows(d, sysm.m, "hard", sysm.u_is_box, OPENLOOP_FAMILIES, plan_identity)
    return batched_input_block(G, g, OpenLoopIndex(2, p0.source.n_vertices, sysm.m),
                               input_facets(sysm, OPENLOOP_FAMILIES), "open-loop", B)


def openloop_shape(prob: TubeProblem, L: int | None = None, f_s: int | None = None,
                   f_t: int | None = None) -> OperatorShape:
    """The :class:`OperatorShape` of a problem (optionally padded)."""
    s = prob.system
    L = int(prob.L) if L is None else int(L)
    Ap = _powers(s.A, L)
    ab = np.stack([Ap[k] @ s.B for k in range(L)])
    return OperatorShape(L, s.n, s.m, prob.source.n_vertices, f_u=input_facets(s, OPENLOOP_FAMILIES),
                         f_s=prob.safe.H.shape[0] if f_s is None else int(f_s),
                         f_t=prob.target.H.shape[0] if f_t is None else int(f_t),
                         ab=tuple(float(v) for v in ab.ravel()))


def _group_rows(group: Sequence[TubeProblem], W0):
    """The rows of problems sharing their horizon and facet normals, derived from the row families.

    Returns
    -------
    dict of str to ``(a, g, keep, c, C)`` per family (``'safe'``, ``'target'``), with ``s`` steps:
    a : ndarray, shape (s, f, n)        each row's unit state-space normal (0 on a row without input
                                        dependence: the operator's coefficients are ``a . w_k(l)``)
    g : ndarray, shape (K, s, n_v, f)   each problem's right-hand sides, per unit of the normal
    keep : ndarray, shape (K, s, n_v, f)  the row is in the LP (a zero row only when it binds)
    c : ndarray, shape (s, f)           radius form: ``rho``'s coefficient (0 in the margin form)
    C : ndarray, shape (s, f, L, m)     the coefficient of ``u_k(t)[j]`` in row ``(l, k, f)`` of the
                                        normalised LP (the same for every vertex ``k``; 0 on a row
                                        without input dependence): the dense rows' vertex block
    """
    p0 = group[0]
    sysm = p0.system
    fams = OPENLOOP_FAMILIES
    d0 = float_plan_terms(p0, W=None if W0 is not None else "system")
    G, _, layout = dense_rows(d0, sysm.m, "margin", sysm.u_is_box, fams, plan_identity)
    lengths = state_lengths(d0, "margin", sysm.u_is_box, lambda H: np.linalg.norm(H, axis=1), fams)
    sets = dict(d0.sets, **{r: d0.sets[r]._replace(h=np.array([getattr(p, r).h for p in group]))
                            for r in ("safe", "target")})
    terms = d0._replace(V=np.array([p.source.vertices for p in group]), sets=sets)
    g = dense_rhs(terms, "margin", sysm.u_is_box, fams)                         # (K, R)
    c = (dense_rhs(d0, "margin", sysm.u_is_box, fams)
         - dense_rhs(float_plan_terms(p0, W=W0), "margin", sysm.u_is_box, fams)) if W0 is not None \
        else np.zeros(G.shape[0])
    zero, keep, G = zero_row_rule(G, g, c)
    unit = G / lengths[:, None]                                                 # (R, L n_v m)
    L, nv = int(p0.L), p0.source.n_vertices
    out = {}
    for f in fams[:2]:
        sl, grid = layout.slice(f.name), layout.shape(f.name)                   # grid (s, n_v, f)
        normals = np.where(zero[sl].reshape(grid)[:, 0, :, None], 0.0,
                           (f.normals(d0) / f.scale(d0)[:, None])[None])        # (s, f, n)
        coef = unit[sl].reshape(grid + (L, nv, sysm.m))[:, 0, :, :, 0]          # vertex 0's block
        out[f.name] = (normals, (g[:, sl] / lengths[sl]).reshape((len(group),) + grid),
                       keep[:, sl].reshape((len(group),) + grid), (c[sl] / lengths[sl]).reshape(grid)[:, 0], coef)
    return out


def build_openloop_data(problems: Sequence[TubeProblem], L_pad: int | None = None,
                        f_s: int | None = None, f_t: int | None = None,
                        W0=None) -> tuple[OperatorShape, OpenLoopData]:
    """Stack the geometry of problems sharing one system and ``n_v`` (horizons may differ).

    Parameters
    ----------
    problems : sequence of TubeProblem, length B (``Z`` is ignored)
    L_pad : int, optional
        Padded horizon (default: the largest ``L``). Rows beyond an instance's own
        horizon are masked; its inputs beyond ``L`` are only boxed, so margins and
        certificates are unchanged.
    f_s, f_t : int, optional
        Padded facet counts (default: the largest in the group).
    W0 : Ball or Polytope, optional
        The radius form for ``W = rho W0`` (see the module docstring): the problems' own
        ``W`` is ignored, ``cS`` / ``cT`` are filled and ``shape.form`` is ``'radius'``.

    Returns
    -------
    shape : OperatorShape
    data : OpenLoopData of NumPy float64 arrays, batch axis last

    Raises
    ------
    FamilyDataError
        When the system's LP has a family the operator does not model (:func:`openloop_unmodelled`).
    """
    p0 = problems[0]
    sysm = p0.system
    missing = openloop_unmodelled(sysm)
    if missing:
        raise FamilyDataError(f"row family {missing[0]!r}: the open-loop operator does not model it, so these "
                              "problems have no operator data (their formulation sends them to HiGHS)")
    n, m = sysm.n, sysm.m
    nv = p0.source.n_vertices
    for p in problems:
        if p.system is not sysm or p.source.n_vertices != nv:
            raise ValueError("build_openloop_data needs one system and equal n_v in a group")
    L, last_step, _, within_horizon = padded_horizon(problems, L_pad)
    f_s = max(p.safe.H.shape[0] for p in problems) if f_s is None else int(f_s)
    f_t = max(p.target.H.shape[0] for p in problems) if f_t is None else int(f_t)
    radius = W0 is not None
    shape = openloop_shape(p0, L, f_s, f_t)._replace(form="radius" if radius else "margin")
    Bsz = len(problems)
    # per family (steps, B, ...): a, g, mask, c, C; the target's one step is dropped at the end
    out = {name: (np.zeros((s, Bsz, f, n)), np.zeros((s, Bsz, nv, f)), np.zeros((s, Bsz, nv, f)),
                  np.zeros((s, Bsz, f)), np.zeros((s, Bsz, f, L, m)))
           for name, s, f in (("safe", L - 1, f_s), ("target", 1, f_t))}
    groups: dict = {}
    for b, p in enumerate(problems):        # rows shared by a horizon and the facet normals
        groups.setdefault((int(p.L), p.safe.H.tobytes(), p.target.H.tobytes()), []).append(b)
    for idx in groups.values():
        rows = _group_rows([problems[b] for b in idx], W0)
        for name, (a_, g_, m_, c_, C_) in out.items():
            a, g, keep, c, C = rows[name]
            s, f = a.shape[0], a.shape[1]
            a_[:s, idx, :f] = a[:, None]
            C_[:s, idx, :f, :C.shape[2]] = C[:, None]
            g_[:s, idx, :, :f] = np.where(keep, g, 0.0).swapaxes(0, 1)
            m_[:s, idx, :, :f] = keep.swapaxes(0, 1)
            c_[:s, idx, :f] = c[:, None]
    (aS, gS, mS, cS, CS), (aT, gT, mT, cT, CT) = (
        [np.ascontiguousarray(np.moveaxis(v, 1, -1)) for v in out[name]] for name in ("safe", "target"))
    aT, gT, mT, cT, CT = aT[0], gT[0], mT[0], cT[0], CT[0]                      # (s, ..., B) -> (..., B)
    x_lower, x_upper = (over_batch(b, Bsz) for b in input_bounds(OpenLoopIndex(L, nv, m), sysm.u_box()))
    data = OpenLoopData(aS=aS, aT=aT, last_step=last_step, gS=gS, gT=gT, mS=mS, mT=mT, x_lower=x_lower, x_upper=x_upper,
                        within_horizon=within_horizon, CS=CS, CT=CT)
    if radius:
        data = data._replace(cS=cS, cT=cT)
    if shape.f_u:                                       # one U per group: the same rows for all
        data = data._replace(input_rows=_input_rows(p0, Bsz))
    return shape, data
