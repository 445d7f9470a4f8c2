"""LTLf formulas over region labels: propositions, lexing and parsing (the syntax, the
propositions ``l<label>`` and the limits: docs/howto/formulas.md).

The formula is checked here (unknown words and propositions are reported with their positions by
:func:`lex`, which lexes LTL formulas too: :mod:`.ltl`) and parsed into a tree (:mod:`.ltlf`,
iterative) with the propositions renamed ``p0, p1, ...``; errors come back as
:class:`SpecificationError` with the position in the user's text. A formula nesting more than
:data:`MAX_NESTING` operators and parentheses is refused before anything recursive runs.
:func:`describe` puts a (sub)formula in words for the messages of :mod:`.explain`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Callable

from ...errors import InputError
from .ltlf import (LTLfAlways, LTLfAnd, LTLfAtomic, LTLfEventually, LTLfFalse, LTLfLast, LTLfNext, LTLfNot, LTLfOr,
                   LTLfSyntaxError, LTLfTrue, LTLfUntil, LTLfWeakNext, parse_tokens)

__all__ = ["SpecificationError", "ParsedFormula", "parse_formula", "proposition_of", "describe",
           "sequence_formula", "RESERVED", "MAX_NESTING", "Parsed", "Grammar", "LTLF", "lex"]

#: Deepest nesting of operators and parentheses a formula may have (module docstring).
MAX_NESTING = 64


class SpecificationError(InputError):
    """A malformed specification; the message names the position or the field."""


#: Reserved words (matched case-insensitively).
RESERVED = ("true", "false", "last", "end")
_OPERATORS = ("G", "F", "X", "WX", "U", "R")
_LABEL = re.compile(r"[0-9A-Za-z]+")
_TOKEN = re.compile(r"\s+|(?P<word>[A-Za-z0-9_]+)|(?P<sym><->|->|&&|\|\||[&|!()])|(?P<bad>.)")


def proposition_of(label) -> str | None:
    """The proposition naming ``label`` (``'3'`` -> ``'l3'``), ``None`` if it cannot be named."""
    s = str(label)
    if not _LABEL.fullmatch(s) or ("l" + s).lower() in RESERVED:
        return None
    return "l" + s


@dataclass(frozen=True)
class Parsed:
    """A formula checked against the map's labels (:class:`ParsedFormula`, :class:`~.ltl.ParsedLTL`).

    Attributes
    ----------
    text : str
        The user's formula.
    propositions : tuple of str
        The propositions it uses, sorted (``('l3', 'l4', ...)``); bit ``b`` of a
        letter stands for ``propositions[b]``.
    labels : tuple of str
        The region label of each proposition.
    """

    text: str
    propositions: tuple
    labels: tuple


@dataclass(frozen=True)
class ParsedFormula(Parsed):
    """An LTLf formula parsed into a tree: ``ltlf`` (:mod:`.ltlf`), over the internal names ``p0, p1, ...``
    (``p{b}`` is ``propositions[b]``)."""

    ltlf: object

    def render(self, ltlf) -> str:
        """A (sub)formula written with the user's proposition names."""
        return re.sub(r"\bp(\d+)\b", lambda m: self.propositions[int(m.group(1))], str(ltlf))

    def conjuncts(self) -> list:
        """The top-level conjuncts of the formula (trees)."""

        out, todo = [], [self.ltlf]
        while todo:
            f = todo.pop(0)
            if isinstance(f, LTLfAnd):
                todo = list(f.formulas) + todo
            else:
                out.append(f)
        return out


@dataclass(frozen=True)
class Grammar:
    """The words of one logic for :func:`lex` (LTLf: :data:`LTLF`, LTL: :data:`~.ltl.LTL`): its ``operators``,
    its ``keywords`` (lower case, read in any case), an ``example`` (for an empty formula), how to
    ``separate`` an operator from a proposition, ``foreign(word, position)`` (the complaint about a word
    of the other logic, else ``None``), ``summary(complaints)`` (one message for them all after the
    others; ``None``: each among the others in the order of the text) and ``runs``, a pattern of unary
    operators that may run together (one token each)."""

    operators: tuple
    keywords: tuple
    example: str
    separate: str
    foreign: Callable
    summary: Callable | None = None
    runs: str | None = None


def _ltl_word(w: str, pos: int) -> str | None:
    """The complaint about ``w`` at ``pos`` if it is a word of LTL (or ``end``), else ``None``."""
    if w.lower() == "end":
        return f"'{w}' at position {pos}: 'end' is not supported; use 'last' for the last instant"
    if w in ("W", "M") or re.fullmatch(r"[XFG]{2,}", w):
        return (f"'{w}' at position {pos}: '{w}' and operators run together (GF, FG) belong to LTL over infinite "
                "runs: give the formula as spec.ltl (tj.plan(ts, ltl=...)), or write 'G F l3' for an LTLf formula "
                "over finite runs")
    return None


