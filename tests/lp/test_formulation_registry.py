"""The LP registry (tubejax/lp/evidence/registry.py): one record per LP, the only place a method is dispatched.

* every module of ``lp/evidence/records/`` is registered, with the pieces an LP needs;
* no ``isinstance`` on an LP's evidence or dense-LP type outside the record modules and the types' own
  modules (the record answers ``formulation_of``), and the comparisons of a method name with a string
  literal may only shrink (a ratchet);
* each registered LP's HiGHS model (the record's dense builder solved by :func:`solve_margin_lp`) agrees
  with its dense rows solved independently by SciPy's ``linprog``, its float and exact checkers pass
  HiGHS's point where the margin is positive, and its rational LP is its dense LP row for row;
* a new LP is one new file in ``records/``: a copy of the library with one more record abstracts, saves
  and verifies with it.
"""

import ast
import importlib.util
import os
import pkgutil
import shutil
import subprocess
import sys
from pathlib import Path

import networkx as nx
import numpy as np
import pytest
from scipy.optimize import linprog

from tubejax.errors import InputError
from tubejax.lp.evidence.rows import check_against_float
from tubejax.lp.evidence.verdict import VERIFY_TOL, highs_verdict
from tubejax.lp.evidence import records
from tubejax.lp.evidence.registry import (FORMULATIONS, exact_references, formulation, formulation_of,
                                          formulation_of_form, method_names, product_methods, radius_forms, series_name, tube_methods)
from tubejax.lp.engines.highs import solve_margin_lp
from tubejax.lp.batch.batch_solver import RADIUS_OPTIONS, PdhgBatchSolver, pdhg_solver
from tubejax.lp.declarations.formulation import PdhgForm
from tubejax.abstraction.product_store import product_refusal
from tubejax.model.geometry import Ball, Polytope
from tubejax.model.problem import pair_problem
from tubejax.model.system import LinearSystem, box_input_set, one_norm_input_set
from tubejax.model.workspace import parse_grid_map

ROOT = Path(__file__).resolve().parents[2] / "tubejax"
_spec = importlib.util.spec_from_file_location("_layers", Path(__file__).resolve().parents[1] / "test_layers.py")
_LAYERS = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_LAYERS)                        # its import graph of tubejax/
#: The evidence and dense-LP types of the registered LPs (read from the registry itself).
LP_TYPES = {t.__name__: t for f in FORMULATIONS.values() for t in (f.evidence_type, f.exact_type, f.lp_type)
            if t is not None}
#: Comparisons ``x == 'tube'`` (or ``!=``, ``in (...)``) of a method name in the library today: a ratchet,
#: lower it when one goes, never raise it (a new LP is a record, not a new branch).
MAX_METHOD_NAME_SWITCHES = 0         # the plots, the sweep tables and the product path read the records
#: (tables keyed by method name count too: ``{"tube": ..., "openloop": ...}``, ``dict(exact2d=...)``)


def _modules():
    for path in sorted(ROOT.rglob("*.py")):
        yield path, ast.parse(path.read_text(encoding="utf-8"))


def _in_records(path: Path) -> bool:
    """Whether ``path`` is a record module (read below ``ROOT``: a checkout's own folder may be named so)."""
    return "records" in path.relative_to(ROOT).parts


