"""Shards of a product run (ProductOptions(shard_count, shard_index), tubejax.verify.product_merge).

On the small 4-D double integrator of tests/test_product_file.py (2x2x2x2 ``boxgrid4d`` grid, one obstacle),
shards 0 and 1 of 2 join disjoint source ranges that cover every cell; merged, they give exactly the
edges, ``L``, variants and margins of the unsharded product run, and the merged files verify. A shard
set with a shard missing or given twice, or shards of different inputs, is refused naming it.
"""

import copy
import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

import tubejax as tj
from tubejax.abstraction.product_abstraction import ProductOptions, build_product_abstraction
from tubejax.abstraction.product_join import JOINT_PAIR_WEIGHT, join_factors, join_weights, shard_weights
from tubejax.abstraction.product_store import ProductRun, load_product, save_product
from tubejax.abstraction.shards import source_range, weighted_owner
from tubejax.api_inputs import box_grid
from tubejax.model.geometry import Ball
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.verify.product_merge import merge_product_shards
from tubejax.verify.shard_merge import MergeError
from tubejax.verify.verifier import verify_directory

from test_product_file import _system, _workspace

ROOT = Path(__file__).resolve().parents[1]


def _sharded(full, count: int, base, zshape: str) -> list:
    """Shards ``0..count-1`` of the product run ``full``, each saved in ``base/k``."""
    ps, dirs = full.product, []
    for k in range(count):
        rec = copy.deepcopy(full.inputs)
        rec["abstraction"]["shard"] = {"count": count, "index": k}
        opts = ProductOptions(L_max=6, zshape=zshape, shard_count=count, shard_index=k)
        part = build_product_abstraction(ps.decomposition, ps.system, opts, Z=ps.Z)
        ProductRun.of_product(part, rec).save(base / str(k))
        dirs.append(base / str(k))
    return dirs


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The unsharded run and the directories of shards 0 and 1 of 2."""
    full = tj.abstract(_workspace(), _system(), zshape="cell", L_max=6, solver="highs", product=True)
    return full, _sharded(full, 2, tmp_path_factory.mktemp("product_shards"), "cell")


def test_source_ranges_partition_the_cells():
    w = np.array([3.0, 0.0, 5.0, 1.0, 1.0, 7.0, 2.0])
    for count in (1, 2, 3, 7, 9):
        ranges = [source_range(w, count, k) for k in range(count)]
        assert ranges[0][0] == 0 and ranges[-1][1] == len(w)
        assert all(a[1] == b[0] for a, b in zip(ranges, ranges[1:]))            # contiguous, disjoint
        owner = weighted_owner(w, count)
        for k, (start, stop) in enumerate(ranges):
            assert np.all(owner[start:stop] == k)


def test_shards_join_their_own_sources(runs):
    full, dirs = runs
    ps = full.product
    everything = join_factors(ps.decomposition, ps.structure, ps.tables)
    weights = shard_weights(ps.structure, ps.tables, everything.joint_src)
    assert weights.sum() > 0
    n = 0
    for k, d in enumerate(dirs):
        part = load_product(d)
        start, stop = source_range(weights, 2, k)
        assert part.stats["shard"]["start"] == start and part.stats["shard"]["stop"] == stop
        assert np.all((part.src >= start) & (part.src < stop))
        n += part.n_edges
    assert n == ps.n_edges and 0 < load_product(dirs[0]).n_edges < n


def test_shard_weights_count_the_joint_pairs_of_each_source(corner):
    """A source's work: the pairs the join enumerates from it plus JOINT_PAIR_WEIGHT per joint pair, counted
    here from the join's own lists (the corner grid has joint pairs)."""
    ps = corner.product
    everything = join_factors(ps.decomposition, ps.structure, ps.tables)
    w = shard_weights(ps.structure, ps.tables, everything.joint_src)
    base = join_weights(ps.structure, ps.tables)
    for i in range(ps.n_cells):
        assert w[i] == base[i] + JOINT_PAIR_WEIGHT * sum(int(s) == i for s in everything.joint_src)
    assert len(everything.joint_src) > 0


