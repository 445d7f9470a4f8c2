"""Prove a saved transition system from its sources: ``python -m tubejax verify DIR``.

A transitions file is never trusted. :func:`verify_directory`

1. reads both files strictly (format names and versions, the npz hash recorded in the json,
   every field, exactly one piece of evidence per edge: :mod:`tubejax.transition_files`);
2. **rebuilds** the problem from the inputs record (workspace files by path and SHA-256, the
   system, ``W``, ``U``, ``Z`` -- a learned one from the run's ``learned_z.json``, its SHA-256
   checked against the record's --, ``eps_min``, the method: :class:`~tubejax.inputs.ProblemInputs`)
   and checks that every datum copied into the file (cells, labels, obstacles, ``A``, ``B``,
   ``U``, ``W``, ``Z`` and each edge's own ``Z``, ``eps_min``, method) equals the rebuilt one
   (:func:`check_sources`, :mod:`tubejax.verify_sources`: the cheap part, which
   :meth:`TransitionSystem.load` runs by default);
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

from .errors import InputError
from .lp.evidence.verdict import TRANSLATE_EDGE, VERIFY_TOL
from .problem import pair_problem
from .transition_files import TransitionFile, TransitionFileError, read_transition_files
from .verify_sources import Rebuilt, check_sources, rebuild
from .zassignment import z_of_pair

__all__ = ["Rebuilt", "VerifyReport", "check_sources", "check_edges", "verify_directory", "rebuild",
           "PROVENANCES", "MARGIN_TOL"]

#: Provenances each (method, solver) can give.
PROVENANCES = {
    ("tube", "highs"): {"highs"},
    ("tube", "pdhg"): {"pdhg+highs", "highs-fallback", TRANSLATE_EDGE, "highs"},
    ("openloop", "highs"): {"openloop-highs"},
    ("openloop", "pdhg"): {"pdhg+highs", "highs-fallback", TRANSLATE_EDGE, "highs"},
    ("exact2d", "highs"): {"exact2d"},
    ("exact2d", "pdhg"): {"exact2d"},
}
#: Largest difference between a claimed margin and the margin its stored evidence achieves.
MARGIN_TOL = 1e-7


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


# ------------------------------------------------------------------ step 3: the edges
def _stored_margin(prob, evidence, method: str) -> float:
    """The margin ``min(g - G x)`` the evidence achieves in the margin form (capped at ``t_max``)."""
    if method == "tube":
        from .lp.formulations.tube.dense import build_tube_lp as build
    else:
        from .lp.formulations.openloop.dense import build_openloop_lp as build
    from .lp.evidence.verdict import evidence_margin
    return evidence_margin(build(prob), evidence)


def _check_edge(ts, k: int, rb: Rebuilt, exact: bool, prob) -> tuple[list[str], str | None]:
    """Findings for edge ``k`` of ``ts`` (whose problem data is the rebuilt one; ``prob`` the edge's
    problem from that data, :meth:`TransitionSystem.problems`), and its proof level."""
    from .lp.evidence import prove_evidence
    from .lp.evidence.safe_set import prove_safe_set

    e = ts.edges[k]
    where = f"edges[{k}] {e.src}->{e.dst} (L={e.L})"
    if rb.method == "exact2d":
        from .exact2d import exact2d_verdict
        ok = exact2d_verdict(prob).status == "edge"
        return ([] if ok else [f"{where}: not a transition (exact polygon computation)"]), None
    out = []
    evidence = ts.tubes[k]
    if evidence is None:
        return [f"{where}: no evidence stored (method {rb.method!r} stores a tube or plan per edge)"], None
    v = ts.violation(k, prob)
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
    for k, prob in ts.problems(sorted(set(int(k) for k in edges))):
        out += _check_edge(ts, k, rb, exact=True, prob=prob)[0]
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
    from .transition_reading import system_from_document
    from .transitions import TransitionSystem

    t0 = time.perf_counter()
    directory = Path(directory)

    def report(findings, n_edges=0, counts=None, n_res=0, summary=""):
        return VerifyReport(findings, n_edges, counts or {}, complete, n_res, time.perf_counter() - t0, summary)

    try:
        doc, arrays = read_transition_files(directory, stem)
        ts = system_from_document(TransitionSystem, doc, arrays, directory / f"{stem}.npz")
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
    for k, prob in ts.problems():             # built vectorised, a chunk of edges at a time
        f, level = _check_edge(ts, k, rb, exact, prob)
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
