"""The Python API: ``import tubejax as tj``. Each function validates what it is given: bad input is an
:class:`~tubejax.errors.InputError` naming the argument, the value and what was expected::

    import tubejax as tj

    ws = tj.grid_map("conf/workspace/maps/paper.txt")           # or the map's text
    ts = tj.abstract(ws, tj.paper_system(radius=0.2), L_max=10)  # batched PDHG, verified edges
    plan = tj.plan(ts, [1, 3, 4, 5, 6])                          # start in region 1, then 3, 4, 5, 6
    sim = tj.simulate(ts, plan, runs=1000, disturbance="adversarial")
    assert sim.ok and tj.verify(ts).ok
    ts.save("out/run1")              # python -m tubejax verify out/run1 proves it from its sources
    tj.export_controller(ts, plan, "out/controller")        # C99 + NumPy-only code, no tubejax needed
    ts.export("out/run1/graph.graphml")

Here: :func:`abstract`, :func:`load`, :func:`verify`, and how conservative a system is (:func:`limit`,
:func:`winning_set`); workspaces and systems: :mod:`tubejax.api_inputs`; plans, simulation and export:
:mod:`tubejax.api_control`.
"""

from __future__ import annotations

import copy
import tempfile
import warnings
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from .abstraction.build import AbstractionOptions, build_abstraction
from .abstraction.product_abstraction import ProductOptions
from .abstraction.product_store import ProductRun, try_product
from .abstraction.preflight import empty_state_constraint
from .api_control import _check_system
from .api_inputs import _argument_error, _as_workspace, same_set, system_entries
from .analyses.conservatism import AREA_TOL, DEFAULT_SIDES, MAX_ITERATIONS, ReachAvoidLimit, WinningSet, \
    reach_avoid_limit, winning_set as _winning_set
from .errors import InputError, InputModelError
from .lp.evidence.registry import FORMULATIONS, formulation
from .inputs import ProblemInputs
from .abstraction.methods import batch_solver
from .transitions.source_files import SavesSources
from .transitions.transition_system import TransitionSystem
from .verify.verifier import VerifyReport, load_with_sources, verify_directory
from .model.workspace.validate import disturbance_fits

__all__ = ["AbstractChoices", "abstract", "verify", "load", "limit", "winning_set"]



@dataclass(frozen=True)
class AbstractChoices:
    """The choices of :func:`abstract`; ``tj.abstract(ws, sys, L_max=5)`` sets them by name.

    Parameters
    ----------
    method : {'tube', 'openloop', 'exact2d'}
        The paper's tube LP, the open-loop baseline (docs/math/open-loop.md), or exact polygon backward
        reachability (2-D, the most any feedback achieves).
    solver : {'pdhg', 'highs'}, optional
        Tube and open-loop methods: ``'pdhg'`` (default; batched, compiled once per shape and
        reused by later calls, JAX switched to float64) or ``'highs'`` (one exact LP at a time).
        Refused for ``exact2d``, which solves no LP.
    zshape : str
        Tube cross-section ``Z``: ``'box'``, ``'diamond'``, ``'cell'``, ``'regular'``,
        ``'chamfer'``, or ``'learned'``/``'learned_pair'`` with ``z_file``.
    z_scale : float
        Size of ``Z`` in ``[1e-3, 1e3]`` (only its shape matters).
    z_file : str or Path, optional
        A ``learned_z.json`` (``experiments/abstract.py zshape=learned``), for the learned kinds.
    L_max : int
        Largest horizon, in ``[1, 1000]``.
    eps_min : float
        ``eps_l >= eps_min`` (C1).
    min_margin : float
        Robustness margin every edge must reach, in ``[0, 0.5]`` (not for ``exact2d``).
    pruning : bool
        The sound necessary conditions and translation classes (never change the result).
    memory_budget_mb : int or None
        Working-set budget of the rounds (never changes the result).
    solver_options : dict, optional
        PDHG options (``pool``, ``max_iters``, ``highs_process``, ``compilation_cache``, ...: the
        keys of ``conf/solver/pdhg.yaml``).
    product : {False, True, 'auto'}
        Exact product decomposition (docs/math/product.md): ``True`` requires it (a coupled problem is
        an error saying why), ``'auto'`` uses it when the structure is detected, else runs the joint
        LPs with a warning saying why; the result then saves as a product system
        (:class:`~tubejax.abstraction.product_store.ProductRun`).
    shard_count, shard_index : int
        Product runs only: solve the factor tables, then join only shard ``shard_index`` of
        ``shard_count``'s source cells (docs/howto/shards.md#product-runs); the saved shards merge
        (``experiments/merge.py``) into exactly the unsharded run. ``1, 0``: all of them.
    """

    method: str = "tube"
    solver: str | None = None
    zshape: str = "box"
    z_scale: float = 1.0
    z_file: object = None
    L_max: int = 10
    eps_min: float = 0.0
    min_margin: float = 0.0
    pruning: bool = True
    memory_budget_mb: int | None = 2048
    solver_options: dict | None = None
    product: bool | str = False
    shard_count: int = 1
    shard_index: int = 0