def test_the_rows_of_a_source_range_are_the_join_of_that_range(runs):
    """JoinedEdges.of_sources against join_factors run on the range alone (the same rows, in the same order)."""
    ps = runs[0].product
    everything = join_factors(ps.decomposition, ps.structure, ps.tables)
    N = ps.n_cells
    for start, stop in ((0, N), (0, N // 3), (N // 3, N), (2, 2), (1, N - 1)):
        own = join_factors(ps.decomposition, ps.structure, ps.tables, sources=(start, stop))
        cut = everything.of_sources(start, stop)
        for f in ("src", "dst", "L", "margin", "variant", "joint_src", "joint_dst", "joint_box_mask", "box_tested"):
            assert np.array_equal(getattr(cut, f), getattr(own, f)), (start, stop, f)
        assert cut.n_box_tested == own.n_box_tested


def test_merge_refuses_ranges_that_do_not_cut_the_cells(runs, tmp_path):
    _, dirs = runs
    other = tmp_path / "gap"
    shutil.copytree(dirs[1], other)
    part = load_product(other)
    rec = json.loads((other / "product_transitions.json").read_text())["inputs"]
    part.stats["shard"]["start"] += 1                     # a source cell no shard owns
    save_product(part, other, rec)
    with pytest.raises(MergeError, match="do not continue the shards before it"):
        merge_product_shards([dirs[0], other])


def test_merged_shards_equal_the_unsharded_run_and_verify(runs, tmp_path):
    full, dirs = runs
    ps = full.product
    merged, record = merge_product_shards(dirs[::-1])
    assert record["abstraction"]["shard"] == {"count": 1, "index": 0}
    for f in ("src", "dst", "L", "variant"):
        assert np.array_equal(getattr(merged, f), getattr(ps, f)), f
    assert np.allclose(merged.margin, ps.margin, rtol=0, atol=0)
    assert set(merged.joint) == {(int(ps.src[k]), int(ps.dst[k])) for k in np.flatnonzero(ps.variant == 2)}
    assert merged.stats["n_joint_pairs"] == ps.stats["n_joint_pairs"]
    assert merged.stats["n_box_tested"] == ps.stats["n_box_tested"]
    save_product(merged, tmp_path / "merged", record)
    rep = verify_directory(tmp_path / "merged")
    assert rep.ok, rep.findings


def test_missing_or_duplicated_shard_refused(runs, tmp_path):
    _, dirs = runs
    with pytest.raises(MergeError, match="missing shard 1 of 2"):
        merge_product_shards([dirs[0]])
    twin = tmp_path / "twin"
    shutil.copytree(dirs[1], twin)
    with pytest.raises(MergeError, match="shard 1 appears twice"):
        merge_product_shards([dirs[0], dirs[1], twin])


def test_shards_of_different_inputs_refused(runs, tmp_path):
    _, dirs = runs
    other = tmp_path / "other"
    shutil.copytree(dirs[1], other)
    jpath = other / "product_transitions.json"
    doc = json.loads(jpath.read_text())
    doc["inputs"]["abstraction"]["L_max"] = 5
    jpath.write_text(json.dumps(doc))
    with pytest.raises(MergeError, match="inputs.abstraction.L_max: 6 in .*, 5 in"):
        merge_product_shards([dirs[0], other])


def test_product_options_refuse_a_bad_shard():
    with pytest.raises(ValueError, match="shard_index must be in"):
        ProductOptions(shard_count=2, shard_index=2)


@pytest.fixture(scope="module")
def corner():
    """tests/test_product.py's corner grid: blocked bounding boxes ('source' edges) and two joint edges."""
    ws = box_grid([0, 0], [3, 3], [3, 3], obstacles=[([2, 0], [3, 1])])
    sysm = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.1))
    return tj.abstract(ws, sysm, zshape="box", L_max=6, solver="highs", product=True)


def test_three_shards_with_joint_and_source_edges(corner, tmp_path):
    full = corner
    ps = full.product
    assert set(ps.variant.tolist()) == {0, 1, 2}
    merged, record = merge_product_shards(_sharded(full, 3, tmp_path, "box"))
    for f in ("src", "dst", "L", "variant", "margin"):
        assert np.array_equal(getattr(merged, f), getattr(ps, f)), f
    assert set(merged.joint) == {(0, 7), (7, 0)}
    save_product(merged, tmp_path / "merged", record)
    rep = verify_directory(tmp_path / "merged")
    assert rep.ok, rep.findings


