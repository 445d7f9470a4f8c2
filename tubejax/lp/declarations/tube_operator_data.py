"""The per-instance coefficients of the matrix-free tube operator, read off the row families.

:func:`build_tube_data` stacks a group of tube problems as the :class:`~.tube_operator.TubeData` of
:func:`~.tube_operator.tube_matvec`. Every coefficient and right-hand side is taken by family name
from the unit-normalised dense rows (:func:`~.tube_lp.margin_rows`); nothing here writes a row of
Problem 2. The coefficients do not depend on the step (except the dynamics at ``l = 0``), so they are
read at horizon 2 and applied at every step; ``tests/lp/test_row_families.py`` holds ``K`` to the
dense rows at other horizons. Problems with the same :func:`~.tube_lp.rows_key` share a derivation.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple, Sequence

import numpy as np

from ...model.geometry import support
from .tube_lp import margin_rows, rows_key, tube_hard_rows
from .tube_variables import BOUND_FAMILIES, TubeIndex, tube_variable_bounds_batch
from ...model.problem import TubeProblem
from .tube_families import TUBE_FAMILIES, Dynamics, InputIn, VertexIn, float_terms, region_sets, system_regions
from .row_families import FamilyDataError, active, dense_rhs, role_names
from .margin_operator import OperatorShape, batched_input_block, hard_families, input_facets, padded_horizon
from .tube_operator import SHARED_FIELDS, TubeData, VertexBlock

__all__ = ["build_tube_data", "vertex_families", "unmodelled_families", "facet_counts"]


def _margin_families(system) -> tuple:
    """``system``'s margin families and whether they are ``VertexIn`` ones followed by one ``Dynamics``
    (the operator's row order)."""
    margin = [f for f in active(TUBE_FAMILIES, system_regions(system)) if f.lp_role(None, system.u_is_box) == "margin"]
    n_vin = sum(isinstance(f, VertexIn) for f in margin)
    return margin, [type(f) for f in margin] == [VertexIn] * n_vin + [Dynamics]


def unmodelled_families(system) -> tuple:
    """The families of ``system``'s tube LP that the matrix-free operator does not model, by name:
    a ``hard`` family other than one ``InputIn`` (:class:`~.margin_operator.InputBlock`), a ``bound`` family other than
    :data:`~.tube_variables.BOUND_FAMILIES`, and margin families other than ``VertexIn`` ones followed by
    the one ``Dynamics`` family. A problem with one goes to HiGHS (the formulation's ``batched`` is false).
    """
    roles = role_names(TUBE_FAMILIES, system_regions(system), system.u_is_box)
    out = [f.name for f in hard_families(system) if type(f) is not InputIn]
    out += [nm for nm in roles.get("bound", ()) if nm not in BOUND_FAMILIES]
    margin, ordered = _margin_families(system)
    return tuple(out if ordered else out + [f.name for f in margin if not isinstance(f, VertexIn)])


def vertex_families(system) -> tuple:
    """The ``VertexIn`` margin families of :data:`TUBE_FAMILIES` that ``system``'s problems have, in order.

    Raises
    ------
    FamilyDataError
        When the margin families are not ``VertexIn`` ones followed by one ``Dynamics`` family.
    """
    margin, ordered = _margin_families(system)
    if not ordered:
        raise FamilyDataError("the tube operator models VertexIn families followed by one Dynamics "
                              f"family, not {[f.name for f in margin]}")
    return tuple(margin[:-1])


def facet_counts(prob: TubeProblem) -> tuple:
    """The facet count of each ``VertexIn`` family's set for ``prob`` (padded by the engine)."""
    sets = region_sets(prob)
    return tuple(int(sets[f.region].H.shape[0]) for f in vertex_families(prob.system))


def _first_step(kind: str) -> int:
    """The step ``l`` of a ``VertexIn`` family's first rows at horizon 2."""
    return {"interior": 1, "last": 2, "all": 1}[kind]


class _ReadRows(NamedTuple):
    """What the operator reads off the unit rows of a group at horizon 2 (everything but the
    right-hand sides, which :func:`_group_rhs` computes per problem)."""

    nrm: np.ndarray          # (R,) the rows' scales
    families: tuple          # per VertexIn family: (slice of its rows, their grid shape, a (f, n), b (f,))
    dynamics: slice          # the dynamics rows
    blocks: dict             # TubeData's dyn0_* and dyn_* coefficients: (n_v, f_z, ...) each
    R: np.ndarray | None     # radius form: rho's coefficient per row


def _read_rows(p0: TubeProblem, W0, ix: TubeIndex, vin: tuple) -> _ReadRows:
    """The coefficients of the problems that share ``p0``'s rows (at horizon 2; views of the
    memoised rows of :func:`~.tube_lp.margin_rows`, not to be written); ``W0``: the radius form.

    They are not memoised again here: most groups' rows are met once (every pair has its own ``Z``
    and pair hull; docs/explanation/performance.md#memoised-lp-rows)."""
    sysm = p0.system
    n, m, nv, fz = sysm.n, sysm.m, p0.source.n_vertices, p0.Z.H.shape[0]
    terms0 = float_terms(p0)
    G, _, nrm, layout = margin_rows(p0, terms0, rhs=False)
    families = []
    for fam in vin:
        sl, grid = layout.slice(fam.name), layout.shape(fam.name)
        rows = G[sl].reshape(grid + (ix.size,))[0]                                   # (f, n_x) at the first step
        l0 = _first_step(fam.steps)
        families.append((sl, grid, rows[:, ix.p_col(l0, 0):ix.p_col(l0, 0) + n], rows[:, ix.eps_col(l0)]))
    dyn = layout.slice("dynamics")
    D = G[dyn].reshape(2, nv, fz, ix.size)
    kv = np.arange(nv)
    u_cols = lambda ell: ix.u_col(ell, 0, 0) + kv[:, None] * m + np.arange(m)[None, :]  # noqa: E731
    pc = lambda ell: slice(ix.p_col(ell, 0), ix.p_col(ell, 0) + n)                      # noqa: E731
    blocks = {"dyn0_p_next": D[0][..., pc(1)], "dyn0_eps_next": D[0][..., ix.eps_col(1)],
              "dyn0_u": D[0][kv[:, None, None], np.arange(fz)[None, :, None], u_cols(0)[:, None, :]],
              "dyn_p": D[1][..., pc(1)], "dyn_eps": D[1][..., ix.eps_col(1)],
              "dyn_u": D[1][kv[:, None, None], np.arange(fz)[None, :, None], u_cols(1)[:, None, :]],
              "dyn_p_next": D[1][..., pc(2)], "dyn_eps_next": D[1][..., ix.eps_col(2)]}
    R = None
    if W0 is not None:                                 # W = rho W0: rho's column
        R = np.zeros(G.shape[0])
        R[dyn] = np.broadcast_to(support(W0, terms0.Z.H), layout.shape("dynamics")).ravel() / nrm[dyn]
    return _ReadRows(nrm, tuple(families), dyn, blocks, R)


def _group_rhs(two: Sequence[TubeProblem], nrm: np.ndarray, W0, vin: tuple) -> np.ndarray:
    """Each problem's right-hand sides on its group's unit rows (scales ``nrm``), ``(K, R)``;
    without ``sigma_W`` in the radius form (``W0`` given). ``vin``: the ``VertexIn`` families."""
    p0 = two[0]
    h = {f.region: np.array([region_sets(p)[f.region].h for p in two]) for f in vin}
    terms = float_terms(p0, V=np.array([p.source.vertices for p in two]), h=h)
    if W0 is not None:
        terms = terms._replace(sigma_w=np.zeros_like(terms.sigma_w))
    return dense_rhs(terms, "margin", p0.system.u_is_box, TUBE_FAMILIES) / nrm


def build_tube_data(problems: Sequence[TubeProblem], f_v: tuple | None = None, L_pad: int | None = None,
                    share: bool = False, W0=None) -> tuple[OperatorShape, TubeData]:
    """Stack problems sharing ``(n, m, n_v, f_z)`` and one system as operator data.

    Parameters
    ----------
    problems : sequence of TubeProblem, length B (horizons may differ)
    f_v : tuple of int, optional
        Padded facet count of each ``VertexIn`` family (default: the largest in the group).
    L_pad : int, optional
        Padded horizon (default: the largest ``L``). An instance with ``L < L_pad``
        keeps its rows through ``last_step``, ``before_horizon``, ``within_horizon``; its variables beyond ``L``
        are unconstrained (only boxed), so margins and certificates are unchanged.
    share : bool
        When the dynamics coefficients (:data:`SHARED_FIELDS`, which depend only on ``Z``,
        ``A``, ``B`` and ``W``) are the same for every problem -- one ``Z`` for all pairs, as
        with the ``box`` shape -- store them once, with a batch axis of length 1 that broadcasts.
    W0 : Ball or Polytope, optional
        The radius form (docs/math/radius.md) for ``W = rho W0``: right-hand sides without
        ``sigma_W``, ``dyn0_rho`` / ``dyn_rho`` hold ``rho``'s coefficients, the variable bounds are those
        valid at every ``rho >= 0`` and ``shape.form`` is ``'radius'``.

    Returns
    -------
    shape : OperatorShape
    data : TubeData of NumPy float64 arrays, batch axis last (length ``B``, or 1 for a shared field)
    """
    p0 = problems[0]
    sysm = p0.system
    n, m = sysm.n, sysm.m
    nv, fz = p0.source.n_vertices, p0.Z.H.shape[0]
    L, *masks = padded_horizon(problems, L_pad)
    for p in problems:
        if (p.source.n_vertices, p.Z.H.shape[0]) != (nv, fz) or p.system is not sysm:
            raise ValueError("build_tube_data needs one system and equal (n_v, f_z) in a group")
    missing = unmodelled_families(sysm)
    if missing:
        raise FamilyDataError(f"row family {missing[0]!r}: the tube operator does not model it, so these problems "
                              "have no operator data (their formulation sends them to HiGHS)")
    vin = vertex_families(sysm)
    if f_v is None:                                             # the engine passes its padded counts
        counts = np.array([facet_counts(p) for p in problems]).reshape(len(problems), len(vin))
        f_v = counts.max(axis=0)
    f_v = tuple(int(c) for c in f_v)
    two = [dataclasses.replace(p, L=2) for p in problems]       # every family has rows at horizon 2
    groups: dict = {}
    for b, p in enumerate(two):
        groups.setdefault(rows_key(p), []).append(b)
    B = len(problems)
    ix = TubeIndex(2, n, nv, m)
    a = [np.zeros((B, f, n)) for f in f_v]
    bb = [np.zeros((B, f)) for f in f_v]
    gv = [np.zeros((B, f)) for f in f_v]
    mk = [np.zeros((B, f)) for f in f_v]
    trailing = {"dyn_p": (n,), "dyn_eps": (), "dyn_u": (m,), "dyn_p_next": (n,), "dyn_eps_next": (), "dyn_rhs": (),
                "dyn0_u": (m,), "dyn0_p_next": (n,), "dyn0_eps_next": (), "dyn0_rhs": (), "dyn0_rho": (), "dyn_rho": ()}
    dyn = {k: np.zeros((B, nv, fz) + s) for k, s in trailing.items()}
    for idx in groups.values():
        rd = _read_rows(two[idx[0]], W0, ix, vin)
        g = _group_rhs([two[b] for b in idx], rd.nrm, W0, vin)
        for j, (sl, grid, ra, rb) in enumerate(rd.families):
            f = grid[-1]
            a[j][idx, :f] = ra
            bb[j][idx, :f] = rb
            gv[j][idx, :f] = g[:, sl].reshape((len(idx),) + grid)[:, 0]
            mk[j][idx, :f] = 1.0
        for k, v in rd.blocks.items():
            dyn[k][idx] = v
        gd = g[:, rd.dynamics].reshape(len(idx), 2, nv, fz)
        dyn["dyn0_rhs"][idx], dyn["dyn_rhs"][idx] = gd[:, 0], gd[:, 1]
        if rd.R is not None:
            Rd = rd.R[rd.dynamics].reshape(2, nv, fz)
            dyn["dyn0_rho"][idx], dyn["dyn_rho"][idx] = Rd[0], Rd[1]
    radius = W0 is not None
    f_u = input_facets(sysm)
    # one U per group: the same rows for all, read off the dense hard rows at horizon 2
    inp = batched_input_block(*tube_hard_rows(two[0]), ix, f_u, "tube", B) if f_u else None
    shape = OperatorShape(L, n, m, nv, "radius" if radius else "margin", f_u, f_z=fz, f_v=f_v,
                          v_steps=tuple(f.steps for f in vin))
    lb, ub = tube_variable_bounds_batch(problems, L, disturbance=not radius)    # (B, n_x)
    last = lambda x: np.ascontiguousarray(np.moveaxis(x, 0, -1))            # noqa: E731
    blocks = tuple(VertexBlock(last(a_), last(b_), last(g_), last(m_),
                               last(np.concatenate([a_, b_[..., None]], axis=2)))
                   for a_, b_, g_, m_ in zip(a, bb, gv, mk))
    d = TubeData(blocks, *[last(dyn[k]) for k in ("dyn_p", "dyn_eps", "dyn_u", "dyn_p_next", "dyn_eps_next", "dyn_rhs",
                                                  "dyn0_u", "dyn0_p_next", "dyn0_eps_next", "dyn0_rhs")],
                 last(lb), last(ub), *masks, None, None,
                 last(dyn["dyn0_rho"]) if radius else None, last(dyn["dyn_rho"]) if radius else None, inp)
    shared = SHARED_FIELDS + (("dyn0_rho", "dyn_rho") if radius else ())
    if share and B > 1 and all(np.all(getattr(d, k) == getattr(d, k)[..., :1]) for k in shared):
        d = d._replace(**{k: np.ascontiguousarray(getattr(d, k)[..., :1]) for k in shared})
    return shape, d._replace(
        dyn0_stacked=np.concatenate([d.dyn0_p_next, d.dyn0_eps_next[:, :, None], d.dyn0_u], axis=2),
        dyn_stacked=np.concatenate([d.dyn_p, d.dyn_eps[:, :, None], d.dyn_p_next, d.dyn_eps_next[:, :, None], d.dyn_u],
                                   axis=2))
