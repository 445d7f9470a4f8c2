"""Where the transition system ``simulate.py`` and ``paper.py`` plan over comes from.

``abstraction_dir`` given: the saved run, loaded as strictly as ``python -m tubejax verify`` reads it
(:func:`tubejax.verify.verifier.load_checked`), with tubes, not one shard, and every problem override
given beside it equal to the run's value (:func:`contradicting_overrides`); a product run
(``product_transitions.json|npz``, e.g. merged shards) is loaded with its problem rebuilt from its sources
and verified before it is planned over (:func:`loaded_product`). Otherwise the abstraction
is built (joint tube LPs through ``abstract.py``, or ``product=true``: by exact product decomposition,
verified before it is planned over).
"""

from __future__ import annotations

import json
import logging
import sys
import time
from pathlib import Path

from hydra.core.hydra_config import HydraConfig
from hydra.core.override_parser.overrides_parser import OverridesParser
from omegaconf import DictConfig

from tubejax.abstraction.methods import batch_solver
from tubejax.abstraction.preflight import RunBudget, budget_refusal, count_cells
from tubejax.abstraction.product_abstraction import build_product_abstraction
from tubejax.abstraction.product_store import load_product
from tubejax.abstraction.product_transitions import product_transition_system
from tubejax.abstraction.runstore import record_differences
from tubejax.analyses.control.controller import require_tubes
from tubejax.errors import InputError
from tubejax.lp.evidence.registry import tube_methods
from tubejax.model.product_structure import NotAProduct
from tubejax.transitions.product_file import PRODUCT_STEM, is_product_run
from tubejax.verify.product_check import verify_product
from tubejax.verify.verifier import load_checked

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import (ConfigError, app_flags, config_dict, config_name, inputs_from_config,  # noqa: E402
                    search_dirs, write_json)

log = logging.getLogger("tubejax")
#: Config keys of the problem (the inputs record): beside ``abstraction_dir`` an override of one must
#: equal the loaded run's value. ``seed`` is the simulation's seed (``sim.seed``) and ``memory_budget_mb``
#: never changes a result, so neither is compared; ``experiment`` presets set any of them.
PROBLEM_KEYS = ("workspace", "system", "disturbance", "zshape", "method", "solver", "L_max", "eps_min",
                "min_margin", "pruning", "verify", "shard", "experiment")


def _manifest_status(run: Path):
    """The status ``rounds/manifest.json`` of ``run`` records (``'complete'``: the run finished), or None."""
    try:
        return json.loads((run / "rounds" / "manifest.json").read_text(encoding="utf-8")).get("status")
    except (OSError, UnicodeDecodeError, ValueError, AttributeError):
        return None


def abstraction_dir(value) -> Path:
    """``abstraction_dir`` resolved: a directory holding transitions.json and transitions.npz."""
    p = Path(str(value)).expanduser()
    cands = [p] if p.is_absolute() else [d / p for d in search_dirs()]
    found = next((c for c in cands if c.exists()), None)
    if found is None:
        raise ConfigError(f"abstraction_dir: {str(value)!r} not found (looked in {', '.join(map(str, cands))})")
    if not found.is_dir():
        raise ConfigError(f"abstraction_dir: expected a directory holding transitions.json and transitions.npz, "
                          f"got the file {str(found)!r}")
    if is_product_run(found):                            # a product run (merged shards included)
        missing = [f for f in (f"{PRODUCT_STEM}.json", f"{PRODUCT_STEM}.npz") if not (found / f).is_file()]
        if missing:
            raise ConfigError(f"abstraction_dir: {str(found)!r} holds no {missing[0]}")
        return found
    missing = [f for f in ("transitions.json", "transitions.npz") if not (found / f).is_file()]
    if missing:
        hint = (" (rounds/ is there: the run was interrupted before it wrote them; continue it with "
                f"experiments/abstract.py resume=true hydra.run.dir={found})"
                if (found / "rounds" / "manifest.json").is_file() and _manifest_status(found) != "complete" else "")
        raise ConfigError(f"abstraction_dir: {str(found)!r} holds no {' and no '.join(missing)}{hint}")
    return found


