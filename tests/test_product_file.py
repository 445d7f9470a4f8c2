"""Saved product systems (tubejax.transitions.product_file, tubejax.abstraction.product_store) and their
verification (``python -m tubejax verify DIR`` on a product run, tubejax.verify.product_run).

A small 4-D double integrator on the 2x2x2x2 ``boxgrid4d`` grid (12 free cells, ``W`` a ball of radius
0.05, ``L_max = 6``) is abstracted by ``tj.abstract(..., product=True)`` and saved; the round trip must give
the same edges and verdicts, the verifier must pass it, and tampered files (an edge without its factor
proof, a changed ``L``, a deleted edge, a changed source) must be refused with a message naming them.
"""

import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import tubejax as tj
from tubejax.__main__ import main as cli
from tubejax.abstraction.product_abstraction import ProductOptions, abstract_auto, build_product_abstraction
from tubejax.abstraction.product_store import ProductProblem, load_product, save_product
from tubejax.api_inputs import box_grid
from tubejax.errors import InputError
from tubejax.model.geometry import Ball, Polytope
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.transitions.file_format import sha256_file
from tubejax.transitions.product_file import PRODUCT_STEM, ProductFileError, read_product_files, verdict_arrays
from tubejax.transitions.provenance import stamp
from tubejax.verify.product_lp import ProductPair, product_lp_margin
from tubejax.verify.verifier import verify_directory

A = np.array([[0.75, 0.25, 0, 0], [-0.25, 1.25, 0, 0], [0, 0, 0.75, 0.25], [0, 0, -0.25, 1.25]])
B = np.array([[0.125, 0], [1.125, 0], [0, 0.125], [0, 1.125]])


def _system(A=A, B=B):
    return LinearSystem(A=A, B=B, U=box_input_set(1.0, 2), W=Ball(4, 0.05))


def _workspace():
    return box_grid([0, 0, 0, 0], [2, 2, 2, 2], [2, 2, 2, 2], obstacles=[([1, 0, 1, 0], [2, 2, 2, 2])])


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    ts = tj.abstract(_workspace(), _system(), zshape="cell", L_max=6, solver="highs", product=True)
    d = tmp_path_factory.mktemp("product_run")
    ts.save(d)
    return ts, d


def _copy(run, tmp_path) -> Path:
    d = tmp_path / "run"
    shutil.copytree(run[1], d)
    return d


def _rewrite(d: Path, **changes):
    """Rewrite the npz with ``changes`` (array name -> new array, ``None`` deletes) and re-hash it in the json,
    so that only the change itself is there to be found."""
    npath, jpath = d / f"{PRODUCT_STEM}.npz", d / f"{PRODUCT_STEM}.json"
    with np.load(npath) as z:
        arrays = {k: z[k] for k in z.files}
    for k, v in changes.items():
        if v is None:
            arrays.pop(k)
        else:
            arrays[k] = v
    np.savez_compressed(npath, **arrays)
    doc = json.loads(jpath.read_text())
    doc["npz_sha256"] = sha256_file(npath)
    jpath.write_text(json.dumps(stamp(doc)))


def test_round_trip_gives_the_same_system(run):
    ts, d = run
    ps = ts.product
    assert ps.n_edges > 0 and (d / "product_transitions.json").is_file()
    back = load_product(d)
    for name in ("src", "dst", "L", "variant"):
        np.testing.assert_array_equal(getattr(back, name), getattr(ps, name))
    np.testing.assert_array_equal(back.margin, ps.margin)
    np.testing.assert_array_equal(back.structure.cell_factor, ps.structure.cell_factor)
    for t0, t1 in zip(ps.tables, back.tables):
        np.testing.assert_array_equal(t0.feasible, t1.feasible)
        for key, v in t0.verdicts.items():
            if v.status == "edge":
                w = t1.verdicts[key]
                assert w.margin == v.margin and w.proof.level == v.proof.level
                for a, b in zip(v.tube, w.tube):
                    np.testing.assert_array_equal(np.asarray(a), b)
    for k in range(ps.n_edges):                   # the assembled tubes are the same
        for a, b in zip(ps.tube(k)[:3], back.tube(k)[:3]):
            np.testing.assert_array_equal(a, b)
    again = load_product(d, ProductProblem(ps.decomposition, ps.system, ps.Z))   # the problem given, no sources
    assert again.n_edges == ps.n_edges


