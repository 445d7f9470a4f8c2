"""Typed values of the input model: strict numbers, flags, choices, vectors and matrices.

Each type is an ``Annotated`` pydantic type whose validator refuses anything but the
documented kind and range and says what it expected; :func:`input_error` turns a
pydantic ``ValidationError`` into one :class:`~tubejax.errors.InputModelError` whose
lines read ``field: expected ..., got ...``.

Rules shared by every field: numbers are ``int`` or ``float`` (never ``bool``, never a
string such as ``'0.1'``), finite (no NaN, no infinity) and within the field's range;
integers are ``int`` (``2.5`` and ``True`` are refused); flags are ``bool``; choices are
one of the listed strings; matrices are lists of equally long rows of numbers.
"""

from __future__ import annotations

import difflib
import math
import numbers
import typing
from typing import Annotated, Callable, Literal

import pydantic
from pydantic import BaseModel, BeforeValidator, ConfigDict
from pydantic_core import PydanticCustomError

from ..errors import InputModelError, short

__all__ = ["MAX_MAGNITUDE", "StrictModel", "problem", "real", "integer", "integer_or", "Flag", "choice", "vector",
           "matrix", "label", "sized_list", "short", "input_error", "register_tags"]

#: Largest magnitude of any number in a matrix, vector or set description.
MAX_MAGNITUDE = 1e6


class StrictModel(BaseModel):
    """Base of every input model: strict types, unknown fields refused, immutable."""

    model_config = ConfigDict(strict=True, extra="forbid", frozen=True)


def problem(field: str, message: str) -> PydanticCustomError:
    """An error about ``field`` (a dotted path below the model raising it), ``message`` verbatim."""
    return PydanticCustomError("tubejax_field", "{message}", {"message": message, "field": field})


def _fail(expected: str):
    return PydanticCustomError("tubejax_value", "{expected}", {"expected": expected})


def _number(value, expected: str) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise _fail(expected)
    try:
        x = float(value)
    except OverflowError:
        raise _fail(expected) from None
    if not math.isfinite(x):
        raise _fail(expected)
    return x


def _num(v) -> str:
    """``1000`` as 1000, ``1e6`` as 1e6, ``0.001`` as 0.001."""
    if isinstance(v, int):
        return str(v)
    return f"{v:g}".replace("e+0", "e").replace("e+", "e").replace("e-0", "e-")


def _range_text(lo, hi, lo_open: bool, hi_open: bool) -> str:
    if lo is not None and hi is not None:
        return f"in {'(' if lo_open else '['}{_num(lo)}, {_num(hi)}{')' if hi_open else ']'}"
    if lo is not None:
        return f"{'>' if lo_open else '>='} {_num(lo)}"
    if hi is not None:
        return f"{'<' if hi_open else '<='} {_num(hi)}"
    return ""


def _expected(kind: str, range_text: str, why: str) -> str:
    """``'<kind> <range> (<why>)'``, the parts that are given."""
    return " ".join(p for p in (kind, range_text) if p) + (f" ({why})" if why else "")


def real(lo: float | None = None, hi: float | None = None, *, lo_open: bool = False, hi_open: bool = False,
         why: str = ""):
    """A finite ``float`` in the given range; ``why`` explains the range in the error."""
    expected = _expected("a finite number", _range_text(lo, hi, lo_open, hi_open), why)

    def check(value):
        x = _number(value, expected)
        if (lo is not None and (x < lo or (lo_open and x == lo))) or \
                (hi is not None and (x > hi or (hi_open and x == hi))):
            raise _fail(expected)
        return x

    return Annotated[float, BeforeValidator(check)]


def integer(lo: int | None = None, hi: int | None = None, *, why: str = ""):
    """An ``int`` (not ``bool``, not ``2.0``) in ``[lo, hi]``."""
    expected = _expected("an integer", _range_text(lo, hi, False, False), why)

    def check(value):
        if isinstance(value, bool) or not isinstance(value, numbers.Integral):
            raise _fail(expected)
        v = int(value)
        if (lo is not None and v < lo) or (hi is not None and v > hi):
            raise _fail(expected)
        return v

    return Annotated[int, BeforeValidator(check)]


def _flag(value):
    if not isinstance(value, bool):
        raise _fail("true or false")
    return value


