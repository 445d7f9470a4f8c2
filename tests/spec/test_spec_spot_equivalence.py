"""Spot's DFAs: language equivalence with Spot's own automaton of the formula, decided by Spot.

Every LTLf formula of the formula tests is turned into a DFA (Spot's ``from_ltlf`` route, the
table over bit-mask letters, Moore); the DFA is written back as an ω-automaton over ``alive`` (a
finite trace ``w`` is the ω-word ``(w & alive) (!alive)^ω``, Spot's own encoding) and
:func:`spot.are_equivalent` compares it with a fresh translation of ``from_ltlf(formula)``.

Before the hand-written construction over flloat's transition function was deleted, the same
check compared its DFAs with Spot's on all these formulas (and 40 random ones): the languages
were equal and the minimal state counts identical on all 48 (docs/howto/formulas.md).
"""

import time

import numpy as np
import pytest
import spot
from hypothesis import given, settings, strategies as st

from tubejax.analyses.spec import dfa_from_formula, parse_formula
from tubejax.analyses.spec.automata import spot_ltlf

LABELS = ["1", "2", "3", "4", "5", "6", "7", "a", "b", "c", "A", "kitchen"]

#: The formulas of the formula tests (tests/spec, tests/test_api.py, the README and docs).
FORMULAS = [
    "(l1 U l2) R (X l3 -> WX l4) <-> (G F lkitchen || last && TRUE)",
    "F l1", "F l3", "F(l1 & F(l2 & F(l3))) & G(!l4)", "F(l1) & G(!l1)", "F(l2) & G(!l1)",
    "F(l2) & G(!l4)", "F(l2)", "F(l3 & F(l2)) & G(!l4)", "F(l3 & F(l4 & F(l5 & F(l6))))",
    "F(l3 & F(l5 & F l3)) & G(!l5 | X l3)", "F(l3 & X X X l2)", "F(l4 & X(false))", "F(l6) & G(!l4)",
    "F(l6) & G(!l5)", "F(l6)", "F(l7) & F(l3)", "F(lA & F la) & G(!l4)", "F(lb & F(la))",
    "F(lb) & G(!lc)", "G !l1 & F l2", "G !l1 & F l3", "G(!l1)", "G(!l4) & F(l1) & F(l6)",
    "G(!l4) & F(l6)", "F(l1 & F l2)", "F(l2 & F(l3)) & G(!l4)", "F(l3 & F(l4 & F(l5)))",
    "F(l3 & F(l5 & F l6)) & G(!l4)", "F(l3 & F(l5))", "F(l3 & l2) & G !l4", "F(lc)",
    "G !l1 & F(l3 & F l2)", "G(!l4) & F(l2) & X l3", "G(F(l1))", "G(l1 -> X l2)", "G(l3 -> X l4)",
    "G(l3 | l4)", "WX(l1) | last", "F l2 & G(!l3)", "F(l3 & F l5) & G(!l2)", "l1 U l2", "!(l1 R l2)",
    "F(l3 & " + "X " * 6 + "l5)", "l1 -> l2 -> l3", "l1 <-> l2 <-> l3", "l1 U l2 U l3", "l1 R l2 R l3",
]


def omega(dfa) -> spot.twa_graph:
    """The ω-automaton over ``alive`` of a DFA that reads non-empty traces (HOA text, one edge a letter)."""
    k, n = len(dfa.propositions), dfa.n_states
    aps = " ".join(f'"{p}"' for p in dfa.propositions) + ' "alive"'

    def letter(s):
        return " & ".join([str(b) if s >> b & 1 else f"!{b}" for b in range(k)] + [str(k)])

    lines = ["HOA: v1", f"States: {n + 2}", f"Start: {n}", f"AP: {k + 1} {aps}",
             "Acceptance: 1 Inf(0)", "--BODY--"]
    for q in range(n + 1):                                   # state n: before the first letter
        lines.append(f"State: {q}")
        src = dfa.initial if q == n else q
        lines += [f"[{letter(s)}] {int(dfa.delta[src, s])}" for s in range(1 << k)]
        if q < n and dfa.accepting[q]:
            lines.append(f"[!{k}] {n + 1}")
    lines += [f"State: {n + 1} {{0}}", f"[!{k}] {n + 1}", "--END--"]
    return spot.automaton("\n".join(lines) + "\n")