def _own_module(path: Path) -> set:
    """The type names ``path`` defines (a type may test itself, e.g. in ``coerce``)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    return {n.name for n in tree.body if isinstance(n, ast.ClassDef)}


def test_every_record_module_is_registered_with_its_pieces():
    files = {m.name for m in pkgutil.iter_modules(records.__path__)}
    assert files and len(FORMULATIONS) == len(files)
    assert method_names() == ("tube", "openloop", "exact2d")
    for f in FORMULATIONS.values():
        if not f.solves_lp:
            assert f.families == () and f.evidence_type is None
            continue
        for piece in ("evidence_type", "exact_type", "lp_type", "violation", "exact_violation", "rational_lp",
                      "bounds", "from_point"):
            assert getattr(f, piece) is not None, (f.name, piece)
        assert set(f.terms) == {"float", "exact"} and f.families and f.evidence_names
        assert formulation_of(f.lp_type.__new__(f.lp_type, *[None] * len(f.lp_type._fields))) is f


def test_each_records_pdhg_forms_are_its_own():
    """The batched PDHG form and the radius form are the record's own (no table by method name elsewhere)."""
    for name, f in FORMULATIONS.items():
        assert f.pdhg is None or (isinstance(f.pdhg, PdhgForm) and formulation_of_form(f.pdhg) is f
                                  and not f.pdhg.radius), name
        if f.pdhg is None:
            with pytest.raises(InputError, match="no batched PDHG form"):
                pdhg_solver(name)
        else:
            assert pdhg_solver(name).form is f.pdhg
        if f.radius is None:
            assert name not in radius_forms()
            with pytest.raises(InputError, match=f"method '{name}' has no radius form on the batched engine"):
                pdhg_solver(name, radius=True)
            continue
        assert name in radius_forms() and f.radius.pdhg.radius and formulation_of_form(f.radius.pdhg) is f
        radius = pdhg_solver(name, radius=True)
        assert radius.form is f.radius.pdhg and radius.options == RADIUS_OPTIONS and radius.record is f
    for copy in (formulation("tube").pdhg._replace(), formulation("openloop").radius.pdhg._replace()):
        with pytest.raises(TypeError, match="held by no registered formulation"):      # equal, not the record's
            PdhgBatchSolver(form=copy)
    FORMULATIONS["plan"] = formulation("openloop")._replace(name="plan")        # two records, one form
    try:
        with pytest.raises(TypeError, match="held by the records openloop, plan"):
            pdhg_solver("plan")
    finally:
        del FORMULATIONS["plan"]
    assert FORMULATIONS["exact2d"].pdhg is None and radius_forms() == ("tube", "openloop") and tube_methods() == ("tube",)
    assert [n for n, f in FORMULATIONS.items() if f.translation_classes] == ["tube", "openloop"]
    assert exact_references() == ("exact2d",) and product_methods() == ("tube",)
    assert series_name("tube", "box") == "tube (box)" and series_name("openloop", "box") == "openloop"
    assert formulation("exact2d").dimensions == (2,) and not formulation("tube").dimensions
    with pytest.raises(InputError, match="'exact2d' has no radius form on the batched engine; expected one of "
                                         "tube, openloop"):
        pdhg_solver("exact2d", radius=True)
    with pytest.raises(InputError, match="method: expected one of tube, openloop, exact2d, got 'nope'"):
        pdhg_solver("nope", radius=True)


def test_the_product_path_takes_the_methods_its_record_names():
    assert product_refusal("tube", 0.0, 3) == ""
    for name in ("openloop", "exact2d", "nope"):
        assert product_refusal(name, 0.0, 3) == f"the product path solves the tube LP, not method {name!r}"


def test_an_unknown_name_or_type_is_refused_by_name():
    with pytest.raises(InputError, match="method: expected one of tube, openloop, exact2d, got 'nope'"):
        formulation("nope")
    with pytest.raises(TypeError, match="tuple is the evidence or LP of no registered formulation"):
        formulation_of((1, 2))


def test_no_isinstance_on_an_lp_type_outside_the_records():
    found = []
    for path, tree in _modules():
        if _in_records(path):
            continue
        own = _own_module(path)
        for node in ast.walk(tree):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "isinstance" \
                    and len(node.args) == 2:
                names = {n.id for n in ast.walk(node.args[1]) if isinstance(n, ast.Name)}
                hit = (names & set(LP_TYPES)) - own
                if hit:
                    found.append(f"{path.relative_to(ROOT.parent)}:{node.lineno}: isinstance on {sorted(hit)}")
    assert not found, "ask the registry (formulation_of) instead:\n" + "\n".join(found)


def _method_name_switches() -> list:
    names = set(FORMULATIONS)
    out = []
    for path, tree in _modules():
        if _in_records(path):
            continue
        for node in ast.walk(tree):
            if not isinstance(node, ast.Compare):
                continue
            consts = [c for c in [node.left, *node.comparators] for c in ast.walk(c)
                      if isinstance(c, ast.Constant) and c.value in names]
            if consts and any(isinstance(op, (ast.Eq, ast.NotEq, ast.In, ast.NotIn)) for op in node.ops):
                out.append(f"{path.relative_to(ROOT.parent)}:{node.lineno}")
    return out + _method_name_tables()


