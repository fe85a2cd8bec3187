"""ROS node `pose_terminal`: the thin ROS edge of :mod:`vr_driver.terminal.pose_input`.

Talks to the driver node through its public API only: the ``move_to_pose`` action (preview with
preview_only, then the move; cancel = stop), the ``plan`` action (preview_only: the terminal's
``plan``) and ``joint_trajectory_action`` (runs the previewed plan), the ``stop_motion`` service, ``robot_status``,
``tool_pose``, ``joint_states`` and ``/diagnostics`` (for the driver's "why no motion" in words).
The workspace is the driver's parameter ``/<driver>/workspace`` (defaults when it is not set).

    rosrun vr_driver pose_terminal                                    interactive
    rosrun vr_driver pose_terminal --pose 1000 200 800 0 45 0 --type lin --yes
    rosrun vr_driver pose_terminal --plan home --velocity-scaling 0.5 --yes   a plan, at half speed
    rosrun vr_driver pose_terminal --ns arm1                          the driver in /arm1 (two_arms.launch)
"""
from __future__ import annotations

import os
import sys
import threading
import time
from typing import List, Optional, Tuple

from ..errors import VrDriverError
from ..terminal.sent_move import ctrl_c_raises
from ..terminal.pose_input import (EXIT_NO_DRIVER, EXIT_OK, EXIT_REFUSED, EXIT_USAGE, Backend, InputError, MoveHandle,
                         MoveProgress, MoveResult, PlanPreview, PlanRequest, PoseRequest, PreviewResult, RangeError,
                         StatusInfo, Terminal, build_arg_parser, fmt_pose, in_namespace, request_from_args)
from ..kinematics.preview import MoveType
from ..poses import ControllerPose, Workspace
from .network_check import OK, Machine, check_master, own_host_error

#: exit status after Ctrl-C while waiting for the driver (the shell's convention for SIGINT)
EXIT_INTERRUPTED = 130

#: how long a preview may take before the driver counts as not answering [s]
PREVIEW_TIMEOUT = 15.0
#: s to wait for the driver's action servers / services to be seen: a fresh node finds them over
#: its own topic connections, which on a loaded machine take more than a second or two
SERVER_WAIT = 10.0


def _pose_from_msg(msg) -> Optional[ControllerPose]:
    try:
        return ControllerPose(msg.x, msg.y, msg.z, msg.rx, msg.ry, msg.rz)
    except VrDriverError:
        return None


def _pid_alive(pid: Optional[int]) -> bool:
    if pid is None:
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    # a zombie child of someone else still answers kill(0): look at its state
    try:
        with open("/proc/%d/stat" % pid) as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return True


class _GoalHandle(MoveHandle):
    """One goal through actionlib's plain ActionClient (its per-goal callbacks carry the goal
    handle, so a quick answer cannot be missed as with SimpleActionClient's "goal handle that we're
    not tracking" race): the outcome, when it came, the last feedback."""

    def __init__(self, client, goal):
        from actionlib import CommState
        self._DONE = CommState.DONE
        self._lock = threading.Lock()
        self._feedback = None
        self._done = threading.Event()
        self._done_at: Optional[float] = None
        self._state: Optional[int] = None
        self._result = None
        self.gh = client.send_goal(goal, transition_cb=self._on_transition, feedback_cb=self._on_feedback)

    def _on_transition(self, gh) -> None:
        if gh.get_comm_state() == self._DONE:
            with self._lock:
                self._state, self._result = gh.get_goal_status(), gh.get_result()
                self._done_at = time.monotonic()
            self._done.set()

    def _on_feedback(self, _gh, fb) -> None:
        with self._lock:
            self._feedback = fb

    def wait(self, timeout: float) -> bool:
        return self._done.wait(timeout)

    def cancel(self) -> None:
        self.gh.cancel()

    def outcome(self):
        """(GoalStatus state, result message) once done, else (None, None)."""
        with self._lock:
            return self._state, self._result

    @staticmethod
    def _ended(state: Optional[int], success: bool, words: str, reached: Optional[ControllerPose]) -> MoveResult:
        from actionlib_msgs.msg import GoalStatus
        if state is None:
            return MoveResult("failed", "no result from the driver", reached)
        if state == GoalStatus.SUCCEEDED and success:
            return MoveResult("succeeded", words, reached)
        if state in (GoalStatus.PREEMPTED, GoalStatus.RECALLED):
            return MoveResult("cancelled", words or "cancelled", reached)
        return MoveResult("failed", words or "the driver ended the goal (action state %d)" % state, reached)


