"""The house in layers: the import graph of ``tubejax/`` has no cycle, and imports only go down.

The package is one sub-package per layer, each importing only the layers before it (``LAYERS``):
``errors`` and ``files`` (bad input, reading the user's files) -> ``model`` (geometry, workspace,
system, the kinds of ``Z`` and the learned-``Z`` table, ``Z`` per pair, the pair problems) -> ``lp``
(itself in layers, ``LP_LAYERS``) -> ``reachability`` (exact 2-D reachability: no LP, but ``lp``'s
verdicts) -> ``inputs`` (every user input, validated) -> ``transitions`` (the
transition system, its records and files, provenance, graph export) -> ``abstraction`` (candidates,
pruning, translation classes, schedule, the rounds, the run store, shards) ->
``verify`` (and the shard merge) ->
``analyses`` (control, specifications, radius, learning ``Z``, sweep tables, figures) -> the API
(``api``, ``api_control``, ``api_inputs``, ``__main__`` and the package itself). No import goes up
(``UPWARD_IMPORTS`` is empty: a ratchet, never add one).

Inside ``lp`` the folders are layers too: ``declarations`` (what each LP is: row families, dense
builders, operators, the record types) -> ``engines`` (PDHG, its pool, HiGHS, workers, float64
certificates, each LP's form on PDHG: solvers that know no verdict) -> ``evidence`` (verdicts, HiGHS
confirmation, exact proofs and decisions, the LP records) -> ``batch`` (the batched solver that groups,
streams, certifies and confirms). Every module of ``lp`` sits in one of them, and
``LP_UPWARD_IMPORTS`` is a ratchet like ``UPWARD_IMPORTS``. Names say what a thing is: no two
modules of the package share a file name.

The graph is read with ``ast`` from the sources, counting imports placed inside functions
as edges too (they hide a cycle from the interpreter, not from the design); imports under
``if TYPE_CHECKING:`` are annotations only and are left out. Imports inside functions are also
counted: they may only shrink (each should be an optional dependency or a deliberate deferral).
"""

import ast
from pathlib import Path

import networkx as nx
import pytest

ROOT = Path(__file__).resolve().parents[1] / "tubejax"
#: Imports placed inside functions today (a ratchet: lower it when one goes, never raise it).
MAX_IMPORTS_IN_FUNCTIONS = 0
#: The layers, lowest first: the first name under ``tubejax`` -> its layer's place.
LAYERS = ("errors", "files", "model", "lp", "reachability", "inputs", "transitions", "abstraction", "verify", "analyses",
          ("api", "api_control", "api_inputs", "__main__"))
#: Imports that go up a layer today (a ratchet: remove one when it goes, never add one).
UPWARD_IMPORTS: set = set()
#: The layers inside ``tubejax.lp``, lowest first (the folder under ``tubejax/lp/``).
LP_LAYERS = ("declarations", "engines", "evidence", "batch")
#: Imports between ``lp`` folders that go up today (a ratchet: remove one when it goes, never add one).
LP_UPWARD_IMPORTS: set = set()