def _method_name_tables() -> list:
    """Tables keyed by two or more method names (``{"tube": ..., "openloop": ...}``, ``dict(tube=..., exact2d=...)``)
    and lists of them (``("tube", "openloop")``, ``choice("tube", "openloop")``): a field of the records or the
    registry instead (a colour, the settings a method ignores, ``radius_forms()``). One such name alone is not
    counted: ``"tube"`` also names a tube set (``{"tube": 3, "run": 4}``)."""
    names = set(FORMULATIONS)
    out = []
    for path, tree in _modules():
        if _in_records(path):
            continue
        for node in ast.walk(tree):
            if isinstance(node, ast.Dict):
                keys = [k.value for k in node.keys if isinstance(k, ast.Constant)]
            elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "dict":
                keys = [k.arg for k in node.keywords]
            elif isinstance(node, (ast.Tuple, ast.List, ast.Set, ast.Call)):
                keys = [k.value for k in (node.args if isinstance(node, ast.Call) else node.elts)
                        if isinstance(k, ast.Constant)]
            else:
                continue
            if len(names & set(keys)) >= 2:
                out.append(f"{path.relative_to(ROOT.parent)}:{node.lineno}: a table keyed by method name")
    return out


def test_method_name_switches_only_shrink():
    found = _method_name_switches()
    assert len(found) <= MAX_METHOD_NAME_SWITCHES, "\n".join(found)


def test_the_checker_sees_an_isinstance_and_a_switch(tmp_path, monkeypatch):
    """The two checks above find what they look for (they cannot pass vacuously)."""
    bad = tmp_path / "tubejax" / "bad.py"
    bad.parent.mkdir()
    bad.write_text("def f(x, m):\n    return isinstance(x, (ExactTube, int)) or m == 'openloop'\n")
    monkeypatch.setattr(__import__(__name__), "ROOT", bad.parent)
    assert len(_method_name_switches()) == 1
    bad.write_text(bad.read_text() + "COLOURS = {'tube': 'blue', 'openloop': 'red'}\nSTYLE = dict(exact2d=1, tube=2)\nZ = {'tube': 3}\n")
    assert len(_method_name_switches()) == 3
    bad.write_text(bad.read_text() + "FORMS = ('tube', 'openloop')\nPICK = choice('tube', 'exact2d')\nONE = ['tube']\n")
    assert len(_method_name_switches()) == 5
    with pytest.raises(AssertionError, match="isinstance on \\['ExactTube'\\]"):
        test_no_isinstance_on_an_lp_type_outside_the_records()


def _problems():
    decomp = parse_grid_map("1..\n.#.\n..2\n")
    Z = Polytope.box([-0.5, -0.5], [0.5, 0.5])
    out = []
    for U, r in ((box_input_set(1.0, 2), 0.1), (one_norm_input_set(1.0, 2), 0.05)):
        s = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=U, W=Ball(2, r))
        out += [pair_problem(decomp, s, Z, i, j, L) for i, j in ((0, 1), (0, 3), (1, 0)) for L in (1, 2, 3)]
    return out


def _linprog_margin(lp) -> float:
    """``max t`` over ``lp``'s dense rows (``G x + t <= g``, ``G_hard x <= g_hard``, bounds), by SciPy."""
    n = lp.G.shape[1]
    c = np.zeros(n + 1)
    c[-1] = -1.0
    ones = np.ones((lp.G.shape[0], 1)) if lp.t_coef is None else lp.t_coef[:, None]
    A = np.vstack([np.hstack([lp.G, ones]), np.hstack([lp.G_hard, np.zeros((lp.G_hard.shape[0], 1))])])
    b = np.concatenate([lp.g, lp.g_hard])
    bounds = [(None if not np.isfinite(lo) else lo, None if not np.isfinite(hi) else hi)
              for lo, hi in zip(lp.lb, lp.ub)] + [(None if not np.isfinite(lp.t_min) else lp.t_min, lp.t_max)]
    res = linprog(c, A_ub=A, b_ub=b, bounds=bounds, method="highs")
    assert res.status == 0, res.message
    return -res.fun


