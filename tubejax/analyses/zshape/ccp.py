"""Configuration-constrained polytopic tubes (2-D): the facet offsets of ``Q_l`` are LP variables.

A comparison with learned ``Z``: ``Q_l = {x : N x <= y_l}`` for fixed unit normals ``N`` and free
offsets ``y_l``, kept valid by the configuration cone ``E y >= 0``; it contains every fixed-``Z`` tube
(the LP and why it is sound: docs/howto/learned-z.md#configuration-constrained-tubes). Declared once
as row families (:data:`CCP_FAMILIES`), from which the HiGHS LP and the float64 check
:func:`ccp_violation` derive.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ...model.geometry import support
from ...lp.declarations.row_families import RowFamily, SetRows, dense_rows, state_lengths, step_indices
from ...lp.declarations.tube_lp import TubeLP
from ...lp.declarations.tube_families import InputIn, VertexIn, system_regions
from ...lp.engines.highs import solve_margin_lp
from ...model.zshape.kinds import make_z
from ...model.problem import pair_problem
from .learn import candidate_pairs

__all__ = ["CcpTube", "CcpLP", "CcpVars", "CcpTerms", "CCP_FAMILIES", "ccp_terms", "ccp_identity", "ccp_vertex_maps",
           "build_ccp_lp", "ccp_violation", "ccp_margin", "octagon_normals", "box_normals", "ccp_abstraction"]


class CcpTube(NamedTuple):
    """``y (L, F)`` facet offsets and ``u`` (``u0 (n_v, m)`` at ``l = 0``, ``u (L-1, F, m)`` after)."""

    y: np.ndarray
    u0: np.ndarray
    u: np.ndarray


class CcpLP(TubeLP):
    """The dense margin-form LP of a CCP tube (:func:`build_ccp_lp`): the fields of
    :class:`~tubejax.lp.declarations.tube_lp.TubeLP`, with ``index = (L, F, n_v, m)``.

    Its own type, so that no step that dispatches on an LP's type
    (:func:`~tubejax.lp.evidence.registry.formulation_of`) takes it for the tube LP: it is an analysis
    LP, not an abstraction method (docs/howto/extending.md#an-analysis-lp-is-not-a-method).
    """

    __slots__ = ()


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


class CcpVars(NamedTuple):
    """A CCP tube, or a batch of them (leading axes ``...``): ``y (..., L, F)``, ``u0 (..., n_v, m)``,
    ``u (..., L-1, F, m)`` (the fields of :class:`CcpTube`)."""

    y: object
    u0: object
    u: object


class CcpTerms(NamedTuple):
    """The float64 data of one CCP problem: ``L``, the source vertices ``V (n_v, 2)``, ``A``, ``B``,
    the normals ``N (F, 2)`` with ``sigma_W(N) (F,)``, the vertex maps ``Wm (F, 2, F)``, the edge
    lengths ``E (F, F)`` (:func:`ccp_vertex_maps`), the sets ``'safe'``, ``'target'``, ``'input'``
    and the names of the sets the system declares (``regions``: which families have rows)."""

    L: int
    V: np.ndarray
    A: np.ndarray
    B: np.ndarray
    N: np.ndarray
    sigma: np.ndarray
    Wm: np.ndarray
    E: np.ndarray
    sets: dict
    regions: frozenset


def _vertices(d: CcpTerms, y):
    """``w_k(y_l)``, shape ``(..., L, F, 2)`` for ``y (..., L, F)``."""
    return (y[..., :, None, None, :] * d.Wm).sum(-1)


@dataclass(frozen=True)
class CcpVertexIn(VertexIn):
    """C2 / C3: :class:`~tubejax.lp.declarations.tube_families.VertexIn` at the vertices
    ``w_k(y_l)`` of ``Q_l`` (``H w_k(y_l) <= h``, ``l`` in ``steps``), every vertex kept."""

    compress_vertices: bool = False

    def grid(self, d):
        return (len(step_indices(self.steps, d.L)), d.N.shape[0], d.sets[self.region].H.shape[0])

    def lhs(self, d, x):
        return _vertices(d, x.y)[..., step_indices(self.steps, d.L), :, :] @ d.sets[self.region].H.T


@dataclass(frozen=True)
class CcpDynamics(RowFamily):
    """C4: ``N (A q + B u_q) <= y_{l+1} - sigma_W(N)``; ``q`` the source cell's vertices at ``l = 0``
    (``first``), the vertices ``w_k(y_l)`` after (``l = 1 .. L-1``)."""

    name: str
    first: bool
    compress_vertices: bool = False

    def grid(self, d):
        return (d.V.shape[0], d.N.shape[0]) if self.first else (d.L - 1, d.N.shape[0], d.N.shape[0])

    def lhs(self, d, x):
        if self.first:
            return x.u0 @ (d.N @ d.B).T - x.y[..., 0, None, :]
        nxt = _vertices(d, x.y)[..., :-1, :, :] @ d.A.T + x.u @ d.B.T            # (..., L-1, F, 2)
        return nxt @ d.N.T - x.y[..., 1:, None, :]

    def rhs(self, d):
        return -d.sigma - d.V @ (d.N @ d.A).T if self.first else -d.sigma

    def scale(self, d):
        return np.linalg.norm(d.N, axis=1)

    def normals(self, d):
        return d.N


@dataclass(frozen=True)
class CcpConfig(RowFamily):
    """The configuration cone: every edge of ``Q_l`` has nonnegative length, ``-E y_l <= 0`` (hard)."""

    name: str = "config"
    compress_vertices: bool = False

    def grid(self, d):
        return (d.L, d.E.shape[0])

    def lp_role(self, d, u_is_box):
        return "hard"

    def lhs(self, d, x):
        return -(x.y @ d.E.T)

    def rhs(self, d):
        return np.zeros(d.E.shape[0])

    def scale(self, d):
        return np.linalg.norm(d.E, axis=1)


@dataclass(frozen=True)
class CcpInputIn(InputIn):
    """C5: :class:`~tubejax.lp.declarations.tube_families.InputIn` for the inputs at ``l = 0``
    (``first``: one per cell vertex, ``u0``) or after (``u``), always hard rows."""

    first: bool = False

    def grid(self, d):
        f_u = d.sets["input"].H.shape[0]
        return (d.V.shape[0], f_u) if self.first else (d.L - 1, d.N.shape[0], f_u)

    def lp_role(self, d, u_is_box):
        return "hard"

    def lhs(self, d, x):
        return super().lhs(d, x._replace(u=x.u0) if self.first else x)


#: The CCP tube LP, in its row order: margin rows C2, C3, C4, then the hard rows.
CCP_FAMILIES: tuple = (CcpVertexIn("safe", "safe", "interior"), CcpVertexIn("target", "target", "last"),
                       CcpDynamics("dynamics_0", True), CcpDynamics("dynamics", False), CcpConfig(),
                       CcpInputIn("input_0", first=True), CcpInputIn("input", first=False))


def ccp_terms(prob, N) -> CcpTerms:
    """:class:`CcpTerms` of a :class:`~tubejax.model.problem.TubeProblem` (its ``Z`` is ignored)."""
    sysm = prob.system
    if sysm.n != 2:
        raise ValueError(f"configuration-constrained tubes here are 2-D, got n = {sysm.n}")
    N = np.asarray(N, float)
    Wm, E = ccp_vertex_maps(N)
    sets = {r: SetRows(P.H, P.h, P.row_norms) for r, P in (("safe", prob.safe), ("target", prob.target),
                                                          ("input", sysm.U))}
    return CcpTerms(int(prob.L), prob.source.vertices, sysm.A, sysm.B, N, support(sysm.W, N), Wm, E, sets,
                    system_regions(sysm))


def ccp_identity(d: CcpTerms, m: int) -> CcpVars:
    """Every unit vector of ``x = [y (L, F), u0 (n_v, m), u (L-1, F, m)]`` as a batch of CCP tubes."""
    L, F, nv = d.L, d.N.shape[0], d.V.shape[0]
    ny, nu0 = L * F, nv * m
    n_x = ny + nu0 + (L - 1) * F * m
    eye = np.eye(n_x)                    # rows counted explicitly: at L = 1, u has no entries
    return CcpVars(eye[:, :ny].reshape(n_x, L, F), eye[:, ny:ny + nu0].reshape(n_x, nv, m),
                   eye[:, ny + nu0:].reshape(n_x, L - 1, F, m))


def build_ccp_lp(prob, N, t_max: float = 1.0) -> CcpLP:
    """The margin-form LP of a CCP tube for a :class:`~tubejax.model.problem.TubeProblem`
    (its ``Z`` is ignored; ``N`` are the normals), derived from :data:`CCP_FAMILIES`. Variables
    ``x = [y (L, F), u0 (n_v, m), u (L-1, F, m)]``, all free; ``lp.layout`` names the rows.

    Each margin row per unit of its state-space normal (the facet of ``S``, ``P_j`` or ``N``), so the
    margin is a distance in the state space as in the tube LP; the hard rows (configuration, C5)
    per unit of their coefficients.
    """
    d = ccp_terms(prob, N)
    m = prob.system.m
    G, g, layout = dense_rows(d, m, "margin", False, CCP_FAMILIES, ccp_identity)
    nrm = state_lengths(d, "margin", False, lambda H: np.linalg.norm(H, axis=1), CCP_FAMILIES)
    hard, hard_rhs, _ = dense_rows(d, m, "hard", False, CCP_FAMILIES, ccp_identity)
    hn = np.linalg.norm(hard, axis=1)
    nx = G.shape[1]
    return CcpLP(G / nrm[:, None], g / nrm, np.zeros(len(g), np.int8), hard / hn[:, None], hard_rhs / hn,
                  np.full(nx, -np.inf), np.full(nx, np.inf), float(t_max), (d.L, d.N.shape[0], d.V.shape[0], m),
                  layout=layout)


def _split(x, L, F, nv, m) -> CcpTube:
    ny, nu0 = L * F, nv * m
    return CcpTube(x[:ny].reshape(L, F), x[ny:ny + nu0].reshape(nv, m), x[ny + nu0:].reshape(L - 1, F, m))


def ccp_violation(prob, N, tube: CcpTube) -> float:
    """Largest violation of a CCP tube, float64: every row of :data:`CCP_FAMILIES`, vertex by
    vertex, per unit of its normal (the configuration per unit of ``|E_k|``). ``inf`` for wrong
    shapes or non-finite values.
    """
    d = ccp_terms(prob, N)
    F, nv, m = d.N.shape[0], d.V.shape[0], prob.system.m
    y, u0, u = (np.asarray(a, float) for a in tube)
    if y.shape != (d.L, F) or u0.shape != (nv, m) or u.shape != (d.L - 1, F, m):
        return float("inf")
    if not all(np.all(np.isfinite(a)) for a in (y, u0, u)):
        return float("inf")
    x = CcpVars(y, u0, u)
    worst = [np.max((f.lhs(d, x) - f.rhs(d)) / f.scale(d)) for f in CCP_FAMILIES if np.prod(f.grid(d))]
    return float(max(0.0, max(worst)))


def ccp_margin(prob, N) -> tuple[float, CcpTube | None, float]:
    """HiGHS's margin of the CCP tube LP, the tube and its :func:`ccp_violation` (``inf`` if none)."""
    lp = build_ccp_lp(prob, N)
    res = solve_margin_lp(lp)
    if res.status != "Optimal":
        return float("nan"), None, float("inf")
    tube = _split(res.x, *lp.index)
    return res.margin, tube, ccp_violation(prob, N, tube)


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
