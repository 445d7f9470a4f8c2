"""Solvers shared by every formulation: batched PDHG, its pool, HiGHS and the helper process; and
``exact2d``, exact 2-D robust backward reachability (an upper bound on every method's edges)."""
