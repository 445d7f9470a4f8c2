"""The inputs record against the run's own config (part of :mod:`tubejax.verify.verifier`'s cheap checks).

Every edge is proved against the problem the inputs record states, and a record with ``W`` shrunk,
``U`` enlarged or ``min_margin`` lowered states an easier problem, so the record is compared field by
field with every copy of the run's config that travels with it (``stats.config`` and
``.hydra/config.yaml``, read as the apps do). :func:`describe_problem` words the problem the edges
were proved for, so a reader sees what ``OK`` means.
"""

from __future__ import annotations

import math
from pathlib import Path

import pydantic

from ..errors import InputError
from ..files import load_yaml_strict
from ..inputs import Disturbance, SystemModel, validate_section
from ..inputs.problem_inputs import app_problem_dict
from ..inputs.values import StrictModel
from .rho import RADIUS_MARK

__all__ = ["HYDRA_CONFIG", "check_run_configs", "describe_problem"]

#: Hydra's copy of a run's config, relative to the run directory.
HYDRA_CONFIG = Path(".hydra") / "config.yaml"
#: The abstraction settings that define the problem or its claims (not how the run was executed).
_ABSTRACTION_KEYS = ("L_max", "eps_min", "min_margin", "pruning", "method")


class _Dynamics(StrictModel):
    system: SystemModel
    disturbance: Disturbance


