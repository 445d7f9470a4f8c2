"""Abstraction cases whose transition systems were recorded with the reference code.

``tests/data/reference_edges.json`` holds, per case, the edges ``(src, dst, L)`` computed by
the all-pairs algorithm of commit 1dd90d5 (run ``tests/data/make_reference_edges.py`` with a
checkout of that commit on ``PYTHONPATH``). The current code must give the identical system.

A case is a dict: ``workspace`` (``('grid', map name)``, ``('polygon', file)`` or
``('boxgrid4d', divisions)``), ``system`` (a ``conf/system`` name), ``radius`` (of the ball
``W``), ``zshape``, ``L_max``, ``pruning`` and ``solver`` (``'highs'`` or ``'pdhg'``, the latter
built as ``experiments/abstract.py`` builds it from ``conf/solver/pdhg.yaml``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

CONF = Path(__file__).resolve().parents[1] / "conf"

_GRID2D = dict(system="integrator2d", radius=0.2, zshape="box", L_max=10, solver="highs")
_DI = dict(system="double_integrator", radius=0.02, zshape="cell", L_max=8, solver="highs")

CASES = {}
for _m in ("tiny", "corridor", "open", "maze"):
    for _p in (True, False):
        CASES[f"{_m}-{'pruned' if _p else 'unpruned'}"] = dict(_GRID2D, workspace=("grid", _m), pruning=_p)
CASES["paper-pdhg-pruned"] = dict(_GRID2D, workspace=("grid", "paper"), pruning=True, solver="pdhg")
for _p in (True, False):
    _s = "pruned" if _p else "unpruned"
    CASES[f"corridor-l1-{_s}"] = dict(_GRID2D, workspace=("grid", "corridor"), system="integrator2d_l1",
                                      radius=0.1, pruning=_p)
    CASES[f"open-sheared-{_s}"] = dict(_GRID2D, workspace=("grid", "open"), system="sheared",
                                       radius=0.1, L_max=6, pruning=_p)
    CASES[f"rooms-{_s}"] = dict(_GRID2D, workspace=("polygon", "rooms.yaml"), zshape="regular",
                                radius=0.05, L_max=6, pruning=_p)
    CASES[f"boxgrid4d-{_s}"] = dict(_DI, workspace=("boxgrid4d", [2, 2, 2, 2]), pruning=_p)
    CASES[f"boxgrid4d-3232-{_s}"] = dict(_DI, workspace=("boxgrid4d", [3, 2, 3, 2]), pruning=_p)


def case_system(case):
    """The :class:`~tubejax.model.system.LinearSystem` of a case."""
    from tubejax.model.geometry import Ball
    from tubejax.model.system import LinearSystem, box_input_set, one_norm_input_set

    if case["system"] == "sheared":                     # a non-identity A in 2-D
        A, B, U = np.array([[1.0, 0.1], [0.0, 1.0]]), 0.5 * np.eye(2), box_input_set(1.0, 2)
    else:
        cfg = yaml.safe_load((CONF / "system" / f"{case['system']}.yaml").read_text())
        A, B = np.array(cfg["A"], float), np.array(cfg["B"], float)
        u = cfg["U"]
        U = box_input_set(u["bound"], B.shape[1]) if u["kind"] == "box" else one_norm_input_set(u["radius"], B.shape[1])
    return LinearSystem(A=A, B=B, U=U, W=Ball(A.shape[0], case["radius"]))


def case_workspace(case):
    """The :class:`~tubejax.model.workspace.CellDecomposition` of a case."""
    from tubejax.model.workspace import box_grid, load_grid_map, load_polygon_workspace

    kind, arg = case["workspace"]
    if kind == "grid":
        return load_grid_map(CONF / "workspace" / "maps" / f"{arg}.txt")
    if kind == "polygon":
        return load_polygon_workspace(CONF / "workspace" / "maps" / arg)
    ws = yaml.safe_load((CONF / "workspace" / "boxgrid4d.yaml").read_text())
    labels = {k: tuple(v) for k, v in ws["labels"].items()} if list(arg) == ws["divisions"] else None
    return box_grid(ws["lower"], ws["upper"], list(arg), obstacles=[tuple(o) for o in ws["obstacles"]],
                    labels=labels)


def case_solver(case):
    """The batch solver of a case (a fresh :class:`PdhgBatchSolver` for ``'pdhg'``)."""
    if case["solver"] == "highs":
        from tubejax.lp.evidence.verdict import highs_solve_batch
        return highs_solve_batch
    from tubejax.lp.batch.batch_solver import PdhgBatchSolver
    opts = yaml.safe_load((CONF / "solver" / "pdhg.yaml").read_text())
    opts = {k: v for k, v in opts.items() if k not in ("name", "compilation_cache")}
    return PdhgBatchSolver(**opts)


def run_case(case):
    """Build the transition system of a case."""
    from tubejax.abstraction import build_abstraction

    return build_abstraction(case_workspace(case), case_system(case), zshape=case["zshape"],
                             L_max=case["L_max"], pruning=case["pruning"], solve_batch=case_solver(case),
                             progress=False)
