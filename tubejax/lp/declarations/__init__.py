"""Declarations: what each LP is, nothing solved (docs/explanation/implementation.md#the-lp-layer).

Row families (:mod:`.row_families`, :mod:`.tube_families`, :mod:`.openloop_families`), the tube
LP's variables and their implied bounds (:mod:`.tube_variables`), the dense builders (:mod:`.tube_lp`,
:mod:`.openloop_lp`), the matrix-free operators and their data (:mod:`.tube_operator`,
:mod:`.openloop_operator`, ``*_operator_data``), the radius form's disturbance and rows
(:mod:`.radius_disturbance`, :mod:`.radius_rows`) and the record types of an LP and of its form on the
batched engine (:mod:`.formulation`).
Imports nothing else of :mod:`tubejax.lp`.
"""
