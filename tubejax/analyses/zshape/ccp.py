"""Configuration-constrained polytopic tubes (2-D): the facet offsets of ``Q_l`` are LP variables.

The comparison asked for in issue 13. Instead of ``Q_l = p_l + eps_l Z`` (a fixed shape), a tube
step is ``Q_l = {x : N x <= y_l}`` for fixed unit normals ``N`` (``F`` of them, counter-clockwise,
consecutive ones less than ``π`` apart) and free offsets ``y_l in R^F``. Its vertices are the
intersections of consecutive facets, ``w_k(y) = [N_{k-1}; N_k]^{-1} [y_{k-1}; y_k]`` (linear in
``y``), and they are the vertices of ``Q_l`` as long as ``y_l`` stays in the configuration cone:
every edge has nonnegative length, ``(w_{k+1}(y) - w_k(y)) . τ_k >= 0`` with ``τ_k`` the
counter-clockwise tangent of facet ``k`` (linear constraints ``E y >= 0``). Then Lemma 1's
interpolating controller works vertex by vertex as for a fixed ``Z``:

* C2 ``H_S w_k(y_l) <= h_S`` (``l = 1 .. L-1``), C3 ``H_j w_k(y_L) <= h_j``;
* C4 ``N (A q + B u_q(l)) <= y_{l+1} - sigma_W(N)`` for ``q`` the source cell's vertices
  (``l = 0``) and the ``w_k(y_l)`` (``l >= 1``), one input per vertex;
* C5 ``u in U``; configuration ``E y_l >= 0`` (hard rows, no margin).

With the normals of a fixed ``Z`` (and ``y_l = N p_l + eps_l h_Z``) every ``Z``-tube is such a
tube, so this class contains the fixed-shape one; with more normals (an octagon) the tube
steps may have more vertices than the cell. Margin form, unit rows and HiGHS as for the tube LP
(:func:`tubejax.lp.solvers.highs.solve_margin_lp`); :func:`ccp_violation` re-checks a tube in
float64, vertex by vertex, independently of the LP assembly.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ...model.geometry import support
from ...lp.formulations.tube.dense import TubeLP
from ...lp.solvers.highs import solve_margin_lp
from ...model.zshape.params import ZFamily, z_facets
from ...model.zshape.kinds import make_z
from ...model.problem import pair_problem
from .learn import candidate_pairs

__all__ = ["CcpTube", "ccp_vertex_maps", "build_ccp_lp", "ccp_violation", "ccp_margin", "octagon_normals",
           "box_normals", "ccp_abstraction", "tube_as_ccp"]


class CcpTube(NamedTuple):
    """``y (L, F)`` facet offsets and ``u`` (``u0 (n_v, m)`` at ``l = 0``, ``u (L-1, F, m)`` after)."""

    y: np.ndarray
    u0: np.ndarray
    u: np.ndarray


def octagon_normals() -> np.ndarray:
    """The 8 unit normals at multiples of ``π/4``, counter-clockwise from ``-y``, shape ``(8, 2)``."""
    a = -np.pi / 2 + np.pi / 4 * np.arange(8)
    return np.stack([np.cos(a), np.sin(a)], axis=1)


def ccp_vertex_maps(N) -> tuple[np.ndarray, np.ndarray]:
    """``Wm (F, 2, F)`` with ``w_k(y) = Wm[k] @ y`` (vertex between facets ``k-1`` and ``k``) and
    ``E (F, F)`` with edge lengths ``E @ y`` (edge ``k`` runs from ``w_k`` to ``w_{k+1}``).

    Raises
    ------
    ValueError
        Normals not unit, not counter-clockwise, or two consecutive ones ``π`` or more apart.
    """
    N = np.asarray(N, float)
    F = N.shape[0]
    if N.ndim != 2 or N.shape[1] != 2 or F < 3 or not np.allclose(np.linalg.norm(N, axis=1), 1.0):
        raise ValueError(f"normals must be >= 3 unit vectors in 2-D, got shape {N.shape}")
    prev = np.roll(N, 1, axis=0)
    cross = prev[:, 0] * N[:, 1] - prev[:, 1] * N[:, 0]
    if np.any(cross <= 1e-9):
        raise ValueError("consecutive normals must turn counter-clockwise by less than pi")
    Wm = np.zeros((F, 2, F))
    for k in range(F):
        inv = np.linalg.inv(np.stack([prev[k], N[k]]))
        Wm[k][:, (k - 1) % F] = inv[:, 0]
        Wm[k][:, k] = inv[:, 1]
    tang = np.stack([-N[:, 1], N[:, 0]], axis=1)
    E = np.einsum("kd,kdf->kf", tang, np.roll(Wm, -1, axis=0) - Wm)
    return Wm, E


def _layout(L, F, nv, m):
    ny = L * F
    nu0 = nv * m
    return ny, nu0, ny + nu0 + (L - 1) * F * m


def build_ccp_lp(prob, N, t_max: float = 1.0) -> TubeLP:
    """The margin-form LP of a CCP tube for a :class:`~tubejax.model.problem.TubeProblem`
    (its ``Z`` is ignored; ``N`` are the normals). Variables ``x = [y (L, F), u0 (n_v, m), u (L-1, F, m)]``.

    Rows (unit-normalised, with ``t``): C2 (``l = 1..L-1``, vertex ``k``, facet of ``S``), C3, C4
    (``l = 0``: cell vertex ``k``; ``l >= 1``: vertex ``k`` of ``Q_l``; facet ``f`` of ``N``). Hard
    rows: the configuration ``-E y_l <= 0`` and C5. Every variable is free.
    """
    sysm = prob.system
    A, B = sysm.A, sysm.B
    n, m = sysm.n, sysm.m
    if n != 2:
        raise ValueError(f"configuration-constrained tubes here are 2-D, got n = {n}")
    N = np.asarray(N, float)
    F = N.shape[0]
    L = int(prob.L)
    V = prob.source.vertices
    nv = V.shape[0]
    Wm, E = ccp_vertex_maps(N)
    ny, nu0, nx = _layout(L, F, nv, m)
    sw = support(sysm.W, N)
    NA, NB = N @ A, N @ B
    blocks, rhs = [], []
    for l in range(1, L + 1):                                   # C2 (l < L) / C3 (l = L), per vertex
        H, h = (prob.safe.H, prob.safe.h) if l < L else (prob.target.H, prob.target.h)
        G = np.zeros((F, H.shape[0], nx))
        G[:, :, (l - 1) * F:l * F] = np.einsum("fd,kdg->kfg", H, Wm)
        blocks.append(G.reshape(-1, nx))
        rhs.append(np.tile(h, F))
    for l in range(L):                                          # C4
        nq = nv if l == 0 else F
        G = np.zeros((nq, F, nx))
        if l == 0:
            g = -sw[None, :] - V @ NA.T                          # (nv, F)
            u0 = G[:, :, ny:ny + nu0].reshape(nq, F, nv, m)
            u0[np.arange(nv), :, np.arange(nv), :] = NB
            G[:, :, ny:ny + nu0] = u0.reshape(nq, F, nu0)
        else:
            g = np.broadcast_to(-sw[None, :], (F, F))
            G[:, :, (l - 1) * F:l * F] = np.einsum("fd,kdg->kfg", NA, Wm)
            s0 = ny + nu0 + (l - 1) * F * m
            ul = G[:, :, s0:s0 + F * m].reshape(F, F, F, m)
            ul[np.arange(F), :, np.arange(F), :] = NB
            G[:, :, s0:s0 + F * m] = ul.reshape(F, F, F * m)
        G[:, np.arange(F), l * F + np.arange(F)] -= 1.0         # -y_{l+1, f}
        blocks.append(G.reshape(-1, nx))
        rhs.append(np.ravel(g))
    G = np.vstack(blocks)
    g = np.concatenate(rhs)
    nrm = np.linalg.norm(G, axis=1)
    G /= nrm[:, None]
    g /= nrm
    Hu, hu = sysm.U.H, sysm.U.h
    nuf = Hu.shape[0]
    cfg = np.zeros((L, F, nx))
    for l in range(L):                                          # configuration: -E y_l <= 0
        cfg[l, :, l * F:(l + 1) * F] = -E / np.linalg.norm(E, axis=1, keepdims=True)
    nin = nv + (L - 1) * F                                      # inputs, in column order
    c5 = np.zeros((nin, nuf, nx))
    c5[:, :, ny:].reshape(nin, nuf, nin, m)[np.arange(nin), :, np.arange(nin), :] = Hu
    hard = np.vstack([cfg.reshape(-1, nx), c5.reshape(-1, nx)])
    hard_rhs = np.concatenate([np.zeros(L * F), np.tile(hu, nin)])
    lb = np.full(nx, -np.inf)
    ub = np.full(nx, np.inf)
    return TubeLP(G, g, np.zeros(len(g), np.int8), hard, hard_rhs, lb, ub, float(t_max), (L, F, nv, m))


def _split(x, L, F, nv, m) -> CcpTube:
    ny, nu0, nx = _layout(L, F, nv, m)
    return CcpTube(x[:ny].reshape(L, F), x[ny:ny + nu0].reshape(nv, m), x[ny + nu0:nx].reshape(L - 1, F, m))


def ccp_violation(prob, N, tube: CcpTube) -> float:
    """Largest violation (unit rows, float64) of a CCP tube, from the geometry, vertex by vertex.

    Checks the configuration (every edge length ``>= 0``, scaled by ``|E_k|``), C2, C3, C4 on
    unit-normalised facets of ``S``, ``P_j`` and ``N``, and C5. ``inf`` for wrong shapes or
    non-finite values.
    """
    sysm = prob.system
    N = np.asarray(N, float)
    F, L = N.shape[0], int(prob.L)
    nv, m = prob.source.n_vertices, sysm.m
    y, u0, u = (np.asarray(a, float) for a in tube)
    if y.shape != (L, F) or u0.shape != (nv, m) or u.shape != (L - 1, F, m):
        return float("inf")
    if not all(np.all(np.isfinite(a)) for a in (y, u0, u)):
        return float("inf")
    Wm, E = ccp_vertex_maps(N)
    w = np.einsum("kdf,lf->lkd", Wm, y)                                    # (L, F, 2)
    viol = [(-(y @ E.T) / np.linalg.norm(E, axis=1)).ravel()]
    if L > 1:
        viol.append((w[:L - 1] @ prob.safe.H.T - prob.safe.h).ravel())
    viol.append((w[L - 1] @ prob.target.H.T - prob.target.h).ravel())
    sw = support(sysm.W, N)
    nxt0 = prob.source.vertices @ sysm.A.T + u0 @ sysm.B.T                  # (nv, 2)
    viol.append((nxt0 @ N.T - y[0] + sw).ravel())
    if L > 1:
        nxt = w[:L - 1] @ sysm.A.T + u @ sysm.B.T                           # (L-1, F, 2)
        viol.append((nxt @ N.T - y[1:, None, :] + sw).ravel())
        viol.append((u @ sysm.U.H.T - sysm.U.h).ravel())
    viol.append((u0 @ sysm.U.H.T - sysm.U.h).ravel())
    return float(max(0.0, max(np.max(v) for v in viol)))


def ccp_margin(prob, N) -> tuple[float, CcpTube | None, float]:
    """HiGHS's margin of the CCP tube LP, the tube and its :func:`ccp_violation` (``inf`` if none)."""
    lp = build_ccp_lp(prob, N)
    res = solve_margin_lp(lp)
    if res.status != "Optimal":
        return float("nan"), None, float("inf")
    tube = _split(res.x, *lp.index)
    return res.margin, tube, ccp_violation(prob, N, tube)


