"""Build a verified transition system (Algorithm 2) -- a thin Hydra app over tubejax.

Examples
--------
python experiments/abstract.py                                   # the paper's example
python experiments/abstract.py workspace.map_file=my.txt disturbance.radius=0.1 L_max=6
python experiments/abstract.py solver=highs hydra.run.dir=out/run1
python experiments/abstract.py system=double_integrator workspace=boxgrid4d zshape=cell L_max=8 product=auto
python experiments/abstract.py hydra.run.dir=out/run1 resume=true      # continue an interrupted run
python experiments/abstract.py -m hydra/launcher=parallel shard.count=3 'shard.index=range(3)' \
    hydra.sweep.dir=out/sweep && python experiments/merge.py out/sweep  # three shards, merged
python experiments/abstract.py zshape=learned zshape.steps=20        # learn Z first (optax), then Algorithm 2
python experiments/abstract.py zshape=learned_pair zshape.file=out/run1/learned_z.json   # reuse a learned Z
python experiments/abstract.py -m zshape=box,cell,diamond,regular,learned system=integrator2d_l1 \
    workspace=corridor hydra.sweep.dir=out/zsweep                   # the learned-Z sweep (docs/howto/learned-z.md)

The run directory holds ``rounds/`` (every finished step, :mod:`tubejax.abstraction.runstore`) while the
run goes on, then ``transitions.json|npz`` and ``metrics.json``; with ``zshape=learned`` or
``learned_pair`` also ``learned_z.json`` (learned before the rounds start, or ``zshape.file``
copied), which the inputs record names with its SHA-256 and ``python -m tubejax verify`` reloads.
With ``product=true`` (or ``auto`` on a problem whose product structure is detected) the run is the
exact product decomposition (docs/math/product.md) and writes ``product_transitions.json|npz``
(docs/reference/formats.md), which ``python -m tubejax verify`` verifies; ``auto`` on a coupled
problem logs why and runs the joint tube LPs.
A directory that already holds a run is never overwritten silently: ``resume=true`` continues
it (the same inputs, checked), ``overwrite=true`` deletes it first, anything else is refused
(exit code 2).
"""

from __future__ import annotations

import logging
import sys
import time
from pathlib import Path

import hydra
from omegaconf import DictConfig

from tubejax.abstraction.preflight import RunBudget, budget_refusal, count_cells, estimate_run
from tubejax.files import sha256_hex
from tubejax.lp.evidence.registry import formulation

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import (PROJECT_ROOT, ConfigError, app_flags, check_config_files, compilation_cache_dir,  # noqa: E402
                    config_dict, config_name, inputs_from_config, warn_if_disturbance_fits_nowhere,
                    warn_if_state_constraint_empty, write_json)

log = logging.getLogger("tubejax")
PAPER_COUNTS = {"states": 67, "transitions": 655}
#: Our stand-in for the paper's Fig. 5 map; the paper's counts are printed beside a run on it only.
PAPER_MAP = PROJECT_ROOT / "conf" / "workspace" / "maps" / "paper.txt"
#: Where the docs say why the counts on our paper map differ from the paper's.
PAPER_COUNTS_DOC = "docs/getting-started.md#why-the-counts-differ-from-the-paper"


def on_paper_map(ts) -> bool:
    """Whether ``ts`` was computed on the paper map (its inputs record names a grid map with the
    SHA-256 of :data:`PAPER_MAP`, wherever the file was)."""
    ws = (ts.inputs or {}).get("workspace") or {}
    rec = ws.get("map_file") if isinstance(ws, dict) else None
    if ws.get("kind") != "grid" or not isinstance(rec, dict):
        return False
    try:
        return rec.get("sha256") == sha256_hex(PAPER_MAP.read_bytes())
    except OSError:
        return False


def count_lines(ts) -> list[str]:
    """The ``states`` and ``transitions`` lines of the apps; on the paper map with the paper's counts
    beside them and where the docs explain the difference."""
    s = ts.stats
    if not on_paper_map(ts):
        return [f"states         : {s['n_cells']:6d}", f"transitions    : {s['n_edges']:6d}"]
    return [f"states         : {s['n_cells']:6d}   (paper: {PAPER_COUNTS['states']})",
            f"transitions    : {s['n_edges']:6d}   (paper: {PAPER_COUNTS['transitions']}; our map differs: "
            f"{PAPER_COUNTS_DOC})"]


