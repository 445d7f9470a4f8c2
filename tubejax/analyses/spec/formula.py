"""LTLf formulas over region labels: propositions, lexing and parsing (flloat).

How a label becomes a proposition
---------------------------------
A region label made of the characters ``0-9A-Za-z`` (case-sensitive, any length)
is the proposition ``l`` followed by the label: label ``3`` is ``l3``, label ``a``
is ``la``, label ``A`` is ``lA`` (a different proposition), label ``kitchen`` is
``lkitchen``. ``l<label>`` holds at a time step when the state lies in the
*closed* region of that label (the union of its closed cells, up to ``1e-9``), so
a state on a boundary shared by two regions satisfies both propositions.
Labels with other characters (possible in polygon workspaces) have no
proposition; they still work in ``spec.sequence``.

Syntax (flloat's LTLf grammar): ``!`` not, ``&``/``&&`` and, ``|``/``||`` or,
``->``, ``<->``, ``X`` next, ``WX`` weak next, ``F`` eventually, ``G`` always,
``U`` until, ``R`` release, ``true``, ``false``, ``last`` (the last instant);
parentheses group. Operators are separate words: ``F l3`` or ``F(l3)``, not
``Fl3``; ``l3 U l4``, not ``l3Ul4``. The words ``true``, ``false``, ``last`` and
``end`` are reserved in any case (so a label ``ast`` cannot be named: ``last``
is the keyword).

The formula is checked here (unknown words and propositions are reported with
their positions) and parsed by flloat with the propositions renamed ``p0, p1,
...`` (flloat only accepts lower-case names); errors come back as
:class:`SpecificationError` with the position in the user's text.

**Nesting depth.** A formula may nest at most :data:`MAX_NESTING` (64) operators
and parentheses: the *nesting depth* is the most operators (``!``, ``X``, ``WX``,
``F``, ``G``, and each chain of one binary operator such as ``a & b & c``) and
parenthesised groups on the way from the whole formula down to one proposition
(``F(l3 & F(l5))`` has depth 5: ``F``, ``(``, ``&``, ``F``, ``(``). Deeper
formulas are refused with the depth found, before anything recursive runs (a
12-region visiting sequence ``F(l1 & F(l2 & ...))`` has depth 35).
"""

from __future__ import annotations

import re
import warnings
from dataclasses import dataclass
from pathlib import Path

from flloat.ltlf import LTLfAnd
from flloat.parser import CUR_DIR
from flloat.parser.ltlf import LTLfTransformer
from lark import Lark
from lark.exceptions import LarkError, UnexpectedInput

from ...errors import InputError

__all__ = ["SpecificationError", "ParsedFormula", "parse_formula", "proposition_of",
           "label_of_proposition", "sequence_formula", "RESERVED", "MAX_NESTING"]

#: Deepest nesting of operators and parentheses a formula may have (module docstring).
MAX_NESTING = 64


class SpecificationError(InputError):
    """A malformed specification; the message names the position or the field."""


#: Reserved words (matched case-insensitively, as flloat does).
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


def label_of_proposition(prop: str) -> str:
    """``'l3'`` -> ``'3'``."""
    return prop[1:]


@dataclass(frozen=True)
class ParsedFormula:
    """A formula checked against the map's labels and parsed by flloat.

    Attributes
    ----------
    text : str
        The user's formula.
    propositions : tuple of str
        The propositions it uses, sorted (``('l3', 'l4', ...)``); bit ``b`` of a
        letter stands for ``propositions[b]``.
    labels : tuple of str
        The region label of each proposition.
    ltlf : flloat LTLfFormula
        The parsed formula over the internal names ``p0, p1, ...`` (``p{b}`` is
        ``propositions[b]``).
    """

    text: str
    propositions: tuple
    labels: tuple
    ltlf: object

    def render(self, ltlf) -> str:
        """A flloat (sub)formula written with the user's proposition names."""
        return re.sub(r"\bp(\d+)\b", lambda m: self.propositions[int(m.group(1))], str(ltlf))

    def conjuncts(self) -> list:
        """The top-level conjuncts of the formula (flloat formulas)."""

        out, todo = [], [self.ltlf]
        while todo:
            f = todo.pop(0)
            if isinstance(f, LTLfAnd):
                todo = list(f.formulas) + todo
            else:
                out.append(f)
        return out


