"""The value checks every vr_driver module shares: what counts as a finite number, an integer, and
whether it lies in a range; which member of a small enum a word names (:func:`choice`, an enum's ``parse`` from
:func:`choice_parser`). ROS-free, no PyKDL; part of the vocabulary layer (beside poses.py).

Each caller keeps its own error type and wording: it passes ``fail``, a function that builds the
exception to raise. ``fail(None)`` is asked for when the value is not of the wanted kind (not a
finite number, not an integer); ``fail(got)`` when it is, but ``got`` (the converted value) lies
outside the range. For example::

    speed = number(value, lambda got: SimError("speed must be > 0, got %r" % (value,)), lo=0.0, lo_open=True)

Rules shared by all callers: a bool (also numpy's) and None are never numbers, even though
``float(True)`` works; NaN and the infinities are never finite numbers; a number too large for a
float is not a finite number (no OverflowError escapes).
"""
from __future__ import annotations

import enum
import math
import operator
import re
from typing import Any, Callable, Optional, Type, TypeVar

import numpy as np

__all__ = ["Fail", "is_bool", "as_finite", "as_integer", "number", "integer", "choice", "choice_parser"]

#: builds the exception for a value that is not of the wanted kind (None) or out of range (got)
Fail = Callable[[Optional[float]], Exception]

#: a decimal integer as text: optional sign, digits, surrounding white space allowed
_INTEGER_TEXT = re.compile(r"^\s*[-+]?\d+\s*$")

_N = TypeVar("_N", int, float)
_E = TypeVar("_E", bound=enum.Enum)


def is_bool(value: Any) -> bool:
    """True for Python's and numpy's booleans (which ``float()`` / ``int()`` would accept)."""
    return isinstance(value, (bool, np.bool_))


def as_finite(value: Any, text: bool = True) -> Optional[float]:
    """``value`` as a float when it is a finite real number, else None.

    ``text=True``: anything ``float()`` converts counts (numeric strings, numpy scalars);
    ``text=False``: only ``int`` and ``float`` instances (values from a parameter server or YAML)."""
    if value is None or is_bool(value):
        return None
    if not text and not isinstance(value, (int, float)):
        return None
    try:
        number = float(value)
    except (TypeError, ValueError, OverflowError):
        return None
    return number if math.isfinite(number) else None


def as_integer(value: Any, text: bool = False, integral: bool = False) -> Optional[int]:
    """``value`` as an int when it is an integer, else None. ``int`` and anything with
    ``__index__`` (numpy integers) count, bools never; ``text=True`` also takes decimal strings
    (" -12 "), ``integral=True`` also finite floats with no fraction (12.0)."""
    if is_bool(value):
        return None
    try:
        return operator.index(value)
    except TypeError:
        pass
    if text and isinstance(value, str) and _INTEGER_TEXT.match(value):
        return int(value)
    if integral:
        number = as_finite(value, text=False)
        if number is not None and number == math.floor(number):
            return int(number)
    return None


def _in_range(got: _N, fail: Fail, lo: Optional[_N], hi: Optional[_N], lo_open: bool) -> _N:
    if (lo is not None and (got < lo or (lo_open and got == lo))) or (hi is not None and got > hi):
        raise fail(got)
    return got


def number(value: Any, fail: Fail, lo: Optional[float] = None, hi: Optional[float] = None, *,
           lo_open: bool = False, text: bool = True) -> float:
    """``value`` as a finite float in [lo, hi] ((lo, hi] with ``lo_open``; a bound left None is
    open-ended); raises ``fail(None)`` when it is not a finite number (:func:`as_finite`, with
    ``text``), ``fail(got)`` when it is out of range."""
    got = as_finite(value, text)
    if got is None:
        raise fail(None)
    return _in_range(got, fail, lo, hi, lo_open)


def integer(value: Any, fail: Fail, lo: Optional[int] = None, hi: Optional[int] = None, *,
            text: bool = False, integral: bool = False) -> int:
    """``value`` as an int in [lo, hi] (a bound left None is open-ended); raises ``fail(None)``
    when it is not an integer (:func:`as_integer`, with ``text`` and ``integral``), ``fail(got)``
    when it is out of range."""
    got = as_integer(value, text, integral)
    if got is None:
        raise fail(None)
    return _in_range(got, fail, lo, hi, False)


def choice(kind: Type[_E], value: Any, fail: Callable[[str], Exception]) -> _E:
    """``value`` as a member of the enum ``kind`` whose values are lower-case words: the member
    itself, or its value as text (case and surrounding white space ignored: " S_Curve "). Otherwise
    raises ``fail(choices)``, ``choices`` the values in words ("linear or s_curve"); the caller's
    message names the setting and the value (``from None``: the enum's own ValueError is no news)."""
    if isinstance(value, kind):
        return value
    try:
        return kind(str(value).strip().lower())
    except ValueError:
        raise fail(" or ".join(member.value for member in kind)) from None


def choice_parser(error: Callable[[str], Exception], message: str) -> Any:
    """An enum's ``parse`` classmethod (assigned in the class body: ``parse = choice_parser(...)``):
    the member :func:`choice` finds for a value, else ``error(message)`` raised, ``message``
    formatted with ``words`` (the enum's values in words) and ``value`` (what was given), e.g.
    ``"ramp_shape must be {words}, got {value!r}"``. Each enum keeps its own error type and words."""
    def parse(cls: Type[_E], value: Any) -> _E:
        return choice(cls, value, lambda words: error(message.format(words=words, value=value)))
    parse.__doc__ = "The member ``value`` names (itself, or its value as text); %s otherwise: %r." % (
        error.__name__, message)
    return classmethod(parse)
