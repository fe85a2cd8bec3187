"""Export through IK (waypoints -> program) and the check of a program read back, both against
the driver's safety envelope (workspace box, reach, joint limits)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Sequence, Tuple

from ..errors import CsrConversionError, CsrError, KinematicsError, PoseError, VrDriverError
from ..kinematics.preview import MoveType
from ..poses import ControllerPose, Workspace
from .conventions import JointConvention
from .fields import CARTESIAN_COLUMNS, JOINT_COLUMNS, SMOOTH_RANGE, WELD_FLAGS, _fmt, _integer, _speed, show
from .model import Command, CsrProgram, Description, Move, Pose, Tool, Variable, default_variables
from .waypoints import Waypoint, _move_type


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
            raise CsrError("%s is not aj or au" % show(self.cartesian), field="cartesian")
        object.__setattr__(self, "default_move", _move_type(self.default_move, "default move"))
        _speed(self.default_speed, "m/min", "default speed")
        _integer(self.default_smooth, "default smooth", *SMOOTH_RANGE)
        if self.weld not in WELD_FLAGS:
            raise CsrError("%s is not N or W" % show(self.weld), field="weld")
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


_KIN_CACHE: Dict[Tuple[Any, ...], Any] = {}


def kinematics_for(params: Any) -> Any:
    """The driver's model (DriverParams.kinematics: the package's or ``model``'s, with the driver's
    prefix and TCP offset; cached per process)."""
    tcp = tuple(params.tcp_offset)
    key = (params.prefix, getattr(params, "model", "")) + tcp
    if key not in _KIN_CACHE:
        from ..driver.core import driver_kinematics
        _KIN_CACHE[key] = driver_kinematics(params)
    return _KIN_CACHE[key]
