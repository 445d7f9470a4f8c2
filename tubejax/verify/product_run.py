"""Verify a saved product system: ``python -m tubejax verify DIR`` on a product run (docs/math/product.md#trust).

:func:`verify_product_run` runs the steps of docs/howto/verify.md#a-product-run: strict reading, the
problem and its product structure rebuilt from the inputs record, every factor verdict, joint tube
and the join re-checked (:func:`~tubejax.verify.product_check.verify_product`), and with
``complete`` every factor LP re-solved after the sound pruning and ``sample`` full pairs as one
joint LP. Every problem becomes one line; nothing raises.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..abstraction.product_factors import SAFE_VARIANTS, solve_factor
from ..abstraction.product_join import join_factors, shard_weights
from ..abstraction.shards import source_range
from ..abstraction.product_store import load_product
from ..errors import InputError
from ..lp.evidence.verdict import highs_solve_batch
from ..transitions.product_file import PRODUCT_STEM
from .product_check import verify_product

__all__ = ["ProductRunReport", "verify_product_run", "check_factor_tables", "shard_sources"]


class ProductRunReport(NamedTuple):
    """What :func:`verify_product_run` found (:func:`tubejax.verify.verifier.verify_directory` makes it a
    :class:`~tubejax.verify.verifier.VerifyReport`): ``findings`` (empty: verified), ``n_edges``,
    ``proof_counts`` (of the factor verdicts the edges rely on), ``n_resolved`` (factor LPs re-solved),
    ``seconds``, ``summary``, ``notes`` and ``scope`` (what an OK report establishes)."""

    findings: list
    n_edges: int
    proof_counts: dict
    n_resolved: int
    seconds: float
    summary: str
    notes: tuple
    scope: str


def check_factor_tables(ps) -> tuple[list[str], int]:
    """Solve every factor LP of ``ps`` again with HiGHS; a feasible one the system lacks is a finding.

    Returns
    -------
    (list of str, int)
        The findings and the number of factor LPs solved.
    """
    out, n = [], 0
    for g, (f, t) in enumerate(zip(ps.structure.factors, ps.tables)):
        again = solve_factor(f, g, ps.L_max, highs_solve_batch, ps.eps_min, progress=False, pruning=True,
                             by_class=False)
        n += again.n_lps
        missing = np.argwhere(again.feasible & ~t.feasible)
        for v, L1, a, b in missing[:20].tolist():
            out.append(f"group {g} factor pair {a}->{b} (L={L1 + 1}, safe set {SAFE_VARIANTS[v]}): HiGHS finds it "
                       "feasible, but the file has no verdict for it (the factor table is incomplete)")
        if len(missing) > 20:
            out.append(f"group {g}: {len(missing) - 20} more feasible factor LPs missing from the file")
    return out, n


def shard_sources(jpath: Path, ps) -> tuple:
    """``((count, index, start, stop), findings)`` of a shard's product file (``None`` for an unsharded run):
    the source range recomputed from its inputs record's ``abstraction.shard``, its factor tables and the
    join of every cell (:func:`~tubejax.abstraction.shards.source_range` over
    :func:`~tubejax.abstraction.product_join.shard_weights`); an edge whose source lies outside it is a finding."""
    try:
        rec = json.loads(Path(jpath).read_text()).get("inputs") or {}
        count, index = (int(rec["abstraction"]["shard"][k]) for k in ("count", "index"))
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None, []
    if count <= 1:
        return None, []
    everything = join_factors(ps.decomposition, ps.structure, ps.tables)
    start, stop = source_range(shard_weights(ps.structure, ps.tables, everything.joint_src), count, index)
    bad = np.flatnonzero((ps.src < start) | (ps.src >= stop))
    return (count, index, start, stop), [
        f"inputs.abstraction.shard: the file claims shard {index} of {count}, whose source cells are "
        f"{start}..{stop - 1}, but {len(bad)} of its {ps.n_edges} edges leave other cells (e.g. edge "
        f"{ps.src[bad[0]]}->{ps.dst[bad[0]]})"] if len(bad) else []


def verify_product_run(directory, stem: str = PRODUCT_STEM, complete: bool = False, exact: bool = True,
                       sample: int = 50, seed: int = 0) -> ProductRunReport:
    """Verify ``directory/<stem>.json|.npz`` (see the module docstring).

    Parameters
    ----------
    complete : bool
        Also re-solve every factor LP and ``sample`` full pairs with HiGHS.
    exact : bool
        Re-prove the factor verdicts that claim an exact proof (rational arithmetic).
    sample : int
        Full pairs re-solved as joint product-family LPs with ``complete``.
    seed : int
        Seed of that sample.

    Returns
    -------
    ProductRunReport
        ``proof_counts`` counts the factor verdicts the edges rely on (``exact``: re-proved exactly).
    """
    t0 = time.perf_counter()
    directory = Path(directory)
    try:
        ps = load_product(directory, stem=stem)
    except InputError as exc:                      # ProductFileError and any source error
        return ProductRunReport([str(exc)], 0, {}, 0, time.perf_counter() - t0, "", (), "")
    shard, findings = shard_sources(directory / f"{stem}.json", ps)
    rep = verify_product(ps, exact=exact, complete=int(sample) if complete else 0, seed=seed,
                         sources=None if shard is None else shard[2:])
    findings += list(rep.problems)
    n_res = 0
    summary = (f"product system of {ps.structure.n_groups} groups ({ps.structure.describe()}) against its sources; "
               f"{rep.n_factor_checked} factor verdicts re-checked, the join recomputed"
               + ("" if shard is None else f" for shard {shard[1]} of {shard[0]}'s source cells "
                                           f"{shard[2]}..{shard[3] - 1}"))
    if complete:
        more, n_res = check_factor_tables(ps)
        findings += more
        summary += (f"; {n_res} factor LPs re-solved with HiGHS, {rep.n_sampled} full pairs re-solved as joint "
                    f"product-family LPs ({rep.n_sample_close} too close to call)")
    counts = {"exact": rep.n_factor_exact, "float": rep.n_factor_checked - rep.n_factor_exact}
    headline = ("edges proved by their factor verdicts; the join complete for the factor tables"
                + ("; every factor LP re-solved (factor tables complete), a sample of full pairs re-solved"
                   if complete else "; factor tables' completeness not checked (run --complete)"))
    notes = (f"{int(np.sum(ps.variant == 2))} edges proved by joint LPs (blocked bounding boxes)",)
    return ProductRunReport(findings, ps.n_edges, counts, n_res, time.perf_counter() - t0, summary, notes, headline)
