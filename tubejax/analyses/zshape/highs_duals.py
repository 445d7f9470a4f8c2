"""Primal-dual optima of margin LPs for the gradient: HiGHS with row duals, reduced costs, warm starts.

The envelope-theorem gradient (:mod:`tubejax.analyses.zshape.lagrangian`) also needs the reduced
costs of the ``eps`` columns, and the optimiser re-solves the same LPs with slightly moved ``Z``, so
the previous basis is a good start. The model is the one
:func:`~tubejax.lp.engines.highs.pass_margin_lp` passes, with :data:`HIGHS_OPTIONS`.
"""

from __future__ import annotations

import threading

import highspy
import numpy as np

from ...lp.declarations.tube_lp import build_tube_lp
from ...lp.engines.highs import new_highs, pass_margin_lp
from .lagrangian import MarginSolution, facet_counts, padded_duals

__all__ = ["MarginLpSolver"]


class MarginLpSolver:
    """Solves margin LPs (:func:`build_tube_lp`) with HiGHS, warm-started per key.

    Thread-safe for distinct keys: each thread has its own ``Highs`` object (HiGHS releases the
    GIL while it solves), and a key's solves depend only on that key's previous basis, so the
    results do not depend on which thread solves what.

    Parameters
    ----------
    warm : bool
        Start each solve from the optimal basis last found for the same key (same LP
        dimensions), which cuts the simplex iterations when ``Z`` moved a little.

    Attributes
    ----------
    n_solves : int
        Solves over the solver's life.
    """

    def __init__(self, warm: bool = True):
        self.warm = warm
        self._local = threading.local()
        self._bases: dict = {}
        self._lock = threading.Lock()
        self.n_solves = 0

    @property
    def _h(self) -> highspy.Highs:
        h = getattr(self._local, "h", None)
        if h is None:
            h = self._local.h = new_highs()
        return h

    def solve(self, prob, key=None, L_pad: int | None = None, f_pad: dict | None = None) -> MarginSolution:
        """One margin LP's optimum, padded to ``L_pad`` steps and ``f_pad`` facets per ``VertexIn``
        region (defaults: its own sizes).

        Raises
        ------
        RuntimeError
            HiGHS does not report an optimum (the margin form is always feasible and bounded,
            so this means numerical trouble; the message names the pair's horizon).
        """
        lp = build_tube_lp(prob)
        ix = lp.index
        L, n, nv, m = ix
        Lp = L if L_pad is None else int(L_pad)
        f_pad = facet_counts(prob) if f_pad is None else f_pad
        h = self._h
        h.clearSolver()
        pass_margin_lp(h, lp)
        basis = self._bases.get(key) if (self.warm and key is not None) else None
        if basis is not None:
            h.setBasis(basis)
        h.run()
        with self._lock:
            self.n_solves += 1
        if h.getModelStatus() != highspy.HighsModelStatus.kOptimal:
            if basis is not None:                     # retry cold once
                self._bases.pop(key, None)
                return self.solve(prob, key, L_pad, f_pad)
            raise RuntimeError(f"HiGHS: {h.modelStatusToString(h.getModelStatus())} on a margin LP "
                               f"(L = {L}); the margin form is always feasible and bounded")
        if self.warm and key is not None:
            self._bases[key] = h.getBasis()
        sol = h.getSolution()
        xt = np.asarray(sol.col_value)
        y = -np.asarray(sol.row_dual)[:lp.G.shape[0]]
        d = np.asarray(sol.col_dual)
        tube = ix.split(xt)
        rows = lp.layout.split(y)
        p = np.zeros((Lp, n))
        eps = np.zeros(Lp)
        u = np.zeros((Lp, nv, m))
        p[:L], eps[:L], u[:L] = tube.p, tube.eps, tube.u
        d_eps = np.zeros(Lp)
        d_eps[:L] = d[ix.eps]
        return MarginSolution(np.float64(xt[-1]), p, eps, u, padded_duals(rows, L, Lp, f_pad), d_eps)
