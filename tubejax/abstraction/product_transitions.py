"""A product system (:class:`~tubejax.abstraction.product_abstraction.ProductSystem`) as a transition system to plan
and simulate over (docs/math/drone.md).

:func:`product_transition_system` gives the :class:`~tubejax.transitions.TransitionSystem` the planner
and Algorithm 1 read: the same cells, system and cross-sections, one :class:`~tubejax.transitions.Edge`
per product edge (provenance ``'product'``, or ``'product-joint'`` for a pair solved as one joint LP)
and its tube assembled from the factor tubes only when it is asked for (:class:`ProductTubes`), so a
system of millions of edges is planned over without building millions of tubes. Algorithm 1 steers
along a :class:`~tubejax.abstraction.product_abstraction.ProductTube` with one scale per axis group
(:func:`~tubejax.analyses.control.controller.axis_scales`).
"""

from __future__ import annotations

from collections.abc import Sequence

from ..transitions.records import Edge
from ..transitions.transition_system import TransitionSystem
from .product_abstraction import JOINT, ProductSystem

__all__ = ["ProductTubes", "product_transition_system", "PRODUCT_PROVENANCES"]

#: Provenance of an edge proved by its factor LPs, and of one proved by a joint LP.
PRODUCT_PROVENANCES = ("product", "product-joint")


class ProductTubes(Sequence):
    """The tubes of a product system's edges, assembled on first use and kept (``len`` = edges)."""

    def __init__(self, ps: ProductSystem):
        self._ps = ps
        self._cache: dict = {}

    def __len__(self) -> int:
        return self._ps.n_edges

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self[i] for i in range(*k.indices(len(self)))]
        k = int(k)
        if not -len(self) <= k < len(self):
            raise IndexError(f"edge {k} of {len(self)}")
        k %= len(self)
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
        ``edges[k]`` is ``ps``'s edge ``k``; ``tubes`` a :class:`ProductTubes`; ``stats`` ``ps.stats``.
    """
    edges = [Edge(int(i), int(j), int(L), float(m), PRODUCT_PROVENANCES[int(v == JOINT)])
             for i, j, L, m, v in zip(ps.src.tolist(), ps.dst.tolist(), ps.L.tolist(), ps.margin.tolist(),
                                      ps.variant.tolist())]
    return TransitionSystem(ps.decomposition, ps.system, ps.Z, edges=edges, tubes=ProductTubes(ps),
                            eps_min=ps.eps_min, method="tube", stats=dict(ps.stats), inputs=inputs)
