"""``rosrun vr_driver calibrate``: the kinematic calibration at the robot, one command.

- ``propose`` / ``fit``: panasonic_vr006l_support.kinematic_calibration (the poses to measure; the
  least-squares fit of pairs, ``--write`` / ``--xacro``).
- ``program OUT.csr``: the proposed poses as a ``.csr`` program in joint form (AJ, one MOVEP each), to
  load into the controller instead of typing the joints in.
- ``record PROGRAM.csr -o PAIRS.yaml``: while the arm visits the program's taught points (from the
  pendant, or the program played step by step), the controller's reported pose (the driver's
  ``tool_pose``) at each rest is recorded against the point's joints
  (:mod:`vr_driver.csr.calibration`); when every point has its pose the pairs are written for
  ``fit`` and the command exits 0. Interrupted (Ctrl-C, ``--timeout``) it writes nothing and names the
  points still missing, unless ``--partial``.

Only ``record`` needs a ROS master (rospy is imported there).
"""
from __future__ import annotations

import argparse
import math
import sys
import threading
from typing import Any, List, Optional, Sequence, Tuple

from ..csr.calibration import (REST_HOLD, REST_STILL_DEG, REST_STILL_MM, PairRecorder, RestDetector,
                               model_errors, taught_points)
from ..csr.cli import load_params, add_convention_arguments, convention_from
from ..csr.export import ExportSettings, export_program, kinematics_for
from ..csr.model import Description
from ..csr.parser import read_program
from ..csr.waypoints import Waypoint
from ..csr.writer import program_bytes, write_file
from ..errors import CsrError, VrDriverError
from ..poses import ControllerPose, Workspace

PROG = "calibrate"
#: the box `program` checks by default: the arm's whole reach (propose_poses keeps the flange 0.3 m
#: above the floor and every joint 10 deg inside its limits; the cell is the operator's to check)
REACH = Workspace(x=(-2000.0, 2000.0), y=(-2000.0, 2000.0), z=(-2000.0, 2000.0))


#: the clearance [m] between the arm's own links that proposed poses keep (the collision geometry is
#: the URDF's primitives, the real arm's housings are not modelled more closely)
SELF_PADDING = 0.01


def _support_main(argv: Sequence[str]) -> int:
    from panasonic_vr006l_support import kinematic_calibration as kc
    return kc.main(list(argv))


def proposed_poses(n: Optional[int] = None, seed: int = 0) -> Tuple[List[Tuple[float, ...]], str]:
    """``propose_poses`` whose poses also keep the arm clear of itself (the URDF's collision geometry,
    the SRDF's pairs, SELF_PADDING): the pendant checks no collision model. Returns the poses and a
    note saying what was checked (without the planning libraries: not the collision geometry)."""
    from panasonic_vr006l_support import kinematic_calibration as kc
    from ..errors import MissingDependency
    from ..kinematics.collision import CollisionChecker
    try:
        checker = CollisionChecker.default(padding=SELF_PADDING)
        valid, note = (lambda q: not checker.in_collision(q)), \
            "clear of the arm's own collision geometry by %g mm" % (SELF_PADDING * 1000.0)
    except MissingDependency as exc:
        valid, note = None, "NOT checked against the arm's collision geometry (%s)" % exc
    poses = kc.propose_poses(kc.DEFAULT_POSES if n is None else n, seed=seed, valid=valid)
    return poses, note


