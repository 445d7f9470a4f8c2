"""Exact rational arrays and the rules that turn float data into rationals.

Rationalisation (how each float becomes a rational number)
----------------------------------------------------------
* :func:`binary_rational` -- the float's exact value (``Fraction(x)``, no rounding). Used for
  everything *computed* in floats and stored: tube values, cell, obstacle and ``Z`` vertices.
* :func:`decimal_rational` -- the shortest decimal that rounds to the float (``Fraction(repr(x))``:
  ``0.2`` means ``1/5``). Used for the data a user types: ``A``, ``B``, ``U``'s and ``W``'s
  vertices, the ball radius, ``eps_min``; it is the decimal ``transitions.json`` writes, so the
  rational problem is exactly the one that file states.

Arithmetic
----------
:class:`QArray` is an array of rationals held as one integer array (numpy object dtype, Python
ints) over one positive integer denominator, so sums and products are vectorised integer
arithmetic with no gcd after every operation.
"""

from __future__ import annotations

import math
from fractions import Fraction
from functools import lru_cache

import numpy as np

__all__ = ["QArray", "binary_rational", "decimal_rational", "sqrt_upper", "sqrt_lower", "snap_rational",
           "row_max", "int_products", "int_matrix", "SQRT_BITS"]

#: Relative precision of the outward-rounded square roots (:func:`sqrt_upper`), in bits.
SQRT_BITS = 64


def binary_rational(x) -> Fraction:
    """The exact value of the float ``x`` (raises ``ValueError`` for nan / inf)."""
    return Fraction(_finite(x))


def decimal_rational(x) -> Fraction:
    """The shortest decimal that rounds to the float ``x``, as a rational (``0.2 -> 1/5``)."""
    return Fraction(repr(_finite(x)))


def _finite(x) -> float:
    x = float(x)
    if not math.isfinite(x):
        raise ValueError(f"cannot make a rational of the non-finite value {x!r}")
    return x


@lru_cache(maxsize=65536)
def snap_rational(x: float, max_den: int = 1 << 32) -> Fraction:
    """The simplest rational (denominator ``<= max_den``) that rounds to the float ``x``,
    else its exact value. For candidate values only (bounds of a basis), never for data."""
    f = binary_rational(x)
    if f.denominator <= 1 << 10:
        return f
    s = f.limit_denominator(max_den)
    return s if float(s) == float(x) else f


def sqrt_upper(q: Fraction, bits: int = SQRT_BITS) -> Fraction:
    """A rational upper bound of ``sqrt(q)`` for ``q >= 0``, exact when ``q`` is a square.

    ``sqrt(a/b) = sqrt(a b) / b``; with ``M = a b 4^bits``, ``ceil(sqrt(M)) / (b 2^bits)``
    is an upper bound whose relative excess is below ``2^-bits`` (``math.isqrt``).
    """
    return _sqrt_bound(q, bits, True)


def sqrt_lower(q: Fraction, bits: int = SQRT_BITS) -> Fraction:
    """A rational lower bound of ``sqrt(q)`` for ``q >= 0``, exact when ``q`` is a square: the
    counterpart of :func:`sqrt_upper` (``floor(sqrt(M)) / (b 2^bits)``), for relaxations."""
    return _sqrt_bound(q, bits, False)


def _sqrt_bound(q: Fraction, bits: int, upper: bool) -> Fraction:
    q = Fraction(q)
    if q < 0:
        raise ValueError(f"sqrt of a negative number {q}")
    a, b = q.numerator, q.denominator
    ra, rb = math.isqrt(a), math.isqrt(b)
    if ra * ra == a and rb * rb == b:
        return Fraction(ra, rb)
    M = a * b << (2 * bits)
    r = math.isqrt(M)
    if upper and r * r < M:
        r += 1
    return Fraction(r, b << bits)


#: From this many entries on the left, ``QArray @ matrix`` skips the matrix's zeros (:func:`_sparse_matmul`).
SPARSE_MATMUL_FROM = 256


