"""Verify a product system (docs/math/product.md#trust).

:func:`verify_product` checks a :class:`~tubejax.abstraction.product_abstraction.ProductSystem` against its data:

1. the product structure is detected again from the decomposition, the system and ``Z``, and must
   give the same groups and factor cells;
2. every factor verdict an edge relies on is re-checked as a joint run's edge is: its tube against
   the factor LP rebuilt from the data, in float64 (``<= VERIFY_TOL``), and exactly where it claims
   an exact proof; a joint edge's tube likewise against its full problem;
3. the join is recomputed independently: each edge's safe-set variant from the bounding box against
   the obstacles (exact coordinate comparisons, all obstacles, no index; other polytopes by
   :func:`~tubejax.model.geometry.meets_obstacles`), its ``L`` as the least horizon at which the factor
   verdicts (read from the verdicts themselves, not the join's bit masks) are edges in every group,
   and the edge set by enumerating the feasible factor pairs group by group and the cells that carry
   them (a different algorithm from the join's gathers over source blocks);
4. with ``complete``, a random sample of full pairs is re-solved as one joint LP of the product family
   with HiGHS (:func:`~tubejax.verify.product_lp.product_lp_margin`).

Every failure is a line in :attr:`ProductReport.problems`; none means verified.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np

from ..abstraction.product_abstraction import JOINT, ProductSystem
from ..abstraction.product_factors import factor_problem, SAFE_VARIANTS
from ..lp.evidence import prove_evidence
from ..lp.evidence.verdict import VERIFY_TOL
from ..lp.declarations.tube_lp import tube_violation
from ..model.geometry import Polytope, meets_obstacles
from ..model.problem import Pairs, pair_problems
from ..model.product_structure import product_structure
from .product_lp import ProductPair, product_lp_margin

__all__ = ["ProductReport", "verify_product"]

#: ``|t*|`` below which the HiGHS re-solve of ``complete`` is too close to call in floats.
COMPLETE_TOL = 1e-7


@dataclass
class ProductReport:
    """What :func:`verify_product` found.

    ``problems`` lists every failure (empty: verified); the counts say what was checked.
    """

    problems: list = field(default_factory=list)
    n_factor_checked: int = 0
    n_factor_exact: int = 0
    n_edges_checked: int = 0
    n_sampled: int = 0
    n_sample_close: int = 0

    @property
    def ok(self) -> bool:
        return not self.problems


def _box_meets_obstacles(lo: np.ndarray, hi: np.ndarray, obstacles) -> np.ndarray:
    """Whether the interior of each box meets an obstacle's, shape ``(K,)``: all obstacles, no index."""
    out = np.zeros(len(lo), dtype=bool)
    for o in obstacles:
        if not isinstance(o, Polytope):              # a 2-D polygon: the geometry layer's interior test
            for k in np.flatnonzero(~out):
                out[k] = meets_obstacles(Polytope.box(lo[k], hi[k]), [o])
            continue
        olo, ohi = o.bounding_box()
        meet = np.all(np.maximum(lo, olo) < np.minimum(hi, ohi), axis=1)
        is_box = o.H.shape[0] == 2 * o.dim and bool(np.all(np.sum(o.H != 0, axis=1) == 1))
        if is_box:
            out |= meet
        else:
            for k in np.flatnonzero(meet & ~out):
                out[k] = meets_obstacles(Polytope.box(lo[k], hi[k]), [o])
    return out


def _check_factor(ps: ProductSystem, g: int, key, report: ProductReport, exact: bool) -> None:
    v, L, a, b = key
    verdict = ps.tables[g].verdicts.get(key)
    where = f"group {g} factor pair {a}->{b} (L={L}, safe set {SAFE_VARIANTS[v]})"
    if verdict is None or verdict.status != "edge":
        report.problems.append(f"{where}: an edge relies on it, but it has no edge verdict")
        return
    prob = factor_problem(ps.structure.factors[g], a, b, L, SAFE_VARIANTS[v], ps.eps_min)
    viol = tube_violation(prob, verdict.tube)
    report.n_factor_checked += 1
    if not viol <= VERIFY_TOL:
        report.problems.append(f"{where}: its tube violates the factor LP by {viol:.3e} > {VERIFY_TOL}")
        return
    proof = verdict.proof
    if exact and proof is not None and proof.level == "exact":
        evidence = proof.exact if getattr(proof, "exact", None) is not None else verdict.tube
        pr = prove_evidence(prob, evidence, resolve=False)
        if pr.level != "exact":
            report.problems.append(f"{where}: claims an exact proof but fails it: {pr.note}")
        else:
            report.n_factor_exact += 1


