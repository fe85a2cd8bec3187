"""The command line of ``csr_export`` / ``python3 -m vr_driver.csr`` (see --help). The only module
of the package that imports ROS, and only in ``--from-topic`` mode."""
from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from typing import Any, Dict, Mapping, Optional, Sequence

from .. import validate
from ..errors import CsrConversionError, CsrError, VrDriverError
from .conventions import JointConvention
from .export import ExportSettings, check_program, export_program, kinematics_for, summarize
from .fields import COMMENT_MAX, CREATOR_MAX, NEWLINES, _date, _integer, clip
from .inputs import load_yaml, read_bounded
from .model import Description
from .parser import decode_csr, parse_program
from .waypoints import WaypointFile, _line, _move_type, load_waypoints, trajectory_waypoints
from .writer import program_bytes, write_file


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



def add_convention_arguments(parser: argparse.ArgumentParser) -> None:
    """The joint-angle convention options (AJ columns <-> the model's joints), shared by csr_export and
    ``calibrate``."""
    conv = parser.add_argument_group("joint-angle convention (verify on the controller)")
    conv.add_argument("--fa-reference", choices=("ua", "horizontal"), default="ua",
                      help="FA measured relative to the upper arm (default) or to the horizontal")
    conv.add_argument("--flip", default="", metavar="AXES", help="axes whose sign is inverted, e.g. UA,BW")
    conv.add_argument("--offset", action="append", default=[], metavar="AXIS=DEG",
                      help="add DEG to an axis after the flip, e.g. BW=-90 (repeatable)")


def convention_from(args: argparse.Namespace, kin: Any) -> JointConvention:
    """The :class:`JointConvention` of parsed :func:`add_convention_arguments` options (``kin``: the
    model, for the FA coupling when FA counts from the horizontal)."""
    coupling = JointConvention.coupling_of(kin) if args.fa_reference == "horizontal" else 1
    return JointConvention.from_options(args.fa_reference, args.flip, args.offset, coupling)

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
    out.add_argument("-o", "--output", metavar="FILE", help="the .csr to write, '-' = standard output (default: "
                                                            "standard output; with --from-csr: write nothing). "
                                                            "An existing file is replaced atomically and keeps "
                                                            "its mode")
    out.add_argument("--force", action="store_true",
                     help="write to an -o that is not a regular file: follow a symbolic link, write into a FIFO "
                          "or a device (refused without --force)")
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
    add_convention_arguments(p)
    p.add_argument("--driver-config", metavar="YAML",
                   help="the driver's parameter file (e.g. vr_driver/config/vr_driver.yaml): workspace box, "
                        "TCP offset, joint names (default: the built-in defaults)")
    return p


def load_params(path: Optional[str]):
    from ..params import DriverParams, ParamError
    if not path:
        return DriverParams()
    try:
        text = read_bounded(path, "--driver-config").decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise CsrError("not UTF-8 text (byte %d)" % exc.start, 0, "--driver-config", path) from None
    docs = load_yaml(text, path, "--driver-config")
    data = docs[0] if docs else {}
    if not isinstance(data, dict):
        raise CsrError("must be a mapping of parameters", 0, "--driver-config", path)
    try:
        return DriverParams.from_dict(data)
    except ParamError as exc:
        raise CsrError(clip(str(exc)), 0, "--driver-config", path) from None


def _as_text(value: Any) -> Any:
    """A scalar of the program block as text (YAML reads ``comment: 12`` as a number); lists,
    mappings and huge integers stay as they are, so the field check refuses them with a short
    quote instead of formatting them whole."""
    if isinstance(value, (str, list, tuple, dict, set)) or (isinstance(value, int) and value.bit_length() > 128):
        return value
    return str(value)


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
        return Description(robot=_as_text(pick("robot", "VR-006L")), comment=_as_text(pick("comment", "ros_export")),
                           sub_comment1=_as_text(program.get("sub_comment1", "")),
                           sub_comment2=_as_text(program.get("sub_comment2", "")),
                           mechanism=_as_text(pick("mechanism", "1(0001)")), tool=_as_text(pick("tool", "1:TOOL01")),
                           creator=_as_text(pick("creator", "ROS")),
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


def _output(data: bytes, path: Optional[str], force: bool = False) -> None:
    """The program to standard output (no -o, or -o -) or to a file through write_file."""
    if not path or path == "-":
        sys.stdout.flush()
        sys.stdout.buffer.write(data)
        sys.stdout.buffer.flush()
        return
    try:
        write_file(data, path, force)
    except OSError as exc:
        raise CsrError("cannot write: %s" % (exc.strerror or exc), 0, "output", path) from None


def _run_export(args: argparse.Namespace, prog: str) -> int:
    params = load_params(args.driver_config)
    joint_names = params.controller_joint_names
    if args.from_topic:
        validate.number(args.timeout, lambda _: CsrError("must be a positive number of seconds, got %g" % args.timeout,
                                                         field="--timeout"), 0.0, lo_open=True)
        trajectory = _from_topic(args.from_topic, args.timeout)
        wfile = WaypointFile(tuple(trajectory_waypoints(trajectory, joint_names, args.from_topic)),
                             kind="trajectory", source=args.from_topic)
    else:
        wfile = load_waypoints(args.input, joint_names)
    defaults = wfile.defaults
    kin = kinematics_for(params)
    convention = convention_from(args, kin)
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
    _output(program_bytes(program, NEWLINES[args.newline]), args.output, args.force)
    if args.output and args.output != "-":
        print("%s: wrote %s: %d poses, %d commands (%s)" % (prog, args.output, len(program.poses),
                                                           len(program.commands), convention.describe()),
              file=sys.stderr)
    return 0


def _run_from_csr(args: argparse.Namespace, prog: str) -> int:
    path = args.from_csr
    text, encoding = decode_csr(read_bounded(path, "file"), path)
    program = parse_program(text, path)
    if args.decimals is not None:
        program = replace(program, decimals=_integer(args.decimals, "--decimals", 0, 15))
    params = load_params(args.driver_config)
    kin = kinematics_for(params)
    convention = convention_from(args, kin)
    rows, problems = check_program(program, kin, convention, params.workspace, args.from_csr)
    if args.output:
        if problems:
            for problem in problems:
                print("%s: refused: %s" % (prog, problem), file=sys.stderr)
            return 1
        _output(program_bytes(program, NEWLINES[args.newline], encoding), args.output, args.force)
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

