"""One solver factory for the API and the apps: :func:`tubejax.abstraction.methods.batch_solver`.

``tj.abstract`` and ``experiments/abstract.py`` both turn validated settings into a solver through it;
these tests check that the same choices give the same settings on both paths, that the factory
builds the solver those settings name, and that an unusable compilation cache is refused by name on both.
"""

import ast
import sys
from pathlib import Path

import pytest

import tubejax as tj
import tubejax.api as api_module
from tubejax.abstraction.methods import batch_solver, method_solver
from tubejax.errors import InputError
from tubejax.lp.evidence.registry import formulation

ROOT = Path(__file__).resolve().parents[1]
TINY = ROOT / "tests" / "data" / "tiny.txt"
OPTIONS = {"pool": 32, "max_iters": 256, "check_every": 8, "dtype": "float64", "highs_process": False}


class _Stop(Exception):
    """Raised by the recording factory, so that no abstraction runs."""


def _api_settings(monkeypatch, **kw):
    """The settings ``tj.abstract`` hands to the factory."""
    seen = []

    def record(settings, **options):
        seen.append((settings, options))
        raise _Stop

    monkeypatch.setattr(api_module, "batch_solver", record)
    with pytest.raises(_Stop):
        tj.abstract(str(TINY), tj.paper_system(radius=0.05), L_max=2, **kw)
    (settings, options), = seen
    return settings, options


def _app_settings(overrides):
    """The settings ``experiments/abstract.py`` hands to the factory, from its composed config."""
    hydra = pytest.importorskip("hydra")
    from omegaconf import OmegaConf

    sys.path.insert(0, str(ROOT / "experiments"))
    try:
        from common import inputs_from_config
    finally:
        sys.path.remove(str(ROOT / "experiments"))
    with hydra.initialize_config_dir(config_dir=str(ROOT / "conf"), version_base=None):
        cfg = hydra.compose(config_name="config", overrides=[f"workspace.map_file={TINY}", *overrides])
    return inputs_from_config(OmegaConf.to_container(cfg, resolve=True)).abstraction


@pytest.mark.parametrize("method", ["tube", "openloop"])
def test_api_and_app_give_the_factory_the_same_solver_settings(monkeypatch, tmp_path, method):
    """The same choices give equal settings (the app's config names a compilation cache by default, the API
    none, so the test names one for both)."""
    given = {**OPTIONS, "compilation_cache": str(tmp_path / "cache")}
    api, options = _api_settings(monkeypatch, method=method, solver_options=given)
    app = _app_settings([f"method={method}", "solver=pdhg", *(f"solver.{k}={v}" for k, v in given.items())])
    assert options == {"reuse": True}
    assert (api.method, api.solver) == (app.method, app.solver)
    assert api.solver.options() == app.solver.options()
    assert api.solver.options()["pool"] == 32 and api.solver.options()["max_iters"] == 256


def test_both_entry_points_call_the_one_factory():
    """No second factory: the API and the app build their solver only through ``batch_solver``."""
    for path in (ROOT / "tubejax" / "api.py", ROOT / "experiments" / "abstract.py"):
        calls = {node.func.id for node in ast.walk(ast.parse(path.read_text()))
                 if isinstance(node, ast.Call) and isinstance(node.func, ast.Name)}
        assert "batch_solver" in calls, path
        assert not calls & {"PdhgBatchSolver", "pdhg_solver", "method_solver"}, path


@pytest.mark.parametrize("method", ["tube", "openloop"])
def test_factory_builds_the_solver_the_settings_name(method):
    settings = _app_settings([f"method={method}", "solver=pdhg", "verify=all",
                              *(f"solver.{k}={v}" for k, v in OPTIONS.items())])
    solver = batch_solver(settings)
    assert solver.form is formulation(method).pdhg and solver.record is formulation(method)
    assert (solver.pooling.pool, solver.exact, solver.executor.highs_process) == (32, True, False)
    assert solver.options.max_iters == 256 and solver.options.check_every == 8
    assert batch_solver(settings) is not solver                      # the app: a fresh solver per run
    assert batch_solver(settings, reuse=True) is batch_solver(settings, reuse=True)     # the API: reused


@pytest.mark.parametrize("method, solver", [("tube", "highs"), ("openloop", "highs"), ("exact2d", "highs")])
def test_reference_solvers_are_the_methods_own(method, solver):
    settings = _app_settings([f"method={method}", f"solver={solver}"])
    assert batch_solver(settings) is method_solver(method)


def test_unusable_compilation_cache_is_refused_by_name_by_the_api(tmp_path):
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    with pytest.raises(InputError, match=r"solver.compilation_cache: cannot keep JAX's compiled code in .*a-file.* "
                                         r"\(it is a file\)"):
        tj.abstract(str(TINY), tj.paper_system(radius=0.05), L_max=2,
                    solver_options={"compilation_cache": str(blocker)})