def _enumerated_edges(ps: ProductSystem) -> dict:
    """``{(i, j): {v: least L}}`` of every pair feasible in every group, by enumerating factor pairs."""
    cf = ps.structure.cell_factor
    by_tuple: dict = {}
    for i, t in enumerate(map(tuple, cf.tolist())):
        by_tuple.setdefault(t, []).append(i)
    out: dict = {}
    for v in range(len(SAFE_VARIANTS)):
        for L in range(1, ps.L_max + 1):
            per_group = [[(a, b) for (vv, LL, a, b), verdict in t.verdicts.items()
                          if vv == v and LL == L and verdict.status == "edge"] for t in ps.tables]
            for combo in itertools.product(*per_group):
                src = by_tuple.get(tuple(a for a, _ in combo), [])
                dst = by_tuple.get(tuple(b for _, b in combo), [])
                for i in src:
                    for j in dst:
                        if i != j:
                            out.setdefault((i, j), {}).setdefault(v, L)
    return out


def verify_product(ps: ProductSystem, *, exact: bool = True, complete: int = 0, seed: int = 0,
                   enumerate_join: bool = True, sources: tuple[int, int] | None = None) -> ProductReport:
    """Re-check a product system (see the module docstring).

    Parameters
    ----------
    ps : ProductSystem
    exact : bool
        Re-prove the factor verdicts that claim an exact proof.
    complete : int
        How many full pairs (half edges, half non-edges where there are enough) to re-solve with
        HiGHS as joint LPs of the product family; 0: none.
    seed : int
        Seed of that sample.
    enumerate_join : bool
        Recompute the edge set by enumeration (item 3); its cost grows with the edges.
    sources : (int, int), optional
        A shard's source cells ``[start, stop)``: only their pairs must be edges (default: every cell's).

    Returns
    -------
    ProductReport
    """
    report = ProductReport()
    decomp = ps.decomposition
    st = product_structure(decomp, ps.system, ps.Z)
    if [f.axes for f in st.factors] != [f.axes for f in ps.structure.factors] or \
            not np.array_equal(st.cell_factor, ps.structure.cell_factor):
        report.problems.append("the product structure detected from the data differs from the system's")
        return report
    lo, hi = decomp.cell_boxes()
    s, d = ps.src, ps.dst
    if np.any(s == d):
        report.problems.append("a self-pair is an edge")
    obstacle = _box_meets_obstacles(np.minimum(lo[s], lo[d]), np.maximum(hi[s], hi[d]), decomp.obstacles)
    cf = st.cell_factor
    needed = set()
    for k in range(ps.n_edges):
        i, j, L, v = int(s[k]), int(d[k]), int(ps.L[k]), int(ps.variant[k])
        where = f"edge {i}->{j} (L={L})"
        if not 1 <= L <= ps.L_max:
            report.problems.append(f"{where}: L outside 1..{ps.L_max}")
            continue
        if v == JOINT:
            continue
        if v != int(obstacle[k]):
            report.problems.append(f"{where}: safe set {SAFE_VARIANTS[v]!r}, but the bounding box "
                                   f"{'meets' if obstacle[k] else 'avoids'} the obstacles")
            continue
        for g in range(st.n_groups):
            needed.add((g, (v, L, int(cf[i, g]), int(cf[j, g]))))
        report.n_edges_checked += 1
    for g, key in sorted(needed):
        _check_factor(ps, g, key, report, exact)
    _check_joint(ps, report, obstacle)
    if enumerate_join:
        _check_join(ps, report, obstacle, sources)
    if complete:
        _complete(ps, report, int(complete), seed)
    return report


