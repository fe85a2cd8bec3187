"""Waypoint input: waypoint YAML / CSV files and YAML dumps of a trajectory_msgs/JointTrajectory,
read into :class:`Waypoint` records that remember their input line. Inputs are bounded
(:mod:`.inputs`: file size, YAML aliases and nesting depth)."""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from typing import Any, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

from ..errors import CsrError, MotionError, PoseError
from ..kinematics.preview import MoveType
from ..poses import ControllerPose
from .fields import SMOOTH_RANGE, _integer, _number, _speed, show
from .inputs import load_yaml, read_bounded


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


def _line_mapping(loader: Any, node: Any) -> _LineDict:
    out = _LineDict(loader.construct_mapping(node, deep=True))
    out.line = node.start_mark.line + 1
    return out


def _line_sequence(loader: Any, node: Any) -> _LineList:
    out = _LineList(loader.construct_sequence(node, deep=True))
    out.line = node.start_mark.line + 1
    return out


_LINE_CONSTRUCTORS = {"tag:yaml.org,2002:map": _line_mapping, "tag:yaml.org,2002:seq": _line_sequence}


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
        raise CsrError("%s is not ptp, lin or circ" % show(value), field=what) from None


def _vector6(value: Any, what: str) -> Tuple[float, ...]:
    if not isinstance(value, (list, tuple)) or len(value) != 6:
        raise CsrError("needs a list of 6 numbers, got %s" % show(value), field=what)
    return tuple(_number(v, "%s[%d]" % (what, i)) for i, v in enumerate(value))


def _waypoint_from_mapping(item: Any, index: int, source: str, line: int) -> Waypoint:
    label = "waypoint %d" % index
    line = _line(item, line)
    try:
        if not isinstance(item, Mapping):
            raise CsrError("expected a mapping with joints / joints_deg / pose, got %s" % show(item))
        unknown = [k for k in item if k not in _WAYPOINT_KEYS]
        if unknown:
            raise CsrError("unknown key %s (allowed: %s)" % (show(unknown[0]), ", ".join(_WAYPOINT_KEYS)))
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
    docs = load_yaml(text, source, "input", _LINE_CONSTRUCTORS)
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
    from ..params import DEFAULT_JOINT_NAMES
    return DEFAULT_JOINT_NAMES


def _parse_waypoint_mapping(data: Mapping[str, Any], source: str) -> WaypointFile:
    unknown = [k for k in data if k not in ("waypoints", "program", "defaults")]
    if unknown:
        raise CsrError("unknown key %s (allowed: waypoints, program, defaults)" % show(unknown[0]), _line(data),
                       "input", source)
    program = data.get("program") or {}
    defaults = data.get("defaults") or {}
    for block, allowed in (("program", _PROGRAM_KEYS), ("defaults", _DEFAULT_KEYS)):
        value = data.get(block) or {}
        if not isinstance(value, Mapping):
            raise CsrError("must be a mapping", _line(data), block, source)
        bad = [k for k in value if k not in allowed]
        if bad:
            raise CsrError("unknown key %s (allowed: %s)" % (show(bad[0]), ", ".join(allowed)), _line(value), block,
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
                raise CsrError("unknown column %s (allowed: %s)" % (show(bad[0]), ", ".join(_CSV_COLUMNS)), lineno,
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
    """:func:`parse_waypoints` on a file (``-`` = standard input), at most MAX_INPUT_BYTES long."""
    data = read_bounded(path, "input")
    source = "<stdin>" if path == "-" else path
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise CsrError("not UTF-8 text (byte %d)" % exc.start, 0, "input", source) from None
    return parse_waypoints(text, source, joint_names)
