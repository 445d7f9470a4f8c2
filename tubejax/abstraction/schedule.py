"""Algorithm 2 as a state machine per candidate pair, and the memory budget of its rounds.

:class:`PairSchedule` holds each candidate pair's next horizon, its pending HiGHS confirmation and
its edge's horizon. A pair's horizons are solved strictly in increasing order, each after the
previous kept one was settled as a non-edge, so the first edge found is at the minimal ``L``
(docs/math/tube-lp.md#paper-slips, slip 2) however the solving is batched, deferred or resumed:
:meth:`PairSchedule.settle` refuses a fact at any other horizon. :class:`MemoryBudget` turns a
budget in MB into a round's chunk size and the confirmations allowed to wait.
:meth:`PairSchedule.progress` estimates the time left, weighting instances by :func:`horizon_cost`.
"""

from __future__ import annotations

import math

import numpy as np

from ..model.zassignment import all_cross_sections

__all__ = ["PairSchedule", "MemoryBudget", "lp_dimensions", "padded_horizon", "horizon_cost", "format_seconds",
           "BYTES_PER_NUMBER", "BYTES_PER_PROBLEM", "BYTES_PER_PENDING"]

#: Bytes of working set per LP variable or row in the batched PDHG engine, about 25 float64 copies
#: (data, scaled copies, iterates, averages, certificates; docs/explanation/performance.md#memory-per-lp).
BYTES_PER_NUMBER = 208
#: Bytes per problem outside the solver's arrays (the problem object ~1.2 kB, its verdict, futures).
BYTES_PER_PROBLEM = 4096
#: Bytes per likely edge waiting for HiGHS (future and verdict here, the queued problem in the helper).
BYTES_PER_PENDING = 8192
#: Share of the budget for one chunk's problems and solver working set; the rest for waiting confirmations.
CHUNK_SHARE = 0.75


