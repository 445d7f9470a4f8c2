"""Config -> validated input model -> typed library objects, shared by the Hydra apps in this folder.

This is the only place that reads config objects; everything in ``tubejax/`` takes typed
arguments. :func:`inputs_from_config` turns the composed config
(``OmegaConf.to_container(cfg, resolve=True)``) into a :class:`tubejax.inputs.ProblemInputs`;
a bad value becomes a :class:`ConfigError` whose message names the config key as the user
types it (``L_max``, ``sim.runs``, ``system.A``), the value and what was expected.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import re
import sys
import warnings
from pathlib import Path
from typing import Annotated

from pydantic import BeforeValidator

from hydra.core.hydra_config import HydraConfig

from tubejax.abstraction.preflight import empty_state_constraint
from tubejax.errors import InputError, InputModelError
from tubejax.files import decode_utf8, load_yaml_strict, read_bytes
from tubejax.inputs import (AbstractionSettings, BudgetSettings, ProblemInputs, SimulationSettings, SpecSettings,
                            validate_section)
from tubejax.inputs.problem_inputs import app_problem_dict
from tubejax.inputs.app_settings import (ConservatismSettings, FigureSettings, RadiusFigureSettings, RadiusSettings,
                                         figure_section)
from tubejax.inputs.values import Flag, StrictModel, integer
from tubejax.transitions.provenance import stamp

sys.path.insert(0, str(Path(__file__).resolve().parent))
from overrides import check_overrides, closest, unknown_key  # noqa: E402

PROJECT_ROOT = Path(__file__).resolve().parents[1]
log = logging.getLogger("tubejax")
# JAX logs at INFO, on every run without a TPU, "Unable to initialize backend 'tpu'" while it looks for
# one; Hydra's logging shows INFO. Only that logger's INFO lines are held back: which devices JAX uses
# (JAX_PLATFORMS, a GPU) is left alone, and its warnings still show.
logging.getLogger("jax._src.xla_bridge").setLevel(logging.WARNING)
_TUBEJAX_DIR = str(PROJECT_ROOT / "tubejax")


def _show_warning(message, category, filename, lineno, file=None, line=None, _default=warnings.showwarning):
    """tubejax's own warnings (a label box cutting cells, ...) as one ``warning: ...`` line on stderr
    and in the log, like the apps' other warnings; any other library's as Python shows them."""
    if str(filename).startswith(_TUBEJAX_DIR) or type(category).__module__.startswith("tubejax") or \
            category.__module__.startswith("tubejax"):
        print(f"warning: {message}", file=sys.stderr)
        log.warning("%s", message)
    else:
        _default(message, category, filename, lineno, file, line)


warnings.showwarning = _show_warning

__all__ = ["ConfigError", "PROJECT_ROOT", "config_dict", "inputs_from_config", "app_flags", "sim_settings",
           "spec_settings", "warn", "warn_if_disturbance_fits_nowhere", "warn_if_state_constraint_empty", "check_config_files", "enable_compilation_cache",
           "write_json", "ArgumentParser", "check_keys", "compilation_cache_dir", "APP_KEYS"]


class ConfigError(InputError):
    """A config value is missing or malformed; the message names the config key."""


#: model path -> config key, for whole fields and then for prefixes; other paths keep their names.
_CONFIG_FIELDS = (("abstraction.solver", "solver"), ("abstraction.method", "method"),
                  ("simulation.mode", "sim.disturbance"))
_CONFIG_PREFIXES = (("abstraction.", ""), ("simulation.", "sim."))


def config_name(path: str) -> str:
    """The config key for a model path (``abstraction.L_max`` -> ``L_max``, ``simulation.runs`` -> ``sim.runs``)."""
    for model, config in _CONFIG_FIELDS:
        if path == model or path.startswith((model + ".", model + "[")):
            return config + path[len(model):]
    for model, config in _CONFIG_PREFIXES:
        if path.startswith(model):
            return config + path[len(model):]
    return path


def config_error(exc: InputModelError) -> ConfigError:
    """``exc`` with its fields renamed to config keys; the first problem is the message."""
    problems = [(config_name(f), m) for f, m in exc.problems]
    more = f" (and {len(problems) - 1} more: {'; '.join(f for f, _ in problems[1:])})" if len(problems) > 1 else ""
    return ConfigError(f"{problems[0][0]}: {problems[0][1]}{more}")


def config_dict(cfg) -> dict:
    """The config as plain containers, interpolations resolved (errors become :class:`ConfigError`)."""
    from omegaconf import OmegaConf
    from omegaconf.errors import OmegaConfBaseException

    try:
        return OmegaConf.to_container(cfg, resolve=True)
    except OmegaConfBaseException as exc:
        key = getattr(exc, "full_key", None) or "config"
        raise ConfigError(f"{key}: cannot resolve the config ({str(exc).splitlines()[0]})") from None


def search_dirs() -> list[Path]:
    """Where relative paths are looked up: the launch directory, then the project root."""
    from hydra.utils import get_original_cwd

    try:
        cwd = Path(get_original_cwd())
    except ValueError:                       # not inside a Hydra app
        cwd = Path.cwd()
    return [cwd, PROJECT_ROOT]


def _pick(section, *keys) -> dict:
    return {k: section[k] for k in keys if isinstance(section, dict) and k in section}


def problem_dict(c: dict) -> dict:
    """The input model's dict from a resolved config dict (:func:`tubejax.inputs.problem_inputs.app_problem_dict`)."""
    return app_problem_dict(c)


