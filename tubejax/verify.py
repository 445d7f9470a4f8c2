"""Prove a saved transition system from its sources: ``python -m tubejax verify DIR``.

A transitions file is never trusted. :func:`verify_directory`

1. reads both files strictly (format names and versions, the npz hash recorded in the json,
   every field, exactly one piece of evidence per edge: :mod:`tubejax.transition_files`);
2. **rebuilds** the problem from the inputs record (workspace files by path and SHA-256, the
   system, ``W``, ``U``, ``Z`` -- a learned one from the run's ``learned_z.json``, its SHA-256
   checked against the record's --, ``eps_min``, the method: :class:`~tubejax.inputs.ProblemInputs`)
   and checks that every datum copied into the file (cells, labels, obstacles, ``A``, ``B``,
   ``U``, ``W``, ``Z`` and each edge's own ``Z``, ``eps_min``, method) equals the rebuilt one
   (:func:`check_sources`: the cheap part, which :meth:`TransitionSystem.load` runs by default);
3. re-checks every edge against the REBUILT problem: ids, no self-loop or duplicate, ``L <=
   L_max``, a provenance the recorded solver can give, the stored evidence in float64
   (``<= 1e-9``), the claimed margin against the margin the stored evidence achieves, and the
   exact (rational) proof of every edge claiming ``"proof": "exact"``, and each edge's critical
   disturbance ``rho_star`` where one is given (at least the file's radius, at most the largest
   radius at which ``W`` fits the target: :mod:`tubejax.radius_analysis.verify_rho`);
4. with ``complete=True``, re-solves every (pair, L) that is not an edge, up to ``L_max`` (and
   every ``L`` below an edge's), with HiGHS, so that deleted edges and non-minimal horizons are
   found (instances that :func:`tubejax.candidates.build_candidates` prunes are infeasible by the
   sound conditions of :mod:`tubejax.pruning`), and every ``rho_star`` with HiGHS.

Every problem becomes one line naming the edge or field; nothing raises.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import NamedTuple

import numpy as np
import shapely

from .errors import InputError
from .geometry import Ball, Polytope
from .lp.evidence.verdict import VERIFY_TOL
from .problem import pair_problem
from .transition_files import TransitionFile, TransitionFileError, read_transition_files
from .zassignment import compare_pair_z, z_of_pair

__all__ = ["Rebuilt", "VerifyReport", "check_sources", "check_edges", "verify_directory", "PROVENANCES",
           "MARGIN_TOL"]

#: Provenances each (method, solver) can give.
PROVENANCES = {
    ("tube", "highs"): {"highs"},
    ("tube", "pdhg"): {"pdhg+highs", "highs-fallback", "highs"},
    ("openloop", "highs"): {"openloop-highs"},
    ("openloop", "pdhg"): {"pdhg+highs", "highs-fallback", "highs"},
    ("exact2d", "highs"): {"exact2d"},
    ("exact2d", "pdhg"): {"exact2d"},
}
#: Largest difference between a claimed margin and the margin its stored evidence achieves.
MARGIN_TOL = 1e-7


class Rebuilt(NamedTuple):
    """The problem rebuilt from an inputs record."""

    inputs: object            # ProblemInputs
    decomposition: object     # CellDecomposition
    system: object            # LinearSystem
    Z: tuple                  # Polytope per cell, or a ZAssignment (per-pair Z)
    eps_min: float
    method: str
    L_max: int
    solver: str
    min_margin: float = 0.0


class VerifyReport(NamedTuple):
    """What :func:`verify_directory` found.

    Attributes
    ----------
    findings : list of str     one line per problem (empty: verified)
    n_edges : int              edges in the file
    proof_counts : dict        ``{'exact': n, 'float': n, 'unknown': n}`` of the edges as re-checked
    complete : bool            whether every non-edge was re-solved
    n_resolved : int           (pair, L) instances re-solved with HiGHS (``complete``)
    seconds : float
    summary : str              what was verified against which sources
    """

    findings: list
    n_edges: int
    proof_counts: dict
    complete: bool
    n_resolved: int
    seconds: float
    summary: str

    @property
    def ok(self) -> bool:
        return not self.findings


# ------------------------------------------------------------------ step 2: the sources
def rebuild(record: dict, directory: Path) -> Rebuilt:
    """The problem of an inputs record (files looked up as recorded, then beside ``directory``).

    Raises
    ------
    InputError
        The record is invalid, a file is missing, or its bytes changed (SHA-256).
    """
    from .inputs import ProblemInputs

    inputs = ProblemInputs.from_record(_run_files_beside(record, directory), search_dirs=[directory])
    decomp = inputs.build_decomposition()
    system = inputs.build_system()
    try:
        Z = inputs.build_cross_sections(decomp)          # a learned Z: its file checked by SHA-256
    except InputError:
        raise
    except ValueError as exc:
        raise InputError(f"zshape: {exc}") from None
    a = inputs.abstraction
    return Rebuilt(inputs, decomp, system, Z, float(a.eps_min), a.method, int(a.L_max), a.solver.name,
                   float(a.min_margin))


def _run_files_beside(record, directory: Path):
    """``record`` with a learned-Z file saved with the run (a bare file name, ``learned_z.json``)
    looked up beside the transitions files first, so a copied or moved run checks its own copy."""
    z = record.get("zshape") if isinstance(record, dict) else None
    f = z.get("file") if isinstance(z, dict) else None
    if not (isinstance(f, dict) and isinstance(f.get("path"), str) and Path(f["path"]).name == f["path"]
            and (directory / f["path"]).is_file()):
        return record
    return {**record, "zshape": {**z, "file": {**f, "resolved": str((directory / f["path"]).resolve())}}}


def _same(a, b) -> bool:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return a.shape == b.shape and bool(np.array_equal(a, b))


def _compare(doc: TransitionFile, arrays: dict, rb: Rebuilt) -> list[str]:
    """Every datum copied into the file that differs from the rebuilt problem."""
    out = []
    d = rb.decomposition
    if doc.method != rb.method:
        out.append(f"method: the file says {doc.method!r}, its inputs record says {rb.method!r}")
    if float(doc.eps_min) != rb.eps_min:
        out.append(f"eps_min: the file says {doc.eps_min!r}, its inputs record says {rb.eps_min!r}")
    if float(doc.min_margin) != rb.min_margin:
        out.append(f"min_margin: the file says {doc.min_margin!r}, its inputs record says {rb.min_margin!r}")
    if len(doc.cells) != d.n_cells:
        out.append(f"cells: the file lists {len(doc.cells)} cells, the workspace has {d.n_cells}")
        return out
    for i, c in enumerate(doc.cells):
        if c.id != i:
            out.append(f"cells[{i}].id: expected {i}, got {c.id}")
        if not _same(c.vertices, d.cells[i].vertices):
            out.append(f"cells[{i}].vertices: differ from cell {i} of the workspace")
        lab = None if c.label is None else str(c.label)
        if lab != d.labels[i]:
            out.append(f"cells[{i}].label: the file says {lab!r}, the workspace says {d.labels[i]!r}")
        if d.grid is not None and (c.grid is None or list(c.grid) != d.grid[i].tolist()):
            out.append(f"cells[{i}].grid: the file says {c.grid!r}, the workspace says {d.grid[i].tolist()}")
        if f"Z_{i}" in arrays and not _same(arrays[f"Z_{i}"], rb.Z[i].vertices):
            out.append(f"Z_{i} (npz): differs from the cross-section {rb.inputs.zshape.kind!r} rebuilt for cell {i}"
                       + _z_source(rb))
    out += compare_pair_z(doc.edges, arrays, rb.Z, _z_source(rb))
    out += _compare_obstacles(doc, d)
    s, sysm = doc.system, rb.system
    for name, a, b in (("A", s.A, sysm.A), ("B", s.B, sysm.B), ("U", s.U.vertices, sysm.U.vertices)):
        if not _same(a, b):
            out.append(f"system.{name}: differs from the inputs record")
    W = sysm.W
    if isinstance(W, Ball):
        if s.W.kind != "ball" or s.W.radius != W.radius or s.W.dim != W.dim:
            out.append(f"system.W: the file says {s.W.model_dump()}, the inputs record gives a ball of radius "
                       f"{W.radius}")
    elif s.W.kind != "polytope" or not _same(s.W.vertices, W.vertices):
        out.append("system.W: differs from the polytope of the inputs record")
    st = doc.stats
    if "n_edges" in st and st["n_edges"] != len(doc.edges):
        out.append(f"stats.n_edges: says {st['n_edges']}, the file lists {len(doc.edges)} edges")
    if "n_cells" in st and st["n_cells"] != d.n_cells:
        out.append(f"stats.n_cells: says {st['n_cells']}, the workspace has {d.n_cells} cells")
    return out


def _z_source(rb: Rebuilt) -> str:
    f = rb.inputs.zshape.file if rb.inputs is not None else None
    return "" if f is None else f" from {f.resolved}"


def _compare_obstacles(doc: TransitionFile, d) -> list[str]:
    if len(doc.obstacles) != len(d.obstacles):
        return [f"obstacles: the file lists {len(doc.obstacles)}, the workspace has {len(d.obstacles)}"]
    out = []
    for k, (o, r) in enumerate(zip(doc.obstacles, d.obstacles)):
        if isinstance(r, Polytope):
            ok = o.kind == "polytope" and _same(Polytope.from_vertices(o.vertices).vertices, r.vertices)
        else:
            try:
                ok = o.kind == "wkt" and bool(shapely.equals(shapely.from_wkt(o.wkt), r))
            except shapely.errors.GEOSException:
                ok = False
        if not ok:
            out.append(f"obstacles[{k}]: differs from obstacle {k} of the workspace")
    return out


def check_sources(ts, doc: TransitionFile, arrays: dict, directory: Path) -> tuple[list[str], Rebuilt | None]:
    """The cheap part of verification: rebuild the problem from ``doc.inputs`` and compare.

    Returns
    -------
    findings : list of str (empty when every copied datum equals the rebuilt one)
    rebuilt : Rebuilt or None (None when the sources could not be rebuilt)
    """
    if doc.inputs is None:
        return ["inputs: the file has no inputs record, so the problem cannot be rebuilt from its sources"], None
    try:
        rb = rebuild(doc.inputs, Path(directory))
    except InputError as exc:
        return [f"inputs: cannot rebuild the problem from the recorded sources: {exc}"], None
    return _compare(doc, arrays, rb), rb


# ------------------------------------------------------------------ step 3: the edges
def _stored_margin(prob, evidence, method: str) -> float:
    """The margin ``min(g - G x)`` the evidence achieves in the margin form (capped at ``t_max``)."""
    if method == "tube":
        from .lp.formulations.tube.dense import build_tube_lp as build
    else:
        from .lp.formulations.openloop.dense import build_openloop_lp as build
    from .lp.evidence.verdict import evidence_margin
    return evidence_margin(build(prob), evidence)


def _check_edge(ts, k: int, rb: Rebuilt, exact: bool) -> tuple[list[str], str | None]:
    """Findings for edge ``k`` of ``ts`` (whose problem data is the rebuilt one), and its proof level."""
    from .lp.evidence import prove_evidence
    from .lp.evidence.safe_set import prove_safe_set

    e = ts.edges[k]
    where = f"edges[{k}] {e.src}->{e.dst} (L={e.L})"
    prob = pair_problem(rb.decomposition, rb.system, z_of_pair(rb.Z, e.src, e.dst), e.src, e.dst, e.L, rb.eps_min,
                        rb.min_margin)
    if rb.method == "exact2d":
        from .exact2d import exact2d_verdict
        ok = exact2d_verdict(prob).status == "edge"
        return ([] if ok else [f"{where}: not a transition (exact polygon computation)"]), None
    out = []
    evidence = ts.tubes[k]
    if evidence is None:
        return [f"{where}: no evidence stored (method {rb.method!r} stores a tube or plan per edge)"], None
    v = ts.violation(k)
    if not v <= VERIFY_TOL:
        out.append(f"{where}: the stored evidence violates Problem 2 by {v:.3e} (> {VERIFY_TOL:g})")
        return out, None
    m = _stored_margin(prob, evidence, rb.method)
    if abs(e.margin - m) > MARGIN_TOL:
        out.append(f"{where}: margin {e.margin!r} claimed, the stored evidence achieves {m:.9g}")
    if not m >= rb.min_margin - VERIFY_TOL:
        out.append(f"{where}: the stored evidence achieves a margin of {m:.9g}, below the required "
                   f"min_margin {rb.min_margin:g}")
    level = e.proof
    if exact and e.proof == "exact":
        ev = e.exact if e.exact is not None else evidence
        if e.exact is not None and any(not np.array_equal(a, b) for a, b in zip(e.exact.to_float(), evidence)):
            out.append(f"{where}: the stored float evidence is not the rounding of the stored rational evidence")
        pr = prove_evidence(prob, ev, resolve=False)
        if pr.level != "exact":
            out.append(f"{where}: claims an exact proof, but {pr.note}")
            level = "float"
        else:
            ok, why = prove_safe_set(prob.safe, rb.decomposition.obstacles)
            if not ok:
                out.append(f"{where}: claims an exact proof, but its safe set is not proven free: {why}")
                level = "float"
    return out, level


def check_edges(ts, edges) -> list[str]:
    """Re-check the evidence of the edges ``edges`` (indices) of a loaded system: float64, the
    claimed margin, and the exact proof where one is claimed (what a simulation relies on).

    ``ts`` must hold the problem data to check against (:meth:`TransitionSystem.load` returns
    the rebuilt problem when the file has an inputs record).
    """
    a = ts.inputs.get("abstraction", {}) if isinstance(ts.inputs, dict) else {}
    rb = Rebuilt(None, ts.decomposition, ts.system, ts.Z, ts.eps_min, ts.method,
                 int(a.get("L_max", max([e.L for e in ts.edges], default=1))), "", ts.min_margin)
    out = []
    for k in sorted(set(int(k) for k in edges)):
        out += _check_edge(ts, k, rb, exact=True)[0]
    return out


def _check_edge_list(doc: TransitionFile, rb: Rebuilt) -> list[str]:
    out, seen = [], set()
    allowed = PROVENANCES.get((rb.method, rb.solver), set())
    for k, e in enumerate(doc.edges):
        where = f"edges[{k}] {e.src}->{e.dst} (L={e.L})"
        if e.src == e.dst:
            out.append(f"{where}: a self-pair is not a transition")
        if (e.src, e.dst) in seen:
            out.append(f"{where}: a second edge for the same pair")
        seen.add((e.src, e.dst))
        if e.L > rb.L_max:
            out.append(f"{where}: L above L_max = {rb.L_max}")
        if e.provenance not in allowed:
            out.append(f"{where}: provenance {e.provenance!r} is not one that method {rb.method!r} with solver "
                       f"{rb.solver!r} gives ({', '.join(sorted(allowed))})")
    return out


# ------------------------------------------------------------------ step 4: completeness
def _check_complete(ts, rb: Rebuilt, progress: bool) -> tuple[list[str], int]:
    """Re-solve every non-edge (pair, L <= L_max) and every L below an edge's with HiGHS."""
    from tqdm.auto import tqdm

    from .candidates import build_candidates

    if rb.method == "exact2d":
        from .exact2d import exact2d_verdict as verdict
    elif rb.method == "openloop":
        from .lp.formulations.openloop.dense import openloop_highs_verdict as verdict
    else:
        from .lp.evidence.verdict import highs_verdict as verdict
    cand = build_candidates(rb.decomposition, rb.system, rb.L_max)      # sound: the rest is infeasible
    shard = rb.inputs.abstraction.shard if rb.inputs is not None else None
    if shard is not None and shard.count > 1:                          # a shard's file: its own sources only
        from .shards import select_shard
        cand = select_shard(cand, rb.decomposition.n_cells, shard.count, shard.index)
    have = {(e.src, e.dst): e.L for e in ts.edges}
    todo = [(int(cand.src[k]), int(cand.dst[k]), L + 1) for k, L in np.argwhere(cand.keep)
            if L + 1 < have.get((int(cand.src[k]), int(cand.dst[k])), rb.L_max + 1)]
    out = []
    for i, j, L in tqdm(todo, desc="verify --complete", unit="LP", disable=not progress, leave=False):
        prob = pair_problem(rb.decomposition, rb.system, z_of_pair(rb.Z, i, j), i, j, L, rb.eps_min, rb.min_margin)
        if verdict(prob).status == "edge":
            if (i, j) in have:
                out.append(f"pair {i}->{j}: a transition exists at L={L}, below the file's L={have[i, j]}")
            else:
                out.append(f"pair {i}->{j}: a transition exists at L={L}, missing from the file")
    return out, len(todo)


