"""A product system (:class:`~tubejax.abstraction.product_abstraction.ProductSystem`) as a transition system to plan
and simulate over (docs/math/drone.md).

:func:`product_transition_system` gives the :class:`~tubejax.transitions.transition_system.TransitionSystem` the planner
and Algorithm 1 read: the same cells, one :class:`~tubejax.transitions.records.Edge` per product edge, made
only when asked for (:class:`ProductEdges`), with its tube assembled from the factor tubes only when
asked for (:class:`ProductTubes`), so millions of edges are planned over without building their
records. Algorithm 1 steers with one scale per axis group
(:func:`~tubejax.analyses.control.controller.axis_scales`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..transitions.records import Edge
from ..transitions.transition_system import TransitionSystem
from .product_abstraction import JOINT, ProductSystem

__all__ = ["ProductEdges", "ProductTubes", "product_transition_system", "PRODUCT_PROVENANCES"]

#: Provenance of an edge proved by its factor LPs, and of one proved by a joint LP.
PRODUCT_PROVENANCES = ("product", "product-joint")


class _LazySequence(Sequence):
    """A sequence whose item ``k`` (``0 <= k < len``) :meth:`_item` makes; slices give lists."""

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self[i] for i in range(*k.indices(len(self)))]
        k = int(k)
        if not -len(self) <= k < len(self):
            raise IndexError(f"edge {k} of {len(self)}")
        return self._item(k % len(self))


class ProductEdges(_LazySequence):
    """The :class:`~tubejax.transitions.records.Edge` records of a product system's edges, made on access.

    ``src``, ``dst``, ``L`` (ndarray of int, shape (E,)) are the system's arrays, for vectorised readers
    (:func:`~tubejax.analyses.control.planner._graph`); an edge is equal to the one a list would hold.
    """

    def __init__(self, ps: ProductSystem):
        self.src, self.dst, self.L = ps.src, ps.dst, ps.L
        self._margin, self._variant = ps.margin, ps.variant

    def __len__(self) -> int:
        return int(len(self.src))

    def _item(self, k: int) -> Edge:
        return Edge(int(self.src[k]), int(self.dst[k]), int(self.L[k]), float(self._margin[k]),
                    PRODUCT_PROVENANCES[int(self._variant[k] == JOINT)])

    def __iter__(self):
        prov = np.where(np.asarray(self._variant) == JOINT, 1, 0).tolist()
        for i, j, L, m, v in zip(self.src.tolist(), self.dst.tolist(), self.L.tolist(), self._margin.tolist(), prov):
            yield Edge(i, j, L, m, PRODUCT_PROVENANCES[v])


class ProductTubes(_LazySequence):
    """The tubes of a product system's edges, assembled on first use and kept (``len`` = edges)."""

    def __init__(self, ps: ProductSystem):
        self._ps = ps
        self._cache: dict = {}

    def __len__(self) -> int:
        return self._ps.n_edges

    def _item(self, k: int):
        if k not in self._cache:
            self._cache[k] = self._ps.tube(k)
        return self._cache[k]


def product_transition_system(ps: ProductSystem, inputs: dict | None = None) -> TransitionSystem:
    """The transition system of ``ps``, to plan and simulate over (module doc).

    Parameters
    ----------
    ps : ProductSystem
    inputs : dict, optional
        The inputs record the system was computed from.

    Returns
    -------
    TransitionSystem
        ``edges`` a :class:`ProductEdges` (``edges[k]`` is ``ps``'s edge ``k``); ``tubes`` a :class:`ProductTubes`; ``stats`` ``ps.stats``.
    """
    return TransitionSystem(ps.decomposition, ps.system, ps.Z, edges=ProductEdges(ps), tubes=ProductTubes(ps),
                            eps_min=ps.eps_min, method="tube", stats=dict(ps.stats), inputs=inputs)