def test_verify_passes_a_product_run_and_checks_it_against_highs(run, capsys):
    ts, d = run
    rep = verify_directory(d, complete=True, sample=6)
    assert rep.ok, rep.findings
    assert rep.n_edges == ts.n_edges and rep.n_resolved > 0 and sum(rep.proof_counts.values()) > 0
    assert "factor tables complete" in rep.headline
    assert cli(["verify", str(d), "--quiet"]) == 0
    assert "verify OK" in capsys.readouterr().out
    assert tj.verify(ts).ok                       # in memory: saved as a product run, then verified
    ps = ts.product                               # the sampled HiGHS margins agree with the system's L
    groups = [f.axes for f in ps.structure.factors]
    for k in range(min(3, ps.n_edges)):
        i, j, L = int(ps.src[k]), int(ps.dst[k]), int(ps.L[k])
        lo, hi = ps.decomposition.cell_boxes()
        if ps.variant[k] == 0:
            safe = Polytope.box(np.minimum(lo[i], lo[j]), np.maximum(hi[i], hi[j]))
            pair = ProductPair(ps.decomposition.cells[i], ps.decomposition.cells[j], safe, ps.Z[i])
            assert product_lp_margin(ps.system, pair, groups, L) >= -1e-9


def test_an_edge_without_its_factor_proof_is_refused(run, tmp_path):
    ts, d0 = run
    d = _copy(run, tmp_path)
    ps = ts.product
    g0 = ps.structure.cell_factor
    i, j, L = int(ps.src[0]), int(ps.dst[0]), int(ps.L[0])
    with np.load(d / f"{PRODUCT_STEM}.npz") as z:
        key = z["g0_key"]
    a, b = int(g0[i, 0]), int(g0[j, 0])
    v = 0 if a == b else int(ps.variant[0])
    keep = ~np.all(key == [v, L, a, b], axis=1)
    assert not keep.all()
    changes = {"g0_key": key[keep]}
    back = load_product(d0)
    verdicts = [back.tables[0].verdicts[tuple(k)] for k in key[keep].tolist()]
    changes.update(verdict_arrays("g0_", verdicts))      # the verdict removed with its key
    _rewrite(d, **changes)
    with pytest.raises(ProductFileError, match=r"edge 0 .*has no factor proof in group 0"):
        read_product_files(d)
    rep = verify_directory(d)
    assert not rep.ok and "has no factor proof in group 0" in rep.findings[0]


def test_a_changed_L_is_found(run, tmp_path):
    ts, d0 = run
    ps = ts.product
    L = ps.L.copy()
    k = int(np.flatnonzero(L < ps.L_max)[0])
    with np.load(d0 / f"{PRODUCT_STEM}.npz") as z:
        fine = z["edge_L"]
    # an L larger than the least feasible one: either no proof at that L, or not the least L
    for new in range(int(L[k]) + 1, ps.L_max + 1):
        d = tmp_path / f"L{new}"
        shutil.copytree(d0, d)
        bad = fine.copy()
        bad[k] = new
        _rewrite(d, edge_L=bad)
        rep = verify_directory(d)
        assert not rep.ok
        assert any(f"edge {k} " in f and "no factor proof" in f for f in rep.findings) or \
            any(f"{ps.src[k]}->{ps.dst[k]}" in f and "least L" in f for f in rep.findings), rep.findings


def test_a_deleted_edge_is_found(run, tmp_path):
    ts, d0 = run
    ps = ts.product
    d = _copy(run, tmp_path)
    keep = np.arange(ps.n_edges) != 0
    with np.load(d0 / f"{PRODUCT_STEM}.npz") as z:
        changes = {name: z[name][keep] for name in ("edge_src", "edge_dst", "edge_L", "edge_margin", "edge_variant")}
    _rewrite(d, **changes)
    rep = verify_directory(d)
    assert not rep.ok
    assert any(f"pair {ps.src[0]}->{ps.dst[0]}" in f and "but not an edge" in f for f in rep.findings), rep.findings


