"""Verify a product system (docs/math/product.md#trust).

:func:`verify_product` checks a :class:`~tubejax.abstraction.product_abstraction.ProductSystem` against
its data: the product structure detected again, every factor verdict an edge relies on (float64,
``<= VERIFY_TOL``, and exactly where a proof is claimed) and every joint edge's tube, and the join
recomputed by another algorithm (no index, ``L`` from the verdicts, the edge set by enumerating each
source's outer product of successor lists); with ``complete``, sampled pairs re-solved as one joint
LP (:func:`~tubejax.verify.product_lp.product_lp_margin`). Every failure is a line in
:attr:`ProductReport.problems`; none means verified.
"""

from __future__ import annotations

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

__all__ = ["ProductReport", "verify_product", "least_product_family_L"]

#: Edges per chunk of the vectorised checks (bounds their working set).
CHUNK = 1 << 20
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
        if o.is_box:
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
    obstacle = np.zeros(len(s), dtype=bool)
    for c0 in range(0, len(s), CHUNK):                   # in chunks: the pair boxes are (E, n) floats
        c = slice(c0, c0 + CHUNK)
        obstacle[c] = _box_meets_obstacles(np.minimum(lo[s[c]], lo[d[c]]), np.maximum(hi[s[c]], hi[d[c]]),
                                           decomp.obstacles)
    _check_edges(ps, report, obstacle, exact)
    _check_joint(ps, report, obstacle)
    if enumerate_join:
        _check_join(ps, report, obstacle, sources)
    if complete:
        _complete(ps, report, int(complete), seed)
    return report


def _check_edges(ps: ProductSystem, report: ProductReport, obstacle, exact: bool) -> None:
    """Each edge's ``L`` range and safe-set variant, then every factor verdict the factor edges rely on."""
    L, v = ps.L, ps.variant
    bad_L = ~((L >= 1) & (L <= ps.L_max))
    joint = ~bad_L & (v == JOINT)
    bad_v = ~bad_L & ~joint & (v != np.asarray(obstacle, dtype=v.dtype))
    for k in np.flatnonzero(bad_L | bad_v):
        where = f"edge {int(ps.src[k])}->{int(ps.dst[k])} (L={int(L[k])})"
        if bad_L[k]:
            report.problems.append(f"{where}: L outside 1..{ps.L_max}")
        else:
            report.problems.append(f"{where}: safe set {SAFE_VARIANTS[int(v[k])]!r}, but the bounding box "
                                   f"{'meets' if obstacle[k] else 'avoids'} the obstacles")
    ok = ~bad_L & ~joint & ~bad_v
    report.n_edges_checked += int(ok.sum())
    cf = ps.structure.cell_factor
    s, d = ps.src[ok], ps.dst[ok]
    for g, f in enumerate(ps.structure.factors):           # the distinct (v, L, a, b), in sorted order
        F, nL = np.int64(f.n_cells), np.int64(ps.L_max + 1)
        key = np.unique(((v[ok].astype(np.int64) * nL + L[ok]) * F + cf[s, g]) * F + cf[d, g])
        ab, b = np.divmod(key, F)
        vl, a = np.divmod(ab, F)
        for key4 in zip(*(x.tolist() for x in (*np.divmod(vl, nL), a, b))):
            _check_factor(ps, g, key4, report, exact)


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


def _verdict_masks(ps: ProductSystem) -> list:
    """Per group, the horizons at which each factor pair's verdict is an edge, read from the verdicts.

    Returns
    -------
    list of ndarray of uint64, shape (2, F_g, F_g)
        ``[g][v, a, b]`` has bit ``L - 1`` set iff ``verdicts[(v, L, a, b)]`` is an edge.
    """
    out = []
    for f, t in zip(ps.structure.factors, ps.tables):
        m = np.zeros((len(SAFE_VARIANTS), f.n_cells, f.n_cells), dtype=np.uint64)
        for (v, L, a, b), verdict in t.verdicts.items():
            if verdict.status == "edge" and 1 <= L <= ps.L_max:
                m[v, a, b] |= np.uint64(1) << np.uint64(L - 1)
        out.append(m)
    return out


def _least_L(mask: np.ndarray) -> np.ndarray:
    """The least ``L`` whose bit ``L - 1`` is set in each ``uint64``; 0 where none, shape like ``mask``."""
    low = mask & (~mask + np.uint64(1))                 # the lowest set bit alone (two's complement)
    out = np.zeros(mask.shape, dtype=np.int64)
    nz = low != 0
    out[nz] = np.round(np.log2(low[nz].astype(np.float64))).astype(np.int64) + 1
    return out


