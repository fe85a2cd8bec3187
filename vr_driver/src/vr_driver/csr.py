"""Offline export and import of Panasonic DTPS ``.csr`` programs. ROS-free (rospy is imported only
by the ``--from-topic`` mode of the command line).

The format (usage, conventions and the details chosen: doc/csr.md) is plain text,
comma separated, in sections::

    [Description]   Key, value lines: Robot, Comment (<= 30 chars), SubComment1/2, Mechanism,
                    Tool, Creator (<= 16 chars), User coordinates, Create, Update, Original, Edit
    [Pose]          "/Name, Type, RT, UA, FA, RW, BW, TW" then "P001, AJ, 0.000, ..." rows
                    (AJ: joint angles in degrees; AU: X, Y, Z mm, U, V, W degrees)
    [Variable]      "LB, LB001, , 0" (type, name <= 8 chars, comment <= 32 chars, value)
    [Command]       TOOL, MOVEP, MOVEL, MOVEC lines; any other instruction is kept verbatim

Model (all frozen dataclasses, equal when their text is equal):

- :class:`Description`, :class:`Pose`, :class:`Variable`, :class:`Tool`, :class:`Move`,
  :class:`RawCommand`, :class:`RawSection`, :class:`CsrProgram`.
- :func:`format_program` / :func:`write_program` write a program (validated first, CsrError
  names the field); :func:`parse_program` / :func:`read_program` read one (CsrError names the
  line and field). ``format_program(parse_program(text)) == text`` for every text this module
  writes.

Export (waypoints -> program), all in controller units (mm, degrees) except joint vectors of the
URDF (radians, chain order joint_1..joint_6):

- :class:`JointConvention` maps URDF joint angles to the AJ columns RT UA FA RW BW TW and back
  (FA relative to UA or to the horizontal, per-axis sign flips and offsets).
- :func:`load_waypoints` reads a waypoint YAML / CSV file or a YAML dump of a
  ``trajectory_msgs/JointTrajectory`` into :class:`Waypoint` records that remember their line.
- :func:`export_program` turns waypoints into a program: Cartesian poses through our IK, seeded
  point to point; every pose inside the workspace box and every joint vector inside the limits,
  else :class:`CsrConversionError` listing each refused waypoint by its input line.
- :func:`check_program` / :func:`summarize` check and describe a program read back.

Command line: ``python3 -m vr_driver.csr --help`` (also ``rosrun vr_driver csr_export``).
Exit codes: 0 ok, 1 conversion failed (a waypoint or pose refused), 2 usage or input error.
"""
from __future__ import annotations

import argparse
import csv
import datetime as _dt
import math
import os
import re
import sys
import tempfile
from dataclasses import dataclass, field, replace
from typing import Any, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple, Union

from .errors import (CsrConversionError, CsrError, KinematicsError, MotionError, PoseError, VrDriverError)
from .motion import MoveType
from .poses import ControllerPose, Workspace

__all__ = [
    "JOINT_COLUMNS",
    "CARTESIAN_COLUMNS",
    "Description",
    "Pose",
    "Variable",
    "Tool",
    "Move",
    "RawCommand",
    "RawSection",
    "CsrProgram",
    "default_variables",
    "format_program",
    "write_program",
    "parse_program",
    "read_program",
    "JointConvention",
    "Waypoint",
    "ExportSettings",
    "load_waypoints",
    "parse_waypoints",
    "trajectory_waypoints",
    "export_program",
    "check_program",
    "summarize",
    "main",
]

# ================================================================================ format constants

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


# ================================================================================== field checks

def _text(value: Any, what: str, max_len: Optional[int] = None, allow_empty: bool = True) -> str:
    """A text field: a str without commas or control characters, no surrounding spaces (they would
    not survive a read), at most ``max_len`` characters."""
    if not isinstance(value, str):
        raise CsrError("must be text, got %r" % (value,), field=what)
    if not value and not allow_empty:
        raise CsrError("must not be empty", field=what)
    if "," in value:
        raise CsrError("%r contains a comma, which would split the field" % value, field=what)
    if not value.isprintable():
        raise CsrError("%r contains a control character" % value, field=what)
    if value != value.strip():
        raise CsrError("%r starts or ends with a space" % value, field=what)
    if max_len is not None and len(value) > max_len:
        raise CsrError("%r is %d characters long, at most %d allowed" % (value, len(value), max_len),
                       field=what)
    return value


def _token(value: Any, what: str) -> str:
    """A non-empty text field without spaces (point names, variable types)."""
    value = _text(value, what, allow_empty=False)
    if not _NAME_RE.match(value):
        raise CsrError("%r may hold only letters, digits and _" % value, field=what)
    return value


def _number(value: Any, what: str) -> float:
    if isinstance(value, bool) or value is None:
        raise CsrError("must be a finite number, got %r" % (value,), field=what)
    try:
        number = float(value.strip()) if isinstance(value, str) else float(value)
    except (TypeError, ValueError):
        raise CsrError("must be a finite number, got %r" % (value,), field=what) from None
    if not math.isfinite(number):
        raise CsrError("must be a finite number, got %r" % (value,), field=what)
    return number


def _integer(value: Any, what: str, lo: Optional[int] = None, hi: Optional[int] = None) -> int:
    if isinstance(value, bool):
        raise CsrError("must be an integer, got %r" % (value,), field=what)
    if isinstance(value, int):
        number = value
    elif isinstance(value, str) and re.match(r"^\s*[-+]?\d+\s*$", value):
        number = int(value)
    else:
        raise CsrError("must be an integer, got %r" % (value,), field=what)
    if (lo is not None and number < lo) or (hi is not None and number > hi):
        raise CsrError("%d is outside [%s, %s]" % (number, lo, hi), field=what)
    return number


def _raw_line(text: Any, what: str) -> str:
    """A line kept verbatim: one non-blank line that does not read as a [Section] header."""
    if not isinstance(text, str) or "\n" in text or "\r" in text or not text.strip():
        raise CsrError("%r is not one non-blank line" % (text,), field=what)
    stripped = text.strip()
    if stripped.startswith("[") and stripped.endswith("]"):
        raise CsrError("%r would be read as a section header" % text, field=what)
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
        raise CsrError("unit %r is not one of %s" % (unit, ", ".join(SPEED_UNITS)), field=what)
    lo, hi = SPEED_UNITS[unit]
    printed = round(speed, 2)                   # what the file will hold
    if not lo <= printed <= hi:
        raise CsrError("%g %s is outside [%g, %g] %s (written with 2 decimals)" % (speed, unit, lo, hi, unit),
                       field=what)
    return speed


def _tool_text(value: Any, what: str) -> str:
    value = _text(value, what, allow_empty=False)
    if not _TOOL_RE.match(value):
        raise CsrError("%r is not 'n:NAME' (e.g. 1:TOOL01)" % value, field=what)
    return value


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
    raise CsrError("%r is not a date and time (YYYY-MM-DD hh:mm:ss)" % (value,), field=what)


# ================================================================================== the model

_DESCRIPTION_KEYS = ("Robot", "Robot2", "Comment", "SubComment1", "SubComment2", "Mechanism", "Tool", "Welder",
                     "Creator", "User coordinates", "User coordinate", "Create", "Update", "Original", "Edit")

@dataclass(frozen=True)
class Description:
    """The [Description] section. ``created`` defaults to the current time (whole seconds),
    ``updated`` to ``created``. ``robot2`` / ``welder`` are written only when not empty.
    ``extra_lines`` holds description lines with unknown keys, verbatim."""

    robot: str = "VR-006L"
    comment: str = "ros_export"
    sub_comment1: str = ""
    sub_comment2: str = ""
    mechanism: str = "1(0001)"
    tool: str = "1:TOOL01"
    creator: str = "ROS"
    user_coordinates: str = "None"
    created: Optional[_dt.datetime] = None
    updated: Optional[_dt.datetime] = None
    original: str = ""
    edit: int = 0
    robot2: str = ""
    welder: str = ""
    user_coordinates_key: str = "User coordinates"
    extra_lines: Tuple[str, ...] = ()

    def __post_init__(self) -> None:
        _text(self.robot, "Robot", allow_empty=False)
        _text(self.comment, "Comment", COMMENT_MAX)
        _text(self.sub_comment1, "SubComment1")
        _text(self.sub_comment2, "SubComment2")
        if not isinstance(self.mechanism, str) or not _MECHANISM_RE.match(self.mechanism):
            raise CsrError("%r is not 'n(hhhh)' (e.g. 1(0001))" % (self.mechanism,), field="Mechanism")
        _tool_text(self.tool, "Tool")
        _text(self.creator, "Creator", CREATOR_MAX)
        _text(self.user_coordinates, "User coordinates")
        if self.user_coordinates_key not in ("User coordinates", "User coordinate"):
            raise CsrError("key %r is not 'User coordinates' or 'User coordinate'" % self.user_coordinates_key,
                           field="User coordinates")
        created = _dt.datetime.now().replace(microsecond=0) if self.created is None \
            else _date(self.created, "Create")
        object.__setattr__(self, "created", created)
        object.__setattr__(self, "updated", created if self.updated is None else _date(self.updated, "Update"))
        _text(self.original, "Original")
        _integer(self.edit, "Edit", 0, 2)
        _text(self.robot2, "Robot2")
        _text(self.welder, "Welder")
        object.__setattr__(self, "extra_lines", tuple(self.extra_lines))
        for line in self.extra_lines:
            _raw_line(line, "Description extra line")
            if _split(line)[0] in _DESCRIPTION_KEYS:
                raise CsrError("%r repeats a known key" % line, field="Description extra line")

    def lines(self) -> List[str]:
        def entry(key: str, value: str) -> str:
            return "%s, %s" % (key, value) if value else "%s," % key

        def date(value: _dt.datetime) -> str:
            return "%04d, %02d, %02d, %02d, %02d, %02d" % (value.year, value.month, value.day,
                                                           value.hour, value.minute, value.second)
        out = [entry("Robot", self.robot)]
        if self.robot2:
            out.append(entry("Robot2", self.robot2))
        out += [entry("Comment", self.comment), entry("SubComment1", self.sub_comment1),
                entry("SubComment2", self.sub_comment2), entry("Mechanism", self.mechanism),
                entry("Tool", self.tool)]
        if self.welder:
            out.append(entry("Welder", self.welder))
        out += [entry("Creator", self.creator), entry(self.user_coordinates_key, self.user_coordinates),
                entry("Create", date(self.created)), entry("Update", date(self.updated)),
                entry("Original", self.original), entry("Edit", str(self.edit))]
        return out + list(self.extra_lines)