def run_abstraction(cfg: DictConfig, out: Path, allow_shard: bool = False):
    """Validate ``cfg`` (:func:`common.inputs_from_config`), open the run directory ``out``
    (:func:`open_run_directory`), run :func:`tubejax.abstraction.build_abstraction`, write the files.

    ``allow_shard``: accept ``shard.count > 1`` (the result then holds one shard's edges only).
    """
    from tubejax.abstraction import AbstractionOptions, RunIO, build_abstraction
    from tubejax.abstraction.methods import batch_solver

    c = config_dict(cfg)
    flags = app_flags(c)
    inputs = inputs_from_config(c)
    a = inputs.abstraction
    if a.solver.name == "pdhg" and formulation(a.method).solves_lp:
        compilation_cache_dir(a.solver.compilation_cache)     # refuse an unusable one before the run starts
    if a.shard.count > 1 and not allow_shard:
        raise ConfigError(f"shard.count: a shard ({a.shard.count} in all) holds only part of the transition system; "
                          "run the shards with experiments/abstract.py, merge them with experiments/merge.py, "
                          "and give the merged directory as abstraction_dir")
    budget = RunBudget(**flags.budget.model_dump())
    refusal = budget_refusal(None, budget, count_cells(inputs.workspace))      # before a million cells are built
    if refusal:
        raise ConfigError(refusal)
    decomp = inputs.build_decomposition()
    system = inputs.build_system()
    warn_if_disturbance_fits_nowhere(decomp, system.W)
    warn_if_state_constraint_empty(decomp, system)
    Z = None if inputs.zshape.learned else inputs.build_cross_sections(decomp)
    ps = product_path(flags.product, inputs, decomp, system, Z, flags.progress) if flags.product is not False else None
    if ps is not None:
        return save_product_run(ps, inputs, out, flags)
    check_run_budget(budget, a, decomp, system, Z)
    check_memory_budget(a, decomp, system, decomp.cells if Z is None else Z)   # before the run directory is touched
    store = open_run_directory(out, inputs.record(), flags)
    t_learn = time.perf_counter()
    inputs = learned_z_inputs(inputs, decomp, system, out, flags)
    learn_seconds = time.perf_counter() - t_learn           # learning Z (0 for fixed kinds or zshape.file)
    if Z is None:                                          # learned: the learned Z, checked again
        Z = inputs.build_cross_sections(decomp)
        check_memory_budget(a, decomp, system, Z)
    solve = batch_solver(a)                        # the API's factory: a fresh solver, its stats this run's
    ts = build_abstraction(decomp, system, AbstractionOptions.of_inputs(inputs), z=Z, solve_batch=solve,
                           io=RunIO(store=store), progress=flags.progress)
    ts.stats["solver"] = a.solver.name
    ts.stats["learn_seconds"] = float(learn_seconds) if inputs.zshape.learned else 0.0
    solver_stats = dict(getattr(solve, "stats", None) or {})
    ts.stats["compile_seconds"] = float(solver_stats.get("compile_seconds", 0.0))
    if solver_stats:
        ts.stats["solver_stats"] = solver_stats
    ts.stats["config"] = c
    ts.inputs = inputs.record()                    # provenance: files by path and SHA-256 (what verify rebuilds)
    jpath, npath = ts.save(out, "transitions")
    write_json(out / "metrics.json", metrics(inputs, ts))
    store.mark_complete()
    return ts, jpath, npath


def product_path(mode, inputs, decomp, system, Z, progress: bool):
    """``product=true|auto``: the product system (docs/math/product.md), or ``None`` where ``auto`` runs the
    joint LPs instead (logged with the reason) -- as :func:`tubejax.abstraction.product_abstraction.abstract_auto`
    decides (:func:`tubejax.abstraction.product_store.try_product`), but the joint LPs then run as every run
    of this app does (budget, rounds, resume).

    Raises
    ------
    ConfigError
        ``product=true`` on a problem the product path cannot solve (the message says why).
    """
    from tubejax.abstraction.methods import batch_solver
    from tubejax.abstraction.product_abstraction import ProductOptions
    from tubejax.abstraction.product_store import try_product

    a = inputs.abstraction
    if a.L_max > 63:
        ps, why = None, f"the product path takes L_max in 1..63, not {a.L_max}"
    else:
        opts = ProductOptions(L_max=a.L_max, eps_min=a.eps_min, zshape=inputs.zshape.kind,
                              z_scale=inputs.zshape.scale, pruning=a.pruning, shard_count=a.shard.count,
                              shard_index=a.shard.index)
        ps, why = try_product(decomp, system, opts, Z=Z, method=a.method, min_margin=a.min_margin,
                              solve_batch=batch_solver(a), progress=progress)
    if ps is None and mode is True:
        raise ConfigError(f"product: {why}; run with product=false (or auto) for the joint tube LPs")
    if ps is None:
        log.warning("product=auto: %s; running the joint LPs", why)
    return ps