def _choices(choices, fields: dict) -> AbstractChoices:
    """``choices`` (default: the defaults) with ``fields`` replaced; an unknown name is refused by name."""
    known = AbstractChoices.__dataclass_fields__
    for key in fields:
        if key not in known:
            raise InputError(f"{key}: not an argument of tubejax.abstract; expected one of progress, "
                             f"{', '.join(known)}")
    return replace(choices or AbstractChoices(), **fields)


def abstract(workspace, system, choices: AbstractChoices | None = None, *, progress: bool = False,
             **fields) -> TransitionSystem:
    """Abstract ``system`` on ``workspace``: Algorithm 2 with the method's own solver, every edge verified
    and its inputs recorded (:mod:`tubejax.api_inputs`), so a saved system verifies like one written by
    ``experiments/abstract.py``.

    Parameters
    ----------
    workspace : Workspace or str or Path
        From :func:`~tubejax.api_inputs.grid_map`, :func:`~tubejax.api_inputs.polygon_workspace`
        or :func:`~tubejax.api_inputs.box_grid`; a path is read as a grid map (``.yaml``: a
        polygon workspace).
    system : LinearSystem
        ``x+ = A x + B u + w``, ``u`` in ``U``, ``w`` in ``W`` (e.g. :func:`~tubejax.api_inputs.paper_system`).
    choices : AbstractChoices, optional
        The choices as one record; ``**fields`` (any field of :class:`AbstractChoices` by name,
        ``tj.abstract(ws, sys, L_max=5)``) replace its fields. An unknown name is refused.
    progress : bool
        Show a progress bar.

    Returns
    -------
    TransitionSystem
        ``inputs`` holds the inputs record; ``stats`` the counts and seconds (``solver``,
        ``compile_seconds``). ``ts.save(DIR)`` writes files that ``python -m tubejax verify DIR``
        (or :func:`verify`) proves from their sources; a workspace given as text is saved beside them.

    Raises
    ------
    InputError
        A bad argument (named as here: ``L_max``, ``solver_options.pool``, ``system.U``), a
        solver for ``exact2d``, or a ``zshape`` that does not fit the cells.
    """
    c = _choices(choices, fields)
    if not (c.product is True or c.product is False or c.product == "auto"):
        raise InputError(f"product: expected True, False or 'auto', got {c.product!r}")
    _check_shard(c)
    ws = _as_workspace(workspace)
    inputs, rebuilt, Z = _abstract_inputs(ws, system, c)
    if not disturbance_fits(ws.decomposition, rebuilt.W).any():
        warnings.warn("the disturbance W fits in no cell (P_j shrunk by W is empty for every cell): no transition "
                      "can exist; make W smaller or the cells larger", stacklevel=2)
    empty_x = empty_state_constraint(ws.decomposition, rebuilt)
    if empty_x:
        warnings.warn(empty_x, stacklevel=2)
    a = inputs.abstraction
    solve = batch_solver(a, reuse=True)           # later calls reuse the compiled code
    stats0 = dict(getattr(solve, "stats", None) or {})
    ps = _abstract_product(ws, rebuilt, c, Z, solve, progress) if c.product is not False else None
    if ps is not None:
        ps.stats["solver"] = a.solver.name
        return ProductRun.of_product(ps, inputs.record(), ws.files)
    ts = build_abstraction(ws.decomposition, rebuilt, AbstractionOptions.of_inputs(inputs), z=Z, solve_batch=solve,
                           progress=progress)
    ts.stats["solver"] = a.solver.name if formulation(c.method).solves_lp else c.method
    st = dict(getattr(solve, "stats", None) or {})
    ts.stats["compile_seconds"] = float(st.get("compile_seconds", 0.0) - stats0.get("compile_seconds", 0.0))
    ts.inputs = inputs.record()
    if ws.files:
        ts = SavesSources.of(ts, ws.files)
    return ts