def tube_as_ccp(prob, tube) -> tuple[np.ndarray, CcpTube]:
    """A ``Z``-tube (:class:`~tubejax.lp.formulations.tube.dense.Tube`) as a CCP tube with ``Z``'s normals.

    ``y_l = H_Z p_l + eps_l h_Z``; the inputs of the vertices ``w_k(y_l) = p_l + eps_l z_k`` are the
    tube's, matched by position (2-D polygon ``Z``: facet ``k`` runs from ``z_k`` to ``z_{k+1}``, so
    ``w_k``, between facets ``k-1`` and ``k``, is ``z_k``). Returns ``(N, tube)``.
    """

    z = prob.Z.vertices
    N, h = z_facets(ZFamily("polygon", 2, len(z), len(z)), z, np)      # facet k: edge z_k -> z_{k+1}
    y = tube.p @ N.T + tube.eps[:, None] * h
    return N, CcpTube(y, tube.u[0], tube.u[1:])


def box_normals() -> np.ndarray:
    """The 4 axis normals counter-clockwise from ``-y`` (the box's facets), shape ``(4, 2)``."""
    return octagon_normals()[::2]


def ccp_abstraction(decomp, system, N, *, L_max: int = 10, eps_min: float = 0.0, pruning: bool = True,
                    pairs=None, exact: dict | None = None) -> dict:
    """Algorithm 2 with CCP tubes of normals ``N``: ``{(i, j): (L, margin)}`` with minimal ``L``.

    An edge needs HiGHS's margin ``>= -1e-6`` and its tube to pass :func:`ccp_violation`
    ``<= 1e-9`` (float64; no rational proof for this class here). ``eps_min`` is unused (no
    ``eps``); the pruning is :func:`tubejax.abstraction.candidates.build_candidates` (it holds for any tube).
    ``pairs`` (a set of ``(i, j)``) restricts the pairs solved, e.g. to exact2d's edges, which
    contain every tube's edges; ``exact`` (exact2d's ``{(i, j): (L, margin)}``) does both: only
    its pairs, and none below its horizon (no tube reaches ``P_j`` sooner than any feedback).
    """

    _, keep = candidate_pairs(decomp, system, L_max, pruning)
    found = {}
    for L in range(1, L_max + 1):
        for i, j in np.argwhere(keep[:, :, L - 1]):
            i, j = int(i), int(j)
            if (i, j) in found or (pairs is not None and (i, j) not in pairs):
                continue
            if exact is not None and ((i, j) not in exact or L < exact[(i, j)][0]):
                continue
            prob = pair_problem(decomp, system, make_z("cell", decomp.cells[i]), i, j, L, eps_min)  # Z unused
            t, tube, viol = ccp_margin(prob, N)
            if t >= -1e-6 and viol <= 1e-9:
                found[(i, j)] = (L, t)
    return found