def _pair_masks(masks: list, cf: np.ndarray, s: np.ndarray, d: np.ndarray) -> np.ndarray:
    """The horizons feasible in every group of pairs ``s -> d``, per variant, shape (2, K), uint64."""
    out = np.full((len(SAFE_VARIANTS), len(s)), ~np.uint64(0), dtype=np.uint64)
    for g, m in enumerate(masks):
        out &= m[:, cf[s, g], cf[d, g]]
    return out


def _candidate_pairs(masks: list, cf: np.ndarray, i: int, cell_keys, radix):
    """The cells ``j != i`` whose factor pairs with ``i`` are edges in every group for some variant.

    Destinations are enumerated as the outer product of the groups' successor lists and found by a
    binary search of their factor tuples' keys (``cell_keys``: ``(sorted keys, cell ids)``).

    Returns
    -------
    dst : ndarray of int, shape (K,)
    mask : ndarray of uint64, shape (2, K)      per variant, the horizons feasible in every group
    """
    key = np.zeros(1, dtype=np.int64)
    mask = np.full((len(SAFE_VARIANTS), 1), ~np.uint64(0), dtype=np.uint64)
    for g, m in enumerate(masks):
        row = m[:, cf[i, g], :]                          # (2, F_g)
        b = np.flatnonzero(np.bitwise_or.reduce(row, axis=0))
        key = (key[:, None] * radix[g] + b[None, :]).ravel()
        mask = (mask[:, :, None] & row[:, None, b]).reshape(len(SAFE_VARIANTS), -1)
    keys, ids = cell_keys
    pos = np.minimum(np.searchsorted(keys, key), len(keys) - 1)
    hit = (keys[pos] == key) & np.any(mask != 0, axis=0)
    dst = ids[pos[hit]]
    keep = dst != i
    return dst[keep], mask[:, hit][:, keep]


def _check_join(ps: ProductSystem, report: ProductReport, obstacle, sources=None, chunk: int = 2048) -> None:
    """Every pair feasible in every group (whose source is in ``sources``, ``[start, stop)``; all when
    ``None``) is an edge, at the least such ``L`` of its variant.

    Independent of the join: the factor verdicts themselves give, per group, the feasible horizons of
    each factor pair (:func:`_verdict_masks`); each edge's least ``L`` is read from them by its factor
    cells, and the pairs that must be edges are enumerated source by source as outer products of
    the groups' successor lists, matched to cells and to the edges by binary search of sorted keys.
    """
    cf, N = ps.structure.cell_factor, ps.n_cells
    masks = _verdict_masks(ps)
    radix = [m.shape[1] for m in masks]
    tkey = np.zeros(N, dtype=np.int64)
    for g, r in enumerate(radix):
        tkey = tkey * r + cf[:, g]
    order = np.argsort(tkey, kind="stable")
    if N and np.any(np.diff(tkey[order]) == 0):
        report.problems.append("two cells have the same factor cells in every group")
        return
    ekey = ps.src.astype(np.int64) * N + ps.dst.astype(np.int64)
    esorted = np.sort(ekey)
    lo, hi = ps.decomposition.cell_boxes()
    start, stop = (0, N) if sources is None else (int(sources[0]), int(sources[1]))
    for c0 in range(start, stop, chunk):
        found = [_candidate_pairs(masks, cf, i, (tkey[order], order), radix) for i in range(c0, min(stop, c0 + chunk))]
        s = np.concatenate([np.full(len(d), i, dtype=np.int64) for i, (d, _) in zip(range(c0, N), found)])
        d = np.concatenate([dd for dd, _ in found]).astype(np.int64)
        m = np.concatenate([mm for _, mm in found], axis=1)
        pos = np.minimum(np.searchsorted(esorted, s * N + d), max(len(esorted) - 1, 0))
        new = ~(esorted[pos] == s * N + d) if len(esorted) else np.ones(len(s), dtype=bool)
        s, d, m = s[new], d[new], m[:, new]
        blocked = _box_meets_obstacles(np.minimum(lo[s], lo[d]), np.maximum(hi[s], hi[d]),
                                       ps.decomposition.obstacles).astype(np.int64)
        want = _least_L(m[blocked, np.arange(len(s))])
        for k in np.flatnonzero(want > 0):
            report.problems.append(f"pair {s[k]}->{d[k]}: feasible in every group at L={want[k]}, but not an edge")
    _check_edge_L(ps, report, obstacle, masks)


