"""Why a formula cannot be met, in words (docs/howto/formulas.md): its top-level conjuncts are tried
alone, then in pairs, and the first that fails is named with the reason (impossible in itself, on
this map, at the start, or not reachable).
"""

from __future__ import annotations

import networkx as nx
import numpy as np
from .ltlf import LTLfAnd, LTLfAtomic, LTLfFalse, LTLfNot, LTLfTrue, _kids

from ..control.planner import PlanningError
from .dfa import DFA, _closure
from .formula import ParsedFormula, SpecificationError, _label, _regions, describe
from .automata import dfa_from_formula
from .labelling import cell_letters, start_letters
from .product import _initial_state, _reached, build_product, plan_dfa

__all__ = ["explain_unsatisfiable", "explain_start", "explain_no_plan", "sub_dfa"]


# ----------------------------------------------------------------------------- sub-automata

def sub_dfa(parsed: ParsedFormula, parts, alphabet) -> DFA:
    """The DFA of the conjunction of ``parts`` (trees of ``parsed``) over ``alphabet`` (``None``: all letters)."""
    f = parts[0] if len(parts) == 1 else LTLfAnd(list(parts))
    text = " & ".join(parsed.render(p) for p in parts)
    return dfa_from_formula(ParsedFormula(text, parsed.propositions, parsed.labels, f), alphabet)


def _culprit(parsed: ParsedFormula, fails) -> list | None:
    """The first top-level conjunct for which ``fails([part])``, else the first such pair, else ``None``.

    A part whose own automaton is too big to build (:class:`SpecificationError`) does not count as failing.
    """
    def fails_(ps):
        try:
            return fails(ps)
        except SpecificationError:
            return False

    parts = parsed.conjuncts()
    if len(parts) == 1:
        return parts if fails_(parts) else None
    for p in parts:
        if fails_([p]):
            return [p]
    for a in range(len(parts)):
        for b in range(a + 1, len(parts)):
            if fails_([parts[a], parts[b]]):
                return [parts[a], parts[b]]
    return None


def _asks(parsed: ParsedFormula, parts) -> str:
    if len(parts) == 1:
        who = "it" if len(parsed.conjuncts()) == 1 else f"part {parsed.render(parts[0])!r}"
        return f"{who} asks {describe(parsed, parts[0])}"
    a, b = parts
    return (f"parts {parsed.render(a)!r} and {parsed.render(b)!r} contradict each other: "
            f"{parsed.render(a)!r} asks {describe(parsed, a)}, and {parsed.render(b)!r} asks "
            f"{describe(parsed, b).replace('the state ', 'it ', 1)}")


# ----------------------------------------------------------------------------- the three failures

def explain_unsatisfiable(parsed: ParsedFormula, alphabet) -> str:
    """Why no trace over the map's letters satisfies the formula (its DFA accepts nothing).

    Parameters
    ----------
    parsed : ParsedFormula
    alphabet : ndarray of bool, shape (2**k,)
        The letters the map can produce (:func:`~tubejax.analyses.spec.labelling.map_alphabet`).

    Returns
    -------
    str
        The failing part (or pair) and what it asks, and whether it is impossible in
        itself or only on this map (naming the regions that would have to meet).
    """
    ok = np.asarray(alphabet, bool)

    logic = _culprit(parsed, lambda ps: not sub_dfa(parsed, ps, None).satisfiable())
    if logic is not None:
        if len(logic) == 1 and isinstance(logic[0], LTLfFalse):
            who = "it" if len(parsed.conjuncts()) == 1 else "its part 'false'"
            return f"{who} is 'false', which never holds: no run satisfies it"
        head = _asks(parsed, logic)
        if len(logic) == 1:
            return f"{head}, which no run can do: it is unsatisfiable in itself"
        return f"{head}; no run can do both: the formula is unsatisfiable"
    parts = _culprit(parsed, lambda ps: not sub_dfa(parsed, ps, ok).satisfiable()) or parsed.conjuncts()
    try:
        full = sub_dfa(parsed, parts, None)
        missing = sorted(np.flatnonzero(~ok).tolist(), key=lambda s: (bin(s).count("1"), s))[:256]
    except SpecificationError:                      # too big over every letter: no regions named
        missing = []
    enough = []                                     # letters the map lacks that alone would make it satisfiable
    for s in missing:
        if not any(e & s == e for e in enough) and _accepts_over(full, ok | (np.arange(len(ok)) == s)):
            enough.append(s)
    combos = [_regions(parsed.labels[b] for b in range(len(parsed.labels)) if s >> b & 1) + " at once"
              for s in enough[:3]]
    head = (_asks(parsed, parts) if len(parts) == 1 else
            f"parts {' and '.join(repr(parsed.render(p)) for p in parts)} together")
    needs = f" ({'; or '.join(combos)})" if combos else ""
    return (f"{head}, which needs the state in several regions at one instant{needs}, and no point of "
            "the map lies in all of them (those regions do not meet): the formula is unsatisfiable on this map")