def _check_joint(ps: ProductSystem, report: ProductReport, obstacle) -> None:
    for k in np.flatnonzero(ps.variant == JOINT):
        i, j, L = int(ps.src[k]), int(ps.dst[k]), int(ps.L[k])
        verdict = ps.joint.get((i, j))
        if not obstacle[k] or verdict is None or verdict.status != "edge":
            report.problems.append(f"edge {i}->{j} (L={L}): a joint edge without a joint verdict for a blocked box")
            continue
        prob = pair_problems(ps.decomposition, ps.system, ps.Z, Pairs([i], [j], [False]), L, ps.eps_min)[0]
        viol = tube_violation(prob, verdict.tube)
        if not viol <= VERIFY_TOL:
            report.problems.append(f"edge {i}->{j} (L={L}): its joint tube violates the LP by {viol:.3e}")
        report.n_edges_checked += 1


def _check_join(ps: ProductSystem, report: ProductReport, obstacle, sources=None) -> None:
    """Every pair feasible in every group (whose source is in ``sources``) is an edge, at the least such ``L``
    of its variant."""
    found = _enumerated_edges(ps)
    if sources is not None:
        found = {p: v for p, v in found.items() if sources[0] <= p[0] < sources[1]}
    edges = {(int(i), int(j)): (int(L), int(v), bool(o)) for i, j, L, v, o in
             zip(ps.src, ps.dst, ps.L, ps.variant, obstacle)}
    lo, hi = ps.decomposition.cell_boxes()
    pairs = [p for p in found if p not in edges]
    if pairs:
        a = np.array(pairs)
        blocked = _box_meets_obstacles(np.minimum(lo[a[:, 0]], lo[a[:, 1]]), np.maximum(hi[a[:, 0]], hi[a[:, 1]]),
                                       ps.decomposition.obstacles)
        for (i, j), o in zip(pairs, blocked):
            if int(o) in found[(i, j)]:
                report.problems.append(f"pair {i}->{j}: feasible in every group at L={found[(i, j)][int(o)]}, "
                                       f"but not an edge")
    for (i, j), (L, v, o) in edges.items():
        want = found.get((i, j), {}).get(int(o))
        if v != JOINT and want != L:
            report.problems.append(f"edge {i}->{j}: L={L}, but the least L feasible in every group is {want}")
        elif v == JOINT and want is not None and want <= L:
            report.problems.append(f"edge {i}->{j}: joint L={L}, but the factors give L={want}")


def _complete(ps: ProductSystem, report: ProductReport, count: int, seed: int) -> None:
    """Re-solve a sample of full pairs as joint product-family LPs with HiGHS."""
    rng = np.random.default_rng(seed)
    N = ps.n_cells
    edges = ps.edge_dict()
    factor_edges = [k for k in range(ps.n_edges) if ps.variant[k] != JOINT]
    pick_e = rng.choice(factor_edges, size=min(len(factor_edges), (count + 1) // 2), replace=False) \
        if factor_edges else []
    others = []
    while len(others) < count - len(pick_e) and N > 1:
        i, j = (int(x) for x in rng.integers(0, N, size=2))
        if i != j and (i, j) not in edges:
            others.append((i, j))
        if len(others) + len(edges) >= N * (N - 1):
            break
    lo, hi = ps.decomposition.cell_boxes()
    groups = [f.axes for f in ps.structure.factors]
    cells = ps.decomposition.cells
    todo = [(int(ps.src[k]), int(ps.dst[k])) for k in pick_e] + others
    for i, j in todo:
        blo, bhi = np.minimum(lo[i], lo[j]), np.maximum(hi[i], hi[j])
        blocked = _box_meets_obstacles(blo[None], bhi[None], ps.decomposition.obstacles)[0]
        safe = cells[i] if blocked else Polytope.box(blo, bhi)
        L_have = edges.get((i, j))
        L_solver, close = None, False
        for L in range(1, ps.L_max + 1):
            t = product_lp_margin(ps.system, ProductPair(cells[i], cells[j], safe, ps.Z[i]), groups, L, ps.eps_min)
            close |= abs(t) < COMPLETE_TOL             # too close to call in floats
            if t >= 0:
                L_solver = L
                break
        report.n_sampled += 1
        report.n_sample_close += int(close)
        if L_solver != L_have and not close:
            report.problems.append(f"pair {i}->{j}: the joint product-family LP (HiGHS) gives L={L_solver}, "
                                   f"the system L={L_have}")
