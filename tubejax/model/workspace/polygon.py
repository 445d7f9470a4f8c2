"""Polygon workspaces (YAML), decomposed by constrained triangulation (docs/reference/formats.md#polygon-workspace).

Polygons have at least 3 ``[x, y]`` points, coordinates at most :data:`MAX_COORDINATE` in magnitude.
The free space and the region boundaries are noded together (``shapely.union_all``), polygonised and
triangulated (``shapely.constrained_delaunay_triangles``: conforming, every region a union of
triangles); with ``max_area``, Rivara's longest-edge (LEPP) bisection refines them (deterministic,
conforming, no degenerating angles); slivers below ``1e-12`` are dropped (the neighbour split across
their long edge first). A triangle whose centroid lies in a region gets its label; cells are in
reading order (centroid ``y`` descending, then ``x``, rounded to 9 decimals). The outside of the
boundary (its grown bounding box minus it) is an obstacle, so a pair hull that leaves a non-convex
boundary is in the obstacle case.
"""

from __future__ import annotations

import numbers
from pathlib import Path

import numpy as np
import shapely

from ...errors import InputError, short
from ...files import decode_utf8, load_yaml_strict, read_bytes
from ..geometry import Polytope
from .decomposition import CellDecomposition

__all__ = ["PolygonWorkspaceError", "MAX_COORDINATE", "parse_polygon_workspace", "parse_polygon_workspace_text",
           "load_polygon_workspace"]

_FIELDS = ("name", "boundary", "obstacles", "regions", "max_area")
_SLIVER_AREA = 1e-12
_AREA_TOL = 1e-9
#: Consecutive points closer than this fraction of the polygon's size are refused (the
#: triangulation would make slivers there that no cell can cover).
_MIN_EDGE_REL = 1e-9
_MAX_TRIANGLES = 200_000
_POINTS_HINT = "a list of at least 3 [x, y] points"
#: Largest coordinate magnitude accepted (beyond it the 1e-9 area tolerances lose their meaning).
MAX_COORDINATE = 1e6


class PolygonWorkspaceError(InputError):
    """A polygon workspace is malformed; the message names the file and the field."""


def _polygon(value, name: str, field: str) -> shapely.Polygon:
    """Validate a list of ``[x, y]`` points and return a valid, non-degenerate polygon."""
    err = f"{name}: field '{field}'"
    if not isinstance(value, (list, tuple)) or len(value) < 3:
        raise PolygonWorkspaceError(f"{err}: expected {_POINTS_HINT}, got {short(value, 60)}")
    pts = []
    for k, p in enumerate(value):
        if (not isinstance(p, (list, tuple)) or len(p) != 2
                or not all(isinstance(x, numbers.Real) and not isinstance(x, bool) for x in p)):
            raise PolygonWorkspaceError(f"{err}: point {k} must be [x, y] with two numbers, got {short(p, 60)}")
        xy = (_as_float(p[0]), _as_float(p[1]))
        if not all(np.isfinite(x) for x in xy):
            raise PolygonWorkspaceError(f"{err}: point {k} is not finite: {short(p, 60)}")
        if max(abs(xy[0]), abs(xy[1])) > MAX_COORDINATE:
            raise PolygonWorkspaceError(
                f"{err}: point {k} = {short(p, 60)} is out of range (expected |x|, |y| <= {MAX_COORDINATE:g})")
        pts.append(xy)
    if len(pts) > 3 and pts[0] == pts[-1]:
        pts.pop()
    if len(set(pts)) < 3:
        raise PolygonWorkspaceError(f"{err}: expected {_POINTS_HINT}, got {len(set(pts))} distinct points")
    P = np.array(pts)
    size = float(np.max(P.max(axis=0) - P.min(axis=0)))
    gaps = np.linalg.norm(P - np.roll(P, -1, axis=0), axis=1)
    k = int(np.argmin(gaps))
    if gaps[k] <= _MIN_EDGE_REL * size:
        raise PolygonWorkspaceError(
            f"{err}: points {k} and {(k + 1) % len(P)} are {gaps[k]:.3g} apart, closer than "
            f"{_MIN_EDGE_REL:g} of the polygon's size {size:g}; merge them or drop one")
    poly = shapely.Polygon(pts)
    if not poly.is_valid:
        raise PolygonWorkspaceError(
            f"{err}: the polygon is not simple ({shapely.is_valid_reason(poly)}); "
            "edges must not cross or touch")
    if poly.area <= _AREA_TOL:
        raise PolygonWorkspaceError(f"{err}: the polygon has zero area")
    return poly


