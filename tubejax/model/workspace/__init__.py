"""Workspaces and their cell decompositions: grid maps, polygon workspaces, n-D box grids."""

from .boxgrid import BoxGridError, box_grid
from .decomposition import CellDecomposition
from .gridmap import GridMapError, load_grid_map, parse_grid_map
from .polygon import PolygonWorkspaceError, load_polygon_workspace, parse_polygon_workspace

__all__ = [
    "BoxGridError", "CellDecomposition", "GridMapError", "PolygonWorkspaceError", "box_grid", "load_grid_map",
    "load_polygon_workspace", "parse_grid_map", "parse_polygon_workspace",
]
