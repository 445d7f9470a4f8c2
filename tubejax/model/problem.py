"""The tube problems: :class:`TubeProblem` (the data of Problem 2 for one ordered pair and a
horizon) and the problems of many pairs; the LP layer states and solves them.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any, NamedTuple

import numpy as np

from .geometry import Polytope
from .system import LinearSystem
from .workspace.decomposition import CellDecomposition
from .zassignment import z_of_pair
from .zshape.kinds import source_points

__all__ = ["TubeProblem", "Pairs", "pair_problem", "pair_problems", "RoundProblems"]


@dataclasses.dataclass(frozen=True, eq=False)
class TubeProblem:
    """Problem 2 for one ordered pair ``(i, j)`` and horizon ``L``.

    Attributes
    ----------
    system : LinearSystem
    source : Polytope       ``P_i`` (its vertices are ``q_k(0)``)
    target : Polytope       ``P_j``
    safe : Polytope         ``S``: ``P_ij`` (free case) or ``P_i`` (obstacle case)
    Z : Polytope            cross-section, as many vertices as ``P_i``, paired by index
    L : int                 horizon, ``>= 1``
    box : (ndarray, ndarray) bounding box of ``P_ij`` (bounds on ``p``)
    eps_min : float         C1 lower bound (default 0)
    min_margin : float      the margin ``t*`` an edge must reach (default 0: Problem 2 itself);
                            in ``[0, 1)``, below ``t_max``
    """

    system: LinearSystem
    source: Polytope
    target: Polytope
    safe: Polytope
    Z: Polytope
    L: int
    box: tuple
    eps_min: float = 0.0
    min_margin: float = 0.0

    def __post_init__(self):
        if int(self.L) < 1:
            raise ValueError(f"L must be >= 1, got {self.L}")
        if not 0.0 <= self.min_margin < 1.0:
            raise ValueError(f"min_margin must be in [0, 1), got {self.min_margin!r}")
        if self.Z.n_vertices != self.source.n_vertices:
            raise ValueError(f"Z has {self.Z.n_vertices} vertices but the source cell has "
                             f"{self.source.n_vertices}")
        if np.any(self.Z.h <= 0):
            raise ValueError("Z must contain 0 in its interior")


def pair_problem(decomp: CellDecomposition, system: LinearSystem, Z: Polytope, i: int, j: int,
                 L: int, eps_min: float = 0.0, min_margin: float = 0.0) -> TubeProblem:
    """Problem 2 for the ordered pair ``(i, j)`` at horizon ``L`` (``S = P_ij``, or ``P_i`` in the obstacle case)."""
    if i == j:
        raise ValueError(f"self-pairs are not transitions (i = j = {i})")
    pairs = Pairs(np.array([i]), np.array([j]), np.array([decomp.obstacle_case(i, j)]))
    return pair_problems(decomp, system, (Z,), pairs, L, eps_min, z_of_source=False, min_margin=min_margin)[0]


class Pairs(NamedTuple):
    """Ordered pairs of cells ``(src[k], dst[k])`` with each pair's obstacle case.

    Attributes
    ----------
    src, dst : array_like of int, shape (K,)
        Source and target cell of each pair.
    obstacle : array_like of bool, shape (K,)
        The obstacle case of each pair (``S = P_i`` there, ``S = P_ij`` otherwise).
    """

    src: Any
    dst: Any
    obstacle: Any


def pair_problems(decomp: CellDecomposition, system: LinearSystem, Z, pairs: Pairs, L: int,
                  eps_min: float = 0.0, z_of_source: bool = True, min_margin: float = 0.0) -> list:
    """Problem 2 for the pairs ``(src[k], dst[k])`` at horizon ``L``, built vectorised (``box``, the
    bounding box of ``P_ij``, is exactly the union of the two cells' boxes).

    Parameters
    ----------
    Z : sequence of Polytope or ZAssignment
        With ``z_of_source``: the cross-sections by source cell, ``Z[i]`` for tubes leaving
        cell ``i``, or a :class:`~tubejax.model.zassignment.ZAssignment` whose per-pair overrides
        apply (:func:`~tubejax.model.zassignment.z_of_pair`); else ``Z[k]`` belongs to pair ``k``.
    pairs : Pairs
        The pairs ``(src[k], dst[k])`` and their obstacle cases, ``K`` of them.
    min_margin : float
        :attr:`TubeProblem.min_margin` of every problem.

    Returns
    -------
    list of TubeProblem, length K
    """
    src = np.asarray(pairs.src, dtype=int)
    dst = np.asarray(pairs.dst, dtype=int)
    obstacle = np.asarray(pairs.obstacle, dtype=bool)
    if np.any(src == dst):
        k = int(np.flatnonzero(src == dst)[0])
        raise ValueError(f"self-pairs are not transitions (i = j = {src[k]})")
    cells = decomp.cells
    lo, hi = decomp.cell_boxes()
    blo = np.minimum(lo[src], lo[dst])
    bhi = np.maximum(hi[src], hi[dst])
    for a in (blo, bhi):
        a.setflags(write=False)
    free = np.flatnonzero(~obstacle)
    safe = [cells[i] for i in src]
    for k, hull in zip(free, decomp.pair_hulls(src[free], dst[free])):
        safe[k] = hull
    L, eps_min, min_margin = int(L), float(eps_min), float(min_margin)
    zs = [z_of_pair(Z, i, j) for i, j in zip(src.tolist(), dst.tolist())] if z_of_source else list(Z)
    # the source's points that Z's vertices pair with (a chamfer Z: vertices and edge points)
    sources = [source_points(cells[i], z.n_vertices) for i, z in zip(src.tolist(), zs)]
    # TubeProblem.__post_init__ checks L, and Z against the source's vertex count: run it once
    # per distinct (Z, source), then create the (frozen) instances without re-checking
    checked = set()
    for q, j, s, z, bl, bh in zip(sources, dst.tolist(), safe, zs, blo, bhi):
        key = (id(z), id(q))
        if key not in checked:
            TubeProblem(system, q, cells[j], s, z, L, (bl, bh), eps_min, min_margin)
            checked.add(key)
    return [_unchecked(system, q, cells[j], s, z, L, (bl, bh), eps_min, min_margin)
            for q, j, s, z, bl, bh in zip(sources, dst.tolist(), safe, zs, blo, bhi)]


_FIELDS = tuple(f.name for f in dataclasses.fields(TubeProblem))


def _unchecked(*values) -> TubeProblem:
    """A :class:`TubeProblem` from its field values in order, without ``__post_init__``."""
    prob = object.__new__(TubeProblem)
    prob.__dict__.update(zip(_FIELDS, values))
    return prob


class RoundProblems:
    """The problems of one round's pairs at horizon ``L`` (arguments as :func:`pair_problems`), built on
    demand: the translation classes need every pair's key but only some problems (most translates are
    settled by their representative), so :meth:`take` builds each pair's at most once.

    Attributes
    ----------
    zs : list of Polytope, length K       each pair's ``Z``
    seconds : float                       time spent building problems so far
    """

    def __init__(self, decomp, system, Z, pairs: Pairs, L: int, eps_min: float = 0.0, min_margin: float = 0.0):
        self.args = (decomp, system, Z)
        self.src, self.dst = np.asarray(pairs.src, dtype=int), np.asarray(pairs.dst, dtype=int)
        self.obstacle = np.asarray(pairs.obstacle, dtype=bool)
        self.L, self.eps_min, self.min_margin = int(L), float(eps_min), float(min_margin)
        self.zs = [z_of_pair(Z, i, j) for i, j in zip(self.src.tolist(), self.dst.tolist())]
        self._built: dict = {}
        self.seconds = 0.0

    def __len__(self) -> int:
        return len(self.src)

    def take(self, idx) -> list:
        """The problems of the pairs ``idx`` (ints into the round), in that order."""
        idx = [int(k) for k in idx]
        new = np.array(sorted({k for k in idx if k not in self._built}), dtype=int)
        if len(new):
            t0 = time.perf_counter()
            decomp, system, Z = self.args
            pairs = Pairs(self.src[new], self.dst[new], self.obstacle[new])
            for k, p in zip(new.tolist(), pair_problems(decomp, system, Z, pairs, self.L, self.eps_min,
                                                        min_margin=self.min_margin)):
                self._built[k] = p
            self.seconds += time.perf_counter() - t0
        return [self._built[k] for k in idx]
