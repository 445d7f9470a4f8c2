"""The typed settings and statistics of the batched engine (:class:`~tubejax.lp.batch.batch_solver.PdhgBatchSolver`).

Three hashable, immutable settings: :class:`~tubejax.lp.engines.pdhg.PdhgOptions` (the iteration's
numbers, which a compiled executable depends on), :class:`PoolOptions` (grouping, padding, chunking)
and :class:`Executor` (where the work runs). :func:`split_options` sorts flat keyword options into
the three, naming any key that belongs to none. The counters come back as a :class:`SolverStats`.
"""

from __future__ import annotations

import dataclasses
import threading
from collections.abc import Mapping
from types import MappingProxyType
from typing import NamedTuple

import jax
import numpy as np

from .pdhg import PdhgOptions

__all__ = ["PoolOptions", "Executor", "SolverStats", "Tally", "split_options"]


class PoolOptions(NamedTuple):
    """How a round's instances reach the compiled pool.

    pool : batch width of the compiled solver (a power of two); a smaller group uses the next
        power of two ``>= min_bucket``
    min_bucket : smallest batch width
    tail_width : width of the narrower executable that takes over a group's last stragglers
        (one more compile per shape); ``None``: none
    l_buckets : ``'auto'`` (2, 4, 8, 12, 16, 24, 32, 48, ...: at most 50 % padding) or explicit sizes
        (a horizon above them unpadded): horizons are padded up to a bucket so that one executable
        serves several rounds
    chunk : instances set up at a time in a shape group: the host holds the pool, the chunks
        being solved and each stopped instance only until its certificates are re-checked;
        the last refuting dual of each key is tried on the next chunks' instances
    share : store coefficients that are the same for every instance of a group once (one ``Z``
        for all pairs)
    dtype : precision of the PDHG iterations (``'float64'`` or ``'float32'``): every certificate
        is re-checked in float64 on the unscaled data either way, so the precision changes which
        solver decides, never a verdict
    """

    pool: int = 128
    min_bucket: int = 16
    tail_width: int | None = None
    l_buckets: str | tuple = "auto"
    chunk: int = 256
    share: bool = True
    dtype: str = "float64"


class Executor(NamedTuple):
    """Where the engine's work runs.

    highs_process : run the HiGHS solves in a helper process shared by every solver
        (:func:`~tubejax.lp.engines.workers.shared_process_workers`) instead of worker threads:
        building and re-checking each LP then never waits for the GIL held by the PDHG loop
    highs_workers : worker threads running the HiGHS solves (when not ``highs_process``)
    mesh : a 1-D ``jax.sharding.Mesh`` (axis ``'batch'``) splitting the batch axis over its
        devices, or ``None``
    """

    highs_process: bool = True
    highs_workers: int = 1
    mesh: jax.sharding.Mesh | None = None


_GROUPS = (PdhgOptions, PoolOptions, Executor)


def split_options(options: Mapping) -> tuple[dict, dict, dict]:
    """Flat keyword options sorted into ``(PdhgOptions, PoolOptions, Executor)`` field dicts.

    Raises
    ------
    TypeError
        A key that is a field of none of them (named, with the known keys).
    """
    out: tuple[dict, dict, dict] = ({}, {}, {})
    for key, value in options.items():
        for group, fields in zip(out, _GROUPS):
            if key in fields._fields:
                group[key] = value
                break
        else:
            known = sorted(f for g in _GROUPS for f in g._fields)
            raise TypeError(f"PdhgBatchSolver: unknown option {key!r}; expected one of {', '.join(known)}")
    return out


@dataclasses.dataclass(frozen=True)
class SolverStats(Mapping):
    """The engine's counters over every round since the last reset (immutable; also a mapping).

    ``slot_iterations`` is iterations x batch width actually run (utilisation is the sum of
    per-instance iterations over it), ``calls`` the jitted calls, ``pdhg_seconds`` host and
    device time with compiling excluded, ``highs_cpu_seconds`` the time inside HiGHS solves
    (overlapped with PDHG in the helper), ``highs_wait_seconds`` the time spent waiting for
    HiGHS after PDHG finished, ``duals_reused`` the instances certified infeasible by another
    instance's dual, ``translated_to_highs`` the likely edges sent to HiGHS without PDHG.
    """

    n_lps: int = 0
    certified_feasible: int = 0
    certified_infeasible: int = 0
    sent_to_highs: int = 0
    highs_confirmations: int = 0
    highs_disagreements: int = 0
    status_counts: Mapping = dataclasses.field(default_factory=lambda: MappingProxyType({}))
    iterations_median: float = float("nan")
    iterations_p99: float = float("nan")
    compile_seconds: float = 0.0
    pdhg_seconds: float = 0.0
    highs_cpu_seconds: float = 0.0
    highs_wait_seconds: float = 0.0
    n_compiles: int = 0
    slot_iterations: int = 0
    calls: int = 0
    device_seconds: float = 0.0
    translated_to_highs: int = 0
    duals_reused: int = 0

    def __getitem__(self, key: str):
        """The field ``key`` (``status_counts`` as a plain dict copy, so that ``dict(stats)`` is JSON data)."""
        if key not in self.__dataclass_fields__:
            raise KeyError(key)
        value = getattr(self, key)
        return dict(value) if isinstance(value, MappingProxyType) else value

    def __iter__(self):
        return iter(self.__dataclass_fields__)

    def __len__(self) -> int:
        return len(self.__dataclass_fields__)


class Tally:
    """The engine's running counters: what :class:`SolverStats` snapshots. Counters are added
    under :attr:`lock` where HiGHS callbacks run on other threads; ``iterations`` holds every
    stopped instance's iteration count (for the median and 99th percentile)."""

    def __init__(self):
        self.lock = threading.Lock()
        self.counts: dict = {f.name: f.default for f in dataclasses.fields(SolverStats) if f.name != "status_counts"}
        self.counts["status_counts"] = {}
        self.iterations: list[int] = []

    def add(self, key: str, value) -> None:
        """Add ``value`` to the counter ``key``."""
        self.counts[key] += value

    def __getitem__(self, key: str):
        return self.counts[key]

    def __setitem__(self, key: str, value) -> None:
        self.counts[key] = value

    def get(self, key: str, default=None):
        return self.counts.get(key, default)

    def snapshot(self) -> SolverStats:
        """The counters now, as an immutable :class:`SolverStats`."""
        c = dict(self.counts)
        c["status_counts"] = MappingProxyType(dict(c["status_counts"]))
        if self.iterations:
            c["iterations_median"] = float(np.median(self.iterations))
            c["iterations_p99"] = float(np.percentile(self.iterations, 99))
        return SolverStats(**c)
