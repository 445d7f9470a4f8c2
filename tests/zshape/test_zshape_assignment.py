"""Per-pair Z through the normal Algorithm 2 path (:class:`tubejax.model.zassignment.ZAssignment`)."""

import numpy as np
import pytest

from tubejax.abstraction import build_abstraction, cross_sections
from tubejax.model.geometry import Polytope
from tubejax.transitions.transition_system import TransitionSystem
from tubejax.model.workspace.gridmap import parse_grid_map
from tubejax.model.zassignment import ZAssignment, all_cross_sections, z_of_pair
from tubejax.analyses.zshape import LearnOptions, learn_pair_z, pair_abstraction


@pytest.fixture(scope="module")
def learned(paper_system):
    decomp = parse_grid_map("...\n...")
    system = paper_system(0.2)
    pz = learn_pair_z(decomp, system, init="box", options=LearnOptions(steps=2, learning_rate=0.1, L_max=4),
                      progress=False)
    return decomp, system, pz


def test_assignment_lookups():
    a = Polytope.box([-1.0, -1.0], [1.0, 1.0])
    b = Polytope.box([-1.0, -0.5], [1.0, 0.5])
    Z = ZAssignment((a, a, a), {(0, 2): b})
    assert len(Z) == 3 and Z[1] is a and list(Z) == [a, a, a]
    assert z_of_pair(Z, 0, 2) is b and z_of_pair(Z, 2, 0) is a and z_of_pair((a, a, a), 0, 2) is a
    assert Z.has_pair(0, 2) and not Z.has_pair(2, 0)
    assert all_cross_sections(Z) == [a, b]
    with pytest.raises(ValueError, match=r"pair \(1, 1\)"):
        ZAssignment((a, a), {(1, 1): b})
    with pytest.raises(ValueError, match="not a Polytope"):
        ZAssignment((a, a), {(0, 1): b.vertices})


def test_learned_pair_through_build_abstraction_equals_pair_abstraction(learned, tmp_path):
    decomp, system, pz = learned
    ref = pair_abstraction(decomp, system, pz, L_max=4, fallback="box")
    Z = ZAssignment(cross_sections(decomp, "box", 1.0), pz)
    ts = build_abstraction(decomp, system, z=Z, zshape="learned_pair", L_max=4, progress=False)
    assert [(e.src, e.dst, e.L) for e in ts.edges] == [(e.src, e.dst, e.L) for e in ref.edges]
    assert [e.proof for e in ts.edges] == [e.proof for e in ref.edges]
    np.testing.assert_allclose([e.margin for e in ts.edges], [e.margin for e in ref.edges], atol=1e-9)
    assert ts.stats["zshape"] == "learned_pair" and np.all(ts.verify() <= 1e-9)
    # the per-pair Z of every edge travels with the files and is what the edge is checked against
    ts.save(tmp_path)
    back = TransitionSystem.load(tmp_path)
    assert isinstance(back.Z, ZAssignment)
    for e in back.edges:
        np.testing.assert_array_equal(back.z_of(e.src, e.dst).vertices, pz[(e.src, e.dst)].vertices)
    assert np.all(back.verify() <= 1e-9)


def test_per_pair_z_changes_the_problem(learned):
    decomp, system, pz = learned
    thin = Polytope.box([-1.0, -0.05], [1.0, 0.05])
    box = build_abstraction(decomp, system, L_max=4, progress=False)
    Z = ZAssignment(cross_sections(decomp, "box", 1.0), {(e.src, e.dst): thin for e in box.edges})
    ts = build_abstraction(decomp, system, z=Z, L_max=4, progress=False)
    assert ts.n_edges < box.n_edges and np.all(ts.verify() <= 1e-9)
    with pytest.raises(ValueError, match="one cross-section per cell"):
        build_abstraction(decomp, system, z=Z.per_cell[:2], L_max=4, progress=False)
