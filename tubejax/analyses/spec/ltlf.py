"""LTLf formula trees and their parser (iterative, any depth).

The tree keeps the formula as written, for explanations (:mod:`.explain`, :func:`~.formula.describe`):
n-ary ``&``, ``|``, ``->``, ``<->``, ``U``, ``R`` chains (``a & b & c`` is one node with three
parts; a parenthesised part stays a part), unary ``!``, ``X``, ``WX``, ``F``, ``G``, the
propositions (internal names ``p0, p1, ...``) and ``true``, ``false``, ``last``. It is written
back fully parenthesised (``(F((p1 & F(p2))) & G(!(p0)))``); Spot builds the automata from it
(:func:`~tubejax.analyses.spec.automata.spot_ltlf`).

Precedence, loosest first: ``<->``, ``->``, ``|``, ``&``, ``U``, ``R``, then the unary
operators. Semantics of the chains: ``a -> b -> c`` is ``(a -> b) -> c``, ``a <-> b <-> c``
says all parts have the same value, ``a U b U c`` is ``a U (b U c)`` (as ``R``).
"""

from __future__ import annotations

__all__ = ["LTLfFormula", "LTLfAtomic", "LTLfTrue", "LTLfFalse", "LTLfLast", "LTLfNot", "LTLfNext",
           "LTLfWeakNext", "LTLfEventually", "LTLfAlways", "LTLfAnd", "LTLfOr", "LTLfImplies",
           "LTLfEquivalence", "LTLfUntil", "LTLfRelease", "parse_tokens", "LTLfSyntaxError"]


class LTLfSyntaxError(ValueError):
    """A token that cannot come where it is: ``position`` is the index of the token (``None``: the end)."""

    def __init__(self, position, what: str):
        super().__init__(what)
        self.position, self.what = position, what


class LTLfFormula:
    """A node of an LTLf formula tree."""

    def find_labels(self) -> set:
        """The proposition names in the subtree (internal names ``p0, ...``)."""
        out, todo = set(), [self]
        while todo:
            g = todo.pop()
            if type(g) is LTLfAtomic:
                out.add(g.s)
            todo.extend(_kids(g))
        return out

    def to_nnf(self) -> "LTLfFormula":
        """Negation normal form: ``!`` only on propositions; ``->`` and ``<->`` expanded."""
        return _nnf(self, False)


class LTLfAtomic(LTLfFormula):
    def __init__(self, s: str):
        self.s = s

    def __str__(self):
        return self.s


class LTLfTrue(LTLfAtomic):
    def __init__(self):
        super().__init__("true")


class LTLfFalse(LTLfAtomic):
    def __init__(self):
        super().__init__("false")


class LTLfLast(LTLfFormula):
    def __str__(self):
        return "last"


class _Unary(LTLfFormula):
    symbol = ""

    def __init__(self, f: LTLfFormula):
        self.f = f

    def __str__(self):
        return f"{self.symbol}({self.f})"


class _Nary(LTLfFormula):
    symbol = ""

    def __init__(self, formulas):
        self.formulas = list(formulas)

    def __str__(self):
        return "(" + f" {self.symbol} ".join(map(str, self.formulas)) + ")"


def _node(base: type, name: str, symbol: str) -> type:
    """The node class of one operator: ``base`` (:class:`_Unary` or :class:`_Nary`) with its ``symbol``."""
    return type(name, (base,), {"symbol": symbol, "__module__": __name__})


LTLfNot, LTLfNext, LTLfWeakNext, LTLfEventually, LTLfAlways = (
    _node(_Unary, name, sym) for name, sym in (("LTLfNot", "!"), ("LTLfNext", "X"), ("LTLfWeakNext", "WX"),
                                               ("LTLfEventually", "F"), ("LTLfAlways", "G")))
LTLfAnd, LTLfOr, LTLfImplies, LTLfEquivalence, LTLfUntil, LTLfRelease = (
    _node(_Nary, name, sym) for name, sym in (("LTLfAnd", "&"), ("LTLfOr", "|"), ("LTLfImplies", "->"),
                                              ("LTLfEquivalence", "<->"), ("LTLfUntil", "U"), ("LTLfRelease", "R")))


def _kids(g) -> list:
    return list(getattr(g, "formulas", None) or ((g.f,) if hasattr(g, "f") else ()))


_DUAL = {LTLfAnd: LTLfOr, LTLfOr: LTLfAnd, LTLfNext: LTLfWeakNext, LTLfWeakNext: LTLfNext,
         LTLfEventually: LTLfAlways, LTLfAlways: LTLfEventually, LTLfUntil: LTLfRelease, LTLfRelease: LTLfUntil}