def _norm(x):
    """``x`` with numbers as floats (bools kept), for comparing a YAML or JSON copy with the record."""
    if isinstance(x, bool) or x is None or isinstance(x, str):
        return x
    if isinstance(x, (int, float)):
        return float(x)
    if isinstance(x, dict):
        return {str(k): _norm(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_norm(v) for v in x]
    return x


def _size(d: dict):
    return d.get("radius", d.get("half_width"))


def _configs(directory: Path, doc, stem: str) -> list[tuple[str, object]]:
    """``(name, config or an error string)`` of every copy of the run's config found."""
    out = []
    cfg = doc.stats.get("config") if isinstance(doc.stats, dict) else None
    if cfg is not None:
        out.append((f"{stem}.json stats.config", cfg))
    if stem != "transitions":
        return out
    radius = isinstance(doc.stats, dict) and doc.stats.get(RADIUS_MARK)
    for d in (directory, directory.parent) if radius else (directory,):
        path = d / HYDRA_CONFIG
        if path.is_file():
            try:
                out.append((str(path), load_yaml_strict(path.read_text(encoding="utf-8"), str(path))))
            except (OSError, UnicodeDecodeError, InputError) as exc:
                out.append((str(path), f"cannot read it ({str(exc).splitlines()[0]})"))
            break
    return out


def _compare(name: str, cfg, inputs, radius_file: bool) -> list[str]:
    """Findings where the config ``cfg`` (an app's config as plain containers) and the record differ."""
    if not isinstance(cfg, dict):
        return [f"{name}: {cfg}" if isinstance(cfg, str) else
                f"{name}: expected a mapping (the run's config), got {type(cfg).__name__}"]
    p = app_problem_dict(cfg)
    rec = inputs.model_dump(mode="json")
    out = []

    def differ(key, said, record):
        out.append(f"{name}: {key} is {said!r}, but the inputs record says {record!r} (the edges are proved for the "
                   "record's problem, not the one the run was configured with)")

    if "system" in p and "disturbance" in p:
        try:
            dyn = validate_section(_Dynamics, {"system": p["system"], "disturbance": p["disturbance"]})
        except InputError as exc:
            return [f"{name}: its system or disturbance cannot be read ({str(exc).splitlines()[0]})"]
        said_sys, rec_sys = dyn.system.model_dump(mode="json"), rec["system"]
        for key in ("A", "B", "U", "X"):
            if _norm(said_sys.get(key)) != _norm(rec_sys.get(key)):
                differ(f"system.{key}", said_sys.get(key), rec_sys.get(key))
        said_w, rec_w = dyn.disturbance.model_dump(mode="json"), rec["disturbance"]
        if not radius_file:
            if _norm(said_w) != _norm(rec_w):
                differ("disturbance", said_w, rec_w)
        elif said_w.get("kind") != rec_w.get("kind"):
            differ("disturbance.kind", said_w.get("kind"), rec_w.get("kind"))
        elif said_w.get("kind") != "polytope":          # one system per radius: one of the config's
            radii = [_norm(r) for r in cfg.get("radii") or [] if isinstance(r, (int, float))]
            if _norm(_size(rec_w)) not in radii + [_norm(_size(said_w))]:
                differ("disturbance (its size, one of radii or its own)", {**said_w, "radii": radii}, rec_w)
    z = p.get("zshape")
    if isinstance(z, dict):
        for key in ("kind", "scale"):
            if key in z and _norm(z[key]) != _norm(rec["zshape"].get(key, 1.0 if key == "scale" else None)):
                differ(f"zshape.{key}", z[key], rec["zshape"].get(key))
    w = p.get("workspace")
    if isinstance(w, dict):
        for key, said in w.items():
            record = rec["workspace"].get(key)
            if isinstance(record, dict) and "path" in record:           # a file: as the user named it
                record = record["path"]
            if key in rec["workspace"] and _norm(said) != _norm(record):
                differ(f"workspace.{key}", said, record)
    a, ra = p.get("abstraction", {}), rec["abstraction"]
    for key in _ABSTRACTION_KEYS:
        if key in a and _norm(a[key]) != _norm(ra.get(key)):
            differ(key if key != "method" else "method.name", a[key], ra.get(key))
    s = a.get("solver")
    if isinstance(s, dict) and "name" in s and s["name"] != ra["solver"]["name"]:
        differ("solver.name", s["name"], ra["solver"]["name"])
    return out


def check_run_configs(directory, doc, rb, stem: str = "transitions") -> tuple[list[str], str]:
    """Compare the inputs record of ``doc`` (rebuilt as ``rb``) with the run's saved configs.

    Returns
    -------
    findings : list of str
        One line per field where a saved config and the record differ (naming the copy).
    note : str
        Which copies agree, or that there was none to compare with.
    """
    if rb.inputs is None:
        return [], ""
    found = _configs(Path(directory), doc, stem)
    if not found:
        return [], ("no saved run config to compare the inputs record with (no stats.config, no .hydra/config.yaml):"
                    " the problem is the one the record states")
    radius_file = bool(isinstance(doc.stats, dict) and doc.stats.get(RADIUS_MARK))
    findings = []
    for name, cfg in found:
        try:
            findings += _compare(name, cfg, rb.inputs, radius_file)
        except (pydantic.ValidationError, TypeError, KeyError, AttributeError) as exc:
            findings.append(f"{name}: cannot be compared with the inputs record ({type(exc).__name__}: "
                            f"{str(exc).splitlines()[0]})")
    names = " and ".join(Path(n).name if n.endswith(".yaml") else n for n, _ in found)
    names = names.replace("config.yaml", ".hydra/config.yaml")
    return findings, f"the inputs record agrees with the run's config ({names})" if not findings else ""


def _num(x) -> str:
    return f"{x:g}" if isinstance(x, float) and math.isfinite(x) else str(x)


def _set(d: dict) -> str:
    kind = d.get("kind")
    if kind == "polytope":
        return f"polytope of {len(d.get('vertices', []))} vertices"
    vals = {k: v for k, v in d.items() if k != "kind"}
    return f"{kind} " + ", ".join(f"{k} {_num(v) if not isinstance(v, list) else v}" for k, v in vals.items())


def describe_problem(rb) -> str:
    """The problem the edges were proved for, in one line (``''`` without an inputs record)."""
    if rb.inputs is None:
        return ""
    rec = rb.inputs.model_dump(mode="json")
    s = rec["system"]
    name = f" ({s['name']})" if s.get("name") else ""
    X = "" if s.get("X") is None else f"; X of {len(s['X']['H'])} rows"
    return (f"W {_set(rec['disturbance'])}; U {_set(s['U'])}; A, B as recorded{name}{X}; Z {rec['zshape']['kind']} "
            f"scale {_num(rec['zshape']['scale'])}; min_margin {_num(rb.min_margin)}; eps_min {_num(rb.eps_min)}")
