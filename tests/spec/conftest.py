"""Small labelled maps with their abstractions (HiGHS, r = 0.2, L_max = 10), built once per session."""

from pathlib import Path

import numpy as np
import pytest

#: Top row 1 . 4 . 2 above a wall; the plain route 1 -> 2 runs along the top row over region 4,
#: the detour goes down to 3 and along the bottom row.
AVOID_MAP = "1.4.2\n.###.\n3....\n"
#: Region 6 lies behind region 4 in a one-row corridor: "never 4" makes "eventually 6" impossible.
BLOCKED_MAP = "1.4.6\n"
PAPER_MAP = Path(__file__).resolve().parents[2] / "conf" / "workspace" / "maps" / "paper.txt"


def _abstraction(path):
    from tubejax.abstraction import build_abstraction
    from tubejax.model.geometry import Ball
    from tubejax.model.system import LinearSystem, box_input_set
    from tubejax.model.workspace.gridmap import load_grid_map

    d = load_grid_map(path)
    s = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
    return build_abstraction(d, s, L_max=10, progress=False)


@pytest.fixture(scope="session")
def avoid_ts(tmp_path_factory):
    p = tmp_path_factory.mktemp("maps") / "avoid.txt"
    p.write_text(AVOID_MAP)
    return _abstraction(p)


@pytest.fixture(scope="session")
def blocked_ts(tmp_path_factory):
    p = tmp_path_factory.mktemp("maps") / "blocked.txt"
    p.write_text(BLOCKED_MAP)
    return _abstraction(p)


@pytest.fixture(scope="session")
def paper_ts():
    return _abstraction(PAPER_MAP)
