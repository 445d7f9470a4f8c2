"""LTL formulas over region labels (infinite runs), parsed by Spot (syntax: docs/howto/formulas.md).

The propositions are those of LTLf formulas (:mod:`.formula`); unary operators may run together
(``GF l3``). ``X`` is the next **time step** of the closed loop, with no stutter
(docs/math/control.md#ltl-over-infinite-runs). LTLf-only words are refused with the key that takes
them; errors name the position in the user's text.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import spot

from .formula import Grammar, Parsed, SpecificationError, _short, check_nesting, known_propositions, lex

__all__ = ["ParsedLTL", "parse_ltl", "LTL_OPERATORS"]

#: The temporal operators of an LTL formula.
LTL_OPERATORS = ("X", "F", "G", "U", "R", "W", "M")


def _ltlf_summary(words: list) -> str:
    """The message on the LTLf-only ``words`` of an LTL formula."""
    return (f"{', '.join(words[:5])} only exist in LTLf formulas over finite runs: give this formula as "
            "spec.formula (tj.plan(ts, '<formula>')), or write it without them")


#: The words of LTL formulas (module docstring).
LTL = Grammar(LTL_OPERATORS, ("true", "false"), "G F l3 & G F l6 & G !l4", "'GF l3', not 'GFl3'",
              lambda w, pos: f"'{w}' (position {pos})" if w == "WX" or w.lower() in ("last", "end") else None,
              _ltlf_summary, r"[XFG]+")


@dataclass(frozen=True)
class ParsedLTL(Parsed):
    """An LTL formula parsed by Spot: ``formula`` (a ``spot.formula``) and its top-level conjuncts ``parts``
    as the user wrote them (Spot merges ``G a & G b`` into ``G(a & b)``; explanations name the user's parts)."""

    formula: object
    parts: tuple = ()

    def conjuncts(self) -> list:
        """The top-level conjuncts (Spot formulas), as written when they are known."""
        if self.parts:
            return list(self.parts)
        f = self.formula
        return list(f) if f.kind() == spot.op_And else [f]


def parse_ltl(text: str, labels, key: str = "spec.ltl") -> ParsedLTL:
    """Check ``text`` against the map's ``labels`` and parse it with Spot.

    Parameters
    ----------
    text : str
        An LTL formula over ``l<label>`` propositions (module docstring).
    labels : iterable
        The region labels present on the map (``None`` entries are ignored).
    key : str
        The name of the input in messages.

    Raises
    ------
    SpecificationError
        Unknown words or propositions (with their positions and the map's propositions), an
        LTLf-only word (``WX``, ``last``, ``end``: use ``spec.formula``), a syntax error
        (with its position), or nesting deeper than :data:`~.formula.MAX_NESTING`.
    """
    if not isinstance(text, str):
        raise SpecificationError(f"{key}: expected a string, got {text!r}")
    known = known_propositions(labels)
    tokens = lex(key, text, known, LTL)
    _check_nesting(tokens, key, text)
    parts, spans, at = [], [], 0
    for _, t, pos in tokens:
        spans.append((at, at + len(t), pos))
        parts.append(t)
        at += len(t) + 1
    internal = " ".join(parts)
    try:
        f = spot.formula(internal)
    except SyntaxError as exc:
        raise SpecificationError(f"{key} {_short(text)!r}: syntax error {_where(str(exc), spans, len(text))}") from None
    props = tuple(sorted({str(a) for a in spot.atomic_prop_collect(f)}))
    return ParsedLTL(text, props, tuple(known[p] for p in props), f, _parts(parts, f))


def _check_nesting(tokens: list, key: str, text: str) -> None:
    """Refuse ``tokens`` nested deeper than :data:`~.formula.MAX_NESTING` (an upper bound: parentheses
    and runs of unary operators)."""
    depth = level = 0
    for _, t, _ in tokens:                                 # parentheses and unary operators, an upper bound
        level += t == "("
        level -= t == ")"
        depth = max(depth, level)
    unary = max((len(run) for run in re.findall(r"(?:[!XFG] )+", " ".join(t for _, t, _ in tokens) + " ")),
                default=0) // 2
    check_nesting(key, text, depth + unary)


def _parts(tokens: list, f) -> tuple:
    """The formulas between the top-level ``&`` of ``tokens``, if they make up ``f`` (else ``()``)."""
    groups, cur, level = [], [], 0
    for t in tokens:
        level += (t == "(") - (t == ")")
        if level == 0 and t in ("|", "||", "->", "<->", "U", "R", "W", "M"):
            return ()
        if level == 0 and t in ("&", "&&"):
            groups.append(cur)
            cur = []
        else:
            cur.append(t)
    groups.append(cur)
    if len(groups) < 2:
        return ()
    try:
            parts = tuple(spot.formula(" ".join(g)) for g in groups)
    except SyntaxError:
        return ()
    return parts if spot.are_equivalent(spot.formula.And(list(parts)), f) else ()


def _where(msg: str, spans, n: int) -> str:
    """The first error of Spot's message, at the position in the user's text."""
    m = re.search(r"^>>> .*\n( *)\^+\n(.*)$", msg, re.M)
    if not m:
        return "(position unknown)"
    i, what = len(m.group(1)) - 4, m.group(2).removeprefix("syntax error, ")
    for a, b, pos in spans:
        if a <= i < b + 1:
            return f"at position {pos}: {what}"
    return f"at position {n} (the formula ends too early): {what}"
