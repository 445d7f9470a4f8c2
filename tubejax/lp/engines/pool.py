"""Streaming a batch of LP instances through a fixed-width, jit-compiled solver.

Between jitted calls the host refills the slots of instances that stopped. To keep each call's
host <-> device traffic to a few transfers, every pytree of instance data is *packed* into one
``(rows, B)`` array per dtype; a :class:`Layout` records how and is a static argument of the runner.
"""

from __future__ import annotations

import time
from typing import Any, Callable, NamedTuple

import jax
import numpy as np

from .pdhg import PAD, RUNNING

__all__ = ["Layout", "bucket_width", "solve_pool", "stream_pool"]


class Layout(NamedTuple):
    """How a pytree with batch-last leaves packs into a few 2-D arrays: per-instance leaves ``(..., B)``
    into one ``(rows, B)`` array per dtype, *broadcast* leaves ``(..., 1)`` (shared by every instance,
    last axis 1 while the batch is wider) into one ``(rows, 1)`` array per dtype, never indexed by slot.

    Attributes
    ----------
    treedef : the pytree structure
    leaves : tuple of ``(dtype_str, shape_without_batch, broadcast)`` per leaf
    """

    treedef: Any
    leaves: tuple

    @classmethod
    def of(cls, tree) -> "Layout":
        leaves, treedef = jax.tree_util.tree_flatten(tree)
        B = max(int(a.shape[-1]) for a in leaves)
        return cls(treedef, tuple((np.dtype(a.dtype).str, tuple(a.shape[:-1]), bool(B > 1 and a.shape[-1] == 1))
                                  for a in leaves))

    @property
    def groups(self) -> tuple:
        """``(dtype_str, broadcast)`` of the packed arrays, in order."""
        return tuple(sorted({(d, b) for d, _, b in self.leaves}))

    @property
    def broadcast(self) -> tuple:
        """Per packed array: True when it is a ``(rows, 1)`` broadcast array."""
        return tuple(b for _, b in self.groups)

    def _slots(self):
        """Per leaf: (array index, first row, number of rows)."""
        groups = self.groups
        off = {g: 0 for g in groups}
        out = []
        for d, shp, b in self.leaves:
            rows = int(np.prod(shp, dtype=np.int64))
            out.append((groups.index((d, b)), off[(d, b)], rows))
            off[(d, b)] += rows
        return out

    def rows(self, leaf: int) -> tuple[int, slice]:
        """``(array index, row slice)`` of the ``leaf``-th leaf."""
        a, r0, n = self._slots()[leaf]
        return a, slice(r0, r0 + n)

    def pack(self, tree, xp=np) -> tuple:
        """The packed arrays, one per :attr:`groups` entry: ``(rows, B)``, or ``(rows, 1)`` when broadcast."""
        leaves = jax.tree_util.tree_leaves(tree)
        groups = [[] for _ in self.groups]
        for a, (k, _, n) in zip(leaves, self._slots()):
            groups[k].append(xp.reshape(a, (n, a.shape[-1])))
        return tuple(g[0] if len(g) == 1 else xp.concatenate(g, axis=0) for g in groups)

    def unpack(self, arrays, xp=np):
        """Inverse of :meth:`pack` (slices: views on the host, static slices in jit)."""
        leaves = [xp.reshape(arrays[k][r0:r0 + n], shp + (arrays[k].shape[-1],))
                  for (k, r0, n), (_, shp, _) in zip(self._slots(), self.leaves)]
        return jax.tree_util.tree_unflatten(self.treedef, leaves)

    def abstract(self, width: int, sharding=None) -> tuple:
        """``jax.ShapeDtypeStruct`` of the packed arrays at batch ``width`` (broadcast arrays
        keep width 1); ``sharding(shape, broadcast)`` gives each one's sharding."""
        rows = {}
        for (k, _, n), (d, _, b) in zip(self._slots(), self.leaves):
            rows[k] = rows.get(k, 0) + n
        out = []
        for k, (d, b) in enumerate(self.groups):
            shp = (rows[k], 1 if b else width)
            out.append(jax.ShapeDtypeStruct(shp, np.dtype(d),
                                            sharding=None if sharding is None else sharding(shp, b)))
        return tuple(out)