@pytest.mark.parametrize("name", [n for n, f in FORMULATIONS.items() if f.solves_lp])
def test_each_lps_highs_model_agrees_with_its_dense_rows(name):
    f = formulation(name)
    signs = set()
    for prob in _problems():
        lp = f.build(prob)
        assert formulation_of(lp) is f
        res = solve_margin_lp(lp)
        assert res.status == "Optimal"
        assert res.margin == pytest.approx(_linprog_margin(lp), abs=1e-7)
        check_against_float(f.rational_lp(prob, lp), lp)
        evidence = lp.index.split(res.x)
        assert type(evidence) is f.evidence_type
        v = highs_verdict(prob, form=name)
        assert v.provenance == f.provenance
        if res.margin > 1e-6:
            signs.add("edge")
            assert f.violation(prob, evidence) <= VERIFY_TOL
            assert v.status == "edge" and type(v.tube) is f.evidence_type
            if v.proof.level == "exact":           # the proved evidence: the rational kept, else the float one
                proved = v.tube if v.proof.exact is None else v.proof.exact
                assert f.exact_violation(prob, f.exact(proved)) <= 0
        elif res.margin < -1e-6:
            signs.add("infeasible")
            assert v.status == "infeasible"
    assert signs == {"edge", "infeasible"}           # the small case has both


NEW_LP = '''"""A trial LP: the open-loop LP's pieces under another name."""
from .openloop_record import FORMULATION as _OPENLOOP

FORMULATION = _OPENLOOP._replace(name="plan", rank=5, provenance="plan-highs")
'''

NEW_LP_RUN = '''
import tempfile
import tubejax as tj
m = tj.grid_map("1...\\n....\\n...2\\n")
ts = tj.abstract(m, tj.paper_system(0.1), method="plan", solver="highs", L_max=3, progress=False)
ref = tj.abstract(m, tj.paper_system(0.1), method="openloop", solver="highs", L_max=3, progress=False)
assert ts.method == "plan" and ts.n_edges > 0
assert sorted((e.src, e.dst, e.L) for e in ts.edges) == sorted((e.src, e.dst, e.L) for e in ref.edges)
d = tempfile.mkdtemp() + "/run"
ts.save(d)
r = tj.verify(d, complete=True)
assert r.findings == [] and r.complete and r.proof_counts["exact"] == ts.n_edges, r
print("ok", ts.n_edges)
'''


def test_a_new_lp_is_one_file(tmp_path):
    """A copy of the library with one more file in ``records/`` abstracts, saves and verifies with the new
    method (the settings, the file format, the verifier and the solvers all read the registry)."""
    shutil.copytree(ROOT, tmp_path / "tubejax", ignore=shutil.ignore_patterns("__pycache__"))
    (tmp_path / "tubejax" / "lp" / "evidence" / "records" / "plan_record.py").write_text(NEW_LP)
    out = subprocess.run([sys.executable, "-c", NEW_LP_RUN], cwd=tmp_path, capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": str(tmp_path), "JAX_PLATFORMS": "cpu"},
                         timeout=300)
    assert out.returncode == 0 and out.stdout.startswith("ok"), out.stderr[-3000:]


def test_the_records_are_below_the_steps_that_read_them():
    """No record module reaches the modules that read the registry (the proofs, the exact decisions, the
    verdicts): the registry imports the records dynamically, which the import graph of
    tests/test_layers.py does not see, so this is where a cycle through it would show."""
    G, _ = _LAYERS.import_graph()
    readers = {"tubejax.lp.evidence.prove", "tubejax.lp.evidence.decide", "tubejax.lp.evidence.verdict",
               "tubejax.lp.evidence.registry"}
    for mod in G.nodes:
        if mod.startswith("tubejax.lp.evidence.records."):
            assert not (nx.descendants(G, mod) & readers), (mod, sorted(nx.descendants(G, mod) & readers))
