"""The exported controller in C99 (libm only): :func:`c_sources` turns the flat tables of
:func:`tubejax.analyses.control.export.controller_data` into a header, a source and a Makefile. The
step is the same arithmetic, in the same order, as :mod:`~tubejax.analyses.control.export_runtime`;
numbers have 17 significant digits, which C reads back to the same double.
"""

from __future__ import annotations

import numpy as np

__all__ = ["c_sources", "HEADER", "SOURCE_CODE"]

HEADER = """\
/* tubejax_controller.h -- a tube controller (Algorithm 1 along a plan) exported by tubejax.
 * C99, no dependency beyond libm. See README.md for what it guarantees.
 */
#ifndef TUBEJAX_CONTROLLER_H
#define TUBEJAX_CONTROLLER_H

#ifdef __cplusplus
extern "C" {
#endif

#define TUBEJAX_N %(n)d              /* state dimension */
#define TUBEJAX_M %(m)d              /* input dimension */
#define TUBEJAX_TOL %(tol)s  /* membership tolerance (a distance) */
#define TUBEJAX_WEIGHTS "%(weights)s"  /* how the step's weights are computed */

/* Status codes of tubejax_controller_step. */
#define TUBEJAX_IN_TUBE 0            /* u written; the controller stays on the current transition */
#define TUBEJAX_ADVANCED 1           /* u written; the last step of a transition: the next call follows the next */
#define TUBEJAX_FINISHED 2           /* the plan is done and x lies in its final set; u not written */
#define TUBEJAX_OUTSIDE (-1)         /* x lies outside the set expected now; u not written, nothing advanced */

/* Where the controller is; tubejax_controller_init sets it to the plan's first step. */
typedef struct {
    int pos;          /* index into the plan's transitions: the prefix, then the cycle */
    int l;            /* step of the current transition's tube, 0 <= l < L */
    int finished;     /* 1 once the plan is done */
    int last;         /* the transition followed last, -1 before the first */
    long long rounds; /* cycles completed */
} tubejax_controller_state;

void tubejax_controller_init(tubejax_controller_state *state);
int tubejax_controller_step(tubejax_controller_state *state, const double x[TUBEJAX_N], double u[TUBEJAX_M]);
/* count independent controllers at once (simulation): x (count, N), u (count, M), status (count). */
void tubejax_controller_step_many(tubejax_controller_state *states, int count, const double *x, double *u,
                                  int *status);
/* After TUBEJAX_OUTSIDE: move to the first step, from the current one on, whose set holds x (the rest
 * of this transition, the later ones, then the cycle's earlier ones if it may run again); returns
 * TUBEJAX_IN_TUBE, or TUBEJAX_OUTSIDE (x outside every remaining tube; the state unchanged). */
int tubejax_controller_locate(tubejax_controller_state *state, const double x[TUBEJAX_N]);

#ifdef __cplusplus
}
#endif
#endif
"""