def _abstract_product(ws, system, c: AbstractChoices, Z, solve, progress):
    """``product=True|'auto'``: the :class:`ProductSystem`, or ``None`` where ``'auto'`` falls back to the joint
    LPs (a warning says why). ``True`` on a problem the product path cannot solve is an InputError saying why."""
    opts = ProductOptions(L_max=min(c.L_max, 63), eps_min=c.eps_min, zshape=c.zshape, z_scale=c.z_scale,
                          pruning=c.pruning, shard_count=c.shard_count, shard_index=c.shard_index)
    ps, why = (try_product(ws.decomposition, system, opts, Z=Z, method=c.method, min_margin=c.min_margin,
                           solve_batch=solve, progress=progress) if c.L_max <= 63 else
               (None, f"the product path takes L_max in 1..63, not {c.L_max}"))
    if ps is None and (c.product is True or c.shard_count > 1):
        raise InputError(f"product: {why}" + ("; shard_count > 1 takes a product run" if c.shard_count > 1 else ""))
    if ps is None:
        warnings.warn(f"product='auto': {why}; running the joint LPs", stacklevel=3)
    return ps


def _check_shard(c: AbstractChoices) -> None:
    """Refuse a bad ``shard_count`` / ``shard_index`` by name, and a shard of a joint-LP run."""
    for name in ("shard_count", "shard_index"):
        value = getattr(c, name)
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise InputError(f"{name}: expected an integer, got {value!r}")
    if not 1 <= c.shard_count <= 10 ** 5:
        raise InputError(f"shard_count: expected an integer in [1, 100000], got {c.shard_count}")
    if not 0 <= c.shard_index < c.shard_count:
        raise InputError(f"shard_index: expected an integer in [0, {c.shard_count - 1}] (shard_count = "
                         f"{c.shard_count}), got {c.shard_index}")
    if c.shard_count > 1 and c.product is False:
        raise InputError("shard_count: tubejax.abstract shards product runs only (product=True or 'auto'), got "
                         "product=False; shard the joint LPs with experiments/abstract.py shard.count=K")


def _abstract_inputs(ws, system, c: AbstractChoices) -> tuple:
    """``(inputs, system, Z)``: the validated inputs record of :func:`abstract`'s choices, the system
    it gives back (exactly ``system``, else refused) and the cross-sections."""
    sys_entry, w_entry = system_entries(system)
    method, solver, solver_options = c.method, c.solver, c.solver_options
    record = FORMULATIONS.get(method)
    no_lp = record is not None and not record.solves_lp
    if no_lp and (solver is not None or solver_options):
        raise InputError(f"solver: method {method!r} solves no LP and takes no solver, got "
                         f"{solver!r}" + (" and solver_options" if solver_options else ""))
    if solver_options is not None and not isinstance(solver_options, dict):
        raise InputError(f"solver_options: expected a dict of PDHG options, got {type(solver_options).__name__}")
    name = "highs" if no_lp else ("pdhg" if solver is None else solver)
    z = {"kind": c.zshape, "scale": c.z_scale, **({"file": str(c.z_file)} if c.z_file is not None else {})}
    data = {"workspace": ws.source, "system": sys_entry, "disturbance": w_entry, "zshape": z,
            "abstraction": {"L_max": c.L_max, "eps_min": c.eps_min, "min_margin": c.min_margin, "pruning": c.pruning,
                            "method": method, "solver": {"name": name, **(solver_options or {})},
                            "memory_budget_mb": c.memory_budget_mb,
                            "shard": {"count": int(c.shard_count), "index": int(c.shard_index)}}}
    try:
        inputs = ProblemInputs.from_dict(data)
        rebuilt = inputs.build_system()
        Z = inputs.build_cross_sections(ws.decomposition)
    except InputModelError as exc:
        raise _argument_error(exc) from None
    if not (np.array_equal(rebuilt.A, system.A) and np.array_equal(rebuilt.B, system.B)
            and same_set(rebuilt.U, system.U) and same_set(rebuilt.W, system.W)):
        raise InputError("system: cannot be recorded exactly (its U or W is not given by its vertices)")
    lost = [name for name in rebuilt.differences(system) if name not in ("U", "W")]
    if lost:
        raise InputError(f"system.{lost[0]}: the inputs record does not give it back exactly")
    return inputs, rebuilt, Z


def load(directory, stem: str = "transitions") -> TransitionSystem:
    """Load a saved transition system, checked against its recorded sources
    (:func:`tubejax.verify.verifier.load_with_sources`).

    Raises
    ------
    TransitionFileError
        A missing, damaged or inconsistent file, or sources that changed.
    """
    return load_with_sources(directory, stem)


def _input_errors(run, *args, **kwargs):
    """``run(*args, **kwargs)``; a ``ValueError`` it raises about the arguments becomes an InputError."""
    try:
        return run(*args, **kwargs)
    except InputError:
        raise
    except ValueError as exc:
        raise InputError(str(exc)) from None


