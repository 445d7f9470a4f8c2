"""Classes up to reflections (tubejax.abstraction.translation_classes.system_reflections).

A reflection of whole axis groups that leaves the system exactly unchanged maps a pair's tube problem
onto its mirror image's: checked against HiGHS (the same margin for a pair and its mirror image) and
against the projection screen without reflections (the same pair horizons refuted, fewer LPs).
"""

from pathlib import Path

import numpy as np
import pytest

from tubejax.abstraction.joint_projections import ProjectionScreen
from tubejax.abstraction.product_abstraction import build_product_abstraction
from tubejax.abstraction.product_join import join_factors
from tubejax.abstraction.translation_classes import TranslationClasses, system_reflections
from tubejax.lp.engines.highs import solve_margin_lp
from tubejax.lp.evidence.registry import formulation
from tubejax.model.geometry import Ball, Polytope, convex_hull_of
from tubejax.model.problem import TubeProblem
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.system_kinds import double_integrator_lookahead
from tubejax.model.workspace.voxelmap import parse_map
from tubejax.model.workspace.lookahead import lift_lookahead

L_MAX = 4


def two_axes(U=None, W=None, X=None, coupled=0.0) -> LinearSystem:
    A, B = double_integrator_lookahead(2, 0.5, 2.0)
    A = A.astype(float)
    A[0, 2] = coupled
    return LinearSystem(A=A, B=B.astype(float), U=U if U is not None else box_input_set(1.0, 2),
                        W=W if W is not None else Ball(4, 0.01), X=X)


def test_the_drone_like_system_has_every_flip_of_its_groups():
    R = system_reflections(two_axes(), [0, 0, 1, 1], [0, 1])
    np.testing.assert_array_equal(R, [[1, 1, 1, 1], [1, 1, -1, -1], [-1, -1, 1, 1], [-1, -1, -1, -1]])


@pytest.mark.parametrize("system, want", [
    (two_axes(U=Polytope.box([-1.0, -1.0], [2.0, 1.0])), [[1, 1, 1, 1], [1, 1, -1, -1]]),   # U not symmetric in x
    (two_axes(coupled=0.1), [[1, 1, 1, 1], [-1, -1, -1, -1]]),                              # A couples the groups
    (two_axes(W=Polytope.box([-0.01, -0.01, -0.01, -0.01], [0.02, 0.01, 0.01, 0.01])), [[1, 1, 1, 1], [1, 1, -1, -1]]),
    (two_axes(X={"H": [[0.0, 0.0, 0.0, 1.0]], "h": [5.0]}), [[1, 1, 1, 1]]),                # a state constraint
])
def test_a_flip_the_data_does_not_allow_is_left_out(system, want):
    np.testing.assert_array_equal(system_reflections(system, [0, 0, 1, 1], [0, 1]), want)


def mirrored(P: Polytope, S) -> Polytope:
    lo, hi = P.bounding_box()
    return Polytope.box(np.where(S < 0, -hi, lo), np.where(S < 0, -lo, hi))


def problem(system, a: Polytope, b: Polytope, Z: Polytope, L: int) -> TubeProblem:
    box = (np.minimum(a.bounding_box()[0], b.bounding_box()[0]), np.maximum(a.bounding_box()[1], b.bounding_box()[1]))
    return TubeProblem(system, a, b, convex_hull_of(a, b), Z, L, box)


@pytest.mark.parametrize("L", [2, 4])
def test_a_pair_and_its_mirror_image_share_a_class_and_highs_margin(L):
    system = two_axes()
    Z = Polytope.box([-0.5, -0.25, -0.5, -0.25], [0.5, 0.25, 0.5, 0.25])
    a = Polytope.box([0.0, 0.25, 0.0, -0.5], [1.0, 0.75, 1.0, 0.0])
    b = Polytope.box([1.0, 0.75, 1.0, 0.0], [2.0, 1.25, 2.0, 0.5])
    R = system_reflections(system, [0, 0, 1, 1], [0, 1])
    cells = [a, b] + [P for S in R[1:] for P in (mirrored(a, S), mirrored(b, S))]
    src, dst = np.arange(0, len(cells), 2), np.arange(1, len(cells), 2)
    probs = [problem(system, cells[i], cells[j], Z, L) for i, j in zip(src, dst)]
    decomp = type("D", (), {"cells": cells})()
    obstacle = np.zeros(len(src), bool)
    flat = TranslationClasses(decomp, system).representatives(src, dst, obstacle, probs)
    mirror = TranslationClasses(decomp, system, R).representatives(src, dst, obstacle, probs)
    assert len(set(flat.tolist())) == 4 and set(mirror.tolist()) == {0}
    tube = formulation("tube")
    margins = [solve_margin_lp(tube.build(p, dense=False)).margin for p in probs]
    assert abs(margins[0]) > 0.01                              # not a margin near 0
    np.testing.assert_allclose(margins, margins[0], rtol=0, atol=1e-9)
    # the target moved in y's look-ahead only: not a mirror image of any flip, another class, another margin
    moved = Polytope.box([1.0, 0.75, 1.0, -0.5], [2.0, 1.25, 2.0, 0.0])
    both = type("D", (), {"cells": [a, b, a, moved]})()
    pair = [probs[0], problem(system, a, moved, Z, L)]
    rep = TranslationClasses(both, system, R).representatives([0, 2], [1, 3], [False, False], pair)
    assert rep.tolist() == [0, 1]
    assert abs(solve_margin_lp(tube.build(pair[1], dense=False)).margin - margins[0]) > 1e-3


@pytest.fixture(scope="module")
def lifted():
    """The 6-D drone on the small building (5 storeys, a floor with holes), 4 look-ahead slabs per axis,
    ``L <= 4``: 844 joint pairs, whose projections on two groups are often mirror images."""
    path = Path(__file__).resolve().parents[1] / "conf" / "workspace" / "maps" / "building3d_small.txt"
    d = lift_lookahead(parse_map(path.read_text(), str(path)), [4, 4, 4])
    A, B = double_integrator_lookahead(3, 0.5, 2.0)
    sysm = LinearSystem(A=A.astype(float), B=B.astype(float), U=box_input_set(1.0, 3), W=Ball(6, 0.01))
    ps = build_product_abstraction(d, sysm, zshape="cell", L_max=L_MAX)
    return d, sysm, ps, join_factors(d, ps.structure, ps.tables)


def test_the_screen_refutes_the_same_pair_horizons_with_fewer_lps(lifted):
    _, sysm, ps, joined = lifted
    mirror, flat = ProjectionScreen(ps.structure, sysm), ProjectionScreen(ps.structure, sysm)
    for proj in flat.projections:
        proj.reflections = proj.reflections[:1]
    assert all(len(p.reflections) == 4 for p in mirror.projections)     # two groups: every flip of them
    for L in range(1, L_MAX + 1):
        k = np.flatnonzero((joined.joint_box_mask & (np.uint64(1) << np.uint64(L - 1))) != 0)
        s, t = joined.joint_src[k], joined.joint_dst[k]
        np.testing.assert_array_equal(mirror.refuted(s, t, L), flat.refuted(s, t, L))
    assert flat.n_refuted == mirror.n_refuted > 0
    assert mirror.n_lps < flat.n_lps and mirror.n_translated > flat.n_translated