SOURCE_CODE = r"""
static int inside_cell(int s, const double *x)
{
    int o = SET_FACETS[s][0], k = SET_FACETS[s][1];
    for (int f = o; f < o + k; ++f) {
        double v = 0.0;
        for (int j = 0; j < TUBEJAX_N; ++j) v += FACET_H[f][j] * x[j];
        v -= FACET_h[f];
        if (!(v <= TUBEJAX_TOL)) return 0;        /* a NaN state is outside too */
    }
    return 1;
}

static int inside_tube(int z, int pi, const double *x)
{
    int o = SET_FACETS[z][0], k = SET_FACETS[z][1];
    double d[TUBEJAX_N];
    for (int j = 0; j < TUBEJAX_N; ++j) d[j] = x[j] - P[pi][j];
    for (int f = o; f < o + k; ++f) {
        double v = 0.0;
        for (int j = 0; j < TUBEJAX_N; ++j) v += FACET_H[f][j] * d[j];
        v -= EPS[pi] * FACET_h[f];
        if (!(v <= TUBEJAX_TOL)) return 0;
    }
    return 1;
}

/* Weights of y in set s: for a box set the multilinear weights of its 2^N corners (t clipped to
 * [0, 1]); else the simplex of its triangulation with the largest least barycentric coordinate (the
 * first on ties), its coordinates clipped at 0 and normalised. zero: a point tube (all coordinates 0).
 * Writes the weights and their vertex ids; returns how many. */
static int set_weights(int s, const double *y, int zero, double *w, int *ids)
{
    if (SET_BOX[s]) {
        double t[TUBEJAX_N];
        for (int i = 0; i < TUBEJAX_N; ++i) {
            double v = zero ? 0.0 : (y[i] - BOX[s][0][i]) / (BOX[s][1][i] - BOX[s][0][i]);
            t[i] = fmin(fmax(v, 0.0), 1.0);
        }
        for (int c = 0; c < TUBEJAX_CORNERS; ++c) {
            double prod = 1.0;
            for (int i = 0; i < TUBEJAX_N; ++i) prod *= ((c >> i) & 1) ? t[i] : 1.0 - t[i];
            w[c] = prod;
            ids[c] = BOX_VERTEX[s][c];
        }
        return TUBEJAX_CORNERS;
    }
    int o = SET_SIMPLICES[s][0], k = SET_SIMPLICES[s][1], best = o;
    double best_score = -HUGE_VAL, beta[TUBEJAX_N + 1];
    for (int q = o; q < o + k; ++q) {
        double c[TUBEJAX_N + 1], sum = 0.0, lo;
        for (int i = 0; i < TUBEJAX_N; ++i) {
            double v = 0.0;
            if (!zero)
                for (int j = 0; j < TUBEJAX_N; ++j) v += SIMP_T[q][i][j] * (y[j] - SIMP_r[q][j]);
            c[i] = v;
            sum += v;
        }
        c[TUBEJAX_N] = 1.0 - sum;
        lo = c[0];
        for (int i = 1; i <= TUBEJAX_N; ++i) lo = fmin(lo, c[i]);
        if (lo > best_score || q == o) {
            best_score = lo;
            best = q;
            for (int i = 0; i <= TUBEJAX_N; ++i) beta[i] = c[i];
        }
    }
    double total = 0.0;
    for (int i = 0; i <= TUBEJAX_N; ++i) total += (w[i] = fmax(beta[i], 0.0));
    for (int i = 0; i <= TUBEJAX_N; ++i) {
        w[i] /= total;
        ids[i] = SIMP_v[best][i];
    }
    return TUBEJAX_N + 1;
}

void tubejax_controller_init(tubejax_controller_state *state)
{
    state->pos = 0;
    state->l = 0;
    state->finished = N_SEQUENCE == 0;
    state->last = -1;
    state->rounds = 0;
}

static int final_inside(const tubejax_controller_state *state, const double *x)
{
    if (state->last < 0) return inside_cell(EMPTY_SET, x);
    const int *t = TRANSITIONS[state->last];
    return inside_tube(t[1], t[3] + t[2] - 1, x);
}

int tubejax_controller_step(tubejax_controller_state *state, const double x[TUBEJAX_N], double u[TUBEJAX_M])
{
    if (state->finished) return final_inside(state, x) ? TUBEJAX_FINISHED : TUBEJAX_OUTSIDE;
    if (state->pos < 0 || state->pos >= N_SEQUENCE) return TUBEJAX_OUTSIDE;
    int k = SEQUENCE[state->pos];
    const int *t = TRANSITIONS[k];
    int s0 = t[0], sz = t[1], L = t[2], l = state->l, row, count, ids[TUBEJAX_CORNERS + TUBEJAX_N + 1];
    double w[TUBEJAX_CORNERS + TUBEJAX_N + 1];
    if (l < 0 || l >= L) return TUBEJAX_OUTSIDE;
    if (l == 0) {
        if (!inside_cell(s0, x)) return TUBEJAX_OUTSIDE;
        count = set_weights(s0, x, 0, w, ids);
        row = t[4];
    } else {
        int pi = t[3] + l - 1;
        double y[TUBEJAX_N], inv = INV_EPS[pi];
        if (!inside_tube(sz, pi, x)) return TUBEJAX_OUTSIDE;
        for (int j = 0; j < TUBEJAX_N; ++j) y[j] = (x[j] - P[pi][j]) * inv;
        count = set_weights(sz, y, inv == 0.0, w, ids);
        row = t[4] + SET_NV[s0] + (l - 1) * SET_NV[sz];
    }
    for (int j = 0; j < TUBEJAX_M; ++j) {
        double v = 0.0;
        for (int i = 0; i < count; ++i) v += w[i] * U[row + ids[i]][j];
        u[j] = v;
    }
    state->last = k;
    if (++state->l < L) return TUBEJAX_IN_TUBE;
    state->l = 0;
    if (++state->pos == N_SEQUENCE) {
        if (N_SEQUENCE > N_PREFIX && (REPEATS < 0 || state->rounds + 1 < REPEATS)) {
            state->pos = N_PREFIX;
            state->rounds += 1;
        } else {
            state->finished = 1;
        }
    }
    return TUBEJAX_ADVANCED;
}

static int inside_step(int k, int l, const double *x)
{
    const int *t = TRANSITIONS[k];
    return l == 0 ? inside_cell(t[0], x) : inside_tube(t[1], t[3] + l - 1, x);
}

int tubejax_controller_locate(tubejax_controller_state *state, const double x[TUBEJAX_N])
{
    if (state->finished) return final_inside(state, x) ? TUBEJAX_FINISHED : TUBEJAX_OUTSIDE;
    if (state->pos < 0 || state->pos >= N_SEQUENCE) return TUBEJAX_OUTSIDE;
    int wrap = N_SEQUENCE > N_PREFIX && (REPEATS < 0 || state->rounds + 1 < REPEATS);
    for (int again = 0; again <= wrap; ++again) {
        int from = again ? N_PREFIX : state->pos, to = again ? state->pos + 1 : N_SEQUENCE;
        for (int pos = from; pos < to; ++pos) {
            int k = SEQUENCE[pos], L = TRANSITIONS[k][2];
            int first = (pos == state->pos && !again) ? state->l : 0;
            int last = (pos == state->pos && again) ? state->l : L;
            for (int l = first; l < last; ++l) {
                if (inside_step(k, l, x)) {
                    state->pos = pos;
                    state->l = l;
                    state->rounds += again;
                    return TUBEJAX_IN_TUBE;
                }
            }
        }
    }
    return TUBEJAX_OUTSIDE;
}

void tubejax_controller_step_many(tubejax_controller_state *states, int count, const double *x, double *u,
                                  int *status)
{
    for (int i = 0; i < count; ++i)
        status[i] = tubejax_controller_step(states + i, x + (long)i * TUBEJAX_N, u + (long)i * TUBEJAX_M);
}
"""