@dataclass(frozen=True)
class Pose:
    """One [Pose] row. AJ / AU rows hold ``values`` (floats: 6 + external axes); rows of other types
    (AV, AP, WU, ...) hold their fields verbatim in ``raw``. ``line`` is where it was read (not
    part of equality)."""

    name: str
    kind: str
    values: Tuple[float, ...] = ()
    raw: Tuple[str, ...] = ()
    line: int = field(default=0, compare=False, repr=False)

    def __post_init__(self) -> None:
        _token(self.name, "pose name")
        _token(self.kind, "pose %s type" % self.name)
        object.__setattr__(self, "values", tuple(_number(v, "pose %s value" % self.name) for v in self.values))
        object.__setattr__(self, "raw", tuple(_text(v, "pose %s field" % self.name) for v in self.raw))
        if self.kind in POSE_COLUMNS:
            if self.raw:
                raise CsrError("an %s pose holds numbers, not raw fields" % self.kind, field="pose " + self.name)
            if len(self.values) < 6:
                raise CsrError("an %s pose needs 6 values (%s), got %d"
                               % (self.kind, ", ".join(POSE_COLUMNS[self.kind]), len(self.values)),
                               field="pose " + self.name)
        elif self.values:
            raise CsrError("pose type %s is kept verbatim: give raw fields, not values" % self.kind,
                           field="pose " + self.name)

    @property
    def width(self) -> int:
        return len(self.values) if self.kind in POSE_COLUMNS else len(self.raw)

    def fields(self, decimals: int) -> List[str]:
        if self.kind in POSE_COLUMNS:
            return [_fmt(v, decimals) for v in self.values]
        return list(self.raw)


@dataclass(frozen=True)
class Variable:
    """One [Variable] row: type (LB byte, LI int16, LL int32, LR real; others kept as written),
    name (<= 8 chars), comment (<= 32 chars), initial value (text as written, checked by type)."""

    type: str
    name: str
    comment: str = ""
    value: str = "0"
    line: int = field(default=0, compare=False, repr=False)

    def __post_init__(self) -> None:
        _token(self.type, "variable type")
        _text(self.name, "variable name", VARIABLE_NAME_MAX, allow_empty=False)
        _text(self.comment, "variable %s comment" % self.name, VARIABLE_COMMENT_MAX)
        _text(self.value, "variable %s value" % self.name, allow_empty=False)
        what = "variable %s value" % self.name
        if self.type in _VAR_RANGES:
            _integer(self.value, what, *_VAR_RANGES[self.type])
        elif self.type == "LR":
            _number(self.value, what)

    def line_text(self) -> str:
        return ", ".join((self.type, self.name, self.comment, self.value))


def default_variables() -> Tuple[Variable, ...]:
    """DTPS's default [Variable] section: LB001..LB005, LI..., LL..., LR001..LR005, all zero."""
    out = []
    for kind in ("LB", "LI", "LL", "LR"):
        for i in range(1, 6):
            out.append(Variable(kind, "%s%03d" % (kind, i), "", "0.000000000000000" if kind == "LR" else "0"))
    return tuple(out)


@dataclass(frozen=True)
class Tool:
    """``TOOL, 1:TOOL01``."""

    tool: str = "1:TOOL01"
    line: int = field(default=0, compare=False, repr=False)

    def __post_init__(self) -> None:
        _tool_text(self.tool, "TOOL tool")

    def line_text(self) -> str:
        return "TOOL, %s" % self.tool


@dataclass(frozen=True)
class Move:
    """A MOVEP / MOVEL / MOVEC line::

        MOVEP, point, speed, unit, N|W, smooth
        MOVEL, point, speed, unit, CL, N|W, smooth
        MOVEC, point, speed, unit, CL, N|W, smooth[, CIR_NORMAL|CIR_SPLIT-OFF]

    ``speed`` is written with 2 decimals; ``cl`` and ``option`` do not exist for MOVEP."""

    opcode: str
    point: str
    speed: float
    unit: str = "m/min"
    weld: str = "N"
    smooth: int = -1
    cl: int = 0
    option: str = ""
    line: int = field(default=0, compare=False, repr=False)

    def __post_init__(self) -> None:
        if self.opcode not in MOVE_OPCODES:
            raise CsrError("%r is not one of %s" % (self.opcode, ", ".join(MOVE_OPCODES)), field="move opcode")
        op = self.opcode
        _token(self.point, op + " point")
        if self.unit not in SPEED_UNITS:
            raise CsrError("%r is not one of %s" % (self.unit, ", ".join(SPEED_UNITS)), field=op + " unit")
        object.__setattr__(self, "speed", _speed(self.speed, self.unit, op + " speed"))
        if self.weld not in WELD_FLAGS:
            raise CsrError("%r is not N (air) or W (weld)" % (self.weld,), field=op + " N/W")
        object.__setattr__(self, "smooth", _integer(self.smooth, op + " smooth level", *SMOOTH_RANGE))
        object.__setattr__(self, "cl", _integer(self.cl, op + " CL no.", 0, 999))
        if op == "MOVEP" and self.cl:
            raise CsrError("MOVEP has no CL number", field="MOVEP CL no.")
        if self.option and (op != "MOVEC" or self.option not in CIRCLE_OPTIONS):
            raise CsrError("%r is not allowed here (only MOVEC takes %s)" % (self.option, " / ".join(CIRCLE_OPTIONS)),
                           field=op + " option")

    def line_text(self) -> str:
        fields = [self.opcode, self.point, "%.2f" % self.speed, self.unit]
        if self.opcode != "MOVEP":
            fields.append(str(self.cl))
        fields += [self.weld, str(self.smooth)]
        if self.option:
            fields.append(self.option)
        return ", ".join(fields)


@dataclass(frozen=True)
class RawCommand:
    """Any other [Command] line (ARC-SET, DELAY, REM, CALL, MOVELW, ...), kept verbatim."""

    text: str
    line: int = field(default=0, compare=False, repr=False)

    def __post_init__(self) -> None:
        _raw_line(self.text, "command")
        op = _split(self.text)[0]
        if op in MOVE_OPCODES + ("TOOL",):
            raise CsrError("%r would be read back as a %s command, not verbatim" % (self.text, op), field="command")

    def line_text(self) -> str:
        return self.text


Command = Union[Tool, Move, RawCommand]


@dataclass(frozen=True)
class RawSection:
    """A section this module does not model ([Work], [Pose R2], ...), kept verbatim, written after
    the known section ``after`` ("" = before [Description])."""

    name: str
    lines: Tuple[str, ...] = ()
    after: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.strip() or "]" in self.name or self.name in SECTION_ORDER:
            raise CsrError("%r is not the name of an extra section" % (self.name,), field="section")
        object.__setattr__(self, "lines", tuple(self.lines))
        for line in self.lines:
            _raw_line(line, "[%s] line" % self.name)
        if self.after not in ("",) + SECTION_ORDER:
            raise CsrError("after=%r is not one of %s" % (self.after, ", ".join(SECTION_ORDER)), field="section")


@dataclass(frozen=True)
class CsrProgram:
    """A whole program. ``variables`` None = no [Variable] section (as the Cenit downloader
    writes). ``pose_columns`` None = the columns of the first pose's type (RT..TW for AJ, X..W
    for AU; RT..TW for no poses). ``decimals``: digits
    written after the point for AJ / AU values (generators write 3, DTPS 15). Equality compares
    the content (what would be written), not where it was read from."""

    description: Description = field(default_factory=Description)
    poses: Tuple[Pose, ...] = ()
    commands: Tuple[Command, ...] = ()
    variables: Optional[Tuple[Variable, ...]] = field(default_factory=default_variables)
    pose_columns: Optional[Tuple[str, ...]] = None
    decimals: int = 3
    extra_sections: Tuple[RawSection, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "poses", tuple(self.poses))
        object.__setattr__(self, "commands", tuple(self.commands))
        if self.variables is not None:
            object.__setattr__(self, "variables", tuple(self.variables))
        if self.pose_columns is None:       # the columns of the first pose's type
            first = self.poses[0] if self.poses else None
            if first is not None and first.kind not in POSE_COLUMNS:
                raise CsrError("pose type %s has no default columns: give pose_columns" % first.kind,
                               field="[Pose] header")
            object.__setattr__(self, "pose_columns", POSE_COLUMNS[first.kind] if first else JOINT_COLUMNS)
        object.__setattr__(self, "pose_columns", tuple(_token(c, "pose column") for c in self.pose_columns))
        object.__setattr__(self, "extra_sections", tuple(self.extra_sections))
        _integer(self.decimals, "decimals", 0, 15)

    def pose(self, name: str) -> Pose:
        for p in self.poses:
            if p.name == name:
                return p
        raise KeyError(name)

    def moves(self) -> List[Move]:
        return [c for c in self.commands if isinstance(c, Move)]

    def columns(self) -> Tuple[str, ...]:
        return self.pose_columns