def verify(target, *, complete: bool = False, exact: bool = True, progress: bool = False) -> VerifyReport:
    """Prove a transition system from its sources (``python -m tubejax verify``) and say whether it holds.

    Parameters
    ----------
    target : TransitionSystem or str or Path
        A system in memory (saved to a temporary directory and verified from there) or a
        directory holding ``transitions.json|npz``.
    complete : bool
        Also re-solve every non-edge with HiGHS (finds missing edges and non-minimal ``L``).
    exact : bool
        Re-prove the edges that claim an exact (rational) proof.
    progress : bool

    Returns
    -------
    VerifyReport
        ``.ok``, ``.findings`` (one line per problem), ``.n_edges``, ``.proof_counts``, ``.summary``,
        ``.headline`` (what OK establishes: completeness is only checked with ``complete=True``) and
        ``.notes`` (the problem the edges are proved for; the run's config and ``metrics.json`` compared).
        A system without an inputs record is checked against its own data only (the summary says so).
    """
    if isinstance(target, (str, Path)):
        return verify_directory(target, complete=complete, exact=exact, progress=progress)
    if not isinstance(target, TransitionSystem):
        raise InputError(f"target: expected a TransitionSystem or a directory, got {type(target).__name__}")
    files = getattr(target, "source_files", ())
    with tempfile.TemporaryDirectory(prefix="tubejax-verify-") as tmp:
        saver = copy.copy(target) if isinstance(target, ProductRun) else (SavesSources.of(target, files) if files
                                                                           else target)
        saver.save(tmp)                   # the caller's record unchanged; a ProductRun writes its product files
        rep = verify_directory(tmp, complete=complete, exact=exact, progress=progress,
                               trust_file_data=target.inputs is None)
    return rep._replace(findings=[f.replace(tmp, "<memory>") for f in rep.findings],
                        summary=rep.summary.replace(tmp, "<memory>"), notes=tuple(n.replace(tmp, "<memory>")
                                                                                  for n in rep.notes))


def limit(workspace, system, *, target, avoid=(), sides: int = DEFAULT_SIDES, max_iterations: int = MAX_ITERATIONS,
          area_tol: float = AREA_TOL, progress: bool = False) -> ReachAvoidLimit:
    """The whole-problem limit of robust reach-avoid in 2-D, as an outer approximation (docs/math/limit.md).

    ``R_0 = T``, ``R_{k+1} = T ∪ (S ∩ Pre(R_k))``: the states from which *some* causal feedback
    reaches the cells of ``target`` while staying in the free cells (without those of ``avoid``),
    for every disturbance. Every method's winning set (:func:`winning_set`) lies inside it.

    Parameters
    ----------
    workspace : Workspace or str or Path
        A 2-D grid map or polygon workspace (:func:`~tubejax.api_inputs.grid_map`, ...).
    system : LinearSystem
        2-D state, invertible ``A``; ``W`` a ball (replaced by its inscribed ``sides``-gon) or a polytope.
    target : str or int
        The region label of ``T``.
    avoid : sequence of labels
        Regions left out of the safe set.
    sides : int
        Sides of the polygon inscribed in a ball ``W`` (``>= 3``; a multiple of it gives a contained limit).
    max_iterations : int
        Cap; a run that reaches it has ``converged = False`` and is not the limit.
    area_tol : float
        Converged when one iteration adds at most ``area_tol * area(S)``.
    progress : bool

    Returns
    -------
    ReachAvoidLimit
        ``.geometry`` (shapely), ``.area``, ``.iterations``, ``.converged``, ``.free_area``,
        ``.target_area``, ``.summary()``.

    Raises
    ------
    InputError
        Not 2-D, a singular ``A``, an unknown or avoided target, bad ``sides``/``max_iterations``/``area_tol``.
    """
    ws = _as_workspace(workspace)
    return _input_errors(reach_avoid_limit, ws.decomposition, system, target, tuple(avoid), sides=sides,
                         max_iterations=max_iterations, area_tol=area_tol, progress=bool(progress))


def winning_set(ts: TransitionSystem, *, target, avoid=()) -> WinningSet:
    """The cells of ``ts`` with a path to a cell labelled ``target`` (docs/math/limit.md#winning-sets).

    Parameters
    ----------
    ts : TransitionSystem
        A 2-D system of any method.
    target : str or int
    avoid : sequence of labels
        Edges whose tube (``tube``) or safe set (``openloop``, ``exact2d``) enters these regions are not used.

    Returns
    -------
    WinningSet
        ``.cells`` (ids), ``.area``, ``.geometry``, ``.summary(limit_area)``.

    Raises
    ------
    InputError
        Not a transition system, not 2-D, an unknown or avoided target.
    """
    _check_system(ts)
    return _input_errors(_winning_set, ts, target, tuple(avoid))
