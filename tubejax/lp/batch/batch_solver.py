"""The batched PDHG engine behind :func:`tubejax.abstraction.build_abstraction`.

:class:`PdhgBatchSolver` is a ``solve_batch(problems, progress=None)`` callable for any LP's
:class:`~tubejax.lp.declarations.formulation.PdhgForm` (the tube LP by default; :func:`pdhg_solver` by method):
problems are grouped by static shape (horizons padded to a bucket, facets padded with masked
rows), set up in chunks as the pool needs them and streamed through a fixed-width pool
(:func:`~tubejax.lp.engines.pool.stream_pool`), each ``(shape, width)`` compiled once. A host
float64 dual bound below ``-margin_safety`` refutes an instance (``'pdhg-certificate'``); every
other instance goes to HiGHS (:func:`~tubejax.lp.evidence.verdict.highs_verdict`) overlapping
the PDHG run, so no edge is reported without HiGHS (docs/explanation/solvers.md#the-batched-path).

:meth:`PdhgBatchSolver.optimise` is the optimise mode (:mod:`tubejax.lp.batch.optimise_mode`):
the same groups, pool and executables, every instance run to ``gap_tol``, without HiGHS. It runs
an LP's radius form (``pdhg_solver(method, radius=True)``, docs/math/radius.md).
"""

from __future__ import annotations

import time
from functools import partial
from typing import NamedTuple, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from ..engines.objective_bounds import make_objective_certify
from ..evidence.verdict import Pending, highs_verdict
from ..declarations.formulation import Formulation, PdhgForm
from ..evidence.radius_lp import radius_highs_optimum
from ..evidence.registry import FORMULATIONS, formulation as lp_record, formulation_of_form
from ..evidence.translate_verdicts import highs_translate_verdicts
from ..evidence.records.tube_record import TUBE_PDHG
from ..engines.pdhg_adapters import flat_ops, pdhg_setup
from ...errors import InputError
from ...model.problem import TubeProblem
from ..engines.pdhg import PdhgOptions, make_pdhg_runner, ruiz_passes
from .optimise_mode import PdhgOptimum, optimise_batch
from .sign_mode import sign_batch, split_future
from ..engines.pool import Layout, bucket_width as _bucket, solve_pool
from ..engines.engine_options import Executor, PoolOptions, SolverStats, Tally, split_options
from ..engines.workers import BACKGROUND, PriorityWorkers, shared_process_workers

__all__ = ["PdhgBatchSolver", "PdhgOptimum", "PoolOptions", "Executor", "SolverStats", "pdhg_solver", "batched_form",
           "RADIUS_OPTIONS"]

#: The radius form's defaults (``pdhg_solver(method, radius=True)``): the optimise mode, a duality gap of 1e-4
#: in radius units (rho* to about four decimals on unit cells; a requested radius within the gap of rho* is
#: HiGHS's to decide anyway), a high cap and a check every 8 iterations
#: (docs/explanation/performance.md#radius-optimise-mode).
RADIUS_OPTIONS = PdhgOptions(mode="optimise", gap_tol=1e-4, max_iters=4096, check_every=8, checks_per_call=16)

#: The main (full-width) executables keep XLA's defaults, which iterate faster; the narrow tail executables
#: run only stragglers and take the faster compile (CPU fusion emitters off)
#: (docs/explanation/performance.md#xla-options-of-the-compiled-pool).
_TAIL_XLA_OPTIONS = {"xla_cpu_use_fusion_emitters": False}


class _Executable(NamedTuple):
    """An AOT-compiled packed runner, called like the jitted one (``layouts`` is baked in)."""

    compiled: object

    def __call__(self, P, S, min_running, layouts=None):
        return self.compiled(P, S, min_running)