def _propose(args: argparse.Namespace) -> int:
    from panasonic_vr006l_support import kinematic_calibration as kc
    poses, note = proposed_poses(args.n, args.seed)
    print(kc.proposal_text(poses, note))
    return 0


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="command")
    prop = sub.add_parser("propose", help="print the joint configurations to measure (deg), clear of the arm itself")
    prop.add_argument("-n", type=int, default=None, help="number of poses (default 12)")
    prop.add_argument("--seed", type=int, default=0)
    sub.add_parser("fit", help="fit the model to pairs (calibrate fit --help)", add_help=False)
    prog = sub.add_parser("program", help="write the proposed poses as a .csr program in joint form")
    prog.add_argument("output", help="the .csr file to write")
    prog.add_argument("-n", type=int, default=None, help="number of poses (default: propose's)")
    prog.add_argument("--seed", type=int, default=0)
    prog.add_argument("--speed", type=float, default=5.0, help="MOVEP speed in m/min (default 5)")
    prog.add_argument("--force", action="store_true", help="replace an existing file")
    prog.add_argument("--driver-config", metavar="YAML", help="the driver's parameter file (model, workspace)")
    prog.add_argument("--workspace-box", action="store_true",
                      help="also keep every pose inside the driver's workspace box (default: the joint limits and "
                           "the floor only, as `propose`: the poses spread over the whole reach)")
    add_convention_arguments(prog)
    rec = sub.add_parser("record", help="record the controller's pose at each taught point of a .csr program")
    rec.add_argument("program", help="the .csr program with the taught points in joint form (AJ)")
    rec.add_argument("-o", "--output", required=True, help="the pairs YAML to write (input of `fit`)")
    rec.add_argument("--hold", type=float, default=REST_HOLD,
                     help="seconds the pose must stand still to count as a rest (default %g)" % REST_HOLD)
    rec.add_argument("--still-mm", type=float, default=REST_STILL_MM,
                     help="how far [mm] the pose may wander during a rest (default %g)" % REST_STILL_MM)
    rec.add_argument("--still-deg", type=float, default=REST_STILL_DEG,
                     help="how far [deg] the orientation may wander during a rest (default %g)" % REST_STILL_DEG)
    rec.add_argument("--model", default=None, metavar="YAML",
                     help="the kinematics YAML our model uses to tell the points apart (default: the package's)")
    rec.add_argument("--topic", default="tool_pose", help="the driver's pose topic (default tool_pose)")
    rec.add_argument("--timeout", type=float, default=0.0, help="give up after this many seconds (0: never)")
    rec.add_argument("--partial", action="store_true", help="on interrupt or timeout write what was recorded")
    rec.add_argument("--driver-config", metavar="YAML", help="the driver's parameter file (for the convention's model)")
    add_convention_arguments(rec)
    return p


def _program(args: argparse.Namespace) -> int:
    params = load_params(args.driver_config)
    kin = kinematics_for(params)
    convention = convention_from(args, kin)
    poses, note = proposed_poses(args.n, args.seed)
    waypoints = [Waypoint(joints=tuple(math.radians(v) for v in q), label="pose %d" % (i + 1))
                 for i, q in enumerate(poses)]
    settings = ExportSettings(description=Description(comment="kinematic calibration", creator="vr_driver"),
                              default_speed=args.speed, convention=convention,
                              workspace=params.workspace if args.workspace_box else REACH)
    program = export_program(waypoints, settings, kin)
    try:
        write_file(program_bytes(program), args.output, args.force)
    except OSError as exc:
        raise CsrError("cannot write: %s" % (exc.strerror or exc), 0, "output", args.output) from None
    print("%s: wrote %s: %d poses (P001..P%03d) in joint form, one MOVEP each at %g m/min; convention: %s; "
          "checked: joint limits, %s, %s (not the cell: look at each pose in RViz first)"
          % (PROG, args.output, len(poses), len(poses), args.speed, convention.describe(),
             "the workspace box" if args.workspace_box else "the flange 0.3 m above the floor", note))
    print("%s: at each point the arm must stand still %g s or more for `calibrate record` (step mode)"
          % (PROG, REST_HOLD))
    return 0


