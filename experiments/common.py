"""Config -> typed library objects, shared by the Hydra apps in this folder.

This is the only place that reads config objects; everything in ``tubejax/``
takes typed arguments.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np

from tubejax.geometry import Ball, Polytope
from tubejax.system import LinearSystem, SystemError_, box_input_set, one_norm_input_set

PROJECT_ROOT = Path(__file__).resolve().parents[1]
log = logging.getLogger("tubejax")


class ConfigError(ValueError):
    """A config value is missing or malformed; the message names the field."""


def resolve_path(path: str, field: str) -> Path:
    """A user path: absolute, relative to the launch directory, or relative to the project root."""
    from hydra.utils import get_original_cwd

    p = Path(str(path))
    if p.is_absolute():
        cands = [p]
    else:
        try:
            cwd = Path(get_original_cwd())
        except ValueError:
            cwd = Path.cwd()
        cands = [cwd / p, PROJECT_ROOT / p]
    for c in cands:
        if c.exists():
            return c
    raise ConfigError(f"{field}: file {path!r} not found (looked in {', '.join(map(str, cands))})")


def _matrix(value, field: str) -> np.ndarray:
    try:
        M = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ConfigError(f"{field}: expected a matrix of numbers, got {value!r}") from None
    return M


def build_system(cfg) -> LinearSystem:
    """``cfg.system`` and ``cfg.disturbance`` -> :class:`LinearSystem`."""
    A = _matrix(cfg.system.A, "system.A")
    B = _matrix(cfg.system.B, "system.B")
    m = B.shape[1] if B.ndim == 2 else 1
    u = cfg.system.U
    try:
        if u.kind == "box":
            U = box_input_set(u.bound, m)
        elif u.kind == "one_norm":
            U = one_norm_input_set(float(u.radius), m)
        elif u.kind == "polytope":
            U = Polytope.from_vertices(np.array(u.vertices, dtype=float))
        else:
            raise ConfigError(f"system.U.kind: expected box, one_norm or polytope, got {u.kind!r}")
        W = build_disturbance(cfg.disturbance, A.shape[0])
        return LinearSystem(A, B, U, W)
    except SystemError_ as exc:
        raise ConfigError(f"system/disturbance config: {exc}") from None


def build_disturbance(d, n: int):
    """``cfg.disturbance`` -> a :class:`Ball` or :class:`Polytope` in ``R^n``."""
    if d.kind == "ball":
        r = float(d.radius)
        if r < 0:
            raise ConfigError(f"disturbance.radius: must be >= 0, got {r}")
        return Ball(n, r)
    if d.kind == "box":
        hw = float(d.half_width)
        if hw <= 0:
            raise ConfigError(f"disturbance.half_width: must be > 0, got {hw}")
        return Polytope.box(-hw * np.ones(n), hw * np.ones(n))
    if d.kind == "polytope":
        return Polytope.from_vertices(np.array(d.vertices, dtype=float))
    raise ConfigError(f"disturbance.kind: expected ball, box or polytope, got {d.kind!r}")


def build_workspace(w):
    """``cfg.workspace`` -> :class:`tubejax.workspace.CellDecomposition`."""
    from tubejax import workspace as ws

    if w.kind == "grid":
        return ws.load_grid_map(resolve_path(w.map_file, "workspace.map_file"))
    if w.kind == "polygon":
        return ws.load_polygon_workspace(resolve_path(w.file, "workspace.file"))
    if w.kind == "boxgrid":
        obstacles = [(np.array(o[0], float), np.array(o[1], float)) for o in (w.get("obstacles") or [])]
        labels = {str(k): (np.array(v[0], float), np.array(v[1], float))
                  for k, v in (w.get("labels") or {}).items()}
        return ws.box_grid(list(w.lower), list(w.upper), list(w.divisions), obstacles=obstacles,
                           labels=labels, name=str(w.get("name", "box grid")))
    raise ConfigError(f"workspace.kind: expected grid, polygon or boxgrid, got {w.kind!r}")


def check_L_max(value) -> int:
    try:
        L = int(value)
    except (TypeError, ValueError):
        raise ConfigError(f"L_max: expected an integer >= 1, got {value!r}") from None
    if L < 1 or L != value:
        raise ConfigError(f"L_max: expected an integer >= 1, got {value!r}")
    return L


def enable_compilation_cache(directory) -> None:
    """JAX's persistent compilation cache (a second run skips most compiling); ``None``/empty: off."""
    if not directory:
        return
    import jax

    path = Path(str(directory)).expanduser()
    path.mkdir(parents=True, exist_ok=True)
    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)


def write_json(path: Path, data) -> None:
    """Write JSON atomically (a temporary file, then rename)."""
    path = Path(path)
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(data, indent=1))
    tmp.replace(path)
