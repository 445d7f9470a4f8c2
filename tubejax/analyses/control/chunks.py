"""Many runs or long plans in bounded memory: the simulation in chunks of runs
(docs/howto/simulate.md#many-runs-and-long-plans).

A simulation's memory grows with ``runs x steps``. :func:`chunk_runs` picks how many runs a chunk
holds so that it needs at most :data:`CHUNK_BYTES`, and refuses up front a plan of which a single
run needs more than :data:`MEMORY_LIMIT_BYTES`. :func:`simulate_in_chunks` runs the chunks in turn
and adds their summaries (:func:`merge_summaries`). One chunk is exactly the unchunked simulation;
chunk ``c`` draws from the seed :func:`chunk_seed` ``(seed, c)``, so results are reproducible.
"""

from __future__ import annotations

import numpy as np
from tqdm.auto import tqdm

from ...errors import InputError

__all__ = ["CHUNK_BYTES", "MEMORY_LIMIT_BYTES", "SimulationTooLarge", "run_step_bytes", "controller_step_bytes",
           "chunk_runs", "chunk_seed", "merge_summaries", "simulate_in_chunks"]

#: Memory one chunk of runs may need (states, inputs, disturbances, random numbers, checks).
CHUNK_BYTES = 1 << 30
#: Memory one run of a plan, with the plan's controller, may need; more is refused up front.
MEMORY_LIMIT_BYTES = 4 << 30
#: Summary counts that add up over chunks, and values whose maximum is the chunks' maximum.
SUM_KEYS = ("runs", "obstacle_entries", "tube_exits", "workspace_exits", "runs_reaching_all_targets",
            "runs_satisfying_spec", "avoided_region_entries")
MAX_KEYS = ("max_tube_violation", "max_outside", "max_input_violation")
PER_SEGMENT_KEYS = ("targets_reached_per_segment",)


class SimulationTooLarge(InputError):
    """A single run of the plan would need more memory than :data:`MEMORY_LIMIT_BYTES`."""


def run_step_bytes(n: int, m: int, n_f: int) -> int:
    """Bytes one state of one run costs (float64): the state, input and disturbance with their
    host copies, the random numbers, the set and barycentric violations, a cell test's
    ``(.., n_f)`` temporary, and the monitor's letters, DFA states and flags."""
    return 8 * (2 * (2 * n + m) + (n + 2) + 4 + n_f + 8)


def controller_step_bytes(n: int, m: int, n_v: int, n_f: int) -> int:
    """Bytes of one step of a plan's controller (:class:`~tubejax.analyses.control.controller.EdgeController`)
    on the host and the device: ``n_v`` vertices, at most ``n_v`` simplices, ``n_f`` facets."""
    return 2 * 8 * (n_v * (n * n + 2 * n + 2) + n_v * m + n_f * (n + 1))


def _plan_sizes(ts, plan) -> tuple[int, int, int, int]:
    """``(n, m, n_v, n_f)``: the largest vertex and facet counts over the plan's edges (``Z`` and source cell)."""
    n, m = ts.decomposition.dim, ts.system.m
    n_v, n_f = 1, 1
    for k in dict.fromkeys(int(k) for k in plan.edges):
        e = ts.edges[k]
        Z, P = ts.z_of(e.src, e.dst), ts.decomposition.cells[e.src]
        n_v = max(n_v, Z.n_vertices, P.n_vertices)
        n_f = max(n_f, len(Z.h), len(P.h))
    if not plan.edges:
        n_f = max(n_f, len(ts.decomposition.cells[plan.cells[0]].h))
    return n, m, n_v, n_f


def _gb(b: float) -> str:
    return f"{b / 2 ** 30:.1f} GB" if b >= 2 ** 28 else f"{b / 2 ** 20:.0f} MB"