def _check_edge_L(ps: ProductSystem, report: ProductReport, obstacle, masks: list, chunk: int = CHUNK) -> None:
    """Each edge's ``L`` against the least ``L`` feasible in every group of its variant (vectorised)."""
    o = np.asarray(obstacle, dtype=np.int64)
    want = np.zeros(ps.n_edges, dtype=np.int64)
    for c0 in range(0, ps.n_edges, chunk):
        k = np.arange(c0, min(ps.n_edges, c0 + chunk))
        want[k] = _least_L(_pair_masks(masks, ps.structure.cell_factor, ps.src[k], ps.dst[k])[o[k], k - c0])
    joint = ps.variant == JOINT
    bad_factor = ~joint & (want != ps.L)
    bad_joint = joint & (want > 0) & (want <= ps.L)
    for k in np.flatnonzero(bad_factor | bad_joint):
        i, j, L, w = int(ps.src[k]), int(ps.dst[k]), int(ps.L[k]), int(want[k])
        if bad_factor[k]:
            report.problems.append(f"edge {i}->{j}: L={L}, but the least L feasible in every group is "
                                   f"{w if w else None}")
        else:
            report.problems.append(f"edge {i}->{j}: joint L={L}, but the factors give L={w}")


class _EdgeLookup:
    """``(i, j) in`` and ``.get((i, j))`` (its ``L``) over a product system's edges, by binary search."""

    def __init__(self, ps: ProductSystem):
        self._N = ps.n_cells
        key = ps.src.astype(np.int64) * self._N + ps.dst.astype(np.int64)
        order = np.argsort(key, kind="stable")
        self._keys, self._L = key[order], ps.L[order]

    def __len__(self) -> int:
        return len(self._keys)

    def get(self, pair, default=None):
        key = int(pair[0]) * self._N + int(pair[1])
        pos = int(np.searchsorted(self._keys, key))
        return int(self._L[pos]) if pos < len(self._keys) and self._keys[pos] == key else default

    def __contains__(self, pair) -> bool:
        return self.get(pair) is not None



def least_product_family_L(ps: ProductSystem, i: int, j: int) -> tuple[int | None, bool]:
    """The least ``L <= L_max`` at which the joint product-family LP of the pair ``(i, j)``
    (:func:`~tubejax.verify.product_lp.product_lp_margin`, SciPy's HiGHS) is feasible, ``None`` where
    none is, and whether some margin on the way came within :data:`COMPLETE_TOL` of 0 (too close to
    call in floats). The safe set is the product path's: the bounding box of ``P_i u P_j`` where it
    meets no obstacle, else ``P_i``."""
    d = ps.decomposition
    lo, hi = d.cell_boxes()
    blo, bhi = np.minimum(lo[i], lo[j]), np.maximum(hi[i], hi[j])
    safe = d.cells[i] if _box_meets_obstacles(blo[None], bhi[None], d.obstacles)[0] else Polytope.box(blo, bhi)
    groups = [f.axes for f in ps.structure.factors]
    pair = ProductPair(d.cells[i], d.cells[j], safe, ps.Z[i])
    close = False
    for L in range(1, ps.L_max + 1):
        t = product_lp_margin(ps.system, pair, groups, L, ps.eps_min)
        close |= abs(t) < COMPLETE_TOL
        if t >= 0:
            return L, close
    return None, close

def _complete(ps: ProductSystem, report: ProductReport, count: int, seed: int) -> None:
    """Re-solve a sample of full pairs as joint product-family LPs with HiGHS."""
    rng = np.random.default_rng(seed)
    N = ps.n_cells
    edges = _EdgeLookup(ps)
    factor_edges = np.flatnonzero(ps.variant != JOINT)
    pick_e = rng.choice(factor_edges, size=min(len(factor_edges), (count + 1) // 2), replace=False) \
        if len(factor_edges) else []
    others = []
    while len(others) < count - len(pick_e) and N > 1:
        i, j = (int(x) for x in rng.integers(0, N, size=2))
        if i != j and (i, j) not in edges:
            others.append((i, j))
        if len(others) + len(edges) >= N * (N - 1):
            break
    todo = [(int(ps.src[k]), int(ps.dst[k])) for k in pick_e] + others
    for i, j in todo:
        L_solver, close = least_product_family_L(ps, i, j)
        L_have = edges.get((i, j))
        report.n_sampled += 1
        report.n_sample_close += int(close)
        if L_solver != L_have and not close:
            report.problems.append(f"pair {i}->{j}: the joint product-family LP (HiGHS) gives L={L_solver}, "
                                   f"the system L={L_have}")
