"""Solvers shared by every formulation: batched PDHG, its pool, HiGHS and the helper process."""