#: The words of LTLf formulas (module docstring).
LTLF = Grammar(_OPERATORS, ("true", "false", "last"), "F(l3) & G(!l4)", "'F l3' or 'F(l3)', not 'Fl3'", _ltl_word)


def lex(key: str, text: str, known: dict, grammar: Grammar) -> list:
    """The tokens ``(kind, value, position)`` of ``text`` (``kind``: ``'sym'``, ``'word'`` or ``'prop'``).

    Raises
    ------
    SpecificationError
        Naming every bad character and word and every proposition not in ``known``
        (proposition -> label of the map), with their positions (:func:`refuse`); or an empty formula.
    """
    tokens, bad, unknown, foreign = [], [], [], []
    for m in _TOKEN.finditer(text):
        pos = m.start()
        if m.group("bad") is not None:
            bad.append(f"unexpected character {m.group('bad')!r} at position {pos}")
        elif m.group("sym") is not None:
            tokens.append(("sym", m.group("sym"), pos))
        elif (w := m.group("word")) is None:
            continue
        elif w.startswith("l") and _LABEL.fullmatch(w[1:]) and w.lower() not in RESERVED:
            if w in known:
                tokens.append(("prop", w, pos))
            else:
                unknown.append(f"{w} (position {pos})")
        elif (why := grammar.foreign(w, pos)) is not None:
            (foreign if grammar.summary else bad).append(why)
        elif w.lower() in grammar.keywords:
            tokens.append(("word", w.lower(), pos))
        elif w in grammar.operators:
            tokens.append(("word", w, pos))
        elif grammar.runs and re.fullmatch(grammar.runs, w):
            tokens.extend(("word", c, pos + i) for i, c in enumerate(w))
        else:
            hint = (f" (separate operators from propositions: {grammar.separate})"
                    if w[:1] in {op[0] for op in grammar.operators} else "")
            bad.append(f"'{w}' at position {pos} is not an operator ({' '.join(grammar.operators)}), "
                       f"a keyword ({' '.join(grammar.keywords)}) or a proposition l<label>{hint}")
    refuse(key, text, bad, unknown, known, [grammar.summary(foreign)] if foreign else [])
    if not tokens:
        raise SpecificationError(f"{key} is empty: write e.g. {grammar.example!r}")
    return tokens


def known_propositions(labels) -> dict:
    """``{proposition: label}`` of the map's ``labels`` that can be named (``None`` entries are ignored)."""
    return {p: str(l) for l in labels if l is not None and (p := proposition_of(l)) is not None}


def refuse(key: str, text: str, bad: list, unknown: list, known: dict, extra=()) -> None:
    """Raise the :class:`SpecificationError` naming the ``bad`` words (ten at most), ``extra`` and the
    ``unknown`` propositions with the map's ``known`` ones; nothing when all are empty."""
    def ten(items):
        return items[:10] + ([f"{len(items) - 10} more"] if len(items) > 10 else [])

    msgs = ten(bad) + list(extra)
    if unknown:
        msgs.append(f"unknown propositions {', '.join(ten(unknown))}: no region carries these labels "
                    f"(the map's propositions: {', '.join(sorted(known)) or 'none'})")
    if msgs:
        raise SpecificationError(f"{key} {_short(text)!r}: " + "; ".join(msgs))


def check_nesting(key: str, text: str, depth: int) -> None:
    """Refuse a formula nested deeper than :data:`MAX_NESTING`."""
    if depth > MAX_NESTING:
        raise SpecificationError(f"{key} {_short(text)!r}: nested {depth} deep (operators and parentheses "
                                 f"inside one another); at most {MAX_NESTING} are supported")


