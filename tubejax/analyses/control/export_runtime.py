"""The exported controller's NumPy-only runtime (copied verbatim into an export as ``tubejax_controller.py``).

It runs Algorithm 1 along a plan (a prefix, then an optional repeating cycle) with the data
:func:`tubejax.analyses.control.export.export_controller` writes beside it, with the same arithmetic as
the exported C, so both give the same inputs::

    import numpy as np, tubejax_controller as tc
    state = tc.init()                        # the plan's first step
    u = np.zeros(tc.M)
    status = tc.step(state, x, u)            # x: the measured state, shape (N,)
    if status < 0: ...                       # OUTSIDE: no input was written; stop safely

A step checks the state against the step's set (unit facet rows, up to the exported ``tol``; else
:data:`OUTSIDE`, nothing written, no advance), weights the set's points (barycentric in the
triangulation's simplex with the largest least coordinate, first on ties; or multilinear on a box
set) and writes ``u = sum_k lambda_k u_k(l)``. Status codes and ``locate`` after :data:`OUTSIDE`:
docs/howto/export.md#calling-it. Nothing here imports anything but NumPy and the standard library.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

__all__ = ["Controller", "State", "init", "step", "locate", "IN_TUBE", "ADVANCED", "FINISHED", "OUTSIDE",
           "STATUS_NAMES"]

#: A step inside the current transition: ``u`` written.
IN_TUBE = 0
#: The last step of a transition: ``u`` written, the next call follows the next transition.
ADVANCED = 1
#: The plan is done (the state lies in its final set): nothing written.
FINISHED = 2
#: The state lies outside the set the controller expects: nothing written, nothing advanced.
OUTSIDE = -1
STATUS_NAMES = {IN_TUBE: "in_tube", ADVANCED: "advanced", FINISHED: "finished", OUTSIDE: "outside"}

_HERE = Path(__file__).resolve().parent
_STEM = "tubejax_controller"


class State:
    """Where the controller is: ``pos`` (index into the plan's transition sequence, prefix then
    cycle), ``l`` (step of that transition's tube), ``rounds`` (cycles completed), ``finished``,
    ``last`` (the transition followed last, ``-1`` before the first)."""

    __slots__ = ("pos", "l", "rounds", "finished", "last")

    def __init__(self):
        self.pos, self.l, self.rounds, self.finished, self.last = 0, 0, 0, 0, -1

    def __repr__(self) -> str:
        return (f"State(pos={self.pos}, l={self.l}, rounds={self.rounds}, finished={self.finished}, "
                f"last={self.last})")


class Controller:
    """The exported data (``<stem>.npz``) and the step function.

    Parameters
    ----------
    directory : str or Path, optional
        Where ``<stem>.npz`` lies (default: beside this file).
    stem : str
    """

    def __init__(self, directory=None, stem: str = _STEM):
        d = Path(directory) if directory is not None else _HERE
        with np.load(d / f"{stem}.npz") as z:
            a = {k: z[k] for k in z.files}
        self.N, self.M = int(a["dims"][0]), int(a["dims"][1])
        self.tol = float(a["tol"][0])
        self.facet_H, self.facet_h = a["facet_H"], a["facet_h"]
        self.simp_T, self.simp_r, self.simp_v = a["simp_T"], a["simp_r"], a["simp_v"]
        self.set_facets, self.set_simplices = a["set_facets"], a["set_simplices"]
        self.set_nv = a["set_nv"]
        self.set_box, self.box, self.box_vertex = a["set_box"], a["box"], a["box_vertex"]
        self.bits = (np.arange(2 ** self.N)[:, None] >> np.arange(self.N)[None] & 1).astype(bool)   # (2^n, n)
        self.tr = a["transitions"]           # (E, 5): start set, Z set, L, p offset, u offset
        self.p, self.eps, self.inv_eps, self.u = a["p"], a["eps"], a["inv_eps"], a["u"]
        self.sequence = a["sequence"]        # prefix then cycle: transition indices
        self.n_prefix, self.repeats, self.empty_set = (int(v) for v in a["plan"])

    # --------------------------------------------------------------- one step
    def _inside_cell(self, s: int, x) -> bool:
        o, k = self.set_facets[s]
        with np.errstate(invalid="ignore", over="ignore"):        # a NaN or infinite state is outside
            v = self.facet_H[o:o + k] @ x - self.facet_h[o:o + k]
        return bool(np.all(v <= self.tol))

    def _inside_tube(self, z: int, pi: int, x) -> bool:
        o, k = self.set_facets[z]
        with np.errstate(invalid="ignore", over="ignore"):
            v = self.facet_H[o:o + k] @ (x - self.p[pi]) - self.eps[pi] * self.facet_h[o:o + k]
        return bool(np.all(v <= self.tol))

    def _weights(self, s: int, y, zero: bool):
        """``(vertex ids, weights)`` of ``y`` in set ``s``: its triangulation's simplex (``n + 1`` each)
        or, for a box set, its ``2^n`` corners (multilinear)."""
        if self.set_box[s]:
            lo, hi = self.box[s]
            t = np.zeros(self.N) if zero else np.clip((y - lo) / (hi - lo), 0.0, 1.0)
            w = np.prod(np.where(self.bits, t, 1.0 - t), axis=1)
            return self.box_vertex[s], w
        o, k = self.set_simplices[s]
        T, r = self.simp_T[o:o + k], self.simp_r[o:o + k]
        c = np.zeros((k, self.N)) if zero else np.einsum("sij,sj->si", T, y - r)
        beta = np.concatenate([c, 1.0 - c.sum(1, keepdims=True)], axis=1)
        best = int(np.argmax(beta.min(1)))
        b = np.maximum(beta[best], 0.0)
        return self.simp_v[o + best], b / b.sum()

    def step(self, state: State, x, u) -> int:
        """One control step (module docstring); writes ``u`` (shape ``(M,)``) in place unless the
        status is :data:`FINISHED` or :data:`OUTSIDE`."""
        x = np.asarray(x, dtype=np.float64).reshape(self.N)
        if state.finished:
            return FINISHED if self._final_inside(state, x) else OUTSIDE
        k = int(self.sequence[state.pos])
        s0, sz, L, po, uo = (int(v) for v in self.tr[k])
        l = state.l
        if l == 0:
            if not self._inside_cell(s0, x):
                return OUTSIDE
            ids, w = self._weights(s0, x, False)
            rows = self.u[uo:uo + int(self.set_nv[s0])]
        else:
            pi = po + l - 1
            if not self._inside_tube(sz, pi, x):
                return OUTSIDE
            inv = self.inv_eps[pi]
            ids, w = self._weights(sz, (x - self.p[pi]) * inv, inv == 0.0)
            nz = int(self.set_nv[sz])
            o = uo + int(self.set_nv[s0]) + (l - 1) * nz
            rows = self.u[o:o + nz]
        u[...] = w @ rows[ids]
        return self._advance(state, k, L)

    def _advance(self, state: State, k: int, L: int) -> int:
        state.last = k
        state.l += 1
        if state.l < L:
            return IN_TUBE
        state.l = 0
        state.pos += 1
        if state.pos == len(self.sequence):
            n_cycle = len(self.sequence) - self.n_prefix
            if n_cycle > 0 and (self.repeats < 0 or state.rounds + 1 < self.repeats):
                state.pos = self.n_prefix
                state.rounds += 1
            else:
                state.finished = 1
        return ADVANCED

    def _inside_step(self, k: int, l: int, x) -> bool:
        """Whether ``x`` lies in the set of step ``l`` of transition ``k``."""
        s0, sz, _, po, _ = (int(v) for v in self.tr[k])
        return self._inside_cell(s0, x) if l == 0 else self._inside_tube(sz, po + l - 1, x)

    def locate(self, state: State, x) -> int:
        """Move the controller to the first step, from where it is on, whose set holds ``x``.

        Searched in order: the rest of the current transition, the later transitions, then (when the
        cycle may run again) the cycle's transitions before the current one. Found: the state moves
        there (a wrap counts a round) and :data:`IN_TUBE` is returned; Algorithm 1 is guaranteed from
        that step on. Not found -- ``x`` is outside every remaining tube -- :data:`OUTSIDE`, the state
        unchanged. A finished plan answers as :meth:`step` does.
        """
        x = np.asarray(x, dtype=np.float64).reshape(self.N)
        if state.finished:
            return FINISHED if self._final_inside(state, x) else OUTSIDE
        n = len(self.sequence)
        wrap = n > self.n_prefix and (self.repeats < 0 or state.rounds + 1 < self.repeats)
        order = [(pos, 0) for pos in range(state.pos, n)]
        if wrap:
            order += [(pos, 1) for pos in range(self.n_prefix, state.pos + 1)]
        for pos, again in order:
            k = int(self.sequence[pos])
            L = int(self.tr[k][2])
            first = state.l if (pos == state.pos and not again) else 0
            last = state.l if (pos == state.pos and again) else L
            for l in range(first, last):
                if self._inside_step(k, l, x):
                    state.pos, state.l, state.rounds = pos, l, state.rounds + again
                    return IN_TUBE
        return OUTSIDE

    def _final_inside(self, state: State, x) -> bool:
        if state.last < 0:                          # a plan without transitions: its start cell
            return self._inside_cell(self.empty_set, x)
        _, sz, L, po, _ = (int(v) for v in self.tr[state.last])
        return self._inside_tube(sz, po + L - 1, x)

    def init(self) -> State:
        """A state at the plan's first step (:func:`tubejax_controller_init` in C)."""
        st = State()
        st.finished = int(len(self.sequence) == 0)
        return st


_DEFAULT: list = []


def _default() -> Controller:
    if not _DEFAULT:
        _DEFAULT.append(Controller())
    return _DEFAULT[0]


def init() -> State:
    """A state at the plan's first step, for the data beside this file."""
    return _default().init()


def step(state: State, x, u) -> int:
    """:meth:`Controller.step` with the data beside this file."""
    return _default().step(state, x, u)


def locate(state: State, x) -> int:
    """:meth:`Controller.locate` with the data beside this file."""
    return _default().locate(state, x)


def description(directory=None, stem: str = _STEM) -> dict:
    """The JSON description of the exported data (``<stem>.json``)."""
    d = Path(directory) if directory is not None else _HERE
    return json.loads((d / f"{stem}.json").read_text())


def __getattr__(name: str):
    if name in ("N", "M"):                      # tc.N, tc.M: the state and input dimensions
        return getattr(_default(), name)
    raise AttributeError(name)