#: A jitted pool call returns to the host once this share of its slots is free while instances wait.
REFILL_FRACTION = 0.25


def bucket_width(n: int, min_bucket: int) -> int:
    """The batch width for ``n`` instances: the next power of two, at least ``min_bucket``."""
    return max(min_bucket, 1 << int(np.ceil(np.log2(max(n, 1)))))


def _leaf_index(tree, field: str) -> int:
    """Index among the flattened leaves of the top-level NamedTuple field ``field``."""
    paths = jax.tree_util.tree_flatten_with_path(tree)[0]
    return next(i for i, (p, _) in enumerate(paths) if getattr(p[0], "name", None) == field)


def solve_pool(run: Callable, prob, state, pool: int, on_done: Callable | None = None, stats: dict | None = None,
               tail: tuple | None = None, put: Callable = jax.device_put):
    """Stream ``N`` instances through a fixed-width pool of ``pool`` slots; keep every final state.

    :func:`stream_pool` with one chunk: whenever an instance stops (any status but ``RUNNING``),
    its slot is refilled on the host, so a slow instance never holds up the others and one batch
    width is compiled.

    Parameters
    ----------
    run : packed runner for width ``pool`` (:func:`tubejax.lp.engines.pdhg.make_pdhg_runner`):
        ``run(P, S, min_running, layouts) -> S``, ``layouts = (Layout.of(prob), Layout.of(state))``
    prob, state : NumPy pytrees with batch axis last, width ``N`` (``state`` from
        :func:`~tubejax.lp.engines.pdhg.pdhg_init`); ``state`` has fields ``status`` and ``it``
    on_done : ``on_done(instances, status)`` with the indices (into ``N``) and statuses of
        the instances that just stopped -- e.g. to start exact solves while PDHG goes on
    stats : dict-like, optional
        Accumulates ``'slot_iterations'`` (iterations run x width), ``'calls'`` and ``'device_seconds'``.
    tail : (int, callable), optional
        ``(width, get_run)``: once no instance waits and at most ``width`` still run, they move
        to a narrower pool run by ``get_run()`` (compiled on first use).
    put : callable
        Host -> device transfer of a tuple of arrays (default ``jax.device_put``; pass
        one that applies a ``NamedSharding`` to split the batch axis over devices).

    Returns
    -------
    the final ``state`` of every instance (NumPy pytree, width ``N``)
    """
    lay_s = Layout.of(state)
    out = tuple(np.array(a, copy=True) for a in lay_s.pack(state))
    runs = {pool: run}

    def get_run(width: int, layouts):
        if width not in runs:
            runs[width] = tail[1]()
        return runs[width]

    def done(idx, status, columns, layout):
        for o, c in zip(out, columns):
            o[:, idx] = c
        if on_done is not None:
            on_done(idx, status)

    stream_pool(get_run, [(prob, state)], pool, done, stats, None if tail is None else tail[0], put)
    return lay_s.unpack(out)


def _narrowed(p_pool: tuple, s_pool: tuple, slots, live, width: int, bc_p, st_at) -> tuple:
    """``(p_pool, s_pool, slots)`` of a pool of ``width`` slots holding the ``live`` slots' instances
    (the rest empty, status ``PAD``); ``st_at`` is the status row's ``(array, rows)``."""
    st_a, st_r = st_at
    sel = np.concatenate([live, np.full(width - live.size, live[0])])
    p_pool = tuple(a if b else a[:, sel] for a, b in zip(p_pool, bc_p))
    s_pool = tuple(a[:, sel] for a in s_pool)
    slots = np.concatenate([slots[live], np.full(width - live.size, -1)])
    s_pool[st_a][st_r.start, live.size:] = PAD
    return p_pool, s_pool, slots


def _device_call(run, p_dev, s_pool: tuple, put, min_running: int, layouts, at, stats):
    """One call of the jitted pool ``run``; returns the new host state and the slots' statuses
    ``(width,)``, and adds the call's slot iterations, count and seconds to ``stats``. ``at`` holds
    the ``(array, rows)`` of the iteration counts' and the statuses' rows."""
    (it_a, it_r), (st_a, st_r) = at
    width = int(s_pool[0].shape[-1])
    it0 = s_pool[it_a][it_r.start].copy()
    t0 = time.perf_counter()
    s_pool = tuple(np.array(a) for a in run(p_dev, put(s_pool), min_running, layouts))
    t_run = time.perf_counter() - t0
    if stats is not None:
        stats["slot_iterations"] = (stats.get("slot_iterations", 0)
                                    + int(np.max(s_pool[it_a][it_r.start] - it0)) * width)
        stats["calls"] = stats.get("calls", 0) + 1
        stats["device_seconds"] = stats.get("device_seconds", 0.0) + t_run
    return s_pool, s_pool[st_a][st_r.start]