def save_product_run(ps, inputs, out: Path, flags):
    """Write the product system ``ps`` into the run directory ``out`` (``product_transitions.json|npz``, which
    ``python -m tubejax verify`` verifies, and ``metrics.json``); returns ``(run, json, npz)``.

    ``metrics.json`` counts the edges but does not list them: the npz holds them as arrays
    (:func:`tubejax.analyses.sweep_results.edge_sets` reads them there), and on the 6-D building the list
    alone was a 295 MB file and over a GB of Python lists.
    """
    from tubejax.abstraction.product_store import ProductRun

    store = open_run_directory(out, inputs.record(), flags)
    ps.stats["solver"] = inputs.abstraction.solver.name
    run = ProductRun.of_product(ps, inputs.record())
    jpath, npath = run.save(out)
    s = ps.stats
    write_json(out / "metrics.json", {
        "method": "tube", "product": True, "solver": s["solver"], "system": inputs.system.name,
        "workspace": ps.decomposition.name, "zshape": inputs.zshape.kind, "L_max": ps.L_max,
        "n_cells": ps.n_cells, "n_edges": ps.n_edges, "n_factor_lps": s["n_factor_lps"],
        "n_joint_lps": s["n_joint_lps"], "seconds": s["seconds"]})
    store.mark_complete()
    return run, jpath, npath


def learned_z_inputs(inputs, decomp, system, out: Path, flags):
    """For ``zshape=learned|learned_pair``: the run's ``out/learned_z.json`` and the inputs that name it.

    ``zshape.file`` given: its bytes are copied there. Else the table is learned now
    (:func:`tubejax.analyses.zshape.learn_run.learn_table`, a progress bar and log lines with the objective
    and the pairs certified), or, when resuming, the one the interrupted run learned is reused
    (learning is deterministic, so it is the one these inputs give). The returned inputs record
    the file by path (``learned_z.json``, looked up beside the transitions files) and SHA-256.
    Other kinds: ``inputs`` unchanged.
    """
    import jax

    from tubejax.inputs import ProblemInputs
    from tubejax.analyses.zshape import LearnOptions
    from tubejax.analyses.zshape.learn_run import learn_table
    from tubejax.model.zshape.z_table import ZTableError, load_z_table

    z = inputs.zshape
    if not z.learned:
        return inputs
    target = out / "learned_z.json"
    if z.file is not None:
        try:                                   # checked where the user put it: errors name their file, not our copy
            table = load_z_table(z.file.resolved, sha256=z.file.sha256)
        except ZTableError as exc:
            raise ConfigError(f"zshape.file: {exc}") from None
        if table.mode != z.kind:
            raise ConfigError(f"zshape.file: {z.file.resolved}: mode: the file holds {table.mode!r} Z, zshape.kind is "
                              f"{z.kind!r} (use zshape={table.mode}, or a file learned with zshape={z.kind})")
        data = z.file.read("learned Z file", ConfigError)
        if Path(z.file.resolved) != target.resolve():
            tmp = target.with_name(target.name + ".tmp")
            tmp.write_bytes(data)
            tmp.replace(target)
        log.info("zshape=%s: using %s (copied to %s)", z.kind, z.file.resolved, target)
    elif flags.resume and target.is_file():
        log.info("resume=true: reusing the learned Z of the interrupted run, %s", target)
    else:
        jax.config.update("jax_enable_x64", True)
        a = inputs.abstraction
        table = learn_table(decomp, system, z.kind, init=z.init, progress=flags.progress,
                            options=LearnOptions(steps=z.steps, learning_rate=z.learning_rate, horizon=z.horizon,
                                                 patience=z.patience, seed=z.seed, L_max=a.L_max,
                                                 eps_min=a.eps_min, pruning=a.pruning))
        sha = table.save(target)
        log.info("zshape=%s: learned %d shapes, %d pairs; wrote %s (sha256 %s)", z.kind, table.n_shapes,
                 len(table.pairs), target, sha[:12])
    record = inputs.record()
    record["zshape"]["file"] = {"path": target.name, "resolved": str(target.resolve())}
    return ProblemInputs.from_record(record, search_dirs=[out])


