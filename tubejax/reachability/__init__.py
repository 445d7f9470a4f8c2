"""Reachability computed exactly, without an LP: an upper bound on every method's edges
(:mod:`.exact2d`), and each method's reference solver (:mod:`.reference_solvers`).
"""