def get_abstraction(cfg: DictConfig, out: Path):
    """Load ``cfg.abstraction_dir`` or build the abstraction into ``out``.

    A loaded run passes every cheap check of ``python -m tubejax verify``
    (:func:`tubejax.verify.verifier.load_checked`), stores tubes (method ``tube``), is not one shard of a
    run, and agrees with every problem override given beside it (:func:`contradicting_overrides`).
    A built one must be of method ``tube`` too (checked before any work).
    """
    c = config_dict(cfg)
    flags = app_flags(c, simulate=True)
    if flags.abstraction_dir:
        d = abstraction_dir(flags.abstraction_dir)
        if is_product_run(d):
            return loaded_product(c, d, out)
        try:
            ts = load_checked(d)                        # as strict as verify's cheap part
        except (OSError, ValueError) as exc:            # TransitionFileError names the file and field
            why = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise ConfigError(f"abstraction_dir: cannot load the transition system: {why}") from None
        check_usable(ts, d)
        refuse_contradictions(c, ts.inputs, d)
        log.info("loaded %d cells, %d edges from %s", ts.n_cells, ts.n_edges, d)
        return ts
    method = inputs_from_config(c).abstraction.method
    if method not in tube_methods():
        raise ConfigError(f"method: {method!r} stores no tubes, so there is no tube controller (Algorithm 1) to "
                          f"simulate; simulate.py needs method={' or '.join(tube_methods())}")
    if flags.product:
        return product_abstraction(c, out, flags)
    from abstract import run_abstraction

    ts, jpath, _ = run_abstraction(cfg, out)
    log.info("abstraction: %d cells, %d edges -> %s", ts.n_cells, ts.n_edges, jpath)
    return ts


def product_abstraction(c: dict, out: Path, flags):
    """``product=true``: the abstraction by exact product decomposition (docs/math/product.md), verified
    (:func:`tubejax.verify.product_check.verify_product`: every factor proof re-checked, the join recomputed)
    before it is planned over; its counts and seconds per phase go to ``out/product.json``.

    Raises
    ------
    ConfigError
        The problem is not a product (the message says why: run without ``product=true``), or the
        verification found a problem.
    """
    inputs = inputs_from_config(c)
    a = inputs.abstraction
    refusal = budget_refusal(None, RunBudget(**flags.budget.model_dump()), count_cells(inputs.workspace))
    if refusal:
        raise ConfigError(refusal)
    t0 = time.perf_counter()
    decomp = inputs.build_decomposition()
    system = inputs.build_system()
    Z = inputs.build_cross_sections(decomp)
    t1 = time.perf_counter()
    log.info("product path: %d cells in R^%d (%.1f s)", decomp.n_cells, decomp.dim, t1 - t0)
    try:
        ps = build_product_abstraction(decomp, system, Z=Z, L_max=a.L_max, eps_min=a.eps_min,
                                       solve_batch=batch_solver(a), progress=flags.progress)
    except NotAProduct as exc:
        raise ConfigError(f"product: {exc}; run without product=true for the joint tube LPs") from None
    log.info("product path: %d cells, %d edges (%.1f s)", decomp.n_cells, ps.n_edges, time.perf_counter() - t1)
    return _verified_system(ps, inputs.record(), out, {"seconds_cells": t1 - t0})


def loaded_product(c: dict, d: Path, out: Path):
    """``abstraction_dir`` holding a product run (``product_transitions.json|npz``; merged shards too): loaded
    with its problem rebuilt from its sources (:func:`~tubejax.abstraction.product_store.load_product`, which
    refuses files that differ from them), not one shard, every problem override equal to the run's
    (:func:`contradicting_overrides`), then verified as a built one is (:func:`_verified_system`)."""
    t0 = time.perf_counter()
    try:
        record = json.loads((d / f"{PRODUCT_STEM}.json").read_text(encoding="utf-8")).get("inputs")
        ps = load_product(d)
    except (OSError, ValueError, AttributeError, InputError) as exc:
        why = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ConfigError(f"abstraction_dir: cannot load the product system: {why}") from None
    refuse_one_shard(record, d)
    refuse_contradictions(c, record, d)
    log.info("loaded the product system of %d cells, %d edges from %s (%.1f s)", ps.n_cells, ps.n_edges, d,
             time.perf_counter() - t0)
    return _verified_system(ps, record, out, {"seconds_load": time.perf_counter() - t0})


def _verified_system(ps, record: dict | None, out: Path, seconds: dict):
    """``ps`` verified (:func:`tubejax.verify.product_check.verify_product`: every factor proof re-checked
    exactly, the join recomputed, each joint edge's tube checked) and made the transition system planned
    over; its counts and seconds per phase (``seconds`` added) go to ``out/product.json``."""
    t0 = time.perf_counter()
    report = verify_product(ps, exact=True, enumerate_join=ps.n_cells <= 20_000)
    t1 = time.perf_counter()
    if not report.ok:
        raise ConfigError(f"product: verification failed: {report.problems[0]}")
    stats = {**ps.stats, **seconds, "cells": ps.n_cells, "seconds_verify": t1 - t0,
             "verify": {k: v for k, v in vars(report).items() if k != "problems"}}
    write_json(out / "product.json", stats)
    log.info("product system verified in %.1f s -> %s", t1 - t0, out / "product.json")
    return product_transition_system(ps, record)


