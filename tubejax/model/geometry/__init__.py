"""Convex polytopes, polyhedra given by inequalities, support functions and obstacle tests."""

from .halfspaces import Halfspaces, HalfspacesError
from .obstacles import interior_overlap_depth, interiors_intersect, meets_obstacles, to_shapely
from .polytope import Polytope, canonical_vertex_order, convex_hull_of, vertices_from_hrep
from .sets import Ball, sample_boundary, sample_uniform, support, support_maximizer

__all__ = [
    "Ball", "Halfspaces", "HalfspacesError", "Polytope", "canonical_vertex_order", "convex_hull_of",
    "interior_overlap_depth", "interiors_intersect", "meets_obstacles",
    "sample_boundary", "sample_uniform", "support", "support_maximizer", "to_shapely",
    "vertices_from_hrep",
]
