"""A row family's float64 coefficients as a CSR matrix, without its dense block
(docs/explanation/performance.md#sparse-margin-rows).

:func:`family_csr` evaluates ``lhs`` on far fewer vectors than the unit vectors of
:func:`~tubejax.lp.declarations.row_families.lp_blocks`, and each coefficient it keeps is the unit
vector's, bit for bit. **Probes:** one per block of about ``sqrt(n_x)`` columns puts NaN in them;
``lhs`` uses only ``+ - * @``, indexing and a maximum, through which NaN passes wherever a coefficient
is nonzero (NaN times an exact zero too), so a row left free of NaN reads no column of the block.
**Colouring:** blocks reaching disjoint rows share evaluations (the sum of their unit vectors), and
on a row reached by one block the others enter no operation. Below :data:`PROBE_FROM` variables every
unit vector is evaluated. A ``-0.0`` is kept as an explicit entry (:func:`csr_dense` writes it back).
"""

from __future__ import annotations

import threading

import numpy as np
import scipy.sparse as sp

__all__ = ["take", "family_csr", "csr_from_entries", "csr_dense", "scale_csr_rows", "csr_nbytes",
           "freeze_csr", "PROBE_FROM", "CHUNK_ENTRIES"]

#: Below this many variables every column is evaluated (the probes would not pay).
PROBE_FROM = 256
#: The most coefficients (columns times rows) one chunk of :func:`family_csr` evaluates at once.
CHUNK_ENTRIES = 1 << 22
#: The probes of this many read-only batches are kept (:func:`_probe`).
PROBES_KEPT = 8

_PROBES: dict = {}


def take(x, cols):
    """The batch of variables ``x`` (a tuple of arrays, the batch on axis 0) at ``cols``."""
    return type(x)(*(np.asarray(a)[cols] for a in x))


def _probe(evaluate, x, n_x: int) -> tuple:
    """The blocks of about ``sqrt(n_x)`` columns (list of int arrays) and the rows each one's NaN
    probe reaches, ``(n_blocks, R)`` bool. The probes of a read-only ``x`` (a shared identity) are
    kept (:data:`_PROBES`, the last :data:`PROBES_KEPT`)."""
    b = int(np.ceil(np.sqrt(n_x)))
    starts = np.arange(0, n_x, b)
    hit = _PROBES.get((id(x), n_x))
    if hit is not None and hit[0] is x:
        probes = hit[1]
    else:
        probes = type(x)(*(np.where(np.add.reduceat(np.asarray(a, float), starts, axis=0) != 0, np.nan, 0.0)
                           if np.size(a) else np.asarray(a, float)[starts] for a in x))
        if all(isinstance(a, np.ndarray) and not a.flags.writeable for a in x):
            for a in probes:
                a.setflags(write=False)
            while len(_PROBES) >= PROBES_KEPT:
                _PROBES.pop(next(iter(_PROBES)), None)
            _PROBES[(id(x), n_x)] = (x, probes)            # x held: its id is not reused meanwhile
    with np.errstate(invalid="ignore"):
        reach = np.isnan(np.asarray(evaluate(probes), float)).reshape(starts.size, -1)
    return [np.arange(s, min(s + b, n_x)) for s in starts], reach


def _groups(reach: np.ndarray) -> list:
    """Blocks (indices into ``reach``) that reach a row, in groups whose reached rows are pairwise
    disjoint: each block joins the first group it does not meet."""
    groups, rows = [], []
    for i in np.flatnonzero(reach.any(axis=1)):
        for g, used in zip(groups, rows):
            if not (used & reach[i]).any():
                g.append(i)
                used |= reach[i]
                break
        else:
            groups.append([i])
            rows.append(reach[i].copy())
    return groups


def family_csr(evaluate, x, n_x: int, n_rows: int) -> sp.csr_matrix:
    """The coefficients of ``evaluate`` (``evaluate(batch) -> (B, R)``: the family's rows on a batch of
    ``B`` variable vectors, ``x`` the ``n_x`` unit vectors as one batch) as a CSR matrix of shape
    ``(n_rows, n_x)``, from probed and coloured blocks of columns (module doc); its nonzeros (and
    each ``-0.0``) kept."""
    if n_x < PROBE_FROM:
        step = max(1, CHUNK_ENTRIES // max(n_rows, 1))
        parts = [_entries(evaluate, x, [np.arange(s, min(s + step, n_x))], None, n_rows) for s in range(0, n_x, step)]
    else:
        blocks, reach = _probe(evaluate, x, n_x)
        parts = [_entries(evaluate, x, [blocks[i] for i in g], reach[g] if len(g) > 1 else None, n_rows)
                 for g in _groups(reach)]
    if not parts:
        return sp.csr_matrix((n_rows, n_x))
    return csr_from_entries(*(np.concatenate(a) for a in zip(*parts)), (n_rows, n_x))


def _entries(evaluate, x, blocks: list, reach, n_rows: int) -> tuple:
    """``(rows, cols, vals)`` of the blocks' columns, evaluated together: the ``o``-th vector is the
    sum of each block's ``o``-th unit vector, and block ``i`` owns the rows ``reach[i]`` (all rows
    when ``reach`` is None: one block)."""
    w = max(blk.size for blk in blocks)
    batch = type(x)(*(sum(np.pad(np.asarray(a, float)[blk], [(0, w - blk.size)] + [(0, 0)] * (np.ndim(a) - 1))
                          for blk in blocks) for a in x))
    G = np.asarray(evaluate(batch), float).reshape(w, n_rows)
    out = []
    for i, blk in enumerate(blocks):
        own = np.arange(n_rows) if reach is None else np.flatnonzero(reach[i])
        V = G[:blk.size, own]
        ci, ri = np.nonzero((V != 0) | np.signbit(V))
        out.append((own[ri], blk[ci], V[ci, ri]))
    return tuple(np.concatenate(a) for a in zip(*out))


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
    summed (``toarray`` adds each entry to ``0.0``, which turns ``-0.0`` into ``0.0``). The flat
    positions of the last read-only ``M`` are kept per thread (translates share their rows)."""
    hit = getattr(_local, "flat", None)
    if hit is None or hit[0] is not M:
        flat = np.repeat(np.arange(M.shape[0]) * M.shape[1], M.indptr[1:] - M.indptr[:-1]) + M.indices
        hit = (M, flat)
        if not M.data.flags.writeable:
            _local.flat = hit
    out = np.zeros(M.shape)
    out.ravel()[hit[1]] = M.data
    return out


_local = threading.local()


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


def freeze_csr(M):
    """``M`` with its arrays read-only (a matrix shared by LPs and memos, not to be written)."""
    for a in (M.data, M.indices, M.indptr):
        a.setflags(write=False)
    return M
