"""Algorithm 2 by exact product decomposition (docs/math/product.md).

:func:`build_product_abstraction` detects the product structure
(:func:`~tubejax.model.product_structure.product_structure`; a coupled problem raises
:class:`~tubejax.model.product_structure.NotAProduct` saying why, and :func:`abstract_auto` then runs
:func:`~tubejax.abstraction.build.build_abstraction`'s joint LPs as today), solves each group's
factor LPs once (:mod:`.product_factors`), joins them (:mod:`.product_join`) and solves the few pairs
whose bounding box meets an obstacle while their hull does not as joint LPs with the paper's safe set.
The result is a :class:`ProductSystem`: every edge with the factor verdicts (or the joint verdict)
that prove it.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass, field
from typing import NamedTuple

import networkx as nx
import numpy as np
from tqdm.auto import tqdm

from ..model.product_structure import NotAProduct, ProductStructure, product_structure
from ..model.system import LinearSystem
from ..model.workspace.decomposition import CellDecomposition
from ..model.zshape.kinds import cross_sections
from .build import build_abstraction
from .joint_projections import ProjectionScreen
from .options import AbstractionOptions
from .product_factors import SAFE_VARIANTS, solve_factors
from .product_join import JoinedEdges, join_factors, shard_weights
from .product_joint_lps import JOINT, joint_pairs, joint_solver, merge_joint
from .shards import source_range

__all__ = ["ProductOptions", "ProductTube", "ProductSystem", "build_product_abstraction", "abstract_auto", "JOINT",
           "VARIANT_NAMES"]

log = logging.getLogger("tubejax")

#: The names of :attr:`ProductSystem.variant`'s values.
VARIANT_NAMES = SAFE_VARIANTS + ("joint",)


@dataclass(frozen=True)
class ProductOptions:
    """The settings of :func:`build_product_abstraction` (what decides the result, and the join's budget).

    Attributes
    ----------
    L_max : int
        Largest horizon, in ``1..63`` (the join keeps the feasible horizons as the bits of a ``uint64``).
    eps_min : float
        ``eps_{l, g} >= eps_min`` (C1).
    zshape, z_scale : str, float
        The cross-section kind and size (:func:`~tubejax.model.zshape.kinds.cross_sections`); with
        ``Z`` given to :func:`build_product_abstraction`, unused.
    pruning : bool
        Drop the factor LPs that the sound necessary conditions of :mod:`tubejax.abstraction.pruning`
        prove infeasible (:func:`~tubejax.abstraction.product_factors.factor_keep`); the result does
        not depend on it.
    memory_mb : float
        Working-set budget of the join (:func:`~tubejax.abstraction.product_join.join_factors`); the
        result does not depend on it.
    shard_count, shard_index : int
        Keep only shard ``shard_index`` of ``shard_count``'s source cells (docs/howto/shards.md): every
        shard solves the factor tables and joins every cell, then keeps its contiguous range of source
        cells and solves their joint LPs (:func:`~tubejax.abstraction.shards.source_range` over
        :func:`~tubejax.abstraction.product_join.shard_weights`); ``1, 0``: all of them.
    """

    L_max: int = 10
    eps_min: float = 0.0
    zshape: str = "cell"
    z_scale: float = 1.0
    pruning: bool = True
    memory_mb: float = 256.0
    shard_count: int = 1
    shard_index: int = 0

    def __post_init__(self):
        if isinstance(self.L_max, bool) or not isinstance(self.L_max, (int, np.integer)) or not 1 <= self.L_max <= 63:
            raise ValueError(f"L_max must be an integer in 1..63 for the product path, got {self.L_max!r}")
        if not float(self.eps_min) >= 0.0:
            raise ValueError(f"eps_min must be a number >= 0, got {self.eps_min!r}")
        if not float(self.memory_mb) > 0.0:
            raise ValueError(f"memory_mb must be a number > 0, got {self.memory_mb!r}")
        for name in ("shard_count", "shard_index"):
            if isinstance(getattr(self, name), bool) or not isinstance(getattr(self, name), (int, np.integer)):
                raise ValueError(f"{name} must be an integer, got {getattr(self, name)!r}")
        if not 0 <= self.shard_index < self.shard_count:
            raise ValueError(f"shard_index must be in [0, {self.shard_count - 1}] (shard_count = {self.shard_count}), "
                             f"got {self.shard_index!r}")

    def replace(self, **fields) -> "ProductOptions":
        """A copy with ``fields`` replaced (checked again); an unknown name raises ``TypeError`` naming it."""
        known = {f.name for f in dataclasses.fields(self)}
        bad = sorted(set(fields) - known)
        if bad:
            raise TypeError(f"{bad[0]}: not a field of ProductOptions (expected one of {', '.join(sorted(known))})")
        return dataclasses.replace(self, **fields)


class ProductTube(NamedTuple):
    """A tube of the product family: ``Q_l = p_l + diag(eps_{l, g(axis)}) Z``.

    ``p (L, n)``, ``eps (L, G)`` (one scale per group), ``u (L, n_v, m)``, ``group_of_axis (n,)``.
    """

    p: np.ndarray
    eps: np.ndarray
    u: np.ndarray
    group_of_axis: np.ndarray

    def vertices(self, Z, source) -> np.ndarray:
        """Tube vertices ``q_k(l)``, shape ``(L + 1, n_v, n)``; ``l = 0``: the source cell's vertices."""
        scale = self.eps[:, self.group_of_axis]                              # (L, n)
        q = self.p[:, None, :] + scale[:, None, :] * Z.vertices[None, :, :]
        return np.concatenate([np.asarray(source.vertices, float)[None], q], axis=0)


@dataclass(eq=False)
class ProductSystem:
    """The transition system of a product problem, with its factor evidence.

    Attributes
    ----------
    decomposition : CellDecomposition
    system : LinearSystem
    Z : tuple of Polytope                 per cell
    structure : ProductStructure
    tables : tuple of FactorTable         one per group
    src, dst, L : ndarray of int, shape (E,)
    margin : ndarray of float, shape (E,)
    variant : ndarray of int, shape (E,)  0 ``'box'``, 1 ``'source'`` (factor proofs), :data:`JOINT`
    joint : dict                          ``(i, j) -> Verdict`` of the joint LPs solved (edges and not)
    L_max : int
    eps_min : float
    stats : dict                          counts and seconds per phase
    """

    decomposition: CellDecomposition
    system: LinearSystem
    Z: tuple
    structure: ProductStructure
    tables: tuple
    src: np.ndarray
    dst: np.ndarray
    L: np.ndarray
    margin: np.ndarray
    variant: np.ndarray
    joint: dict
    L_max: int
    eps_min: float = 0.0
    stats: dict = field(default_factory=dict)

    @property
    def n_cells(self) -> int:
        return self.decomposition.n_cells

    @property
    def n_edges(self) -> int:
        return int(len(self.src))

    def edge_dict(self) -> dict:
        """``{(i, j): L}`` of every edge."""
        return dict(zip(zip(self.src.tolist(), self.dst.tolist()), self.L.tolist()))

    def factor_verdicts(self, k: int) -> list:
        """The factor verdicts that prove edge ``k`` (one per group), ``[]`` for a joint edge."""
        if self.variant[k] == JOINT:
            return []
        i, j, L, v = int(self.src[k]), int(self.dst[k]), int(self.L[k]), int(self.variant[k])
        cf = self.structure.cell_factor
        return [t.verdict(v, L, cf[i, g], cf[j, g]) for g, t in enumerate(self.tables)]

    def tube(self, k: int):
        """Edge ``k``'s tube: a :class:`ProductTube` assembled from its factor tubes (a joint edge: its Tube)."""
        i, j = int(self.src[k]), int(self.dst[k])
        if self.variant[k] == JOINT:
            return self.joint[(i, j)].tube
        L, n, m = int(self.L[k]), self.structure.n, self.structure.m
        Zi = self.Z[i]
        p = np.zeros((L, n))
        eps = np.zeros((L, self.structure.n_groups))
        u = np.zeros((L, Zi.n_vertices, m))
        group_of_axis = np.zeros(n, dtype=np.int64)
        for g, (f, verdict) in enumerate(zip(self.structure.factors, self.factor_verdicts(k))):
            axes, inputs = list(f.axes), list(f.inputs)
            tg = verdict.tube
            Zg = f.Z[self.structure.cell_factor[i, g]]
            kg = np.array([int(np.flatnonzero(np.all(Zg.vertices == z, axis=1))[0]) for z in Zi.vertices[:, axes]])
            p[:, axes] = tg.p
            eps[:, g] = tg.eps
            u[:, :, inputs] = np.asarray(tg.u)[:, kg, :]
            group_of_axis[axes] = g
        return ProductTube(p, eps, u, group_of_axis)

    def to_networkx(self):
        """The graph as a ``networkx.DiGraph``, edges with ``L`` (= ``weight``) and ``margin``."""
        G = nx.DiGraph()
        G.add_nodes_from(range(self.n_cells))
        G.add_weighted_edges_from(zip(self.src.tolist(), self.dst.tolist(), self.L.tolist()))
        for i, j, L, mg in zip(self.src.tolist(), self.dst.tolist(), self.L.tolist(), self.margin.tolist()):
            G.edges[i, j].update(L=L, margin=mg)
        return G


def build_product_abstraction(decomp: CellDecomposition, system: LinearSystem, options: ProductOptions | None = None,
                              *, Z=None, solve_batch=None, joint_solve_batch=None, progress: bool = False,
                              **fields) -> ProductSystem:
    """Algorithm 2 for a product problem: factor LPs, the join, and the joint LPs of blocked boxes.

    Parameters
    ----------
    decomp : CellDecomposition
    system : LinearSystem
    options : ProductOptions, optional
        ``L_max``, ``eps_min``, ``zshape``, ``z_scale``, ``pruning``, ``memory_mb``, ``shard_count``,
        ``shard_index`` (default: its defaults).
    Z : sequence of Polytope, optional
        One cross-section per cell instead of ``options.zshape``.
    solve_batch : callable, optional
        A batch solver of the tube method for the factor and joint LPs (default HiGHS,
        :data:`~tubejax.lp.evidence.verdict.highs_solve_batch`; e.g. the batched
        :class:`~tubejax.lp.batch.batch_solver.PdhgBatchSolver`).
    joint_solve_batch : callable, optional
        The batch solver of the joint LPs; default: HiGHS one LP at a time on its group-vertex LP
        (:class:`~tubejax.abstraction.joint_duals.DualReuseSolver` with
        :func:`~tubejax.abstraction.group_vertex_lp.solve_by_group_vertices`), whatever ``solve_batch`` is:
        the joint LPs the projections leave are nearly all edges, each needing HiGHS and its exact proof
        anyway, so a batched first pass only adds to them.
    progress : bool
    **fields
        Fields of :class:`ProductOptions` (``L_max=6``, ``zshape='box'``) replacing those of ``options``.

    Returns
    -------
    ProductSystem
        ``stats``: ``groups``, ``n_factor_lps``, ``n_factor_pruned``, ``n_factor_edges``, ``n_joint_pairs``,
        ``n_joint_lps``, ``n_joint_reused`` / ``n_joint_projected`` (joint LPs refuted by an earlier LP's
        dual / by a projection, not built), ``n_joint_translated`` (joint edges proved by their class
        representative's exact tube, translated, not built), ``n_projection_lps``, ``n_box_tested``,
        ``n_edges``, ``seconds_*`` per phase and ``seconds``; a shard also ``shard``: ``count``, ``index``,
        ``start``, ``stop``, ``n_edges``.

    Raises
    ------
    NotAProduct
        The problem is not a product (the message says why).
    """
    opt = (options or ProductOptions()).replace(**fields) if fields else (options or ProductOptions())
    L_max, eps_min, pruning = opt.L_max, opt.eps_min, opt.pruning
    t0 = time.perf_counter()
    Zs = cross_sections(decomp, opt.zshape, opt.z_scale) if Z is None else tuple(Z)
    structure = product_structure(decomp, system, Zs)
    t1 = time.perf_counter()
    log.info("%s", structure.describe())
    tables = solve_factors(structure.factors, int(L_max), solve_batch, eps_min, progress, pruning)
    t2 = time.perf_counter()
    shard, joined = _join_shard(decomp, structure, tables, opt, progress)
    t3 = time.perf_counter()
    jsolver = joint_solver(joint_solve_batch)
    screen = ProjectionScreen(structure, system, eps_min)
    joint, jL, jmargin, n_joint_lps = joint_pairs(decomp, system, Zs, joined, int(L_max), eps_min, jsolver, screen)
    src, dst, L, margin, variant = merge_joint(joined, jL, jmargin, decomp.n_cells)
    order = np.lexsort((dst, src))
    t4 = time.perf_counter()
    stats = {"groups": [list(f.axes) for f in structure.factors],
             "n_factor_cells": [f.n_cells for f in structure.factors],
             "n_factor_lps": int(sum(t.n_lps for t in tables)),
             "n_factor_pruned": int(sum(sum(t.pruned.values()) for t in tables)),
             "n_factor_edges": int(sum(t.feasible.sum() for t in tables)),
             "n_box_tested": int(joined.n_box_tested), "n_joint_pairs": int(len(joined.joint_src)),
             "n_joint_lps": int(n_joint_lps), "n_joint_reused": int(getattr(jsolver, "n_reused", 0)),
             "n_joint_translated": int(getattr(jsolver, "n_translated", 0)),
             "n_projection_lps": screen.n_lps, "n_joint_projected": screen.n_refuted, "n_edges": int(len(src)),
             "seconds_detect": t1 - t0, "seconds_factors": t2 - t1, "seconds_join": t3 - t2,
             "seconds_joint": t4 - t3, "seconds": t4 - t0}
    if opt.shard_count > 1:
        stats["shard"] = dict(shard, n_edges=int(len(src)))
    return ProductSystem(decomp, system, Zs, structure, tables, src[order], dst[order], L[order], margin[order],
                         variant[order], joint, int(L_max), float(eps_min), stats)


def _join_shard(decomp, structure, tables, opt: ProductOptions, progress: bool) -> tuple[dict, JoinedEdges]:
    """The join of shard ``opt.shard_index`` of ``opt.shard_count``'s source cells ``[start, stop)`` and that
    range (``{'count', 'index', 'start', 'stop'}``).

    A shard joins every source cell, then keeps its contiguous range of about equal work
    (:func:`~tubejax.abstraction.shards.source_range` over :func:`~tubejax.abstraction.product_join.shard_weights`:
    the joint LPs' pairs, known only after the join, are most of a shard's work).
    """
    with tqdm(total=decomp.n_cells, desc="join", unit="cell", disable=not progress, leave=False) as bar:
        joined = join_factors(decomp, structure, tables, opt.memory_mb, bar)
    if opt.shard_count == 1:
        return {"count": 1, "index": 0, "start": 0, "stop": decomp.n_cells}, joined
    start, stop = source_range(shard_weights(structure, tables, joined.joint_src), opt.shard_count, opt.shard_index)
    return ({"count": int(opt.shard_count), "index": int(opt.shard_index), "start": start, "stop": stop},
            joined.of_sources(start, stop))


def abstract_auto(decomp: CellDecomposition, system: LinearSystem, options: ProductOptions | None = None, *, Z=None,
                  solve_batch=None, progress: bool = False, joint: AbstractionOptions | None = None, **fields):
    """The product path when the problem is a product, else today's joint LPs.

    Parameters
    ----------
    decomp, system, options, Z, solve_batch, progress
        As :func:`build_product_abstraction`.
    joint : AbstractionOptions, optional
        The options of the joint LPs when the problem is not a product; default: ``options``' ``L_max``,
        ``eps_min``, ``zshape``, ``z_scale`` and ``pruning``.
    **fields
        Fields of :class:`ProductOptions` (``L_max=6``) replacing those of ``options``; any other name
        goes to :func:`~tubejax.abstraction.build.build_abstraction` (``io=...``).

    Returns
    -------
    (ProductSystem or TransitionSystem, str)
        The result and ``''`` (product) or the reason the problem is not a product (joint LPs run,
        and the reason is logged).
    """
    names = {f.name for f in dataclasses.fields(ProductOptions)}
    opt = (options or ProductOptions()).replace(**{k: v for k, v in fields.items() if k in names})
    rest = {k: v for k, v in fields.items() if k not in names}
    try:
        return build_product_abstraction(decomp, system, opt, Z=Z, solve_batch=solve_batch, progress=progress), ""
    except NotAProduct as exc:
        log.warning("%s; running the joint tube LPs", exc)
        joint = joint or AbstractionOptions(L_max=opt.L_max, eps_min=opt.eps_min, zshape=opt.zshape,
                                            z_scale=opt.z_scale, pruning=opt.pruning)
        return build_abstraction(decomp, system, joint, z=Z, solve_batch=solve_batch, progress=progress,
                                 **rest), str(exc)
