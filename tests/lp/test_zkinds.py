"""The fixed kinds of Z live in one registry (``tubejax.model.zshape.kinds.ZKINDS``).

Every place that needs to know the kinds -- the validated settings, the dimension and method
checks of the inputs, learning's starts, the config group -- derives them from the registry, so a
new kind is one entry there plus its ``conf/zshape/<name>.yaml``.
"""

import re
from pathlib import Path

import numpy as np
import pytest

from tubejax.model.geometry import Polytope
from tubejax.inputs.settings import ZShapeSettings
from tubejax.model.zshape.kinds import FIXED_KINDS, LEARNED_ZSHAPES, ZKINDS, ZSHAPES, make_z, z_kind_problem

ROOT = Path(__file__).resolve().parents[2]


def test_every_kind_has_its_config_and_is_accepted_by_the_settings():
    for name in ZKINDS:
        assert (ROOT / "conf" / "zshape" / f"{name}.yaml").is_file(), name
        assert ZShapeSettings(kind=name).kind == name
    assert set(FIXED_KINDS) == set(ZSHAPES) and len(FIXED_KINDS) == len(ZSHAPES)
    with pytest.raises(ValueError):
        ZShapeSettings(kind="hexagon")


def test_no_other_module_lists_the_kinds():
    """A literal list of kind names outside the registry would miss a new kind."""
    names = "|".join(sorted(ZKINDS, key=len, reverse=True))
    listing = re.compile(rf"""["'](?:{names})["']\s*,\s*["'](?:{names})["']""")
    own = ROOT / "tubejax" / "lp" / "formulations" / "zshape.py"
    bad = [f"{p.relative_to(ROOT)}:{i}" for p in sorted((ROOT / "tubejax").rglob("*.py")) if p != own
           for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1) if listing.search(line)]
    assert not bad, bad


@pytest.mark.parametrize("n, nv", [(2, 4), (2, 3), (2, 6), (3, 8), (4, 16), (3, 4)])
def test_fits_and_dimensions_agree_with_make_z(n, nv):
    """A kind the registry says fits builds a Z with per_vertex * n_v vertices; one it refuses raises."""
    if n == 2:
        ang = 2 * np.pi * np.arange(nv) / nv
        cell = Polytope.from_vertices(np.stack([np.cos(ang), np.sin(ang)], axis=1) + 5.0)
    elif nv == 2 ** n:
        cell = Polytope.box(np.zeros(n), np.ones(n))
    else:
        cell = Polytope.from_vertices(np.vstack([np.zeros(n), np.eye(n)]))       # a simplex
    nv = cell.n_vertices
    for name, k in ZKINDS.items():
        ok = z_kind_problem(name, n) is None and k.fits(n, nv) is None
        if ok:
            Z = make_z(name, cell)
            assert Z.n_vertices == k.per_vertex * nv and np.all(Z.h > 0)         # 0 inside Z
        else:
            with pytest.raises(ValueError, match=name):
                make_z(name, cell)


def test_methods_of_a_kind():
    assert z_kind_problem("chamfer", 2, tubes=False) is not None and z_kind_problem("chamfer", 2) is None
    assert all(z_kind_problem(k, 2) is None for k in ZKINDS)
    assert "unknown zshape" in z_kind_problem("hexagon", 2)
    assert set(LEARNED_ZSHAPES) == {"learned", "learned_pair"}