def _accepts_over(dfa: DFA, letters) -> bool:
    """Whether ``dfa`` accepts some trace whose letters are all in ``letters`` (``(2**k,)`` bool)."""
    start = np.arange(dfa.n_states) == dfa.initial
    return bool((_closure(dfa.delta[:, np.flatnonzero(letters)], start, backward=False) & dfa.accepting).any())


def _start_words(ts, parsed: ParsedFormula, start: int) -> str:
    must, may = cell_letters(ts.decomposition, parsed.labels, start)
    inside = [parsed.labels[b] for b in range(len(parsed.labels)) if must >> b & 1]
    touch = [parsed.labels[b] for b in range(len(parsed.labels)) if (may & ~must) >> b & 1]
    words = [f"lies in {_regions(inside)}"] if inside else []
    words += [f"meets {_regions(touch)} (a start state on its boundary, or in the part of the cell it "
              "covers, is in it)"] if touch else []
    return " and ".join(words) or f"lies outside {_regions(parsed.labels)}"


def explain_start(ts, start: int, parsed: ParsedFormula, dfa: DFA, err: PlanningError) -> str:
    """Why the start cell already fails the formula (its state after ``x(0)`` is dead or ambiguous).

    Parameters
    ----------
    ts : TransitionSystem
    start : int
        The start cell.
    parsed : ParsedFormula
    dfa : DFA
        The formula's automaton over the map's letters.
    err : PlanningError
        What :func:`~tubejax.analyses.spec.product.plan_dfa` raised (returned when no part can be blamed).

    Returns
    -------
    str
        The part violated (or possibly violated, for a start cell that touches a region)
        at the start, what it asks and where the start cell lies.
    """
    alphabet = dfa.alphabet

    def dead(ps):
        d = sub_dfa(parsed, ps, alphabet)
        return not d.live()[d.delta[d.initial, start_letters(ts.decomposition, d.labels, start)]].all()

    try:
        _initial_state(ts, dfa, start)
        ambiguous = False
    except PlanningError:
        ambiguous = True
    parts = _culprit(parsed, dead)
    if parts is None:
        return str(err)
    where = _start_words(ts, parsed, start)
    if len(parsed.conjuncts()) == 1:
        who, asks = "it", f"it asks {describe(parsed, parts[0])}"
    else:
        who = "part " + " & ".join(repr(parsed.render(p)) for p in parts)
        asks = "; ".join(f"{parsed.render(p)!r} asks {describe(parsed, p)}" for p in parts)
    if ambiguous:
        return (f"{who} may already be violated at the start cell {start}: {asks}, and the start cell "
                f"{where}; start in a cell away from that region")
    return f"{who} is already violated at the start cell {start}: {asks}, and the start cell {where}"


def _polarity(parsed: ParsedFormula, f) -> tuple[list, list]:
    """Labels occurring un-negated (wanted) and negated (forbidden) in ``f``'s negation normal form."""

    pos, neg, todo = set(), set(), [(f.to_nnf(), False)]
    while todo:
        g, negated = todo.pop()
        if isinstance(g, LTLfAtomic) and not isinstance(g, (LTLfTrue, LTLfFalse)):
            (neg if negated else pos).add(_label(parsed, g))
            continue
        todo.extend((c, isinstance(g, LTLfNot)) for c in _kids(g))
    return sorted(pos), sorted(neg)


def _timed(f) -> bool:
    return any(tok in str(f) for tok in ("X(", "WX(", "last"))


def _graph_reach(ts, start: int) -> set:
    """Labels of the cells reachable from ``start`` over the transitions, whatever the specification."""
    g = nx.DiGraph([(e.src, e.dst) for e in ts.edges])
    seen = nx.descendants(g, start) | {start} if start in g else {start}
    lab = ts.decomposition.labels
    return {str(lab[c]) for c in seen if lab[c] is not None}


