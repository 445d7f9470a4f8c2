"""Prove a saved transition system from its sources: ``python -m tubejax verify DIR``.

A transitions file is never trusted. :func:`verify_directory` runs the checks of
docs/howto/verify.md#what-it-checks: strict reading, the problem rebuilt from the inputs record and
every copied datum compared (:mod:`tubejax.verify.rebuild_sources`), the files' other claims
(:func:`check_run`; :func:`load_checked` refuses all it finds), every edge re-checked, and with
``complete=True`` every non-edge settled up to ``L_max``. Every problem is one line; nothing raises;
nothing relies on ``metrics.json``. Without ``complete`` the report says completeness was not
checked (:attr:`VerifyReport.headline`).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..errors import InputError
from ..reachability.reference_solvers import reference_verdict
from ..lp.evidence import prove_evidence
from ..lp.evidence.safe_set import prove_safe_set
from ..lp.evidence.verdict import evidence_margin
from ..lp.evidence.registry import FORMULATIONS, formulation
from ..lp.evidence.verdict import TRANSLATE_EDGE, TRANSLATED_PROOF, VERIFY_TOL
from .rho import check_rho_star, check_rho_star_complete
from ..transitions.file_format import TransitionFile, TransitionFileError, read_transition_files
from ..transitions.product_file import PRODUCT_STEM, is_product_run
from ..transitions.reading import system_from_document
from ..transitions.transition_system import TransitionSystem
from .claims import check_metrics, check_shard, compatible
from .run_config import check_run_configs, describe_problem
from .completeness import check_complete
from .product_run import verify_product_run
from .rebuild_sources import Rebuilt, check_sources, rebuild

__all__ = ["Rebuilt", "VerifyReport", "RunCheck", "check_sources", "check_edges", "check_run", "load_checked",
           "load_with_sources", "verify_directory", "rebuild", "provenances", "MARGIN_TOL"]

#: Provenances of the batched PDHG solver's verdicts (its own, HiGHS's where it fell back or confirmed).
_PDHG_PROVENANCES = frozenset({"pdhg+highs", "highs-fallback", TRANSLATE_EDGE, "highs"})


def provenances(method: str, solver: str) -> frozenset:
    """The provenances ``method`` with ``solver`` (``'highs'`` or ``'pdhg'``) can give, read from its record:
    its own (HiGHS's, or the exact computation's), and with PDHG those of the batched solver, plus
    :data:`TRANSLATED_PROOF` where its PDHG form proves exact translates. Empty for an unknown pair."""
    form = FORMULATIONS.get(method)
    if form is None or solver not in ("highs", "pdhg"):
        return frozenset()
    if solver == "highs" or not form.solves_lp:
        return frozenset({form.provenance})
    translates = form.pdhg is not None and form.pdhg.translates
    return _PDHG_PROVENANCES | ({TRANSLATED_PROOF} if translates else set())
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
    notes : tuple of str       what else was and was not checked (the problem, config, ``metrics.json``)
    exact : bool               whether the exact proofs were re-proved
    scope : str                what an OK report establishes, where not :attr:`headline`'s (a product run)
    """

    findings: list
    n_edges: int
    proof_counts: dict
    complete: bool
    n_resolved: int
    seconds: float
    summary: str
    notes: tuple = ()
    exact: bool = True
    scope: str = ""

    @property
    def ok(self) -> bool:
        return not self.findings

    @property
    def headline(self) -> str:
        """What an OK report establishes, in words: the edges proved, and whether completeness was checked."""
        if self.scope:
            return self.scope
        proved = "edges proved" if self.exact else "edges proved (exact proofs not re-proved: --no-exact)"
        if self.complete:
            return f"{proved}; complete (every non-edge up to L_max settled)"
        return f"{proved}; completeness not checked (run --complete)"