def _modules() -> dict:
    out = {}
    for p in sorted(ROOT.rglob("*.py")):
        parts = list(p.relative_to(ROOT.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    return out


def _type_checking_nodes(tree) -> set:
    ids = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            for child in node.body:
                ids.update(id(n) for n in ast.walk(child))
    return ids


def _function_nodes(tree) -> set:
    ids = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            ids.update(id(n) for n in ast.walk(node) if n is not node)
    return ids


def import_graph():
    """``(graph, imports inside functions)``: module -> imported tubejax module, from the sources."""
    mods = _modules()
    G = nx.DiGraph()
    inner = []
    for mod, path in mods.items():
        G.add_node(mod)
        tree = ast.parse(path.read_text(encoding="utf-8"))
        skip, in_func = _type_checking_nodes(tree), _function_nodes(tree)
        package = mod if path.name == "__init__.py" else mod.rsplit(".", 1)[0]
        for node in ast.walk(tree):
            if not isinstance(node, (ast.Import, ast.ImportFrom)) or id(node) in skip:
                continue
            if id(node) in in_func:
                inner.append((mod, ast.unparse(node)))
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            else:
                base = package.split(".")
                if node.level:
                    base = base[:len(base) - node.level + 1]
                    name = ".".join(base + ([node.module] if node.module else []))
                else:
                    name = node.module or ""
                targets = [f"{name}.{a.name}" for a in node.names] + [name]
            for t in targets:
                while t and t not in mods and "." in t:
                    t = t.rsplit(".", 1)[0]
                if t in mods and t != mod and t.startswith("tubejax"):
                    G.add_edge(mod, t)
    return G, inner


def test_the_import_graph_has_no_cycle():
    G, _ = import_graph()
    cycles = [sorted(c) for c in nx.strongly_connected_components(G) if len(c) > 1]
    assert not cycles, "import cycles (a module reaches back up the layers):\n" + "\n".join(map(str, cycles))


def _layer(module: str) -> int:
    head = module.split(".")[1] if "." in module else "__main__"
    for i, layer in enumerate(LAYERS):
        if head == layer or head in layer:
            return i
    raise AssertionError(f"{module} is in no layer: add it to LAYERS")


def test_imports_only_go_down():
    G, _ = import_graph()
    up = {(a, b) for a, b in G.edges if _layer(b) > _layer(a)}
    assert up <= UPWARD_IMPORTS, "imports that go up a layer:\n" + "\n".join(
        f"{a} -> {b}" for a, b in sorted(up - UPWARD_IMPORTS))
    assert UPWARD_IMPORTS <= up, "gone (remove them from UPWARD_IMPORTS): " + str(sorted(UPWARD_IMPORTS - up))


def _lp_layer(module: str) -> int:
    parts = module.split(".")
    if len(parts) < 3 or parts[2] not in LP_LAYERS:
        raise AssertionError(f"{module} is in no layer of tubejax/lp/: move it into one of {LP_LAYERS}")
    return LP_LAYERS.index(parts[2])


def test_every_lp_module_is_in_an_lp_layer():
    lp = [m for m in _modules() if m.startswith("tubejax.lp.")]
    assert lp, "no module under tubejax/lp/"
    stray = [m for m in lp if m.split(".")[2] not in LP_LAYERS]
    assert not stray, f"modules of tubejax/lp/ outside the layer folders {LP_LAYERS}: {stray}"


def test_lp_imports_only_go_down():
    G, _ = import_graph()
    lp = [(a, b) for a, b in G.edges if a.startswith("tubejax.lp.") and b.startswith("tubejax.lp.")]
    assert lp, "the lp layer imports nothing of itself: the graph reader is broken"
    up = {(a, b) for a, b in lp if _lp_layer(b) > _lp_layer(a)}
    assert up <= LP_UPWARD_IMPORTS, "imports that go up an lp layer (move or split the module):\n" + "\n".join(
        f"{a} -> {b}" for a, b in sorted(up - LP_UPWARD_IMPORTS))
    assert LP_UPWARD_IMPORTS <= up, "gone (remove them from LP_UPWARD_IMPORTS): " + str(
        sorted(LP_UPWARD_IMPORTS - up))


def test_module_names_do_not_repeat():
    names = {}
    for path in ROOT.rglob("*.py"):
        if path.name != "__init__.py":
            names.setdefault(path.name, []).append(str(path.relative_to(ROOT)))
    repeated = {n for n, paths in names.items() if len(paths) > 1}
    assert not repeated, "a file name used twice (say what the module is):\n" + "\n".join(
        f"{n}: {sorted(names[n])}" for n in sorted(repeated))


def test_the_lp_checker_finds_an_upward_import(tmp_path, monkeypatch):
    """An engine importing a verdict is caught, and a module outside the lp folders is named."""
    pkg = tmp_path / "tubejax"
    for folder in ("engines", "evidence"):
        (pkg / "lp" / folder).mkdir(parents=True)
        (pkg / "lp" / folder / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("")
    (pkg / "lp" / "__init__.py").write_text("")
    (pkg / "lp" / "evidence" / "verdict.py").write_text("V = 1\n")
    (pkg / "lp" / "engines" / "pdhg.py").write_text("from ..evidence.verdict import V\n")
    (pkg / "lp" / "stray.py").write_text("")
    monkeypatch.setattr(__import__(__name__), "ROOT", pkg)
    with pytest.raises(AssertionError, match="tubejax.lp.engines.pdhg -> tubejax.lp.evidence.verdict"):
        test_lp_imports_only_go_down()
    with pytest.raises(AssertionError, match="tubejax.lp.stray"):
        test_every_lp_module_is_in_an_lp_layer()


def test_imports_inside_functions_only_shrink():
    _, inner = import_graph()
    assert len(inner) <= MAX_IMPORTS_IN_FUNCTIONS, (
        f"{len(inner)} imports inside functions (at most {MAX_IMPORTS_IN_FUNCTIONS}); import at the top of "
        "the module unless it is an optional dependency:\n" + "\n".join(f"{m}: {s}" for m, s in inner))


def test_the_checker_finds_a_cycle(tmp_path, monkeypatch):
    """The graph reader sees imports inside functions (a cycle the interpreter tolerates)."""
    pkg = tmp_path / "tubejax"
    (pkg / "a").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "a" / "__init__.py").write_text("from .b import f\n")
    (pkg / "a" / "b.py").write_text("def f():\n    from ..c import g\n    return g\n")
    (pkg / "c.py").write_text("from .a.b import f\n\ndef g():\n    return f\n")
    monkeypatch.setattr(__import__(__name__), "ROOT", pkg)
    G, inner = import_graph()
    assert ("tubejax.a.b", "tubejax.c") in G.edges and ("tubejax.c", "tubejax.a.b") in G.edges
    assert len(inner) == 1
    assert any(len(c) > 1 for c in nx.strongly_connected_components(G))