MAKEFILE = """\
# Builds the exported tube controller: a static library, a shared library (for ctypes, FFI) and an object.
CC ?= cc
CFLAGS ?= -std=c99 -O2 -Wall -Wextra -pedantic
LDLIBS = -lm

all: libtubejax_controller.a libtubejax_controller.so

tubejax_controller.o: tubejax_controller.c tubejax_controller.h
\t$(CC) $(CFLAGS) -fPIC -c tubejax_controller.c -o $@

libtubejax_controller.a: tubejax_controller.o
\t$(AR) rcs $@ $^

libtubejax_controller.so: tubejax_controller.o
\t$(CC) -shared -o $@ $^ $(LDLIBS)

clean:
\trm -f tubejax_controller.o libtubejax_controller.a libtubejax_controller.so

.PHONY: all clean
"""


def _num(v) -> str:
    s = repr(float(v))
    return s if any(c in s for c in ".en") else s + ".0"


def _array(ctype: str, name: str, a: np.ndarray, fmt) -> str:
    """``static const ctype name[d0][d1]... = {...};`` (a zero-length table gets one zero entry)."""
    a = np.asarray(a)
    if a.shape[0] == 0:
        a = np.zeros((1,) + a.shape[1:], a.dtype)
    dims = "".join(f"[{d}]" for d in a.shape)

    def body(x):
        if x.ndim == 1:
            return "{" + ", ".join(fmt(v) for v in x) + "}"
        return "{" + ",\n ".join(body(y) for y in x) + "}"

    return f"static const {ctype} {name}{dims} = {body(a)};\n"


def c_sources(data: dict, weights: str = "triangulation") -> dict:
    """``{file name: text}``: the header, the source (data as static arrays, then the step) and a Makefile."""
    n, m = (int(v) for v in data["dims"])
    n_prefix, repeats, empty = (int(v) for v in data["plan"])
    for k, v in data.items():
        if v.dtype.kind == "f" and not np.all(np.isfinite(v)):
            raise ValueError(f"controller data {k!r} holds a value that is not finite; it cannot be written as C")
    header = HEADER % {"n": n, "m": m, "tol": _num(data["tol"][0]), "weights": weights}
    f, i = _num, lambda v: str(int(v))
    parts = ["/* tubejax_controller.c -- generated by tubejax; the plan's tubes as static arrays. */\n",
             "#include <math.h>\n#include \"tubejax_controller.h\"\n\n",
             "#define TUBEJAX_CORNERS (1 << TUBEJAX_N)\n",
             f"#define N_SEQUENCE {len(data['sequence'])}\n#define N_PREFIX {n_prefix}\n",
             f"#define REPEATS {repeats}\n#define EMPTY_SET {max(empty, 0)}\n\n",
             _array("double", "FACET_H", data["facet_H"], f), _array("double", "FACET_h", data["facet_h"], f),
             _array("double", "SIMP_T", data["simp_T"], f), _array("double", "SIMP_r", data["simp_r"], f),
             _array("int", "SIMP_v", data["simp_v"], i), _array("int", "SET_FACETS", data["set_facets"], i),
             _array("int", "SET_SIMPLICES", data["set_simplices"], i), _array("int", "SET_NV", data["set_nv"], i),
             _array("int", "SET_BOX", data["set_box"], i), _array("double", "BOX", data["box"], f),
             _array("int", "BOX_VERTEX", data["box_vertex"], i),
             _array("int", "TRANSITIONS", data["transitions"], i), _array("double", "P", data["p"], f),
             _array("double", "EPS", data["eps"], f), _array("double", "INV_EPS", data["inv_eps"], f),
             _array("double", "U", data["u"], f), _array("int", "SEQUENCE", data["sequence"], i),
             SOURCE_CODE]
    return {"tubejax_controller.h": header, "tubejax_controller.c": "".join(parts), "Makefile": MAKEFILE}