def chunk_runs(ts, plan, n_runs: int, chunk_bytes: int | None = None, limit_bytes: int | None = None) -> int:
    """How many runs of ``plan`` a chunk holds (``n_runs`` when all fit in one).

    ``chunk_bytes`` and ``limit_bytes`` default to :data:`CHUNK_BYTES` and :data:`MEMORY_LIMIT_BYTES`.

    Raises
    ------
    SimulationTooLarge
        One run with the plan's controller needs more than ``limit_bytes``; the message gives
        the memory it would need.
    """
    chunk_bytes = CHUNK_BYTES if chunk_bytes is None else int(chunk_bytes)
    limit_bytes = MEMORY_LIMIT_BYTES if limit_bytes is None else int(limit_bytes)
    n, m, n_v, n_f = _plan_sizes(ts, plan)
    S = int(plan.cost)
    per_run = (S + 1) * run_step_bytes(n, m, n_f)
    ctrl = S * controller_step_bytes(n, m, n_v, n_f)
    if per_run + ctrl > limit_bytes:
        raise SimulationTooLarge(f"the plan has {S:,} steps: one run of it needs about {_gb(per_run + ctrl)} "
                                 f"({_gb(ctrl)} for its controller), more than the {_gb(limit_bytes)} a "
                                 f"simulation may use; simulating {n_runs:,} runs in chunks would need that "
                                 "at least once. Shorten the plan (fewer cycles, a shorter specification)")
    return int(max(1, min(n_runs, chunk_bytes // per_run)))     # the controller is built once per chunk


def chunk_seed(seed: int, index: int) -> int:
    """The seed of chunk ``index`` of a chunked simulation with seed ``seed`` (an int in ``[0, 2**32)``)."""
    return int(np.random.SeedSequence([int(seed), int(index)]).generate_state(1, np.uint32)[0])


#: Summary keys holding a count per name (``{name: count}``) that add up over chunks.
PER_NAME_KEYS = ("outside_state_constraints",)


def merge_summaries(summaries: list) -> dict:
    """One summary of several chunks' (:meth:`SimulationResult.summary` or the spec monitor's): counts
    (:data:`SUM_KEYS`, per segment, per name in :data:`PER_NAME_KEYS`) add up, :data:`MAX_KEYS` take the
    largest, every other value is the first chunk's (the same in every chunk)."""
    out = dict(summaries[0])
    for key in SUM_KEYS:
        if key in out:
            out[key] = int(sum(s[key] for s in summaries))
    for key in MAX_KEYS:
        if key in out:
            out[key] = float(max(s[key] for s in summaries))
    for key in PER_SEGMENT_KEYS:
        if key in out:
            out[key] = [int(v) for v in np.sum([s[key] for s in summaries], axis=0)]
    for key in PER_NAME_KEYS:
        if key in out:
            out[key] = {name: int(sum(s[key].get(name, 0) for s in summaries)) for name in out[key]}
    return out


def simulate_in_chunks(run, n_runs: int, seed: int, runs_per_chunk: int, progress: bool = False):
    """Call ``run(n, seed)`` -> ``(result, summary)`` on chunks of at most ``runs_per_chunk`` runs.

    Parameters
    ----------
    run : callable
        Simulates ``n`` runs with ``seed``; returns its result and summary dict.
    n_runs, seed : int
    runs_per_chunk : int
        From :func:`chunk_runs`.
    progress : bool
        A progress bar over the runs (with its time estimate) when there is more than one chunk.

    Returns
    -------
    (result, summary)
        One chunk: ``run(n_runs, seed)`` itself. Several: the first chunk's result (its runs, for
        figures) and the merged summary (:func:`merge_summaries`) with ``seed``, ``chunks`` and
        ``runs_per_chunk``.
    """
    if n_runs <= runs_per_chunk:
        return run(n_runs, seed)
    full, rest = divmod(n_runs, runs_per_chunk)
    sizes = [runs_per_chunk] * full + ([rest] if rest else [])
    first, summaries = None, []
    with tqdm(total=n_runs, desc="simulation", unit="run", disable=not progress, leave=False) as bar:
        for c, n in enumerate(sizes):
            res, s = run(n, chunk_seed(seed, c))
            first = res if first is None else first
            summaries.append(s)
            bar.update(n)
    merged = merge_summaries(summaries)
    merged.update(seed=int(seed), chunks=len(sizes), runs_per_chunk=int(runs_per_chunk))
    return first, merged