def _nnf(f, neg: bool):
    """NNF of ``f`` (``neg``: of its negation); formulas are at most 64 deep when this runs."""
    t = type(f)
    if t is LTLfNot:
        return _nnf(f.f, not neg)
    if t is LTLfTrue or t is LTLfFalse:
        return (LTLfFalse() if t is LTLfTrue else LTLfTrue()) if neg else f
    if t is LTLfAtomic:
        return LTLfNot(f) if neg else f
    if t is LTLfLast:                                   # !last: there is a next instant
        return LTLfNext(LTLfTrue()) if neg else f
    if t is LTLfImplies:
        g = f.formulas[0]
        for h in f.formulas[1:]:
            g = LTLfOr([LTLfNot(g), h])
        return _nnf(g, neg)
    if t is LTLfEquivalence:
        return _nnf(LTLfOr([LTLfAnd(f.formulas), LTLfAnd([LTLfNot(g) for g in f.formulas])]), neg)
    if isinstance(f, _Unary):
        return (_DUAL[t] if neg else t)(_nnf(f.f, neg))
    return (_DUAL[t] if neg else t)([_nnf(g, neg) for g in f.formulas])


#: Binary operators: token -> (precedence, node class).
_BINARY = {"<->": (1, LTLfEquivalence), "->": (2, LTLfImplies), "|": (3, LTLfOr), "||": (3, LTLfOr),
           "&": (4, LTLfAnd), "&&": (4, LTLfAnd), "U": (5, LTLfUntil), "R": (6, LTLfRelease)}
_UNARY = {"!": LTLfNot, "X": LTLfNext, "WX": LTLfWeakNext, "F": LTLfEventually, "G": LTLfAlways}
_CONST = {"true": LTLfTrue, "false": LTLfFalse, "last": LTLfLast}


class _Group:
    """A parenthesised part while parsing (kept as a part, and counted in the nesting depth)."""

    def __init__(self, f):
        self.f = f


def parse_tokens(tokens) -> tuple[LTLfFormula, int]:
    """Parse ``[(kind, value)]`` tokens (``kind``: ``'prop'`` with an internal name, ``'word'``,
    ``'sym'``) into a tree, iteratively (shunting-yard); returns ``(formula, nesting depth)``.

    Raises
    ------
    LTLfSyntaxError
        With the index of the offending token, or ``None`` when the formula ends too early.
    """
    out, ops = [], []                  # operands (nodes, _Group), operators ('(' , unary, binary)
    want_operand = True

    def reduce_top():
        op = ops.pop()
        if op in _UNARY:
            out.append(_UNARY[op](out.pop()))
            return
        b, a = out.pop(), out.pop()
        cls = _BINARY[op][1]
        if type(a) is cls:                              # a chain a op b op c: one node
            a.formulas.append(b)
            out.append(a)
        else:
            out.append(cls([a, b]))

    for i, (kind, value) in enumerate(tokens):
        if want_operand:
            if kind == "prop" or value in _CONST:
                out.append(LTLfAtomic(value) if kind == "prop" else _CONST[value]())
                want_operand = False
            elif value in _UNARY or value == "(":
                ops.append((value, i) if value == "(" else value)
            else:
                raise LTLfSyntaxError(i, f"unexpected {value!r}")
            if not want_operand:
                while ops and ops[-1] in _UNARY:
                    reduce_top()
            continue
        if value in _BINARY:
            prec = _BINARY[value][0]
            while ops and ops[-1] in _BINARY and _BINARY[ops[-1]][0] >= prec:
                reduce_top()
            ops.append("&" if value == "&&" else "|" if value == "||" else value)
            want_operand = True
        elif value == ")":
            while ops and not isinstance(ops[-1], tuple):
                reduce_top()
            if not ops:
                raise LTLfSyntaxError(i, "unexpected ')'")
            ops.pop()
            out.append(_Group(out.pop()))
            while ops and ops[-1] in _UNARY:
                reduce_top()
        else:
            raise LTLfSyntaxError(i, f"unexpected {value!r}")
    if want_operand:
        raise LTLfSyntaxError(None, "the formula ends too early")
    while ops:
        if isinstance(ops[-1], tuple):
            raise LTLfSyntaxError(None, "a '(' is not closed")
        reduce_top()
    root = out.pop()
    return _strip(root)


def _unwrap(g, d: int):
    """The content of nested groups, and the depth counted through them."""
    while isinstance(g, _Group):
        g, d = g.f, d + 1
    return g, d


def _strip(root) -> tuple[LTLfFormula, int]:
    """Replace the groups by their content (iteratively) and count the nesting depth on the way:
    each operator node (a chain counts once) and each parenthesised group adds one."""
    root, d0 = _unwrap(root, 0)
    best, todo = 0, [(root, d0)]
    while todo:
        g, d = todo.pop()
        if isinstance(g, (_Unary, _Nary)):
            d += 1
        best = max(best, d)
        if isinstance(g, _Unary):
            g.f, dc = _unwrap(g.f, d)
            todo.append((g.f, dc))
        elif isinstance(g, _Nary):
            for j, c in enumerate(g.formulas):
                g.formulas[j], dc = _unwrap(c, d)
                todo.append((g.formulas[j], dc))
    return root, best
