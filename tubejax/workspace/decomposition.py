"""A cell decomposition of the free workspace (SPEC section 1).

:class:`CellDecomposition` is what every workspace kind (grid map, polygon
workspace, n-D box grid) produces and what the abstraction consumes.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import shapely

from ..geometry import Polytope, convex_hull_of, interiors_intersect, to_shapely
from ..geometry.obstacles import TOUCH_TOL

__all__ = ["CellDecomposition"]


@dataclass(frozen=True, eq=False)
class CellDecomposition:
    """Convex cells covering the free space, with labels and obstacles.

    Attributes
    ----------
    cells : tuple of Polytope
        ``P_0 ... P_{N-1}`` (0-based ids), all of one dimension ``n``.
    labels : tuple of (str or None)
        Region label of each cell (``None`` for an unlabelled cell).
    obstacles : tuple
        Convex :class:`Polytope` obstacles (any dimension) and/or 2-D shapely
        geometries (possibly non-convex). Their union is ``O``.
    grid : ndarray of int, shape (N, d) or None
        Grid index of each cell: ``(row, col)`` for grid maps, the box index
        for n-D box grids, ``None`` for triangulations.
    name : str
        Where the decomposition came from (a file name, say).
    """

    cells: tuple
    labels: tuple
    obstacles: tuple = ()
    grid: np.ndarray | None = None
    name: str = ""
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self):
        if len(self.cells) == 0:
            raise ValueError(f"{self.name or 'decomposition'}: no cells")
        if len(self.labels) != len(self.cells):
            raise ValueError(f"{self.name}: {len(self.labels)} labels for {len(self.cells)} cells")
        dims = {c.dim for c in self.cells}
        if len(dims) != 1:
            raise ValueError(f"{self.name}: cells of mixed dimensions {sorted(dims)}")
        from .validate import validate_decomposition  # cells have volume, no overlaps, no obstacle inside
        validate_decomposition(self)

    @property
    def n_cells(self) -> int:
        return len(self.cells)

    @property
    def dim(self) -> int:
        return self.cells[0].dim

    def cells_with_label(self, label) -> list[int]:
        """Ids of the cells carrying ``label`` (compared as strings)."""
        return [i for i, l in enumerate(self.labels) if l is not None and str(l) == str(label)]

    def pair_hull(self, i: int, j: int) -> Polytope:
        """``P_ij = co(P_i u P_j)`` (cached; in 2-D built from the shapely hulls of all pairs)."""
        key = (min(i, j), max(i, j))
        cache = self._cache.setdefault("hulls", {})
        if key not in cache:
            geoms = self._pair_hull_geoms() if self.dim == 2 else None
            if geoms is not None:
                ring = shapely.get_coordinates(shapely.get_exterior_ring(geoms[key]))
                cache[key] = Polytope.from_convex_polygon(ring)
            else:
                cache[key] = convex_hull_of(self.cells[i], self.cells[j])
        return cache[key]

    def _pair_hull_geoms(self) -> dict:
        """2-D only: ``{(i, j): shapely polygon of P_ij}`` for all ``i < j``, computed at once."""
        if "hull_geoms" not in self._cache:
            N = self.n_cells
            iu, ju = np.triu_indices(N, k=1)
            verts = [c.vertices for c in self.cells]
            counts = np.array([len(v) for v in verts])
            coords = np.concatenate([np.vstack([verts[i], verts[j]]) for i, j in zip(iu, ju)]) \
                if len(iu) else np.zeros((0, 2))
            idx = np.repeat(np.arange(len(iu)), counts[iu] + counts[ju])
            hulls = shapely.convex_hull(shapely.multipoints(coords, indices=idx)) if len(iu) else []
            self._cache["hull_geoms"] = {(int(i), int(j)): g for i, j, g in zip(iu, ju, hulls)}
        return self._cache["hull_geoms"]

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Bounding box of all cells, ``(lower, upper)`` each of shape ``(n,)``."""
        V = np.vstack([c.vertices for c in self.cells])
        return V.min(axis=0), V.max(axis=0)

    def obstacle_case(self, i: int, j: int) -> bool:
        """Whether ``int P_ij`` meets ``int O`` (SPEC section 1)."""
        return bool(self.obstacle_case_matrix()[i, j])

    def obstacle_case_matrix(self) -> np.ndarray:
        """Boolean ``(N, N)`` matrix: entry ``(i, j)`` is True in the obstacle case.

        In 2-D all pair hulls are tested against the union of the obstacles
        at once with shapely; otherwise one overlap LP per candidate obstacle.
        """
        if "obstacle_case" in self._cache:
            return self._cache["obstacle_case"]
        N = self.n_cells
        out = np.zeros((N, N), dtype=bool)
        if self.obstacles:
            if self.dim == 2:
                union = shapely.union_all([o if not isinstance(o, Polytope) else to_shapely(o)
                                           for o in self.obstacles])
                shapely.prepare(union)
                iu, ju = np.triu_indices(N, k=1)
                geoms = self._pair_hull_geoms()
                hulls = np.array([geoms[int(i), int(j)] for i, j in zip(iu, ju)], dtype=object)
                hit = shapely.intersects(union, hulls)
                area = np.zeros(len(hulls))
                if hit.any():
                    area[hit] = shapely.area(shapely.intersection(hulls[hit], union))
                flag = area > TOUCH_TOL
                out[iu, ju] = flag
                out[ju, iu] = flag
            else:
                for i in range(N):
                    for j in range(i + 1, N):
                        hull = self.pair_hull(i, j)
                        flag = any(interiors_intersect(hull, o) for o in self.obstacles)
                        out[i, j] = out[j, i] = flag
        self._cache["obstacle_case"] = out
        return out