def check_usable(ts, d: Path) -> None:
    """Refuse a loaded run that cannot be simulated: no tubes (``exact2d``, ``openloop``), or one shard."""
    try:
        require_tubes(ts)
    except InputError as exc:
        raise ConfigError(f"abstraction_dir: {d}: {exc}") from None
    refuse_one_shard(ts.inputs, d)


def refuse_one_shard(record: dict | None, d: Path) -> None:
    """Refuse a loaded run whose inputs record ``record`` says it is one shard of a run."""
    shard = ((record or {}).get("abstraction") or {}).get("shard") or {}
    if shard.get("count", 1) > 1:
        raise ConfigError(f"abstraction_dir: {d} holds shard {shard.get('index')} of {shard['count']} (only the "
                          "edges leaving its share of the cells); merge the shards with experiments/merge.py and "
                          "give the merged directory")


def refuse_contradictions(c: dict, record: dict | None, d: Path) -> None:
    """Refuse problem overrides that contradict the loaded run's inputs record (:func:`contradicting_overrides`)."""
    bad = contradicting_overrides(c, record, task_overrides())
    if bad:
        more = f" (and {len(bad) - 1} more)" if len(bad) > 1 else ""
        raise ConfigError(f"{bad[0]}{more}; abstraction_dir={d} is simulated as it was computed: omit the "
                          "override, give the run's value, or compute a new abstraction without abstraction_dir")


def task_overrides() -> list[tuple[str, str]]:
    """``(override as typed, its key or config group)`` of the running Hydra app's command line."""
    if not HydraConfig.initialized():
        return []
    parsed = OverridesParser.create().parse_overrides(list(HydraConfig.get().overrides.task))
    return [(o.input_line, o.key_or_group) for o in parsed]


def _comparable(record: dict, keep_z_file: bool) -> dict:
    """An inputs record as a user's override is compared with it: files by content (SHA-256) only,
    without what an override cannot contradict (the record's version, the abstraction's seed and
    memory budget; the run's own learned-Z file unless ``keep_z_file``)."""
    def files_by_content(v):
        if isinstance(v, dict):
            if "sha256" in v and "path" in v:
                return {"sha256": v["sha256"]}
            return {k: files_by_content(x) for k, x in v.items()}
        return [files_by_content(x) for x in v] if isinstance(v, list) else v

    r = files_by_content({k: v for k, v in (record or {}).items() if k != "version"})
    a = r.get("abstraction")
    if isinstance(a, dict):
        r["abstraction"] = {k: v for k, v in a.items() if k not in ("seed", "memory_budget_mb")}
    z = r.get("zshape")
    if isinstance(z, dict) and not keep_z_file:
        r["zshape"] = {k: v for k, v in z.items() if k != "file"}
    return r


def _describe_difference(name: str, there, given) -> str:
    if name.endswith(".sha256"):
        return (f"{name[:-len('.sha256')]}: the file differs from the run's (SHA-256 {str(there)[:12]}... in the "
                f"run, {str(given)[:12]}... given)")
    return f"{name}: {there!r} in the run, {given!r} given"


def contradicting_overrides(c: dict, record: dict | None, overrides: list[tuple[str, str]]) -> list[str]:
    """One line per problem override (:data:`PROBLEM_KEYS`) whose value differs from the loaded
    run's inputs record ``record``; overrides equal to the run's values pass.

    ``c`` is the composed config (the overrides applied); an invalid override is refused by
    :func:`common.inputs_from_config` as it would be without ``abstraction_dir``.
    """
    mine = [(text, key) for text, key in overrides if key.split(".")[0] in PROBLEM_KEYS]
    if not mine or not isinstance(record, dict):
        return []
    given = inputs_from_config(c).record()
    keep_z_file = any(key.startswith("zshape.file") for _, key in mine)
    diffs = [(config_name(p), a, b)
             for p, a, b in record_differences(_comparable(record, keep_z_file), _comparable(given, keep_z_file))]
    out = []
    for text, key in mine:
        hits = [(n, a, b) for n, a, b in diffs
                if key == "experiment" or n == key or n.startswith((key + ".", key + "[")) or key.startswith(n + ".")]
        hit = min(hits, key=lambda d: not d[0].endswith((".kind", ".name")), default=None)   # a kind first
        if hit is not None:
            out.append(f"{text}: contradicts the loaded run ({_describe_difference(*hit)})")
    return out