def _as_float(value) -> float:
    """``float(value)``, with integers too large for a float as ``inf``."""
    try:
        return float(value)
    except OverflowError:
        return np.inf


def _max_area(value, name: str, free_area: float) -> float | None:
    if value is None:
        return None
    err = f"{name}: field 'max_area'"
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not np.isfinite(_as_float(value)) \
            or float(value) <= 0:
        raise PolygonWorkspaceError(f"{err}: expected a positive number, got {short(value, 60)}")
    if free_area / float(value) > _MAX_TRIANGLES / 4:
        raise PolygonWorkspaceError(
            f"{err}: {value} is too small for a free area of {free_area:g} "
            f"(it would need more than {_MAX_TRIANGLES // 4} triangles)")
    return float(value)


class _Mesh:
    """A conforming triangle mesh: vertices ``(x, y)`` and triangles of vertex ids."""

    def __init__(self):
        self.pts: list[tuple[float, float]] = []
        self.ids: dict[tuple[float, float], int] = {}
        self.tris: dict[int, tuple[int, int, int]] = {}
        self.edges: dict[tuple[int, int], set[int]] = {}
        self.next_tri = 0

    def vertex(self, p) -> int:
        p = (float(p[0]), float(p[1]))
        if p not in self.ids:
            self.ids[p] = len(self.pts)
            self.pts.append(p)
        return self.ids[p]

    def add(self, tri: tuple[int, int, int]) -> None:
        t, self.next_tri = self.next_tri, self.next_tri + 1
        self.tris[t] = tri
        for e in self._edges_of(tri):
            self.edges.setdefault(e, set()).add(t)

    def remove(self, t: int) -> tuple[int, int, int]:
        tri = self.tris.pop(t)
        for e in self._edges_of(tri):
            self.edges[e].discard(t)
        return tri

    @staticmethod
    def _edges_of(tri):
        a, b, c = tri
        return [tuple(sorted(e)) for e in ((a, b), (b, c), (c, a))]

    def area(self, t: int) -> float:
        (ax, ay), (bx, by), (cx, cy) = (self.pts[v] for v in self.tris[t])
        return 0.5 * abs((bx - ax) * (cy - ay) - (cx - ax) * (by - ay))

    def longest(self, t: int) -> tuple[int, int]:
        """Longest edge; ties broken by the vertex ids (a total order, so LEPP terminates)."""
        def key(e):
            (ax, ay), (bx, by) = self.pts[e[0]], self.pts[e[1]]
            return ((ax - bx) ** 2 + (ay - by) ** 2, e)
        return max(self._edges_of(self.tris[t]), key=key)

    def neighbour(self, t: int, e: tuple[int, int]) -> int | None:
        others = self.edges.get(e, set()) - {t}
        return min(others) if others else None

    def split_edge(self, e: tuple[int, int], m: int) -> None:
        """Split every triangle on edge ``e`` at vertex ``m`` (which lies on ``e``)."""
        for t in sorted(self.edges.get(e, set())):
            tri = self.remove(t)
            k = next(k for k in range(3) if {tri[k], tri[(k + 1) % 3]} == set(e))
            p, q, r = tri[k], tri[(k + 1) % 3], tri[(k + 2) % 3]
            self.add((p, m, r))
            self.add((m, q, r))

    def drop_slivers(self) -> None:
        """Remove triangles of area < 1e-12, splitting the neighbour across the long edge."""
        for _ in range(len(self.tris) + 1):
            thin = sorted(t for t in self.tris if self.area(t) < _SLIVER_AREA)
            if not thin:
                return
            t = thin[0]
            e = self.longest(t)
            mid = next(v for v in self.tris[t] if v not in e)
            self.remove(t)
            self.split_edge(e, mid)

    def refine(self, max_area: float, name: str) -> None:
        """Rivara LEPP bisection until every triangle has area ``<= max_area``."""
        while True:
            big = sorted(t for t in self.tris if self.area(t) > max_area)
            if not big:
                return
            for t in big:
                while t in self.tris:
                    cur = t
                    while True:
                        e = self.longest(cur)
                        nb = self.neighbour(cur, e)
                        if nb is None or self.longest(nb) == e:
                            (ax, ay), (bx, by) = self.pts[e[0]], self.pts[e[1]]
                            self.split_edge(e, self.vertex((0.5 * (ax + bx), 0.5 * (ay + by))))
                            break
                        cur = nb
                if len(self.tris) > _MAX_TRIANGLES:
                    raise PolygonWorkspaceError(
                        f"{name}: field 'max_area': refinement exceeded {_MAX_TRIANGLES} triangles")


