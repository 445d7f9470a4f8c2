"""The jobs of a Hydra sweep, planned and checked before the first one starts.

Configured for every app in ``conf/config.yaml`` (``abstract``, ``radius``, ``simulate``, ``paper``):

* **Job folders named by their overrides.** ``hydra.sweep.subdir`` is
  ``${tubejax.job_dir:${hydra.overrides.task}}``: the job's own overrides, sorted, without the
  flags ``progress``, ``resume`` and ``overwrite`` (:func:`job_dir_name`:
  ``L_max-4+disturbance.radius-0.1+method-tube``). Adding methods or radii to a sweep directory
  adds folders; it never reuses another job's folder.
* **Checked before the first job** (:class:`SweepCheck`, ``hydra.callbacks.sweep_check``):
  ``on_multirun_start`` expands the sweep exactly as the sweeper will, composes every job's
  config and validates it as its app does (:func:`check_job`: the input model of
  :mod:`tubejax.inputs`, the files, the cells, the app's own settings). One bad value refuses
  the whole sweep (``error: ...`` naming the value and the job, exit code 2) and no job runs.
* **Each distinct job once.** Jobs whose composed configs are equal (:func:`job_key`: the
  flags aside, and for the methods that ignore them, :func:`tubejax.lp.evidence.registry.ignored_settings`,
  ``zshape`` and ``eps_min``, for exact2d also ``solver``) run once: the first valid one of
  them runs, the others are skipped as duplicates. A job equal to a finished job already in the
  sweep directory is skipped too (``done``), so rerunning a sweep command with more methods runs
  only the new jobs. ``overwrite=true`` runs them again (the app deletes the old run first).
* **Never overwritten silently.** A job whose folder holds an unfinished run is refused unless
  ``resume=true`` (continue it) or ``overwrite=true``; one whose folder holds a finished run of
  other inputs (a changed file or default) is refused unless ``overwrite=true``.

The plan goes to ``SWEEP_DIR/sweep.json`` (every job of every sweep into that directory: its
folder, overrides, status ``run`` | ``done`` | ``duplicate`` and the job it duplicates), which
``experiments/aggregate.py`` reads to name missing and failed jobs. :class:`PlannedSweeper`
(``hydra/sweeper: planned``, Hydra's basic sweeper; in
``experiments/hydra_plugins/tubejax_sweeper``, where Hydra looks for sweepers) launches only the
jobs planned to run.
"""

from __future__ import annotations

import copy
import hashlib
import json
import os
import sys
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import quote

from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf, open_dict, read_write

sys.path.insert(0, str(Path(__file__).resolve().parent))

__all__ = ["SweepCheck", "planned_skips", "job_dir_name", "job_key", "check_job", "plan_sweep", "PLAN_FILE",
           "FLAGS"]

#: The plan of every sweep into a directory (``SWEEP_DIR/sweep.json``).
PLAN_FILE = "sweep.json"
#: Top-level keys that change how a job runs, never its result: not in folder names or job keys.
FLAGS = ("progress", "resume", "overwrite")
#: Longest folder name (bytes) before the end is replaced by a hash.
_MAX_NAME = 200
#: Jobs the sweeps planned in this process skip: ``{sweep dir: {job overrides: plan status}}``.
_SKIP: dict[str, dict[tuple, str]] = {}


def _encode(text: str, keep: str) -> str:
    """Percent-encode all but letters, digits and ``keep`` (``~`` too: Hydra refuses it unquoted)."""
    return quote(text, safe=keep).replace("~", "%7E")