def _same_broadcast(a: tuple, b: tuple, flags: tuple) -> bool:
    return all(not f or (x.shape == y.shape and np.array_equal(x, y)) for x, y, f in zip(a, b, flags))


class _ChunkStream:
    """The state of :func:`stream_pool`: the chunks set up and not yet entered, the pool of one pass
    (chunks with equal layouts and shared arrays), and how many instances have stopped."""

    def __init__(self, get_run, chunks, on_done, stats, tail, put):
        self.get_run, self.it, self.on_done = get_run, iter(chunks), on_done
        self.stats, self.tail, self.put = stats, tail, put
        self.nxt: list = []                  # the next chunk, once set up: [P, S, lay_p, lay_s, offset, entered]
        self.seen = 0
        self.total = 0

    def load(self):
        """The next chunk (set up now if it is not yet), or None at the end."""
        if not self.nxt:
            try:
                prob, state = next(self.it)
            except StopIteration:
                return None
            lp, ls = Layout.of(prob), Layout.of(state)
            P, S = lp.pack(prob), ls.pack(state)
            self.nxt.append([P, S, lp, ls, self.seen, 0])
            self.seen += int(S[0].shape[-1])
        return self.nxt[0]

    def _begin(self, width: int) -> None:
        """Start a pass with the next chunk: an empty pool of ``width`` slots in its layouts."""
        self.cur = cur = self.nxt.pop(0)
        P0, S0, lay_p, lay_s = cur[:4]
        self.P0, self.layouts, self.bc_p = P0, (lay_p, lay_s), lay_p.broadcast
        self.st_at = lay_s.rows(_leaf_index(lay_s.unpack(S0), "status"))
        self.it_at = lay_s.rows(_leaf_index(lay_s.unpack(S0), "it"))
        self.width, self.run = width, self.get_run(width, self.layouts)
        self.p_pool = tuple(a.copy() if b else np.repeat(a[:, :1], width, axis=1) for a, b in zip(P0, self.bc_p))
        self.s_pool = tuple(np.repeat(a[:, :1], width, axis=1) for a in S0)
        self.slots = np.full(width, -1)
        st_a, st_r = self.st_at
        self.s_pool[st_a][st_r.start, :] = PAD

    def _compatible(self, c) -> bool:
        return c is not None and c[2:4] == list(self.layouts) and _same_broadcast(c[0], self.P0, self.bc_p)

    def take(self, k: int) -> list:
        """Up to ``k`` running instances of compatible chunks: ``[(chunk, local index array)]``. An
        instance that enters already stopped (a status other than ``RUNNING`` in its chunk's
        state) goes to ``on_done`` at once and takes no slot."""
        st_a, st_r = self.st_at
        out = []
        while k > 0:
            cur = self.cur
            left = int(cur[1][0].shape[-1]) - cur[5]
            if left <= 0:
                if not self._compatible(self.load()):
                    break
                self.cur = self.nxt.pop(0)
                continue
            n = min(k, left)
            loc = np.arange(cur[5], cur[5] + n)
            cur[5] += n
            entry = cur[1][st_a][st_r.start, loc]
            stopped = entry != RUNNING
            if stopped.any():
                self.on_done(cur[4] + loc[stopped], entry[stopped].copy(),
                             tuple(a[:, loc[stopped]] for a in cur[1]), self.layouts[1])
                self.total += int(stopped.sum())
                loc = loc[~stopped]
            if loc.size:
                out.append((cur, loc))
                k -= loc.size
        return out

    def fill(self, where) -> int:
        """Put new instances into the free slots ``where``; returns the slots filled."""
        used = 0
        for c, loc in self.take(len(where)):
            dst = where[used:used + len(loc)]
            for d_, s_, b in zip(self.p_pool, c[0], self.bc_p):
                if not b:
                    d_[:, dst] = s_[:, loc]
            for d_, s_ in zip(self.s_pool, c[1]):
                d_[:, dst] = s_[:, loc]
            self.slots[dst] = c[4] + loc
            used += len(loc)
        return used

    def _shrink(self, live_idx) -> None:
        """Move the live instances to the narrower tail pool."""
        tail = self.tail
        self.p_pool, self.s_pool, self.slots = _narrowed(self.p_pool, self.s_pool, self.slots, live_idx, tail,
                                                         self.bc_p, self.st_at)
        self.width = tail
        self.run = self.get_run(tail, self.layouts)

    def run_pass(self, pool: int) -> bool:
        """Stream the next run of compatible chunks through a pool of ``pool`` slots until it
        drains; returns whether chunks are left."""
        self._begin(pool)
        tail, (st_a, st_r) = self.tail, self.st_at
        more = self.fill(np.arange(pool)) == pool      # compatible instances may still enter
        p_dev = self.put(self.p_pool)
        while True:
            width = self.width
            live = self.slots >= 0
            can_shrink = tail is not None and tail < width and not more
            min_running = int(width * (1.0 - REFILL_FRACTION)) if more else (tail if can_shrink else 0)
            self.s_pool, status = _device_call(self.run, p_dev, self.s_pool, self.put, min_running, self.layouts,
                                               (self.it_at, self.st_at), self.stats)
            done = np.flatnonzero(live & (status != RUNNING))
            if done.size:
                self.on_done(self.slots[done].copy(), status[done].copy(),
                             tuple(s[:, done] for s in self.s_pool), self.layouts[1])
                self.total += done.size
                self.slots[done] = -1
                self.s_pool[st_a][st_r.start, done] = PAD
                if more:
                    n = self.fill(done)
                    more = n == done.size
                    if n:
                        p_dev = self.put(self.p_pool)
            live_idx = np.flatnonzero(self.slots >= 0)
            if live_idx.size == 0:
                break
            if tail is not None and tail < self.width and not more and live_idx.size <= tail:
                self._shrink(live_idx)
                p_dev = self.put(self.p_pool)
        if self.cur[5] < int(self.cur[1][0].shape[-1]):    # the rest of a chunk (cannot happen: kept whole)
            self.nxt.insert(0, self.cur)
        return self.load() is not None