Flag = Annotated[bool, BeforeValidator(_flag)]


def choice(*values: str):
    """One of the strings ``values``."""
    expected = "one of " + ", ".join(values)

    def check(value):
        if not isinstance(value, str) or value not in values:
            raise _fail(expected)
        return value

    return Annotated[Literal[values], BeforeValidator(check)]  # type: ignore[valid-type]


def integer_or(lo: int, hi: int, *values: str):
    """An integer in ``[lo, hi]`` (as :func:`integer`) or one of the strings ``values``."""
    expected = f"an integer {_range_text(lo, hi, False, False)} or one of " + ", ".join(values)

    def check(value):
        if isinstance(value, str) and value in values:
            return value
        if isinstance(value, bool) or not isinstance(value, numbers.Integral) or not lo <= int(value) <= hi:
            raise _fail(expected)
        return int(value)

    return Annotated[int | Literal[values], BeforeValidator(check)]  # type: ignore[valid-type]


def _is_sequence(value) -> bool:
    return isinstance(value, (list, tuple))


def vector(what: str = "a list of numbers", min_len: int = 1, max_abs: float = MAX_MAGNITUDE):
    """A non-empty list of finite numbers, each of magnitude ``<= max_abs``."""
    expected = f"{what} (finite, |x| <= {_num(max_abs)})"

    def check(value):
        if not _is_sequence(value) or len(value) < min_len:
            raise _fail(expected)
        out = [_number(x, expected) for x in value]
        if any(abs(x) > max_abs for x in out):
            raise _fail(expected)
        return out

    return Annotated[list[float], BeforeValidator(check)]


def matrix(what: str = "a matrix (a list of rows of numbers)", max_abs: float = MAX_MAGNITUDE):
    """A non-empty list of equally long, non-empty rows of finite numbers (``|x| <= max_abs``)."""
    expected = f"{what}, finite with |x| <= {_num(max_abs)}"

    def check(value):
        if not _is_sequence(value) or not value or not all(_is_sequence(r) and r for r in value):
            raise _fail(expected)
        if len({len(r) for r in value}) != 1:
            raise _fail(f"{what} with rows of equal length")
        out = [[_number(x, expected) for x in r] for r in value]
        if any(abs(x) > max_abs for r in out for x in r):
            raise _fail(expected)
        return out

    return Annotated[list[list[float]], BeforeValidator(check)]


def _label(value):
    if isinstance(value, bool) or not isinstance(value, (str, int)) or str(value) == "" or len(str(value)) > 64:
        raise _fail("a region label (a non-empty string or an integer, at most 64 characters)")
    return value


#: A region label as the user wrote it: a string or an integer (compared as strings).
label = Annotated[str | int, BeforeValidator(_label)]


def sized_list(lo: int, hi: int, expected: str, distinct: bool = False) -> BeforeValidator:
    """A list (or tuple) of ``lo`` to ``hi`` items, pairwise distinct (as strings) with ``distinct``."""
    def check(value):
        if not isinstance(value, (list, tuple)) or not lo <= len(value) <= hi or \
                (distinct and len(set(map(str, value))) != len(value)):
            raise _fail(expected)
        return list(value)

    return BeforeValidator(check)


# --------------------------------------------------------------------- errors
def _field(loc: tuple, prefix: str, rename: Callable[[str], str] | None) -> str:
    parts = [prefix] if prefix else []
    for p in loc:
        if isinstance(p, int):
            parts[-1:] = [f"{parts[-1]}[{p}]"] if parts else [f"[{p}]"]
        elif not parts or not str(p).startswith(("function-", "tagged-union")):
            parts.append(str(p))
    name = ".".join(parts) or "input"
    return rename(name) if rename else name


def _closest(name: str, names) -> str | None:
    """The name among ``names`` closest to ``name`` (a typo, another case), or None."""
    names = sorted(set(names))
    close = difflib.get_close_matches(name, names, n=1, cutoff=0.6)
    return close[0] if close else next((k for k in names if k.lower() == name.lower()), None)


def _models(tp) -> list:
    """The pydantic models in a type (itself, or the members of a union, optional or list)."""
    if isinstance(tp, type) and issubclass(tp, BaseModel):
        return [tp]
    return [m for a in typing.get_args(tp) for m in _models(a)]