def _triangulate(free, regions: dict, max_area: float | None, name: str) -> list[np.ndarray]:
    """Conforming triangles of ``free`` (region edges inserted), each an array of shape (3, 2)."""
    lines = shapely.union_all([free.boundary] + [r.boundary for r in regions.values()])
    faces = [f for f in shapely.get_parts(shapely.polygonize(shapely.get_parts(lines)))
             if f.area > _SLIVER_AREA and free.contains(f.point_on_surface())]
    mesh = _Mesh()
    for face in faces:
        for tri in shapely.get_parts(shapely.constrained_delaunay_triangles(face)):
            mesh.add(tuple(mesh.vertex(p) for p in np.asarray(tri.exterior.coords)[:3]))
    mesh.drop_slivers()
    if max_area is not None:
        mesh.refine(max_area, name)
        mesh.drop_slivers()
    return [np.array([mesh.pts[v] for v in mesh.tris[t]]) for t in sorted(mesh.tris)]


def _obstacles(obs_data, boundary, name: str) -> tuple[list, shapely.Geometry]:
    """The ``obstacles`` field's polygons, each inside ``boundary``, and the free space they leave."""
    if not isinstance(obs_data, list):
        raise PolygonWorkspaceError(
            f"{name}: field 'obstacles': expected a list of polygons, got {short(obs_data, 60)}")
    obstacles = []
    for k, o in enumerate(obs_data):
        poly = _polygon(o, name, f"obstacles[{k}]")
        if shapely.difference(poly, boundary).area > _AREA_TOL:
            raise PolygonWorkspaceError(
                f"{name}: field 'obstacles[{k}]': the obstacle is not inside the boundary")
        obstacles.append(poly)
    free = shapely.difference(boundary, shapely.union_all(obstacles)) if obstacles else boundary
    if free.area <= _AREA_TOL:
        raise PolygonWorkspaceError(f"{name}: field 'obstacles': the obstacles cover the whole boundary")
    return obstacles, free


def _regions(reg_data, free, name: str) -> dict[str, shapely.Polygon]:
    """The ``regions`` field: label -> polygon, each meeting the free space ``free``, none overlapping."""
    if not isinstance(reg_data, dict):
        raise PolygonWorkspaceError(
            f"{name}: field 'regions': expected a mapping label -> polygon, got {short(reg_data, 60)}")
    regions: dict[str, shapely.Polygon] = {}
    for label, pts in reg_data.items():
        if isinstance(label, bool) or not isinstance(label, (str, int)) or str(label) == "":
            raise PolygonWorkspaceError(
                f"{name}: field 'regions': a label must be a non-empty string or integer, got {label!r}")
        field = f"regions[{label!r}]"
        if str(label) in regions:
            raise PolygonWorkspaceError(f"{name}: field '{field}': duplicate label {str(label)!r}")
        poly = _polygon(pts, name, field)
        if shapely.intersection(poly, free).area <= _AREA_TOL:
            raise PolygonWorkspaceError(f"{name}: field '{field}': the region does not meet the free space")
        for other, opoly in regions.items():
            if shapely.intersection(poly, opoly).area > _AREA_TOL:
                raise PolygonWorkspaceError(
                    f"{name}: field '{field}': the region overlaps region {other!r}")
        regions[str(label)] = poly
    return regions


