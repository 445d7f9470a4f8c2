"""Seeded rooms-and-corridors grid maps of any size (docs/reference/formats.md#grid-map), for benchmarks.

:func:`rooms_and_corridors` gives a connected map of rooms, corridors and doors, the same for the same
seed; :func:`building` stacks such plans into a 3-D voxel map with stairwells between storeys.
"""

from __future__ import annotations

import numpy as np
from scipy.cluster.hierarchy import DisjointSet

__all__ = ["rooms_and_corridors", "rooms_and_corridors_map", "building", "building_map"]

#: Fraction of free cells the generator produces with its default sizes (measured).
_FREE_FRACTION = 0.77


def _walls(length: int, rng, room: tuple[int, int]) -> list[int]:
    """Wall positions cutting ``0 .. length-1`` into spans of ``room[0] .. room[1]`` cells."""
    out, pos = [], -1
    while True:
        pos += int(rng.integers(room[0], room[1] + 1)) + 1
        if pos >= length - room[0]:
            return out
        out.append(pos)


def _spans(walls: list[int], length: int) -> list[tuple[int, int]]:
    """The free spans ``[a, b)`` between walls."""
    edges = [-1] + walls + [length]
    return [(a + 1, b) for a, b in zip(edges[:-1], edges[1:]) if b > a + 1]


def rooms_and_corridors(rows: int, cols: int, seed: int = 0, room: tuple[int, int] = (3, 6),
                        corridor_prob: float = 0.2, extra_doors: float = 0.3,
                        labels: bool = True) -> str:
    """A connected rooms-and-corridors grid map as text (``#`` wall, ``.`` free).

    ``rows`` lines of ``cols`` characters (each ``>= 1``), a function of all arguments (``seed`` seeds
    ``numpy.random.default_rng``): ``room`` the smallest and largest room side, ``corridor_prob`` the
    probability that a band of rooms becomes a corridor, ``extra_doors`` that of a door the spanning
    tree does not need; ``labels``: ``1`` on the first free cell, ``2`` on the last (row-major).
    """
    if int(rows) < 1 or int(cols) < 1:
        raise ValueError(f"rows and cols must be >= 1, got {rows} x {cols}")
    if not (1 <= room[0] <= room[1]):
        raise ValueError(f"room must be (min, max) with 1 <= min <= max, got {room}")
    rng = np.random.default_rng(seed)
    rows, cols = int(rows), int(cols)
    wr, wc = _walls(rows, rng, room), _walls(cols, rng, room)
    free = np.ones((rows, cols), dtype=bool)
    free[wr, :] = False
    free[:, wc] = False
    rs, cs = _spans(wr, rows), _spans(wc, cols)
    # corridors: a band of rooms without the walls across it
    for a, b in rs:
        if rng.random() < corridor_prob:
            free[a:b, wc] = True
    for a, b in cs:
        if rng.random() < corridor_prob:
            free[wr, a:b] = True
    # rooms graph: (r, c) neighbours across one wall; doors on a random spanning tree + extras
    nr, nc = len(rs), len(cs)
    links = [((r, c), (r, c + 1)) for r in range(nr) for c in range(nc - 1)] + \
            [((r, c), (r + 1, c)) for r in range(nr - 1) for c in range(nc)]
    rooms = DisjointSet((r, c) for r in range(nr) for c in range(nc))
    for k in rng.permutation(len(links)):
        (r0, c0), (r1, c1) = links[k]
        if not (rooms.merge((r0, c0), (r1, c1)) or rng.random() < extra_doors):    # merge: True if it joined
            continue
        a, b = rs[r0] if r0 == r1 else cs[c0]
        width = min(int(rng.integers(1, 3)), b - a)
        at = int(rng.integers(a, b - width + 1))
        if r0 == r1:                                   # vertical wall between columns c0 and c1
            free[at:at + width, wc[c0]] = True
        else:                                          # horizontal wall between rows r0 and r1
            free[wr[r0], at:at + width] = True
    grid = np.where(free, ".", "#").astype("<U1")
    if labels and free.any():
        idx = np.argwhere(free)
        grid[tuple(idx[0])] = "1"
        if len(idx) > 1:
            grid[tuple(idx[-1])] = "2"
    return "".join("".join(row) + "\n" for row in grid)


