"""A cell decomposition of the free workspace (docs/math/problem-data.md): what every workspace kind
produces and the abstraction consumes."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..geometry import Polytope
from .obstacle_index import ObstacleIndex
from .pair_hulls import padded_vertices, pair_hull_geoms, pair_hull_hreps, pair_hull_polytopes
from .validate import validate_decomposition

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
        Convex :class:`Polytope` obstacles and/or 2-D shapely geometries; their union is ``O``.
    grid : ndarray of int, shape (N, d) or None
        Grid index of each cell (``None`` for triangulations).
    name : str
        Where the decomposition came from (a file name, say).
    domain : Polytope or None
        The workspace as one convex set when it is one (an n-D box grid: its box), so that
        free space a removed cell leaves outside every obstacle is still inside it; ``None``:
        the workspace is the union of the cells and the obstacles.
    """

    cells: tuple
    labels: tuple
    obstacles: tuple = ()
    grid: np.ndarray | None = None
    name: str = ""
    domain: Polytope | None = None
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self):
        if len(self.cells) == 0:
            raise ValueError(f"{self.name or 'decomposition'}: no cells")
        if len(self.labels) != len(self.cells):
            raise ValueError(f"{self.name}: {len(self.labels)} labels for {len(self.cells)} cells")
        dims = {c.dim for c in self.cells}
        if len(dims) != 1:
            raise ValueError(f"{self.name}: cells of mixed dimensions {sorted(dims)}")
        validate_decomposition(self)      # cells have volume, no overlaps, no obstacle inside

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
        """``P_ij = co(P_i u P_j)`` of one pair (see :meth:`pair_hulls`)."""
        return self.pair_hulls([i], [j])[0]

    def pair_hulls(self, src, dst) -> list:
        """``P_ij`` of the pairs ``(src[k], dst[k])``, vectorised, a list of ``K``
        (:mod:`tubejax.model.workspace.pair_hulls`)."""
        return pair_hull_polytopes(self.cells, src, dst, self._cache.setdefault("hull_shapes", {}),
                                   self.padded_vertices())

    def pair_hull_hreps(self, src, dst) -> list:
        """An H-rep ``(H, h)`` of each ``P_ij`` (:meth:`pair_hulls`' facets; in n-D without
        building the polytopes, :func:`~tubejax.model.workspace.pair_hulls.pair_hull_hreps`)."""
        return pair_hull_hreps(self.cells, src, dst, self._cache.setdefault("hull_shapes", {}),
                               self.padded_vertices())

    def padded_vertices(self) -> tuple[np.ndarray, np.ndarray]:
        """All cell vertices zero-padded to one count, ``(V (N, nv_max, n), counts (N,))`` (cached)."""
        if "padded" not in self._cache:
            self._cache["padded"] = padded_vertices(self.cells)
        return self._cache["padded"]

    def cell_boxes(self) -> tuple[np.ndarray, np.ndarray]:
        """Bounding boxes of the cells, ``(lower, upper)`` each of shape ``(N, n)`` (cached)."""
        if "cell_boxes" not in self._cache:
            lo = np.array([c.bounding_box()[0] for c in self.cells])
            hi = np.array([c.bounding_box()[1] for c in self.cells])
            lo.setflags(write=False)
            hi.setflags(write=False)
            self._cache["cell_boxes"] = (lo, hi)
        return self._cache["cell_boxes"]

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Bounding box of all cells, ``(lower, upper)`` each of shape ``(n,)``."""
        V = np.vstack([c.vertices for c in self.cells])
        return V.min(axis=0), V.max(axis=0)

    def obstacle_case(self, i: int, j: int) -> bool:
        """Whether ``int P_ij`` meets ``int O`` (docs/math/problem-data.md), for one pair."""
        return bool(self.obstacle_cases([i], [j])[0])

    def obstacle_cases(self, src, dst) -> np.ndarray:
        """Whether ``int P_ij`` meets ``int O`` for the pairs ``(src[k], dst[k])``, shape ``(K,)``
        (only those pairs built and tested, :class:`~tubejax.model.workspace.obstacle_index.ObstacleIndex`)."""
        src = np.asarray(src, dtype=int).reshape(-1)
        dst = np.asarray(dst, dtype=int).reshape(-1)
        if not self.obstacles:
            return np.zeros(len(src), dtype=bool)
        index = self._obstacle_index()
        lo, hi = self.cell_boxes()
        if self.dim == 2:
            hulls = lambda a, b: pair_hull_geoms(self.cells, a, b, self.padded_vertices())  # noqa: E731
        else:
            hulls = self.pair_hulls
        return index.pair_cases(self.cells, lo, hi, src, dst, hulls)

    def _obstacle_index(self) -> ObstacleIndex:
        if "obstacle_index" not in self._cache:
            lo, hi = self.cell_boxes()
            tile = 8.0 * float(np.median(np.max(hi - lo, axis=1)))
            self._cache["obstacle_index"] = ObstacleIndex(self.obstacles, self.dim, tile)
        return self._cache["obstacle_index"]

    def obstacle_case_matrix(self) -> np.ndarray:
        """Boolean ``(N, N)`` matrix of :meth:`obstacle_case` over all pairs (all-pairs: for small
        decompositions, tests and plots only)."""
        if "obstacle_case" in self._cache:
            return self._cache["obstacle_case"]
        N = self.n_cells
        out = np.zeros((N, N), dtype=bool)
        iu, ju = np.triu_indices(N, k=1)
        flag = self.obstacle_cases(iu, ju)
        out[iu, ju] = flag
        out[ju, iu] = flag
        self._cache["obstacle_case"] = out
        return out