def job_dir_name(overrides) -> str:
    """A job's folder name, from its own overrides (``hydra.overrides.task``).

    The overrides except :data:`FLAGS`, sorted, as ``key-value`` joined by ``+``
    (``L_max-4+disturbance.radius-0.1+method-tube``). Every other character but letters, digits,
    ``_`` and ``.`` (and ``-`` in a value) is percent-encoded (a map file ``/data/a.txt`` becomes
    ``%2Fdata%2Fa.txt``), so distinct overrides give distinct names, no name leaves the sweep
    directory, and a name can be given unquoted as ``hydra.run.dir=...`` (Hydra's override grammar
    refuses ``=`` and ``,`` in a value). A name over 200 bytes keeps its first 150 and a SHA-256 of
    the whole. No overrides: ``defaults``.

    Examples
    --------
    >>> job_dir_name(["method=tube", "L_max=4", "progress=false"])
    'L_max-4+method-tube'
    >>> job_dir_name(["workspace.map_file=/tmp/maps/a b.txt"])
    'workspace.map_file-%2Ftmp%2Fmaps%2Fa%20b.txt'
    """
    items = []
    for o in sorted(str(o) for o in (overrides or [])):
        key, _, value = o.partition("=")
        if key.lstrip("+~") in FLAGS:
            continue
        items.append(_encode(key, "_.") + "-" + _encode(value, "_.-"))
    name = "+".join(items) or "defaults"
    if len(name.encode()) > _MAX_NAME:
        name = name[:150] + "+sha256-" + hashlib.sha256("\n".join(items).encode()).hexdigest()[:16]
    return name


OmegaConf.register_new_resolver("tubejax.job_dir", lambda overrides: job_dir_name(list(overrides)), replace=True)


def _method(c: dict):
    m = c.get("method")
    return m.get("name") if isinstance(m, dict) else m


def job_key(c: dict) -> str:
    """What makes two jobs the same: the resolved config without :data:`FLAGS` and without the
    settings its method ignores (:func:`tubejax.lp.evidence.registry.ignored_settings`; not for ``radius.py``,
    which solves the tube form whatever ``method`` is)."""
    from tubejax.lp.evidence.registry import ignored_settings

    key = {k: v for k, v in c.items() if k not in FLAGS}
    if "radii" not in c:
        for k in ignored_settings(_method(c)):
            key.pop(k, None)
    return json.dumps(key, sort_keys=True, default=str)


def app_of(c: dict) -> str:
    """``radius``, ``simulate`` (also ``paper.py``), ``conservatism`` or ``abstract``, from the config's own keys."""
    return ("radius" if "radii" in c else "simulate" if "sim" in c else "conservatism" if "methods" in c
            else "abstract")


#: The file a finished job of each app has written last.
DONE_FILE = {"abstract": "metrics.json", "simulate": "simulation.json", "radius": "radius.json",
             "conservatism": "conservatism.json"}


def check_job(c: dict, cache: dict | None = None):
    """Validate one job's resolved config as its app does before any work; returns its
    :class:`~tubejax.inputs.ProblemInputs` (``None`` for a simulation of a given ``abstraction_dir``).

    Beyond the input model: the workspace is built (a map file parsed, its cells checked; once
    per distinct workspace in ``cache``), the system and fixed cross-sections too, and each app's
    own settings (``radius.py``: ``radii``, ``radius_methods`` and what its form supports;
    ``simulate.py``: ``spec``, ``sim``, ``abstraction_dir``).

    Raises
    ------
    ValueError
        (:class:`common.ConfigError` and every other :class:`tubejax.errors.InputError`) naming
        the key, the value and what was expected.
    """
    from common import app_flags, inputs_from_config, sim_settings, spec_settings

    cache = {} if cache is None else cache
    app = app_of(c)
    if app == "simulate":
        from simulated_abstraction import abstraction_dir

        flags = app_flags(c, simulate=True)
        spec_settings(c.get("spec"))
        sim = c.get("sim") or {}
        sim_settings(sim.get("runs"), sim.get("disturbance"), sim.get("seed"), cycles=sim.get("cycles", 1))
        if flags.abstraction_dir is not None:
            abstraction_dir(flags.abstraction_dir)
            return None
    app_flags(c, figures=app == "radius")
    inputs = inputs_from_config(c)
    if app == "conservatism":
        from conservatism import check_conservatism, conservatism_settings

        check_conservatism(c, inputs, conservatism_settings(c))
    if app == "radius":
        from radius import check_radius_settings, radius_settings

        check_radius_settings(inputs, radius_settings(c))
    ws = json.dumps(inputs.record()["workspace"], sort_keys=True)
    if ws not in cache:
        cache[ws] = inputs.build_decomposition()
    inputs.build_system()
    if not inputs.zshape.learned:
        inputs.build_cross_sections(cache[ws])
    return inputs


