"""The whole-problem limit of robust reach-avoid in 2-D: ``R_{k+1} = T ∪ (S ∩ Pre(R_k))`` from ``R_0 = T``
to a fixed point, computed as an outer approximation (docs/math/limit.md#the-limit,
docs/math/limit.md#what-is-approximated-and-in-which-direction). A run stopped by ``max_iterations``
(``converged = False``) is not the limit; a state constraint ``X`` binds from step 1 on
(docs/math/limit.md#state-constraint).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np
import shapely
from tqdm.auto import tqdm

from ...reachability.exact2d import clip_halfplanes
from ...model.geometry import Ball
from .polygons import (DEFAULT_SIDES, SLACK, disturbance_polygon, input_polygon, polygonal, robust_pre,
                       simplify_tolerance, tidy)

__all__ = ["ReachAvoidLimit", "reach_avoid_limit", "safe_and_target", "labelled_cells", "AREA_TOL", "MAX_ITERATIONS"]

log = logging.getLogger("tubejax")

#: Converged when one more iteration adds at most this fraction of ``area(S)``.
AREA_TOL = 1e-9
#: Default cap on the iterations (a run that reaches it is not converged).
MAX_ITERATIONS = 10_000


@dataclass(frozen=True, eq=False)
class ReachAvoidLimit:
    """An outer approximation of ``R_∞`` and how it was obtained.

    Attributes
    ----------
    geometry : shapely (Multi)Polygon
        The computed set ``R̂`` (``⊇ R_∞`` when ``converged``).
    converged : bool
        One more iteration added at most ``area_tol * free_area``; ``False``: stopped at
        ``max_iterations``, and ``geometry`` is not the limit.
    iterations : int
        Applications of ``R -> T ∪ (S ∩ Pre(R))``, the last one (the one that changed nothing) included.
    free_area, target_area : float
        ``area(S)`` (free cells without avoided ones; without ``X``) and ``area(T)``.
    last_growth : float
        Area the last iteration added.
    sides : int
        Sides of the polygon inscribed in a ball ``W`` (0 for a polytope ``W``).
    areas : tuple of float
        ``area(R̂_k)``, ``k = 0 .. iterations``.
    seconds : float
    target, avoid : str, tuple of str
    """

    geometry: object
    converged: bool
    iterations: int
    free_area: float
    target_area: float
    last_growth: float
    sides: int
    areas: tuple = ()
    seconds: float = 0.0
    target: str = ""
    avoid: tuple = ()
    safe: object = field(default=None, repr=False)

    @property
    def area(self) -> float:
        """``area(R̂)``."""
        return float(self.geometry.area)

    def summary(self) -> dict:
        """``{"area", "iterations", "converged"}`` (the ``limit`` entry of ``conservatism.json``)."""
        return {"area": self.area, "iterations": int(self.iterations), "converged": bool(self.converged)}


def _inverse(A: np.ndarray) -> np.ndarray | None:
    """``A^{-1}`` (``None`` for ``A = I``); refuses a singular ``A``."""
    A = np.asarray(A, float)
    if np.array_equal(A, np.eye(2)):
        return None
    if abs(np.linalg.det(A)) <= 1e-12 * max(1.0, float(np.linalg.norm(A)) ** 2):
        raise ValueError(f"system.A: the limit needs an invertible A (Pre(R) = A^-1((R ⊖ W) ⊕ (-B U))), "
                         f"got the singular {A.tolist()}")
    return np.linalg.inv(A)


def labelled_cells(decomp, target, avoid=()) -> tuple:
    """``(target, avoid, target cells, avoided cells)``: the labels as strings (``avoid`` sorted) and their cells.

    Raises
    ------
    ValueError
        A label no cell carries, or the target among the avoided labels.
    """
    target, avoid = str(target), tuple(sorted({str(a) for a in avoid}))
    have = sorted({str(l) for l in decomp.labels if l is not None})
    for what, label in [("target", target)] + [("avoid", a) for a in avoid]:
        if label not in have:
            raise ValueError(f"{what}: no cell carries the label {label!r} (labels present: {have})")
    if target in avoid:
        raise ValueError(f"avoid: the target {target!r} is also avoided")
    return target, avoid, decomp.cells_with_label(target), {c for a in avoid for c in decomp.cells_with_label(a)}


def safe_and_target(decomp, target, avoid=()) -> tuple:
    """``(S, T, avoid)``: the free cells without the avoided labels' cells, the target label's cells
    (shapely polygons) and the avoided labels as sorted strings.

    Raises
    ------
    ValueError
        Not 2-D, an unknown label, or the target among the avoided labels.
    """
    if decomp.dim != 2:
        raise ValueError(f"workspace: the limit is computed in 2-D, got a {decomp.dim}-D decomposition")
    target, avoid, tcells, avoided = labelled_cells(decomp, target, avoid)
    polys = [shapely.Polygon(c.vertices) for c in decomp.cells]
    S = shapely.union_all([p for i, p in enumerate(polys) if i not in avoided])
    T = shapely.union_all([polys[i] for i in tcells])
    return polygonal(S), polygonal(T), avoid


def _state_constraint(X, S):
    """``X ∩ box`` as a shapely polygon, ``box`` the bounding box of ``S`` grown by one; each row
    moved out by ``SLACK`` times the box size (outer)."""
    lo, hi = np.asarray(S.bounds[:2]) - 1.0, np.asarray(S.bounds[2:]) + 1.0
    poly = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
    scale = float(np.max(np.abs(np.concatenate([lo, hi]))))
    poly = clip_halfplanes(poly, X.H / X.row_norms[:, None], X.h / X.row_norms + SLACK * scale)
    return shapely.Polygon(poly) if poly.shape[0] >= 3 else shapely.Polygon()


def reach_avoid_limit(decomp, system, target, avoid=(), *, sides: int = DEFAULT_SIDES,
                      max_iterations: int = MAX_ITERATIONS, area_tol: float = AREA_TOL,
                      progress: bool = False) -> ReachAvoidLimit:
    """Iterate ``R_{k+1} = T ∪ (S ∩ Pre(R_k))`` from ``R_0 = T`` to a fixed point (docs/math/limit.md).

    Parameters
    ----------
    decomp : CellDecomposition
        2-D cells (a grid map or a polygon workspace).
    system : LinearSystem
        2-D state, invertible ``A``; ``W`` a ball (inscribed ``sides``-gon) or a polytope.
    target : str
        The label whose cells form ``T``.
    avoid : sequence of str
        Labels whose cells are left out of ``S``.
    sides : int
        Sides of the regular polygon inscribed in a ball ``W`` (``>= 3``).
    max_iterations : int
        Cap (``>= 1``); reaching it gives ``converged = False``.
    area_tol : float
        Converged when one iteration adds at most ``area_tol * area(S)``, in ``(0, 1e-3]``.
    progress : bool
        A progress bar over the iterations (with the area and the last growth) and a log line
        every 50 iterations.

    Returns
    -------
    ReachAvoidLimit

    Raises
    ------
    ValueError
        Not 2-D, a singular ``A``, an unknown or avoided target label, bad ``sides``,
        ``max_iterations`` or ``area_tol``.
    """
    t0 = time.perf_counter()
    if system.n != 2:
        raise ValueError(f"system: the limit is computed in 2-D, got an n = {system.n} state")
    if isinstance(max_iterations, bool) or not isinstance(max_iterations, (int, np.integer)) or max_iterations < 1:
        raise ValueError(f"max_iterations: expected an integer >= 1, got {max_iterations!r}")
    if not (isinstance(area_tol, (int, float)) and 0 < float(area_tol) <= 1e-3):
        raise ValueError(f"area_tol: expected a number in (0, 1e-3], got {area_tol!r}")
    Ainv = _inverse(system.A)
    W_poly = disturbance_polygon(system.W, sides)
    BU_poly = input_polygon(system.B, system.U)
    S, T, avoid = safe_and_target(decomp, target, avoid)
    X = system.state_constraints.get("X")
    SX, TX = S, T
    if X is not None:
        Xp = _state_constraint(X, S)
        SX, TX = polygonal(S.intersection(Xp)), polygonal(T.intersection(Xp))
    tol = float(area_tol) * float(S.area)
    eta = simplify_tolerance(W_poly)
    R, areas, growth, converged, k = TX, [float(TX.area)], float("inf"), False, 0
    with tqdm(total=int(max_iterations), desc="reach-avoid limit", unit="it", disable=not progress,
              leave=False) as bar:
        while k < max_iterations:
            k += 1
            pre = robust_pre(tidy(R, eta), Ainv, W_poly, BU_poly)
            new = polygonal(shapely.union_all([R, TX, shapely.intersection(SX, pre)]))
            growth = float(new.area) - float(R.area)
            R = new
            areas.append(float(R.area))
            bar.update(1)
            bar.set_postfix(area=f"{R.area:.4f}", growth=f"{growth:.2e}")
            if progress and k % 50 == 0:
                log.info("reach-avoid limit: iteration %d, area %.6f, last growth %.3e", k, R.area, growth)
            if growth <= tol:
                converged = True
                break
    if X is not None:                                   # x(0) need not lie in X (docs/math/limit.md#state-constraint)
        R = polygonal(shapely.union_all([R, T, shapely.intersection(S, robust_pre(R, Ainv, W_poly, BU_poly))]))
    if not converged:
        log.warning("reach-avoid limit: not converged after %d iterations (last growth %.3e > %.3e): the set "
                    "is not the limit", k, growth, tol)
    return ReachAvoidLimit(R, converged, k, float(S.area), float(T.area), float(growth),
                           int(sides) if isinstance(system.W, Ball) else 0, tuple(areas),
                           time.perf_counter() - t0, str(target), avoid, S)