def open_run_directory(out: Path, record: dict, flags):
    """The :class:`~tubejax.abstraction.runstore.RunStore` of ``out``: a new run, or the interrupted one to resume.

    Raises
    ------
    ConfigError
        ``out`` holds a run and neither ``resume`` nor ``overwrite`` is set; ``resume`` with
        inputs that differ from the run's (each difference named); both flags at once.
    """
    from tubejax.abstraction.runstore import RunStore, record_differences, run_state
    from tubejax.abstraction.shards import comparable_record

    if flags.resume and flags.overwrite:
        raise ConfigError("overwrite: give resume=true (continue the run) or overwrite=true (delete it), not both")
    state = run_state(out)
    store = RunStore(out)
    identity = {"inputs": comparable_record(record, drop_shard_index=False)}
    if state != "empty" and flags.overwrite:
        store.clear()
        log.warning("overwrite=true: deleted the %s run in %s", state, out)
        state = "empty"
    if state == "partial" and not store.exists() and not (out / "transitions.json").exists():
        raise ConfigError(f"hydra.run.dir: {out} holds the remains of a run without its manifest "
                          f"({store.manifest_path}: no record of its steps), so it cannot be resumed; "
                          "choose a new hydra.run.dir, or delete it with overwrite=true")
    if state != "empty" and not flags.resume:
        what = ("a finished run" + _describe(store) + "; resume=true reads it back (the same inputs)"
                if state == "complete" else
                "an interrupted run" + _describe(store) + "; continue it with resume=true (the same inputs)")
        raise ConfigError(f"hydra.run.dir: {out} already holds {what}, choose a new hydra.run.dir, or delete it "
                          "with overwrite=true")
    if state == "empty" or not store.exists():
        if state != "empty":
            raise ConfigError(f"resume: {out} holds a finished run without round files (rounds/): nothing to "
                              "resume; choose a new hydra.run.dir, or delete it with overwrite=true")
        if flags.resume:
            log.info("resume=true: no run in %s yet, starting one", out)
        store.create(identity)
        return store
    diff = record_differences(store.identity().get("inputs"), identity["inputs"])
    if diff:
        raise ConfigError(f"resume: the inputs differ from those of the run in {out}: "
                          + "; ".join(_difference(p, a, b) for p, a, b in diff[:4])
                          + (f" (and {len(diff) - 4} more)" if len(diff) > 4 else "")
                          + "; resume with the same inputs, or choose a new hydra.run.dir")
    log.info("resume=true: continuing the run in %s", out)
    return store


def _describe(store) -> str:
    try:
        steps = store.manifest()["steps"] if store.exists() else None
    except ValueError:
        return " (its rounds/manifest.json is unreadable)"
    return "" if steps is None else f" ({len(steps)} finished steps in rounds/)"


def _difference(path: str, there, now) -> str:
    key = config_name(path)
    if path.endswith(".sha256"):
        return (f"{key[:-len('.sha256')]}: the file changed (SHA-256 {str(there)[:12]}... in the run, "
                f"{str(now)[:12]}... now)")
    return f"{key}: {there!r} in the run, {now!r} now"


