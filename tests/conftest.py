import jax
import pytest

jax.config.update("jax_enable_x64", True)


@pytest.fixture(scope="session")
def corridor_path():
    from pathlib import Path

    return Path(__file__).resolve().parents[1] / "conf" / "workspace" / "maps" / "corridor.txt"


@pytest.fixture(scope="session")
def paper_system():
    import numpy as np

    from tubejax.model.geometry import Ball
    from tubejax.model.system import LinearSystem, box_input_set

    def make(r=0.2):
        return LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, r))

    return make


#: Tests that start the apps or a notebook kernel in a new process (each pays Python, JAX and often the
#: solver's compile again): marked ``slow``, so ``pytest -m "not slow"`` is a quicker first check. CI
#: (.ci/run) runs every test.
END_TO_END = ("experiments/", "test_notebooks.py", "test_provenance.py")


def pytest_collection_modifyitems(config, items):
    for item in items:
        path = item.path.as_posix()
        if any(f"/tests/{p}" in path for p in END_TO_END):
            item.add_marker(pytest.mark.slow)
