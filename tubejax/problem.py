"""From a decomposition and a system to the tube problem of one pair and horizon."""

from __future__ import annotations

from .geometry import Polytope
from .lp.formulations.tube.dense import TubeProblem
from .system import LinearSystem
from .workspace.decomposition import CellDecomposition

__all__ = ["pair_problem"]


def pair_problem(decomp: CellDecomposition, system: LinearSystem, Z: Polytope, i: int, j: int,
                 L: int, eps_min: float = 0.0) -> TubeProblem:
    """Problem 2 for the ordered pair ``(i, j)`` at horizon ``L``.

    ``S = P_ij`` in the free case and ``S = P_i`` in the obstacle case
    (:meth:`CellDecomposition.obstacle_case`).
    """
    if i == j:
        raise ValueError(f"self-pairs are not transitions (i = j = {i})")
    hull = decomp.pair_hull(i, j)
    safe = decomp.cells[i] if decomp.obstacle_case(i, j) else hull
    return TubeProblem(system, decomp.cells[i], decomp.cells[j], safe, Z, int(L),
                       hull.bounding_box(), float(eps_min))