def test_the_vertex_count_rule_is_stated_once():
    """``Z``'s vertex count against the cell's is one rule (``z_vertex_count_problem``): the
    generating points, the learned tables and the transition files all follow it, and no other
    module restates it (a ``% n_v`` test of a vertex count)."""
    from tubejax.model.zshape.kinds import source_points, z_vertex_count_problem
    from tubejax.transitions.file_format import _z_rows

    square = Polytope.box(np.zeros(2), np.ones(2))
    cube = Polytope.box(np.zeros(3), np.ones(3))
    for cell in (square, cube):
        for n_z in range(1, 3 * cell.n_vertices + 1):
            why = z_vertex_count_problem(n_z, cell.n_vertices, cell.dim)
            assert (why is None) == (n_z == cell.n_vertices or (cell.dim == 2 and n_z % cell.n_vertices == 0))
            if why is None:
                assert source_points(cell, n_z).vertices.shape == (n_z, cell.dim)
            else:
                with pytest.raises(ValueError, match=f"Z has {n_z} vertices"):
                    source_points(cell, n_z)
            stored = _z_rows(np.zeros((n_z, cell.dim)), cell.n_vertices, cell.dim)
            assert stored == (n_z if why is None else cell.n_vertices)
    pattern = re.compile(r"n_vertices\s*%|%\s*\w*\.?n_vertices|%\s*nv\b|%\s*k\s*==\s*0")
    offenders = [str(p.relative_to(ROOT)) for p in (ROOT / "tubejax").rglob("*.py")
                 if p.name != "kinds.py" and pattern.search(p.read_text())]
    assert offenders == []


def test_fixed_kinds_have_dyadic_vertices_near_their_shape():
    """Every rounded fixed kind's ``Z`` lies on the grid of ``on_z_grid`` (short dyadic rationals: the
    same numbers in float64 and in exact arithmetic), within half a grid step of the kind's shape,
    with 0 inside and its vertex count kept; ``cell`` is the cell's shape exactly."""
    from tubejax.model.zshape.kinds import Z_GRID_BITS, on_z_grid

    hexagon = Polytope.from_vertices([[np.cos(a), np.sin(a)] for a in np.pi / 3 * np.arange(6)])
    cells = (Polytope.box(np.zeros(2), np.ones(2)), Polytope.box(np.zeros(2), [3.0, 1.0]), hexagon,
             Polytope.from_vertices([[0.0, 0.0], [1.0, 0.0], [0.3, 0.7]]), Polytope.box(np.zeros(3), np.ones(3)))
    seen = 0
    for cell in cells:
        for name, kind in ZKINDS.items():
            for scale in (1.0, 0.3):
                try:
                    Z = make_z(name, cell, scale)
                except ValueError:
                    continue
                seen += 1
                raw = kind.build(cell.vertices - cell.vertices.mean(axis=0), cell.n_vertices, scale)
                if not kind.rounded:                  # ``cell``: the cell's exact shape, unrounded
                    assert np.array_equal(Z.vertices, raw.vertices), name
                    continue
                step = 2.0 ** (np.floor(np.log2(scale)) - Z_GRID_BITS)
                assert np.array_equal(Z.vertices / step, np.round(Z.vertices / step)), name
                assert np.max(np.abs(Z.vertices - raw.vertices)) <= step / 2, name
                assert np.all(Z.h > 0) and Z.n_vertices == raw.n_vertices
                assert on_z_grid(Z, scale) is Z
    assert seen >= 15


def test_regular_z_of_square_cells_gives_the_box_system():
    """The regular 4-gon is a box: on dyadic vertices it gives the box's transitions, every edge
    proved exactly (with ``cos``/``sin`` floats it lost the zero-margin edges)."""
    import tubejax as tj

    ws = tj.grid_map("1....\n..#..\n....2\n")
    box, reg = (tj.abstract(ws, tj.paper_system(0.2), zshape=z, solver="highs", L_max=6) for z in ("box", "regular"))
    assert [(e.src, e.dst, e.L) for e in reg.edges] == [(e.src, e.dst, e.L) for e in box.edges]
    assert {e.proof for e in reg.edges} == {"exact"}
    assert np.allclose([e.margin for e in reg.edges], [e.margin for e in box.edges], rtol=0, atol=1e-12)
    from tubejax.lp.evidence.exact_problem import exact_tube_data

    prob = next(iter(reg.problems()))[1]                # the exact data's Z: short denominators
    assert max(int(v.denominator) for v in exact_tube_data(prob).Z.V.to_fractions().ravel()) <= 2 ** 10
