"""Step 4 of :mod:`tubejax.verify.verifier` (``verify --complete``): every non-edge and every
horizon below an edge's, its recorded evidence re-checked or the instance re-solved with HiGHS."""

from __future__ import annotations

import numpy as np
from tqdm.auto import tqdm

from ..abstraction.candidates import build_candidates
from ..abstraction.shards import select_shard
from ..abstraction.translation_classes import TranslationClasses
from ..lp.engines.certify import MARGIN_SAFETY
from ..lp.evidence.decide import certificate_rows, recheck_refutation
from ..lp.evidence.registry import formulation
from ..reachability.reference_solvers import reference_verdict
from ..model.problem import pair_problem
from ..model.zassignment import z_of_pair
from .rebuild_sources import Rebuilt

__all__ = ["check_complete"]


def check_complete(ts, rb: Rebuilt, progress: bool) -> tuple[list[str], int, int]:
    """Every non-edge (pair, L <= L_max) and every L below an edge's: its recorded evidence
    re-checked, or (without one) the instance re-solved with HiGHS.

    A non-edge record is re-checked by its kind: an exact certificate or implied bounds exactly (no
    solve); a translate by its class (the representative an exact translate with its own record at
    the same ``L``); a float64 dual bound by a HiGHS re-solve whose optimum must lie below it. Other
    instances are re-solved; pruned ones re-derived from the pruning rules. A record at or above an
    edge's ``L`` contradicts the edge. Returns (findings, instances re-solved, instances settled by record).
    """
    if rb.min_margin > 0 and ts.margin_scaling != "state":
        return ([f"min_margin {rb.min_margin!r}: this file measures margins per unit of the LP coefficients "
                 f"(format {ts.margin_scaling!r}, before version 3), so which instances reach it cannot be "
                 "re-derived; rerun the abstraction with this tubejax to check completeness"], 0, 0)
    form = formulation(rb.method)
    verdict = reference_verdict(rb.method)
    build = form.build
    cand = build_candidates(rb.decomposition, rb.system, rb.L_max)      # sound: the rest is infeasible
    shard = rb.inputs.abstraction.shard if rb.inputs is not None else None
    if shard is not None and shard.count > 1:                          # a shard's file: its own sources only
        cand = select_shard(cand, rb.decomposition.n_cells, shard.count, shard.index)
    have = {(e.src, e.dst): e.L for e in ts.edges}
    todo = [(int(cand.src[k]), int(cand.dst[k]), L + 1) for k, L in np.argwhere(cand.keep)
            if L + 1 < have.get((int(cand.src[k]), int(cand.dst[k])), rb.L_max + 1)]
    records = ts.nonedges.index() if getattr(ts, "nonedges", None) is not None else {}
    out = [f"non-edge record {i}->{j} at L={L}: the pair has an edge at L={have[i, j]} <= {L}"
           for (i, j, L) in records if (i, j) in have and have[i, j] <= L]
    classes = TranslationClasses(rb.decomposition, rb.system) if form.solves_lp else None
    counts = {"rechecked": 0, "resolved": 0}
    # an exact certificate's row numbers mean the rows of the families the file recorded; with other
    # families (another tubejax's declaration) its records are not read and the instances re-solved
    same_rows = ts.certificate_rows is None or tuple(ts.certificate_rows) == certificate_rows(rb.method, rb.system)

    def prob_of(i, j, L):
        return pair_problem(rb.decomposition, rb.system, z_of_pair(rb.Z, i, j), i, j, L, rb.eps_min, rb.min_margin)

    def translate_holds(i, j, L, ref) -> str:
        rep = records.get((int(ref.certificate[0]), int(ref.certificate[1]), L)) if ref.certificate else None
        if rep is None or rep.kind in ("translate", "none"):
            return "its representative has no refutation of its own at this L"
        a, b = int(ref.certificate[0]), int(ref.certificate[1])
        key = classes.representatives(np.array([a, i]), np.array([b, j]),
                                      rb.decomposition.obstacle_cases(np.array([a, i]), np.array([b, j])),
                                      [prob_of(a, b, L), prob_of(i, j, L)])
        return "" if key[1] == 0 else f"{a}->{b} is not an exact translate of it"

    for i, j, L in tqdm(todo, desc="verify --complete", unit="LP", disable=not progress, leave=False):
        prob = prob_of(i, j, L)
        ref = records.get((i, j, L))
        where = f"pair {i}->{j} at L={L}"
        if ref is not None and ref.kind in ("exact", "bounds") and form.solves_lp and (
                ref.kind == "bounds" or same_rows):
            ok, why = recheck_refutation(prob, build(prob), ref)
            if ok:
                counts["rechecked"] += 1
                continue
            out.append(f"{where}: its recorded {ref.kind} refutation does not hold: {why}")
        elif ref is not None and ref.kind == "translate" and classes is not None:
            why = translate_holds(i, j, L, ref)
            if not why:
                counts["rechecked"] += 1
                continue
            out.append(f"{where}: its recorded translate refutation does not hold: {why}")
        v = verdict(prob)
        counts["resolved"] += 1
        if v.status == "edge":
            if (i, j) in have:
                out.append(f"pair {i}->{j}: a transition exists at L={L}, below the file's L={have[i, j]}")
            else:
                out.append(f"pair {i}->{j}: a transition exists at L={L}, missing from the file")
        elif (ref is not None and ref.kind == "dual" and np.isfinite(v.margin) and v.margin > ref.bound + MARGIN_SAFETY
              and ts.margin_scaling == "state"):              # an older file's bounds are in other units
            out.append(f"{where}: recorded dual bound {ref.bound:.6g} is below HiGHS's optimum {v.margin:.6g}")
    return out, counts["resolved"], counts["rechecked"]
