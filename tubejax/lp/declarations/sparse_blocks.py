"""A row family's float64 coefficients as a CSR matrix, without its dense block.

A family's coefficients are its ``lhs`` applied to the unit vectors of the LP's variables
(:func:`~tubejax.lp.declarations.row_families.lp_blocks`): one evaluation of the row grid per
variable. Most of them are zero -- the tube's cross-section rows never read the inputs ``u``, the
bulk of the variables of a many-vertex tube -- so :func:`family_csr` first finds the columns a
family can read (:func:`column_support`) and evaluates ``lhs`` on those unit vectors only, a chunk
of columns at a time, keeping each chunk's nonzeros.

:func:`column_support` puts NaN in a block of variables at a time. ``lhs`` is built from ``+``,
``-``, ``*``, ``@``, indexing and (for compressed families) a maximum, and NaN passes through each
of them wherever the coefficient along the way is nonzero (a NaN times an exact zero stays NaN
too). So a block whose rows all stay free of NaN has only zero coefficients, and leaving it out
drops no coefficient; a marked block may still hold zero columns, whose evaluation adds nothing.
Each evaluated column is the unit vector the dense derivation uses, through the same operations,
so every coefficient is the dense one bit for bit; an evaluated ``-0.0`` is kept as an explicit
entry (:func:`csr_dense` writes it back), a skipped block is ``+0.0`` (the dense derivation may
give it either sign of zero there).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["take", "column_support", "family_csr", "csr_from_entries", "csr_dense", "scale_csr_rows", "csr_nbytes",
           "PROBE_FROM", "CHUNK_ENTRIES"]

#: Below this many variables every column is evaluated (the probes would not pay).
PROBE_FROM = 256
#: The most coefficients (columns times rows) one chunk of :func:`family_csr` evaluates at once.
CHUNK_ENTRIES = 1 << 22


def take(x, cols):
    """The batch of variables ``x`` (a tuple of arrays, the batch on axis 0) at ``cols``."""
    return type(x)(*(np.asarray(a)[cols] for a in x))


def column_support(evaluate, x, n_x: int) -> np.ndarray:
    """Columns outside of which every coefficient of ``evaluate`` is zero, sorted, shape ``(k,)``.

    Parameters
    ----------
    evaluate : callable
        ``evaluate(batch) -> (B, R)``: the family's rows on a batch of ``B`` variable vectors.
    x : tuple of arrays
        The ``n_x`` unit vectors of the LP's variables as a batch (float64).
    n_x : int

    Returns
    -------
    ndarray of int
        The union of the blocks of about ``sqrt(n_x)`` columns whose NaN probe reaches a row
        (module doc); every column when ``n_x < PROBE_FROM``.
    """
    if n_x < PROBE_FROM:
        return np.arange(n_x)
    b = int(np.ceil(np.sqrt(n_x)))
    starts = np.arange(0, n_x, b)
    probes = type(x)(*(np.where(np.add.reduceat(np.asarray(a, float), starts, axis=0) != 0, np.nan, 0.0)
                       if np.size(a) else np.asarray(a, float)[starts] for a in x))
    with np.errstate(invalid="ignore"):
        hit = np.isnan(np.asarray(evaluate(probes), float)).reshape(starts.size, -1).any(axis=1)
    blocks = [np.arange(s, min(s + b, n_x)) for s in starts[hit]]
    return np.concatenate(blocks) if blocks else np.zeros(0, int)


def family_csr(evaluate, x, n_x: int, n_rows: int) -> sp.csr_matrix:
    """The coefficients of ``evaluate`` (as in :func:`column_support`) as a CSR matrix of shape
    ``(n_rows, n_x)``: each column of the support evaluated on its unit vector, at most
    :data:`CHUNK_ENTRIES` coefficients at a time; its nonzeros (and ``-0.0``) kept."""
    cols = column_support(evaluate, x, n_x)
    step = max(1, CHUNK_ENTRIES // max(n_rows, 1))
    rows, cc, vals = [], [], []
    for s in range(0, cols.size, step):
        c = cols[s:s + step]
        G = np.asarray(evaluate(take(x, c)), float).reshape(c.size, n_rows)
        ci, ri = np.nonzero((G != 0) | np.signbit(G))
        rows.append(ri)
        cc.append(c[ci])
        vals.append(G[ci, ri])
    if not rows:
        return sp.csr_matrix((n_rows, n_x))
    return csr_from_entries(np.concatenate(rows), np.concatenate(cc), np.concatenate(vals), (n_rows, n_x))


def csr_from_entries(rows, cols, vals, shape) -> sp.csr_matrix:
    """A CSR matrix of distinct entries ``(rows[k], cols[k]) = vals[k]``, shape ``shape``, with its
    columns sorted in each row and every given entry kept (explicit zeros too)."""
    order = np.lexsort((cols, rows))
    indptr = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=shape[0]))])
    idx = np.int32 if max(shape) < 2 ** 31 and len(order) < 2 ** 31 else np.int64
    M = sp.csr_matrix((np.asarray(vals, float)[order], np.asarray(cols, idx)[order], indptr.astype(idx)), shape=shape)
    M.has_sorted_indices = True
    return M


def csr_dense(M) -> np.ndarray:
    """The dense float64 array of the CSR matrix ``M``, shape ``M.shape``: entries written, not
    summed (``toarray`` adds each entry to ``0.0``, which turns ``-0.0`` into ``0.0``)."""
    out = np.zeros(M.shape)
    out[np.repeat(np.arange(M.shape[0]), np.diff(M.indptr)), M.indices] = M.data
    return out


def scale_csr_rows(M, nrm: np.ndarray):
    """A copy of the CSR matrix ``M (R, n_x)`` with row ``r`` divided by ``nrm[r]``: entry by entry
    what the dense division gives (a row with ``nrm == 0`` is stored in full: ``0 / 0`` is NaN)."""
    if np.any(nrm == 0):
        G = csr_dense(M) / nrm[:, None]
        return csr_from_entries(*np.nonzero(np.ones(G.shape, bool)), G.ravel(), G.shape)
    M = M.copy()
    M.data /= np.repeat(nrm, np.diff(M.indptr))
    return M


def csr_nbytes(G) -> int:
    """The bytes a dense array or a CSR matrix holds."""
    return G.nbytes if isinstance(G, np.ndarray) else G.data.nbytes + G.indices.nbytes + G.indptr.nbytes