@dataclass
class Job:
    """One job of a sweep: its overrides, folder, resolved config and what the plan does with it."""

    overrides: list
    dir: Path
    config: dict | None = None
    inputs: object = None
    error: str | None = None
    status: str = "run"
    same_as: Path | None = None
    reason: str = ""
    key: str = ""
    flags: dict = field(default_factory=dict)


def _task_dict(cfg: DictConfig) -> dict:
    """The job's resolved config without ``hydra`` (what the app gets)."""
    from common import config_dict

    task = copy.deepcopy(cfg)
    with read_write(task), open_dict(task):
        if "hydra" in task:
            del task["hydra"]
    return config_dict(task)


def _sweep_jobs(config: DictConfig) -> list[list[str]]:
    """The jobs' overrides, in launch order, exactly as :class:`BasicSweeper` expands them."""
    from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
    from hydra.core.global_hydra import GlobalHydra
    from hydra.core.override_parser.overrides_parser import OverridesParser

    params = OmegaConf.select(config, "hydra.sweeper.params") or {}
    args = [f"{k}={v}" for k, v in params.items()] + list(config.hydra.overrides.task)
    loader = GlobalHydra.instance().config_loader() if GlobalHydra.instance().is_initialized() else None
    parsed = OverridesParser.create(config_loader=loader).parse_overrides(args)
    return [list(j) for batch in BasicSweeper.split_arguments(parsed, None) for j in batch]


def _existing_jobs(sweep: Path) -> dict[str, Path]:
    """``{job key: folder}`` of the finished jobs already in ``sweep`` (any folder layout)."""
    found = {}
    for cfg_file in sorted(sweep.glob("*/.hydra/config.yaml")):
        d = cfg_file.parent.parent
        try:
            c = _task_dict(OmegaConf.load(cfg_file))
        except Exception:                          # an unreadable old job: not a match for anything
            continue
        if (d / DONE_FILE[app_of(c)]).is_file():
            found.setdefault(job_key(c), d)
    return found


def _strip_resolved(record):
    if isinstance(record, dict):
        return {k: _strip_resolved(v) for k, v in record.items() if k != "resolved"}
    if isinstance(record, list):
        return [_strip_resolved(v) for v in record]
    return record


def _same_inputs(d: Path, job: Job) -> str | None:
    """``None`` when the run in ``d`` was made from ``job``'s inputs (files by SHA-256), else the first difference."""
    from common import config_name
    from tubejax.abstraction.runstore import RunStore, record_differences
    from tubejax.abstraction.shards import comparable_record

    store = RunStore(d)
    if job.inputs is None or not store.exists():
        return None
    try:
        old = store.identity().get("inputs")
    except (ValueError, OSError):
        return "its rounds/manifest.json is unreadable"
    new = comparable_record(job.inputs.record(), drop_shard_index=False)
    diff = record_differences(_strip_resolved(old), _strip_resolved(new))
    if not diff:
        return None
    path, there, now = diff[0]
    return f"{config_name(path)}: {there!r} there, {now!r} now"


def _describe(job: Job, swept: set | None = None) -> str:
    """The job's overrides that differ between the sweep's jobs (all of them when none do)."""
    shown = [o for o in job.overrides if swept and o.split("=", 1)[0].lstrip("+~") in swept]
    return " ".join(shown or job.overrides) or "(no overrides)"


