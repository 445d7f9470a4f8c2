"""A row family added to the tube LP is used by every consumer, or refused by name (issue 46).

The declaration (:data:`~tubejax.lp.declarations.tube_families.TUBE_FAMILIES`) is patched as a
contributor would extend it -- one more family -- and each consumer is held to it: the float LP,
HiGHS, the float and exact checks, the rational rows, the certificate rows, ``verify``; the PDHG
operator, which does not model the family, refuses it by name (the problem goes to HiGHS), and so
do the variable bounds for a family with the ``bound`` role. A set missing from a consumer's data
is an error naming the family, never a family switched off.
"""

import dataclasses
import sys
import types

import numpy as np
import pytest

import tubejax as tj
from tubejax.lp.evidence.check import exact_terms, exact_tube_violation
from tubejax.lp.evidence.decide import certificate_rows
from tubejax.lp.evidence.exact_problem import clear_caches, exact_tube_data
from tubejax.lp.evidence.rows import check_against_float, rational_tube_lp
from tubejax.lp.evidence.verdict import highs_verdict
from tubejax.lp.evidence.registry import FORMULATIONS
from tubejax.lp.declarations.row_families import FamilyDataError, RowFamily
from tubejax.lp.declarations import tube_families
from tubejax.lp.declarations.tube_lp import build_tube_lp, tube_violation
from tubejax.lp.declarations.tube_variables import Tube
from tubejax.lp.declarations.tube_families import TUBE_FAMILIES, TubeVars, float_terms, tube_residuals
from tubejax.lp.declarations.tube_operator_data import build_tube_data, unmodelled_families
from tubejax.lp.evidence.records.tube_record import TUBE_PDHG
from tubejax.verify.verifier import verify_directory

CAP = 1000.0


@dataclasses.dataclass(frozen=True)
class EpsCap(RowFamily):
    """``eps_l <= CAP``: a family no consumer knows by name (never binding on these maps)."""

    name: str = "eps_cap"
    role: str = "hard"
    compress_vertices: bool = False

    def grid(self, d):
        return (d.L,)

    def lp_role(self, d, u_is_box):
        return self.role

    def lhs(self, d, x):
        return x.eps

    def rhs(self, d):
        return d.eps_min * 0 + int(CAP)

    def scale(self, d):
        return d.Z.scale[:1] * 0 + 1

    def normals(self, d):
        return d.Z.H[:1] * 0


def _declare(monkeypatch, extra, method="tube"):
    """Every binding of ``method``'s declaration (the tube LP's or the open-loop LP's) -- module
    globals, default arguments, the method's record -- replaced by one with ``extra`` appended."""
    base = FORMULATIONS[method].families
    new = base + (extra,)
    for mod in list(sys.modules.values()):
        if not (isinstance(mod, types.ModuleType) and mod.__name__.startswith("tubejax")):
            continue
        for name, value in list(vars(mod).items()):
            if value is base:
                monkeypatch.setattr(mod, name, new)
            fn = getattr(value, "__func__", value)
            defaults = getattr(fn, "__defaults__", None)
            if isinstance(fn, types.FunctionType) and defaults and any(d is base for d in defaults):
                monkeypatch.setattr(fn, "__defaults__", tuple(new if d is base else d for d in defaults))
    monkeypatch.setitem(FORMULATIONS, method, FORMULATIONS[method]._replace(families=new))
    clear_caches()
    return new


def _problem(L=3):
    ts = tj.abstract(tj.grid_map("1...\n....\n...2\n"), tj.paper_system(0.1), solver="highs", L_max=L)
    return ts, next(iter(ts.problems()))[1]


def test_a_hard_family_is_used_by_every_consumer_or_refused_by_name(monkeypatch, tmp_path):
    _declare(monkeypatch, EpsCap())
    ts, prob = _problem()
    L = int(prob.L)
    lp = build_tube_lp(prob)                                           # the float LP: its rows are hard rows
    assert lp.G_hard.shape[0] == L and np.allclose(lp.g_hard, CAP)
    assert np.array_equal(lp.G_hard[:, lp.index.eps], np.eye(L))
    v = highs_verdict(prob)                                            # HiGHS keeps the edge (the cap binds nowhere)
    assert v.status == "edge" and np.all(np.asarray(v.tube.eps) <= CAP)
    over = Tube(np.asarray(v.tube.p), np.full(L, 2 * CAP), np.asarray(v.tube.u))
    assert tube_violation(prob, over) > 0                              # the float check has the rows ...
    names = [nm for nm, _, _ in tube_residuals(float_terms(prob), TubeVars(*over))]
    assert names[-1] == "eps_cap"
    assert exact_tube_violation(prob, over) > 0                        # ... and the exact check
    assert tube_violation(prob, v.tube) <= 1e-9
    rlp = rational_tube_lp(prob, lp)                                   # the rational rows
    assert len(rlp.hard_rows) == L
    check_against_float(rlp, lp)
    assert certificate_rows("tube", prob.system)[-1] == "eps_cap"     # the certificate rows
    assert unmodelled_families(prob.system) == ("eps_cap",)           # PDHG refuses it by name: HiGHS
    assert not TUBE_PDHG.batched(prob)
    with pytest.raises(FamilyDataError, match="'eps_cap'"):               # and has no operator data for it
        build_tube_data([prob])
    ts.save(tmp_path)                                                  # verify, complete
    assert list(ts.certificate_rows or certificate_rows("tube", prob.system))[-1] == "eps_cap"
    rep = verify_directory(tmp_path, complete=True)
    assert rep.ok, rep.findings