def stream_pool(get_run: Callable, chunks, pool: int, on_done: Callable,
                stats: dict | None = None, tail: int | None = None, put: Callable = jax.device_put) -> int:
    """Stream instances that arrive in chunks through a fixed-width pool; keep no result.

    The memory-bounded form of :func:`solve_pool`: chunks are set up only when needed and a stopped
    instance's packed state columns go to ``on_done`` at once, so the host holds the pool and two chunks
    whatever the number of instances. Consecutive chunks share the pool when their layouts and broadcast
    arrays are equal; otherwise the pool drains first.

    Parameters
    ----------
    get_run : callable
        ``get_run(width, layouts) -> run`` (see :func:`solve_pool`), compiled on first use.
    chunks : iterable of ``(prob, state)``
        NumPy pytrees with batch axis last (``state`` from
        :func:`~tubejax.lp.engines.pdhg.pdhg_init`, with fields ``status`` and ``it``);
        instance ``k`` of the stream is the ``k``-th over all chunks. An instance whose status
        is not ``RUNNING`` (decided before it enters) goes to ``on_done`` as it would enter.
    pool : int
        Batch width.
    on_done : callable
        ``on_done(instances, status, columns, layout)``: stream indices ``(k,)``, their final
        statuses, the packed state columns ``(rows, k)`` of each packed array and the state's
        :class:`Layout` (``layout.unpack(columns)`` gives the state pytree of those instances).
    tail : int, optional
        Once no instance is left to enter and at most ``tail`` still run, they move to a pool
        of that width.
    stats, put : as for :func:`solve_pool`.

    Returns
    -------
    int : the number of instances streamed.
    """
    stream = _ChunkStream(get_run, chunks, on_done, stats, tail, put)
    if stream.load() is None:
        return 0
    while stream.run_pass(pool):                 # one pass per run of compatible chunks
        pass
    return stream.total