def rooms_and_corridors_map(free_cells: int, seed: int = 0, **kw) -> str:
    """A square :func:`rooms_and_corridors` map with about ``free_cells`` free cells.

    Of the sides within 5 of ``sqrt(free_cells / 0.77)``, the one whose map (same seed) comes
    closest to ``free_cells`` is used.
    """
    return _closest(free_cells, 1, 1, "#\n", lambda side: rooms_and_corridors(side, side, seed, **kw))


def _closest(free_cells: int, per_plan: int, smallest: int, blocked: str, make) -> str:
    """Of the maps ``make(side)`` for the sides within 5 of the estimate (at least ``smallest``), the
    one with the count of characters not in ``blocked`` closest to ``free_cells``."""
    if int(free_cells) < 1:
        raise ValueError(f"free_cells must be >= 1, got {free_cells}")
    guess = max(smallest, int(round(np.sqrt(free_cells / (_FREE_FRACTION * per_plan)))))
    best = None
    for side in range(max(smallest, guess - 5), guess + 6):
        text = make(side)
        n = sum(ch not in blocked for ch in text)
        if best is None or abs(n - free_cells) < best[0]:
            best = (abs(n - free_cells), text)
    return best[1]


def building(floors: int, rows: int, cols: int, seed: int = 0, storey: int = 2, stairwells: int = 2,
             **kw) -> str:
    """A connected 3-D building as voxel-map text (layers bottom first, separated by ``---``):
    ``floors`` storeys of ``storey`` layers of one :func:`rooms_and_corridors` plan (floor ``f``: seed
    ``seed + f``, ``**kw`` passed on), a slab between storeys with ``stairwells`` holes of 2 x 2 voxels
    (1 x 1 where no 2 x 2 spot is free on both), ``1`` on the first free voxel, ``2`` on the last.
    """
    if min(int(floors), int(storey), int(stairwells)) < 1:
        raise ValueError(f"floors, storey and stairwells must be >= 1, got {floors}, {storey}, {stairwells}")
    rng = np.random.default_rng(seed)
    plans = [np.array([[ch != "#" for ch in line] for line in
                       rooms_and_corridors(rows, cols, seed + f, labels=False, **kw).splitlines()])
             for f in range(int(floors))]
    layers: list = []
    for f, plan in enumerate(plans):
        if f:
            layers.append(_slab(plans[f - 1] & plan, int(stairwells), rng))
        layers += [plan] * int(storey)
    grids = [np.where(free, ".", "#").astype("<U1") for free in layers]
    first, last = np.argwhere(layers[0]), np.argwhere(layers[-1])
    if len(first):
        grids[0][tuple(first[0])] = "1"
    if len(last):
        grids[-1][tuple(last[-1])] = "2"
    return "---\n".join("".join("".join(row) + "\n" for row in g) for g in grids)


def _slab(both: np.ndarray, holes: int, rng) -> np.ndarray:
    """A slab's free voxels: ``holes`` stairwells where ``both`` storeys are free (2 x 2 spots
    first, else single voxels), shape ``both.shape``."""
    square = both[:-1, :-1] & both[1:, :-1] & both[:-1, 1:] & both[1:, 1:]
    spots = np.argwhere(square)
    size = 2
    if not len(spots):
        spots, size = np.argwhere(both), 1
    out = np.zeros_like(both)
    for r, c in spots[rng.permutation(len(spots))[:holes]]:
        out[r:r + size, c:c + size] = True
    return out


def building_map(free_cells: int, floors: int = 3, seed: int = 0, **kw) -> str:
    """A :func:`building` of ``floors`` storeys on square floor plans, with about ``free_cells``
    free voxels (of the sides within 5 of the estimate, the closest)."""
    return _closest(free_cells, int(floors) * kw.get("storey", 2), 2, "#-\n",
                    lambda side: building(floors, side, side, seed, **kw))