def test_a_shard_verifies_on_its_own_and_a_mislabelled_one_is_refused(runs, tmp_path):
    _, dirs = runs
    for d in dirs:
        rep = verify_directory(d)
        assert rep.ok, rep.findings
    other = tmp_path / "mislabelled"
    shutil.copytree(dirs[0], other)
    jpath = other / "product_transitions.json"
    doc = json.loads(jpath.read_text())
    doc["inputs"]["abstraction"]["shard"]["index"] = 1        # shard 0's edges, claimed to be shard 1's
    jpath.write_text(json.dumps(doc))
    rep = verify_directory(other)
    assert not rep.ok
    assert any("claims shard 1 of 2" in f for f in rep.findings)
    assert any("but not an edge" in f for f in rep.findings)  # shard 1's own pairs are missing


def test_merge_app_merges_a_product_sweep_and_refuses_a_mixed_one(runs, tmp_path, capsys):
    """experiments/merge.py on a sweep of product shards (each a finished run directory)."""
    _, dirs = runs
    sys.path.insert(0, str(ROOT / "experiments"))
    try:
        from merge import main as merge_main
    finally:
        sys.path.remove(str(ROOT / "experiments"))
    sweep = tmp_path / "sweep"
    for k, d in enumerate(dirs):
        shutil.copytree(d, sweep / str(k))
    assert merge_main([str(sweep)]) == 0
    assert "merged 2 product shards" in capsys.readouterr().out
    assert verify_directory(sweep / "merged").ok
    (sweep / "2").mkdir()
    (sweep / "2" / "transitions.json").write_text("{}")
    assert merge_main([str(sweep)]) == 2
    assert "a joint-LP shard (transitions.json) among product shards" in capsys.readouterr().err


def test_abstract_takes_shards_that_merge_into_the_unsharded_run(runs, tmp_path):
    """``tj.abstract(product=True, shard_count=K, shard_index=k)``: saved and merged, the three shards give the
    unsharded run's edges, ``L``, variants and margins (compared with the run of the module fixture)."""
    full, _ = runs
    ps = full.product
    dirs = []
    for k in range(3):
        part = tj.abstract(_workspace(), _system(), zshape="cell", L_max=6, solver="highs", product=True,
                           shard_count=3, shard_index=k)
        assert part.inputs["abstraction"]["shard"] == {"count": 3, "index": k}
        assert np.all(part.product.src >= part.product.stats["shard"]["start"])
        part.save(tmp_path / str(k))
        dirs.append(tmp_path / str(k))
    merged, record = merge_product_shards(dirs)
    assert record["abstraction"]["shard"] == {"count": 1, "index": 0}
    for f in ("src", "dst", "L", "variant", "margin"):
        assert np.array_equal(getattr(merged, f), getattr(ps, f)), f
    assert 0 < load_product(dirs[0]).n_edges < ps.n_edges


@pytest.mark.parametrize("fields, match", [
    ({"shard_count": 2, "shard_index": 2}, r"shard_index: expected an integer in \[0, 1\] \(shard_count = 2\), got 2"),
    ({"shard_count": 0}, r"shard_count: expected an integer in \[1, 100000\], got 0"),
    ({"shard_count": 2, "shard_index": -1}, r"shard_index: expected an integer in \[0, 1\]"),
    ({"shard_count": 2.0}, r"shard_count: expected an integer, got 2\.0"),
    ({"shard_index": True}, r"shard_index: expected an integer, got True"),
    ({"shard_count": 2, "product": False}, r"shard_count: tubejax.abstract shards product runs only"),
])
def test_abstract_refuses_a_bad_shard_by_name(fields, match):
    kw = {"zshape": "cell", "L_max": 6, "solver": "highs", "product": True, **fields}
    with pytest.raises(tj.InputError, match=match):
        tj.abstract(_workspace(), _system(), **kw)


def test_abstract_refuses_a_shard_of_a_coupled_problem():
    """``product='auto'`` on a coupled problem falls back to the joint LPs, which tj.abstract does not shard."""
    ws = box_grid([0, 0], [2, 2], [2, 2])
    sysm = LinearSystem(A=np.array([[1.0, 0.5], [0.0, 1.0]]), B=0.5 * np.eye(2), U=box_input_set(1.0, 2),
                        W=Ball(2, 0.05))
    with pytest.raises(tj.InputError, match="shard_count > 1 takes a product run"):
        tj.abstract(ws, sysm, zshape="box", L_max=3, solver="highs", product="auto", shard_count=2, shard_index=1)
