"""The factor abstractions of a product problem (docs/math/product.md#factor-abstractions).

Each axis group's tube LPs are solved once over its factor cells: every ordered factor pair, at
every horizon ``L <= L_max``, for the safe sets ``'box'`` and ``'source'``. The problems are ordinary
:class:`~tubejax.model.problem.TubeProblem` s of the factor system, handed to any batch solver of
the tube method, so each verdict carries the same evidence and proof as in a joint run.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np
from tqdm.auto import tqdm

from ..lp.evidence.verdict import highs_solve_batch
from ..model.geometry import Polytope
from ..model.problem import TubeProblem
from ..model.product_structure import Factor
from ..model.workspace.decomposition import CellDecomposition
from .pruning import prune_pairs, reach_tables, target_fits
from .translation_classes import TranslationClasses, solve_by_class

__all__ = ["SAFE_VARIANTS", "FactorTable", "factor_problem", "factor_keep", "solve_factor", "solve_factors",
           "same_factor_data"]

log = logging.getLogger("tubejax")

#: The product safe sets, in the order of :attr:`FactorTable.feasible`'s first axis.
SAFE_VARIANTS = ("box", "source")


@dataclass(eq=False)
class FactorTable:
    """The verdicts of one group's factor LPs.

    Attributes
    ----------
    group : int
    factor : Factor
    L_max : int
    feasible : ndarray of bool, shape (2, L_max, F, F)
        ``feasible[v, L - 1, a, b]``: the factor LP of ``(a, b)`` at ``L`` with safe set
        ``SAFE_VARIANTS[v]`` is an edge (its tube confirmed as in a joint run).
    margin : ndarray of float, shape (2, L_max, F, F)
        Its margin ``t*`` (nan where the solver did not report one).
    verdicts : dict
        ``(v, L, a, b) -> Verdict`` of every factor LP solved or settled by translation (the ``'source'`` entries of
        self-pairs are the ``'box'`` ones); a pruned LP has none.
    seconds : float
    n_lps : int                  factor LPs solved
    pruned : dict                factor LPs pruned, per reason (:mod:`tubejax.abstraction.pruning`)
    n_translated : int
        Non-edges settled by their translation class's clearly infeasible representative, not solved
        (:func:`~tubejax.abstraction.translation_classes.solve_by_class`; never an edge).
    """

    group: int
    factor: Factor
    L_max: int
    feasible: np.ndarray
    margin: np.ndarray
    verdicts: dict = field(repr=False)
    seconds: float = 0.0
    n_lps: int = 0
    pruned: dict = field(default_factory=dict)
    n_translated: int = 0

    @property
    def mask(self) -> np.ndarray:
        """The feasible horizons as bits, ``mask[v, a, b]`` bit ``L - 1`` set iff feasible, shape (2, F, F), uint64."""
        bits = np.left_shift(np.uint64(1), np.arange(self.L_max, dtype=np.uint64))
        return np.bitwise_or.reduce(np.where(self.feasible, bits[None, :, None, None], np.uint64(0)), axis=1)

    def verdict(self, v: int, L: int, a: int, b: int):
        """The verdict of ``(a, b)`` at ``L`` with safe set ``SAFE_VARIANTS[v]``."""
        return self.verdicts[(int(v), int(L), int(a), int(b))]

    def problem(self, v: int, L: int, a: int, b: int, eps_min: float = 0.0) -> TubeProblem:
        """The factor LP itself (:func:`factor_problem`)."""
        return factor_problem(self.factor, a, b, L, SAFE_VARIANTS[int(v)], eps_min)


def factor_problem(factor: Factor, a: int, b: int, L: int, variant: str, eps_min: float = 0.0,
                   boxes: dict | None = None) -> TubeProblem:
    """The tube LP of the factor pair ``(a, b)`` at ``L`` with safe set ``variant``.

    Parameters
    ----------
    factor : Factor
    a, b : int               factor cells (``a == b`` allowed)
    L : int
    variant : {'box', 'source'}
    eps_min : float
    boxes : dict, optional
        ``(a, b) -> (lo, hi, bounding box)``, filled and reused (the same for every ``L``).
    """
    if variant not in SAFE_VARIANTS:
        raise ValueError(f"variant: expected one of {SAFE_VARIANTS}, got {variant!r}")
    Fa, Fb = factor.cells[a], factor.cells[b]
    hit = None if boxes is None else boxes.get((a, b))
    if hit is None:
        lo = np.minimum(Fa.bounding_box()[0], Fb.bounding_box()[0])
        hi = np.maximum(Fa.bounding_box()[1], Fb.bounding_box()[1])
        for x in (lo, hi):
            x.setflags(write=False)
        hit = (lo, hi, Fa if a == b else Polytope.box(lo, hi))
        if boxes is not None:
            boxes[(a, b)] = hit
    lo, hi, box = hit
    safe = box if variant == "box" else Fa
    return TubeProblem(factor.system, Fa, Fb, safe, factor.Z[a], int(L), (lo, hi), float(eps_min))


def factor_keep(factor: Factor, L_max: int) -> tuple[np.ndarray, np.ndarray]:
    """Which factor LPs may be feasible, by the sound necessary conditions of :mod:`.pruning`.

    The tests hold for every safe set (reachability of ``F_b ⊖ W_g`` from every vertex of ``F_a``),
    self-pairs included; the obstacle-case test (O) (``A F_a ⊕ B U`` must meet ``F_b ⊖ W_g``) holds
    for the ``'source'`` safe set.

    Returns
    -------
    keep : ndarray of bool, shape (2, L_max, F, F)
        ``False``: the factor LP is infeasible for sure.
    counts : dict
        Pruned instances per reason.
    """
    F = factor.n_cells
    fdec = CellDecomposition(tuple(factor.cells), (None,) * F, name=f"factor cells of axes {list(factor.axes)}")
    sysm = factor.system
    a, b = (x.ravel() for x in np.meshgrid(np.arange(F), np.arange(F), indexing="ij"))
    keep = np.zeros((2, int(L_max), F, F), dtype=bool)
    fits = target_fits(fdec, sysm)
    ok = fits[b]
    counts = {"target_too_small": int(2 * L_max * np.sum(~ok))}
    if ok.any():
        T = reach_tables(fdec, sysm, int(L_max))
        kp, reach1, c = prune_pairs(fdec, sysm, T, a[ok], b[ok])
        keep[0][:, a[ok], b[ok]] = kp.T
        keep[1][:, a[ok], b[ok]] = kp.T & reach1[None, :]
        counts.update({k: 2 * v for k, v in c.items()})
        counts["obstacle_unreachable"] = int(np.sum(kp & ~reach1[:, None]))
    return keep, counts


def solve_factor(factor: Factor, group: int, L_max: int, solve_batch=None, eps_min: float = 0.0,
                 progress: bool = False, pruning: bool = True, by_class: bool = True) -> FactorTable:
    """Solve every factor LP of one group.

    Parameters
    ----------
    factor : Factor
    group : int              the group's index (recorded)
    L_max : int
    solve_batch : callable, optional
        ``solve_batch(problems, progress=bar) -> list[Verdict]`` of the tube method; default
        :data:`~tubejax.lp.evidence.verdict.highs_solve_batch`.
    eps_min : float
    progress : bool
    pruning : bool
        Drop the factor LPs that :func:`factor_keep` proves infeasible (they get no verdict).
    by_class : bool
        With ``pruning``: solve one LP per exact translation class first
        (:mod:`tubejax.abstraction.translation_classes`: the translates of a clearly infeasible one are
        settled by it; every edge is solved and proved). ``False``: every LP kept is solved (a verifier's
        independent re-solve).

    Returns
    -------
    FactorTable
    """
    t0 = time.perf_counter()
    solve_batch = highs_solve_batch if solve_batch is None else solve_batch
    F = factor.n_cells
    a, b = (x.ravel() for x in np.meshgrid(np.arange(F), np.arange(F), indexing="ij"))
    keep, pruned = factor_keep(factor, L_max) if pruning else (np.ones((2, int(L_max), F, F), bool), {})
    keys, probs, boxes = [], [], {}
    for L in range(1, int(L_max) + 1):
        for v, variant in enumerate(SAFE_VARIANTS):
            own = ((a != b) if v == 1 else np.ones_like(a, bool)) & keep[v, L - 1, a, b]
            for x, y in zip(a[own].tolist(), b[own].tolist()):
                keys.append((v, L, x, y))
                probs.append(factor_problem(factor, x, y, L, variant, eps_min, boxes))
    with tqdm(total=len(probs), desc=f"factor LPs, axes {list(factor.axes)}", unit="LP", disable=not progress,
              leave=False) as bar:
        if pruning and by_class and probs:             # one solve per exact translation class first
            k = np.array(keys, dtype=np.int64).reshape(-1, 4)
            fdec = CellDecomposition(tuple(factor.cells), (None,) * F, name=f"factor cells of axes {list(factor.axes)}")
            verdicts, n_moved = solve_by_class(solve_batch, TranslationClasses(fdec, factor.system), probs, k[:, 2],
                                               k[:, 3], k[:, 0] == 1, progress=bar)
        else:
            verdicts, n_moved = list(solve_batch(probs, progress=bar)), 0
    if len(verdicts) != len(probs):
        raise RuntimeError(f"solve_batch returned {len(verdicts)} verdicts for {len(probs)} problems")
    feasible = np.zeros((2, int(L_max), F, F), dtype=bool)
    margin = np.full((2, int(L_max), F, F), np.nan)
    table = {}
    for (v, L, x, y), verdict in zip(keys, verdicts):
        if not hasattr(verdict, "status"):           # a Pending confirmation: wait for it
            verdict = verdict.result()
        table[(v, L, x, y)] = verdict
        feasible[v, L - 1, x, y] = verdict.status == "edge"
        margin[v, L - 1, x, y] = verdict.margin
    for L in range(1, int(L_max) + 1):               # a self-pair's 'source' LP is its 'box' LP
        for x in range(F):
            if (0, L, x, x) in table:
                table[(1, L, x, x)] = table[(0, L, x, x)]
    diag = np.arange(F)
    feasible[1][:, diag, diag] = feasible[0][:, diag, diag]
    margin[1][:, diag, diag] = margin[0][:, diag, diag]
    seconds = time.perf_counter() - t0
    log.info("factor axes %s: %d LPs solved, %d settled by translation, %d feasible, %d pruned, %.2f s",
             list(factor.axes), len(probs) - n_moved, n_moved, int(feasible.sum()), sum(pruned.values()), seconds)
    return FactorTable(int(group), factor, int(L_max), feasible, margin, table, seconds, len(probs) - n_moved, pruned,
                       n_moved)


def _same_sets(P, Q) -> bool:
    """Whether two sets are given by the same data, bit for bit (a polytope's ``vertices``, ``H``, ``h``)."""
    if isinstance(P, Polytope) != isinstance(Q, Polytope):
        return False
    if not isinstance(P, Polytope):
        return type(P) is type(Q) and P.dim == Q.dim and P.radius == Q.radius
    return all(x.shape == y.shape and np.array_equal(x, y) for x, y in ((P.vertices, Q.vertices), (P.H, Q.H),
                                                                      (P.h, Q.h)))


def same_factor_data(f: Factor, g: Factor) -> bool:
    """Whether two factors pose the same factor LPs, bit for bit: the same system (``A``, ``B``, ``U``,
    ``W``, state constraints), factor cells and cross-sections, in the same order."""
    s, t = f.system, g.system
    return (not s.differences(t) and _same_sets(s.U, t.U) and _same_sets(s.W, t.W)
            and len(f.cells) == len(g.cells) and all(map(_same_sets, f.cells, g.cells))
            and len(f.Z) == len(g.Z) and all(map(_same_sets, f.Z, g.Z)))


def solve_factors(factors, L_max: int, solve_batch=None, eps_min: float = 0.0, progress: bool = False,
                  pruning: bool = True) -> tuple:
    """:func:`solve_factor` of every group; a group whose factor LPs are those of an earlier group, bit for bit
    (:func:`same_factor_data`: e.g. two axes of a cubic grid), takes that group's verdicts (``n_lps = 0``).

    Returns
    -------
    tuple of FactorTable, one per group
    """
    tables: list = []
    for g, f in enumerate(factors):
        twin = next((t for t in tables if same_factor_data(t.factor, f)), None)
        if twin is None:
            tables.append(solve_factor(f, g, L_max, solve_batch, eps_min, progress, pruning))
        else:
            log.info("factor axes %s: the factor LPs of axes %s, bit for bit", list(f.axes), list(twin.factor.axes))
            tables.append(FactorTable(int(g), f, twin.L_max, twin.feasible.copy(), twin.margin.copy(),
                                      dict(twin.verdicts), 0.0, 0, dict(twin.pruned), 0))
    return tuple(tables)