def inputs_from_config(cfg) -> ProblemInputs:
    """The validated :class:`ProblemInputs` of an ``experiments/abstract.py``-style config.

    Raises
    ------
    ConfigError
        A bad value, named by its config key (``workspace.map_file``, ``L_max``, ``solver.pool``).
    """
    c = config_dict(cfg) if not isinstance(cfg, dict) else cfg
    try:
        return ProblemInputs.from_dict(problem_dict(c), search_dirs())
    except InputModelError as exc:
        raise config_error(exc) from None


def sim_settings(runs, mode, seed, field: str = "sim", cycles=1) -> SimulationSettings:
    """Validated simulation settings; errors name ``{field}.runs``, ``{field}.disturbance``, ``{field}.seed``,
    ``{field}.cycles``."""
    try:
        return validate_section(SimulationSettings, {"runs": runs, "mode": mode, "seed": seed, "cycles": cycles},
                                "simulation")
    except InputModelError as exc:
        err = config_error(exc)
        raise ConfigError(str(err).replace("sim.", f"{field}.", 1)) from None


def spec_settings(spec) -> SpecSettings:
    """Validated ``spec`` (sequence, start_cell, planner)."""
    try:
        return validate_section(SpecSettings, spec, "spec")
    except InputModelError as exc:
        raise config_error(exc) from None


def _product_choice(value):
    if value is True or value is False or value == "auto":
        return value
    raise ValueError(f"expected auto, true or false, got {value!r}")


#: ``product`` of experiments/abstract.py: ``auto`` (the product path when the structure is detected), true, false.
ProductChoice = Annotated[object, BeforeValidator(_product_choice)]


class _AbstractFlags(StrictModel):
    progress: Flag = True
    resume: Flag = False
    overwrite: Flag = False
    budget: BudgetSettings = BudgetSettings()
    product: ProductChoice = False           # radius and conservatism accept only false (app_flags)


class _RadiusFlags(_AbstractFlags):
    figures: Annotated[RadiusFigureSettings, figure_section("radius")] = RadiusFigureSettings()


class _SimulateFlags(StrictModel):
    progress: Flag = True
    budget: BudgetSettings = BudgetSettings()
    figures: Annotated[FigureSettings, figure_section("simulate")] = FigureSettings()
    abstraction_dir: str | None = None
    adversarial_runs: integer(1, 10 ** 7) | None = None
    product: Flag = False


def app_flags(c: dict, simulate: bool = False, figures: bool = False):
    """The apps' own top-level keys (``progress``, ``resume``, ``overwrite``; ``figures``, ``abstraction_dir``
    for simulate; ``figures`` too with ``figures=True``), validated.

    ``figures`` comes back as a :class:`~tubejax.inputs.FigureSettings` (simulate) or
    :class:`~tubejax.inputs.RadiusFigureSettings` (``figures=True``); ``figures: true``/``false``
    stands for the defaults with ``enabled`` set, and the object is true exactly when ``enabled``.

    First refuses a key the app does not read (:func:`check_keys`; the app is the running Hydra
    app's primary config, else ``simulate``, ``radius`` or ``config`` after the arguments).
    """
    app = hydra_config_name()
    if app not in APP_KEYS:
        app = "simulate" if simulate else ("radius" if figures else "config")
    check_keys(c, app)
    if app in _JOINT_ONLY_APPS and c.get("product", False) is not False:   # composed from config.yaml's key
        raise ConfigError(f"product: {_APP_SCRIPTS[app]} runs the joint tube LPs; product=true|auto is for "
                          f"experiments/abstract.py and experiments/simulate.py (got {c['product']!r})")
    model = _SimulateFlags if simulate else (_RadiusFlags if figures else
                                             _AbstractFlags)
    data = _pick(c, *model.model_fields)
    try:
        return validate_section(model, data)
    except InputModelError as exc:
        raise config_error(exc) from None