def _why_alone(ts, start, parsed, part, letters, alphabet) -> str:
    """Why one part cannot be met from ``start`` although it is satisfiable (regions or time steps)."""
    asks = f"it asks {describe(parsed, part)}"
    try:
        dfa = sub_dfa(parsed, [part], alphabet)
        cells, _ = _reached(ts, dfa, start, build_product(ts, dfa, letters))
    except (PlanningError, SpecificationError):
        return asks
    lab = ts.decomposition.labels
    have = {str(lab[c]) for c in cells if lab[c] is not None}
    want, avoid = _polarity(parsed, part)
    anywhere = _graph_reach(ts, start)
    if never := [l for l in want if l not in anywhere]:
        return (f"{asks}, but {_regions(never)} cannot be reached from cell {start} at all (no chain of "
                "transitions leads there)")
    if _timed(part):
        Ls = sorted({int(e.L) for e in ts.edges if e.src == start})
        span = f"{Ls[0]} to {Ls[-1]}" if len(Ls) > 1 else f"{Ls[0]}" if Ls else ""
        steps = f"the transitions from cell {start} take {span} steps" if Ls else f"no transition leaves cell {start}"
        what = f"{_regions(want)} can be reached from cell {start}, but not" if want else "no plan fits"
        return (f"{asks}; {what} at the time step it fixes (each step of the closed loop is one instant, "
                f"{steps}, and a tube set counts only where it surely lies)")
    if missing := [l for l in want if l not in have]:
        how = ("every path there enters, or has a tube that may sweep, a region it forbids"
               if set(avoid) - set(want) else "every path there first leaves what it allows, or has a tube "
               "that may")
        return f"{asks}, but {_regions(missing)} cannot be reached from cell {start} while keeping to it ({how})"
    return (f"{asks}; the regions it names can be reached from cell {start}, but no run of tubes keeps to "
            "it all the way (a tube that only may enter a region counts as neither a visit nor a miss)")


def explain_no_plan(ts, start: int, parsed: ParsedFormula, letters, alphabet) -> str:
    """Which part of a satisfiable formula cannot be met from ``start``, and why.

    Parameters
    ----------
    ts : TransitionSystem
    start : int
    parsed : ParsedFormula
    letters : EdgeLetters
        Of every edge, for ``parsed.labels``.
    alphabet : ndarray of bool, shape (2**k,)

    Returns
    -------
    str
        The first part that cannot be met alone (regions out of reach, or not at the
        time step it fixes), else the first pair that cannot be met together (the
        regions one cannot reach while the other is kept), else all of them.
    """
    parts = parsed.conjuncts()

    def fails(ps):
        try:
            plan_dfa(ts, start, sub_dfa(parsed, ps, alphabet), letters=letters)
            return False
        except PlanningError:
            return True

    if len(parts) < 2:
        return f"{parsed.render(parts[0])!r} cannot be met from cell {start}: " + _why_alone(
            ts, start, parsed, parts[0], letters, alphabet)
    culprit = _culprit(parsed, fails) or []                 # a part too big to tell is not blamed
    if len(culprit) == 1:
        return (f"part {parsed.render(culprit[0])!r} cannot be met on its own from cell {start}: "
                + _why_alone(ts, start, parsed, culprit[0], letters, alphabet))
    if culprit:
        a, b = culprit
        reach, keep = (a, b) if _has_eventually(a) or not _has_eventually(b) else (b, a)
        why = _cause(ts, start, parsed, [keep], letters, alphabet, reach.find_labels())
        return (f"part {parsed.render(reach)!r} cannot be met together with {parsed.render(keep)!r}"
                + (f": {why}" if why else ""))
    reach = next((p for p in parts if _has_eventually(p)), parts[0])
    rest = [p for p in parts if p is not reach]
    why = _cause(ts, start, parsed, rest, letters, alphabet, reach.find_labels())
    return ("its parts can each be met, and every two of them together, but not all at once"
            + (f": {why}" if why else ""))


def _has_eventually(f) -> bool:
    return any(tok in str(f) for tok in ("F(", "U", "last"))


def _cause(ts, start, parsed, keep, letters, alphabet, want) -> str:
    """Regions of ``want`` (internal proposition names) that cannot be reached while the parts ``keep`` are kept."""
    try:
        dfa = sub_dfa(parsed, keep, alphabet)
        cells, _ = _reached(ts, dfa, start, build_product(ts, dfa, letters))
    except (PlanningError, SpecificationError):
        return ""
    lab = ts.decomposition.labels
    missing = [parsed.labels[int(p[1:])] for p in sorted(want)
               if not any(lab[c] is not None and str(lab[c]) == parsed.labels[int(p[1:])] for c in cells)]
    if not missing:
        return ""
    kept = " and ".join(repr(parsed.render(k)) for k in keep)
    return (f"with {kept} kept, region {', '.join(missing)} cannot be reached from "
            f"cell {start} (every path there enters, or has a tube that may sweep, a region it forbids)")