class PairSchedule:
    """Per-pair progress of Algorithm 2 over sparse candidates.

    Parameters
    ----------
    keep : ndarray of bool, shape (K, L_max)
        ``keep[k, L-1]``: horizon ``L`` of pair ``k`` is a candidate instance.

    Attributes
    ----------
    next_L : ndarray of int, shape (K,)
        Next horizon to solve, ``L_max + 1`` once every kept horizon was refused.
    edge_L : ndarray of int, shape (K,)
        Horizon of the pair's edge, 0 while none is known.
    pending : ndarray of bool, shape (K,)
        A likely edge at ``next_L`` awaits confirmation (the pair is not solved meanwhile).
    """

    def __init__(self, keep: np.ndarray):
        self.keep = np.asarray(keep, dtype=bool)
        self.L_max = self.keep.shape[1]
        K = self.keep.shape[0]
        self.next_L = self._next_kept(np.arange(K), np.zeros(K, dtype=np.int64))
        self.edge_L = np.zeros(K, dtype=np.int64)
        self.pending = np.zeros(K, dtype=bool)
        self.cost = np.array([horizon_cost(L) for L in range(1, self.L_max + 1)], dtype=float)
        # instances left (and their cost) if no further edge is found, kept up to date by settle:
        # recomputing them from keep is O(K L_max), once per settle a quadratic step on long runs
        self._left = int(self.keep.sum())
        self._cost_left = float(self.keep.sum(axis=0) @ self.cost)
        self.cost_settled = 0.0
        self._marks: list = []                           # (seconds, cost_settled) at earlier estimates

    def _next_kept(self, ks, L) -> np.ndarray:
        """Smallest kept horizon above ``L[i]`` for pair ``ks[i]`` (``L_max + 1`` if none)."""
        cols = np.arange(1, self.L_max + 1)
        later = self.keep[ks] & (cols[None, :] > np.asarray(L)[:, None])
        return np.where(later.any(axis=1), later.argmax(axis=1) + 1, self.L_max + 1).astype(np.int64)

    def open_at(self, L: int) -> np.ndarray:
        """Pairs to solve at horizon ``L`` now (sorted): next horizon ``L``, not pending, no edge."""
        return np.flatnonzero((self.next_L == L) & ~self.pending & (self.edge_L == 0))

    def min_open(self) -> int | None:
        """Smallest horizon some pair can be solved at now, or ``None``."""
        ok = ~self.pending & (self.edge_L == 0) & (self.next_L <= self.L_max)
        return int(self.next_L[ok].min()) if ok.any() else None

    def suspend(self, ks) -> None:
        """Pairs ``ks`` have a likely edge at their next horizon, waiting for confirmation."""
        self.pending[np.asarray(ks, dtype=np.int64)] = True

    def release(self, ks) -> None:
        """Pairs ``ks`` wait no longer (their refused likely edge's next horizons may be solved)."""
        self.pending[np.asarray(ks, dtype=np.int64)] = False

    def settle(self, ks, L, is_edge) -> None:
        """Record the verdicts of pairs ``ks`` at horizons ``L``: an edge ends a pair, a non-edge moves
        it to its next kept horizon.

        Raises
        ------
        ValueError
            A pair was settled at a horizon other than its next one, or after its edge.
        """
        ks = np.asarray(ks, dtype=np.int64)
        L = np.broadcast_to(np.asarray(L, dtype=np.int64), ks.shape)
        is_edge = np.broadcast_to(np.asarray(is_edge, dtype=bool), ks.shape)
        if len(np.unique(ks)) != len(ks):
            raise ValueError("a pair was settled twice in one batch of facts")
        bad = (self.next_L[ks] != L) | (self.edge_L[ks] != 0)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            k = int(ks[i])
            raise ValueError(f"pair {k} settled at L={int(L[i])}, but its next horizon is {int(self.next_L[k])}"
                             + (f" and it already has an edge at L={int(self.edge_L[k])}" if self.edge_L[k] else ""))
        self.pending[ks] = False
        self.edge_L[ks[is_edge]] = L[is_edge]
        rest = ks[~is_edge]
        self.next_L[rest] = self._next_kept(rest, L[~is_edge])
        self.cost_settled += float(self.cost[L - 1].sum())
        self._left -= len(rest)                          # a non-edge: that instance is done
        self._cost_left -= float(self.cost[L[~is_edge] - 1].sum())
        ke, Le = ks[is_edge], L[is_edge]                 # an edge: its later horizons too
        later = self.keep[ke] & (np.arange(self.keep.shape[1])[None, :] >= (Le - 1)[:, None])
        self._left -= int(later.sum())
        self._cost_left -= float((later @ self.cost).sum())

    def remaining(self) -> int:
        """Instances still to solve if no further edge is found (pending ones included)."""
        return self._left

    def remaining_cost(self) -> float:
        """The :func:`horizon_cost` of the instances :meth:`remaining` counts."""
        return max(self._cost_left, 0.0)

    def seconds_left(self, seconds: float) -> float | None:
        """About how many seconds the rest takes, ``seconds`` after the first LP started, if no edge is found
        beyond the ``pending`` likely edges; None before anything was settled. Instances are weighted by
        :func:`horizon_cost`, at the slower of the whole run's and the last minute's pace, so the estimate
        follows a run that slows down."""
        if self.cost_settled <= 0 or seconds <= 0:
            return None
        left = self.remaining_cost()
        pend = np.flatnonzero(self.pending & (self.edge_L == 0))
        if 0 < len(pend) * self.L_max <= 1 << 22:
            later = self.keep[pend] & (np.arange(1, self.L_max + 1)[None, :] > self.next_L[pend, None])
            left -= float(later.sum(axis=0) @ self.cost)
        pace = seconds / self.cost_settled
        marks = self._marks
        while len(marks) > 1 and seconds - marks[1][0] >= RECENT_SECONDS:
            marks.pop(0)                                 # keep the last mark at least a minute old
        if marks and seconds - marks[0][0] >= RECENT_SECONDS and self.cost_settled > marks[0][1]:
            pace = max(pace, (seconds - marks[0][0]) / (self.cost_settled - marks[0][1]))
        marks.append((seconds, self.cost_settled))
        return pace * max(left, 0.0)

    def progress(self, seconds: float) -> str:
        """For a log line: ``'at most 1,234 instances left, at most ~5 min at the current pace'``
        (:meth:`remaining`, :meth:`seconds_left`: bounds that shrink as edges are found)."""
        eta = self.seconds_left(seconds)
        left = f"at most {self.remaining():,} instances left"
        return left if eta is None else f"{left}, at most ~{format_seconds(eta)} at the current pace"