# ------------------------------------------------------------------ the whole verification
def verify_directory(directory, stem: str = "transitions", complete: bool = False, exact: bool = True,
                     progress: bool = False, trust_file_data: bool = False) -> VerifyReport:
    """Verify ``directory/<stem>.json|.npz`` against its sources (see the module docstring).

    Parameters
    ----------
    complete : bool
        Also re-solve every non-edge with HiGHS (finds deleted edges; costs one HiGHS solve per
        unpruned non-edge instance).
    exact : bool
        Re-prove the edges that claim an exact proof (rational arithmetic).
    trust_file_data : bool
        For a file without an inputs record: check the edges against the data copied into the
        file (self-consistency only) instead of refusing.

    Returns
    -------
    VerifyReport
    """
    from .transitions import TransitionSystem, _from_document

    t0 = time.perf_counter()
    directory = Path(directory)

    def report(findings, n_edges=0, counts=None, n_res=0, summary=""):
        return VerifyReport(findings, n_edges, counts or {}, complete, n_res, time.perf_counter() - t0, summary)

    try:
        doc, arrays = read_transition_files(directory, stem)
        ts = _from_document(TransitionSystem, doc, arrays, directory / f"{stem}.npz")
    except (TransitionFileError, InputError) as exc:
        return report([str(exc)])
    if doc.inputs is None and trust_file_data:
        from .lp.formulations.zshape import make_z  # noqa: F401  (Z comes from the npz here)
        L_max = int(doc.stats.get("L_max", max([e.L for e in doc.edges], default=1)))
        solver = str(doc.stats.get("solver", "highs"))
        rb = Rebuilt(None, ts.decomposition, ts.system, ts.Z, ts.eps_min, ts.method, L_max, solver,
                     ts.min_margin)
        findings = []
        summary = "against the data copied into the file (no inputs record: self-consistency only)"
    else:
        findings, rb = check_sources(ts, doc, arrays, directory)
        if rb is None:
            return report(findings, len(doc.edges))
        src = rb.inputs.workspace
        summary = f"against its sources ({_describe_sources(src)}, method {rb.method}, L_max {rb.L_max})"
    findings += _check_edge_list(doc, rb)
    ts.decomposition, ts.system, ts.Z, ts.eps_min, ts.method = rb.decomposition, rb.system, rb.Z, rb.eps_min, rb.method
    ts.min_margin = rb.min_margin
    levels = []
    for k in range(ts.n_edges):
        f, level = _check_edge(ts, k, rb, exact)
        findings += f
        levels.append(level)
    counts = {"exact": levels.count("exact"), "float": levels.count("float"), "unknown": levels.count(None)}
    from .radius_analysis.verify_rho import check_rho_star, check_rho_star_complete
    findings += check_rho_star(ts)
    n_rho = sum(e.rho_star is not None for e in ts.edges)
    n_res = 0
    if complete and not any(f.startswith("inputs:") for f in findings):
        more, n_res = _check_complete(ts, rb, progress)
        findings += more
        more, n_lps = check_rho_star_complete(ts, rb.L_max)
        findings += more
        if n_rho:
            summary += f"; rho_star of {n_rho} edges re-solved with HiGHS ({n_lps} radius LPs)"
    elif n_rho:
        summary += f"; rho_star of {n_rho} edges checked"
    return report(findings, ts.n_edges, counts, n_res, summary)


def _describe_sources(src) -> str:
    for name in ("map_file", "file"):
        f = getattr(src, name, None)
        if f is not None:
            return f"{f.resolved} sha256 {f.sha256[:12]}..."
    return f"{getattr(src, 'kind', 'workspace')} workspace"
