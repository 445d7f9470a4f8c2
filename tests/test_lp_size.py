"""The LP sizes stated in docs/math/tube-lp.md#lp-size are those of the LPs the code builds.

Per pair and horizon ``L``: ``L (n + 1 + n_v m)`` variables plus ``t``; margin rows
``(L − 1) f_S + f_j + L f_X + L n_v f_Z`` (tube) or ``(L − 1) n_i f_S + n_i f_j`` (open loop);
hard rows ``L n_v f_U`` (``L n_i f_U`` open loop) for a non-box ``U`` and none for a box. The
cases cover square cells with a box ``Z``, triangles with ``Z`` the cell and with ``chamfer``
(``n_v = 2 n_i``), a 1-norm ``U``, the obstacle case, a state constraint and a 4-D box grid.
"""

import numpy as np
import pytest

from tubejax.lp.declarations.openloop_lp import build_openloop_lp
from tubejax.lp.declarations.tube_lp import build_tube_lp
from tubejax.model.geometry import Ball, Halfspaces
from tubejax.model.problem import pair_problem
from tubejax.model.system import LinearSystem, box_input_set, one_norm_input_set
from tubejax.model.workspace import box_grid, load_grid_map
from tubejax.model.workspace.polygon import load_polygon_workspace
from tubejax.model.zshape.kinds import make_z

ROOT = __import__("pathlib").Path(__file__).resolve().parents[1]
MAPS = ROOT / "conf" / "workspace" / "maps"


def _planar(u: str = "box", X=None) -> LinearSystem:
    U = box_input_set(1.0, 2) if u == "box" else one_norm_input_set(1.0, 2)
    return LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=U, W=Ball(2, 0.2), X=X)


def _expected_tube(prob, L: int) -> tuple[int, int, int]:
    n, m = prob.system.n, prob.system.m
    n_v, f_z = prob.Z.n_vertices, prob.Z.H.shape[0]
    f_x = sum(c.H.shape[0] for c in prob.system.state_constraints.values())
    cols = L * (n + 1 + n_v * m) + 1
    rows = (L - 1) * prob.safe.H.shape[0] + prob.target.H.shape[0] + L * f_x + L * n_v * f_z
    hard = 0 if prob.system.u_is_box else L * n_v * prob.system.U.H.shape[0]
    return cols, rows, hard


def _sizes(lp) -> tuple[int, int, int]:
    return lp.G.shape[1] + 1, lp.G.shape[0], lp.G_hard.shape[0]


def _cases():
    grid = load_grid_map(MAPS / "paper.txt")
    rooms = load_polygon_workspace(MAPS / "rooms.yaml")
    speed = Halfspaces([[0.0, 1.0]], [9.5], "system.X")
    grid4 = box_grid([0, 0, 0, 0], [2, 2, 2, 2], 2)
    di = LinearSystem(A=np.eye(4), B=np.kron(np.eye(2), [[0.125], [1.125]]), U=box_input_set(1.0, 2),
                      W=Ball(4, 0.02))
    tri = next(i for i in range(rooms.n_cells) if rooms.cells[i].n_vertices == 3)
    nb = next(j for j in range(rooms.n_cells) if j != tri)
    return [("grid, box Z, free case", grid, _planar(), "box", 0, 2),
            ("grid, box Z, obstacle case", grid, _planar(), "box", 0, 10),
            ("grid, 1-norm U", grid, _planar("one_norm"), "box", 0, 2),
            ("grid, state constraint", grid, _planar(X=speed), "box", 0, 2),
            ("triangles, Z the cell", rooms, _planar(), "cell", tri, nb),
            ("triangles, chamfer", rooms, _planar("one_norm"), "chamfer", tri, nb),
            ("4-D box grid", grid4, di, "box", 0, 1)]


@pytest.mark.parametrize("case", _cases(), ids=lambda c: c[0])
@pytest.mark.parametrize("L", [1, 2, 5])
def test_tube_lp_size(case, L):
    _, decomp, system, zshape, i, j = case
    prob = pair_problem(decomp, system, make_z(zshape, decomp.cells[i]), i, j, L)
    assert _sizes(build_tube_lp(prob)) == _expected_tube(prob, L)


def test_the_cases_cover_what_the_page_names():
    cases = _cases()
    grid, system = cases[1][1], cases[1][2]
    assert grid.obstacle_case(0, 10) and not grid.obstacle_case(0, 2)
    assert make_z("chamfer", cases[5][1].cells[cases[5][4]]).n_vertices == 6
    assert cases[6][1].cells[0].n_vertices == 16


@pytest.mark.parametrize("case", [c for c in _cases() if c[3] != "chamfer" and c[0] != "grid, state constraint"],
                         ids=lambda c: c[0])
@pytest.mark.parametrize("L", [1, 3])
def test_openloop_lp_size(case, L):
    _, decomp, system, zshape, i, j = case
    prob = pair_problem(decomp, system, make_z(zshape, decomp.cells[i]), i, j, L)
    n_i, m = prob.source.n_vertices, system.m
    lp = build_openloop_lp(prob)
    rows = (L - 1) * n_i * prob.safe.H.shape[0] + n_i * prob.target.H.shape[0]
    hard = 0 if system.u_is_box else L * n_i * system.U.H.shape[0]
    assert _sizes(lp) == (L * n_i * m + 1, rows, hard)