def assert_same_language(text):
    p = parse_formula(text, LABELS)
    new = dfa_from_formula(p)
    ref = spot.translate(spot.from_ltlf(spot_ltlf(p)))
    assert spot.are_equivalent(omega(new), ref), text
    return new


@pytest.mark.parametrize("text", FORMULAS)
def test_spot_dfa_has_the_language_of_the_formula(text):
    assert_same_language(text)


def test_restricted_alphabets_keep_the_language_on_those_letters():
    """Over the letters a map can produce (here: never two regions at once) the restricted DFA
    is smaller or equal and accepts what the full one accepts, on those letters only."""
    p = parse_formula("F(l3 & F(l5 & F l6)) & G(!l4)", LABELS)
    k = len(p.propositions)
    ok = np.array([bin(s).count("1") <= 1 for s in range(1 << k)])
    full, small = dfa_from_formula(p), dfa_from_formula(p, ok)
    assert small.n_states <= full.n_states
    props = p.propositions
    pairs = [f"!({a} & {b})" for i, a in enumerate(props) for b in props[i + 1:]]
    only = spot.translate(f"G({' & '.join(pairs)})")                 # never two regions at once
    assert spot.are_equivalent(spot.product(omega(small), only), spot.product(omega(full), only))
    assert not spot.are_equivalent(omega(small), omega(full))            # they differ on the other letters


def formulas(depth):
    atoms = st.sampled_from(["l1", "l2", "l3", "true", "false", "last"])
    if depth == 0:
        return atoms
    sub = formulas(depth - 1)
    return st.one_of(
        atoms,
        st.builds(lambda o, a: f"{o}({a})", st.sampled_from(["!", "X", "WX", "F", "G"]), sub),
        st.builds(lambda a, o, b: f"({a} {o} {b})", sub, st.sampled_from(["&", "|", "->", "<->", "U", "R"]), sub))


@settings(max_examples=40, deadline=None)
@given(formulas(3))
def test_random_formulas_have_the_same_language(text):
    if not any(f"l{i}" in text for i in "123"):
        text = f"({text}) & (l1 | !l1)"
    assert_same_language(text)


def test_spot_is_not_slower_on_the_formula_tests():
    """Construction time over all the formulas of the formula tests (the figures are in the docs)."""
    t = time.perf_counter()
    for text in FORMULAS:
        dfa_from_formula(parse_formula(text, LABELS))
    assert time.perf_counter() - t < 10


def test_the_check_tells_languages_apart():
    """A negative control: DFAs one letter apart in their languages are not equivalent."""
    a = dfa_from_formula(parse_formula("F(l1 & F l2)", LABELS))
    b = dfa_from_formula(parse_formula("F(l1 & X F l2)", LABELS))
    assert not spot.are_equivalent(omega(a), omega(b))


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_letter_sets_match_minterms(seed):
    """The letters of every edge (read from its BDD) are exactly the minterms that imply its condition,
    on Spot's automata of random formulas (Büchi, and the finite automata of the LTLf route)."""
    from spot import buddy
    from tubejax.analyses.spec.automata import letter_sets

    props = [f"l{i}" for i in range(seed + 1)]
    for f in spot.randltl(props, 40, seed=seed, tree_size=(5, 25)):
        for aut in (spot.translate(f, "sbacc", "buchi"), spot.to_finite(spot.translate(spot.from_ltlf(f)))):
            d = aut.get_dict()
            var = {props.index(str(p)): d.varnum(p) for p in aut.ap()}
            edges = list(aut.edges())
            for e, (src, dst, ok) in zip(edges, letter_sets(aut, props)):
                assert (src, dst) == (e.src, e.dst)
                for s in range(1 << len(props)):
                    m = buddy.bddtrue
                    for b, v in var.items():
                        m &= buddy.bdd_ithvar(v) if s >> b & 1 else buddy.bdd_nithvar(v)
                    assert ok[s] == (buddy.bdd_implies(m, e.cond) == 1), (str(f), s)