def _tags(model) -> set:
    """The literal values of ``model``'s fields (a tagged union member's tag is one of them)."""
    return {v for f in model.model_fields.values() if typing.get_origin(f.annotation) is Literal
            for v in typing.get_args(f.annotation)}


def model_fields_at(model, loc: tuple) -> list[str]:
    """The field names of the model found at ``loc`` (a pydantic error location, union tags
    included) below ``model``; empty when ``loc`` leads to no model."""
    models = [model]
    for p in loc:
        if isinstance(p, int):                       # an item of a list: the models inside it
            continue
        tagged = [m for m in models if p not in m.model_fields and p in _tags(m)]
        if tagged:                                   # ('disturbance', 'ball', ...): the member tagged 'ball'
            models = tagged
            continue
        models = [x for m in models if p in m.model_fields for x in _models(m.model_fields[p].annotation)]
    return [f for m in models for f in m.model_fields]


def _describe(err: dict, known=lambda loc: ()) -> tuple[tuple, str]:
    """``(loc, message)`` for one pydantic error dict; ``known(loc)`` gives the field names at ``loc``
    (to suggest the one meant for an unknown field)."""
    kind, loc, ctx = err["type"], tuple(err["loc"]), err.get("ctx") or {}
    got = short(err.get("input"))
    if kind == "tubejax_value":
        return loc, f"expected {ctx['expected']}, got {got}"
    if kind == "tubejax_field":
        return loc + tuple(p for p in str(ctx.get("field", "")).split(".") if p), str(ctx["message"])
    if kind == "missing":
        return loc, "missing (this field is required)"
    if kind == "extra_forbidden":
        near = _closest(str(loc[-1]), known(loc[:-1])) if loc else None
        return loc, f"unknown field (value {got})" + (f"; did you mean {near}?" if near else "")
    if kind in ("union_tag_invalid", "union_tag_not_found"):
        tags = str(ctx.get("expected_tags", "")).replace("'", "")
        disc = str(ctx.get("discriminator", "kind")).strip("'")
        if kind == "union_tag_invalid":
            return loc + (disc,), f"expected one of {tags}, got {short(ctx.get('tag'))}"
        tags = ", ".join(_UNIONS.get(str(loc[-1]) if loc else "", ()))
        return loc + (disc,), f"missing (expected one of {tags})" if tags else "missing"
    if kind in ("model_type", "model_attributes_type", "dict_type"):
        return loc, f"expected a mapping of fields, got {got}"
    if kind == "value_error":
        return loc, str(ctx.get("error", err["msg"]))
    return loc, f"{err['msg'][0].lower()}{err['msg'][1:]}, got {got}"


def input_error(exc: pydantic.ValidationError, prefix: str = "",
                rename: Callable[[str], str] | None = None, model=None) -> InputModelError:
    """One :class:`InputModelError` listing every problem of ``exc``.

    Parameters
    ----------
    exc : pydantic.ValidationError
    prefix : str
        Prepended to every field path (e.g. ``'system'``).
    rename : callable, optional
        Maps a dotted model path to the name the user knows (e.g. a config key).
    model : type, optional
        The model validated: an unknown field's message then suggests the field meant.
    """
    problems, seen = [], set()
    for err in exc.errors(include_url=False):
        loc, msg = _describe(err, (lambda at: model_fields_at(model, at)) if model is not None else (lambda at: ()))
        # drop the tag segment pydantic adds for discriminated unions: ('disturbance', 'ball', 'radius')
        loc = tuple(p for k, p in enumerate(loc)
                    if not (k > 0 and isinstance(p, str) and p in _UNIONS.get(str(loc[k - 1]), ())))
        field = _field(loc, prefix, rename)
        if (field, msg) not in seen:
            seen.add((field, msg))
            problems.append((field, msg))
    return InputModelError(problems)


#: Field name of a tagged union -> its discriminator values.
_UNIONS: dict[str, tuple[str, ...]] = {}


def register_tags(field: str, *tags: str) -> None:
    """Declare the tagged union ``field`` and its discriminator values, so error paths read
    ``disturbance.radius`` (not ``disturbance.ball.radius``) and a missing tag lists the choices."""
    _UNIONS[field] = tags