# ------------------------------------------------------------------ keys
#: Top-level keys of the problem (every app reads them): the input model's sections and settings.
_PROBLEM_KEYS = ("workspace", "system", "disturbance", "zshape", *AbstractionSettings.model_fields)
#: Top-level keys each app reads, by its primary config (``@hydra.main(config_name=...)``);
#: Hydra's own ``hydra`` node is always allowed.
APP_KEYS = {
    "config": (*_PROBLEM_KEYS, *_AbstractFlags.model_fields),
    "radius": (*_PROBLEM_KEYS, *_RadiusFlags.model_fields, *RadiusSettings.model_fields),
    "simulate": (*_PROBLEM_KEYS, "resume", "overwrite", "spec", "sim",
                 *(k for k in _SimulateFlags.model_fields if k != "adversarial_runs")),
    "paper": (*_PROBLEM_KEYS, "resume", "overwrite", "spec", "sim", *_SimulateFlags.model_fields),
    "conservatism": (*_PROBLEM_KEYS, *_AbstractFlags.model_fields, *ConservatismSettings.model_fields),
}
#: Apps whose config holds ``product`` (composed from conf/config.yaml) but that take only ``product=false``.
_JOINT_ONLY_APPS = ("radius", "conservatism")
#: The app scripts' primary configs.
APP_CONFIGS = {"abstract": "config", "radius": "radius", "simulate": "simulate", "paper": "paper",
               "conservatism": "conservatism"}
#: Sections the apps read key by key, and their keys (the other sections are validated whole by
#: strict models, which refuse unknown fields themselves).
SECTION_KEYS = {"method": ("name",), "sim": ("runs", "disturbance", "seed", "cycles")}
_APP_SCRIPTS = {v: f"experiments/{k}.py" for k, v in APP_CONFIGS.items()}


def hydra_config_name() -> str | None:
    """The primary config of the running Hydra app (``config``, ``radius``, ...), or None outside one."""
    try:
        return str(HydraConfig.get().job.config_name)
    except Exception:                                # noqa: BLE001 -- not inside a Hydra app
        return None


def check_keys(c: dict, app: str = "config") -> None:
    """Refuse a key of the resolved config ``c`` that app ``app`` never reads.

    ``+L_mx=5`` adds a top-level key that nothing reads, so it would be ignored silently;
    each app's keys are :data:`APP_KEYS` (``hydra`` is Hydra's own), and the keys of the
    sections read key by key are :data:`SECTION_KEYS`. The other sections are strict models.

    Raises
    ------
    ConfigError
        Naming the first unknown key and, when one is close, the key meant.
    """
    known = APP_KEYS.get(app, APP_KEYS["config"])
    where = _APP_SCRIPTS.get(app, f"the {app} config")
    for key in c:
        if key not in known and key != "hydra":
            raise ConfigError(str(unknown_key(str(key), known, where)))
    for section, keys in SECTION_KEYS.items():
        if section in known and isinstance(c.get(section), dict):
            for key in c[section]:
                if key not in keys:
                    raise ConfigError(str(unknown_key(f"{section}.{key}", keys, section)))


class ArgumentParser(argparse.ArgumentParser):
    """``argparse`` for the command-line scripts (merge, aggregate): a bad argument, an unknown
    option (the one meant suggested) or a missing one is one ``error:`` line and exit code 2, as
    in the Hydra apps, instead of argparse's usage block."""

    def error(self, message: str):
        m = re.match(r"unrecognized arguments: (\S+)", message)
        options = [o for a in self._actions for o in a.option_strings]
        near = closest(m.group(1).split("=")[0], options) if m else None
        hint = f"; did you mean {near}?" if near else ""
        print(f"error: {message}{hint} (usage: {self.format_usage().strip().removeprefix('usage: ')})",
              file=sys.stderr)
        sys.exit(2)


def warn(message: str) -> None:
    """One ``warning: ...`` line on stderr, and the same in the run's log."""
    print(f"warning: {message}", file=sys.stderr)
    log.warning("%s", message)


