"""The .csr format's constants and the checks of single fields (text, tokens, numbers, speeds,
dates). ROS-free; every message quotes at most a short prefix of the value (:func:`show`)."""
from __future__ import annotations

import datetime as _dt
import itertools
import re
from typing import Any, List, Mapping, Optional

from .. import validate
from ..errors import CsrError


JOINT_COLUMNS = ("RT", "UA", "FA", "RW", "BW", "TW")
CARTESIAN_COLUMNS = ("X", "Y", "Z", "U", "V", "W")
POSE_COLUMNS = {"AJ": JOINT_COLUMNS, "AU": CARTESIAN_COLUMNS}
SECTION_ORDER = ("Description", "Pose", "Variable", "Command")

COMMENT_MAX = 30              # DTPS: Comment <= 30 chars
CREATOR_MAX = 16              # Creator <= 16 chars
VARIABLE_NAME_MAX = 8         # variable name <= 8 chars
VARIABLE_COMMENT_MAX = 32     # variable comment <= 32 chars

MOVE_OPCODES = ("MOVEP", "MOVEL", "MOVEC")
SPEED_UNITS = {"m/min": (0.01, 180.0), "%": (0.01, 100.0)}   # our bounds; verify on the controller
SMOOTH_RANGE = (-1, 10)       # -1 = default; Cenit maps accuracy to 0..8, we accept up to 10
WELD_FLAGS = ("N", "W")       # N = air (no weld), W = weld
CIRCLE_OPTIONS = ("CIR_NORMAL", "CIR_SPLIT-OFF")
EDIT_VALUES = (0, 1, 2)       # 0 editable, 1 only positions editable, 2 prohibited
_VAR_RANGES = {"LB": (0, 255), "LI": (-32768, 32767), "LL": (-2147483648, 2147483647)}

_MECHANISM_RE = re.compile(r"^\d+\([0-9A-Fa-f]{4}\)$")
_TOOL_RE = re.compile(r"^(\d{1,3}):(\S(?:.*\S)?)$")
_NAME_RE = re.compile(r"^[A-Za-z0-9_]+$")
NEWLINES = {"crlf": "\r\n", "lf": "\n"}

DEFAULT_DATE = _dt.datetime(2000, 1, 1, 0, 0, 0)


SHOW_MAX = 40                 # characters of a value quoted in a message


def show(value: Any, limit: int = SHOW_MAX) -> str:
    """How a value is quoted in a message: its repr, cut to at most ``limit`` characters (then
    ending in "..."). Lists and mappings are summarised (3 items, 2 levels) without walking them
    whole, so a huge or alias-expanded input value costs nothing to quote."""
    text = _short_repr(value, 2, limit)
    return text if len(text) <= limit else text[:max(limit - 3, 1)] + "..."


def _short_repr(value: Any, levels: int, limit: int) -> str:
    if isinstance(value, (str, bytes, bytearray)):
        return repr(value[:limit + 1])
    if isinstance(value, Mapping):
        if levels <= 0:
            return "{...}"
        items = ["%s: %s" % (_short_repr(k, levels - 1, limit), _short_repr(v, levels - 1, limit))
                 for k, v in itertools.islice(value.items(), 3)]
        return "{%s%s}" % (", ".join(items), ", ..." if len(value) > 3 else "")
    if isinstance(value, (list, tuple, set, frozenset)):
        if levels <= 0:
            return "[...]"
        items = [_short_repr(v, levels - 1, limit) for v in itertools.islice(value, 3)]
        return "[%s%s]" % (", ".join(items), ", ..." if len(value) > 3 else "")
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 128:
        return "<an integer of %d bits>" % value.bit_length()   # str() of a huge int is slow or refused
    try:
        text = repr(value)
    except Exception:          # an object whose repr fails must not hide the real error
        text = "<%s>" % type(value).__name__
    return text