# ====================================================================================== writing

def _check_structure(program: CsrProgram, source: str = "") -> None:
    """Checks across lines: pose widths vs the header, unique pose and variable names, every MOVE names a pose,
    MOVEC comes in runs of at least 3. Errors name the line when the objects were read from a file."""
    columns = program.columns()
    seen: Dict[str, Pose] = {}
    for p in program.poses:
        if p.width != len(columns):
            raise CsrError("%d values, but the /Name header has %d columns (%s)"
                           % (p.width, len(columns), ", ".join(columns)), p.line, "pose " + p.name, source)
        if p.name in seen:
            first = seen[p.name]
            raise CsrError("the name is used twice%s" % (" (first on line %d)" % first.line if first.line else ""),
                           p.line, "pose " + p.name, source)
        seen[p.name] = p
    names: Dict[str, Variable] = {}
    for v in program.variables or ():
        if v.name in names:
            first = names[v.name]
            raise CsrError("the name is used twice%s" % (" (first on line %d)" % first.line if first.line else ""),
                           v.line, "variable " + v.name, source)
        names[v.name] = v
    commands = program.commands
    for c in commands:
        if isinstance(c, Move) and c.point not in seen:
            raise CsrError("point %s is not in [Pose]" % c.point, c.line, c.opcode + " point", source)
    i = 0
    while i < len(commands):
        if isinstance(commands[i], Move) and commands[i].opcode == "MOVEC":
            j = i
            while j < len(commands) and isinstance(commands[j], Move) and commands[j].opcode == "MOVEC":
                j += 1
            if j - i < 3:
                c = commands[i]
                raise CsrError("a circle needs at least 3 consecutive MOVEC points, this run has %d" % (j - i),
                               c.line, "MOVEC " + c.point, source)
            i = j
        else:
            i += 1


def format_program(program: CsrProgram, newline: str = "\r\n") -> str:
    """The program as text (``newline`` "\\r\\n" or "\\n"); CsrError if it is inconsistent."""
    if newline not in ("\r\n", "\n"):
        raise CsrError("newline must be CRLF or LF, got %r" % (newline,), field="newline")
    _check_structure(program)
    sections: List[Tuple[str, List[str]]] = []

    def extras(after: str) -> None:
        for raw in program.extra_sections:
            if raw.after == after:
                sections.append((raw.name, list(raw.lines)))

    extras("")
    sections.append(("Description", program.description.lines()))
    extras("Description")
    header = "/Name, Type, " + ", ".join(program.columns())
    sections.append(("Pose", [header] + [", ".join([p.name, p.kind] + p.fields(program.decimals))
                                         for p in program.poses]))
    extras("Pose")
    if program.variables is not None:
        sections.append(("Variable", [v.line_text() for v in program.variables]))
    extras("Variable")
    sections.append(("Command", [c.line_text() for c in program.commands]))
    extras("Command")
    out: List[str] = []
    for k, (name, lines) in enumerate(sections):
        if k:
            out.append("")
        out.append("[%s]" % name)
        out.extend(lines)
    return newline.join(out) + newline


def program_bytes(program: CsrProgram, newline: str = "\r\n", encoding: str = "ascii") -> bytes:
    text = format_program(program, newline)
    try:
        return text.encode(encoding)
    except UnicodeEncodeError as exc:
        bad = text[exc.start:exc.end]
        line = text.count("\n", 0, exc.start) + 1
        raise CsrError("%r cannot be written in %s" % (bad, encoding), line, "text") from None


def write_program(program: CsrProgram, path: str, newline: str = "\r\n", encoding: str = "ascii") -> None:
    """Write atomically (a temporary file in the same directory, then renamed): a failed export
    never leaves half a file, and a second export replaces the first (never appends)."""
    _atomic_write(program_bytes(program, newline, encoding), path)


def _atomic_write(data: bytes, path: str) -> None:
    directory = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix=".csr-", dir=directory)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


# ====================================================================================== parsing

def _split(text: str) -> List[str]:
    return [t.strip() for t in text.split(",")]


def _parse_description(section_line: int, lines: List[Tuple[int, str]], source: str) -> Description:
    text_keys = {"Robot": "robot", "Robot2": "robot2", "Comment": "comment", "SubComment1": "sub_comment1",
                 "SubComment2": "sub_comment2", "Mechanism": "mechanism", "Tool": "tool", "Welder": "welder",
                 "Creator": "creator", "User coordinates": "user_coordinates",
                 "User coordinate": "user_coordinates", "Original": "original"}
    kwargs: Dict[str, Any] = {}
    seen: Dict[str, int] = {}          # attribute -> line
    key_lines: Dict[str, int] = {}     # key as written -> line
    extra: List[str] = []
    for lineno, text in lines:
        tokens = _split(text)
        key, values = tokens[0], tokens[1:]
        if key in text_keys or key in ("Create", "Update", "Edit"):
            attr = text_keys.get(key, key)
            if attr in seen:
                raise CsrError("given twice (first on line %d)" % seen[attr], lineno, key, source)
            seen[attr] = lineno
            key_lines[key] = lineno
        try:
            if key in text_keys:
                if len(values) > 1:
                    raise CsrError("%d comma-separated values; the value must not contain a comma"
                                   % len(values), field=key)
                kwargs[text_keys[key]] = values[0] if values else ""
                if key.startswith("User coordinate"):
                    kwargs["user_coordinates_key"] = key
                _check_description_field(key, kwargs[text_keys[key]])
            elif key in ("Create", "Update"):
                if len(values) != 6:
                    raise CsrError("needs 6 numbers YYYY, MM, DD, hh, mm, ss, got %d field(s) %r"
                                   % (len(values), ", ".join(values)), field=key)
                parts = [_integer(v, key) for v in values]
                try:
                    stamp = _dt.datetime(*parts)
                except ValueError as exc:
                    raise CsrError("%s is not a valid date and time (%s)" % (", ".join(values), exc),
                                   field=key) from None
                kwargs["created" if key == "Create" else "updated"] = stamp
            elif key == "Edit":
                if len(values) != 1:
                    raise CsrError("needs one value 0, 1 or 2", field=key)
                kwargs["edit"] = _integer(values[0], key, 0, 2)
            else:
                extra.append(text)
        except CsrError as exc:
            raise exc.located(lineno, source) from None
    for required in ("Robot", "Tool"):
        if required.lower() not in kwargs:
            raise CsrError("no %s line" % required, section_line, "[Description]", source)
    kwargs.setdefault("created", DEFAULT_DATE)     # deterministic when the file has no Create line
    kwargs["extra_lines"] = tuple(extra)
    try:
        return Description(**kwargs)
    except CsrError as exc:
        raise exc.located(key_lines.get(exc.field, section_line), source) from None


def _check_description_field(key: str, value: str) -> None:
    limits = {"Comment": COMMENT_MAX, "Creator": CREATOR_MAX}
    if key == "Mechanism":
        if not _MECHANISM_RE.match(value):
            raise CsrError("%r is not 'n(hhhh)' (e.g. 1(0001))" % value, field=key)
    elif key == "Tool":
        _tool_text(value, key)
    else:
        _text(value, key, limits.get(key), allow_empty=key not in ("Robot",))


def parse_program(text: str, source: str = "") -> CsrProgram:
    """Read a program from text (CRLF or LF). CsrError names ``source``, the line and the field."""
    if text.startswith("\ufeff"):
        text = text[1:]
    sections: List[Tuple[str, int, List[Tuple[int, str]]]] = []
    for lineno, raw in enumerate(text.splitlines(), 1):
        stripped = raw.strip()
        if stripped.startswith("[") and stripped.endswith("]"):
            name = stripped[1:-1].strip()
            if not name:
                raise CsrError("empty section name", lineno, "section", source)
            if any(name == s[0] for s in sections):
                raise CsrError("section [%s] appears twice" % name, lineno, "section", source)
            sections.append((name, lineno, []))
        elif not stripped:
            continue
        elif not sections:
            raise CsrError("text before the first [Section] line: %r" % stripped[:40], lineno, "file", source)
        else:
            sections[-1][2].append((lineno, raw.rstrip("\r\n")))
    found = {name: (lineno, lines) for name, lineno, lines in sections}
    last_line = text.count("\n") + (0 if text.endswith("\n") else 1)
    for required in ("Description", "Pose", "Command"):
        if required not in found:
            raise CsrError("no [%s] section" % required, last_line, "file", source)

    description = _parse_description(found["Description"][0], found["Description"][1], source)
    columns, poses, decimals = _parse_poses(found["Pose"], source)
    variables = None
    if "Variable" in found:
        variables = []
        for lineno, text_line in found["Variable"][1]:
            tokens = _split(text_line)
            if len(tokens) != 4:
                raise CsrError("needs 4 fields (type, name, comment, value), got %d" % len(tokens), lineno,
                               "variable", source)
            try:
                variables.append(Variable(tokens[0], tokens[1], tokens[2], tokens[3], line=lineno))
            except CsrError as exc:
                raise exc.located(lineno, source) from None
    commands = [_parse_command(lineno, text_line, source) for lineno, text_line in found["Command"][1]]
    extra: List[RawSection] = []
    after = ""
    for name, _lineno, lines in sections:
        if name in SECTION_ORDER:
            after = name
        else:
            extra.append(RawSection(name, tuple(t for _, t in lines), after))
    order = [name for name, _, _ in sections if name in SECTION_ORDER]
    expected = [name for name in SECTION_ORDER if name in order]
    if order != expected:
        line = found[[a for a, b in zip(order, expected) if a != b][0]][0]
        raise CsrError("sections out of order: %s (expected %s)" % (", ".join(order), ", ".join(expected)),
                       line, "section", source)
    program = CsrProgram(description, tuple(poses), tuple(commands),
                         None if variables is None else tuple(variables), columns, decimals, tuple(extra))
    _check_structure(program, source)
    return program