def warn_if_state_constraint_empty(decomp, system) -> bool:
    """Warn when ``system.X`` holds no point of the workspace, proved exactly
    (:func:`tubejax.abstraction.preflight.empty_state_constraint`): no transition can exist."""
    why = empty_state_constraint(decomp, system)
    if why:
        warn(why)
    return bool(why)


def warn_if_disturbance_fits_nowhere(decomp, W) -> int:
    """Warn (stderr and log) when ``P_j ⊖ W`` is empty for every cell: no transition can exist.

    Returns the number of cells ``W`` fits in (:func:`tubejax.model.workspace.validate.disturbance_fits`).
    """
    from tubejax.model.workspace.validate import disturbance_fits

    fits = disturbance_fits(decomp, W)
    n_fit = int(fits.sum())
    if n_fit == 0:
        msg = (f"the disturbance W fits in no cell (P_j shrunk by W, the Pontryagin difference, is empty for all "
               f"{decomp.n_cells} cells): no transition can exist; make W smaller or the cells larger")
        print(f"warning: {msg}", file=sys.stderr)
        log.warning("%s", msg)
    elif n_fit < decomp.n_cells:
        log.info("W fits in %d of %d cells; no transition can end in the others", n_fit, decomp.n_cells)
    return n_fit


def check_config_files(argv: list[str] | None = None) -> None:
    """Refuse a YAML error or a duplicate key in a config file before Hydra reads it.

    OmegaConf refuses duplicate keys too, but Hydra reports that with a traceback; this
    prints one line naming the file, the line and the key, and exits with code 2. Checks
    ``conf/`` and every ``--config-dir``/``-cd``/``--config-path``/``-cp`` in ``argv``.
    """
    args = sys.argv[1:] if argv is None else list(argv)
    dirs = [PROJECT_ROOT / "conf"]
    for k, a in enumerate(args):
        for flag in ("--config-dir", "-cd", "--config-path", "-cp"):
            if a == flag and k + 1 < len(args):
                dirs.append(Path(args[k + 1]))
            elif a.startswith(flag + "="):
                dirs.append(Path(a.split("=", 1)[1]))
    for d in dirs:
        for f in sorted(d.expanduser().rglob("*.yaml")) if d.expanduser().is_dir() else []:
            try:
                load_yaml_strict(decode_utf8(read_bytes(f, "config file", ConfigError), str(f), ConfigError),
                                 str(f), ConfigError)
            except ConfigError as exc:
                print(f"error: {exc}", file=sys.stderr)
                sys.exit(2)
    if argv is None:
        try:
            check_overrides(args, APP_CONFIGS.get(Path(sys.argv[0]).stem), check_keys, _APP_SCRIPTS)
        except InputError as exc:
            print(f"error: {exc}", file=sys.stderr)
            sys.exit(2)


def compilation_cache_dir(directory, key: str = "solver.compilation_cache") -> Path | None:
    """:func:`tubejax.abstraction.methods.compilation_cache_dir`, its error a :class:`ConfigError`."""
    from tubejax.abstraction.methods import compilation_cache_dir as checked_dir
    try:
        return checked_dir(directory, key)
    except InputError as exc:
        raise ConfigError(str(exc)) from None


def enable_compilation_cache(directory) -> None:
    """:func:`tubejax.abstraction.methods.enable_compilation_cache`, its error a :class:`ConfigError`."""
    from tubejax.abstraction.methods import enable_compilation_cache as enable
    try:
        enable(directory)
    except InputError as exc:
        raise ConfigError(str(exc)) from None


def write_json(path: Path, data) -> None:
    """Write JSON atomically (a temporary file, then rename), with the output's provenance.

    A dict gets the package version, git commit and dirtiness, and command line of this run
    (:func:`tubejax.transitions.provenance.stamp`): as one ``"provenance"`` object, or, for
    ``metrics.json`` (one flat row of a sweep's table), as the columns ``tubejax_version``,
    ``git_commit``, ``git_dirty`` and ``command``. A non-finite float (the ``mean_L`` of a run
    without edges) is written as ``null``, as in every other file tubejax writes: bare ``NaN`` is
    not JSON (docs/reference/formats.md#metricsjson).
    """
    path = Path(path)
    tmp = path.with_suffix(path.suffix + ".tmp")
    body = _finite_or_null(stamp(data, flat=path.name == "metrics.json"))
    tmp.write_text(json.dumps(body, indent=1, allow_nan=False))
    tmp.replace(path)


def _finite_or_null(value):
    """``value`` with every non-finite float (in dicts, lists and tuples) replaced by ``None``."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite_or_null(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite_or_null(v) for v in value]
    return value
