"""Learned ``Z`` for a whole run: :func:`learn_table` learns the run's ``learned_z.json`` table
(docs/howto/learned-z.md).

``learned``: one ``Z`` per cell shape from ``init`` (``'best'``: the fixed kind that certifies most
pairs); ``learned_pair``: then one per candidate pair started from it. Cell shapes of different
vertex counts and start kinds are learned separately, each keeping the run that certifies most pairs.
The same inputs and seed give the same bytes.
"""

from __future__ import annotations

import jax
import numpy as np

from ...model.zshape.kinds import make_z, start_kinds
from ...model.zshape.z_table import ZTable
from ...model.zshape.z_table import cell_shape_key
from .learn import LearnOptions, candidate_pairs, learn_z
from .starts import CERTIFIED_TOL

__all__ = ["learn_table"]


def _families(decomp, pairs) -> list:
    """The candidate pairs ``(B, 2)`` split by the source cell's vertex count (sorted by it)."""
    nv = np.array([decomp.cells[int(i)].n_vertices for i, _ in pairs], dtype=int)
    return [pairs[nv == v] for v in sorted(set(nv.tolist()))]


def _history(res) -> list:
    return [{k: r[k] for k in ("step", "objective", "certified", "accepted")} for r in res.history]


def learn_table(decomp, system, mode: str, *, init: str = "best", options: LearnOptions = LearnOptions(),
                progress: bool = True) -> ZTable:
    """Learn the ``learned_z.json`` table of a run (see the module docstring).

    Parameters
    ----------
    decomp : CellDecomposition
    system : LinearSystem
    mode : {'learned', 'learned_pair'}
    init : str
        The starting kind (:func:`~tubejax.model.zshape.kinds.make_z`), or ``'best'``: per
        cell shape the fixed kind that fits and certifies most candidate pairs at their horizon
        (:func:`~tubejax.model.zshape.kinds.start_kinds`; ties go to the earlier of
        :data:`~tubejax.model.zshape.kinds.FIXED_KINDS`).
    options : LearnOptions
        ``require_gain`` is always on: a cell shape (a pair, for ``learned_pair``) keeps its start
        unless learning certifies strictly more of its pairs, so the learned ``Z`` does not trade
        an edge of the start for a larger surrogate. ``L_max``, ``eps_min`` and ``pruning`` are the
        run's :func:`~tubejax.abstraction.build_abstraction`'s (the pairs learned for are its
        candidate pairs; with ``pruning``, one LP per translation class, which leaves the table the same).
    progress : bool
        A progress bar per learning run (the objective and the pairs certified; also logged).

    Returns
    -------
    ZTable
        Mode ``mode``; shapes of every family learned, and for ``learned_pair`` the pairs.

    Raises
    ------
    ValueError
        ``init`` does not fit the cells (e.g. ``box`` for triangles), or a bad option.
    RuntimeError
        JAX without float64 (``jax_enable_x64``).
    """
    if mode not in ("learned", "learned_pair"):
        raise ValueError(f"mode must be 'learned' or 'learned_pair', got {mode!r}")
    if not jax.config.jax_enable_x64:
        raise RuntimeError("learning Z solves its LPs in float64: call jax.config.update('jax_enable_x64', True) "
                           "first")
    options = options._replace(require_gain=True, L_max=int(options.L_max), eps_min=float(options.eps_min),
                               pruning=bool(options.pruning))
    cand, _ = candidate_pairs(decomp, system, options.L_max, options.pruning)
    shapes, pairs, record = [], {}, []
    common = dict(options=options, progress=progress)
    for group in _families(decomp, cand):
        cell0 = decomp.cells[int(group[0, 0])]
        kinds = start_kinds(init, cell0)
        by_nv: dict = {}                           # Z's vertex count -> the kinds with it (chamfer: 2 n_i)
        for k in kinds:
            by_nv.setdefault(make_z(k, cell0).n_vertices, []).append(k)
        runs = [(nv, ks, learn_z(decomp, system, mode="learned", init=ks, pairs=group, n_vertices=nv, **common))
                for nv, ks in sorted(by_nv.items())]
        polys = [res.polytopes() for _, _, res in runs]
        group_cells = runs[0][2].group_cells
        certified = np.stack([np.bincount(res.group_of_pair, weights=res.margins >= -CERTIFIED_TOL,
                                          minlength=len(group_cells)) for _, _, res in runs])
        chosen = np.argmax(certified, axis=0)       # per cell shape: most pairs certified; ties: fewer vertices
        shared = {}
        for g, i in enumerate(group_cells):
            P = polys[chosen[g]][g]
            shapes.append((decomp.cells[int(i)].vertices, P.vertices))
            shared[cell_shape_key(decomp.cells[int(i)].vertices)] = P
        for r, (nv, ks, res) in enumerate(runs):
            entry = {"mode": "learned", "n_vertices": nv, "starts": ks,
                     "start_of_shape": [ks[int(k)] for k in res.start_index], "n_pairs": int(len(res.pairs)),
                     "n_classes": int(res.n_classes), "n_lps": int(res.n_lps), "n_compiles": int(res.n_compiles),
                     "shapes_taken": int(np.sum(chosen == r)), "history": _history(res)}
            mine = chosen[res.group_of_pair] == r                  # the pairs of the shapes this run keeps
            if mode == "learned_pair" and mine.any():
                res2 = learn_z(decomp, system, mode="learned_pair", pairs=res.pairs[mine], n_vertices=nv,
                               init=lambda i, j: shared[cell_shape_key(decomp.cells[i].vertices)], **common)
                P2 = res2.polytopes()
                pairs.update({(int(i), int(j)): P2[g].vertices for (i, j), g in zip(res2.pairs, res2.group_of_pair)})
                entry["pairs"] = {"n_classes": int(res2.n_classes), "n_lps": int(res2.n_lps),
                                  "n_compiles": int(res2.n_compiles), "history": _history(res2)}
            record.append(entry)
    return ZTable(mode, decomp.dim, shapes, pairs if mode == "learned_pair" else None,
                  _learning(init, options, len(cand), record))


def _learning(init, options: LearnOptions, n_candidates: int, families: list) -> dict:
    """The table's ``learning`` record: the settings of :func:`learn_table` and what each family's runs did."""
    return {"init": init, "steps": int(options.steps), "learning_rate": float(options.learning_rate),
            "horizon": options.horizon, "patience": options.patience, "require_gain": True,
            "seed": int(options.seed), "L_max": int(options.L_max), "eps_min": float(options.eps_min),
            "pruning": bool(options.pruning), "n_candidate_pairs": int(n_candidates), "families": families}

