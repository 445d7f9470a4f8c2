"""HiGHS prints nothing unless asked, whatever highspy release is installed."""

import subprocess
import sys
from pathlib import Path

QUIET = '''
import numpy as np
from tubejax.lp.engines.highs import new_highs, solve_margin_lp
from tubejax.lp.declarations.tube_lp import build_tube_lp
from tubejax.model.problem import pair_problem
from tubejax.model.workspace.gridmap import parse_grid_map
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.geometry import Ball
from tubejax.model.zshape.kinds import make_z
dec = parse_grid_map("1.2")
sysm = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.1))
res = solve_margin_lp(build_tube_lp(pair_problem(dec, sysm, make_z("box", dec.cells[0]), 0, 1, 3)))
new_highs()
print("margin", res.status)
'''


def test_highs_prints_nothing_on_stdout():
    root = Path(__file__).resolve().parents[2]
    res = subprocess.run([sys.executable, "-c", QUIET], cwd=root, capture_output=True, text=True,
                         timeout=120)
    assert res.returncode == 0, res.stderr[-3000:]
    assert res.stdout == "margin Optimal\n", res.stdout
