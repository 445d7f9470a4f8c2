"""``t*(Z)`` of a batch of ``(pair, L)`` margin LPs as a differentiable JAX function.

:class:`PairMargins` wraps the batched solve in a :func:`jax.custom_vjp`: the forward pass solves
every LP with HiGHS on the host (:func:`jax.pure_callback`,
:class:`~tubejax.analyses.zshape.highs_duals.MarginLpSolver`), the backward pass differentiates the
Lagrangian at that optimum (:func:`~tubejax.analyses.zshape.lagrangian.lagrangian`), so the solver is
never unrolled. It compiles once per batch shape (the horizons are an argument).
"""

from __future__ import annotations

import dataclasses
import os
from concurrent.futures import ThreadPoolExecutor

import jax
import jax.numpy as jnp
import numpy as np

from ...model.geometry import Polytope
from ...model.zshape.kinds import make_z, z_vertex_count_problem
from ...model.problem import Pairs, pair_problems
from .highs_duals import MarginLpSolver
from .lagrangian import (MarginSolution, dual_shape, facet_counts, lagrangian, margin_families, pair_geometry, stack,
                         system_arrays)
from ...model.zshape.params import ZFamily, z_facets

__all__ = ["PairMargins", "learning_polytope", "MIN_PER_THREAD"]

#: Fewer instances than this per thread are solved in the calling thread.
MIN_PER_THREAD = 16
_POOLS: dict = {}                       # threads -> a ThreadPoolExecutor shared by every PairMargins


def learning_polytope(family: ZFamily, z) -> Polytope:
    """``Z`` with vertices ``z`` (``(n_v, n)``) and the family's facet order (no re-sorting), for the LPs
    solved while learning; :func:`~tubejax.model.zshape.params.polytope_from_z` gives the checked one."""
    z = np.asarray(z, np.float64)
    H, h = z_facets(family, z, np)
    return Polytope(z, H, h)


