"""Export the controller of a plan as dependency-free code: C99 (libm only) and a NumPy-only module.

:func:`export_controller` writes the files of docs/howto/export.md#what-is-written: the C
(:mod:`~tubejax.analyses.control.export_c`), the runtime :mod:`~tubejax.analyses.control.export_runtime`
verbatim with its ``.npz`` data and ``.json`` description, and a ``README.md``.

The plan is a :class:`Lasso` (a prefix of transitions, then an optional repeating cycle). Each
transition's data is Algorithm 1's closed form (docs/math/control.md): the step's set as unit facet
rows, a fixed triangulation as barycentric maps ``beta[:n] = T_s (y - r_s)``, and the vertex inputs.
Each set and each transition is stored once however often it is used.

Flat tables (``F`` facets, ``S`` simplices, ``K`` sets, ``E`` transitions, ``P`` tube steps,
``V`` vertex-input rows; offsets index the flat tables):

``facet_H (F, n)``, ``facet_h (F,)``; ``simp_T (S, n, n)``, ``simp_r (S, n)``, ``simp_v (S, n + 1)``
(vertex ids within the set); ``set_facets (K, 2)``, ``set_simplices (K, 2)`` (offset, count),
``set_nv (K,)``; ``transitions (E, 5)``: start set, ``Z`` set, ``L``, offset into ``p``/``eps``, offset
into ``u``; ``p (P, n)``, ``eps (P,)`` (``Q_l = p_l + eps_l Z`` for ``l = 1..L``), ``inv_eps (P,)``
(``1 / eps``, 0 for a point tube); ``u (V, m)`` (per transition: the source points' inputs, then
``L - 1`` blocks of ``Z``'s); ``sequence`` (the prefix, then the cycle: transition ids);
``plan = (n_prefix, repeats, empty_set)`` (``repeats``: cycle runs, ``-1`` forever, 0 without cycle);
``set_box (K,)`` (1: multilinear weights), ``box (K, 2, n)`` (lower and upper corner),
``box_vertex (K, 2^n)`` (vertex id of corner ``c``; bit ``i`` set: upper bound in coordinate ``i``).

``weights=``: ``'triangulation'`` (the library's controller) or ``'multilinear'`` on box sets
(docs/howto/export.md#weights).
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ...errors import InputError
from ...model.geometry import Ball, Polytope
from ...model.zshape.kinds import source_points
from . import export_runtime
from .controller import _scaled_inverse, _tri_cached, require_tubes
from .export_c import c_sources
from .export_readme import readme_text
from .planner import Plan

__all__ = ["Lasso", "plan_lasso", "controller_data", "export_controller", "box_corners", "LANGUAGES", "WEIGHTS",
           "STEM", "TOL"]

#: What :func:`export_controller` can write.
LANGUAGES = ("c", "python")
#: How the step's weights are computed (module docstring).
WEIGHTS = ("triangulation", "multilinear")
#: File stem of every exported file.
STEM = "tubejax_controller"
#: Default membership tolerance of the exported controller (a distance: the facet rows are unit).
TOL = 1e-9


class Lasso(NamedTuple):
    """A plan as transitions: ``prefix``, then ``cycle`` ``repeats`` times (``-1``: forever).

    prefix, cycle : tuple of int
        Edge indices into ``ts.edges``; consecutive edges connect, and the cycle closes.
    repeats : int
        0 when ``cycle`` is empty, else ``>= 1`` or ``-1``.
    start_cell : int
        The cell the plan starts in.
    """

    prefix: tuple
    cycle: tuple
    repeats: int
    start_cell: int


def _patrol_cycle(plan, stats) -> tuple:
    """``(n_prefix, cycle)`` of a patrol plan (the prefix, then the cycle ``stats['cycles']`` times)."""
    edges = [int(k) for k in plan.edges]
    n_pre, times = int(plan.segment_ends[0]), int(stats["cycles"])
    n_c, rest = divmod(len(edges) - n_pre, times)
    cycle = edges[n_pre:n_pre + n_c]
    if rest or not n_c or edges[n_pre:] != cycle * times:
        raise InputError(f"plan: a patrol plan whose edges after the prefix ({n_pre}) are not its cycle "
                         f"repeated {times} times")
    return n_pre, cycle


def plan_lasso(ts, plan, cycles: int | None = None) -> Lasso:
    """The :class:`Lasso` of a plan.

    Parameters
    ----------
    ts : TransitionSystem
    plan : Plan, SpecPlan or Lasso
        A sequence or LTLf formula plan (a prefix only), a patrol or an LTL plan (``tj.plan(ts,
        ltl=...)``: its prefix and its cycle, whatever turns of the cycle ``plan.plan`` holds), or a
        lasso.
    cycles : int, optional
        How often a patrol's or an LTL plan's cycle runs: ``None`` (default) forever, else an
        integer ``>= 1``.

    Raises
    ------
    InputError
        A bad ``cycles``, or transitions that do not connect.
    """
    if cycles is not None and (isinstance(cycles, bool) or not isinstance(cycles, (int, np.integer)) or cycles < 1):
        raise InputError(f"cycles: expected None (forever) or an integer >= 1, got {cycles!r}")
    if isinstance(plan, Lasso):
        lasso = plan
    else:
        kind = getattr(plan, "kind", None)
        cells_plan = getattr(plan, "plan", plan)
        if not isinstance(cells_plan, Plan):
            raise InputError(f"plan: expected a plan from tj.plan (or a Plan, or a Lasso), got {type(plan).__name__}")
        start = int(cells_plan.cells[0])
        repeats = -1 if cycles is None else int(cycles)
        if kind == "ltl":
            info = getattr(plan, "lasso", None) or {}
            if "prefix_edges" not in info or not info.get("cycle_edges"):
                raise InputError("plan: an LTL plan without its lasso (prefix_edges, cycle_edges): "
                                 "plan it with tj.plan(ts, ltl=...)")
            lasso = Lasso(tuple(int(k) for k in info["prefix_edges"]), tuple(int(k) for k in info["cycle_edges"]),
                          repeats, start)
        elif kind == "patrol":
            n_pre, cycle = _patrol_cycle(cells_plan, plan.stats)
            lasso = Lasso(tuple(int(k) for k in cells_plan.edges[:n_pre]), tuple(cycle), repeats, start)
        else:
            lasso = Lasso(tuple(int(k) for k in cells_plan.edges), (), 0, start)
    _check_lasso(ts, lasso)
    return lasso


def _check_lasso(ts, lasso: Lasso) -> None:
    seq = list(lasso.prefix) + list(lasso.cycle)
    bad = [k for k in seq if isinstance(k, bool) or not 0 <= int(k) < ts.n_edges]
    if bad:
        raise InputError(f"plan: edge {bad[0]!r} is not an edge index of the system (0..{ts.n_edges - 1})")
    if not 0 <= int(lasso.start_cell) < ts.n_cells:
        raise InputError(f"plan: start cell {lasso.start_cell!r} is not a cell id (0..{ts.n_cells - 1})")
    if bool(lasso.cycle) != (lasso.repeats != 0) or lasso.repeats < -1:
        raise InputError(f"plan: repeats must be 0 without a cycle and -1 or >= 1 with one, got {lasso.repeats}")
    at = int(lasso.start_cell)
    for pos, k in enumerate(seq + list(lasso.cycle[:1])):
        e = ts.edges[int(k)]
        if int(e.src) != at:
            where = "the cycle does not close" if pos == len(seq) else f"transition {pos} (edge {k})"
            raise InputError(f"plan: {where}: edge {k} leaves cell {e.src}, the plan is in cell {at}")
        at = int(e.dst)
    require_tubes(ts, seq)


def box_corners(points: np.ndarray):
    """``(lo (n,), hi (n,), vertex (2^n,))`` when ``points (2^n, n)`` are exactly the corners of an
    axis-aligned box with ``lo < hi`` (``vertex[c]``: the point at corner ``c``, bit ``i`` of ``c`` set
    for ``hi_i``), else ``None``."""
    P = np.asarray(points, float)
    n = P.shape[1]
    lo, hi = P.min(0), P.max(0)
    if len(P) != 2 ** n or not np.all(lo < hi):
        return None
    up = P == hi
    if not np.all(up | (P == lo)):
        return None
    code = up.astype(np.int64) @ (1 << np.arange(n))
    if len(set(code.tolist())) != len(P):
        return None
    vertex = np.empty(len(P), np.int32)
    vertex[code] = np.arange(len(P))
    return lo, hi, vertex


class _Tables:
    """Collects the flat tables; each set (a source cell per vertex count, a ``Z``) once."""

    def __init__(self, n: int, m: int, multilinear: bool):
        self.n, self.m, self.multilinear = n, m, multilinear
        self.H, self.h, self.T, self.r, self.v = [], [], [], [], []
        self.sets, self.keys, self.boxes = [], {}, []
        self.F = self.S = 0

    def add_set(self, key, H, h, points) -> int:
        if key in self.keys:
            return self.keys[key]
        norms = np.linalg.norm(H, axis=1)
        tri = _tri_cached(points)
        self.H.append(H / norms[:, None]); self.h.append(h / norms)
        self.T.append(tri.T); self.r.append(tri.r); self.v.append(tri.simplices)
        self.boxes.append(box_corners(points) if self.multilinear else None)
        self.sets.append((self.F, len(h), self.S, len(tri.simplices), len(points)))
        self.F += len(h); self.S += len(tri.simplices)
        self.keys[key] = len(self.sets) - 1
        return self.keys[key]


def controller_data(ts, lasso: Lasso, tol: float = TOL, weights: str = "triangulation") -> dict:
    """The flat tables of the exported controller (module docstring), float64 / int32 arrays."""
    if not (isinstance(tol, (int, float)) and not isinstance(tol, bool) and 0 <= tol < 1):
        raise InputError(f"tol: expected a number in [0, 1), got {tol!r}")
    if weights not in WEIGHTS:
        raise InputError(f"weights: expected one of {list(WEIGHTS)}, got {weights!r}")
    n, m = ts.system.n, ts.system.m
    tab = _Tables(n, m, weights == "multilinear")
    cells = ts.decomposition.cells
    seq = list(lasso.prefix) + list(lasso.cycle)
    order = list(dict.fromkeys(int(k) for k in seq))
    index = {k: i for i, k in enumerate(order)}
    trs, ps, epss, invs, us, info = [], [], [], [], [], []
    P_off = U_off = 0
    for k in order:
        e, tube = ts.edges[k], ts.tubes[k]
        Z = ts.z_of(e.src, e.dst)
        P = cells[e.src]
        pts = source_points(P, Z.n_vertices)
        s0 = tab.add_set(("cell", int(e.src), Z.n_vertices), P.H, P.h, pts.vertices)
        sz = tab.add_set(("Z", Z.vertices.tobytes(), Z.vertices.shape), Z.H, Z.h, Z.vertices)
        p, eps, u = (np.asarray(a, float) for a in tube)
        L = int(e.L)
        inv = np.array([_scaled_inverse(np.ones(1), float(ep))[0] for ep in eps])
        trs.append((s0, sz, L, P_off, U_off)); info.append((k, int(e.src), int(e.dst), L))
        ps.append(p); epss.append(eps); invs.append(inv)
        us.append(u[0][:len(pts.vertices)])
        us += [u[l][:Z.n_vertices] for l in range(1, L)]
        P_off += L
        U_off += len(pts.vertices) + (L - 1) * Z.n_vertices
    start = int(lasso.start_cell)
    P0 = cells[start]
    empty = tab.add_set(("cell", start, P0.n_vertices), P0.H, P0.h, P0.vertices) if not seq else -1
    off = np.array([s[:2] for s in tab.sets], np.int32).reshape(-1, 2)
    soff = np.array([s[2:4] for s in tab.sets], np.int32).reshape(-1, 2)
    boxes = [b or (np.zeros(n), np.zeros(n), np.zeros(2 ** n, np.int32)) for b in tab.boxes]
    f64 = lambda parts, shape: (np.concatenate(parts).astype(np.float64) if parts  # noqa: E731
                                else np.zeros((0,) + shape))
    return dict(
        dims=np.array([n, m], np.int32), tol=np.array([float(tol)]),
        facet_H=f64(tab.H, (n,)), facet_h=f64(tab.h, ()),
        simp_T=f64(tab.T, (n, n)), simp_r=f64(tab.r, (n,)),
        simp_v=np.concatenate(tab.v).astype(np.int32) if tab.v else np.zeros((0, n + 1), np.int32),
        set_facets=off, set_simplices=soff, set_nv=np.array([s[4] for s in tab.sets], np.int32),
        set_box=np.array([b is not None for b in tab.boxes], np.int32),
        box=np.array([np.stack(b[:2]) for b in boxes], float).reshape(-1, 2, n),
        box_vertex=np.array([b[2] for b in boxes], np.int32).reshape(-1, 2 ** n),
        transitions=np.array(trs, np.int32).reshape(-1, 5), p=f64(ps, (n,)), eps=f64(epss, ()),
        inv_eps=f64(invs, ()), u=f64(us, (m,)),
        sequence=np.array([index[int(k)] for k in seq], np.int32),
        plan=np.array([len(lasso.prefix), int(lasso.repeats), empty], np.int32),
        transition_info=np.array(info, np.int32).reshape(-1, 4))


def _w_text(W) -> dict:
    if isinstance(W, Ball):
        return {"kind": "ball", "radius": float(W.radius), "norm": "euclidean"}
    if isinstance(W, Polytope):
        return {"kind": "polytope", "vertices": np.asarray(W.vertices, float).tolist(),
                "H": np.asarray(W.H, float).tolist(), "h": np.asarray(W.h, float).tolist()}
    return {"kind": type(W).__name__}


def description(ts, lasso: Lasso, data: dict, spec: str | None = None, weights: str = "triangulation") -> dict:
    """The JSON description of the exported data (what each array is, the plan, the model)."""
    sysm = ts.system
    start = ts.decomposition.cells[int(lasso.start_cell)]
    shapes = {k: list(v.shape) for k, v in data.items()}
    info = data["transition_info"]
    return {
        "format": "tubejax-controller", "version": 1,
        "n": int(sysm.n), "m": int(sysm.m), "tol": float(data["tol"][0]), "weights": weights,
        "model": {"A": np.asarray(sysm.A, float).tolist(), "B": np.asarray(sysm.B, float).tolist(),
                  "U": {"H": np.asarray(sysm.U.H, float).tolist(), "h": np.asarray(sysm.U.h, float).tolist()},
                  "W": _w_text(sysm.W)},
        "plan": {"start_cell": int(lasso.start_cell),
                 "start_cell_H": np.asarray(start.H, float).tolist(),
                 "start_cell_h": np.asarray(start.h, float).tolist(),
                 "prefix_edges": [int(k) for k in lasso.prefix],
                 "cycle_edges": [int(k) for k in lasso.cycle], "repeats": int(lasso.repeats),
                 "steps_prefix": int(sum(ts.edges[int(k)].L for k in lasso.prefix)),
                 "steps_cycle": int(sum(ts.edges[int(k)].L for k in lasso.cycle)),
                 "spec": spec},
        "transitions": [{"edge": int(k), "src": int(s), "dst": int(d), "L": int(L)} for k, s, d, L in info],
        "status": {"in_tube": export_runtime.IN_TUBE, "advanced": export_runtime.ADVANCED,
                   "finished": export_runtime.FINISHED, "outside": export_runtime.OUTSIDE},
        "arrays": shapes,
        "layout": __doc__[__doc__.index("Flat tables"):].strip(),
    }


def export_controller(ts, plan, directory, languages=LANGUAGES, cycles: int | None = None,
                      tol: float = TOL, weights: str = "triangulation") -> list:
    """Write the controller of ``plan`` as C99 and/or NumPy-only Python into ``directory``.

    Parameters
    ----------
    ts : TransitionSystem
        A system of method ``'tube'`` (its edges store the tubes).
    plan : Plan, SpecPlan or Lasso
        See :func:`plan_lasso`.
    directory : str or Path
        Created if missing; the exported files are overwritten.
    languages : sequence of {'c', 'python'}
    cycles : int, optional
        A patrol's or an LTL plan's cycle runs forever (``None``) or this many times.
    tol : float
        Membership tolerance of every check (a distance).
    weights : {'triangulation', 'multilinear'}
        The library's triangulation weights everywhere, or multilinear weights on box sets.

    Returns
    -------
    list of Path
        The files written (README, data description, sources).

    Raises
    ------
    InputError
        An unknown language, a bad plan, ``cycles`` or ``tol``, or a system without tubes.
    """
    langs = [languages] if isinstance(languages, str) else list(languages)
    unknown = [l for l in langs if l not in LANGUAGES]
    if unknown or not langs:
        raise InputError(f"languages: expected some of {list(LANGUAGES)}, got {languages!r}")
    lasso = plan_lasso(ts, plan, cycles)
    data = controller_data(ts, lasso, tol, weights)
    spec = getattr(plan, "spec", None)
    if getattr(plan, "kind", None) == "patrol" and isinstance(spec, str):      # the repeats are the export's
        spec = re.sub(r" x\d+(?=,|$)", "", spec)
    desc = description(ts, lasso, data, spec, weights)
    out = Path(directory)
    if out.exists() and not out.is_dir():
        raise InputError(f"directory: {out} exists and is not a directory")
    out.mkdir(parents=True, exist_ok=True)
    files = [out / "README.md", out / f"{STEM}.json"]
    files[0].write_text(readme_text(desc, langs))
    files[1].write_text(json.dumps(desc, indent=1) + "\n")
    if "python" in langs:
        np.savez(out / f"{STEM}.npz", **data)
        shutil.copyfile(export_runtime.__file__, out / f"{STEM}.py")
        files += [out / f"{STEM}.npz", out / f"{STEM}.py"]
    if "c" in langs:
        for name, text in c_sources(data, weights).items():
            (out / name).write_text(text)
            files.append(out / name)
    return files