def test_a_bound_family_the_bounds_do_not_model_is_refused_by_name(monkeypatch):
    _, prob = _problem()
    _declare(monkeypatch, EpsCap(role="bound"))
    with pytest.raises(FamilyDataError, match="'eps_cap'"):
        build_tube_lp(prob)
    assert "eps_cap" in unmodelled_families(prob.system)


def test_a_set_missing_from_the_data_is_an_error_naming_the_family():
    """The hazard of ``RegionRows.applies`` deciding from the data: the family switched itself
    off where its set was missing (exact data built for known names only)."""
    _, prob = _problem()
    d = float_terms(prob)
    x = TubeVars(np.zeros((2, 2)), np.ones(2), np.zeros((2, 4, 2)))
    for name in ("target", "input"):
        lacking = d._replace(sets={k: v for k, v in d.sets.items() if k != name})
        with pytest.raises(FamilyDataError, match=f"row family '{name}'.*'{name}'"):
            tube_residuals(lacking, x)
    e = exact_terms(exact_tube_data(prob))
    lacking = e._replace(sets={k: v for k, v in e.sets.items() if k != "safe"})
    with pytest.raises(FamilyDataError, match="row family 'safe'"):
        tube_residuals(lacking, x)
    # every set a system declares is in the float and the exact data
    assert set(d.sets) == set(e.sets) == set(tube_families.system_regions(prob.system))


@dataclasses.dataclass(frozen=True)
class InputCap(RowFamily):
    """``u_k(l)[0] <= CAP`` in the open-loop LP: a hard family its operator does not know by name."""

    name: str = "u_cap"
    compress_vertices: bool = False

    def grid(self, d):
        return (d.L, d.V.shape[-2], 1)

    def lp_role(self, d, u_is_box):
        return "hard"

    def lhs(self, d, x):
        return x.u[..., 0:1]

    def rhs(self, d):                   # in the terms' arithmetic (float or rational)
        return d.sets["input"].h[..., :1] * 0 + int(CAP)

    def scale(self, d):
        return d.sets["input"].scale[:1] * 0 + 1

    def normals(self, d):
        return d.sets["safe"].H[:1] * 0


@pytest.mark.parametrize("U", ["box", "one_norm"])
def test_the_open_loop_operators_refuse_a_family_they_do_not_model(monkeypatch, U):
    """The open-loop operator models ``safe``, ``target`` and ``input`` (bounds or hard rows); a
    family added to the declaration is in the dense LP and HiGHS's verdict, and the operators (margin
    and radius form) refuse it by name: the problem goes to HiGHS."""
    from tubejax.lp.declarations.openloop_lp import build_openloop_lp
    from tubejax.lp.declarations.openloop_operator_data import build_openloop_data, openloop_unmodelled
    from tubejax.lp.evidence.records.openloop_record import OPENLOOP_PDHG, RADIUS_OPENLOOP_PDHG
    from tubejax.model.system import one_norm_input_set

    _, prob = _problem()
    if U == "one_norm":
        prob = dataclasses.replace(prob, system=dataclasses.replace(prob.system, U=one_norm_input_set(1.0, 2)))
    assert OPENLOOP_PDHG.batched(prob) and not openloop_unmodelled(prob.system)
    n_hard = build_openloop_lp(prob).G_hard.shape[0]
    status = highs_verdict(prob, form="openloop").status
    _declare(monkeypatch, InputCap(), "openloop")
    L, nv = int(prob.L), prob.source.n_vertices
    lp = build_openloop_lp(prob)                                       # the dense LP has its rows
    assert lp.G_hard.shape[0] == n_hard + L * nv and np.allclose(lp.g_hard[n_hard:], CAP)
    assert highs_verdict(prob, form="openloop").status == status              # never binding
    assert openloop_unmodelled(prob.system) == ("u_cap",)
    assert not OPENLOOP_PDHG.batched(prob) and not RADIUS_OPENLOOP_PDHG.batched(prob)
    with pytest.raises(FamilyDataError, match="'u_cap'"):
        build_openloop_data([prob])