class PairMargins:
    """The margins ``t*`` of fixed ordered pairs as a function of their cross-sections.

    Parameters
    ----------
    decomp : CellDecomposition
    system : LinearSystem
    pairs : array of int, shape (B, 2)
        The ordered pairs ``(i, j)``; every source cell has ``family.n_vertices`` vertices.
    family : ZFamily
    L_max : int
        Largest horizon (the padding of every instance).
    eps_min : float
    solver : MarginLpSolver, optional
    threads : int, optional
        Threads that solve a batch (default: the CPUs this process may use). HiGHS releases the
        GIL while solving, and each instance's warm start is its own, so the margins do not
        depend on it.

    Notes
    -----
    :meth:`solve` reuses an instance's last solution when its ``Z`` and ``L`` are bit for bit the
    same as last time (an optimum of the very same LP; a stopped group of the learner).

    Calling ``margins(z, L)`` with ``z`` of shape ``(B, n_v, n)`` and ``L`` of shape ``(B,)``
    (int) returns ``t*`` of shape ``(B,)``; it is differentiable in ``z`` (``L`` is not).
    :meth:`solve` is the same on the host, returning the whole :class:`MarginSolution`.
    """

    def __init__(self, decomp, system, pairs, family: ZFamily, L_max: int, eps_min: float = 0.0,
                 solver: MarginLpSolver | None = None, threads: int | None = None):
        self.decomp, self.system, self.family = decomp, system, family
        self.pairs = np.asarray(pairs, dtype=int).reshape(-1, 2)
        self.L_max, self.eps_min = int(L_max), float(eps_min)
        self.solver = solver or MarginLpSolver()
        self.threads = max(1, len(os.sched_getaffinity(0)) if threads is None else int(threads))
        self._last: dict = {}                # instance -> ((Z bytes, L), its last solution)
        self.sa = system_arrays(system)
        cells = decomp.cells
        for i, _ in self.pairs:
            why = z_vertex_count_problem(family.n_vertices, cells[int(i)].n_vertices, family.n)
            if why is not None:
                raise ValueError(f"cell {int(i)}, Z family {family.kind!r}: {why}")
        # each pair's problem without its Z and L, built once (vectorised): a solve swaps those in
        src, dst = self.pairs[:, 0], self.pairs[:, 1]
        placeholder: dict = {}          # a Z of the family's vertex count (the problems' q_k(0) follow it)
        zs = [placeholder.setdefault(int(i), _placeholder(family, cells[int(i)])) for i in src]
        self._base = pair_problems(decomp, system, zs, Pairs(src, dst, decomp.obstacle_cases(src, dst)), 1,
                                   self.eps_min, z_of_source=False)
        counts = [facet_counts(b) for b in self._base]
        self.f_pad = {r: max(c[r] for c in counts) for r in counts[0]} if counts else {}
        self._fn = self._build()

    # ------------------------------------------------------------------ host side
    def _problem(self, b: int, Z: Polytope, L: int):
        return dataclasses.replace(self._base[b], Z=Z, L=int(L))

    def solve(self, z, L) -> MarginSolution:
        """Host solve of every instance: ``z (B, n_v, n)``, ``L (B,)`` -> batched :class:`MarginSolution`."""
        z = np.asarray(z, np.float64)
        L = np.asarray(L, dtype=int)

        def one(b):
            key = (z[b].tobytes(), int(L[b]))
            hit = self._last.get(b)
            if hit is not None and hit[0] == key:          # the same Z and L as last time (a stopped group)
                return hit[1]
            prob = self._problem(b, learning_polytope(self.family, z[b]), int(L[b]))
            sol = self.solver.solve(prob, key=(b, int(L[b])), L_pad=self.L_max, f_pad=self.f_pad)
            self._last[b] = (key, sol)
            return sol

        return stack(self._map(one, range(len(self.pairs))))

    def _map(self, fn, items) -> list:
        """``[fn(b) for b in items]``, over :attr:`threads` threads when there are enough items."""
        items = list(items)
        if self.threads <= 1 or len(items) < 2 * MIN_PER_THREAD:
            return [fn(b) for b in items]
        pool = _POOLS.get(self.threads)
        if pool is None:
            pool = _POOLS[self.threads] = ThreadPoolExecutor(self.threads, thread_name_prefix="tubejax-margins")
        return list(pool.map(fn, items, chunksize=max(1, len(items) // (4 * self.threads))))

    def solve_subset(self, z, L, idx) -> np.ndarray:
        """Host margins of the instances ``idx`` only: ``t (len(idx),)``; ``z (B, n_v, n)``, ``L (B,)``."""
        z = np.asarray(z, np.float64)
        return np.array(self._map(lambda b: float(self.solver.solve(
            self._problem(int(b), learning_polytope(self.family, z[b]), int(L[b])), key=(int(b), int(L[b]))).t),
            idx))

    def geometry(self, L):
        """Batched :class:`~tubejax.analyses.zshape.lagrangian.PairGeometry` at horizons ``L (B,)`` (host)."""
        return stack([pair_geometry(dataclasses.replace(p, L=int(L[b])), self.f_pad) for b, p in enumerate(self._base)])

    # ------------------------------------------------------------------ JAX side
    def _shapes(self):
        B, Lp, fam = len(self.pairs), self.L_max, self.family
        n, m = self.system.n, self.system.m
        f = jax.ShapeDtypeStruct
        d = jnp.float64
        y = {g.name: f((B,) + dual_shape(g, Lp, self.f_pad, (fam.n_vertices, fam.n_facets)), d)
             for g in margin_families(regions=self.f_pad)}
        return MarginSolution(f((B,), d), f((B, Lp, n), d), f((B, Lp), d), f((B, Lp, fam.n_vertices, m), d), y,
                              f((B, Lp), d))

    def _build(self):
        fam, sa = self.family, self.sa
        shapes = self._shapes()
        geom_all = self.geometry(np.ones(len(self.pairs), dtype=int))
        geom_all = jax.tree_util.tree_map(jnp.asarray, geom_all)

        def host(z, L):
            return self.solve(z, L)

        def lag_batch(z, geom, sol):
            def one(zb, gb, sb):
                H, h = z_facets(fam, zb)
                return lagrangian(zb, H, h, gb, sb, sa)
            return jax.vmap(one)(z, geom, sol)

        @jax.custom_vjp
        def margins(z, L):
            return jax.pure_callback(host, shapes, z, L, vmap_method="sequential").t

        def fwd(z, L):
            sol = jax.pure_callback(host, shapes, z, L, vmap_method="sequential")
            return sol.t, (z, L, sol)

        def bwd(res, ct):
            z, L, sol = res
            geom = geom_all._replace(L=L.astype(geom_all.L.dtype))
            _, vjp = jax.vjp(lambda zz: lag_batch(zz, geom, sol), z)
            (dz,) = vjp(ct)
            return dz, np.zeros(L.shape, dtype=jax.dtypes.float0)

        margins.defvjp(fwd, bwd)
        return margins

    def __call__(self, z, L):
        return self._fn(z, L)


def _placeholder(family: ZFamily, cell) -> Polytope:
    """A ``Z`` with ``family.n_vertices`` vertices for building ``cell``'s problems (replaced per solve)."""
    if family.kind == "polygon" and family.n_vertices != cell.n_vertices:
        a = 2 * np.pi * np.arange(family.n_vertices) / family.n_vertices
        return Polytope.from_vertices(np.stack([np.cos(a), np.sin(a)], axis=1))
    return make_z("cell", cell)

