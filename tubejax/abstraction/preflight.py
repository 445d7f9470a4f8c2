"""Checks before a run starts: inputs that can only give nothing, and what a run will cost.

:func:`empty_state_constraint` proves exactly that ``X`` misses the workspace; :func:`count_cells`
counts cells before the decomposition is built (building a million takes minutes and gigabytes);
:func:`estimate_run` bounds the LPs, the largest LP and the memory (an upper bound, never a promise
of run time); :func:`budget_refusal` says why a run is beyond a :class:`RunBudget`.
"""

from __future__ import annotations

import math
from fractions import Fraction
from typing import NamedTuple

import numpy as np

from ..lp.evidence.basis import BasisError
from ..lp.evidence.simplex import ExactLP, exact_simplex, farkas_value
from ..lp.evidence.registry import formulation
from ..model.workspace.voxelmap import LAYER_SEPARATOR
from .candidates import build_candidates
from .schedule import MemoryBudget, lp_dimensions, padded_horizon

__all__ = ["RunBudget", "RunEstimate", "empty_state_constraint", "count_cells", "estimate_run", "budget_refusal",
           "BYTES_PER_CELL"]

#: Memory of one cell of a decomposition (its polytope, label, grid index and the spatial index), about.
BYTES_PER_CELL = 3000


class RunBudget(NamedTuple):
    """The largest run started without asking (``None``: no limit on that count).

    Attributes
    ----------
    max_cells : int or None        cells of the workspace
    max_lps : int or None          LPs at most solved (kept ``(pair, L)`` instances)
    max_lp_size : int or None      variables plus rows of the largest LP (at ``L_max``)
    """

    max_cells: int | None = 250_000
    max_lps: int | None = 10_000_000
    max_lp_size: int | None = 25_000


class RunEstimate(NamedTuple):
    """What a run will compute, estimated before it starts (module docstring).

    Attributes
    ----------
    n_cells : int
    n_candidate_pairs : int        ordered pairs with at least one horizon kept
    n_lps : int                    kept ``(pair, L)`` instances: at most this many LPs
    lp_size : int                  variables plus rows of one LP at ``L_max``
    largest_fitting_L : int        the largest ``L_max`` whose LP fits ``max_lp_size`` (0: none)
    megabytes : int                decomposition, candidates and the rounds' working set
    L_max : int
    """

    n_cells: int
    n_candidate_pairs: int
    n_lps: int
    lp_size: int
    largest_fitting_L: int
    megabytes: int
    L_max: int

    def line(self) -> str:
        """One line for the log and the console."""
        return (f"estimate: {self.n_cells:,} cells, {self.n_candidate_pairs:,} candidate pairs, at most "
                f"{self.n_lps:,} LPs (the largest, at L_max = {self.L_max}, with {self.lp_size:,} variables and "
                f"rows), about {self.megabytes:,} MB")


def _box(decomp) -> tuple[np.ndarray, np.ndarray]:
    """The bounding box of the free cells, shape ``(n,)`` each."""
    V = np.concatenate([c.vertices for c in decomp.cells])
    return V.min(axis=0), V.max(axis=0)


def empty_state_constraint(decomp, system) -> str | None:
    """Why ``system.X`` holds no point of the workspace, or ``None`` (nonempty, no ``X``, or undecided).

    The LP ``max t s.t. H x + t <= h, lo <= x <= hi, t <= 1`` over the free cells' bounding box is
    solved in rationals (every float is one exactly): an optimum ``t* < 0`` comes with multipliers
    ``y >= 0`` whose Farkas value is checked ``< 0`` exactly, which proves the intersection empty.
    Nothing is decided by the sign of a float. The finding names ``system.X`` and the box.
    """
    X = getattr(system, "X", None)
    if X is None or not decomp.cells:
        return None
    H, h = np.asarray(X.H, float), np.asarray(X.h, float)
    lo, hi = _box(decomp)
    n = H.shape[1]
    rows = [{**{j: Fraction(float(v)) for j, v in enumerate(r) if v}, n: Fraction(1)} for r in H]
    lp = ExactLP(rows, [Fraction(float(v)) for v in h], [Fraction(float(v)) for v in lo] + [None],
                 [Fraction(float(v)) for v in hi] + [Fraction(1)], n, len(rows))
    try:
        res = exact_simplex(lp, near=(lo + hi) / 2)
    except BasisError:
        return None
    if res.feasible:
        return None
    val = farkas_value(lp, res.y)
    if val is None or not val < 0:
        return None
    return (f"system.X: the state constraint holds no point of the workspace (H x <= h, {H.shape[0]} "
            f"row{'s' if H.shape[0] != 1 else ''}, misses the box {lo.tolist()}..{hi.tolist()} around the free cells, proved exactly); "
            "every tube vertex must lie in X, so no transition can exist: check the signs of H and h")