def clip(text: str, limit: int = 200) -> str:
    """A message (e.g. of a library error that may quote input) cut to ``limit`` characters."""
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _text(value: Any, what: str, max_len: Optional[int] = None, allow_empty: bool = True) -> str:
    """A text field: a str without commas or control characters, no surrounding spaces (they would
    not survive a read), at most ``max_len`` characters."""
    if not isinstance(value, str):
        raise CsrError("must be text, got %s" % show(value), field=what)
    if not value and not allow_empty:
        raise CsrError("must not be empty", field=what)
    if "," in value:
        raise CsrError("%s contains a comma, which would split the field" % show(value), field=what)
    if not value.isprintable():
        raise CsrError("%s contains a control character" % show(value), field=what)
    if value != value.strip():
        raise CsrError("%s starts or ends with a space" % show(value), field=what)
    if max_len is not None and len(value) > max_len:
        raise CsrError("%s is %d characters long, at most %d allowed" % (show(value), len(value), max_len),
                       field=what)
    return value


def _matching(value: Any, what: str, pattern: "re.Pattern[str]", otherwise: str) -> str:
    """A non-empty text field (:func:`_text`) that ``pattern`` matches; CsrError "<value> <otherwise>"
    if it does not."""
    value = _text(value, what, allow_empty=False)
    if not pattern.match(value):
        raise CsrError("%s %s" % (show(value), otherwise), field=what)
    return value


def _token(value: Any, what: str) -> str:
    """A non-empty text field without spaces (point names, variable types)."""
    return _matching(value, what, _NAME_RE, "may hold only letters, digits and _")


def _number(value: Any, what: str) -> float:
    return validate.number(value, lambda _: CsrError("must be a finite number, got %s" % show(value), field=what))


def _integer(value: Any, what: str, lo: Optional[int] = None, hi: Optional[int] = None) -> int:
    def fail(got: Optional[float]) -> CsrError:
        if got is None:
            return CsrError("must be an integer, got %s" % show(value), field=what)
        return CsrError("%d is outside [%s, %s]" % (got, lo, hi), field=what)
    return validate.integer(value, fail, lo, hi, text=True)


def _raw_line(text: Any, what: str) -> str:
    """A line kept verbatim: one non-blank line that does not read as a [Section] header."""
    if not isinstance(text, str) or "\n" in text or "\r" in text or not text.strip():
        raise CsrError("%s is not one non-blank line" % show(text), field=what)
    stripped = text.strip()
    if stripped.startswith("[") and stripped.endswith("]"):
        raise CsrError("%s would be read as a section header" % show(text), field=what)
    return text


def _fmt(value: float, decimals: int) -> str:
    text = "%.*f" % (decimals, value)
    if float(text) == 0.0:                      # no "-0.000"
        text = "%.*f" % (decimals, 0.0)
    return text


def _decimals(token: str) -> int:
    token = token.strip()
    if "e" in token.lower() or "." not in token:
        return 0
    return len(token.split(".", 1)[1])


def _speed(value: Any, unit: str, what: str) -> float:
    speed = _number(value, what)
    if unit not in SPEED_UNITS:
        raise CsrError("unit %s is not one of %s" % (show(unit), ", ".join(SPEED_UNITS)), field=what)
    lo, hi = SPEED_UNITS[unit]
    printed = round(speed, 2)                   # what the file will hold
    if not lo <= printed <= hi:
        raise CsrError("%g %s is outside [%g, %g] %s (written with 2 decimals)" % (speed, unit, lo, hi, unit),
                       field=what)
    return speed


def _tool_text(value: Any, what: str) -> str:
    """A tool as the file writes it: ``n:NAME`` (the Tool header, a TOOL line)."""
    return _matching(value, what, _TOOL_RE, "is not 'n:NAME' (e.g. 1:TOOL01)")


def _date(value: Any, what: str) -> _dt.datetime:
    if isinstance(value, _dt.datetime):
        return value.replace(microsecond=0, tzinfo=None)
    if isinstance(value, _dt.date):
        return _dt.datetime(value.year, value.month, value.day)
    if isinstance(value, str):
        try:
            return _dt.datetime.fromisoformat(value.strip()).replace(microsecond=0, tzinfo=None)
        except ValueError:
            pass
    raise CsrError("%s is not a date and time (YYYY-MM-DD hh:mm:ss)" % show(value), field=what)


def _split(text: str) -> List[str]:
    return [t.strip() for t in text.split(",")]
