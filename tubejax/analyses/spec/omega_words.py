"""Simulated runs of a lasso checked against an LTL formula by Spot, independently of the planner.

A run of a lasso plan (prefix of ``P`` steps, then ``c`` turns of a cycle of ``C`` steps) has
the float64 region word ``w(0), ..., w(P + cC)`` (:func:`~tubejax.analyses.spec.monitor.region_letters`:
the labels whose closed regions hold the state at each time step). The run stands for the
infinite run that repeats the cycle forever; turn ``k`` of it gives the ultimately periodic word

    ``w(0) ... w(P + kC) ; cycle{ w(P + kC + 1) ... w(P + (k + 1)C) }``

and the run *satisfies the formula* when, for every simulated turn ``k``, Spot finds the
intersection of that word's automaton with the automaton of the formula's negation empty.
Nothing of the planner's product or its Büchi automaton is used: the negation is
translated afresh from the formula, and equal words are checked once.
"""

from __future__ import annotations

import numpy as np
import spot

__all__ = ["lasso_words_satisfy", "word_text"]


def word_text(propositions, prefix, cycle) -> str:
    """Spot's text of the ultimately periodic word ``prefix; cycle{cycle}`` of bit-mask letters."""
    def letter(s):
        if not propositions:
            return "1"
        return " & ".join(p if s >> b & 1 else f"!{p}" for b, p in enumerate(propositions))

    head = "; ".join(letter(int(s)) for s in prefix)
    loop = "; ".join(letter(int(s)) for s in cycle)
    return (head + "; " if head else "") + f"cycle{{{loop}}}"


def lasso_words_satisfy(formula, propositions, letters, prefix_steps: int, cycle_steps: int,
                        cycles: int) -> np.ndarray:
    """``(runs,)`` bool: each run's words satisfy ``formula`` for every simulated turn (module docstring).

    Parameters
    ----------
    formula : spot.formula or str
    propositions : sequence of str
        Proposition of each letter bit.
    letters : ndarray of int, shape (runs, T + 1)
        The float64 region letters, ``T = prefix_steps + cycles * cycle_steps``.
    prefix_steps, cycle_steps, cycles : int
    """
    letters = np.asarray(letters, np.int64)
    P, C = int(prefix_steps), int(cycle_steps)
    if letters.shape[-1] != P + cycles * C + 1 or C < 1:
        raise ValueError(f"letters: expected {P + cycles * C + 1} time steps (prefix {P}, {cycles} x cycle {C}), "
                         f"got {letters.shape[-1]}")
    f = spot.formula(str(formula))
    neg = spot.translate(spot.formula.Not(f))
    d = neg.get_dict()
    seen = {}
    out = np.ones(letters.shape[0], bool)
    for r in range(letters.shape[0]):
        for k in range(cycles):
            head = letters[r, :P + k * C + 1]
            loop = letters[r, P + k * C + 1:P + (k + 1) * C + 1]
            key = (head.tobytes(), loop.tobytes())
            if key not in seen:
                w = spot.parse_word(word_text(propositions, head, loop), d)
                seen[key] = not neg.intersects(w.as_automaton())
            if not seen[key]:
                out[r] = False
                break
    return out
