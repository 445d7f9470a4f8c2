"""A formula in words: what a (sub)formula asks, for the messages of :mod:`.explain`.

:func:`describe` puts a (sub)formula in words for the common shapes (``F``, ``G``,
``X``, ``U`` of region conditions) and quotes it otherwise; the private helpers name
a proposition's region and a list of regions the same way in every message.
"""

from __future__ import annotations

from .ltlf import (LTLfAlways, LTLfAnd, LTLfAtomic, LTLfEventually, LTLfFalse, LTLfLast, LTLfNext, LTLfNot,
                         LTLfOr, LTLfTrue, LTLfUntil, LTLfWeakNext)

from .formula import ParsedFormula

__all__ = ["describe"]


# ----------------------------------------------------------------------------- words

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