class RosMoveHandle(_GoalHandle):
    """A move_to_pose goal: progress and result from the action's own feedback and result."""

    def progress(self) -> Optional[MoveProgress]:
        with self._lock:
            fb = self._feedback
        if fb is None:
            return None
        return MoveProgress(fb.phase, fb.distance_to_go, fb.angle_to_go, _pose_from_msg(fb.current))

    def result(self) -> MoveResult:
        state, result = self.outcome()
        if state is None:
            return MoveResult("failed", "no result from the driver")
        reached = _pose_from_msg(result.reached) if result is not None else None
        return self._ended(state, result is not None and result.success,
                           result.reason if result is not None else "", reached)


class RosTrajectoryHandle(_GoalHandle):
    """A previewed plan running through joint_trajectory_action: progress is the TCP's distance to the
    plan's end (``pose_now()``: the last tool_pose), the result the trajectory action's."""

    def __init__(self, client, goal, target: Optional[ControllerPose], pose_now, pose_after=None):
        self.pose_after = pose_after          # (time, timeout) -> the first tool_pose received after time
        self.target = target
        self.pose_now = pose_now
        super().__init__(client, goal)

    def progress(self) -> Optional[MoveProgress]:
        pose = self.pose_now()
        with self._lock:
            phase = "moving" if self._feedback is not None else "sending"
        if pose is None or self.target is None:
            return MoveProgress(phase)
        dp, da = pose.distance_to(self.target)
        return MoveProgress(phase, dp, da, pose)

    def result(self) -> MoveResult:
        with self._lock:
            state, result, done_at = self._state, self._result, self._done_at
        # where the arm is: the first tool_pose after the result (the last one may predate the end)
        reached = self.pose_after(done_at, 1.0) if self.pose_after is not None and done_at is not None else None
        reached = reached or self.pose_now()
        return self._ended(state, result is not None and result.error_code == 0,
                           result.error_string if result is not None else "", reached)


class _Failed(MoveHandle):
    """A move that could not be started (its reason as the result)."""

    def __init__(self, reason: str) -> None:
        self.reason = reason

    def wait(self, timeout: float) -> bool:
        return True

    def progress(self) -> Optional[MoveProgress]:
        return None

    def cancel(self) -> None:
        pass

    def result(self) -> MoveResult:
        return MoveResult("failed", self.reason)