def plan_sweep(config: DictConfig) -> tuple[list[Job], list[tuple[str, str]]]:
    """Every job of the sweep ``config`` describes, with its plan status; and the problems that refuse it.

    Returns
    -------
    jobs : list of Job
        In launch order; ``status`` ``run``, ``done`` (finished in its folder already) or
        ``duplicate`` (``same_as`` the job that computes it).
    problems : list of (str, str)
        Per refusal, the message and the job's swept overrides: a bad value (the app's message),
        an unfinished run without ``resume=true``, a finished run of other inputs or settings
        without ``overwrite=true``.
    """
    from hydra.core.global_hydra import GlobalHydra
    from hydra.core.hydra_config import HydraConfig
    from tubejax.abstraction.runstore import run_state

    loader = GlobalHydra.instance().config_loader()
    sweep = Path(os.path.abspath(str(config.hydra.sweep.dir)))
    jobs, cache = [], {}
    saved = HydraConfig.instance().cfg
    try:
        for overrides in _sweep_jobs(config):
            cfg = loader.load_sweep_config(config, list(overrides))
            HydraConfig.instance().set_config(cfg)
            job = Job(overrides=list(overrides), dir=sweep / str(OmegaConf.select(cfg, "hydra.sweep.subdir")))
            try:
                job.config = _task_dict(cfg)
                job.flags = {k: job.config.get(k) is True for k in FLAGS}
                job.key = job_key(job.config)
                job.inputs = check_job(job.config, cache)
            except ValueError as exc:
                job.error = str(exc)
                job.key = job.key or _describe(job)
            jobs.append(job)
    finally:
        HydraConfig.instance().cfg = saved
    values: dict[str, set] = {}
    for j in jobs:
        for o in j.overrides:
            k, _, v = o.partition("=")
            values.setdefault(k.lstrip("+~"), set()).add(v)
    swept = {k for k, v in values.items() if len(v) > 1}
    existing = _existing_jobs(sweep) if sweep.is_dir() else {}
    problems = []
    groups: OrderedDict[str, list[Job]] = OrderedDict()
    for job in jobs:
        groups.setdefault(job.key, []).append(job)
    for key, members in groups.items():
        valid = [j for j in members if j.error is None]
        if not valid:
            for j in members:
                j.status = "invalid"
            j = members[0]
            problems.append((f"{j.error} (sweep job: {_describe(j, swept)})", _describe(j, swept)))
            continue
        rep = valid[0]
        old = existing.get(key)
        if old is not None and not rep.flags["overwrite"]:
            diff = _same_inputs(old, rep)
            if diff is not None:
                problems.append((f"hydra.sweep.dir: {old} holds a finished job with other inputs ({diff}); "
                                 f"rerun it with overwrite=true, or choose a new hydra.sweep.dir",
                                 _describe(rep, swept)))
            for j in members:
                j.status, j.same_as = ("done", None) if j.dir == old else ("duplicate", old)
                differ = [k for k in _ignored(j.config) if j.config.get(k) != rep.config.get(k)]
                j.reason = ("finished already" if j.dir == old else
                            f"method {_method(j.config)} ignores {', '.join(differ)}" if differ else
                            "the same job finished already")
            continue
        rep.status = "run"
        state = run_state(rep.dir) if rep.dir.is_dir() else "empty"
        cfg_file = rep.dir / ".hydra" / "config.yaml"
        if state != "empty" and cfg_file.is_file() and not rep.flags["overwrite"]:
            try:
                there = job_key(_task_dict(OmegaConf.load(cfg_file)))
            except Exception:
                there = None
            if there != key:
                problems.append((f"hydra.sweep.dir: {rep.dir} holds a job of other settings (a default or "
                                 "config file changed since); rerun it with overwrite=true, or choose a new "
                                 "hydra.sweep.dir", _describe(rep, swept)))
        if state != "empty" and not (rep.flags["resume"] or rep.flags["overwrite"]):
            done = (rep.dir / DONE_FILE[app_of(rep.config)]).is_file()
            if not done:
                problems.append((f"hydra.sweep.dir: {rep.dir} holds an unfinished job; continue it with "
                                 "resume=true (finished jobs are skipped), or start it again with overwrite=true",
                                 _describe(rep, swept)))
        for j in members:
            if j is not rep:
                j.status, j.same_as = "duplicate", rep.dir
                differ = [k for k in _ignored(j.config) if j.config.get(k) != rep.config.get(k)]
                j.reason = f"method {_method(j.config)} ignores {', '.join(differ)}" if differ else "the same job"
    return jobs, problems


def _ignored(c: dict) -> tuple:
    from tubejax.lp.evidence.registry import ignored_settings

    return () if c is None or "radii" in c else ignored_settings(_method(c))