def _sparse_matmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a @ b`` for object integer arrays ``a (..., k)`` and ``b (k, f)``, column by column over ``b``'s
    nonzeros only (facet normals and dynamics matrices are mostly zeros); the same integers."""
    out = np.zeros(a.shape[:-1] + (b.shape[1],), dtype=object)
    for f in range(b.shape[1]):
        cs = np.flatnonzero(b[:, f])
        if cs.size:
            out[..., f] = a[..., cs] @ b[cs, f]
    return out


class QArray:
    """An array of rationals ``num / den``.

    Attributes
    ----------
    num : ndarray of object (Python ints), any shape
    den : int, > 0
        One denominator for the whole array.
    """

    __slots__ = ("num", "den")

    def __init__(self, num, den: int = 1):
        den = int(den)
        if den <= 0:
            raise ValueError(f"QArray denominator must be > 0, got {den}")
        self.num = np.asarray(num, dtype=object)
        self.den = den

    @classmethod
    def from_floats(cls, x) -> "QArray":
        """The exact values of a float array (:func:`binary_rational` elementwise)."""
        x = np.asarray(x, dtype=float)
        if not np.all(np.isfinite(x)):
            raise ValueError("cannot make rationals of non-finite values")
        if x.size == 0:
            return cls(np.zeros(x.shape, dtype=object), 1)
        # x = mant * 2^ex with an odd integer mant (53 bits at most, its trailing zeros moved into
        # ex); the denominator 2^-min(ex) is then the least one: some numerator is odd
        mant, ex = np.frexp(x)
        mant = (mant * 2.0 ** 53).astype(np.int64)
        low = (mant & -mant).astype(float)               # lowest set bit, 2^tz exactly (0 for x = 0)
        tz = np.frexp(low)[1].astype(np.int64) - 1
        nz = mant != 0
        mant = np.where(nz, mant >> np.where(nz, tz, 0), 0)
        ex = ex.astype(np.int64) - 53 + tz
        if not nz.any():
            return cls(np.zeros(x.shape, dtype=object), 1)
        e0 = min(int(ex[nz].min()), 0)
        shift = np.where(nz, ex - e0, 0)                 # >= 0
        num = mant.astype(object) << shift.astype(object)       # Python ints, elementwise
        return cls(num, 1 << -e0)

    @classmethod
    def from_decimals(cls, x) -> "QArray":
        """:func:`decimal_rational` elementwise."""
        x = np.asarray(x, dtype=float)
        return cls.from_fractions(np.vectorize(decimal_rational, otypes=[object])(x)
                                  if x.size else np.zeros(x.shape, dtype=object))

    @classmethod
    def from_fractions(cls, x) -> "QArray":
        """From an array of Fractions / ints (any shape)."""
        fr = np.asarray(x, dtype=object)
        flat = [Fraction(v) for v in fr.ravel().tolist()]
        den = math.lcm(*(f.denominator for f in flat))
        num = np.array([f.numerator * (den // f.denominator) for f in flat] or [], dtype=object)
        return cls(num.reshape(fr.shape), den)

    @classmethod
    def coerce(cls, x) -> "QArray":
        """A QArray as is; floats exactly (:meth:`from_floats`); Fractions / ints otherwise."""
        if isinstance(x, QArray):
            return x
        a = np.asarray(x)
        if a.dtype.kind == "f":
            return cls.from_floats(a)
        if a.dtype.kind in "iub":
            return cls(a.astype(object), 1)
        return cls.from_fractions(a)

    def reduced(self) -> "QArray":
        """Divide numerator and denominator by their common gcd."""
        if self.den == 1 or self.num.size == 0:
            return self
        g = self.den
        for v in self.num.ravel().tolist():
            g = math.gcd(g, v)
            if g == 1:
                return self
        return QArray(self.num // g, self.den // g)

    def _common(self, other):
        if not isinstance(other, QArray):
            other = QArray.coerce(other)
        if self.den == other.den:
            return self.num, other.num, self.den
        d = math.lcm(self.den, other.den)
        return self.num * (d // self.den), other.num * (d // other.den), d

    def __add__(self, other) -> "QArray":
        a, b, d = self._common(other)
        return QArray(a + b, d)

    def __sub__(self, other) -> "QArray":
        a, b, d = self._common(other)
        return QArray(a - b, d)

    def __neg__(self) -> "QArray":
        return QArray(-self.num, self.den)

    def __mul__(self, other) -> "QArray":
        if isinstance(other, (int, Fraction)):
            f = Fraction(other)
            return QArray(self.num * f.numerator, self.den * f.denominator)
        o = QArray.coerce(other)
        return QArray(self.num * o.num, self.den * o.den)

    __rmul__ = __mul__

    def __matmul__(self, other) -> "QArray":
        o = QArray.coerce(other)
        if o.num.ndim == 2 and self.num.ndim >= 2 and self.num.size >= SPARSE_MATMUL_FROM:
            return QArray(_sparse_matmul(self.num, o.num), self.den * o.den)
        return QArray(self.num @ o.num, self.den * o.den)

    def __getitem__(self, key) -> "QArray":
        return QArray(self.num[key], self.den)

    @property
    def T(self) -> "QArray":
        return QArray(self.num.T, self.den)

    @property
    def shape(self) -> tuple:
        return self.num.shape

    def reshape(self, *shape) -> "QArray":
        return QArray(self.num.reshape(*shape), self.den)

    @staticmethod
    def concatenate(arrays, axis: int = 0) -> "QArray":
        d = math.lcm(*(a.den for a in arrays))
        return QArray(np.concatenate([a.num * (d // a.den) for a in arrays], axis=axis), d)

    def to_fractions(self) -> np.ndarray:
        """Elementwise :class:`Fraction` values, object array of the same shape."""
        out = np.empty(self.num.shape, dtype=object)
        flat = out.reshape(-1)
        for k, v in enumerate(self.num.ravel().tolist()):
            flat[k] = Fraction(v, self.den)
        return out

    def to_float(self) -> np.ndarray:
        """Nearest float64 of each entry (correctly rounded integer division)."""
        d = self.den
        return np.array([v / d for v in self.num.ravel().tolist()], dtype=float).reshape(self.num.shape)

    def to_strings(self) -> np.ndarray:
        """``"num/den"`` (reduced) per entry: a lossless text form for files."""
        return np.array([str(f) if f.denominator != 1 else f"{f.numerator}/1"
                         for f in self.to_fractions().ravel().tolist()],
                        dtype=str).reshape(self.num.shape)

    @classmethod
    def from_strings(cls, s) -> "QArray":
        """Inverse of :meth:`to_strings` (each entry ``"num/den"``; raises ``ValueError``)."""
        s = np.asarray(s)
        if s.dtype.kind not in "US":
            raise ValueError(f"expected an array of 'num/den' strings, got dtype {s.dtype}")
        try:
            vals = [Fraction(str(v)) for v in s.ravel().tolist()]
        except (ValueError, ZeroDivisionError) as exc:
            raise ValueError(f"expected 'num/den' strings: {exc}") from None
        return cls.from_fractions(np.array(vals or [], dtype=object).reshape(s.shape))

    def __repr__(self) -> str:
        return f"QArray(shape={self.shape}, den={self.den})"


def row_max(values: QArray, scale: np.ndarray) -> Fraction:
    """``max_r values[..., r] / scale[r]`` exactly (``scale`` > 0, object ints, shape ``(R,)``).

    Over the common denominator ``lcm(scale) * den``: the largest of the integers
    ``values.num[..., r] * (lcm(scale) / scale[r])``.
    """
    num = values.num
    if num.size == 0:
        return Fraction(-10 ** 30)
    sc = np.asarray(scale, dtype=object)
    common = math.lcm(*{int(v) for v in sc.ravel().tolist()})
    top = np.max(num * (common // sc)) if common > 1 else np.max(num)
    return Fraction(int(top), common * values.den)


#: int64 arithmetic is used only below this bound, with room for one more addition (the sign bit aside).
_INT64_SAFE = 1 << 62


def _fits_int64(*factors: int, terms: int = 1) -> bool:
    """Whether a sum of ``terms`` products of integers bounded by ``factors`` (absolute values) is safe in
    int64: every factor below ``2^62`` and their product times ``terms`` too, so that no entry, product
    or partial sum can reach ``2^62`` (the one rule of :func:`int_products` and :func:`int_matrix`)."""
    bound = terms
    for f in factors:
        if not f < _INT64_SAFE:
            return False
        bound *= f
    return bound < _INT64_SAFE


def _max_abs(A: np.ndarray) -> int:
    """The largest absolute entry of a non-empty integer array (Python int)."""
    return int(np.max(np.abs(A)))


def int_products(A, B) -> np.ndarray:
    """``A @ B.T`` for integer matrices ``A (r, n)``, ``B (s, n)`` (lists or arrays of Python ints, or ``A``
    as :func:`int_matrix` gives it), exactly: in int64 when no partial sum can reach ``2^62``
    (:func:`_fits_int64`), else in Python ints (object array), shape ``(r, s)``."""
    A = A if isinstance(A, np.ndarray) and A.dtype == np.int64 else np.asarray(A, dtype=object)
    B = np.asarray(B, dtype=object)
    if A.size == 0 or B.size == 0:
        return np.zeros((A.shape[0], B.shape[0]), dtype=object)
    if _fits_int64(_max_abs(A), _max_abs(B), terms=A.shape[1]):
        return A.astype(np.int64, copy=False) @ B.astype(np.int64).T
    return A.astype(object) @ B.T


def int_matrix(A) -> np.ndarray:
    """The integer matrix ``A`` (lists of Python ints) as int64 when its entries are below ``2^62`` in
    absolute value (:func:`_fits_int64` of the entries alone), else as an object array: for repeated
    :func:`int_products`, which checks the products' sums again."""
    A = np.asarray(A, dtype=object)
    return A.astype(np.int64) if A.size and _fits_int64(_max_abs(A)) else A
