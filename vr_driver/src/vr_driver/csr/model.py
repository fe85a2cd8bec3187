"""The .csr program model: frozen dataclasses, equal when their text is equal, each validated on
construction (CsrError names the field), and the checks across lines (:func:`check_structure`)."""
from __future__ import annotations

import datetime as _dt
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Tuple, Union

from ..errors import CsrError
from .fields import (_MECHANISM_RE, _VAR_RANGES, CIRCLE_OPTIONS, COMMENT_MAX, CREATOR_MAX, JOINT_COLUMNS,
                     MOVE_OPCODES, POSE_COLUMNS, SECTION_ORDER, SMOOTH_RANGE, SPEED_UNITS, VARIABLE_COMMENT_MAX,
                     VARIABLE_NAME_MAX, WELD_FLAGS, _date, _fmt, _integer, _number, _raw_line, _speed, _split,
                     _text, _token, _tool_text, show)


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
            raise CsrError("%s is not 'n(hhhh)' (e.g. 1(0001))" % show(self.mechanism), field="Mechanism")
        _tool_text(self.tool, "Tool")
        _text(self.creator, "Creator", CREATOR_MAX)
        _text(self.user_coordinates, "User coordinates")
        if self.user_coordinates_key not in ("User coordinates", "User coordinate"):
            raise CsrError("key %s is not 'User coordinates' or 'User coordinate'" % show(self.user_coordinates_key),
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
                raise CsrError("%s repeats a known key" % show(line), field="Description extra line")

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
            raise CsrError("%s is not one of %s" % (show(self.opcode), ", ".join(MOVE_OPCODES)), field="move opcode")
        op = self.opcode
        _token(self.point, op + " point")
        if self.unit not in SPEED_UNITS:
            raise CsrError("%s is not one of %s" % (show(self.unit), ", ".join(SPEED_UNITS)), field=op + " unit")
        object.__setattr__(self, "speed", _speed(self.speed, self.unit, op + " speed"))
        if self.weld not in WELD_FLAGS:
            raise CsrError("%s is not N (air) or W (weld)" % show(self.weld), field=op + " N/W")
        object.__setattr__(self, "smooth", _integer(self.smooth, op + " smooth level", *SMOOTH_RANGE))
        object.__setattr__(self, "cl", _integer(self.cl, op + " CL no.", 0, 999))
        if op == "MOVEP" and self.cl:
            raise CsrError("MOVEP has no CL number", field="MOVEP CL no.")
        if self.option and (op != "MOVEC" or self.option not in CIRCLE_OPTIONS):
            raise CsrError("%s is not allowed here (only MOVEC takes %s)"
                           % (show(self.option), " / ".join(CIRCLE_OPTIONS)), field=op + " option")

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
            raise CsrError("%s would be read back as a %s command, not verbatim" % (show(self.text), op),
                           field="command")

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
            raise CsrError("%s is not the name of an extra section" % show(self.name), field="section")
        object.__setattr__(self, "lines", tuple(self.lines))
        for line in self.lines:
            _raw_line(line, "[%s] line" % self.name)
        if self.after not in ("",) + SECTION_ORDER:
            raise CsrError("after=%s is not one of %s" % (show(self.after), ", ".join(SECTION_ORDER)), field="section")


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


def check_structure(program: CsrProgram, source: str = "") -> None:
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
