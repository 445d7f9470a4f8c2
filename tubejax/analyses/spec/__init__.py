"""Temporal-logic specifications over region labels (docs/math/control.md#specifications): LTLf
formulas as DFAs, LTL formulas as Büchi automata (both by Spot), the regions each tube set can meet,
the sound products, the plans, why none exists (:mod:`.explain`) and the monitor of simulated runs.
"""

from .dfa import DFA, sequence_dfa
from .formula import ParsedFormula, SpecificationError, parse_formula, proposition_of
from .automata import dfa_from_formula
from .automata import Buchi, buchi_from_formula
from .labelling import EdgeLetters, cell_letters, edge_letters, map_alphabet
from .monitor import MonitorResult, SpecSimulation, lasso_words_satisfy, monitor, region_letters, simulate_spec
from .lasso import BuchiProduct, Lasso, build_buchi_product, cheapest_lasso
from .ltl import ParsedLTL, parse_ltl
from .ltl_plans import explain_no_lasso, patrol_formula, plan_ltl, plan_patrol
from .plans import plan_formula, plan_sequence_spec, sequence_spec_plan
from .product import NoPlanError, Product, SpecPlan, avoided_labels, build_product, edge_successors, plan_dfa
from .regions import region_pieces

__all__ = [
    "Buchi", "BuchiProduct", "Lasso", "ParsedLTL", "buchi_from_formula", "build_buchi_product", "cheapest_lasso",
    "explain_no_lasso", "lasso_words_satisfy", "parse_ltl", "patrol_formula", "plan_ltl",
    "DFA", "EdgeLetters", "MonitorResult", "NoPlanError", "ParsedFormula", "Product", "SpecPlan",
    "SpecSimulation", "SpecificationError", "avoided_labels", "build_product", "cell_letters",
    "dfa_from_formula", "edge_letters", "edge_successors", "map_alphabet", "monitor", "parse_formula",
    "plan_dfa", "plan_formula", "plan_patrol", "plan_sequence_spec", "proposition_of",
    "region_letters", "region_pieces", "sequence_dfa", "sequence_spec_plan", "simulate_spec",
]