def _lex(text: str, known: dict):
    """Tokens ``(kind, value, position)``; raises on unknown words and propositions."""
    tokens, unknown, bad = [], [], []
    for m in _TOKEN.finditer(text):
        pos = m.start()
        if m.group("bad") is not None:
            bad.append(f"unexpected character {m.group('bad')!r} at position {pos}")
        elif m.group("sym") is not None:
            tokens.append(("sym", m.group("sym"), pos))
        elif (w := m.group("word")) is not None:
            if w.lower() == "end":
                bad.append(f"'{w}' at position {pos}: 'end' is not supported (flloat 0.3); "
                           "use 'last' for the last instant")
            elif w.lower() in RESERVED:
                tokens.append(("word", w.lower(), pos))
            elif w in _OPERATORS:
                tokens.append(("word", w, pos))
            elif w.startswith("l") and _LABEL.fullmatch(w[1:]):
                if w in known:
                    tokens.append(("prop", w, pos))
                else:
                    unknown.append(f"{w} (position {pos})")
            elif w in ("W", "M") or re.fullmatch(r"[XFG]{2,}", w):
                bad.append(f"'{w}' at position {pos}: '{w}' and operators run together (GF, FG) "
                           "belong to LTL over infinite runs: give the formula as spec.ltl "
                           "(tj.plan(ts, ltl=...)), or write 'G F l3' for an LTLf formula over finite runs")
            else:
                hint = (" (separate operators from propositions: 'F l3' or 'F(l3)', not 'Fl3')"
                        if w[:1] in "GFXURW" else "")
                bad.append(f"'{w}' at position {pos} is not an operator ({' '.join(_OPERATORS)}), "
                           f"a keyword (true false last) or a proposition l<label>{hint}")
    more = lambda items: items[:10] + ([f"{len(items) - 10} more"] if len(items) > 10 else [])  # noqa: E731
    msgs = more(bad)
    if unknown:
        have = ", ".join(sorted(known)) or "none"
        msgs.append(f"unknown propositions {', '.join(more(unknown))}: no region carries these labels "
                    f"(the map's propositions: {have})")
    if msgs:
        raise SpecificationError(f"formula {_short(text)!r}: " + "; ".join(msgs))
    if not tokens:
        raise SpecificationError("formula is empty: write e.g. 'F(l3) & G(!l4)'")
    return tokens


def parse_formula(text: str, labels) -> ParsedFormula:
    """Check ``text`` against the map's ``labels`` and parse it with flloat.

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
    parser, transformer = _parser()                  # imports flloat and lark quietly

    if not isinstance(text, str):
        raise SpecificationError(f"formula: expected a string, got {text!r}")
    known = {}
    for l in labels:
        if l is not None and (p := proposition_of(l)) is not None:
            known[p] = str(l)
    tokens = _lex(text, known)
    props = tuple(sorted({v for k, v, _ in tokens if k == "prop"}))
    index = {p: b for b, p in enumerate(props)}
    parts, spans, at = [], [], 0
    for kind, value, pos in tokens:                  # internal text, one space between tokens
        s = f"p{index[value]}" if kind == "prop" else value
        spans.append((at, at + len(s), pos))
        parts.append(s)
        at += len(s) + 1
    internal = " ".join(parts)
    try:
        tree = parser.parse(internal)               # LALR: iterative, any depth
    except UnexpectedInput as exc:
        where = _user_position(exc, spans, len(text))
        raise SpecificationError(f"formula {_short(text)!r}: syntax error {where}") from None
    except LarkError as exc:
        raise SpecificationError(f"formula {_short(text)!r}: cannot parse ({exc})") from None
    depth = _nesting(tree)
    if depth > MAX_NESTING:
        raise SpecificationError(f"formula {_short(text)!r}: nested {depth} deep (operators and parentheses "
                                 f"inside one another); at most {MAX_NESTING} are supported")
    try:
        f = transformer.transform(tree)
    except (LarkError, NotImplementedError, AssertionError) as exc:
        raise SpecificationError(f"formula {_short(text)!r}: cannot parse ({exc})") from None
    return ParsedFormula(text, props, tuple(known[p] for p in props), f)


#: Parse-tree nodes that are an operator or a parenthesised group (flloat's ltlf.lark).
_NESTING_NODES = frozenset({"ltlf_equivalence", "ltlf_implication", "ltlf_or", "ltlf_and", "ltlf_until",
                            "ltlf_release", "ltlf_always", "ltlf_eventually", "ltlf_next",
                            "ltlf_weak_next", "ltlf_not", "ltlf_wrapped"})


def _nesting(tree) -> int:
    """Most operator and parenthesis nodes on one root-to-leaf path of a lark tree (iterative)."""
    best, todo = 0, [(tree, 0)]
    while todo:
        t, d = todo.pop()
        d += t.data in _NESTING_NODES
        best = max(best, d)
        todo.extend((c, d) for c in t.children if hasattr(c, "children"))
    return best


def _short(text: str, n: int = 80) -> str:
    """``text`` cut to about ``n`` characters for a message."""
    return text if len(text) <= n else f"{text[:n // 2]} ... {text[-n // 4:]}"


_PARSER = {}


def _parser():
    """flloat's LTLf grammar as a lark LALR parser, and flloat's transformer to formulas (cached)."""
    if "p" not in _PARSER:
        with warnings.catch_warnings():              # lark-parser 0.12 imports sre_parse (deprecated)
            warnings.simplefilter("ignore", DeprecationWarning)
            with open(Path(CUR_DIR) / "ltlf.lark") as fh:   # as flloat does: '%import .pl' relative to it
                _PARSER["p"] = (Lark(fh, parser="lalr"), LTLfTransformer())
    return _PARSER["p"]


def _user_position(exc, spans, n) -> str:
    tok = getattr(exc, "token", None)
    if tok is not None and getattr(tok, "type", "") == "$END":
        return f"at position {n} (the formula ends too early)"
    i = getattr(exc, "pos_in_stream", None)
    if i is None:
        return "(position unknown)"
    for a, b, pos in spans:
        if a <= i < b + 1:
            word = f" near {str(tok)!r}" if tok is not None else ""
            return f"at position {pos}{word}"
    return f"at position {n} (the formula ends too early)"


def sequence_formula(props) -> str:
    """``['l3', 'l4', 'l5']`` -> ``'F(l3 & F(l4 & F(l5)))'`` (visit in order)."""
    props = list(props)
    if not props:
        raise SpecificationError("sequence: give at least one target label")
    out = f"F({props[-1]})"
    for p in reversed(props[:-1]):
        out = f"F({p} & {out})"
    return out
