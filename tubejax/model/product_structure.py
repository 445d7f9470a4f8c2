"""Exact product structure of a problem: the axis groups over which ``A``, ``B``, ``U``, every cell,
``Z`` and ``X`` decompose (docs/math/product.md#product-problems, also why ``W`` need not). Every test
is an equality of the float64 data, with no tolerance. :func:`product_structure` gives the
:class:`ProductStructure` or raises :class:`NotAProduct` saying why.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .geometry import Ball, Halfspaces, Polytope
from .system import LinearSystem, exact_matrix
from .workspace.decomposition import CellDecomposition

__all__ = ["NotAProduct", "Factor", "ProductStructure", "axis_groups", "product_structure",
           "factor_system"]


class NotAProduct(InputError):
    """The problem is not a product over axis groups; the message says which part couples them."""


@dataclass(frozen=True, eq=False)
class Factor:
    """One axis group of a product problem: its system and its factor cells.

    Attributes
    ----------
    axes : tuple of int          the state axes of the group (ascending)
    inputs : tuple of int        the input axes of the group (ascending)
    system : LinearSystem        ``A_g``, ``B_g``, ``U_g``, ``W_g`` (``W``'s projection), ``X_g``
    cells : tuple of Polytope    the factor cells: the distinct projections of the cells, shape
                                 ``(F,)``, in order of first appearance
    Z : tuple of Polytope        the projection of ``Z`` for tubes leaving each factor cell, ``(F,)``
    """

    axes: tuple
    inputs: tuple
    system: LinearSystem
    cells: tuple
    Z: tuple

    @property
    def n_cells(self) -> int:
        return len(self.cells)


@dataclass(frozen=True, eq=False)
class ProductStructure:
    """A problem split into axis groups.

    Attributes
    ----------
    factors : tuple of Factor    one per group, ``G >= 2`` of them, by their first axis
    cell_factor : ndarray of int, shape (N, G)
        The factor cell of each cell in each group: ``P_i = prod_g factors[g].cells[cell_factor[i, g]]``
        (after reordering the axes by group).
    n, m : int                   the full state and input dimensions
    """

    factors: tuple
    cell_factor: np.ndarray
    n: int
    m: int

    @property
    def n_groups(self) -> int:
        return len(self.factors)

    def describe(self) -> str:
        """One line: the groups and their factor cell counts."""
        parts = [f"axes {list(f.axes)} inputs {list(f.inputs)}: {f.n_cells} factor cells" for f in self.factors]
        return f"product of {self.n_groups} groups (" + "; ".join(parts) + ")"


def axis_groups(A, B) -> tuple[list, list]:
    """The blocks of ``A`` and ``B``, found from their exact zero pattern.

    Parameters
    ----------
    A : array_like, shape (n, n)
    B : array_like, shape (n, m)

    Returns
    -------
    state_groups : list of list of int
        Connected components of the state axes (``a ~ b`` when ``A[a, b] != 0`` or ``A[b, a] != 0``,
        or both are moved by one input), by their first axis.
    input_groups : list of list of int
        The inputs acting on each group (an input that moves no state joins the first group).
    """
    A, B = exact_matrix(A), exact_matrix(B)
    n, m = B.shape
    parent = list(range(n + m))                 # union-find over states 0..n-1 and inputs n..n+m-1

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    def union(a, b):
        ra, rb = find(a), find(b)
        if ra != rb:
            parent[max(ra, rb)] = min(ra, rb)

    for a in range(n):
        for b in range(n):
            if A[a, b] != 0:
                union(a, b)
        for k in range(m):
            if B[a, k] != 0:
                union(a, n + k)
    roots = sorted({find(a) for a in range(n)})
    states = [[a for a in range(n) if find(a) == r] for r in roots]
    inputs = [[k for k in range(m) if find(n + k) == r] for r in roots]
    inputs[0] += [k for k in range(m) if find(n + k) not in roots]
    inputs[0].sort()
    return states, inputs


def _product_of_projections(V: np.ndarray, groups) -> tuple[bool, list]:
    """Whether the point set ``V (k, d)`` is exactly the Cartesian product of its projections on
    ``groups``; also each projection's distinct points (order of first appearance)."""
    projections, index = [], []
    for g in groups:
        P, first, inv = np.unique(V[:, g], axis=0, return_index=True, return_inverse=True)
        order = np.argsort(first)                      # order of first appearance
        rank = np.empty_like(order)
        rank[order] = np.arange(len(order))
        projections.append(P[order])
        index.append(rank[np.ravel(inv)])
    sizes = [len(P) for P in projections]
    if int(np.prod(sizes)) != len(V):
        return False, projections
    keys = np.ravel_multi_index(tuple(index), tuple(sizes))
    return len(np.unique(keys)) == len(V), projections


def _factor_polytope(points: np.ndarray) -> Polytope:
    """The polytope with these vertices (a box when there are ``2^d`` box corners)."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    d = points.shape[1]
    if len(points) == 2 ** d and np.all((points == lo) | (points == hi)):
        return Polytope.box(lo, hi)
    return Polytope.from_vertices(points)


def _vertex_index(P: Polytope, points: np.ndarray) -> np.ndarray:
    """Index in ``P.vertices`` of each row of ``points`` (all exact vertices of ``P``), ``-1`` if none."""
    eq = np.all(points[:, None, :] == P.vertices[None, :, :], axis=2)
    return np.where(eq.any(axis=1), np.argmax(eq, axis=1), -1)


def factor_system(system: LinearSystem, axes, inputs, U_points) -> LinearSystem:
    """The system of the state ``axes`` and ``inputs`` (lists; a union of groups): ``A``, ``B`` blocks,
    ``U`` of the points ``U_points`` (the projection of ``U``'s vertices), ``W``'s projection, ``X``'s rows
    on those axes."""
    W = system.W
    if isinstance(W, Ball):
        Wg = Ball(len(axes), W.radius)
    else:
        Wg = Polytope.from_vertices(np.unique(W.vertices[:, axes], axis=0))
    X = None
    if system.X is not None:
        rows = [r for r in range(system.X.H.shape[0]) if np.any(system.X.H[r, axes] != 0)]
        if rows:
            X = Halfspaces(system.X.H[np.ix_(rows, axes)], system.X.h[rows], name=f"system.X (axes {list(axes)})")
    return LinearSystem(A=system.A[np.ix_(axes, axes)], B=system.B[np.ix_(axes, inputs)],
                        U=_factor_polytope(U_points), W=Wg, X=X)


def product_structure(decomp: CellDecomposition, system: LinearSystem, Z) -> ProductStructure:
    """The exact product structure of ``(decomp, system, Z)``.

    Parameters
    ----------
    decomp : CellDecomposition
    system : LinearSystem
    Z : sequence of Polytope, length N
        The cross-section of tubes leaving each cell (one per cell, as
        :func:`~tubejax.model.zshape.kinds.cross_sections` gives).

    Returns
    -------
    ProductStructure

    Raises
    ------
    NotAProduct
        The part that couples the groups, named: one block, ``U``, a cell, a ``Z``, the pairing
        of a ``Z`` with its cell, or ``X``.
    """
    n, m = system.n, system.m
    states, inputs = axis_groups(system.A, system.B)
    if len(states) < 2:
        raise NotAProduct(f"not a product: A and B couple all {n} state axes into one block (A = "
                          f"{np.array2string(system.A, precision=4)}), so the tube LP does not split")
    if any(not g for g in inputs):
        k = next(i for i, g in enumerate(inputs) if not g)
        raise NotAProduct(f"not a product: the state axes {states[k]} form a block that no input moves")
    ok, U_parts = _product_of_projections(system.U.vertices, inputs)
    if not ok:
        raise NotAProduct(f"not a product: U is not the product of its projections on the input groups {inputs}")
    if system.X is not None:
        for r, row in enumerate(system.X.H):
            touched = [g for g, axes in enumerate(states) if np.any(row[axes] != 0)]
            if len(touched) > 1:
                raise NotAProduct(f"not a product: row {r} of system.X involves the axes of groups "
                                  f"{[states[g] for g in touched]}")
    N, G = decomp.n_cells, len(states)
    if len(Z) != N:
        raise ValueError(f"Z: expected one cross-section per cell ({N}), got {len(Z)}")
    box = np.array([c.is_box for c in decomp.cells])
    checked: dict = {}                                  # (cell shape, id(Z)) -> index into zparts
    zparts: list = []                                   # per checked shape: Z's projection on each group
    shape_of = np.empty(N, dtype=np.int64)
    for i, (cell, z) in enumerate(zip(decomp.cells, Z)):
        # a box cell with a box Z: both products, their canonical orders pair corners by the same bits
        both_boxes = bool(box[i]) and z.n_vertices == cell.n_vertices and z.is_box
        shape_key = ("box", z.vertices.tobytes()) if both_boxes else ((cell.vertices - cell.vertices[0]).tobytes(), id(z))
        if shape_key not in checked:
            checked[shape_key] = len(zparts)
            zparts.append(_box_parts(z, states) if both_boxes else _check_cell_and_z(i, cell, z, states))
        shape_of[i] = checked[shape_key]
    lo, hi = decomp.cell_boxes()
    cell_factor = np.empty((N, G), dtype=np.int64)
    f_cells: list[list] = [[] for _ in range(G)]
    f_Z: list[list] = [[] for _ in range(G)]
    for g, axes in enumerate(states):
        if box.all():                                   # a box is the product of its projections: its corners
            keys = np.concatenate([lo[:, axes], hi[:, axes]], axis=1)
        else:
            keys = np.array([np.unique(c.vertices[:, axes], axis=0).tobytes() for c in decomp.cells], dtype=object)
        _, first, inv = np.unique(keys, axis=0 if box.all() else None, return_index=True, return_inverse=True)
        inv = np.ravel(inv)
        order = np.argsort(first)                       # factor ids in order of first appearance
        rank = np.empty_like(order)
        rank[order] = np.arange(len(order))
        cell_factor[:, g] = rank[inv]
        for f, i in enumerate(first[order].tolist()):
            f_cells[g].append(_factor_polytope(np.unique(decomp.cells[i].vertices[:, axes], axis=0)))
            f_Z[g].append(zparts[shape_of[i]][g])
        for i in range(N):                              # every cell of a factor cell has the same Z there
            zg = zparts[shape_of[i]][g]
            ref = f_Z[g][cell_factor[i, g]]
            if zg is not ref and not np.array_equal(zg.vertices, ref.vertices):
                raise NotAProduct(f"not a product: cells sharing a projection on axes {axes} have Z with different "
                                  f"projections (cell {i})")
    factors = tuple(Factor(tuple(s), tuple(u), factor_system(system, s, u, U_parts[g]), tuple(f_cells[g]),
                           tuple(f_Z[g])) for g, (s, u) in enumerate(zip(states, inputs)))
    cell_factor.setflags(write=False)
    return ProductStructure(factors, cell_factor, n, m)


def _box_parts(z: Polytope, states) -> list:
    """The projections of the box ``z`` on the groups."""
    lo, hi = z.bounding_box()
    return [Polytope.box(lo[axes], hi[axes]) for axes in states]


def _check_cell_and_z(i: int, cell: Polytope, z: Polytope, states) -> list:
    """Check that cell ``i`` and its ``Z`` are products paired group by group; ``Z``'s projections."""
    ok, _ = _product_of_projections(cell.vertices, states)
    if not ok:
        raise NotAProduct(f"not a product: cell {i} is not the product of its projections on the axis groups "
                          f"{states}")
    if z.n_vertices != cell.n_vertices:
        raise NotAProduct(f"not a product: the Z of cell {i} has {z.n_vertices} vertices, its cell "
                          f"{cell.n_vertices} (a chamfered Z is not a product)")
    ok, _ = _product_of_projections(z.vertices, states)
    if not ok:
        raise NotAProduct(f"not a product: the Z of cell {i} is not the product of its projections on the axis "
                          f"groups {states}")
    out = []
    for axes in states:
        Fc = _factor_polytope(np.unique(cell.vertices[:, axes], axis=0))
        Fz = _factor_polytope(np.unique(z.vertices[:, axes], axis=0))
        kc = _vertex_index(Fc, cell.vertices[:, axes])
        kz = _vertex_index(Fz, z.vertices[:, axes])
        if np.any(kc < 0) or np.any(kz < 0) or not np.array_equal(kc, kz):
            raise NotAProduct(f"not a product: the Z of cell {i} pairs its vertices with the cell's in a way that "
                              f"is not the product of the pairings on axes {axes}")
        out.append(Fz)
    return out
