"""Problems through the helpers' pipe as stacked arrays (tubejax.model.problem_pack): the problems
that arrive equal the ones sent, bit for bit, and so do their HiGHS verdicts."""

import dataclasses
import pickle

import numpy as np
import pytest

from tubejax.abstraction import cross_sections
from tubejax.lp.evidence.translate_verdicts import highs_translate_verdicts
from tubejax.lp.evidence.verdict import TRANSLATE_EDGE
from tubejax.model.geometry import Ball
from tubejax.model.problem import Pairs, pair_problems
from tubejax.model.problem_pack import ProblemPack
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.workspace import parse_grid_map

FIELDS = ("source", "target", "safe", "Z")


@pytest.fixture(scope="module")
def problems():
    d = parse_grid_map("......\n......\n.#..#.\n......\n")
    s = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
    src = np.array([0, 1, 2, 6, 7, 8])
    dst = src + 1
    return pair_problems(d, s, cross_sections(d, "box", 1.0), Pairs(src, dst, d.obstacle_cases(src, dst)), 3)


def _bits(a):
    a = np.asarray(a)
    return a.dtype, a.shape, a.tobytes()


def test_a_pack_unpickles_to_the_same_problems_bit_for_bit(problems):
    got = pickle.loads(pickle.dumps(ProblemPack(problems)))
    assert type(got) is list and len(got) == len(problems)
    for p, q in zip(problems, got):
        for f in FIELDS:
            for a in ("vertices", "H", "h"):
                assert _bits(getattr(getattr(p, f), a)) == _bits(getattr(getattr(q, f), a))
                assert not getattr(getattr(q, f), a).flags.writeable          # shared: read-only
        assert (p.L, p.eps_min, p.min_margin) == (q.L, q.eps_min, q.min_margin)
        assert all(_bits(x) == _bits(y) for x, y in zip(p.box, q.box))
        assert q.system is got[0].system
    assert len(pickle.dumps(ProblemPack(problems))) < len(pickle.dumps(list(problems)))


def test_problems_that_differ_in_shape_or_horizon_travel_as_a_plain_list(problems):
    mixed = list(problems[:2]) + [dataclasses.replace(problems[2], L=4)]
    got = pickle.loads(pickle.dumps(ProblemPack(mixed)))
    assert type(got) is list and [p.L for p in got] == [3, 3, 4]
    assert pickle.loads(pickle.dumps(ProblemPack([]))) == []


def test_verdicts_of_a_pack_equal_those_of_the_list(problems):
    a = highs_translate_verdicts(list(problems), TRANSLATE_EDGE)
    b = highs_translate_verdicts(pickle.loads(pickle.dumps(ProblemPack(problems))), TRANSLATE_EDGE)
    for x, y in zip(a, b):
        assert (x.status, x.margin, x.provenance) == (y.status, y.margin, y.provenance)
        if x.tube is not None:
            assert all(np.array_equal(u, v) for u, v in zip(x.tube, y.tube))
