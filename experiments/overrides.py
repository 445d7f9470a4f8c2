"""Hydra command lines checked before Hydra runs: overrides it would refuse, refused in one line.

Hydra reports an override of a key the composed config lacks (``figures=maybe`` on
experiments/abstract.py), an unknown group option (``disturbance=boxx``) or a malformed override
with several lines and exit code 1. :func:`check_overrides` composes the app's config as Hydra
will (its own config loader, the same search path) and raises an
:class:`~tubejax.errors.InputError` naming the key or option and the one meant; the apps print
one ``error:`` line and exit with code 2 (``experiments/common.py``, :func:`check_config_files`).

Like ``experiments/common.py`` this reads Hydra; nothing in ``tubejax/`` does.
"""

from __future__ import annotations

import difflib
import re
from pathlib import Path
from typing import Callable

from omegaconf import DictConfig, OmegaConf

from tubejax.errors import InputError

try:                                                 # Hydra's own loader, as hydra.main uses it (1.3)
    from hydra._internal.hydra import Hydra
    from hydra._internal.utils import create_automatic_config_search_path
    from hydra.core.config_search_path import SearchPathQuery
    from hydra.core.global_hydra import GlobalHydra
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.errors import HydraException, MissingConfigException
    from hydra.types import RunMode
except ImportError:                                  # another Hydra: check_overrides leaves every check to it
    Hydra = None

__all__ = ["closest", "unknown_key", "split_args", "check_overrides"]

CONF_DIR = Path(__file__).resolve().parents[1] / "conf"


def closest(name: str, known) -> str | None:
    """The name among ``known`` closest to ``name`` (a typo, another case), or None when none is close."""
    known = [str(k) for k in known]
    close = difflib.get_close_matches(str(name), known, n=1, cutoff=0.6)
    if not close:                                    # a different case: l_max -> L_max
        close = [k for k in known if k.lower() == str(name).lower()][:1]
    return close[0] if close else None


def unknown_key(key: str, known, where: str) -> InputError:
    """The error for ``key`` (a dotted config key), whose last part is not one of ``known`` (the keys of
    ``where``): the key meant when one is close, else the keys there are."""
    parent, _, name = key.rpartition(".")
    near = closest(name, known)
    if near is not None:
        return InputError(f"{key}: unknown key; did you mean {parent + '.' if parent else ''}{near}? "
                           f"({where} has no key {name!r})")
    return InputError(f"{key}: unknown key (the keys of {where}: {', '.join(sorted(map(str, known)))})")




#: Hydra's flags that take a value, and those that do not (others, such as --help or --cfg: no pre-check).
_VALUE_FLAGS = {"--config-dir": "config_dir", "-cd": "config_dir", "--config-name": "config_name",
                "-cn": "config_name", "--config-path": "config_path", "-cp": "config_path"}
_PLAIN_FLAGS = ("-m", "--multirun")


def split_args(args: list[str]):
    """``(overrides, flags)`` of a Hydra command line, or None when it holds a flag not listed above."""
    overrides, flags, k = [], {}, 0
    while k < len(args):
        a = args[k]
        name, eq, value = a.partition("=")
        if a in _PLAIN_FLAGS:
            flags["multirun"] = True
        elif name in _VALUE_FLAGS:
            if not eq:
                if k + 1 >= len(args):
                    return None
                k, value = k + 1, args[k + 1]
            flags[_VALUE_FLAGS[name]] = value
        elif a.startswith("-"):
            return None
        else:
            overrides.append(a)
        k += 1
    return overrides, flags


