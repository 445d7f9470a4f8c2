"""The open-loop operator as explicit per-instance coefficients (host only, for the diagonal scaling).

:func:`openloop_coef_data` gives ``K`` of :mod:`tubejax.lp.declarations.openloop_operator` as
coefficients, so that ``|K|`` and ``K o K`` (the Ruiz and Pock-Chambolle scalings of the PDHG
setup) are :func:`numpy.abs` and squares of them; :func:`openloop_coef_ops` applies them. The
coefficients are not written here: they are the dense rows the open-loop row families derive
(:func:`~tubejax.lp.declarations.row_families.dense_rows`), normalised and read off per vertex
block by :func:`~tubejax.lp.declarations.openloop_operator_data.build_openloop_data`
(``OpenLoopData.CS``, ``CT``).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .openloop_operator import OpenLoopData, OpenLoopShape, OpenLoopX, OpenLoopY, pack_x, pack_y, unpack_x, unpack_y

__all__ = ["OpenLoopCoef", "openloop_coef_data", "openloop_coef_ops"]


class OpenLoopCoef(NamedTuple):
    """Explicit per-instance coefficients (host only; for the diagonal scaling).

    CS : (L-1, f_s, L, m, B)  coefficient of ``u_k(t)[j]`` in C2 row ``(l, k, f)``
    CT : (f_t, L, m, B)       the same for C3
    mS, mT : row masks (dropped rows get no coefficient, not even ``t``'s)
    tS : (L-1, f_s, B) or (1, 1, 1)   ``t``'s coefficient in C2 rows (1 in the margin form)
    tT : (f_t, B) or (1, 1)           ``t``'s coefficient in C3 rows
    CU : (f_u, m, B) or None          coefficient of ``u_k(l)[j]`` in hard input row ``(l, k, f)``
    mU : (L, n_v, f_u, B) or None     their row mask
    """

    CS: np.ndarray
    CT: np.ndarray
    mS: np.ndarray
    mT: np.ndarray
    tS: np.ndarray
    tT: np.ndarray
    CU: np.ndarray | None = None
    mU: np.ndarray | None = None

    def apply(self, fn) -> "OpenLoopCoef":
        """The coefficients mapped by ``fn`` (masks unchanged): ``np.abs`` gives ``|K|``,
        squaring ``K o K``."""
        return self._replace(CS=fn(self.CS), CT=fn(self.CT), tS=fn(self.tS), tT=fn(self.tT),
                             CU=None if self.CU is None else fn(self.CU))


def openloop_coef_data(shape: OpenLoopShape, d: OpenLoopData) -> OpenLoopCoef:
    """The operator of ``d`` as explicit coefficients (``|K|`` = :func:`numpy.abs` of them).

    Raises
    ------
    ValueError
        When ``d`` has no coefficients (``d.lean()``: the device copy).
    """
    if d.CS is None or d.CT is None:
        raise ValueError("OpenLoopData without its coefficients CS, CT (a lean() copy): build it with "
                         "build_openloop_data")
    if shape.form == "radius":
        return OpenLoopCoef(d.CS, d.CT, d.mS, d.mT, d.cS, d.cT, d.Hu, d.mU)
    return OpenLoopCoef(d.CS, d.CT, d.mS, d.mT, np.ones((1, 1, 1)), np.ones((1, 1)), d.Hu, d.mU)


def openloop_coef_ops(shape: OpenLoopShape):
    """``matvec``, ``rmatvec`` on flat vectors with :class:`OpenLoopCoef` data (NumPy, host).

    With ``coef.apply(np.abs)`` they apply ``|K|``, with ``coef.apply(np.square)`` ``K o K``
    (the ``t`` column is ``tS``, ``tT`` on real rows, 0 on masked ones and on the hard input rows).
    """
    def mv(c: OpenLoopCoef, z):
        x = unpack_x(shape, z)
        rS = (np.einsum("lftjb,tkjb->lkfb", c.CS, x.u) + c.tS[:, None] * x.t) * c.mS
        rT = (np.einsum("ftjb,tkjb->kfb", c.CT, x.u) + c.tT[None] * x.t) * c.mT
        rU = None if c.CU is None else np.einsum("fjb,tkjb->tkfb", c.CU, x.u) * c.mU
        return pack_y(OpenLoopY(rS, rT, rU))

    def rmv(c: OpenLoopCoef, yv):
        y = unpack_y(shape, yv)
        yS, yT = y.yS * c.mS, y.yT * c.mT
        gu = np.einsum("lftjb,lkfb->tkjb", c.CS, yS) + np.einsum("ftjb,kfb->tkjb", c.CT, yT)
        if c.CU is not None:
            gu = gu + np.einsum("fjb,tkfb->tkjb", c.CU, y.yU * c.mU)
        gt = np.sum(c.tS[:, None] * yS, axis=(0, 1, 2)) + np.sum(c.tT[None] * yT, axis=(0, 1))
        return pack_x(OpenLoopX(gu, gt))

    return mv, rmv