def _parse_poses(section: Tuple[int, List[Tuple[int, str]]], source: str
                 ) -> Tuple[Tuple[str, ...], List[Pose], int]:
    section_line, lines = section
    columns: Optional[Tuple[str, ...]] = None
    header_line = section_line
    poses: List[Pose] = []
    decimals = -1                       # -1: no numeric pose seen

    for lineno, text in lines:
        tokens = _split(text)
        if tokens[0].startswith("/"):
            if columns is not None:
                raise CsrError("a second /Name header line", lineno, "[Pose] header", source)
            if len(tokens) < 3 or tokens[0] != "/Name" or tokens[1] != "Type":
                raise CsrError("the header must read '/Name, Type, <columns>', got %r" % text.strip(), lineno,
                               "[Pose] header", source)
            header_line = lineno
            try:
                columns = tuple(_token(c, "pose column %d" % (i + 1)) for i, c in enumerate(tokens[2:]))
            except CsrError as exc:
                raise exc.located(lineno, source) from None
            continue
        if columns is None:
            raise CsrError("a pose before the '/Name, Type, ...' header line", lineno, "[Pose] header", source)
        if len(tokens) < 2:
            raise CsrError("a pose line needs a name, a type and values", lineno, "pose", source)
        name, kind, values = tokens[0], tokens[1], tokens[2:]
        what = "pose %s" % name
        if len(values) != len(columns):
            raise CsrError("%d values, but the /Name header (line %d) has %d columns (%s)"
                           % (len(values), header_line, len(columns), ", ".join(columns)), lineno, what, source)
        try:
            if kind in POSE_COLUMNS:
                numbers = []
                for col, v in zip(columns, values):
                    numbers.append(_number(v, "%s %s" % (what, col)))
                    decimals = max(decimals, _decimals(v))
                poses.append(Pose(name, kind, tuple(numbers), line=lineno))
            else:
                poses.append(Pose(name, kind, raw=tuple(values), line=lineno))
        except CsrError as exc:
            raise exc.located(lineno, source) from None
    if columns is None:
        raise CsrError("no '/Name, Type, ...' header line", section_line, "[Pose] header", source)
    return columns, poses, min(decimals, 15) if decimals >= 0 else 3


def _parse_command(lineno: int, text: str, source: str) -> Command:
    tokens = _split(text)
    op = tokens[0]
    try:
        if op == "TOOL":
            if len(tokens) != 2:
                raise CsrError("needs 2 fields (TOOL, n:NAME), got %d" % len(tokens), field="TOOL")
            return Tool(tokens[1], line=lineno)
        if op in MOVE_OPCODES:
            layout = {"MOVEP": "MOVEP, point, speed, unit, N/W, smooth",
                      "MOVEL": "MOVEL, point, speed, unit, CL, N/W, smooth",
                      "MOVEC": "MOVEC, point, speed, unit, CL, N/W, smooth[, option]"}[op]
            counts = {"MOVEP": (6,), "MOVEL": (7,), "MOVEC": (7, 8)}[op]
            if len(tokens) not in counts:
                raise CsrError("needs %s fields (%s), got %d"
                               % (" or ".join(map(str, counts)), layout, len(tokens)), field=op)
            if op == "MOVEP":
                _, point, speed, unit, weld, smooth = tokens
                cl, option = "0", ""
            else:
                point, speed, unit, cl, weld, smooth = tokens[1:7]
                option = tokens[7] if len(tokens) == 8 else ""
            return Move(op, point, _number(speed, op + " speed"), unit, weld,
                        _integer(smooth, op + " smooth level"), _integer(cl, op + " CL no."), option, line=lineno)
        return RawCommand(text, line=lineno)
    except CsrError as exc:
        raise exc.located(lineno, source) from None


def decode_csr(data: bytes, source: str = "") -> Tuple[str, str]:
    """(text, encoding): UTF-8 (ASCII) first, then cp932 (Shift-JIS, DTPS's home); CsrError else."""
    for encoding in ("utf-8", "cp932"):
        try:
            text = data.decode(encoding)
        except UnicodeDecodeError:
            continue
        return text, ("ascii" if text.isascii() else encoding)
    raise CsrError("neither UTF-8 nor Shift-JIS (cp932) text", 0, "file", source)


def read_program(path: str) -> CsrProgram:
    """Read a .csr file (UTF-8 / ASCII, else Shift-JIS); CsrError (naming the file) on unreadable
    or malformed content."""
    try:
        with open(path, "rb") as f:
            data = f.read()
    except OSError as exc:
        raise CsrError("cannot read: %s" % (exc.strerror or exc), 0, "file", path) from None
    text, _ = decode_csr(data, path)
    return parse_program(text, path)


# ============================================================================ joint conventions

@dataclass(frozen=True)
class JointConvention:
    """URDF joints (radians, joint_1..joint_6) <-> AJ columns RT UA FA RW BW TW (degrees)::

        x_i   = degrees(q_i)                    for every axis, except
        x_FA  = degrees(q_3 + coupling * q_2)   when fa_reference == "horizontal"
        AJ_i  = sign_i * x_i + offset_i

    ``fa_reference`` "ua": FA is the forearm angle relative to the upper arm (the URDF's joint_3);
    "horizontal": the forearm angle relative to the horizontal (as ABB / Fanuc J3 count it).
    ``coupling`` is +1 when joint_2 and joint_3 turn about the same direction (our URDF), -1 when
    opposite (:meth:`coupling_of` reads it from a Kinematics). ``signs`` are +1 / -1,
    ``offsets`` degrees. The default (ua, +1, 0) is the identity: both conventions agree at the
    zero pose (upper arm vertical, forearm horizontal), and the thesis gives no other evidence."""

    fa_reference: str = "ua"
    signs: Tuple[int, ...] = (1, 1, 1, 1, 1, 1)
    offsets: Tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    coupling: int = 1

    def __post_init__(self) -> None:
        if self.fa_reference not in ("ua", "horizontal"):
            raise CsrError("%r is not 'ua' or 'horizontal'" % (self.fa_reference,), field="FA reference")
        signs = tuple(self.signs)
        if len(signs) != 6 or any(s not in (1, -1) or isinstance(s, bool) for s in signs):
            raise CsrError("signs must be six values +1 / -1, got %r" % (self.signs,), field="signs")
        object.__setattr__(self, "signs", signs)
        if len(tuple(self.offsets)) != 6:
            raise CsrError("offsets must be six numbers (degrees), got %r" % (self.offsets,), field="offsets")
        object.__setattr__(self, "offsets", tuple(_number(v, "offset %s" % axis)
                                                  for axis, v in zip(JOINT_COLUMNS, self.offsets)))
        if self.coupling not in (1, -1):
            raise CsrError("coupling must be +1 or -1, got %r" % (self.coupling,), field="coupling")

    @classmethod
    def from_options(cls, fa_reference: str = "ua", flip: Union[str, Sequence[str]] = (),
                     offsets: Union[Mapping[str, float], Sequence[str]] = (), coupling: int = 1
                     ) -> "JointConvention":
        """From option values: ``flip`` "UA,BW" or ["UA", "BW"]; ``offsets`` {"BW": -90} or
        ["BW=-90"]. Axis names are RT UA FA RW BW TW (case-insensitive)."""
        names = flip.split(",") if isinstance(flip, str) else list(flip)
        signs = [1] * 6
        for name in names:
            if not name.strip():
                continue
            signs[_axis_index(name, "flip")] = -1
        values = [0.0] * 6
        items = offsets.items() if isinstance(offsets, Mapping) else [_split_offset(s) for s in offsets]
        for axis, value in items:
            values[_axis_index(axis, "offset")] = _number(value, "offset %s" % axis)
        return cls(fa_reference, tuple(signs), tuple(values), coupling)

    @staticmethod
    def coupling_of(kinematics: Any) -> int:
        """+1 if the chain's 2nd and 3rd joints turn about the same direction at the zero pose,
        -1 if opposite; CsrError if they are not parallel (no 'horizontal' FA then)."""
        import numpy as np
        t = np.eye(4)
        axes = []
        for j in kinematics.chain_joints:
            t = t @ j.origin()
            if j.movable:
                axes.append(t[:3, :3] @ np.array(j.axis))
        if len(axes) < 3:
            raise CsrError("the chain has fewer than 3 joints", field="FA reference")
        dot = float(axes[1] @ axes[2])
        if abs(abs(dot) - 1.0) > 1e-6:
            raise CsrError("joint 2 and joint 3 are not parallel: the FA reference is undefined", field="FA reference")
        return 1 if dot > 0 else -1

    def to_aj(self, q: Sequence[float]) -> Tuple[float, ...]:
        x = [math.degrees(v) for v in q[:6]]
        if self.fa_reference == "horizontal":
            x[2] = math.degrees(q[2] + self.coupling * q[1])
        return tuple(s * v + o for s, v, o in zip(self.signs, x, self.offsets))

    def from_aj(self, aj: Sequence[float]) -> Tuple[float, ...]:
        x = [(v - o) * s for v, s, o in zip(aj[:6], self.signs, self.offsets)]
        q = [math.radians(v) for v in x]
        if self.fa_reference == "horizontal":
            q[2] = math.radians(x[2]) - self.coupling * q[1]
        return tuple(q)

    def describe(self) -> str:
        flips = [a for a, s in zip(JOINT_COLUMNS, self.signs) if s < 0]
        offs = ["%s%+g" % (a, o) for a, o in zip(JOINT_COLUMNS, self.offsets) if o]
        return "FA relative to %s, flipped: %s, offsets: %s" % (
            "UA" if self.fa_reference == "ua" else "the horizontal", ",".join(flips) or "none",
            ",".join(offs) or "none")