def parse_formula(text: str, labels) -> ParsedFormula:
    """Check ``text`` against the map's ``labels`` and parse it.

    Parameters
    ----------
    text : str
        An LTLf formula over ``l<label>`` propositions (module docstring).
    labels : iterable
        The region labels present on the map (``None`` entries are ignored).

    Returns
    -------
    ParsedFormula

    Raises
    ------
    SpecificationError
        Unknown words or propositions (all of them, with their positions), a
        syntax error (with its position), or nesting deeper than :data:`MAX_NESTING`.
    """
    if not isinstance(text, str):
        raise SpecificationError(f"formula: expected a string, got {text!r}")
    known = known_propositions(labels)
    tokens = lex("formula", text, known, LTLF)
    props = tuple(sorted({v for k, v, _ in tokens if k == "prop"}))
    index = {p: b for b, p in enumerate(props)}
    internal = [(k, f"p{index[v]}" if k == "prop" else v) for k, v, _ in tokens]
    try:
        f, depth = parse_tokens(internal)             # iterative: any depth
    except LTLfSyntaxError as exc:
        where = (f"at position {len(text)} (the formula ends too early)" if exc.position is None
                 else f"at position {tokens[exc.position][2]} near {tokens[exc.position][1]!r}")
        raise SpecificationError(f"formula {_short(text)!r}: syntax error {where}") from None
    check_nesting("formula", text, depth)
    return ParsedFormula(text, props, tuple(known[p] for p in props), f)


def _short(text: str, n: int = 80) -> str:
    """``text`` cut to about ``n`` characters for a message."""
    return text if len(text) <= n else f"{text[:n // 2]} ... {text[-n // 4:]}"


def sequence_formula(props) -> str:
    """``['l3', 'l4', 'l5']`` -> ``'F(l3 & F(l4 & F(l5)))'`` (visit in order)."""
    props = list(props)
    if not props:
        raise SpecificationError("sequence: give at least one target label")
    out = f"F({props[-1]})"
    for p in reversed(props[:-1]):
        out = f"F({p} & {out})"
    return out


def _label(parsed: ParsedFormula, atom) -> str:
    return parsed.labels[int(str(atom.s)[1:])]


def _state(parsed: ParsedFormula, f) -> str | None:
    """A condition on one instant in words (``'in region 3 and outside region 4'``), ``None`` if temporal."""

    if isinstance(f, LTLfTrue):
        return "anywhere"
    if isinstance(f, LTLfFalse):
        return "nowhere (false)"
    if isinstance(f, LTLfAtomic):
        return f"in region {_label(parsed, f)}"
    if isinstance(f, LTLfNot) and isinstance(f.f, LTLfAtomic) and not isinstance(f.f, (LTLfTrue, LTLfFalse)):
        return f"outside region {_label(parsed, f.f)}"
    if isinstance(f, (LTLfAnd, LTLfOr)):
        parts = [_state(parsed, g) for g in f.formulas]
        if all(p is not None for p in parts):
            return (" and " if isinstance(f, LTLfAnd) else " or ").join(parts)
    return None


def describe(parsed: ParsedFormula, f) -> str:
    """What the (sub)formula ``f`` asks, in words.

    Parameters
    ----------
    parsed : ParsedFormula
        The formula ``f`` belongs to (its proposition names and labels).
    f : LTLfFormula
        Over the internal names ``p0, p1, ...``.

    Returns
    -------
    str
        E.g. ``'the state to be in region 3 at some instant'``, ``'the state never to be in
        region 4'``; shapes without words are quoted (``"that 'G((l3 -> X(l4)))' holds"``).
    """

    if isinstance(f, LTLfFalse):
        return "'false', which never holds"
    if isinstance(f, LTLfLast):
        return "the run to end at the start (no step at all)"
    if (s := _state(parsed, f)) is not None:
        return f"the state to start {s}"
    if isinstance(f, LTLfEventually) and (s := _state(parsed, f.f)) is not None:
        return f"the state to be {s} at some instant"
    if isinstance(f, LTLfAlways):
        g = f.f
        if isinstance(g, LTLfNot) and (s := _state(parsed, g.f)) is not None and s.startswith("in region"):
            return f"the state never to be {s}"
        if (s := _state(parsed, g)) is not None:
            return f"the state to be {s} at every instant"
    if isinstance(f, (LTLfNext, LTLfWeakNext)):
        k, g, weak = 0, f, False
        while isinstance(g, (LTLfNext, LTLfWeakNext)):
            k, weak, g = k + 1, weak or isinstance(g, LTLfWeakNext), g.f
        step = f"at time step {k} ({k} step{'s' if k > 1 else ''} after the start)"
        if_long = ", if the run lasts that long" if weak else ""
        if isinstance(g, LTLfLast):
            return f"the run to end exactly at time step {k}"
        if (s := _state(parsed, g)) is not None:
            return f"the state to be {s} {step}{if_long}"
    if isinstance(f, LTLfUntil) and len(f.formulas) == 2:
        a, b = (_state(parsed, g) for g in f.formulas)
        if a is not None and b is not None:
            return f"the state to stay {a} until it is {b}"
    return f"that {parsed.render(f)!r} holds"


def _regions(labels) -> str:
    labels = list(labels)
    return ("region " if len(labels) == 1 else "regions ") + ", ".join(labels)