def write_plan(sweep: Path, jobs: list[Job], overrides: list[str]) -> Path:
    """Add this sweep's jobs to ``sweep/sweep.json`` (a job's folder keeps its latest entry)."""
    path = sweep / PLAN_FILE
    try:
        plan = json.loads(path.read_text()) if path.is_file() else {}
    except (OSError, ValueError):
        plan = {}
    if plan.get("format") != "tubejax.sweep":
        plan = {"format": "tubejax.sweep", "version": 1, "sweeps": [], "jobs": {}}
    plan["sweeps"].append({"time": time.strftime("%Y-%m-%dT%H:%M:%S"), "overrides": list(overrides),
                           "jobs": len(jobs), "run": sum(j.status == "run" for j in jobs)})

    def rel(d: Path) -> str:
        return d.name if d.parent == sweep else str(d)

    owners = {j.dir for j in jobs if j.status != "duplicate"}
    for j in jobs:
        if j.status == "duplicate" and j.dir in owners:
            continue                                 # its folder is the job it duplicates (flags differ)
        plan["jobs"][rel(j.dir)] = {"overrides": j.overrides, "status": j.status,
                                    "same_as": None if j.same_as is None else rel(j.same_as), "reason": j.reason}
    sweep.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(plan, indent=1))
    tmp.replace(path)
    return path


def _sweeper_is_basic(config: DictConfig) -> bool:
    target = str(OmegaConf.select(config, "hydra.sweeper._target_") or "")
    return target.endswith(("BasicSweeper", "PlannedSweeper"))


class SweepCheck(Callback):
    """Plans and validates a sweep before its first job (see the module docstring)."""

    def on_multirun_start(self, config: DictConfig, **kwargs) -> None:
        if not _sweeper_is_basic(config):
            print(f"sweep: {OmegaConf.select(config, 'hydra.sweeper._target_')} is not the basic sweeper; "
                  "its jobs are not checked before they start", file=sys.stderr)
            return
        sweep = Path(os.path.abspath(str(config.hydra.sweep.dir)))
        try:
            jobs, problems = plan_sweep(config)
        except SystemExit:
            raise
        except Exception as exc:                 # Hydra would turn it into a warning and run the sweep unchecked
            print(f"error: the sweep could not be checked before its first job ({type(exc).__name__}: {exc}); "
                  "no job was started", file=sys.stderr)
            sys.exit(2)
        if problems:
            others = [short for _, short in problems[1:]]
            more = (f" (and {len(others)} more: {'; '.join(others[:5])}{' ...' if len(others) > 5 else ''})"
                    if others else "")
            print(f"error: {problems[0][0]}{more}; no job of the sweep was started",
                  file=sys.stderr)
            sys.exit(2)
        if not str(OmegaConf.select(config, "hydra.sweeper._target_")).endswith("PlannedSweeper"):
            for j in jobs:                       # Hydra's own basic sweeper launches every job
                j.status, j.same_as, j.reason = "run", None, ""
            print("sweep: hydra/sweeper is not 'planned': every job runs, duplicates and finished jobs included",
                  file=sys.stderr)
        path = write_plan(sweep, jobs, list(config.hydra.overrides.task))
        _SKIP[str(sweep)] = {tuple(j.overrides): j.status for j in jobs if j.status != "run"}
        n = {s: sum(j.status == s for j in jobs) for s in ("run", "done", "duplicate")}
        ignoring = sorted({j.reason for j in jobs if j.status == "duplicate" and j.reason.startswith("method")})
        print(f"sweep: {len(jobs)} jobs: {n['run']} to run"
              + (f", {n['duplicate']} duplicates skipped" if n["duplicate"] else "")
              + (f" ({'; '.join(ignoring)}: run once)" if ignoring else "")
              + (f", {n['done']} finished already in {sweep} (skipped)" if n["done"] else "")
              + f"; plan in {path}", flush=True)


def planned_skips(sweep: Path) -> dict[tuple, str] | None:
    """``{job overrides: status}`` of the jobs the sweep into ``sweep`` planned in this process not to
    run; ``None`` when no sweep check ran (every job runs)."""
    return _SKIP.get(str(sweep))