class PdhgBatchSolver:
    """Callable batch solver accumulating statistics across rounds (:attr:`stats`).

    With a form that has ``dual_key``, the last refuting dual of each key is tried on
    the next instances with that key before they enter the pool; with one that has
    ``translates``, an edge is proved by its translation class's canonical exact tube where that
    holds (:mod:`tubejax.lp.evidence.translate_verdicts`).

    Parameters
    ----------
    options : PdhgOptions, optional
        The PDHG iteration's numbers.
    pooling : PoolOptions, optional
        Grouping, padding, chunks and batch widths (:class:`~tubejax.lp.engines.engine_options.PoolOptions`).
    executor : Executor, optional
        Where HiGHS and PDHG run (:class:`~tubejax.lp.engines.engine_options.Executor`).
    form : PdhgForm
        The LP to solve: a record's ``pdhg`` or ``radius.pdhg`` (default: the tube LP's margin form,
        :data:`~tubejax.lp.evidence.records.tube_record.TUBE_PDHG`; by method: :func:`pdhg_solver`), the object itself
        (:func:`~tubejax.lp.evidence.registry.formulation_of_form`; a ``TypeError`` for a copy).
    exact : bool
        Also solve every certified-infeasible instance with HiGHS and count
        disagreements (slow; for validation).
    **overrides
        Fields of the three settings objects by name (``pool=64``, ``max_iters=512``,
        ``highs_process=False``: :func:`~tubejax.lp.engines.engine_options.split_options`),
        replacing those of ``options``, ``pooling`` and ``executor``.

    Attributes
    ----------
    record : Formulation
        The LP whose form :attr:`form` is: its verdicts and evidence are this record's.
    stats : SolverStats
        The counters so far (immutable snapshot).
    n_traces : int
        How many times a PDHG runner was traced (a repeated shape adds none).
    """

    def __init__(self, options: PdhgOptions | None = None, pooling: PoolOptions | None = None,
                 executor: Executor | None = None, *, form: PdhgForm = TUBE_PDHG,
                 exact: bool = False, **overrides):
        pdhg_kw, pool_kw, exec_kw = split_options(overrides)
        self.form = form
        self.record = formulation_of_form(form)          # the record holding this very form
        self.options = (options or PdhgOptions())._replace(**pdhg_kw)
        if self.options.mode not in ("sign", "optimise"):
            raise ValueError(f"PdhgOptions.mode: expected 'sign' or 'optimise', got {self.options.mode!r}")
        ruiz_passes(self.options)                 # a bad ruiz_iters fails here, not mid-abstraction
        pooling = (pooling or PoolOptions())._replace(**pool_kw)
        lb = pooling.l_buckets
        if isinstance(lb, str) and lb != "auto":
            raise ValueError(f"PoolOptions.l_buckets: expected 'auto' or a sequence of horizons, got {lb!r}")
        self.pooling = pooling._replace(pool=int(pooling.pool), min_bucket=int(pooling.min_bucket),
                                        chunk=max(int(pooling.chunk), 1), share=bool(pooling.share),
                                        l_buckets=lb if isinstance(lb, str) else tuple(sorted(lb)))
        self.executor = (executor or Executor())._replace(**exec_kw)
        self.exact = bool(exact)
        self.dtype = np.dtype(self.pooling.dtype)
        ex = self.executor
        self.workers = shared_process_workers() if ex.highs_process else PriorityWorkers(int(ex.highs_workers))
        self._compiled: dict = {}
        self._fpad: dict = {}
        self.n_traces = 0
        self.reset_stats()

    # -- the record's evidence (read from the form at each call: a test's variant replaces fields of form) -----
    @property
    def verdict(self):
        """``verdict(problem, provenance)``: the HiGHS verdict of :attr:`record`'s LP, whose evidence is stored
        (:func:`~tubejax.lp.evidence.verdict.highs_verdict`, given the record's registered name: it runs in the
        HiGHS helper processes, and the registry refuses two records of one name); ``None`` on a radius form."""
        return None if self.form.radius else partial(highs_verdict, form=self.record.name)

    @property
    def verdicts(self):
        """``verdicts(problems, provenance, translated)``: exact translates confirmed together, on a margin form
        with ``translates`` (:func:`~tubejax.lp.evidence.translate_verdicts.highs_translate_verdicts`); else
        ``None`` (each problem confirmed on its own)."""
        return highs_translate_verdicts if self.form.translates and not self.form.radius else None

    @property
    def optimum(self):
        """``optimum(problem) -> (value, point)``: HiGHS's ``rho*`` of :attr:`record`'s radius LP
        (:func:`~tubejax.lp.evidence.radius_lp.radius_highs_optimum`) on a radius form; else ``None``."""
        return partial(radius_highs_optimum, form=self.record) if self.form.radius else None

    def reset_stats(self):
        """Zero the counters (the compiled executables are kept)."""
        self.tally = Tally()

    @property
    def stats(self) -> SolverStats:
        """The counters over every round since the last :meth:`reset_stats` (an immutable snapshot)."""
        return self.tally.snapshot()

    def _sharding(self, shape, broadcast: bool = False):
        """``NamedSharding`` splitting the last (batch) axis of an array of ``shape`` over the
        mesh (replicated when ``broadcast``: a ``(rows, 1)`` array shared by every instance),
        or None without a mesh."""
        mesh = self.executor.mesh
        if mesh is None:
            return None
        batch = None if broadcast else mesh.axis_names[0]
        spec = jax.sharding.PartitionSpec(*([None] * (len(shape) - 1)), batch)
        return jax.sharding.NamedSharding(mesh, spec)

    def put(self, tree):
        """Host -> device transfer of ``tree``, the batch axis split over the executor's mesh."""
        if self.executor.mesh is None:
            return jax.device_put(tree)
        return jax.device_put(tree, jax.tree_util.tree_map(
            lambda a: self._sharding(a.shape, a.shape[-1] == 1), tree))

    @property
    def n_executables(self) -> int:
        """How many PDHG executables (shape x batch width) have been compiled so far."""
        return len(self._compiled)

    def width(self, n: int) -> int:
        """The pool's batch width for a group of ``n`` instances."""
        return min(self.pooling.pool, _bucket(n, self.pooling.min_bucket))

    # -- compiled pieces -------------------------------------------------------------------
    def _compile(self, shape, width: int, layouts, opts: PdhgOptions) -> _Executable:
        """Trace, lower and compile the packed runner of ``shape`` at batch ``width``."""
        mv, rmv, cert = flat_ops(self.form.operator, shape, jnp)
        if opts.mode == "optimise":                       # (-lower, upper) for any form
            cert = make_objective_certify(mv, rmv, jnp)

        def count():
            self.n_traces += 1

        fn = make_pdhg_runner(mv, rmv, cert, opts, on_trace=count)
        t0 = time.perf_counter()
        args = tuple(lay.abstract(width, self._sharding) for lay in layouts)
        xla = _TAIL_XLA_OPTIONS if width == self.pooling.tail_width else None
        with jax.enable_x64(True):
            compiled = fn.lower(*args, 0, layouts).compile(compiler_options=xla)
        self.tally.add("compile_seconds", time.perf_counter() - t0)
        self.tally.add("n_compiles", 1)
        return _Executable(compiled)

    def runner(self, shape, width: int, prob, state, opts: PdhgOptions, layouts=None) -> _Executable:
        """The executable for ``(shape, width)`` and the options' mode, compiled on first use
        (``layouts`` of the packed problem and state, else taken from ``prob`` and ``state``)."""
        layouts = (Layout.of(prob), Layout.of(state)) if layouts is None else tuple(layouts)
        key = (self.form.operator, shape, width) + layouts + (opts,)
        if key not in self._compiled:
            self._compiled[key] = self._compile(shape, width, layouts, opts)
        return self._compiled[key]

    def cast(self, a):
        """A floating array in the iteration precision (``pooling.dtype``); other arrays as they are."""
        return a.astype(self.dtype) if np.issubdtype(a.dtype, np.floating) else a

    # -- one group ---------------------------------------------------------------------------
    def l_pad(self, L: int) -> int:
        """Padded horizon: the smallest bucket ``>= L`` (see ``PoolOptions.l_buckets``)."""
        buckets = self.pooling.l_buckets
        if buckets == "auto":                       # 2, 4, 8, 12, 16, 24, 32, 48, ...
            b = 2
            while b < L:
                b = b * 2 if b < 8 else (b * 3 // 2 if b & (b - 1) == 0 else b * 4 // 3)
            return b
        return min([b for b in buckets if b >= L], default=L)

    def solve_group(self, probs: Sequence[TubeProblem], key, progress, on_done=None,
                     opts: PdhgOptions | None = None):
        """PDHG on one shape group: ``(shape, data, status, iterations, x_best, y_cert, problem)``
        (flat primal / dual points ``(n, B)``; ``problem`` the unscaled flat PdhgProblem)."""
        opts = self.options if opts is None else opts
        L_pad, shape_key = key[0], key[1]
        # facet counts only ever grow per (L_pad, static shape): later rounds and later
        # abstractions (another radius: another system) reuse the executable
        f_pad = self.facet_padding(L_pad, shape_key, probs)
        shape, data, prob, state = pdhg_setup(self.form, probs, L_pad, f_pad, opts, self.pooling.share)
        return self._run_pool(shape, data, len(probs), prob, state, progress, on_done, opts) + (prob,)

    def facet_padding(self, L_pad: int, shape_key, probs) -> tuple:
        """The padded facet counts of a group: the form's ``facet_counts``, at least what
        the same ``(L_pad, static shape)`` was padded to before, so later rounds and later
        abstractions (another radius: another system) reuse the executable."""
        pad_key = (self.form.facet_counts, L_pad, shape_key)
        counts = np.array([self.form.facet_counts(p) for p in probs])          # (B, families)
        f_pad = tuple(int(c) for c in np.maximum(counts.max(axis=0), self._fpad.get(pad_key, 0)))
        self._fpad[pad_key] = f_pad
        return f_pad

    def _run_pool(self, shape, data, n: int, prob, state, progress, on_done, opts: PdhgOptions):
        """Stream ``n`` instances through the fixed-width pool (plus a narrow tail executable)."""
        width = self.width(n)
        if self.dtype != np.float64:                      # iterate in lower precision
            prob, state = jax.tree_util.tree_map(self.cast, (prob, state))
        run = self.runner(shape, width, prob, state, opts)

        def done(inst, status):
            if progress is not None:
                progress.update(len(inst))
            if on_done is not None:
                on_done(inst, status)

        tw = self.pooling.tail_width
        tail = (tw, lambda: self.runner(shape, tw, prob, state, opts)) if tw and tw < width else None
        out = solve_pool(run, prob, state, width, on_done=done, stats=self.tally, tail=tail, put=self.put)
        f64 = lambda a: np.asarray(a, np.float64)          # noqa: E731
        return shape, data, out.status, out.it, f64(out.x_best), f64(out.y_cert)

    # -- the batch-solver protocol -------------------------------------------------------------
    #: :func:`tubejax.abstraction.build_abstraction` may ask for deferred confirmations.
    supports_deferred = True

    #: :meth:`__call__` takes ``likely_edges`` (see there).
    supports_likely_edges = True

    def __call__(self, problems: Sequence[TubeProblem], progress=None, defer: bool = False,
                 likely_edges=()) -> list:
        """Solve one round; returns one verdict per problem.

        Instances that PDHG does not certify infeasible are handed to HiGHS in a
        helper process (or worker threads, ``highs_process=False``) as soon as they
        stop, so exact solves overlap the PDHG run; fallbacks (PDHG undecided) run
        before confirmations of likely edges. Runs in float64
        whatever the global ``jax_enable_x64`` setting.

        Parameters
        ----------
        problems : sequence of TubeProblem
        progress : tqdm-like, optional
        defer : bool
            Return a :class:`~tubejax.lp.evidence.verdict.Pending` (not yet confirmed) for each
            likely edge instead of waiting for HiGHS, so confirmations overlap later
            rounds; every other entry is a :class:`~tubejax.lp.evidence.verdict.Verdict`.
        likely_edges : iterable of int, or of sequences of int
            Indices of problems known to be likely edges (an exact translate is one,
            :mod:`tubejax.abstraction.translation_classes`): they skip PDHG and go to HiGHS as confirmations
            (provenance ``'highs-translate'``), decided by HiGHS like every other edge. A
            sequence groups exact translates of one problem: with a form that has
            ``translates``, they are confirmed together, HiGHS warm-started from one to the next
            (:func:`~tubejax.lp.evidence.translate_verdicts.confirm_translates_with_highs`).

        Returns
        -------
        list of Verdict (or Pending when ``defer``)
        """
        if self.verdict is None:
            raise TypeError(f"the {self.record.name!r} radius form computes optima, not verdicts: "
                            "call PdhgBatchSolver.optimise(problems)")
        with jax.enable_x64(True):
            return sign_batch(self, problems, progress, defer, likely_edges)

    def confirm_later(self, problems: Sequence[TubeProblem], provenances: Sequence[str]) -> list:
        """HiGHS confirmations of likely edges, made as every HiGHS answer of this solver is made
        (each problem on its own: a group of one), each a
        :class:`~tubejax.lp.evidence.verdict.Pending` with its given provenance.

        A resumed run hands them the likely edges whose confirmation was still running when the
        run stopped (:class:`~tubejax.abstraction.runstore.Facts` ``pending``), so that they end with the
        verdict and the provenance they would have had.
        """
        fn = self.verdicts
        if fn is not None:
            futs = self.workers.submit_many([(BACKGROUND, fn, ([p], "highs")) for p in problems])
            futs = [split_future(f, 1)[0] for f in futs]
        else:
            futs = self.workers.submit_many([(BACKGROUND, self.verdict, (p, "highs")) for p in problems])
        return [Pending(f, str(prov)) for f, prov in zip(futs, provenances)]

    # -- the optimisation mode -----------------------------------------------------------------
    def optimise(self, problems: Sequence[TubeProblem], progress=None) -> PdhgOptimum:
        """Solve every problem's LP to optimality (``PdhgOptions.mode = 'optimise'``).

        Grouped, padded and streamed as by :meth:`__call__`; each instance stops once
        ``upper - lower <= gap_tol`` (``'optimal'``), once ``upper < -margin_safety``
        (``'infeasible'``), or at ``max_iters``. ``lower`` and ``upper`` are recomputed on the host in
        float64 from the unscaled data (:func:`~tubejax.lp.engines.objective_bounds.host_objective_certificates`),
        and the status follows them. HiGHS solves only the problems the form does not batch
        (HiGHS's optimum, :func:`~tubejax.lp.evidence.radius_lp.radius_highs_optimum`). Runs in float64
        whatever ``jax_enable_x64`` says.

        Parameters
        ----------
        problems : sequence of TubeProblem, length B
        progress : tqdm-like, optional

        Returns
        -------
        PdhgOptimum
        """
        with jax.enable_x64(True):
            return optimise_batch(self, problems, progress)


def batched_form(record: Formulation, radius: bool = False) -> PdhgForm | None:
    """The form of the LP ``record`` on the batched engine: its margin form (``record.pdhg``) or, with
    ``radius``, its radius form (``record.radius.pdhg``); ``None`` where the record has none."""
    if not radius:
        return record.pdhg
    return None if record.radius is None else record.radius.pdhg


def pdhg_solver(method: str = "tube", *, radius: bool = False, options: PdhgOptions | None = None,
                **kw) -> PdhgBatchSolver:
    """The batched engine on the LP ``method``: its record's margin form, or with ``radius`` its radius form
    (call ``.optimise(problems)``: ``rho*`` per problem, docs/math/radius.md).

    Parameters
    ----------
    method : str
        A method whose record has the form (:func:`batched_form`).
    radius : bool
        The radius form (optimise mode) instead of the margin form (sign mode, verdicts).
    options : PdhgOptions, optional
        Default ``PdhgOptions()``, with ``radius`` :data:`RADIUS_OPTIONS`.
    **kw
        :class:`PdhgBatchSolver` arguments (``pooling``, ``executor``, ``exact``, fields by name).

    Raises
    ------
    InputError
        ``method`` is unknown, or its LP has no such form (the message lists the methods that have one).
    """
    form = batched_form(lp_record(method), radius)
    if form is None:
        kind = "radius form on the batched engine" if radius else "batched PDHG form"
        raise InputError(f"method {method!r} has no {kind}; expected one of "
                         f"{', '.join(n for n, f in FORMULATIONS.items() if batched_form(f, radius) is not None)}")
    return PdhgBatchSolver(options or (RADIUS_OPTIONS if radius else None), form=form, **kw)