def test_damaged_files_name_the_file_and_field(run, tmp_path):
    d = _copy(run, tmp_path)
    _rewrite(d, cell_factor=None)
    with pytest.raises(ProductFileError, match="missing array 'cell_factor'"):
        read_product_files(d)
    d2 = tmp_path / "hash"
    shutil.copytree(run[1], d2)
    with open(d2 / f"{PRODUCT_STEM}.npz", "ab") as f:
        f.write(b"x")
    with pytest.raises(ProductFileError, match="SHA-256 differs"):
        read_product_files(d2)
    rep = verify_directory(d2)
    assert not rep.ok and "product_transitions.npz" in rep.findings[0]


def test_product_auto_falls_back_to_the_joint_lps_saying_why():
    c, s = np.cos(0.3), np.sin(0.3)
    R = np.kron(np.array([[c, -s], [s, c]]), np.eye(2))
    rot = LinearSystem(A=R @ A @ R.T, B=R @ B, U=box_input_set(1.0, 2), W=Ball(4, 0.05))
    ws = _workspace()
    with pytest.warns(UserWarning, match="couple all 4 state axes"):
        ts = tj.abstract(ws, rot, zshape="cell", L_max=1, solver="highs", product="auto")
    assert not hasattr(ts, "product") or ts.product is None
    with pytest.raises(InputError, match="product: .*couple"):
        tj.abstract(ws, rot, zshape="cell", L_max=1, solver="highs", product=True)
    with pytest.raises(InputError, match="product: expected"):
        tj.abstract(ws, rot, product="maybe")
    res, why = abstract_auto(ws.decomposition, rot, ProductOptions(L_max=1))
    assert "couple" in why and res.n_edges >= 0


def test_options_record_and_save_refuses_an_unproved_edge(run, tmp_path):
    ts, _ = run
    ps = ts.product
    with pytest.raises(TypeError, match="L_mx: not a field"):
        build_product_abstraction(ps.decomposition, ps.system, L_mx=3)
    with pytest.raises(ValueError, match="L_max must be an integer in 1..63"):
        ProductOptions(L_max=64)
    t0 = ps.tables[0]
    cf = ps.structure.cell_factor
    k = 0
    need = (0 if cf[ps.src[k], 0] == cf[ps.dst[k], 0] else int(ps.variant[k]), int(ps.L[k]),
            int(cf[ps.src[k], 0]), int(cf[ps.dst[k], 0]))
    verdicts = {key: v for key, v in t0.verdicts.items() if key != need}
    if need[2] == need[3]:
        verdicts.pop((1,) + need[1:], None)
    bad = replace(ps, tables=(replace(t0, verdicts=verdicts),) + ps.tables[1:])
    with pytest.raises(ValueError, match=r"has no confirmed verdict in group 0; the system cannot be saved"):
        save_product(bad, tmp_path / "bad")
    assert not (tmp_path / "bad" / "product_transitions.json").exists()
    # the last edge's verdict in the last group: the first edge (in edge order) that needs that verdict is named
    g, k = len(ps.tables) - 1, ps.n_edges - 1
    key = (int(ps.variant[k]), int(ps.L[k]), int(cf[ps.src[k], g]), int(cf[ps.dst[k], g]))
    tg = ps.tables[g]
    bad = replace(ps, tables=ps.tables[:g] + (replace(tg, verdicts={q: v for q, v in tg.verdicts.items() if q != key}),))
    first = next(e for e in range(ps.n_edges) if (int(ps.variant[e]), int(ps.L[e]), int(cf[ps.src[e], g]),
                                                   int(cf[ps.dst[e], g])) == key)
    with pytest.raises(ValueError, match=rf"^edge {ps.src[first]}->{ps.dst[first]} \(L={ps.L[first]}\): .* group {g};"):
        save_product(bad, tmp_path / "bad")