class Recording:
    """The ROS-free state of ``record``: taught points, the rest detector, the pair recorder; fed one
    reported pose at a time (:meth:`pose`), it logs through ``say`` and sets :attr:`done` when every
    point has its pose."""

    def __init__(self, recorder: PairRecorder, detector: RestDetector, say=print) -> None:
        self.recorder = recorder
        self.detector = detector
        self.say = say
        self.done = threading.Event()
        self.lock = threading.Lock()

    def pose(self, stamp: float, pose: Sequence[float]) -> None:
        with self.lock:
            rest = self.detector.feed(stamp, pose)
            if rest is None:
                return
            _rec, line = self.recorder.add(rest)
            self.say(line)
            if self.recorder.complete:
                self.done.set()


def _record(args: argparse.Namespace) -> int:
    program = read_program(args.program)
    params = load_params(args.driver_config)
    convention = convention_from(args, kinematics_for(params) if args.fa_reference == "horizontal" else None)
    points = taught_points(program, convention, args.program)
    try:
        detector = RestDetector(args.hold, args.still_mm, args.still_deg)
    except ValueError as exc:
        raise CsrError(str(exc), field="option") from None
    if not (math.isfinite(args.timeout) and args.timeout >= 0.0):
        raise CsrError("--timeout must be 0 (never) or a positive number of seconds, got %g" % args.timeout,
                       field="option")
    try:
        errors = model_errors(args.model)
    except (OSError, ValueError) as exc:
        raise CsrError("the model %s: %s" % (args.model, exc), field="--model") from None
    recorder = PairRecorder(points, errors)

    import rospy
    from geometry_msgs.msg import PoseStamped

    from .support import init_node
    init_node("calibration_recorder", anonymous=True)
    recording = Recording(recorder, detector, say=rospy.loginfo)

    def on_pose(msg: Any) -> None:
        p, q = msg.pose.position, msg.pose.orientation
        try:
            pose = ControllerPose.from_ros((p.x, p.y, p.z), (q.x, q.y, q.z, q.w)).as_tuple()
        except (VrDriverError, ValueError) as exc:
            rospy.logwarn_throttle(5.0, "%s: a %s sample is not a pose: %s" % (PROG, args.topic, exc))
            return
        recording.pose(msg.header.stamp.to_sec(), pose)

    topic = rospy.resolve_name(args.topic)
    rospy.Subscriber(topic, PoseStamped, on_pose, queue_size=50)
    rospy.loginfo("%s: %d taught points of %s (%s); recording %s: hold %g s within %g mm / %g deg at each, "
                  "the controller's tool set to zero (TCP = flange)", PROG, len(points), args.program,
                  convention.describe(), topic, args.hold, args.still_mm, args.still_deg)
    end = None if not args.timeout else rospy.get_time() + args.timeout
    while not rospy.is_shutdown() and not recording.done.wait(0.2):
        if end is not None and rospy.get_time() > end:
            rospy.logwarn("%s: --timeout %g s reached", PROG, args.timeout)
            break
    with recording.lock:
        if recorder.complete or args.partial:
            try:
                recorder.write(args.output, args.program, partial=args.partial)
            except CsrError as exc:
                print("%s: error: %s" % (PROG, exc), file=sys.stderr)
                return 1
            print("%s: wrote %s: %d pairs%s" % (PROG, args.output, len(recorder.recorded),
                                               "" if recorder.complete else
                                               " (missing: %s)" % ", ".join(recorder.missing())))
            return 0
        print("%s: error: not every taught point was recorded (missing: %s): nothing written (--partial writes "
              "what there is)" % (PROG, ", ".join(recorder.missing())), file=sys.stderr)
        return 1


def main(argv: Optional[Sequence[str]] = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] == "fit":
        return _support_main(argv)
    args = _parser().parse_args(argv)
    if args.command is None:
        _parser().print_help(sys.stderr)
        return 2
    try:
        if args.command == "propose":
            return _propose(args)
        return _program(args) if args.command == "program" else _record(args)
    except (CsrError, VrDriverError) as exc:
        print("%s: error: %s" % (PROG, exc), file=sys.stderr)
        return 1
