"""Reading a .csr program (CRLF or LF, UTF-8 / ASCII or Shift-JIS); every CsrError names the
source, the line and the field."""
from __future__ import annotations

import datetime as _dt
from typing import Any, Dict, List, Optional, Tuple

from ..errors import CsrError
from .fields import (_MECHANISM_RE, COMMENT_MAX, CREATOR_MAX, DEFAULT_DATE, MOVE_OPCODES, POSE_COLUMNS,
                     SECTION_ORDER, _decimals, _integer, _number, _split, _text, _token, _tool_text, show)
from .inputs import read_bounded
from .model import (Command, CsrProgram, Description, Move, Pose, RawCommand, RawSection, Tool, Variable,
                    check_structure)


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
                    raise CsrError("needs 6 numbers YYYY, MM, DD, hh, mm, ss, got %d field(s) %s"
                                   % (len(values), show(", ".join(values))), field=key)
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
            raise CsrError("%s is not 'n(hhhh)' (e.g. 1(0001))" % show(value), field=key)
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
            raise CsrError("text before the first [Section] line: %s" % show(stripped), lineno, "file", source)
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
    check_structure(program, source)
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
                raise CsrError("the header must read '/Name, Type, <columns>', got %s" % show(text.strip()), lineno,
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
    or malformed content, or a file longer than MAX_INPUT_BYTES."""
    text, _ = decode_csr(read_bounded(path, "file"), path)
    return parse_program(text, path)