def test_edges_in_any_order_load_as_stored_and_a_repeated_pair_is_refused(run, tmp_path):
    """The duplicate-pair check of the reader: a saved file's edges are sorted by ``(src, dst)`` (checked by
    one comparison), a hand-written file's need not be (checked by a sort); both find a repeated pair."""
    ts, d0 = run
    ps = ts.product
    names = ("edge_src", "edge_dst", "edge_L", "edge_margin", "edge_variant")
    with np.load(d0 / f"{PRODUCT_STEM}.npz") as z:
        edges, joint_edge = {k: z[k] for k in names}, z["joint_edge"]
    assert np.all(np.diff(edges["edge_src"] * ps.n_cells + edges["edge_dst"]) > 0)     # as saved: sorted
    back = load_product(d0)
    for name in names:                                     # loaded array for array, dtype included
        got = getattr(back, name.removeprefix("edge_"))
        assert got.dtype == edges[name].dtype and np.array_equal(got, edges[name])
    perm = np.random.default_rng(0).permutation(ps.n_edges)
    d = tmp_path / "shuffled"
    shutil.copytree(d0, d)
    _rewrite(d, joint_edge=np.sort(np.argsort(perm)[joint_edge]), **{k: v[perm] for k, v in edges.items()})
    shuffled = load_product(d)
    for name in names:
        np.testing.assert_array_equal(getattr(shuffled, name.removeprefix("edge_")), edges[name][perm])
    for where in (1, ps.n_edges):                          # edge 0 again: next to itself (sorted), at the end
        d = tmp_path / f"twice{where}"
        shutil.copytree(d0, d)
        _rewrite(d, **{k: np.insert(v, where, v[0]) for k, v in edges.items()})
        with pytest.raises(ProductFileError, match="'edge_src', 'edge_dst': a pair is listed twice"):
            read_product_files(d)


def test_joint_edges_load_as_saved_and_a_factor_edge_after_them_is_named(tmp_path):
    """A system with joint edges (the corner of tests/test_product.py: (0, 7) and (7, 0) are joint): saved and
    loaded array for array with its joint verdicts; a factor edge whose ``L`` has no proof is named by its
    index in the file, the joint edges before it counted."""
    d = box_grid([0, 0], [3, 3], [3, 3], obstacles=[([2, 0], [3, 1])])
    sysm = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.1))
    ps = build_product_abstraction(d.decomposition, sysm, zshape="box", L_max=6)
    save_product(ps, tmp_path / "ok")
    back = load_product(tmp_path / "ok", ProductProblem(ps.decomposition, ps.system, ps.Z))
    for name in ("src", "dst", "L", "margin", "variant"):
        np.testing.assert_array_equal(getattr(back, name), getattr(ps, name))
    joint = np.flatnonzero(ps.variant == 2)
    assert {(int(ps.src[k]), int(ps.dst[k])) for k in joint} == {(0, 7), (7, 0)} and set(back.joint) == {(0, 7), (7, 0)}
    for pair, v in back.joint.items():
        for a, b in zip(ps.joint[pair].tube, v.tube):
            np.testing.assert_array_equal(np.asarray(a), b)
    cf = ps.structure.cell_factor
    k, L = next((k, L) for k in range(ps.n_edges - 1, joint[0], -1) if ps.variant[k] != 2 for L in range(1, 7)
                if any((0 if cf[ps.src[k], g] == cf[ps.dst[k], g] else int(ps.variant[k]), L, int(cf[ps.src[k], g]),
                        int(cf[ps.dst[k], g])) not in t.verdicts for g, t in enumerate(ps.tables)))
    with np.load(tmp_path / "ok" / f"{PRODUCT_STEM}.npz") as z:
        bad = z["edge_L"].copy()
    bad[k] = L
    _rewrite(tmp_path / "ok", edge_L=bad)
    with pytest.raises(ProductFileError, match=rf"edge {k} \({ps.src[k]} -> {ps.dst[k]}, L={L}, .*has no factor proof"):
        read_product_files(tmp_path / "ok")