def check_run_budget(budget, settings, decomp, system, Z) -> None:
    """Log the run's estimate (cells, candidate pairs, LPs, memory:
    :func:`tubejax.abstraction.preflight.estimate_run`) and refuse a run beyond ``budget``, naming the
    estimate and the keys that change it (a shard counts its share of the LPs)."""
    est = estimate_run(decomp, system, decomp.cells if Z is None else Z, settings.L_max, settings.pruning,
                       settings.method, settings.memory_budget_mb, budget.max_lp_size)
    if settings.shard.count > 1:
        est = est._replace(n_lps=-(-est.n_lps // settings.shard.count))
    log.info("%s", est.line())
    refusal = budget_refusal(est, budget)
    if refusal:
        raise ConfigError(refusal)


def check_memory_budget(settings, decomp, system, Z) -> None:
    """Refuse up front a ``memory_budget_mb`` in which one LP at ``L_max`` does not fit, naming what it
    would need (:meth:`tubejax.abstraction.schedule.MemoryBudget.megabytes_needed`); else the rounds would run
    one LP at a time and still exceed it. exact2d solves no LP."""
    from tubejax.abstraction.schedule import MemoryBudget

    mb = settings.memory_budget_mb
    if mb is None or not formulation(settings.method).solves_lp:
        return
    need = MemoryBudget(mb, decomp, system, Z).megabytes_needed(settings.L_max)
    if need > mb:
        raise ConfigError(f"memory_budget_mb: one LP at horizon L_max = {settings.L_max} needs about {need} MB "
                          f"of working memory ({decomp.n_cells} cells of up to "
                          f"{max(c.n_vertices for c in decomp.cells)} vertices, a {system.n}-D state), more than "
                          f"the budget of {mb} MB; raise memory_budget_mb to at least {need}, or lower L_max")


def metrics(inputs, ts) -> dict:
    """One flat row per job, for experiments/aggregate.py."""
    s = ts.stats
    Ls = [e.L for e in ts.edges]
    margins = [e.margin for e in ts.edges]
    d, a = inputs.disturbance, inputs.abstraction
    return {
        "method": a.method, "solver": a.solver.name, "system": inputs.system.name,
        "workspace": ts.decomposition.name, "disturbance": d.kind,
        "radius": float(getattr(d, "radius", getattr(d, "half_width", float("nan")))),
        "zshape": inputs.zshape.kind, "L_max": a.L_max, "pruning": a.pruning,
        "n_cells": s["n_cells"], "n_edges": s["n_edges"], "n_lps": s["n_lps"],
        "n_pruned": s["n_pruned"], "n_translated": s.get("n_translated", 0), "n_zero_margin": s["n_zero_margin"],
        "mean_L": float(sum(Ls) / len(Ls)) if Ls else float("nan"),
        "mean_margin": float(sum(margins) / len(margins)) if margins else float("nan"),
        "seconds": s["seconds"], "compile_seconds": s["compile_seconds"],
        "learn_seconds": s.get("learn_seconds", 0.0),
        "edges": [[e.src, e.dst, e.L] for e in ts.edges],
    }


@hydra.main(version_base=None, config_path="../conf", config_name="config")
def main(cfg: DictConfig) -> None:
    out = Path(hydra.core.hydra_config.HydraConfig.get().runtime.output_dir)
    try:
        ts, jpath, npath = run_abstraction(cfg, out, allow_shard=True)
    except (ConfigError, ValueError) as exc:   # every InputError (ConfigError, RunStoreError, ...) is a ValueError
        log.error("%s", exc)
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:
        msg = (f"interrupted: the finished steps are in {out / 'rounds'}; continue with resume=true "
               f"hydra.run.dir={out}")
        log.error("%s", msg)
        print(msg, file=sys.stderr)
        sys.exit(130)
    s = ts.stats
    print(f"workspace      : {ts.decomposition.name}")
    if getattr(ts, "product", None) is not None:
        print(f"product path   : {ts.product.structure.describe()}\nstates         : {ts.n_cells:6d}\n"
              f"transitions    : {ts.n_edges:6d}\nfactor LPs     : {s['n_factor_lps']:6d}   joint LPs: "
              f"{s['n_joint_lps']}\nseconds        : {s['seconds']:.2f}\nwrote          : {jpath}\n"
              f"                 {npath}  (python -m tubejax verify {out})")
        if "shard" in s:
            sh = s["shard"]
            print(f"shard          : {sh['index']} of {sh['count']} (source cells {sh['start']}..{sh['stop'] - 1}); "
                  "merge the shards with experiments/merge.py SWEEP_DIR, then verify the merged run")
        return
    print("\n".join(count_lines(ts)))
    n_tr = s.get("n_translated", 0)
    print(f"LPs solved     : {s['n_lps'] - n_tr:6d}   pruned (pair, L): {s['n_pruned']}  {s['pruned']}")
    if n_tr:
        print(f"by translation : {n_tr:6d}   non-edges settled by an exact translate's infeasibility")
    print(f"zero-margin    : {s['n_zero_margin']:6d}   unconfirmed: {s['n_unconfirmed']}")
    print(f"seconds        : {s['seconds']:.2f}   (compiling: {s['compile_seconds']:.2f}; solver {s['solver']})")
    if "solver_stats" in s:
        st = s["solver_stats"]
        print(f"PDHG           : certified infeasible {st.get('certified_infeasible')}, certified feasible "
              f"{st.get('certified_feasible')} (HiGHS-confirmed), sent to HiGHS {st.get('sent_to_highs')}, "
              f"HiGHS disagreements {st.get('highs_disagreements')}")
    if s.get("resumed_lps"):
        print(f"resumed        : {s['resumed_lps']} instances read back from {out / 'rounds'}")
    if "shard" in s:
        sh = s["shard"]
        print(f"shard          : {sh['index']} of {sh['count']} ({sh['n_sources']} source cells, "
              f"{sh['n_pairs']} pairs); merge the shards with experiments/merge.py SWEEP_DIR")
    print(f"wrote          : {jpath}\n                 {npath}")
    if (out / "learned_z.json").is_file() and s.get("zshape") in ("learned", "learned_pair"):
        print(f"                 {out / 'learned_z.json'} (the learned Z)")


if __name__ == "__main__":
    check_config_files()
    main()