def check_overrides(args: list[str], config_name: str | None, check_keys: Callable[[dict, str], None],
                    scripts: dict) -> None:
    """Compose the app's config as Hydra will, and refuse what Hydra would refuse, in one line.

    Hydra itself reports an override of a key the config lacks (``figures=maybe`` on
    experiments/abstract.py), an unknown group option (``disturbance=boxx``) or a malformed
    override with several lines and exit code 1; this names the key or option, suggests the
    one meant, and raises an :class:`InputError` (the apps print one ``error:`` line and exit 2).
    It then applies ``check_keys`` to the composed config (``+L_mx=5``). Overrides of
    ``hydra.*`` are Hydra's own and left to it; a sweep (``-m``) is checked at its first value;
    a command line with other Hydra flags (``--help``, ``--cfg``) is not checked, nor is any
    with a Hydra whose internals differ from 1.3's (Hydra then reports as usual).

    Parameters
    ----------
    args : list of str
        The command line after the script.
    config_name : str or None
        The app's primary config (None: nothing is checked).
    check_keys : callable
        ``check_keys(config_dict, config_name)`` raises on a key the app does not read.
    scripts : dict
        Primary config -> the script's name, for the messages.
    """
    split = split_args(args)
    if config_name is None or split is None or Hydra is None:
        return
    overrides, flags = split
    config_name = flags.get("config_name", config_name)
    parser, parsed = OverridesParser.create(), []
    for ov in overrides:
        try:
            parsed += parser.parse_overrides([ov])
        except HydraException as exc:
            why = str(exc).split("\n")[0]
            raise InputError(f"{ov}: not a valid override ({why}; expected key=value, e.g. L_max=6 or "
                              "spec.sequence=[1,3])") from None
    plain = []
    for o in parsed:
        if o.key_or_group.split(".")[0].split("/")[0] == "hydra":
            continue
        if o.is_sweep_override():
            if not flags.get("multirun"):
                raise InputError(f"{o.input_line}: several values given; for a list write "
                                  f"{o.key_or_group}=[...], to sweep over them add --multirun")
            try:
                plain.append(f"{o.get_key_element()}={next(iter(o.sweep_string_iterator()))}")
            except Exception:                        # noqa: BLE001 -- interval or glob sweeps: Hydra's to check
                return
        else:
            plain.append(o.input_line)
    search_path = create_automatic_config_search_path(str(CONF_DIR.parent / "experiments" / "app.py"), None,
                                                      flags.get("config_path", "../conf"))
    if "config_dir" in flags:
        search_path.prepend(provider="command-line", path=f"file://{Path(flags['config_dir']).resolve()}",
                            anchor=SearchPathQuery(provider="schema"))
    GlobalHydra.instance().clear()
    try:
        hydra = Hydra.create_main_hydra2(task_name="check", config_search_path=search_path)

        def compose(ovs):
            return hydra.compose_config(config_name, ovs, run_mode=RunMode.RUN, with_log_configuration=False)

        try:
            cfg = compose(plain)
        except MissingConfigException as exc:
            raise _missing_option(exc) from None
        except HydraException as exc:
            raise _composition_error(exc, plain, compose, scripts.get(config_name, "the config")) from None
        c = OmegaConf.to_container(cfg, resolve=False)
    except InputError:
        raise
    except Exception:                                # noqa: BLE001 -- anything else: Hydra reports it as usual
        return
    finally:
        GlobalHydra.instance().clear()
    check_keys({k: v for k, v in c.items() if k != "hydra"}, config_name)


def _missing_option(exc) -> InputError:
    """``disturbance=boxx``: the group, the option, the one meant, the options there are."""
    group, _, option = str(exc.missing_cfg_file or "").rpartition("/")
    options = list(exc.options or [])
    if not group or not options:
        return InputError(str(exc).split("\n")[0])
    near = closest(option, options)
    hint = f"; did you mean {group}={near}?" if near else ""
    return InputError(f"{group}: no option {option!r}{hint} (the options of {group}: {', '.join(options)})")


def _composition_error(exc, overrides: list[str], compose, where: str) -> InputError:
    """An override of a key the composed config lacks (naming it, the key meant, the keys there are),
    else Hydra's message on one line."""
    cause = exc.__cause__
    key = getattr(cause, "full_key", None)
    if not re.match(r"Could not override '", str(exc)) or "not in struct" not in str(cause) or not key:
        lines = [ln.strip() for ln in f"{exc}\n{cause or ''}".split("\n") if ln.strip()]
        return InputError("; ".join(lines[:3]))
    parent = key.rpartition(".")[0]
    bad = re.match(r"Could not override '([^']+)'", str(exc)).group(1)
    try:                                             # the config without that override: the keys there are
        base = compose([o for o in overrides if o.partition("=")[0] != bad])
    except Exception:                                # noqa: BLE001 -- another override fails too
        base = None
    node = (base if not parent else OmegaConf.select(base, parent)) if base is not None else None
    known = [str(k) for k in node.keys() if k != "hydra"] if isinstance(node, DictConfig) else []
    choice = OmegaConf.select(base, f"hydra.runtime.choices.{parent}") if parent and base is not None else None
    where = (f"{parent}={choice}" if isinstance(choice, str) else parent) if parent else where
    return unknown_key(key, known, where)