#: The window of the recent pace in :meth:`PairSchedule.seconds_left`.
RECENT_SECONDS = 60.0


def horizon_cost(L: int) -> float:
    """Relative cost of one LP at horizon ``L``: its variables and rows grow linearly with the
    padded horizon (:func:`lp_dimensions`), plus a fixed part per LP worth about 4 horizons
    (building, sending and checking it), so a run's cost grows like ``L_max^2`` in the horizons."""
    return float(padded_horizon(L) + 4)


def format_seconds(s: float) -> str:
    """``42 s``, ``12 min``, ``3.5 h``."""
    if s < 90:
        return f"{s:.0f} s"
    if s < 5400:
        return f"{s / 60:.0f} min"
    return f"{s / 3600:.1f} h"


def padded_horizon(L: int) -> int:
    """The horizon the batched engine may pad ``L`` to (powers of two up to 8, then by at most a half)."""
    if L <= 8:
        return max(2, 1 << max(0, math.ceil(math.log2(max(L, 1)))))
    return math.ceil(1.5 * L)


def lp_dimensions(n: int, m: int, n_v: int, f_z: int, f_s: int, f_t: int, L: int) -> tuple[int, int]:
    """``(variables, rows)`` of the margin-form tube LP (docs/math/margins.md) at horizon ``L``."""
    n_x = L * (n + 1) + L * n_v * m + 1
    rows = (L - 1) * f_s + f_t + L * n_v * f_z
    return n_x, rows


class MemoryBudget:
    """How much of a round to solve per call, and how many confirmations may wait, within a budget.

    The estimate is per LP: :data:`BYTES_PER_NUMBER` times the variables and rows of the
    largest instance (horizon padded as the batched engine pads it, ``S`` with up to twice the
    facets of the largest cell), plus :data:`BYTES_PER_PROBLEM`. It bounds the working set of
    the rounds (problems, solver arrays, waiting confirmations), not the transition system
    being built nor the fixed cost of the interpreter and JAX.

    Parameters
    ----------
    megabytes : float or None
        The budget; ``None``: unbounded (a round is one chunk).
    decomp, system, Z
        The problem (cells, dimensions, cross-sections: a per-cell sequence or a
        :class:`~tubejax.model.zassignment.ZAssignment`, whose per-pair ``Z`` count too).
    """

    def __init__(self, megabytes, decomp, system, Z):
        self.megabytes = None if megabytes is None else float(megabytes)
        if self.megabytes is not None and not self.megabytes > 0:
            raise ValueError(f"memory_budget_mb must be > 0, got {megabytes!r}")
        f_cell = max(c.H.shape[0] for c in decomp.cells) if decomp.n_cells else 0
        zs = list(all_cross_sections(Z))
        nv = max([c.n_vertices for c in decomp.cells] + [z.n_vertices for z in zs], default=0)   # a chamfer Z: more
        self._dims = (system.n, system.m, nv, max((z.H.shape[0] for z in zs), default=0), 2 * f_cell, f_cell)

    def bytes_per_lp(self, L: int) -> int:
        """Estimated peak bytes of one LP at horizon ``L`` inside a round."""
        n_x, rows = lp_dimensions(*self._dims, padded_horizon(L))
        return BYTES_PER_NUMBER * (n_x + rows) + BYTES_PER_PROBLEM

    def megabytes_needed(self, L_max: int) -> int:
        """The smallest budget in which a chunk of one LP at horizon ``L_max`` (the largest of a run)
        fits: below it :meth:`chunk_size` would still give 1 and the rounds exceed the budget."""
        return math.ceil(self.bytes_per_lp(L_max) / CHUNK_SHARE / 2 ** 20)

    def chunk_size(self, L: int) -> int | None:
        """Problems per solver call at horizon ``L`` (``None``: the whole round)."""
        if self.megabytes is None:
            return None
        return max(1, int(CHUNK_SHARE * self.megabytes * 2 ** 20 // self.bytes_per_lp(L)))

    def max_pending(self) -> int | None:
        """Confirmations allowed to wait before the rounds pause for HiGHS (``None``: no limit)."""
        if self.megabytes is None:
            return None
        return max(1, int((1 - CHUNK_SHARE) * self.megabytes * 2 ** 20 // BYTES_PER_PENDING))