class RosBackend(Backend):
    """The driver through ROS. :meth:`connect` first."""

    def __init__(self, driver: str = "interface", ns: str = ""):
        self.driver = driver
        self.ns = ns                     # the driver's namespace ("" = the terminal's own)
        self._lock = threading.Lock()
        self._changed = threading.Condition(self._lock)   # a robot_status or tool_pose arrived
        self._updates = 0
        self._status = None
        self._status_time: Optional[float] = None
        self._tool_pose: Optional[ControllerPose] = None
        self._tool_pose_time: Optional[float] = None
        self._joints: Optional[Tuple[float, ...]] = None
        self._diag = {}
        self.client = None
        self.workspace = Workspace()
        self.workspace_source = "defaults"

    # ------------------------------------------------------------------ connection
    def connect(self, wait: float, launch_pid: Optional[int] = None, say=print) -> Optional[str]:
        """Init the node and wait for the master and the action server. None, or why not."""
        import rosgraph
        import rospy
        import actionlib
        from vr_driver.msg import MoveToPoseAction, RobotStatus
        from geometry_msgs.msg import PoseStamped
        from sensor_msgs.msg import JointState
        from diagnostic_msgs.msg import DiagnosticArray
        from vr_driver.srv import StopMotion

        end = time.monotonic() + wait
        master = rosgraph.Master("/pose_terminal")
        uri = rosgraph.get_master_uri()
        announced = False
        while True:
            try:
                master.getPid()
                break
            except Exception:  # socket errors of all kinds: the master is not (yet) up
                pass
            if not _pid_alive(launch_pid):
                return "the launch (pid %d) has ended before the ROS master came up" % launch_pid
            if time.monotonic() >= end:
                verdict, _address = check_master(uri, Machine())
                return "no ROS master at %s (waited %.0f s): start the driver first (scripts/run)%s" % (
                    uri, wait, "" if verdict.level == OK else "; " + verdict.text)
            if not announced:
                say("Waiting for the ROS master at %s ..." % uri)
                announced = True
            time.sleep(0.2)
        # a master on another machine must reach this one by the host it advertises: else every goal
        # from here would be lost without a word (doc/network.md)
        unreachable = own_host_error(uri)
        if unreachable is not None:
            return unreachable
        from .support import init_node
        init_node("pose_terminal", anonymous=True, disable_signals=True)

        def name(relative: str) -> str:
            return rospy.resolve_name(in_namespace(self.ns, relative))
        self.driver = name(self.driver)
        rospy.Subscriber(name("robot_status"), RobotStatus, self._on_status, queue_size=1)
        rospy.Subscriber(name("tool_pose"), PoseStamped, self._on_tool_pose, queue_size=1)
        rospy.Subscriber(name("joint_states"), JointState, self._on_joints, queue_size=1)
        rospy.Subscriber("/diagnostics", DiagnosticArray, self._on_diag, queue_size=10)
        self.client = actionlib.ActionClient(name("move_to_pose"), MoveToPoseAction)
        from vr_driver.msg import FollowJointTrajectoryAction, PlanAction
        self.plan_client = actionlib.ActionClient(name("plan"), PlanAction)
        self.plan_name = name("plan")
        self.trajectory_client = actionlib.ActionClient(name("joint_trajectory_action"), FollowJointTrajectoryAction)
        self.stop_proxy = rospy.ServiceProxy(name("stop_motion"), StopMotion)   # industrial_msgs/StopMotion
        announced = False
        while not self.client.wait_for_server(rospy.Duration(0.5)):
            if not _pid_alive(launch_pid):
                return "the launch (pid %d) has ended before the driver came up" % launch_pid
            if time.monotonic() >= end:
                return ("no driver: the action %s is not served (waited %.0f s); is the driver "
                        "(node %s) running?" % (name("move_to_pose"), wait, self.driver))
            if not announced:
                say("Waiting for the driver (action %s) ..." % name("move_to_pose"))
                announced = True
        self._read_workspace()
        return None

    def wait_motion_possible(self, timeout: float) -> Optional[StatusInfo]:
        """Wait up to ``timeout`` s for a robot_status saying motion is possible and the arm's pose
        (tool_pose comes at the joint_states rate; robot_status, published on every change, may
        come first); the last status."""
        end = time.monotonic() + timeout
        while True:
            with self._lock:
                seen = self._updates
            s = self.status()
            left = end - time.monotonic()
            if (s is not None and s.motion_possible and s.pose is not None) or left <= 0:
                return s
            with self._changed:
                self._changed.wait_for(lambda: self._updates != seen, left)

    def _read_workspace(self) -> None:
        import rospy
        name = self.driver.rstrip("/") + "/workspace"
        try:
            data = rospy.get_param(name, None)
        except Exception as exc:  # parameter server trouble: keep the defaults, say so
            self.workspace_source = "defaults (cannot read %s: %s)" % (name, exc)
            return
        if data is None:
            self.workspace_source = "defaults (%s is not set)" % name
            return
        try:
            self.workspace = Workspace.from_dict(data)
            self.workspace_source = name
        except (VrDriverError, TypeError, ValueError) as exc:
            self.workspace_source = "defaults (%s is invalid: %s)" % (name, exc)

    def shutdown(self) -> None:
        import rospy
        if rospy.core.is_initialized():
            rospy.signal_shutdown("pose_terminal done")

    # ------------------------------------------------------------------ subscriptions
    def _on_status(self, msg) -> None:
        with self._changed:
            self._status, self._status_time = msg, time.monotonic()
            self._updates += 1
            self._changed.notify_all()

    def _on_tool_pose(self, msg) -> None:
        p, q = msg.pose.position, msg.pose.orientation
        try:
            pose = ControllerPose.from_ros((p.x, p.y, p.z), (q.x, q.y, q.z, q.w))
        except VrDriverError:
            return
        with self._changed:
            self._tool_pose, self._tool_pose_time = pose, time.monotonic()
            self._updates += 1
            self._changed.notify_all()

    def _on_joints(self, msg) -> None:
        with self._lock:
            self._joints = tuple(msg.position)

    def _on_diag(self, msg) -> None:
        # the driver's diagnostic_updater names its entries "<node name without the leading />: ..."
        prefix = self.driver.strip("/") + ": "
        with self._lock:
            for st in msg.status:
                if st.name.startswith(prefix):
                    self._diag[st.name[len(prefix):]] = (st.message, {kv.key: kv.value for kv in st.values})

    # ------------------------------------------------------------------ Backend
    def status(self) -> Optional[StatusInfo]:
        from vr_driver.msg import RobotMode, TriState
        with self._lock:
            msg, t = self._status, self._status_time
            pose, joints, diag = self._tool_pose, self._joints, dict(self._diag)
        if msg is None:
            return None

        def tri(v) -> Optional[bool]:
            return None if v.val == TriState.UNKNOWN else v.val == TriState.TRUE

        modes = {RobotMode.AUTO: "auto (controller program running)", RobotMode.MANUAL: "manual",
                 RobotMode.UNKNOWN: "unknown"}
        link_msg, _ = diag.get("link", ("", {}))
        _, ctrl = diag.get("controller", ("", {}))
        why = ctrl.get("why no motion", "")
        possible = tri(msg.motion_possible)
        if possible is False and (not why or why == "-"):
            why = self._why_from_fields(msg, tri, link_msg)
        linked = tri(msg.e_stopped) is not None        # the driver publishes UNKNOWN without a link
        age = time.monotonic() - t
        stale = age > 2.0
        if not link_msg:              # no diagnostics yet: what robot_status tells
            link_msg = "connected" if linked else "down (no feedback from the controller)"
        return StatusInfo(
            link=link_msg, motion_possible=None if stale else possible,
            why_no_motion="" if why == "-" else why, mode=modes.get(msg.mode.val, str(msg.mode.val)),
            e_stopped=tri(msg.e_stopped), drives_powered=tri(msg.drives_powered), in_motion=tri(msg.in_motion),
            in_error=tri(msg.in_error), error_code=msg.error_code,
            pose=pose if linked else None, joints=joints if linked else None,
            age=age)

    @staticmethod
    def _why_from_fields(msg, tri, link_msg: str) -> str:
        reasons = []
        if tri(msg.e_stopped) is None:
            reasons.append("no link to the controller" + (" (%s)" % link_msg if link_msg else ""))
        if tri(msg.e_stopped):
            reasons.append("the emergency stop is active")
        if tri(msg.in_error):
            reasons.append("the controller reports an error")
        if tri(msg.drives_powered) is False:
            reasons.append("the drives are off")
        return "; ".join(reasons)

    def _goal(self, request: PoseRequest, preview_only: bool):
        from vr_driver.msg import CartesianPose, MoveToPoseGoal
        kinds = {MoveType.PTP: MoveToPoseGoal.PTP, MoveType.LIN: MoveToPoseGoal.LIN,
                 MoveType.CIRC: MoveToPoseGoal.CIRC}
        goal = MoveToPoseGoal(target=CartesianPose(*request.target.as_tuple()), move_type=kinds[request.move_type],
                              preview_only=preview_only)
        if request.via is not None:
            goal.has_via = True
            goal.via = CartesianPose(*request.via.as_tuple())
        return goal

    def preview(self, request: PoseRequest) -> PreviewResult:
        import rospy
        from actionlib_msgs.msg import GoalStatus
        if not self.client.wait_for_server(rospy.Duration(SERVER_WAIT)):
            return PreviewResult(False, "no answer: the driver's move_to_pose action is gone (is the driver "
                                 "still running?)", unavailable=True)
        handle = RosMoveHandle(self.client, self._goal(request, preview_only=True))
        if not handle.wait(PREVIEW_TIMEOUT):
            handle.cancel()
            return PreviewResult(False, "no answer from the driver within %.0f s" % PREVIEW_TIMEOUT,
                                 unavailable=True)
        state, result = handle.outcome()
        if state == GoalStatus.SUCCEEDED and result is not None and result.success:
            return PreviewResult(True, result.reason, tuple(result.joint_target), result.estimated_duration)
        reason = result.reason if result is not None and result.reason else "the driver refused the goal"
        if reason.startswith("refused: "):
            reason = reason[len("refused: "):]
        return PreviewResult(False, reason)

    def start_move(self, request: PoseRequest) -> MoveHandle:
        return RosMoveHandle(self.client, self._goal(request, preview_only=False))

    def plan(self, request: PlanRequest) -> PlanPreview:
        """The plan action with preview_only (the driver shows it on ~plan_markers)."""
        import rospy
        from actionlib_msgs.msg import GoalStatus
        from vr_driver.msg import CartesianPose, PlanGoal
        if not self.plan_client.wait_for_server(rospy.Duration(SERVER_WAIT)):
            return PlanPreview(False, "the driver does not plan: the action %s is not served (it needs OMPL, "
                               "TOPP-RA, pinocchio and coal: the driver's log says which is missing)" % self.plan_name)
        goal = PlanGoal(preview_only=True, velocity_scaling=request.velocity_scaling)
        if request.target is not None:
            goal.goal_type, goal.pose = PlanGoal.POSE, CartesianPose(*request.target.as_tuple())
        else:
            goal.goal_type, goal.named_state = PlanGoal.NAMED, request.state
        handle = RosMoveHandle(self.plan_client, goal)
        if not handle.wait(PREVIEW_TIMEOUT):
            handle.cancel()
            return PlanPreview(False, "no answer from the planner within %.0f s" % PREVIEW_TIMEOUT, unavailable=True)
        state, result = handle.outcome()
        if state == GoalStatus.SUCCEEDED and result is not None and result.error_code == result.SUCCESS \
                and result.trajectory.points:
            return PlanPreview(True, "", result.duration, result.planning_time,
                               tuple(result.trajectory.points[-1].positions), _pose_from_msg(result.target),
                               len(result.trajectory.points), result.planner_id, token=result.trajectory,
                               velocity_scaling=result.velocity_scaling, peak_tcp_speed=result.peak_tcp_speed,
                               peak_joint=result.peak_joint, peak_joint_speed=result.peak_joint_speed,
                               peak_joint_fraction=result.peak_joint_fraction, run_duration=result.run_duration,
                               run_peak_tcp_speed=result.run_peak_tcp_speed, run_words=result.run_words)
        reason = result.error_string if result is not None and result.error_string else "the planner refused the goal"
        if reason.startswith("refused: "):
            reason = reason[len("refused: "):]
        return PlanPreview(False, reason)

    def start_plan(self, preview: PlanPreview) -> MoveHandle:
        """Exactly the previewed trajectory, through joint_trajectory_action (the plan action's own
        execution path)."""
        import rospy
        from vr_driver.msg import FollowJointTrajectoryGoal
        if not self.trajectory_client.wait_for_server(rospy.Duration(SERVER_WAIT)):
            return _Failed("the driver's joint_trajectory_action is not served: nothing was sent")

        def pose_now() -> Optional[ControllerPose]:
            with self._lock:
                return self._tool_pose
        return RosTrajectoryHandle(self.trajectory_client, FollowJointTrajectoryGoal(trajectory=preview.token),
                                   preview.target, pose_now, self._pose_after)

    def _pose_after(self, since: float, timeout: float) -> Optional[ControllerPose]:
        """The first tool_pose received after ``since`` (time.monotonic), waiting up to ``timeout``; None."""
        with self._changed:
            self._changed.wait_for(lambda: self._tool_pose_time is not None and self._tool_pose_time > since,
                                   timeout)
            return self._tool_pose if self._tool_pose_time is not None and self._tool_pose_time > since else None

    def stop(self) -> Tuple[bool, str]:
        import rospy
        try:
            self.stop_proxy.wait_for_service(SERVER_WAIT)
            response = self.stop_proxy()
        except (rospy.ROSException, rospy.ServiceException) as exc:
            return False, "stop_motion is not available: %s" % exc
        from vr_driver.msg import ServiceReturnCode
        if response.code.val == ServiceReturnCode.SUCCESS:
            return True, "stop sent"
        return False, "the driver could not take the stop (code %d; see its log)" % response.code.val