def _axis_index(name: str, what: str) -> int:
    key = name.strip().upper()
    if key not in JOINT_COLUMNS:
        raise CsrError("%r is not an axis (%s)" % (name, ", ".join(JOINT_COLUMNS)), field=what)
    return JOINT_COLUMNS.index(key)


def _split_offset(text: str) -> Tuple[str, str]:
    if "=" not in text:
        raise CsrError("%r is not AXIS=DEGREES (e.g. BW=-90)" % (text,), field="offset")
    axis, value = text.split("=", 1)
    return axis, value


# ================================================================================ waypoint input

@dataclass(frozen=True)
class Waypoint:
    """One target of the program. Exactly one of ``joints`` (URDF radians, chain order) and
    ``pose`` (controller pose, mm / deg). ``move``/``speed``/``smooth`` None = the export
    default. ``source``/``line``/``label`` locate it in the input for error messages."""

    joints: Optional[Tuple[float, ...]] = None
    pose: Optional[ControllerPose] = None
    move: Optional[MoveType] = None
    speed: Optional[float] = None
    smooth: Optional[int] = None
    source: str = ""
    line: int = 0
    label: str = ""

    def error(self, reason: str) -> CsrError:
        return CsrError(reason, self.line, self.label, self.source)


class _LineDict(dict):
    line = 0


class _LineList(list):
    line = 0


def _make_loader():
    import yaml

    class Loader(yaml.SafeLoader):
        pass

    def mapping(loader, node):
        out = _LineDict(loader.construct_mapping(node, deep=True))
        out.line = node.start_mark.line + 1
        return out

    def sequence(loader, node):
        out = _LineList(loader.construct_sequence(node, deep=True))
        out.line = node.start_mark.line + 1
        return out

    Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, mapping)
    Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_SEQUENCE_TAG, sequence)
    return Loader


def _line(value: Any, default: int = 0) -> int:
    return getattr(value, "line", 0) or default


_WAYPOINT_KEYS = ("joints", "joints_deg", "pose", "move", "speed", "smooth")
_PROGRAM_KEYS = ("comment", "sub_comment1", "sub_comment2", "creator", "robot", "tool", "mechanism", "date",
                 "edit")
_DEFAULT_KEYS = ("move", "speed", "smooth")


@dataclass(frozen=True)
class WaypointFile:
    """What an input file holds: the waypoints, plus the ``program`` and ``defaults`` blocks of a
    waypoint YAML (empty for CSV and trajectories)."""

    waypoints: Tuple[Waypoint, ...]
    program: Mapping[str, Any] = field(default_factory=dict)
    defaults: Mapping[str, Any] = field(default_factory=dict)
    kind: str = "waypoints"          # waypoints | csv | trajectory
    source: str = ""


def _move_type(value: Any, what: str) -> MoveType:
    try:
        return MoveType.parse(value)
    except MotionError:
        raise CsrError("%r is not ptp, lin or circ" % (value,), field=what) from None


def _vector6(value: Any, what: str) -> Tuple[float, ...]:
    if not isinstance(value, (list, tuple)) or len(value) != 6:
        raise CsrError("needs a list of 6 numbers, got %r" % (value,), field=what)
    return tuple(_number(v, "%s[%d]" % (what, i)) for i, v in enumerate(value))


def _waypoint_from_mapping(item: Any, index: int, source: str, line: int) -> Waypoint:
    label = "waypoint %d" % index
    line = _line(item, line)
    try:
        if not isinstance(item, Mapping):
            raise CsrError("expected a mapping with joints / joints_deg / pose, got %r" % (item,))
        unknown = sorted(str(k) for k in item if k not in _WAYPOINT_KEYS)
        if unknown:
            raise CsrError("unknown key %r (allowed: %s)" % (unknown[0], ", ".join(_WAYPOINT_KEYS)))
        given = [k for k in ("joints", "joints_deg", "pose") if k in item]
        if len(given) != 1:
            raise CsrError("needs exactly one of joints (rad), joints_deg (deg), pose (mm, deg); got %s"
                           % (", ".join(given) or "none"))
        key = given[0]
        values = _vector6(item[key], key)
        joints = pose = None
        if key == "joints":
            joints = values
        elif key == "joints_deg":
            joints = tuple(math.radians(v) for v in values)
        else:
            pose = ControllerPose(*values)
        move = _move_type(item["move"], "move") if "move" in item else None
        speed = _speed(item["speed"], "m/min", "speed") if "speed" in item else None
        smooth = _integer(item["smooth"], "smooth", *SMOOTH_RANGE) if "smooth" in item else None
    except (CsrError, PoseError) as exc:
        if isinstance(exc, PoseError):
            exc = CsrError(str(exc), field="pose")
        what = "%s %s" % (label, exc.field) if exc.field else label
        raise CsrError(exc.reason, exc.line or line, what, exc.source or source) from None
    return Waypoint(joints, pose, move, speed, smooth, source, line, label)


def parse_waypoints(text: str, source: str = "", joint_names: Sequence[str] = ()) -> WaypointFile:
    """Parse waypoint YAML (a list, or a mapping with ``waypoints`` and optional ``program`` /
    ``defaults``), or a YAML dump of a JointTrajectory (``rostopic echo -n 1``; also found
    inside a DisplayTrajectory / RobotTrajectory / action goal dump), or CSV when ``source``
    ends in ``.csv``. ``joint_names``: the controller joint names (trajectory column order)."""
    if source.lower().endswith(".csv"):
        return _parse_csv(text, source)
    import yaml
    try:
        docs = [d for d in yaml.load_all(text, Loader=_make_loader()) if d is not None]
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        reason = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise CsrError("not valid YAML: %s" % reason, mark.line + 1 if mark else 0, "input", source) from None
    if not docs:
        raise CsrError("no waypoints (the file is empty)", 0, "input", source)
    data = docs[0]
    if isinstance(data, Mapping) and "waypoints" in data:
        return _parse_waypoint_mapping(data, source)
    if isinstance(data, list):
        return _parse_waypoint_list(data, source, {}, {})
    trajectory = _find_trajectory(data)
    if trajectory is not None:
        return WaypointFile(tuple(trajectory_waypoints(trajectory, joint_names or _default_joint_names(), source)),
                            kind="trajectory", source=source)
    raise CsrError("neither a waypoint file (a list, or a mapping with 'waypoints') nor a JointTrajectory "
                   "(joint_names and points)", _line(data, 1), "input", source)


def _default_joint_names() -> Tuple[str, ...]:
    from .params import DEFAULT_JOINT_NAMES
    return DEFAULT_JOINT_NAMES


def _parse_waypoint_mapping(data: Mapping[str, Any], source: str) -> WaypointFile:
    unknown = sorted(str(k) for k in data if k not in ("waypoints", "program", "defaults"))
    if unknown:
        raise CsrError("unknown key %r (allowed: waypoints, program, defaults)" % unknown[0], _line(data), "input",
                       source)
    program = data.get("program") or {}
    defaults = data.get("defaults") or {}
    for block, allowed in (("program", _PROGRAM_KEYS), ("defaults", _DEFAULT_KEYS)):
        value = data.get(block) or {}
        if not isinstance(value, Mapping):
            raise CsrError("must be a mapping", _line(data), block, source)
        bad = sorted(str(k) for k in value if k not in allowed)
        if bad:
            raise CsrError("unknown key %r (allowed: %s)" % (bad[0], ", ".join(allowed)), _line(value), block,
                           source)
    waypoints = data["waypoints"]
    if not isinstance(waypoints, list):
        raise CsrError("must be a list", _line(data), "waypoints", source)
    return _parse_waypoint_list(waypoints, source, program, defaults)


def _parse_waypoint_list(items: List[Any], source: str, program: Mapping[str, Any],
                         defaults: Mapping[str, Any]) -> WaypointFile:
    if not items:
        raise CsrError("no waypoints (the list is empty)", _line(items), "waypoints", source)
    out = [_waypoint_from_mapping(item, i + 1, source, _line(items)) for i, item in enumerate(items)]
    try:
        if "move" in defaults:
            _move_type(defaults["move"], "move")
        if "speed" in defaults:
            _speed(defaults["speed"], "m/min", "speed")
        if "smooth" in defaults:
            _integer(defaults["smooth"], "smooth", *SMOOTH_RANGE)
    except CsrError as exc:
        raise CsrError(exc.reason, _line(defaults), "defaults " + exc.field, source) from None
    return WaypointFile(tuple(out), program, dict(defaults), "waypoints", source)


