"""Engines: numerical LP solvers that know no verdict (docs/explanation/implementation.md#the-lp-layer).
Imports only :mod:`tubejax.lp.declarations` of the LP layer.
"""
