"""Which cross-section ``Z`` each ordered pair's tubes use: a :class:`ZAssignment` is a per-cell tuple
(``Z[i]`` for tubes leaving cell ``i``) plus per-pair overrides (``learned_pair``; Lemma 1 holds pair
by pair), read by :func:`z_of_pair`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .geometry import Polytope

__all__ = ["ZAssignment", "z_of_pair", "all_cross_sections", "compare_pair_z"]


class ZAssignment(Sequence):
    """Per-cell cross-sections with per-pair overrides.

    Parameters
    ----------
    per_cell : sequence of Polytope, length N
        ``per_cell[i]``: the ``Z`` of pairs ``(i, j)`` without an override.
    pairs : dict (int, int) -> Polytope, optional
        The overrides (a ``ValueError`` for a self-pair, a cell outside ``[0, N)`` or a non-Polytope).
    """

    def __init__(self, per_cell, pairs: dict | None = None):
        self._cells = tuple(per_cell)
        N = len(self._cells)
        out = {}
        for key, z in (pairs or {}).items():
            i, j = (int(key[0]), int(key[1]))
            if not (0 <= i < N and 0 <= j < N) or i == j:
                raise ValueError(f"ZAssignment: pair ({i}, {j}) is not a pair of distinct cells in [0, {N})")
            if not isinstance(z, Polytope):
                raise ValueError(f"ZAssignment: the Z of pair ({i}, {j}) is a {type(z).__name__}, not a Polytope")
            out[(i, j)] = z
        self._pairs = out

    def __len__(self) -> int:
        return len(self._cells)

    def __getitem__(self, i):
        return self._cells[i]

    def __repr__(self) -> str:
        return f"ZAssignment({len(self._cells)} cells, {len(self._pairs)} pair overrides)"

    @property
    def per_cell(self) -> tuple:
        """The per-cell defaults, length N."""
        return self._cells

    @property
    def pairs(self) -> dict:
        """``{(i, j): Polytope}`` of the overrides (a copy)."""
        return dict(self._pairs)

    def of_pair(self, i: int, j: int) -> Polytope:
        """The ``Z`` of pair ``(i, j)``: its override, else cell ``i``'s default."""
        return self._pairs.get((int(i), int(j)), self._cells[int(i)])

    def has_pair(self, i: int, j: int) -> bool:
        """Whether ``(i, j)`` has an override."""
        return (int(i), int(j)) in self._pairs


def z_of_pair(Z, i: int, j: int) -> Polytope:
    """The ``Z`` of pair ``(i, j)`` in a :class:`ZAssignment` or a per-cell sequence (``Z[i]``)."""
    if isinstance(Z, ZAssignment):
        return Z.of_pair(i, j)
    return Z[int(i)]


def all_cross_sections(Z) -> list:
    """Every distinct ``Z`` object of an assignment or a per-cell sequence (defaults, then overrides)."""
    out, seen = [], set()
    for z in list(Z) + (list(Z.pairs.values()) if isinstance(Z, ZAssignment) else []):
        if id(z) not in seen:
            seen.add(id(z))
            out.append(z)
    return out


def compare_pair_z(edges, arrays: dict, Z, source: str = "") -> list[str]:
    """Each edge's own ``Z`` in a transitions npz (``edge_{k}_Z``) against ``Z``'s, one line per difference.

    Parameters
    ----------
    edges : list of edges (``src``, ``dst``, ``L``)
    arrays : dict            the npz's arrays
    Z : ZAssignment or sequence of Polytope
        The rebuilt cross-sections: an edge has ``edge_{k}_Z`` exactly when its pair has its own ``Z``.
    source : str             where ``Z`` came from, for the messages (e.g. `` from /run/learned_z.json``)
    """
    out = []
    for k, e in enumerate(edges):
        own = isinstance(Z, ZAssignment) and Z.has_pair(e.src, e.dst)
        key = f"edge_{k}_Z"
        where = f"edges[{k}] {e.src}->{e.dst} (L={e.L})"
        if own and key not in arrays:
            out.append(f"{where}: {key} (npz) is missing, but the pair has its own Z{source}")
        elif not own and key in arrays:
            out.append(f"{where}: {key} (npz) is given, but the inputs give the pair no Z of its own")
        elif own and not np.array_equal(np.asarray(arrays[key], float), Z.of_pair(e.src, e.dst).vertices):
            out.append(f"{where}: {key} (npz) differs from the pair's Z rebuilt{source}")
    return out
