"""Reachability computed exactly, without an LP: an upper bound on every method's edges.

:mod:`.exact2d` -- exact 2-D robust backward reachability (the method ``exact2d``); its verdicts are
those of :mod:`tubejax.lp.evidence.verdict`, and the transition system, the abstraction and the
verifier use it;
:mod:`.reference_solvers` -- each method's reference solver and verdict (HiGHS for an LP, :mod:`.exact2d`
for ``exact2d``): the one place that chooses between them.
"""
