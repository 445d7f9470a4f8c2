"""Reachability computed exactly, without an LP: an upper bound on every method's edges.

:mod:`.exact2d` -- exact 2-D robust backward reachability (the method ``exact2d``); its verdicts are
those of :mod:`tubejax.lp.evidence.verdict`, and the transition system, the abstraction and the
verifier use it.
"""
