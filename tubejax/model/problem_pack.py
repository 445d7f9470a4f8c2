"""Many tube problems through a pipe as a few arrays (the HiGHS helpers' jobs).

A job of translates carries hundreds of :class:`~tubejax.model.problem.TubeProblem` sharing their
system, ``L`` and shapes; :class:`ProblemPack` stacks their polytopes' arrays instead of pickling
each, and unpickles to a plain list of problems with the same values, bit for bit.
"""

from __future__ import annotations

import numpy as np

from .geometry import Polytope
from .problem import TubeProblem, _unchecked

__all__ = ["ProblemPack"]

_SETS = ("source", "target", "safe", "Z")


def _polytope(V: np.ndarray, H: np.ndarray, h: np.ndarray) -> Polytope:
    """A :class:`Polytope` of arrays that came from one (as unpickling makes it, no checks)."""
    P = object.__new__(Polytope)
    P.__dict__.update(vertices=V, H=H, h=h)
    return P


def _packed(problems: list):
    """``(system, L, eps_min, min_margin, arrays)`` of problems that share the first four and
    their sets' shapes, else ``None``."""
    p0 = problems[0]
    if not all(type(p) is TubeProblem for p in problems):
        return None
    head = (p0.system, int(p0.L), float(p0.eps_min), float(p0.min_margin))
    arrays = []
    for name in _SETS:
        sets = [getattr(p, name) for p in problems]
        shapes = {(P.vertices.shape, P.H.shape, P.h.shape) for P in sets}
        if len(shapes) != 1 or not all(type(P) is Polytope for P in sets):
            return None
        arrays += [_stacked([P.vertices for P in sets]), _stacked([P.H for P in sets]), _stacked([P.h for P in sets])]
    if any(p.system is not head[0] or (int(p.L), float(p.eps_min), float(p.min_margin)) != head[1:] for p in problems):
        return None
    box = [np.array([np.asarray(p.box[a], float) for p in problems]) for a in (0, 1)]
    if any(x.ndim != 2 for x in box):
        return None
    return head + (len(problems), tuple(arrays + box))


def _stacked(arrays: list):
    """``arrays`` (equal shapes) stacked, or the first one alone when all are equal bit for bit
    (the facet normals of translates, a grid's ``Z``)."""
    a = np.array(arrays)
    same = np.all(a.view(np.uint64) == a[:1].view(np.uint64)) if a.dtype == np.float64 else False
    return ("one", a[0]) if same else ("each", a)


def _each(item, K: int):
    kind, a = item
    a.setflags(write=False)                 # shared between problems: never changed in place
    return [a] * K if kind == "one" else list(a)


def _unpack(system, L: int, eps_min: float, min_margin: float, K: int, arrays: tuple) -> list:
    """The problems of :func:`_packed`, as a list."""
    sets = [[_polytope(V, H, h) for V, H, h in zip(*(_each(x, K) for x in arrays[3 * a:3 * a + 3]))]
            for a in range(len(_SETS))]
    lo, hi = arrays[-2:]
    return [_unchecked(system, s, t, sf, z, L, (bl, bh), eps_min, min_margin)
            for s, t, sf, z, bl, bh in zip(*sets, lo, hi)]


class ProblemPack(list):
    """A list of :class:`~tubejax.model.problem.TubeProblem` that pickles as stacked arrays when
    they share their system, ``L``, ``eps_min``, ``min_margin`` and set shapes (else as a list),
    and unpickles to a plain ``list`` of equal problems."""

    def __reduce__(self):
        packed = _packed(list(self)) if len(self) > 1 else None
        if packed is None:
            return list, (list(self),)
        return _unpack, packed
