"""The product path's joint LPs (docs/math/product.md): the pairs the join leaves to a joint LP with the
paper's safe set (a bounding box that meets an obstacle while the hull does not), solved by
translation class at the horizons where their ``'box'`` product LP is feasible, and merged into the
joined edges.
"""

from __future__ import annotations

import logging

import numpy as np

from ..model.problem import Pairs, pair_problems
from ..transitions.records import EdgeArrays
from .group_vertex_lp import solve_by_group_vertices
from .joint_duals import DualReuseSolver
from .translation_classes import TranslationClasses, solve_by_class

__all__ = ["JOINT", "joint_solver", "joint_pairs", "merge_joint"]

log = logging.getLogger("tubejax")

#: :attr:`~tubejax.abstraction.product_abstraction.ProductSystem.variant` of an edge proved by a joint LP
#: with the paper's safe set ``co(P_i u P_j)``.
JOINT = 2


def merge_joint(joined, jL: dict, jmargin: dict, n_cells: int):
    """The joined edges with the joint edges merged in: a joint edge wins where its ``L`` is smaller.

    The pairs are matched by :meth:`~tubejax.transitions.records.EdgeArrays.find` (binary search over the
    sorted keys ``src * n_cells + dst``).

    Returns
    -------
    src, dst, L, margin, variant : ndarray, shape (E,)
        Not sorted: the joined edges in their order (some replaced by joint ones), then the new joint edges.
    """
    src, dst, L, margin, variant = (joined.src, joined.dst, joined.L.copy(), joined.margin.copy(),
                                    joined.variant.copy())
    if not jL:
        return src, dst, L, margin, variant
    pairs = np.array(list(jL.keys()), dtype=np.int64).reshape(-1, 2)
    Lj = np.array(list(jL.values()), dtype=np.int64)
    mj = np.array([jmargin[p] for p in jL], dtype=float)
    at = EdgeArrays.of(joined, n_cells).find(pairs[:, 0], pairs[:, 1])
    found = at >= 0
    k = at[found]
    better = Lj[found] < L[k]
    k, kk = k[better], np.flatnonzero(found)[better]
    L[k], margin[k], variant[k] = Lj[kk], mj[kk], JOINT
    new = ~found
    return (np.concatenate([src, pairs[new, 0].astype(src.dtype)]),
            np.concatenate([dst, pairs[new, 1].astype(dst.dtype)]),
            np.concatenate([L, Lj[new].astype(L.dtype)]), np.concatenate([margin, mj[new]]),
            np.concatenate([variant, np.full(int(new.sum()), JOINT, dtype=variant.dtype)]))


def joint_solver(joint_solve_batch):
    """The solver of the joint LPs (see :func:`~tubejax.abstraction.product_abstraction.build_product_abstraction`)."""
    return joint_solve_batch if joint_solve_batch is not None else DualReuseSolver(solve_by_group_vertices)


def joint_pairs(decomp, system, Zs, joined, L_max: int, eps_min: float, solve_batch, screen=None):
    """Algorithm 2 with the paper's safe set for the pairs the join left to the joint LP.

    Only the horizons where the ``'box'`` product LP is feasible are tried (the paper's LP at ``L``
    is a restriction of it), in increasing order, each pair up to its first edge. With ``screen``
    (a :class:`~tubejax.abstraction.joint_projections.ProjectionScreen`), a pair's joint LP at ``L`` is
    built only when no projection of it on fewer axis groups is proved infeasible. Each horizon's
    pairs are solved by exact translation class
    (:func:`~tubejax.abstraction.translation_classes.solve_by_class`): a representative clearly
    infeasible settles its class; a representative edge's translates go to ``solve_batch`` as
    ``likely_edges`` with it (:class:`~tubejax.abstraction.joint_duals.DualReuseSolver` proves them
    by its exact tube translated, checked on their own data); the rest are solved on their own.

    Returns
    -------
    verdicts : dict        ``(i, j) -> Verdict`` at the last horizon tried
    L_of, margin_of : dict ``(i, j) -> L``, ``margin`` of the edges
    n_lps : int            the problems handed to ``solve_batch`` (a class's settled members are not)
    """
    verdicts, L_of, margin_of = {}, {}, {}
    open_ = np.ones(len(joined.joint_src), dtype=bool)
    n_lps = n_moved = 0
    classes = TranslationClasses(decomp, system)
    for L in range(1, L_max + 1):
        bit = np.uint64(1) << np.uint64(L - 1)
        k = np.flatnonzero(open_ & ((joined.joint_box_mask & bit) != 0))
        if k.size and screen is not None:
            k = k[~screen.refuted(joined.joint_src[k], joined.joint_dst[k], L)]
        if k.size == 0:
            continue
        s, d = joined.joint_src[k], joined.joint_dst[k]
        obstacle = np.zeros(k.size, bool)
        probs = pair_problems(decomp, system, Zs, Pairs(s, d, obstacle), L, eps_min)
        out, moved = solve_by_class(solve_batch, classes, probs, s, d, obstacle)
        out = [v if hasattr(v, "status") else v.result() for v in out]
        n_lps += len(probs) - moved
        n_moved += moved
        for kk, i, j, v in zip(k.tolist(), s.tolist(), d.tolist(), out):
            verdicts[(i, j)] = v
            if v.status == "edge":
                open_[kk] = False
                L_of[(i, j)], margin_of[(i, j)] = L, float(v.margin)
        log.info("joint LPs at L = %d: %d posed, %d settled by their class, %d edges so far", L, len(probs), moved,
                 len(L_of))
    log.info("joint LPs: %d non-edges settled by their class's representative", n_moved)
    return verdicts, L_of, margin_of, n_lps
