"""Declarations: what each LP is, nothing solved (docs/explanation/implementation.md#the-lp-layer).
Row families, dense builders, matrix-free operators, the radius form and the record types of an LP;
imports nothing else of :mod:`tubejax.lp`.
"""