def _check_edge(ts, k: int, rb: Rebuilt, exact: bool, prob) -> tuple[list[str], str | None]:
    """Findings for edge ``k`` of ``ts`` (whose problem data is the rebuilt one; ``prob`` the edge's
    problem from that data, :meth:`TransitionSystem.problems`), and its proof level."""
    e = ts.edges[k]
    where = f"edges[{k}] {e.src}->{e.dst} (L={e.L})"
    if not formulation(rb.method).solves_lp:
        ok = reference_verdict(rb.method)(prob).status == "edge"
        return ([] if ok else [f"{where}: not a transition (exact polygon computation)"]), None
    out = []
    evidence = ts.tubes[k]
    if evidence is None:
        return [f"{where}: no evidence stored (method {rb.method!r} stores a tube or plan per edge)"], None
    v = ts.violation(k, prob)
    if not v <= VERIFY_TOL:
        out.append(f"{where}: the stored evidence violates Problem 2 by {v:.3e} (> {VERIFY_TOL:g})")
        return out, None
    # the margin min(g - G x) the evidence achieves, rows scaled as the file's (pre-format-3: per LP unit)
    m = evidence_margin(formulation(rb.method).build(prob, scaling=ts.margin_scaling), evidence)
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
    ``ts`` must hold the problem data to check against (as :meth:`TransitionSystem.load` gives it)."""
    a = ts.inputs.get("abstraction", {}) if isinstance(ts.inputs, dict) else {}
    rb = Rebuilt(None, ts.decomposition, ts.system, ts.Z, ts.eps_min, ts.method,
                 int(a.get("L_max", max([e.L for e in ts.edges], default=1))), "", ts.min_margin)
    out = []
    for k, prob in ts.problems(sorted(set(int(k) for k in edges))):
        out += _check_edge(ts, k, rb, exact=True, prob=prob)[0]
    return out


def _check_edge_list(doc: TransitionFile, rb: Rebuilt) -> list[str]:
    out, seen = [], set()
    allowed = provenances(rb.method, rb.solver)
    for k, e in enumerate(doc.edges):
        where = f"edges[{k}] {e.src}->{e.dst} (L={e.L})"       # self-pairs: refused when read
        if (e.src, e.dst) in seen:
            out.append(f"{where}: a second edge for the same pair")
        seen.add((e.src, e.dst))
        if e.L > rb.L_max:
            out.append(f"{where}: L above L_max = {rb.L_max}")
        if e.provenance not in allowed:
            out.append(f"{where}: provenance {e.provenance!r} is not one that method {rb.method!r} with solver "
                       f"{rb.solver!r} gives ({', '.join(sorted(allowed))})")
    return out


class RunCheck(NamedTuple):
    """What :func:`check_run` found.

    Attributes
    ----------
    ts : TransitionSystem or None   the file's system; with ``rb``, holding the REBUILT problem data
    doc : TransitionFile or None    the validated json (None: the files could not be read)
    rb : Rebuilt or None            the rebuilt problem (None: the edges cannot be checked)
    findings : list of str          one line per problem
    summary : str                   what the file was checked against
    notes : tuple of str            what else was compared (the run's config, ``metrics.json``) or was absent
    """

    ts: object
    doc: TransitionFile | None
    rb: Rebuilt | None
    findings: list
    summary: str
    notes: tuple = ()


def check_run(directory, stem: str = "transitions", trust_file_data: bool = False) -> RunCheck:
    """The cheap part of verification (steps 1 and 2 of the module docstring): no LP, no proof.

    ``trust_file_data``: check a file without an inputs record against its own copied data
    (self-consistency only) instead of refusing it.
    """
    directory = Path(directory)
    try:
        doc, arrays = read_transition_files(directory, stem)
        ts = system_from_document(TransitionSystem, doc, arrays, directory / f"{stem}.npz")
    except (TransitionFileError, InputError) as exc:
        return RunCheck(None, None, None, [str(exc)], "")
    if doc.inputs is None and trust_file_data:
        L_max = int(doc.stats.get("L_max", max([e.L for e in doc.edges], default=1)))
        solver = str(doc.stats.get("solver", "highs"))
        rb = Rebuilt(None, ts.decomposition, ts.system, ts.Z, ts.eps_min, ts.method, L_max, solver,
                     ts.min_margin)
        findings = []
        summary = "against the data copied into the file (no inputs record: self-consistency only)"
    else:
        findings, rb = check_sources(ts, doc, arrays, directory)
        if rb is None:
            return RunCheck(ts, doc, None, findings, "")
        why = compatible(doc, rb)
        if why:
            return RunCheck(ts, doc, None, findings + [f"edges: {why}"], "")
        summary = (f"against its sources ({_describe_sources(rb.inputs.workspace)}, method {rb.method}, "
                   f"L_max {rb.L_max})")
    findings += _check_edge_list(doc, rb)
    findings += check_shard(doc, rb)
    notes = [f"for the problem its inputs record states: {describe_problem(rb)}"] if rb.inputs is not None else []
    more, note = check_run_configs(directory, doc, rb, stem)
    findings += more
    notes += [note] if note else []
    if stem == "transitions":                 # metrics.json is the row of the run's transitions files
        more, note = check_metrics(directory, doc, rb)
        findings += more
        notes += [note] if note else []
    ts.decomposition, ts.system, ts.Z, ts.eps_min, ts.method = rb.decomposition, rb.system, rb.Z, rb.eps_min, rb.method
    ts.min_margin = rb.min_margin
    findings += check_rho_star(ts)
    return RunCheck(ts, doc, rb, findings, summary, tuple(notes))


def load_checked(directory, stem: str = "transitions"):
    """A saved system for use (the simulator's loader), holding the problem data rebuilt from its
    sources: anything :func:`check_run` finds (a missing inputs record too) raises a
    ``TransitionFileError`` with the first finding and how many more there are. The edges' evidence
    is not re-checked here: re-check the edges a plan uses with :func:`check_edges`.
    """
    directory = Path(directory)
    chk = check_run(directory, stem)
    if chk.findings:
        first = chk.findings[0]
        if not first.startswith(str(directory)):
            first = f"{directory / (stem + '.json')}: {first}"
        more = (f" (and {len(chk.findings) - 1} more; python -m tubejax verify {directory} lists them)"
                if len(chk.findings) > 1 else "")
        raise TransitionFileError(first + more)
    return chk.ts


def load_with_sources(directory, stem: str = "transitions", prove: bool = False):
    """A saved system holding the decomposition and system REBUILT from its recorded sources, every
    copied datum checked (:func:`check_sources`); a file without an inputs record loads as it is.

    A ``TransitionFileError`` names the file and field of a missing, damaged or inconsistent file, or
    of copied data that differ from the sources.
    """
    directory = Path(directory)
    doc, arr = read_transition_files(directory, stem)
    ts = system_from_document(TransitionSystem, doc, arr, directory / f"{stem}.npz")
    if doc.inputs is not None:
        findings, rebuilt = check_sources(ts, doc, arr, directory)
        if findings:
            more = f" (and {len(findings) - 1} more; run python -m tubejax verify)" if len(findings) > 1 else ""
            raise TransitionFileError(f"{directory / (stem + '.json')}: {findings[0]}{more}")
        ts.decomposition, ts.system = rebuilt.decomposition, rebuilt.system
    if prove:
        ts.prove()
    return ts


def verify_directory(directory, stem: str = "transitions", complete: bool = False, exact: bool = True,
                     progress: bool = False, trust_file_data: bool = False, sample: int = 50) -> VerifyReport:
    """Verify ``directory/<stem>.json|.npz`` against its sources (see the module docstring); a product
    run goes to :func:`tubejax.verify.product_run.verify_product_run` (``sample``: its joint LPs re-solved).

    Parameters
    ----------
    complete : bool
        Also settle every non-edge (finds deleted edges; up to one HiGHS solve per unpruned instance).
    exact : bool
        Re-prove the edges that claim an exact proof (rational arithmetic).
    trust_file_data : bool
        For a file without an inputs record: check the edges against the data copied into the
        file (self-consistency only) instead of refusing.

    Returns
    -------
    VerifyReport
    """
    t0 = time.perf_counter()
    directory = Path(directory)
    if stem == PRODUCT_STEM or (not (directory / f"{stem}.json").exists() and is_product_run(directory)):
        r = verify_product_run(directory, complete=complete, exact=exact, sample=sample)
        return VerifyReport(r.findings, r.n_edges, r.proof_counts, complete, r.n_resolved, r.seconds, r.summary,
                            r.notes, exact, r.scope)

    def report(findings, n_edges=0, counts=None, n_res=0, summary="", notes=()):
        return VerifyReport(findings, n_edges, counts or {}, complete, n_res, time.perf_counter() - t0, summary,
                            tuple(notes), exact)

    chk = check_run(directory, stem, trust_file_data)
    if chk.rb is None:                        # unreadable, not rebuilt, or cells that are not the sources'
        return report(chk.findings, len(chk.doc.edges) if chk.doc is not None else 0)
    ts, rb, findings, summary = chk.ts, chk.rb, list(chk.findings), chk.summary
    levels = []
    for k, prob in ts.problems():             # built vectorised, a chunk of edges at a time
        f, level = _check_edge(ts, k, rb, exact, prob)
        findings += f
        levels.append(level)
    counts = {"exact": levels.count("exact"), "float": levels.count("float"), "unknown": levels.count(None)}
    n_rho = sum(e.rho_star is not None for e in ts.edges)
    n_res = 0
    if complete and not any(f.startswith("inputs:") for f in findings):
        more, n_res, n_rech = check_complete(ts, rb, progress)
        findings += more
        summary += f"; {n_rech} non-edges settled by their recorded evidence, {n_res} re-solved with HiGHS"
        more, n_lps = check_rho_star_complete(ts, rb.L_max)
        findings += more
        if n_rho:
            summary += f"; rho_star of {n_rho} edges re-solved with HiGHS ({n_lps} radius LPs)"
    elif n_rho:
        summary += f"; rho_star of {n_rho} edges checked"
    return report(findings, ts.n_edges, counts, n_res, summary, chk.notes)


def _describe_sources(src) -> str:
    for name in ("map_file", "file"):
        f = getattr(src, name, None)
        if f is not None:
            return f"{f.resolved} sha256 {f.sha256[:12]}..."
    return f"{getattr(src, 'kind', 'workspace')} workspace"