def parse_polygon_workspace(data: dict, name: str = "<data>") -> CellDecomposition:
    """Build the triangulated :class:`CellDecomposition` of a polygon workspace.

    Parameters
    ----------
    data : dict
        The parsed YAML document (docs/reference/formats.md#polygon-workspace).
    name : str
        For error messages (the file path), and the name when ``data`` has none.

    Returns
    -------
    CellDecomposition
        ``N`` triangular cells (``vertices (3, 2)``) in reading order; ``grid=None``. A
        ``PolygonWorkspaceError`` names the field of any malformed, crossing or overlapping input.
    """
    if not isinstance(data, dict):
        raise PolygonWorkspaceError(
            f"{name}: expected a mapping with fields {', '.join(_FIELDS)}, got {type(data).__name__}")
    unknown = [k for k in data if k not in _FIELDS]
    if unknown:
        raise PolygonWorkspaceError(
            f"{name}: unknown field {unknown[0]!r} (expected one of {', '.join(_FIELDS)})")
    if "boundary" not in data:
        raise PolygonWorkspaceError(f"{name}: field 'boundary': missing (expected {_POINTS_HINT})")
    title = data.get("name")
    if title is not None and not isinstance(title, (str, int)):
        raise PolygonWorkspaceError(f"{name}: field 'name': expected a string, got {short(title, 60)}")
    boundary = _polygon(data["boundary"], name, "boundary")

    obstacles, free = _obstacles(data.get("obstacles") or [], boundary, name)
    regions = _regions(data.get("regions") or {}, free, name)
    max_area = _max_area(data.get("max_area"), name, free.area)

    tris = _triangulate(free, regions, max_area, name)
    cents = np.array([t.mean(axis=0) for t in tris])
    order = sorted(range(len(tris)), key=lambda i: (round(-cents[i, 1], 9), round(cents[i, 0], 9),
                                                     tuple(np.round(tris[i], 12).ravel())))
    try:
        cells = tuple(Polytope.from_vertices(tris[i]) for i in order)
    except ValueError:      # qhull on a flat triangle: nearly collinear or coincident input points
        raise PolygonWorkspaceError(
            f"{name}: fields 'boundary'/'obstacles'/'regions': the triangulation left a flat "
            "triangle (nearly coincident or collinear points); move or drop such points") from None
    labels = [None] * len(tris)
    for lab, poly in regions.items():
        for k in np.flatnonzero(shapely.contains_xy(poly, cents[order, 0], cents[order, 1])):
            labels[k] = lab
    x0, y0, x1, y1 = boundary.bounds
    outside = shapely.difference(shapely.box(x0 - 1, y0 - 1, x1 + 1, y1 + 1), boundary)
    return CellDecomposition(cells, tuple(labels), tuple(obstacles) + (outside,), None,
                             str(title) if title is not None else name)


def load_polygon_workspace(path) -> CellDecomposition:
    """Read a UTF-8 YAML polygon workspace file (:func:`parse_polygon_workspace`); errors name the
    file, and the line and column where there is one."""
    p = Path(path)
    text = decode_utf8(read_bytes(p, "polygon workspace", PolygonWorkspaceError), str(p), PolygonWorkspaceError)
    return parse_polygon_workspace_text(text, name=str(p))


def parse_polygon_workspace_text(text: str, name: str = "<string>") -> CellDecomposition:
    """Parse the YAML text of a polygon workspace (duplicate keys are refused with their line)."""
    data = load_yaml_strict(text, name, PolygonWorkspaceError)
    if data is None:
        raise PolygonWorkspaceError(f"{name}: the file is empty (expected at least a 'boundary' field)")
    return parse_polygon_workspace(data, name=name)
