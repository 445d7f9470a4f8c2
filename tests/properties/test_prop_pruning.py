"""Property: pruning is sound (issue 11, item 6; :mod:`tubejax.abstraction.pruning`).

For random small systems and decompositions (1-D to 3-D, HiGHS only, so no compile):

* every ``(i, j, L)`` that :func:`build_candidates` drops is infeasible for HiGHS, in the tube LP
  and in the open-loop LP (both methods use the same pruning);
* an abstraction with pruning has exactly the edges and horizons of one without, and every
  edge passes :func:`property_cases.check_edge`.
"""

from functools import partial
import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from hypothesis import event, given, strategies as st  # noqa: E402

from property_cases import case_strategy, check_edge, note_case, property_settings  # noqa: E402
from tubejax.abstraction import build_abstraction  # noqa: E402
from tubejax.lp.evidence.verdict import highs_verdict  # noqa: E402
from tubejax.lp.evidence.verdict import highs_solver  # noqa: E402
from tubejax.model.zshape.kinds import make_z  # noqa: E402
from tubejax.model.problem import pair_problem  # noqa: E402
from tubejax.abstraction.candidates import build_candidates  # noqa: E402

openloop_solve_batch = highs_solver("openloop")
openloop_highs_verdict = partial(highs_verdict, form="openloop")

KINDS = ("box1", "box2", "box3", "tri")
L_MAX = 3


def _edges(ts) -> list:
    return sorted((e.src, e.dst, e.L) for e in ts.edges)


@pytest.mark.parametrize("kind", KINDS)
@property_settings(4)
@given(data=st.data())
def test_pruning_drops_only_infeasible_horizons(kind, data):
    case = data.draw(case_strategy(kind), label="case")
    d, sysm = case.decomp, case.system
    cand = build_candidates(d, sysm, L_MAX)
    counts = cand.pruned
    N = d.n_cells
    keep = np.zeros((N, N, L_MAX), dtype=bool)         # dense here: the cases are small
    keep[cand.src, cand.dst] = cand.keep
    off_diag = ~np.eye(N, dtype=bool)[:, :, None]
    assert int((~keep & off_diag).sum()) == sum(counts.values())
    Z = [make_z(case.zshape, c, case.z_scale) for c in d.cells]
    for i, j, l in np.argwhere(~keep & off_diag):
        p = pair_problem(d, sysm, Z[i], int(i), int(j), int(l) + 1, case.eps_min)
        for verdict in (highs_verdict, openloop_highs_verdict):
            v = verdict(p)
            assert v.status != "edge", f"pruned (i, j, L) = ({i}, {j}, {l + 1}) is a {verdict.__name__} edge"

    kw = dict(zshape=case.zshape, z_scale=case.z_scale, L_max=L_MAX, eps_min=case.eps_min,
              progress=False)
    full = build_abstraction(d, sysm, pruning=False, **kw)
    pruned = build_abstraction(d, sysm, pruning=True, **kw)
    assert _edges(pruned) == _edges(full)
    assert pruned.stats["n_lps"] + pruned.stats["n_pruned"] >= full.stats["n_lps"]
    for k in range(pruned.n_edges):
        check_edge(pruned, k)
    note_case(case, pruned)
    event("some pruned" if counts and sum(counts.values()) else "none pruned")