def _find_trajectory(data: Any, depth: int = 0) -> Optional[Mapping[str, Any]]:
    """The first mapping with joint_names and points, searched depth first (a JointTrajectory dump,
    or one inside a DisplayTrajectory / RobotTrajectory / FollowJointTrajectory goal dump)."""
    if depth > 6:
        return None
    if isinstance(data, Mapping):
        if "joint_names" in data and "points" in data:
            return data
        children: Iterable[Any] = data.values()
    elif isinstance(data, list):
        children = data
    else:
        return None
    for child in children:
        found = _find_trajectory(child, depth + 1)
        if found is not None:
            return found
    return None


def trajectory_waypoints(trajectory: Mapping[str, Any], joint_names: Sequence[str], source: str = ""
                         ) -> List[Waypoint]:
    """Joint waypoints (PTP, default speed) from a JointTrajectory as a mapping (``joint_names``,
    ``points[].positions`` in radians); ``joint_names`` gives the chain order J1..J6."""
    names = trajectory.get("joint_names")
    line = _line(trajectory)
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise CsrError("must be a list of joint names", line, "joint_names", source)
    missing = [n for n in joint_names if n not in names]
    if missing:
        raise CsrError("misses %s (has %s)" % (", ".join(missing), ", ".join(names)), _line(names, line),
                       "joint_names", source)
    index = [names.index(n) for n in joint_names]
    points = trajectory.get("points")
    if not isinstance(points, list) or not points:
        raise CsrError("the trajectory has no points", line, "points", source)
    out = []
    for k, point in enumerate(points, 1):
        label = "point %d" % k
        pline = _line(point, _line(points, line))
        if not isinstance(point, Mapping) or not isinstance(point.get("positions"), list):
            raise CsrError("needs a positions list", pline, label, source)
        positions = point["positions"]
        if len(positions) != len(names):
            raise CsrError("%d positions for %d joint names" % (len(positions), len(names)), pline, label, source)
        try:
            q = tuple(_number(positions[i], "%s position of %s" % (label, names[i])) for i in index)
        except CsrError as exc:
            raise exc.located(pline, source) from None
        out.append(Waypoint(joints=q, source=source, line=pline, label=label))
    return out


_CSV_POSE = ("x", "y", "z", "rx", "ry", "rz")
_CSV_JOINTS = tuple("joint_%d" % i for i in range(1, 7))
_CSV_JOINTS_DEG = tuple("joint_%d_deg" % i for i in range(1, 7))
_CSV_COLUMNS = ("move", "speed", "smooth") + _CSV_POSE + _CSV_JOINTS + _CSV_JOINTS_DEG


