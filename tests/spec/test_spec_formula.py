"""Formulas over region labels: propositions, parsing, and errors that name positions."""

import pytest

from tubejax.analyses.spec import SpecificationError, parse_formula, proposition_of
from tubejax.analyses.spec.formula import sequence_formula

LABELS = ["1", "2", "3", "4", "a", "A", "kitchen", None]


def test_every_label_becomes_l_followed_by_it():
    assert proposition_of("3") == "l3" and proposition_of(3) == "l3"
    assert proposition_of("a") == "la" and proposition_of("A") == "lA"
    assert proposition_of("kitchen") == "lkitchen"
    assert proposition_of("x-1") is None and proposition_of("") is None
    assert proposition_of("ast") is None                     # 'last' is the keyword


def test_parse_orders_propositions_and_keeps_case():
    p = parse_formula("F(lA & F la) & G(!l4)", LABELS)
    assert p.propositions == ("l4", "lA", "la") and p.labels == ("4", "A", "a")
    assert str(p.ltlf) == "(F((p1 & F(p2))) & G(!(p0)))"
    assert p.render(p.ltlf) == "(F((lA & F(la))) & G(!(l4)))"
    assert [p.render(c) for c in p.conjuncts()] == ["F((lA & F(la)))", "G(!(l4))"]


def test_operators_and_keywords():
    p = parse_formula("(l1 U l2) R (X l3 -> WX l4) <-> (G F lkitchen || last && TRUE)", LABELS)
    assert set(p.propositions) == {"l1", "l2", "l3", "l4", "lkitchen"}


def test_unknown_propositions_are_all_named_with_positions():
    with pytest.raises(SpecificationError) as e:
        parse_formula("F(l7) & G(!l9) & F(l3)", LABELS)
    msg = str(e.value)
    assert "unknown propositions l7 (position 2), l9 (position 11)" in msg
    assert "l1, l2, l3, l4, lA, la, lkitchen" in msg


def test_words_that_are_not_operators_or_propositions():
    with pytest.raises(SpecificationError, match=r"'Fl3' at position 0 .* not 'Fl3'"):
        parse_formula("Fl3", LABELS)
    with pytest.raises(SpecificationError, match=r"'x3' at position 2"):
        parse_formula("F x3", LABELS)
    with pytest.raises(SpecificationError, match=r"unexpected character '\$' at position 3"):
        parse_formula("l1 $ l2", LABELS)
    with pytest.raises(SpecificationError, match="'end' is not supported"):
        parse_formula("F(l1 & end)", LABELS)


@pytest.mark.parametrize("text, pos", [("F(l3 & ", 7), ("F(l3) & X", 9), ("F(l3 & & l4)", 7),
                                       ("l3 l4", 3), ("(l1", 3)])
def test_syntax_errors_name_the_position(text, pos):
    with pytest.raises(SpecificationError, match=rf"syntax error at position {pos}\b"):
        parse_formula(text, LABELS)


def test_empty_and_non_string():
    with pytest.raises(SpecificationError, match="empty"):
        parse_formula("   ", LABELS)
    with pytest.raises(SpecificationError, match="expected a string"):
        parse_formula(3, LABELS)
    assert issubclass(SpecificationError, ValueError)


def test_sequence_formula():
    assert sequence_formula(["l3", "l4", "l5"]) == "F(l3 & F(l4 & F(l5)))"
    with pytest.raises(SpecificationError):
        sequence_formula([])
