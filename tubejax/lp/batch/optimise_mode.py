"""The optimisation mode of the batched engine: optima, not only signs.

:func:`optimise_batch` is :meth:`PdhgBatchSolver.optimise
<tubejax.lp.batch.batch_solver.PdhgBatchSolver.optimise>`: the solver's grouping, pool and
executables with ``PdhgOptions.mode = 'optimise'`` (:mod:`tubejax.lp.engines.pdhg`). Every
instance runs until its duality gap is below ``gap_tol`` or its optimum is certified
negative; the result is per instance the optimum's estimate, a rigorous upper bound (the
form's host float64 re-check of the dual), a lower estimate, the status and the
primal point, without HiGHS.

It runs an LP's radius form (docs/math/radius.md), its record's ``radius.pdhg``
(:func:`~tubejax.lp.batch.batch_solver.pdhg_solver` with ``radius=True``, defaults
:data:`~tubejax.lp.batch.batch_solver.RADIUS_OPTIONS`): the margin form's operator in its
``'radius'`` form (``t``'s all-ones column becomes ``rho``'s coefficients), with the bounds,
``rho_min``, ``rho_max`` and reference point of :mod:`~tubejax.lp.evidence.radius_lp`
(:func:`~tubejax.lp.engines.pdhg_adapters.pdhg_setup`). A group is one system (any radius of one
shape shares the executables). A non-box ``U``'s rows are hard rows (no ``rho``; the reference
``u = 0`` satisfies them strictly). Problems with a family an operator does not model, or whose
reference point violates C2 / C3 (only with ``eps_min > 0``), go to HiGHS.
"""

from __future__ import annotations

import time
from collections import defaultdict
from functools import partial
from typing import NamedTuple, Sequence

import numpy as np

from ..engines.objective_bounds import host_objective_certificates
from ..engines.pdhg import NUMERICAL
from ..engines.pdhg_adapters import flat_ops

__all__ = ["PdhgOptimum", "optimise_batch"]


class PdhgOptimum(NamedTuple):
    """What :meth:`PdhgBatchSolver.optimise` returns, one entry per problem (``B`` problems).

    Attributes
    ----------
    value : ndarray, shape (B,)
        The estimate of the optimum: ``t`` (the radius form: ``rho``) of the primal point,
        clipped to ``[lower, upper]``.
    lower : ndarray, shape (B,)
        A lower estimate: the largest ``t`` feasible with the primal point (repaired, see
        :mod:`tubejax.lp.engines.objective_bounds`), ``-inf`` when none.
    upper : ndarray, shape (B,)
        A rigorous upper bound on the optimum (float64 weak duality, re-checked on the host).
    status : tuple of str
        ``'optimal'`` (``upper - lower <= gap_tol``), ``'infeasible'`` (``upper <
        -margin_safety``: the optimum is certified negative, its value not sought),
        ``'max_iters'``, ``'numerical'``.
    iterations : ndarray of int, shape (B,)
    point : list
        The primal points (the form's evidence type, e.g. a ``Tube``; not verified).
    provenance : tuple of str
        ``'pdhg'``, or ``'highs'`` for a problem the form does not batch (then
        ``value = lower = upper`` is HiGHS's optimum).
    """

    value: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    status: tuple
    iterations: np.ndarray
    point: list
    provenance: tuple


def optimise_batch(solver, problems: Sequence, progress=None) -> PdhgOptimum:
    """:meth:`PdhgBatchSolver.optimise <tubejax.lp.batch.batch_solver.PdhgBatchSolver.optimise>`
    for ``solver`` (call it inside ``jax.enable_x64(True)``).

    The status follows the host re-check: ``'infeasible'`` when ``upper < -margin_safety``,
    ``'optimal'`` when ``upper - lower <= gap_tol``, else ``'numerical'`` or ``'max_iters'``
    as the device said (a device that stopped on a float32 bound the float64 re-check does
    not confirm also gives ``'max_iters'``).
    """
    opts = solver.options._replace(mode="optimise")
    fm = solver.form
    st = solver.tally
    B = len(problems)
    st.add("n_lps", B)
    value, lower, upper = np.full(B, np.nan), np.full(B, np.nan), np.full(B, np.nan)
    iters = np.zeros(B, dtype=np.int64)
    status, prov, point = [""] * B, ["pdhg"] * B, [None] * B
    counts = defaultdict(int, st["status_counts"])
    groups = defaultdict(list)
    for k, p in enumerate(problems):
        key = (solver.l_pad(int(p.L)),) + tuple(fm.group_key(p)) if fm.batched(p) else None
        groups[key].append(k)
    for k in groups.pop(None, []):
        if solver.optimum is None:
            raise ValueError(f"problem {k} is not batched by the {solver.record.name!r} form and it has no exact "
                             "optimum (only a radius form has one)")
        v, pt = solver.optimum(problems[k])
        value[k] = lower[k] = upper[k] = v
        status[k] = "optimal" if v >= 0 else ("infeasible" if v < 0 else "numerical")
        prov[k], point[k] = "highs", pt
        st.add("sent_to_highs", 1)
        counts[status[k]] += 1
        if progress is not None:
            progress.update(1)
    for key, ks in groups.items():
        t0 = time.perf_counter()
        c0 = st["compile_seconds"]
        probs = [problems[k] for k in ks]
        shape, _, dev, its, z, y, prob = solver.solve_group(probs, key, progress, opts=opts)
        neg_lower, up = host_objective_certificates(partial(flat_ops, fm.operator), shape, prob, z, y)
        for a, k in enumerate(ks):
            lo_a, up_a = -float(neg_lower[a]), float(up[a])
            if up_a < -opts.margin_safety:
                s_ = "infeasible"
            elif up_a - lo_a <= opts.gap_tol:
                s_ = "optimal"
            else:                                        # the device stopped, the re-check did not
                s_ = "numerical" if dev[a] == NUMERICAL else "max_iters"
            value[k] = min(max(float(z[-1, a]), lo_a), up_a)
            lower[k], upper[k], status[k] = lo_a, up_a, s_
            iters[k] = int(its[a])
            point[k] = z[:, a].copy() if fm.point is None else fm.point(shape, z[:, a], problems[k])
            counts[s_] += 1
        st.iterations += its.tolist()
        st.add("pdhg_seconds", time.perf_counter() - t0 - (st["compile_seconds"] - c0))
    st["status_counts"] = dict(counts)
    return PdhgOptimum(value, lower, upper, tuple(status), iters, point, tuple(prov))