def count_cells(source) -> int | None:
    """The cells of a workspace source before it is built: the free characters of a grid or voxel
    map (times its velocity divisions), the boxes of a box grid (obstacles not subtracted: an upper bound); ``None`` for a
    polygon file (its triangles are only known once it is triangulated)."""
    kind = getattr(source, "kind", None)
    if kind == "grid":
        text = source._text()
        return source.cells_per_map_cell * sum(len(s) - s.count("#") for s in (ln.strip() for ln in text.split("\n"))
                                               if s and s != LAYER_SEPARATOR)
    if kind == "boxgrid":
        d = source.divisions
        return int(np.prod(np.broadcast_to(np.asarray(d), (len(source.lower),)), dtype=object))
    return None


def _lp_size(mb: MemoryBudget, L: int) -> int:
    return int(sum(lp_dimensions(*mb._dims, padded_horizon(L))))


def estimate_run(decomp, system, Z, L_max: int, pruning: bool = True, method: str = "tube",
                 memory_budget_mb: float | None = None, max_lp_size: int | None = None) -> RunEstimate:
    """The estimate of the module docstring for a run with these inputs (``Z``: per-cell sequence or
    ``ZAssignment``); builds the candidates, the run's first step (seconds on 10,000 cells)."""
    cand = build_candidates(decomp, system, L_max, pruning, vertex_lp=False)
    n_lps = int(cand.keep.sum())
    mb = MemoryBudget(memory_budget_mb, decomp, system, Z if Z is not None else decomp.cells)
    lp = formulation(method).solves_lp
    size = _lp_size(mb, L_max) if lp else 0
    fit = L_max
    if max_lp_size is not None and size > max_lp_size:
        lo, hi = 0, L_max                                   # the size grows with L: bisect
        while lo < hi:
            mid = (lo + hi + 1) // 2
            lo, hi = (mid, hi) if _lp_size(mb, mid) <= max_lp_size else (lo, mid - 1)
        fit = lo
    n_pairs = len(cand.src)
    rounds = 0 if not lp else min(
        mb.bytes_per_lp(L_max) * max(1, int(cand.keep[:, -1].sum() if cand.keep.size else 0)),
        math.inf if memory_budget_mb is None else memory_budget_mb * 2 ** 20)
    total = decomp.n_cells * BYTES_PER_CELL + n_pairs * (17 + L_max) + rounds
    return RunEstimate(decomp.n_cells, n_pairs, n_lps, size, fit, int(math.ceil(total / 2 ** 20)), L_max)


def _n(x) -> str:
    return f"{x:,}"


def budget_refusal(estimate: RunEstimate | None, budget: RunBudget, n_cells: int | None = None,
                   key: str = "budget") -> str | None:
    """Why a run is beyond ``budget`` (naming the estimate, ``key.<field>`` and what changes it), or None;
    with ``estimate=None`` only ``n_cells`` is checked (before the decomposition is built)."""
    cells = estimate.n_cells if estimate is not None else n_cells
    if budget.max_cells is not None and cells is not None and cells > budget.max_cells:
        return (f"{key}.max_cells: the workspace has {_n(cells)} cells, more than the budget of "
                f"{_n(budget.max_cells)} (about {_n(math.ceil(cells * BYTES_PER_CELL / 2 ** 20))} MB for the cells "
                "alone, and the LPs grow with them); use a coarser map (workspace.map_file, workspace.divisions), "
                f"or raise {key}.max_cells if this is meant")
    if estimate is None:
        return None
    if budget.max_lp_size is not None and estimate.lp_size > budget.max_lp_size:
        fit = (f"L_max <= {estimate.largest_fitting_L} fits" if estimate.largest_fitting_L
               else "no horizon fits")
        return (f"L_max: one LP at horizon L_max = {estimate.L_max} has {_n(estimate.lp_size)} variables and rows, "
                f"more than {key}.max_lp_size = {_n(budget.max_lp_size)}: an LP's solve time grows faster than its "
                f"size, and the run has up to {_n(estimate.n_lps)} of them ({fit}); lower L_max, or raise "
                f"{key}.max_lp_size if this is meant [{estimate.line()}]")
    if budget.max_lps is not None and estimate.n_lps > budget.max_lps:
        return (f"{key}.max_lps: the run would solve up to {_n(estimate.n_lps)} LPs, more than the budget of "
                f"{_n(budget.max_lps)}; lower L_max, keep pruning=true, use a coarser map (workspace.map_file, "
                f"workspace.divisions) or a shard of the run (shard.count), or raise {key}.max_lps "
                f"[{estimate.line()}]")
    return None