# ---------------------------------------------------------------------------------------- main

def _readline_input():
    """input() with line editing and a history of this session (when stdin is a terminal)."""
    if sys.stdin.isatty():
        try:
            import readline  # noqa: F401  (importing it gives input() line editing)
        except ImportError:
            pass
    return input


def main(argv: Optional[List[str]] = None) -> int:
    ctrl_c_raises()                      # Ctrl-C stops a move, even where SIGINT came in ignored
    if argv is None:
        try:
            import rospy
            argv = rospy.myargv(sys.argv)[1:]
        except ImportError:
            argv = sys.argv[1:]
    parser = build_arg_parser()
    args = parser.parse_args(argv)
    one_shot = args.pose is not None or args.plan is not None
    if not one_shot and (args.move_type is not None or args.via is not None or args.preview):
        parser.error("--type, --via and --preview go with --pose")
    # syntax before connecting: a typo is a usage error, whatever the driver's workspace
    if one_shot:
        try:
            request_from_args(args, Workspace())
        except RangeError:
            pass                      # judged against the driver's own workspace once connected
        except InputError as exc:
            parser.error(str(exc))
    backend = RosBackend(args.driver, args.ns)
    out = sys.stdout
    try:
        error = backend.connect(args.wait, args.launch_pid, say=lambda text: print(text, flush=True))
    except KeyboardInterrupt:
        print("\nInterrupted while waiting for the driver.", flush=True)
        backend.shutdown()
        return EXIT_INTERRUPTED
    if error is not None:
        print("pose_terminal: %s" % error, file=sys.stderr, flush=True)
        backend.shutdown()
        return EXIT_NO_DRIVER
    try:
        terminal = Terminal(backend, backend.workspace, out=out, input_fn=_readline_input(), assume_yes=args.yes,
                            velocity_scaling=args.velocity_scaling)
        if one_shot:
            try:
                request = request_from_args(args, backend.workspace)
            except RangeError as exc:
                print("Refused, nothing was sent: %s" % exc, flush=True)
                return EXIT_REFUSED
            except InputError as exc:
                parser.error(str(exc))
            if not args.preview:
                backend.wait_motion_possible(min(5.0, args.wait))
            return terminal.run_once(request, preview_only=args.preview)
        ws = backend.workspace
        print("Connected to the driver; workspace X %g..%g, Y %g..%g, Z %g..%g mm, angles %g..%g deg (%s)."
              % (ws.x + ws.y + ws.z + ws.angle + (backend.workspace_source,)), flush=True)
        status = backend.wait_motion_possible(min(10.0, max(args.wait, 1.0)))
        if status is None:
            print("No robot_status from the driver yet ('status' shows it later).", flush=True)
        elif status.motion_possible:
            print("Controller ready: motion possible; the arm is at %s."
                  % (fmt_pose(status.pose) if status.pose is not None else "(pose unknown)"), flush=True)
        else:
            print("Motion is not possible now: %s ('status' shows more)."
                  % (status.why_no_motion or "see 'status'"), flush=True)
        return terminal.run_interactive()
    except KeyboardInterrupt:            # before the dialogue took over Ctrl-C
        print("\nInterrupted.", flush=True)
        return EXIT_INTERRUPTED
    finally:
        backend.shutdown()


__all__ = ["RosBackend", "RosMoveHandle", "main", "EXIT_OK", "EXIT_REFUSED", "EXIT_USAGE", "EXIT_NO_DRIVER",
           "EXIT_INTERRUPTED"]