def _parse_csv(text: str, source: str) -> WaypointFile:
    header: Optional[List[str]] = None
    header_line = 0
    items: List[Tuple[int, Dict[str, str]]] = []
    for lineno, line in enumerate(text.splitlines(), 1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        try:
            cells = next(csv.reader([line], skipinitialspace=True))
        except csv.Error as exc:
            raise CsrError("not valid CSV: %s" % exc, lineno, "input", source) from None
        cells = [c.strip() for c in cells]
        if header is None:
            header, header_line = [c.lower() for c in cells], lineno
            bad = [c for c in header if c not in _CSV_COLUMNS]
            if bad:
                raise CsrError("unknown column %r (allowed: %s)" % (bad[0], ", ".join(_CSV_COLUMNS)), lineno,
                               "CSV header", source)
            if len(set(header)) != len(header):
                raise CsrError("a column appears twice", lineno, "CSV header", source)
            continue
        if len(cells) > len(header):
            raise CsrError("%d cells, the header (line %d) has %d columns" % (len(cells), header_line, len(header)),
                           lineno, "row", source)
        items.append((lineno, {k: v for k, v in zip(header, cells) if v != ""}))
    if header is None or not items:
        raise CsrError("no waypoints (needs a header line and at least one row)", 0, "input", source)
    out = []
    for index, (lineno, row) in enumerate(items, 1):
        item: Dict[str, Any] = {}
        groups = [(cols, key) for cols, key in ((_CSV_POSE, "pose"), (_CSV_JOINTS, "joints"),
                                                 (_CSV_JOINTS_DEG, "joints_deg")) if any(c in row for c in cols)]
        if len(groups) != 1 or not all(c in row for c in groups[0][0]):
            raise CsrError("needs all six of x..rz, or joint_1..joint_6 (rad), or joint_1_deg..joint_6_deg, and "
                           "only one of them", lineno, "waypoint %d" % index, source)
        cols, key = groups[0]
        item[key] = [row[c] for c in cols]
        for k in ("move", "speed", "smooth"):
            if k in row:
                item[k] = row[k]
        out.append(_waypoint_from_mapping(item, index, source, lineno))
    return WaypointFile(tuple(out), kind="csv", source=source)


def load_waypoints(path: str, joint_names: Sequence[str] = ()) -> WaypointFile:
    """:func:`parse_waypoints` on a file (``-`` = standard input)."""
    if path == "-":
        return parse_waypoints(sys.stdin.read(), "<stdin>", joint_names)
    try:
        with open(path, "rb") as f:
            data = f.read()
    except OSError as exc:
        raise CsrError("cannot read: %s" % (exc.strerror or exc), 0, "input", path) from None
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise CsrError("not UTF-8 text (byte %d)" % exc.start, 0, "input", path) from None
    return parse_waypoints(text, path, joint_names)


def _check_circles(waypoints: Sequence[Waypoint], default_move: MoveType) -> None:
    kinds = [w.move or default_move for w in waypoints]
    i = 0
    while i < len(kinds):
        if kinds[i] is MoveType.CIRC:
            j = i
            while j < len(kinds) and kinds[j] is MoveType.CIRC:
                j += 1
            if j - i < 3:
                raise waypoints[i].error("a circle needs at least 3 consecutive circ waypoints, this run has %d"
                                         % (j - i))
            i = j
        else:
            i += 1


# ======================================================================================= export

_OPCODES = {MoveType.PTP: "MOVEP", MoveType.LIN: "MOVEL", MoveType.CIRC: "MOVEC"}


@dataclass(frozen=True)
class ExportSettings:
    """How waypoints become a program. ``cartesian``: "aj" writes Cartesian waypoints as joint
    angles from our IK (default: DTPS and the Cenit downloader write AJ); "au" writes them as AU
    rows with U, V, W = Rx, Ry, Rz (the controller's angle convention is unverified).
    ``workspace`` is the driver's box (DriverParams.workspace)."""

    description: Description = field(default_factory=Description)
    default_move: MoveType = MoveType.PTP
    default_speed: float = 10.0
    default_smooth: int = -1
    weld: str = "N"
    cartesian: str = "aj"
    convention: JointConvention = field(default_factory=JointConvention)
    workspace: Workspace = field(default_factory=Workspace)
    decimals: int = 3
    variables: Optional[Tuple[Variable, ...]] = field(default_factory=default_variables)

    def __post_init__(self) -> None:
        if self.cartesian not in ("aj", "au"):
            raise CsrError("%r is not aj or au" % (self.cartesian,), field="cartesian")
        object.__setattr__(self, "default_move", _move_type(self.default_move, "default move"))
        _speed(self.default_speed, "m/min", "default speed")
        _integer(self.default_smooth, "default smooth", *SMOOTH_RANGE)
        if self.weld not in WELD_FLAGS:
            raise CsrError("%r is not N or W" % (self.weld,), field="weld")
        _integer(self.decimals, "decimals", 0, 15)


def _home_seed(kin: Any) -> Tuple[float, ...]:
    home = kin.named_states.get("home")
    return tuple(home) if home is not None else kin.clamp((0.0,) * kin.dof)


def export_program(waypoints: Sequence[Waypoint], settings: ExportSettings, kinematics: Any,
                   seed: Optional[Sequence[float]] = None) -> CsrProgram:
    """The program for ``waypoints``: a TOOL line, then one pose (P001, P002, ...) and one MOVE
    per waypoint. Joint waypoints must lie inside the joint limits and put the TCP inside the
    workspace box; Cartesian ones must lie inside the box and have an IK solution (seeded by the
    previous waypoint's joints; the first by ``seed``, default the SRDF's home). Raises
    CsrError for structural problems (no waypoints, a short circle run) and CsrConversionError
    listing every refused waypoint."""
    if not waypoints:
        raise CsrError("no waypoints", field="input")
    _check_circles(waypoints, settings.default_move)
    kin = kinematics
    q_prev = tuple(seed) if seed is not None else _home_seed(kin)
    problems: List[CsrError] = []
    poses: List[Pose] = []
    commands: List[Command] = [Tool(settings.description.tool)]
    for index, wp in enumerate(waypoints, 1):
        try:
            q, tcp = _solve(wp, kin, settings.workspace, q_prev)
        except VrDriverError as exc:
            problems.append(wp.error(str(exc)))
            continue
        q_prev = q
        name = "P%03d" % index
        if wp.pose is not None and settings.cartesian == "au":
            poses.append(Pose(name, "AU", wp.pose.as_tuple()))
        else:
            poses.append(Pose(name, "AJ", settings.convention.to_aj(q)))
        move = wp.move or settings.default_move
        commands.append(Move(_OPCODES[move], name,
                             settings.default_speed if wp.speed is None else wp.speed, "m/min", settings.weld,
                             settings.default_smooth if wp.smooth is None else wp.smooth))
    if problems:
        raise CsrConversionError(problems)
    columns = (CARTESIAN_COLUMNS if all(p.kind == "AU" for p in poses) else JOINT_COLUMNS)
    return CsrProgram(settings.description, tuple(poses), tuple(commands), settings.variables, columns,
                      settings.decimals)


def _solve(wp: Waypoint, kin: Any, workspace: Workspace, seed: Sequence[float]
           ) -> Tuple[Tuple[float, ...], ControllerPose]:
    """(joints, TCP pose) of a waypoint, or a VrDriverError saying why it is refused."""
    if wp.joints is not None:
        try:
            q = kin.check_limits(wp.joints)
        except KinematicsError as exc:
            raise CsrError(str(exc)) from None
        tcp = kin.fk_pose(q)
        try:
            workspace.check(tcp)
        except PoseError as exc:
            raise CsrError("the TCP at these joints %s is outside the workspace box: %s"
                           % (_fmt_pose(tcp), exc)) from None
        return q, tcp
    pose = wp.pose
    try:
        workspace.check(pose)
    except PoseError as exc:
        raise CsrError("outside the workspace box: %s" % exc) from None
    try:
        q = kin.ik_pose(pose, seed=seed)
    except KinematicsError as exc:
        raise CsrError("no IK solution for %s: %s" % (_fmt_pose(pose), exc)) from None
    return q, pose


def _fmt_pose(pose: ControllerPose) -> str:
    v = [_fmt(x, 1) for x in pose.as_tuple()]
    return "(%s, %s, %s mm, %s, %s, %s deg)" % tuple(v)


def check_program(program: CsrProgram, kinematics: Any, convention: JointConvention,
                  workspace: Workspace, source: str = "") -> Tuple[List[str], List[CsrError]]:
    """Check every pose of a program read back against our safety envelope: AJ rows (through
    ``convention``) inside the joint limits (within half the printed precision) with the TCP in
    the workspace box; AU rows inside the box and reachable (IK seeded pose to pose). Returns
    (one summary line per pose, problems)."""
    kin = kinematics
    tol = math.radians(0.5 * 10.0 ** -program.decimals) + 1e-12
    rows: List[str] = []
    problems: List[CsrError] = []
    q_prev = _home_seed(kin)
    for p in program.poses:
        where = "pose " + p.name
        values = " ".join("%9.3f" % v for v in p.values[:6])
        if p.kind == "AJ":
            q = convention.from_aj(p.values)
            bad = kin.limit_violations(q, tol)
            tcp = kin.fk_pose(kin.clamp(q))
            note = "ok"
            if bad:
                note = "outside the joint limits: " + "; ".join(bad)
            elif not workspace.contains(tcp):
                try:
                    workspace.check(tcp)
                except PoseError as exc:
                    note = "TCP outside the workspace box: %s" % exc
            else:
                q_prev = q
            rows.append("%-6s AJ %s | TCP %s | %s" % (p.name, values, _fmt_pose(tcp), note))
        elif p.kind == "AU":
            pose = ControllerPose(*p.values[:6])
            note = "ok"
            try:
                workspace.check(pose)
                q_prev = kin.ik_pose(pose, seed=q_prev)
            except PoseError as exc:
                note = "outside the workspace box: %s" % exc
            except KinematicsError as exc:
                note = "unreachable: %s" % exc
            rows.append("%-6s AU %s | %s" % (p.name, values, note))
        else:
            note = "ok"
            rows.append("%-6s %s %s | not checked (type kept verbatim)" % (p.name, p.kind, ", ".join(p.raw)))
        if note != "ok":
            problems.append(CsrError(note, p.line, where, source))
    return rows, problems


def summarize(program: CsrProgram, rows: Sequence[str] = (), source: str = "") -> str:
    """A human-readable summary: description, counts, then ``rows`` (from check_program)."""
    d = program.description
    kinds: Dict[str, int] = {}
    for p in program.poses:
        kinds[p.kind] = kinds.get(p.kind, 0) + 1
    ops: Dict[str, int] = {}
    for c in program.commands:
        op = c.opcode if isinstance(c, Move) else "TOOL" if isinstance(c, Tool) else "verbatim"
        ops[op] = ops.get(op, 0) + 1
    lines = [
        "%sprogram %r: robot %s, tool %s, creator %r, created %s, updated %s, edit %d"
        % (source + ": " if source else "", d.comment, d.robot, d.tool, d.creator, d.created, d.updated, d.edit),
        "poses: %d (%s); commands: %d (%s); variables: %s; extra sections: %s"
        % (len(program.poses), ", ".join("%s %d" % kv for kv in sorted(kinds.items())) or "none",
           len(program.commands), ", ".join("%s %d" % kv for kv in sorted(ops.items())) or "none",
           "none" if program.variables is None else len(program.variables),
           ", ".join(s.name for s in program.extra_sections) or "none"),
    ]
    moves = {m.point: m for m in program.moves()}
    for row in rows:
        name = row.split()[0]
        m = moves.get(name)
        lines.append("  " + row + ("" if m is None else " | %s %.2f %s" % (m.opcode, m.speed, m.unit)))
    return "\n".join(lines)


# ============================================================================== the command line

_EPILOG = """\
input formats:
  waypoint YAML  a list of waypoints, or {program: {...}, defaults: {...}, waypoints: [...]};
                 a waypoint has exactly one of joints: [6 rad], joints_deg: [6 deg],
                 pose: [X, Y, Z mm, Rx, Ry, Rz deg], and optionally move: ptp|lin|circ,
                 speed: m/min, smooth: -1..10. program keys: comment, sub_comment1,
                 sub_comment2, creator, robot, tool, mechanism, date, edit.
  waypoint CSV   (*.csv) header line with columns move, speed, smooth, and x,y,z,rx,ry,rz or
                 joint_1..joint_6 (rad) or joint_1_deg..joint_6_deg (deg); '#' lines are skipped
  trajectory     a YAML dump of a trajectory_msgs/JointTrajectory (rostopic echo -n 1 /topic >
                 file.yaml), or --from-topic /topic; every point becomes a MOVEP at --speed

joint-angle convention (VERIFY ON THE REAL CONTROLLER before running an exported program):
  AJ_i = sign_i * degrees(q_i) + offset_i for the URDF joints q_1..q_6 (joint_1..joint_6);
  with --fa-reference horizontal, FA uses degrees(q_3 + q_2) (the forearm angle to the
  horizontal) before its sign and offset.
  The defaults (FA relative to UA, no flips, no offsets) are the identity on our URDF and are
  NOT confirmed for the VR-006L. Check on the pendant: jog each axis + from the zero pose and
  compare with the URDF direction (examples/axis_check.yaml); see which FA reference holds.
  Cartesian AU rows (--cartesian au) take U, V, W = Rx, Ry, Rz: also unverified.
  See vr_driver/doc/csr.md.

safety: every Cartesian waypoint must lie inside the driver's workspace box and be reachable;
  every joint waypoint inside the joint limits with its TCP inside the box (--driver-config
  gives the box, the TCP offset and the joint names of a deployed driver).

exit codes: 0 ok, 1 conversion failed (a waypoint or pose refused; one line each on stderr),
  2 usage or input error.
"""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:          # one line, exit 2
        self.exit(2, "%s: error: %s (see --help)\n" % (self.prog, message))


def _build_parser(prog: str) -> argparse.ArgumentParser:
    p = _Parser(prog=prog, formatter_class=argparse.RawDescriptionHelpFormatter, epilog=_EPILOG,
                description="Export waypoints or a JointTrajectory to a Panasonic DTPS .csr program, or read a "
                            ".csr back (summary, check, re-export).")
    src = p.add_argument_group("input (exactly one)")
    src.add_argument("input", nargs="?", help="waypoint YAML / CSV or JointTrajectory YAML ('-' = stdin)")
    src.add_argument("--from-topic", metavar="TOPIC", help="wait for one trajectory_msgs/JointTrajectory on TOPIC")
    src.add_argument("--from-csr", metavar="FILE", help="read a .csr: print a summary and check it, or re-export "
                                                        "it with -o")
    src.add_argument("--timeout", type=float, default=10.0, metavar="S",
                     help="--from-topic: seconds to wait (default 10)")
    out = p.add_argument_group("output")
    out.add_argument("-o", "--output", metavar="FILE", help="the .csr to write (default: standard output; "
                                                            "with --from-csr: write nothing)")
    out.add_argument("--newline", choices=sorted(NEWLINES), default="crlf",
                     help="line ends (default crlf, as Windows tools such as DTPS expect)")
    out.add_argument("--decimals", type=int, default=None, metavar="N",
                     help="digits after the point of pose values (default 3; --from-csr: as read)")
    out.add_argument("--cartesian", choices=("aj", "au"), default="aj",
                     help="write Cartesian waypoints as AJ joint angles from our IK (default) or as AU rows")
    desc = p.add_argument_group("program description (override the YAML's program block)")
    desc.add_argument("--comment", help="program comment, <= %d chars (default ros_export)" % COMMENT_MAX)
    desc.add_argument("--creator", help="creator, <= %d chars (default ROS)" % CREATOR_MAX)
    desc.add_argument("--robot", help="robot model string (default VR-006L; the thesis' DTPS needed TA1400(G3))")
    desc.add_argument("--tool", help="tool n:NAME (default 1:TOOL01)")
    desc.add_argument("--mechanism", help="mechanism n(hhhh) (default 1(0001))")
    desc.add_argument("--date", help="create/update time YYYY-MM-DDThh:mm:ss (default now)")
    moves = p.add_argument_group("move defaults (for waypoints that do not set their own)")
    moves.add_argument("--move", choices=("ptp", "lin", "circ"), help="move type (default ptp = MOVEP)")
    moves.add_argument("--speed", type=float, help="speed in m/min (default 10)")
    moves.add_argument("--smooth", type=int, help="smooth level, -1 = controller default (default -1)")
    conv = p.add_argument_group("joint-angle convention (verify on the controller)")
    conv.add_argument("--fa-reference", choices=("ua", "horizontal"), default="ua",
                      help="FA measured relative to the upper arm (default) or to the horizontal")
    conv.add_argument("--flip", default="", metavar="AXES", help="axes whose sign is inverted, e.g. UA,BW")
    conv.add_argument("--offset", action="append", default=[], metavar="AXIS=DEG",
                      help="add DEG to an axis after the flip, e.g. BW=-90 (repeatable)")
    p.add_argument("--driver-config", metavar="YAML",
                   help="the driver's parameter file (e.g. vr_driver/config/vr_driver.yaml): workspace box, "
                        "TCP offset, joint names (default: the built-in defaults)")
    return p


def _load_params(path: Optional[str]):
    from .params import DriverParams, ParamError
    if not path:
        return DriverParams()
    import yaml
    try:
        with open(path) as f:
            data = yaml.safe_load(f) or {}
    except OSError as exc:
        raise CsrError("cannot read: %s" % (exc.strerror or exc), 0, "--driver-config", path) from None
    except yaml.YAMLError as exc:
        raise CsrError("not valid YAML: %s" % exc, 0, "--driver-config", path) from None
    if not isinstance(data, dict):
        raise CsrError("must be a mapping of parameters", 0, "--driver-config", path)
    try:
        return DriverParams.from_dict(data)
    except ParamError as exc:
        raise CsrError(str(exc), 0, "--driver-config", path) from None


_KIN_CACHE: Dict[Tuple[float, ...], Any] = {}


def _kinematics(params: Any) -> Any:
    """Kinematics.default() with the driver's TCP offset (cached per process)."""
    key = tuple(params.tcp_offset)
    if key not in _KIN_CACHE:
        from .kinematics import Kinematics
        kin = Kinematics.default()
        if any(key):
            kin.conventions = kin.conventions.with_tcp(key)
        _KIN_CACHE[key] = kin
    return _KIN_CACHE[key]


def _description(args: argparse.Namespace, program: Mapping[str, Any], source: str) -> Description:
    """The description from the options, else the input's program block, else the defaults; an
    error names the option, or the program block's line."""
    options = {"Robot": "robot", "Comment": "comment", "Mechanism": "mechanism", "Tool": "tool",
               "Creator": "creator", "date": "date", "Create": "date", "Update": "date"}

    def pick(name: str, default: Any) -> Any:
        value = getattr(args, name, None)
        return value if value is not None else program.get(name, default)

    try:
        date = pick("date", None)
        return Description(robot=str(pick("robot", "VR-006L")), comment=str(pick("comment", "ros_export")),
                           sub_comment1=str(program.get("sub_comment1", "")),
                           sub_comment2=str(program.get("sub_comment2", "")),
                           mechanism=str(pick("mechanism", "1(0001)")), tool=str(pick("tool", "1:TOOL01")),
                           creator=str(pick("creator", "ROS")),
                           created=_date(date, "date") if date is not None else None,
                           edit=_integer(program.get("edit", 0), "edit", 0, 2))
    except CsrError as exc:
        option = options.get(exc.field, "")
        if option and getattr(args, option, None) is not None:
            raise CsrError(exc.reason, field="--" + option) from None
        raise CsrError(exc.reason, _line(program), "program " + exc.field, source) from None


def _from_topic(topic: str, timeout: float) -> Dict[str, Any]:
    """One JointTrajectory from ``topic`` as a plain mapping (rospy imported only here)."""
    try:
        import rosgraph
        import rospy
        from trajectory_msgs.msg import JointTrajectory
    except ImportError as exc:
        raise CsrError("needs ROS (rospy, trajectory_msgs): %s" % exc, field="--from-topic") from None
    if not rosgraph.is_master_online():
        raise CsrError("no ROS master at %s" % rosgraph.get_master_uri(), field="--from-topic")
    rospy.init_node("csr_export", anonymous=True, disable_signals=True)
    try:
        msg = rospy.wait_for_message(topic, JointTrajectory, timeout=timeout)
    except rospy.ROSException:
        raise CsrError("no trajectory_msgs/JointTrajectory within %g s" % timeout, field=topic) from None
    return {"joint_names": list(msg.joint_names),
            "points": [{"positions": list(pt.positions)} for pt in msg.points]}


def _output(data: bytes, path: Optional[str]) -> None:
    if not path or path == "-":
        sys.stdout.flush()
        sys.stdout.buffer.write(data)
        sys.stdout.buffer.flush()
        return
    try:
        _atomic_write(data, path)
    except OSError as exc:
        raise CsrError("cannot write: %s" % (exc.strerror or exc), 0, "output", path) from None


def _run_export(args: argparse.Namespace, prog: str) -> int:
    params = _load_params(args.driver_config)
    joint_names = params.controller_joint_names
    if args.from_topic:
        if not (math.isfinite(args.timeout) and args.timeout > 0):
            raise CsrError("must be a positive number of seconds, got %g" % args.timeout, field="--timeout")
        trajectory = _from_topic(args.from_topic, args.timeout)
        wfile = WaypointFile(tuple(trajectory_waypoints(trajectory, joint_names, args.from_topic)),
                             kind="trajectory", source=args.from_topic)
    else:
        wfile = load_waypoints(args.input, joint_names)
    defaults = wfile.defaults
    kin = _kinematics(params)
    coupling = JointConvention.coupling_of(kin) if args.fa_reference == "horizontal" else 1
    convention = JointConvention.from_options(args.fa_reference, args.flip, args.offset, coupling)
    try:
        settings = ExportSettings(
            description=_description(args, wfile.program, wfile.source),
            default_move=_move_type(args.move if args.move is not None else defaults.get("move", "ptp"), "move"),
            default_speed=args.speed if args.speed is not None else defaults.get("speed", 10.0),
            default_smooth=args.smooth if args.smooth is not None else defaults.get("smooth", -1),
            cartesian=args.cartesian, convention=convention, workspace=params.workspace,
            decimals=3 if args.decimals is None else args.decimals)
    except CsrError as exc:
        raise exc.located(field="option") from None
    program = export_program(wfile.waypoints, settings, kin)
    _output(program_bytes(program, NEWLINES[args.newline]), args.output)
    if args.output and args.output != "-":
        print("%s: wrote %s: %d poses, %d commands (%s)" % (prog, args.output, len(program.poses),
                                                           len(program.commands), convention.describe()),
              file=sys.stderr)
    return 0


def _run_from_csr(args: argparse.Namespace, prog: str) -> int:
    path = args.from_csr
    try:
        with open(path, "rb") as f:
            text, encoding = decode_csr(f.read(), path)
    except OSError as exc:
        raise CsrError("cannot read: %s" % (exc.strerror or exc), 0, "file", path) from None
    program = parse_program(text, path)
    if args.decimals is not None:
        program = replace(program, decimals=_integer(args.decimals, "--decimals", 0, 15))
    params = _load_params(args.driver_config)
    kin = _kinematics(params)
    coupling = JointConvention.coupling_of(kin) if args.fa_reference == "horizontal" else 1
    convention = JointConvention.from_options(args.fa_reference, args.flip, args.offset, coupling)
    rows, problems = check_program(program, kin, convention, params.workspace, args.from_csr)
    if args.output:
        if problems:
            for problem in problems:
                print("%s: refused: %s" % (prog, problem), file=sys.stderr)
            return 1
        _output(program_bytes(program, NEWLINES[args.newline], encoding), args.output)
        return 0
    print(summarize(program, rows, args.from_csr))
    print("check (%s): %s" % (convention.describe(),
                              "all %d poses inside the limits and the workspace box" % len(program.poses)
                              if not problems else "%d pose(s) refused" % len(problems)))
    for problem in problems:
        print("%s: refused: %s" % (prog, problem), file=sys.stderr)
    return 1 if problems else 0


def main(argv: Optional[Sequence[str]] = None, prog: str = "csr_export") -> int:
    """The command line (see --help). Returns the exit code: 0 ok, 1 conversion failed, 2 usage or
    input error; expected errors print one line each on stderr, never a traceback."""
    if argv is None:   # roslaunch appends __name:= / __log:= remappings
        argv = [a for a in sys.argv[1:] if not (a.startswith("__") and ":=" in a)]
    parser = _build_parser(prog)
    try:
        args = parser.parse_args(list(argv))
    except SystemExit as exc:
        return 0 if not exc.code else 2
    sources = [s for s in (args.input, args.from_topic, args.from_csr) if s]
    if len(sources) != 1:
        print("%s: error: give exactly one input: a file, --from-topic TOPIC or --from-csr FILE (see --help)"
              % prog, file=sys.stderr)
        return 2
    try:
        if args.from_csr:
            return _run_from_csr(args, prog)
        return _run_export(args, prog)
    except CsrConversionError as exc:
        for problem in exc.problems:
            print("%s: refused: %s" % (prog, problem), file=sys.stderr)
        return 1
    except VrDriverError as exc:
        print("%s: error: %s" % (prog, exc), file=sys.stderr)
        return 2
    except OSError as exc:
        print("%s: error: %s: %s" % (prog, getattr(exc, "filename", "") or "output", exc.strerror or exc),
              file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("%s: interrupted" % prog, file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main(prog="python3 -m vr_driver.csr"))
