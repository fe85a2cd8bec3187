"""The plan action's core, ROS-free: a goal (joints, a named state of the SRDF, or a TCP pose in the
controller's units) planned from the arm's joints with :class:`vr_driver.kinematics.planner.Planner`
against a snapshot of the driver's collision checker and scene, inside the driver's workspace box,
and the outcome as a code and words (the node vr_driver.ros.plan_server only translates messages).

    planning = PlanActionCore(core)          # MissingDependency when OMPL / TOPP-RA / the checker's
                                             # libraries cannot be imported (the action is then not served)
    outcome = planning.plan(PlanGoal(pose=ControllerPose(500, 866, 725, 0, 45, 60)))
    outcome.ok, outcome.code, outcome.text, outcome.trajectory (a PlannedTrajectory), outcome.target

- **Consistent snapshot**: each plan takes its own copy of the driver's checker (CollisionChecker.copy:
  the scene and padding of that moment, own pinocchio data), so a scene changed while it plans does
  not change what it plans against; the next plan sees the change.
- **The workspace box**: every configuration the planner accepts also has its TCP inside the driver's
  workspace box (what the driver checks the stream's segments against), with the planner's clearance
  as a margin on the box too, so the trajectory it returns is one the driver's own checks accept.
- **Where it runs**: in the caller's thread, one plan at a time (a lock of its own: OMPL's random
  numbers are process-wide), on a Kinematics and a checker of its own. The driver's planning gate is
  taken only to copy the checker: a plan's budget does not hold up previews, trajectory checks or
  joint_command steps (a stream's commands would time out behind it). The node does not call it in
  its own interpreter: OMPL's solve and the planner's other C++ calls hold the interpreter lock for
  0.6 to 5 s, which starved the bus thread past the card's watchdog. The plan action runs it in a
  worker process (:mod:`vr_driver.driver.planning.plan_process`: on the parts of a driver a plan needs,
  PlanningParts, with the node's scene, joints and bus cycle sent with the requests); tests and
  benches call it directly.
- **What the driver will accept**: with a Cartesian protocol (v1, v3) the controller solves each
  target's pose itself, taking the solution nearest the previous target: near the wrist singularity
  (joint_5 = 0) that is not always the planned one, and the driver refuses such a stream ("in another
  configuration than planned"); near the stretched-out arm the two elbow branches of a pose meet,
  with the same effect. So the planner keeps |joint_5| >= :data:`WRIST_MARGIN` and joint_3
  :data:`ELBOW_MARGIN` from the stretch away from the start and the goal (as it keeps its clearance);
  a goal on the other elbow branch is planned through the stretch where the controller does change
  branch (:meth:`PlanActionCore._elbow_crossing`), every other leg on its own side of it
  (:func:`elbow_side_legs`); and a plan is checked by the driver's own stream
  checks (its points, their configurations and segments) before it is returned; one they refuse,
  no path within the budget, or a timing that fails its checks is planned again (:data:`ATTEMPTS` in
  all, each with the whole budget: a sampling planner's next try differs; a try after one that found
  no path searches with another planner, :func:`retry_planner`, and crosses the stretched elbow by
  other waypoints, :meth:`PlanActionCore._elbow_crossings`), so that a preview shows what will run. The planning time is then at most ATTEMPTS x the budget. A plan from where the
  last plan ended whose tries found no path retreats on its last try along the way the arm came
  (:func:`retreat_waypoints`: out of a narrow place such as under a hood), every leg checked.
- **Kept between plans**: the paths of the plans made (:class:`~vr_driver.kinematics.roadmap.Roadmap`,
  one per core: in the plan action's worker process, for as long as it lives), tried as a route
  before the next search; dropped when the scene, the padding or the box changes (the snapshot's
  key, :func:`cell_key`). A hint only: every motion of a route is checked again by
  the plan's own validity, and the plan is checked as any other.
- **Words**: a start or goal in collision names the link and the object (the checker's contacts);
  a TCP outside the box says which field and by how much.
"""
from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from ...errors import MissingDependency, VrDriverError
from ...kinematics import deps
from ...kinematics.planner import (DEFAULT_CLEARANCE, PLANNERS, BatchValidity, PlannedTrajectory, Planner, PlanningError,
                                   joint_weights, pose_target)
from ...kinematics.roadmap import Roadmap
from ...kinematics.solver import ConfigurationRule, Kinematics, stretched_elbow
from ...poses import ControllerPose, Workspace
from ..checks.commissioned import planning_kinematics

__all__ = ["SUCCESS", "PLANNING_FAILED", "INVALID_MOTION_PLAN", "CONTROL_FAILED", "PREEMPTED",
           "START_STATE_IN_COLLISION", "GOAL_IN_COLLISION", "INVALID_GOAL", "INVALID_ROBOT_STATE",
           "NO_IK_SOLUTION", "PlanGoal", "PlanOutcome", "CellValidity", "WorkspaceContact", "PlanActionCore",
           "cell_key", "margin_validity",
           "arm_points", "code_of", "driver_sends", "elbow_crossings", "elbow_side_legs", "plan_with_crossing",
           "retreat_waypoints", "retry_planner"]

# the result codes of vr_driver/Plan.action (moveit_msgs/MoveItErrorCodes' values)
SUCCESS = 1
PLANNING_FAILED = -1
INVALID_MOTION_PLAN = -2
CONTROL_FAILED = -4
PREEMPTED = -7
START_STATE_IN_COLLISION = -10
GOAL_IN_COLLISION = -12
INVALID_GOAL = -16
INVALID_ROBOT_STATE = -17
NO_IK_SOLUTION = -31

_FEATURE = "the plan action (vr_driver.driver.planning.planning)"
#: [rad] a Cartesian protocol's plan keeps |joint_5| at least this far from the wrist singularity
#: (except near its start and goal: the planner's escape zone)
WRIST_MARGIN = 0.0524          # 3 deg
#: [rad] ... and joint_3 at least this far from the stretched-out arm (kinematics.solver.stretched_elbow),
#: where the pose's two elbow branches lie within twice this of each other: the controller's IK of a
#: rounded pose may take the other one, or find the pose beyond its reach (0.1 mm past a stretched
#: arm); 8 deg costs the arm about 3 mm of its reach
ELBOW_MARGIN = math.radians(8.0)
#: [rad] a plan across the stretched elbow turns joint_3 alone from this near the stretch on the
#: start's side to ELBOW_CROSS past it (PlanActionCore._elbow_crossing): after a target e from the
#: stretch, one d past it is nearest the planned branch once d > about 4 e (joint_2's share of the
#: mirror); 2 deg keeps the first target's wire pose well solved (at the stretch the rounding alone
#: moves the wrist by 1.5 deg: bench/planning.py, query 52)
ELBOW_APPROACH = math.radians(2.0)
ELBOW_CROSS = math.radians(12.0)
#: [rad] ... with |joint_5| at least this there
ELBOW_WRIST = math.radians(6.0)
#: [s] the arm holds this long at rest at the first of the two (plan_with_crossing): the turn
#: from rest keeps the stream's points around the stretch close enough for the G2 to change branch
#: on them, and under the G2 rule current_joints the target past it is taken with the arm there
ELBOW_HOLD = 0.1
#: plans made at most for one goal: no path within the budget, a timing that fails its checks or a
#: stream the driver refuses is planned again (a sampling planner's next path differs)
ATTEMPTS = 3
#: the search of a try after a try that found no path (the requested planner's search otherwise):
#: OMPL's LBKPIECE1 (lazy bidirectional KPIECE: it grows its trees along a projection of the joints
#: and checks motions lazily) where RRTConnect was asked for, RRTConnect where another was. A goal
#: reached only through a narrow passage -- the hood cell's query 52, a folded wrist turning under
#: the hood's top -- was found by RRTConnect in 1 of 15 one-second tries, by LBKPIECE1 in 7 of 8
#: (bench/README.md, "Planning"); the path is checked, simplified and timed as any other
RETRY_PLANNER = "LBKPIECE1"
#: [rad] a plan from within this of the last plan's end (every joint) may retreat along its path on
#: its last try (retreat_waypoints)
RETREAT_NEAR = math.radians(1.0)
#: [rad] a goal this close to the arm's joints on every joint is where the arm is: nothing to move
AT_GOAL = 1e-4
#: the chain indices of the wrist bend (joint_5) and the elbow (joint_3)
_WRIST = 4
_ELBOW = 2
_SHOULDER = 1
#: [rad] joint_2 of the elbow crossings tried after those on the straight line's other joints
#: (PlanActionCore._elbow_crossings): the upper arm upright and 20 deg either way, the stretched
#: arm pointing up, clear of what stands on a table
CROSS_UPRIGHT = (0.0, math.radians(20.0), math.radians(-20.0))


@dataclass(frozen=True)
class PlanGoal:
    """One goal: exactly one of ``joints`` ((names, positions [rad])), ``named`` (an SRDF state) and
    ``pose`` (TCP in ``base``, mm / deg). ``planner_id`` "" / ``planning_time`` 0 /
    ``velocity_scaling`` 0 take the driver's parameters."""

    joints: Optional[Tuple[Tuple[str, ...], Tuple[float, ...]]] = None
    named: str = ""
    pose: Optional[ControllerPose] = None
    planner_id: str = ""
    planning_time: float = 0.0
    velocity_scaling: float = 0.0

    def describe(self) -> str:
        if self.pose is not None:
            return "the pose X %g  Y %g  Z %g  Rx %g  Ry %g  Rz %g" % self.pose.as_tuple()
        if self.named:
            return "the named state %r" % self.named
        if self.joints is not None:
            return "the joints (%s) deg" % ", ".join("%.1f" % math.degrees(v) for v in self.joints[1])
        return "no goal"


@dataclass(frozen=True)
class PlanOutcome:
    """``code`` one of the result codes, ``text`` in words; on success ``trajectory`` and ``target``
    (the TCP pose at its end), ``planning_time`` [s] (also on failure: how long it tried)."""

    code: int
    text: str
    trajectory: Optional[PlannedTrajectory] = None
    planning_time: float = 0.0
    planner_id: str = ""
    target: Optional[ControllerPose] = None
    contacts: Tuple[Any, ...] = field(default=())
    #: where the call's time went [s] and what it did: ``crossing`` (the elbow crossing's waypoints),
    #: ``snapshot`` (copying the checker), the planner's steps summed over the tries (``goal``,
    #: ``plan``, ``simplify``, ``time``, ``check``), ``stream_check`` (the driver's own check of each
    #: plan, :meth:`PlanActionCore.driver_refusal`), ``checks`` (validity checks made: the box and the
    #: checker), ``tries`` (plans made), ``replans`` (why a try was planned again, in words),
    #: ``retreat`` (1 when the last try went back along the last plan's path) and ``roadmap``
    #: (legs that were a route of earlier plans, :class:`~vr_driver.kinematics.roadmap.Roadmap`)
    profile: Dict[str, Any] = field(default_factory=dict)
    #: on success, what the driver sends for ``trajectory`` as its stream check made it
    #: (:meth:`PlanActionCore.driver_refusal`): a streaming protocol's points, v1's PTP previews --
    #: what the node announces the run with (``DriverCore.announce``) instead of making them again;
    #: empty when not known (the node makes them)
    stream: Tuple[Any, ...] = ()
    previews: Tuple[Any, ...] = ()

    @property
    def ok(self) -> bool:
        return self.code == SUCCESS


class WorkspaceContact:
    """A 'contact' with the workspace box: the TCP outside it (a field and by how much), in the form of
    the checker's Contact (``link_a``, ``other``, ``distance`` [m], ``world``)."""

    def __init__(self, link: str, field_name: str, excess: float, unit: str) -> None:
        self.link_a = link
        self.other = "workspace box"
        self.world = True
        self.distance = -excess / 1000.0 if unit == "mm" else 0.0
        self._text = "%s outside the workspace box (%s by %.1f %s)" % (link, field_name, excess, unit)

    def __str__(self) -> str:
        return self._text


def joints_to_plan_from(status: Any) -> Any:
    """The arm's joints in the driver's ``status`` (a DriverStatus), or -- when they are not known --
    the refusal in words (a str)."""
    if status.joints is None or not getattr(status, "joints_valid", True):
        return "refused: the arm's joints are not known (%s)" % (
            status.why_no_motion() or "no feedback from the controller")
    return tuple(status.joints)


class CellValidity:
    """A collision checker (or None: nothing to collide with) and the workspace box as one validity
    the planner takes like a checker: ``in_collision(q)`` (the arm hits something, or its TCP is
    outside the box shrunk by ``margin`` [mm]), ``contacts(q)`` naming them, ``copy()``, ``padding`` /
    ``set_padding`` (the planner's clearance: raising the padding by x also shrinks the box by x)."""

    def __init__(self, checker: Any, kinematics: Kinematics, workspace: Workspace, margin: float = 0.0,
                 padding: float = 0.0, counter: Optional[List[int]] = None) -> None:
        self.checker = checker
        #: [checks made by this validity and its copies] (the plan action's profile)
        self.counter = counter if counter is not None else [0]
        self._tcp: Any = None           # _tcp_by_checker's finding
        self._tcp_reach: Optional[np.ndarray] = None   # [m/rad] per joint: how far its turn moves the TCP at most
        self._reach: Any = None         # _reach_ball's finding
        self.kin = kinematics
        self.workspace = workspace
        self.margin = float(margin)
        self._padding = float(checker.padding) if checker is not None else float(padding)

    @property
    def padding(self) -> float:
        return self._padding

    def set_padding(self, padding: float) -> None:
        self.margin += (padding - self._padding) * 1000.0
        self._padding = padding
        if self.checker is not None:
            self.checker.set_padding(padding)

    def copy(self) -> "CellValidity":
        return CellValidity(self.checker.copy() if self.checker is not None else None, self.kin, self.workspace,
                            self.margin, self._padding, self.counter)

    def _outside(self, q: Sequence[float]) -> Optional[Tuple[str, float, str]]:
        """(field, excess, unit) of the TCP's worst field beyond the box less the margin, or None."""
        worst = None
        for name, value in zip(("x", "y", "z"), self.kin.tcp_position(q)):
            lo, hi = getattr(self.workspace, name)
            excess = max(lo + self.margin - value, value - (hi - self.margin))
            if excess > 0 and (worst is None or excess > worst[1]):
                worst = (name.upper(), excess, "mm")
        return worst

    def _tcp_by_checker(self) -> Any:
        """(the checker's probe of the TCP in ``base``: :meth:`CollisionChecker.point_probe
        <vr_driver.kinematics.collision.CollisionChecker.point_probe>`) when the checker's model puts
        the TCP where the kinematics do (checked at three configurations, to 1e-6 mm), else False:
        then the box is checked by KDL's FK."""
        if self._tcp is None:
            self._tcp = False
            if self.checker is not None and hasattr(self.checker, "point_probe") \
                    and hasattr(self.kin, "tcp_in_tip"):
                base, offset = self.kin.tcp_in_tip()
                try:
                    probe = self.checker.point_probe(self.kin.tip, offset, base)
                    n = len(self.kin.joint_names)
                    for q in ((0.0,) * n, tuple(0.3 + 0.1 * i for i in range(n)), tuple(-0.9 + 0.2 * i for i in range(n))):
                        self.checker.in_collision(q)
                        p = self.checker.point_here(probe)
                        if max(abs(a - b / 1000.0) for a, b in zip(p, self.kin.tcp_position(q))) > 1e-9:
                            return self._tcp
                except (VrDriverError, ValueError, TypeError):
                    return self._tcp
                self._tcp = probe
        return self._tcp

    def _reach_ball(self) -> Any:
        """(the centre [mm, in ``base``], the half-widths along X, Y, Z [mm]) of a box the TCP never
        leaves, whatever the joints, or False (a prismatic joint, a kinematics without the chain, a
        chain whose first two joints are not movable one after the other). The second movable
        joint's origin turns on a circle about the first joint's axis; the TCP stays within the
        lengths of the chain's offsets after it plus its distance from the tip (the triangle
        inequality, as ``joint_weights``) of that origin."""
        if self._reach is None:
            self._reach = False
            joints = getattr(self.kin, "chain_joints", None)
            if joints and hasattr(self.kin, "tcp_in_tip") and all(j.type != "prismatic" for j in joints):
                base, offset = self.kin.tcp_in_tip()
                frame = np.eye(4)
                k = 0
                while k < len(joints) and not joints[k].movable:
                    frame = frame @ joints[k].origin
                    k += 1
                if k + 1 < len(joints) and joints[k + 1].movable:
                    frame = np.asarray(base, dtype=float) @ frame @ joints[k].origin    # joint k's frame in base
                    axis = np.asarray(joints[k].axis, dtype=float)
                    axis = axis / np.linalg.norm(axis)
                    o = joints[k + 1].origin[:3, 3]
                    along = float(axis @ o)
                    rho = float(np.linalg.norm(o - along * axis))
                    centre = frame[:3, 3] + frame[:3, :3] @ (along * axis)
                    turn = frame[:3, :3] @ axis            # the axis in base
                    beyond = sum(float(np.linalg.norm(j.origin[:3, 3])) for j in joints[k + 2:])
                    beyond += float(np.linalg.norm(offset))
                    half = rho * np.sqrt(np.clip(1.0 - turn * turn, 0.0, 1.0)) + beyond
                    # (a micrometre for the rounding)
                    self._reach = (centre * 1000.0, half * 1000.0 + 1e-3)
        return self._reach

    def box_holds_every_tcp(self) -> bool:
        """Whether the box less the margin holds :meth:`_reach_ball`'s: no configuration can put the
        TCP outside it, so the box need not be checked (a box as wide as the arm's whole reach)."""
        ball = self._reach_ball()
        if not ball:
            return False
        centre, half = ball
        ws, m = self.workspace, self.margin
        return all(lo + m <= c - h and c + h <= hi - m for c, h, (lo, hi) in zip(centre, half, (ws.x, ws.y, ws.z)))

    def in_collision(self, q: Sequence[float]) -> bool:
        self.counter[0] += 1
        if self.box_holds_every_tcp():
            return self.checker is not None and self.checker.in_collision(q)
        tcp = self._tcp_by_checker()
        if not tcp:
            # the box first: the TCP's position alone (KDL), a third of the checker's time
            if self._outside(q) is not None:
                return True
            return self.checker is not None and self.checker.in_collision(q)
        # one forward kinematics (the checker's pinocchio, in its collision check) for both: the
        # collisions first, then the TCP where that check put it
        if self.checker.in_collision(q):
            return True
        return self._out_of_box(self.checker.point_here(tcp))

    def _out_of_box(self, p: Sequence[float]) -> bool:
        """Whether the TCP at ``p`` [m, in ``base``] is outside the box less the margin."""
        x, y, z = p
        ws, m = self.workspace, self.margin
        return not (ws.x[0] + m <= x * 1000.0 <= ws.x[1] - m and ws.y[0] + m <= y * 1000.0 <= ws.y[1] - m
                    and ws.z[0] + m <= z * 1000.0 <= ws.z[1] - m)

    def first_invalid(self, qs: Sequence[Sequence[float]]) -> Optional[int]:
        """The index of the first row of ``qs`` (n x the joints) that :meth:`in_collision` finds
        invalid, or None -- the collisions of the rows in one call of the checker (its
        ``first_collision``, up to the first), then the box of the rows before that one (none when
        the box holds every TCP, :meth:`box_holds_every_tcp`)."""
        whole = self.box_holds_every_tcp()
        tcp = self._tcp_by_checker() if not whole else None
        if (not whole and not tcp) or not hasattr(self.checker, "first_collision"):
            for i, q in enumerate(qs):
                if self.in_collision(tuple(q)):
                    return i
            return None
        qs = np.asarray(qs, dtype=float)
        hit = self.checker.first_collision(qs)
        end = len(qs) if hit is None else hit
        for i in ([] if whole else self._box_rows(qs[:end], tcp)):
            if self._out_of_box(self.checker.point_at(qs[i], tcp)):
                self.counter[0] += i + 1
                return i
        self.counter[0] += end + (hit is not None)
        return hit

    def _box_rows(self, qs: np.ndarray, tcp: Any) -> List[int]:
        """The rows of ``qs`` whose TCP must be checked against the box, in order: all but those
        proven inside it by the first or the last row's -- the TCP of a row moves no farther from
        that row's than sum_i w_i |dq_i| (``joint_weights`` with the TCP's distance from the tip as
        the allowance: the triangle inequality), so a row within less than the box's room around
        that TCP is inside (the first and the last row are checked themselves)."""
        n = len(qs)
        if n <= 2:
            return list(range(n))
        if self._tcp_reach is None:
            self._tcp_reach = np.array(joint_weights(self.kin, float(np.linalg.norm(self.kin.tcp_in_tip()[1]))))
        ws, m = self.workspace, self.margin
        need = np.ones(n, dtype=bool)
        for k in (0, n - 1):
            p = self.checker.point_at(qs[k], tcp) * 1000.0
            room = min(p[0] - ws.x[0] - m, ws.x[1] - m - p[0], p[1] - ws.y[0] - m, ws.y[1] - m - p[1],
                       p[2] - ws.z[0] - m, ws.z[1] - m - p[2])
            if room > 0.0:
                # [mm], with a micrometre's allowance for the rounding of both sides
                need &= np.abs(qs - qs[k]) @ self._tcp_reach * 1000.0 + 1e-3 >= room
        need[0] = need[-1] = True
        return np.flatnonzero(need).tolist()

    def contacts(self, q: Sequence[float]) -> List[Any]:
        out: List[Any] = list(self.checker.contacts(q)) if self.checker is not None else []
        outside = self._outside(q)
        if outside is not None:
            out.append(WorkspaceContact("the TCP", *outside))
        return out


def code_of(exc: PlanningError) -> int:
    """The result code of a planner's refusal (its step and whether it named contacts)."""
    text = str(exc)
    if exc.step == "start":
        return START_STATE_IN_COLLISION if exc.contacts or "in collision" in text else INVALID_ROBOT_STATE
    if exc.step == "goal":
        if exc.contacts or "in collision" in text:
            return GOAL_IN_COLLISION
        if "unreachable" in text:
            return NO_IK_SOLUTION
        return INVALID_GOAL
    if exc.step == "plan":
        return PLANNING_FAILED
    return INVALID_MOTION_PLAN


def arm_points(kinematics: Kinematics, q: Sequence[float]) -> List[Tuple[float, float, float]]:
    """The origins of the chain's segments at ``q`` in the chain root [m], base to tip, repeated points
    left out: a stick figure of the arm (the planned sweep in RViz)."""
    import PyKDL as kdl
    chain = kinematics.chain
    solver = kdl.ChainFkSolverPos_recursive(chain)
    jnt = kdl.JntArray(len(q))
    for i, v in enumerate(q):
        jnt[i] = float(v)
    out: List[Tuple[float, float, float]] = [(0.0, 0.0, 0.0)]
    for seg in range(1, chain.getNrOfSegments() + 1):
        f = kdl.Frame()
        if solver.JntToCart(jnt, f, seg) < 0:
            continue
        p = (f.p[0], f.p[1], f.p[2])
        if math.dist(p, out[-1]) > 1e-6:
            out.append(p)
    return out


def cell_key(validity: CellValidity) -> Tuple[Any, ...]:
    """What a plan's validity depends on besides the model: the scene's objects, the padding, the
    box and its margin (the roadmap's key: another drops its paths, :meth:`Roadmap.keep
    <vr_driver.kinematics.roadmap.Roadmap.keep>`)."""
    checker = validity.checker
    scene = tuple(repr(o) for o in checker.scene.objects()) if checker is not None else None
    ws = validity.workspace
    return scene, validity.padding, (tuple(ws.x), tuple(ws.y), tuple(ws.z)), validity.margin


def margin_validity(strict: CellValidity, wrist_margin: bool, stretched: Optional[float]) -> BatchValidity:
    """``strict`` with |joint_5| >= WRIST_MARGIN (``wrist_margin``) and joint_3 ELBOW_MARGIN from
    ``stretched`` (the stretched elbow's joint_3; None: no elbow margin), one configuration or a
    batch (the margins in numpy, then ``strict`` on the rows before the first outside them)."""
    elbow = stretched is not None

    def clear(q) -> bool:
        return (not wrist_margin or abs(q[_WRIST]) >= WRIST_MARGIN) and (
            not elbow or abs(math.remainder(q[_ELBOW] - stretched, 2.0 * math.pi)) >= ELBOW_MARGIN)

    def first_invalid(qs: Sequence[Sequence[float]]) -> Optional[int]:
        qs = np.asarray(qs, dtype=float)
        bad = np.zeros(len(qs), dtype=bool)
        if wrist_margin:
            bad |= np.abs(qs[:, _WRIST]) < WRIST_MARGIN
        if elbow:
            turn = 2.0 * math.pi
            off = qs[:, _ELBOW] - stretched
            off = np.abs(off - turn * np.round(off / turn))
            # clear's exact remainder where the rounding above could tip the comparison
            edge = np.flatnonzero(np.abs(off - ELBOW_MARGIN) < 1e-9)
            off[edge] = [abs(math.remainder(v - stretched, turn)) for v in qs[edge, _ELBOW].tolist()]
            bad |= off < ELBOW_MARGIN
        outside = np.flatnonzero(bad)
        end = int(outside[0]) if len(outside) else len(qs)
        hit = strict.first_invalid(qs[:end]) if end else None
        return hit if hit is not None else (end if end < len(qs) else None)
    return BatchValidity(lambda q: clear(q) and not strict.in_collision(q), first_invalid)


def elbow_side_legs(stretched: float):
    """The planner's ``leg_validity`` of a Cartesian protocol: a leg between two configurations on
    one side of the stretched elbow (joint_3 ``stretched``) keeps joint_3 on that side, at the
    stretch at most; a leg across it (an elbow crossing's turn of joint_3 alone, straight) or from
    or to the stretch itself, nothing more. The controller solves each target nearest the one
    before and keeps the branch it is on where a plan crosses the stretch otherwise (bench/README.md,
    "Planning"): without this, the search legs of a crossing -- planned without the elbow margin,
    to reach the crossing's waypoints near the stretch -- crossed the stretch and back on their own
    and the driver's stream check refused the plan (the hood cell's query 38: 3 tries of 3 refused
    in 5 of 20 seeds), and a last try without the margins did the same. The escape zones of the
    search do not lift it."""
    turn = 2.0 * math.pi

    def off(v: float) -> float:
        return math.remainder(v - stretched, turn)

    def leg(a: Sequence[float], b: Sequence[float]) -> Optional[BatchValidity]:
        side = off(a[_ELBOW])
        if side * off(b[_ELBOW]) <= 0.0:
            return None
        sign = 1.0 if side > 0.0 else -1.0

        def one(q: Sequence[float]) -> bool:
            return sign * off(q[_ELBOW]) >= 0.0

        def batch(qs: Sequence[Sequence[float]]) -> Optional[int]:
            qs = np.asarray(qs, dtype=float)
            d = qs[:, _ELBOW] - stretched
            d = sign * (d - turn * np.round(d / turn))
            # the exact remainder where the rounding above could tip the sign
            for i in np.flatnonzero(np.abs(d) < 1e-9).tolist():
                d[i] = sign * off(float(qs[i, _ELBOW]))
            bad = np.flatnonzero(d < 0.0)
            return int(bad[0]) if len(bad) else None
        return BatchValidity(one, batch)
    return leg


def elbow_crossings(start: Sequence[float], goal: Sequence[float], stretched: float, strict: Any, limits: Any
                    ) -> Tuple[Tuple[Tuple[float, ...], ...], ...]:
    """Up to ATTEMPTS pairs (near, past) of waypoints that cross the stretched elbow (joint_3
    ``stretched``) from ``start``'s side to ``goal``'s, each inside ``limits`` and valid by
    ``strict``, the planner's validity without the margins.

    The controller solves each target nearest the one before: a pose just past the stretch it
    solves onto the branch it is on (the other branch's solution lies farther than its mirror),
    and a plan that crosses in the direction joint_2 and joint_3 fold in together (the wrist
    centre out to full reach and back) never leaves it. Turning joint_3 alone from near the
    stretch does: from ELBOW_APPROACH on the start's side, ELBOW_CROSS past it the planned
    branch is the nearest (bench/README.md, "Planning"). So the plan passes the stretch where
    the straight joint line from the start to the goal does (joint_5 moved to ELBOW_WRIST from
    0, on the start's side, if it is nearer: the wrist singularity there too would leave
    joint_4 / joint_6 to the controller) -- or, where that is not valid, with the other joints
    at the start's, or at the goal's, or half, a quarter, three quarters of the way -- and
    turns joint_3 alone between those two places (past the goal's joint_3 when that is nearer the
    stretch than ELBOW_CROSS / 2: a target that near it the G2 solves onto the start's branch
    from the start's side, onto the goal's from beyond). A try that found no path through one
    crossing (a leg walled in: the hood cell's query 52) takes the next: the same places, then
    each with the upper arm upright (joint_2 at CROSS_UPRIGHT, where the stretched arm points
    up, away from a table, a hood or a shelf: the hood cell's query 88, whose straight line
    crosses the stretch with the arm reaching down into the table). None when no such pair is
    valid (the planner's clearance, the limits, the box): the plan is made as before and the
    driver's stream check decides."""
    a, b = start[_ELBOW], goal[_ELBOW]
    # to ELBOW_CROSS past the stretch, or to the goal's joint_3 if nearer; a goal nearer the stretch
    # than ELBOW_CROSS / 2 is reached from ELBOW_CROSS past it, back along its own branch
    turn = min(ELBOW_CROSS, abs(b - stretched)) if abs(b - stretched) >= ELBOW_CROSS / 2.0 else ELBOW_CROSS
    found: List[Tuple[Tuple[float, ...], ...]] = []
    # the other joints where the straight line crosses; else the start's, the goal's, between
    for upright in (None,) + CROSS_UPRIGHT:
        for f in ((stretched - a) / (b - a), 0.0, 1.0, 0.5, 0.25, 0.75):
            near = [x + f * (y - x) for x, y in zip(start, goal)]
            if upright is not None:
                near[_SHOULDER] = upright
            if abs(near[_WRIST]) < ELBOW_WRIST:
                near[_WRIST] = math.copysign(ELBOW_WRIST, start[_WRIST] if start[_WRIST] else 1.0)
            near[_ELBOW] = stretched + math.copysign(ELBOW_APPROACH, a - stretched)
            past = list(near)
            past[_ELBOW] = stretched + math.copysign(turn, b - stretched)
            pair = (tuple(near), tuple(past))
            if pair not in found and all(all(lo <= v <= hi for v, lo, hi in zip(q, limits.lower, limits.upper))
                                         and strict(q) for q in pair):
                found.append(pair)
                if len(found) == ATTEMPTS:
                    return tuple(found)
    return tuple(found)


class PlanActionCore:
    """The plan action's ROS-free part (``ros/plan_server.py`` is its ROS edge): plans for a
    :class:`~vr_driver.driver.core.DriverCore` with the OMPL planner
    (:class:`~vr_driver.kinematics.planner.Planner`) against the driver's own checks (see the module
    text). Not the previews of single moves: :class:`~vr_driver.kinematics.preview.MovePreviewer`. Raises
    MissingDependency when the planner's libraries (OMPL, TOPP-RA) cannot be imported, or when the
    driver checks collisions (``collision_check``) but has no checker (its libraries are missing)."""

    def __init__(self, core: Any, kinematics: Any = None, clock=time.perf_counter) -> None:
        for module in ("ompl", "toppra"):
            deps.require(module, _FEATURE)
        self.core = core
        self.params = core.params
        self._lock = threading.Lock()        # one plan at a time
        if self.params.collision_check and core.collision is None:
            # the core leaves it None only when its libraries are missing: say which
            for module in ("pinocchio", "coal"):
                deps.require(module, _FEATURE)
            raise MissingDependency("pin", "pinocchio", _FEATURE, "the driver has no collision checker")
        if kinematics is None:
            from ..core import driver_kinematics
            kinematics = driver_kinematics(self.params)   # its own: no solver shared with the bus thread
        # the commissioned joint speed and acceleration limits (planning_limits), where measured
        self.kin = planning_kinematics(self.params, kinematics)
        self.clock = clock
        #: the geometric path of the last plan made (its start first), or None: a way back out of
        #: where it went, for a next plan from its end that finds no path (:func:`retreat_waypoints`)
        self.last_path: Optional[Tuple[Tuple[float, ...], ...]] = None
        #: the paths of the plans made in this cell (kinematics.roadmap: a hint the planner checks
        #: again), kept while the scene, the padding and the box stay (:func:`cell_key`)
        self.roadmap = Roadmap(joint_weights(self.kin))
        #: the plan the stream check took last, with what the driver sends for it (PlanOutcome.stream, previews)
        self._prepared: Tuple[Any, Tuple[Any, ...], Tuple[Any, ...]] = (None, (), ())
        # a Planner is cheap; making one checks its libraries and the limits once, here
        Planner(self.kin, None, planner=self.params.planner_id)

    @property
    def collision_checked(self) -> bool:
        return self.core.collision is not None and self.params.collision_check

    def snapshot(self) -> CellValidity:
        """The validity a plan uses: a copy of the driver's checker (its scene and padding now) and the
        workspace box."""
        checker = self.core.collision if self.collision_checked else None
        return CellValidity(checker.copy() if checker is not None else None, self.kin, self.params.workspace)

    def resolve(self, goal: PlanGoal) -> Tuple[Any, str, float, float]:
        """(the planner's goal, planner, budget [s], velocity scaling) or PlanningError('goal', ...)."""
        given = [goal.joints is not None, bool(goal.named), goal.pose is not None]
        if sum(given) != 1:
            raise PlanningError("request", "a goal is exactly one of joints, a named state or a pose (got %d)"
                                % sum(given))
        planner_id = goal.planner_id or self.params.planner_id
        if planner_id not in PLANNERS:
            raise PlanningError("request", "unknown planner_id %r: the planners are %s"
                                % (planner_id, ", ".join(PLANNERS)))
        budget = goal.planning_time if goal.planning_time else self.params.planning_time
        if not (isinstance(budget, (int, float)) and math.isfinite(budget) and 0.0 < budget <= 60.0):
            raise PlanningError("request", "allowed_planning_time must be in (0, 60] s (0: the parameter "
                                "planning_time), got %r" % (goal.planning_time,))
        scaling = goal.velocity_scaling if goal.velocity_scaling else self.params.velocity_scaling
        if not (isinstance(scaling, (int, float)) and math.isfinite(scaling) and 0.0 < scaling <= 1.0):
            raise PlanningError("request", "velocity_scaling must be in (0, 1] (0: the parameter "
                                "velocity_scaling), got %r" % (goal.velocity_scaling,))
        if goal.pose is not None:
            try:
                target = self.params.workspace.check(goal.pose)
            except VrDriverError as exc:
                raise PlanningError("request", "goal pose: %s" % exc) from None
        elif goal.named:
            target = goal.named
        else:
            names, positions = goal.joints
            if len(names) != len(positions) or len(set(names)) != len(names):
                raise PlanningError("request", "a joint goal needs one position per joint name, each name once "
                                    "(got %d names, %d positions)" % (len(names), len(positions)))
            expected = tuple(self.core.joint_names)
            if set(names) != set(expected):
                raise PlanningError("request", "a joint goal names every joint of the arm (%s), got %s"
                                    % (", ".join(expected), ", ".join(names) or "none"))
            by_name = dict(zip(names, positions))
            target = tuple(float(by_name[n]) for n in expected)
            if not all(math.isfinite(v) for v in target):
                raise PlanningError("request", "joint goal: every position must be a finite number, got %r"
                                    % (target,))
        return target, planner_id, float(budget), float(scaling)

    def plan(self, goal: PlanGoal, start: Optional[Sequence[float]] = None, seed: Optional[int] = None
             ) -> PlanOutcome:
        """Plan ``goal`` from ``start`` (default: the arm's joints now; motion need not be possible:
        a preview is allowed while the arm cannot move). Never raises for a bad goal: the outcome says."""
        t0 = self.clock()
        try:
            target, planner_id, budget, scaling = self.resolve(goal)
        except PlanningError as exc:
            return PlanOutcome(INVALID_GOAL, "refused: %s" % exc, planner_id=goal.planner_id)
        if start is None:
            start = joints_to_plan_from(self.core.status())
            if isinstance(start, str):
                return PlanOutcome(INVALID_ROBOT_STATE, start, planner_id=planner_id)
        refusal = ""
        prof: Dict[str, Any] = {"crossing": 0.0, "snapshot": 0.0, "planner": 0.0, "stream_check": 0.0, "checks": 0,
                                "tries": 0, "replans": []}
        tick = time.perf_counter()
        try:
            crossings, target = self._elbow_crossings(tuple(start), target)
        except PlanningError:
            crossings = ()          # (the planner says why, below)
        prof["crossing"] = time.perf_counter() - tick
        validity = None
        first = 0                       # the first try of the crossings
        given = target                  # the goal as given (a pose: every solution)
        switched = False                # the crossings are to a pose's solution across the stretch
        search = planner_id             # the try's search: another after one that found no path
        for attempt in range(ATTEMPTS):
            if validity is not None:
                prof["checks"] += validity.counter[0]
            # each try its own crossing while there are others: one whose leg found no path is walled in
            crossing = crossings[min(attempt - first, len(crossings) - 1)] if crossings else ()
            # a joint goal with joint_5 of the other sign: the wrist margin would wall every path off
            wrist_across = isinstance(target, tuple) and len(target) == len(start) \
                and start[_WRIST] * target[_WRIST] < 0.0
            prof["tries"] += 1
            tick = time.perf_counter()
            try:
                with self._lock:
                    with self.core.planning_gate:     # the checker is replaced as a whole under it
                        validity = self.snapshot()
                    self.roadmap.keep(cell_key(validity))
                    prof["snapshot"] += time.perf_counter() - tick
                    planner = Planner(self.kin, validity, planner=search, time_budget=budget,
                                      seed=None if seed is None else seed + attempt, velocity_scaling=scaling,
                                      acceleration_scaling=scaling, planning_validity=self._planning_validity(
                                          validity, wrist_margin=attempt < ATTEMPTS - 1 and not wrist_across,
                                          elbow_margin=attempt < ATTEMPTS - 1 and not crossing),
                                      goal_preference=self._candidate_rank(
                                          wrist=attempt < ATTEMPTS - 1 and not wrist_across), roadmap=self.roadmap,
                                      leg_validity=self._elbow_sides() if crossing else None)
                    held = ConfigurationRule.parse(self.params.controller.configuration) \
                        is ConfigurationRule.CURRENT_JOINTS
                    retreat = retreat_waypoints(self.last_path, tuple(start), () if switched or not held else crossing,
                                                attempt, prof["replans"], self._stretch())
                    if retreat:
                        prof["retreat"] = 1
                        if crossing and not held:
                            # back the way the arm came (to before the stretch where the last plan
                            # crossed it), then across the stretch there (the hood cell's query 37:
                            # out from under the hood's top on the start's side walled in)
                            crossing = self._crossing_back(planner, validity, retreat[-1], target) or crossing
                        else:
                            # back the way the arm came, then to any solution of the goal as given
                            target, crossing = given, ()
                    plan = self._at_goal(planner, tuple(start), target) or \
                        plan_with_crossing(planner, tuple(start), target, crossing, retreat)
            except PlanningError as exc:
                prof["planner"] += time.perf_counter() - tick
                if exc.step in ("plan", "time", "check") and attempt < ATTEMPTS - 1:
                    prof["replans"].append("%s: %s" % (exc.step, str(exc)[:80]))
                    if exc.step == "plan":
                        search = retry_planner(planner_id)
                        if not crossings and goal.pose is not None:
                            # the pose's solutions on the start's side of the stretched elbow walled
                            # in: the next tries cross to the nearest valid one across it
                            try:
                                crossings, target = self._elbow_crossings(tuple(start), target, across=True)
                            except PlanningError:
                                crossings = ()
                            first, switched = attempt + 1, bool(crossings)
                    continue
                prof["checks"] += validity.counter[0] if validity is not None else 0
                return PlanOutcome(code_of(exc), "%s: %s" % (_STEP_WORDS.get(exc.step, "refused"), exc),
                                   planning_time=self.clock() - t0, planner_id=planner_id, contacts=exc.contacts,
                                   profile=prof)
            except (VrDriverError, ValueError, TypeError) as exc:
                return PlanOutcome(INVALID_GOAL, "refused: %s" % exc, planning_time=self.clock() - t0,
                                   planner_id=planner_id)
            prof["planner"] += time.perf_counter() - tick
            for key, value in plan.timings.items():
                prof[key] = prof.get(key, 0.0) + value
            tick = time.perf_counter()
            refusal = self.driver_refusal(plan)
            prof["stream_check"] += time.perf_counter() - tick
            if not refusal:
                break
            prof["replans"].append("stream: %s" % refusal[:80])
        else:
            prof["checks"] += validity.counter[0] if validity is not None else 0
            return PlanOutcome(INVALID_MOTION_PLAN, "the driver would refuse each of %d plans, the last: %s%s"
                               % (ATTEMPTS, refusal, self._across_the_elbow(start, plan.goal)),
                               planning_time=self.clock() - t0, planner_id=planner_id, profile=prof)
        prof["checks"] += validity.counter[0] if validity is not None else 0
        elapsed = self.clock() - t0
        end = self.kin.fk_pose(plan.goal)
        if len(plan.times) == 1:
            text = "planned with %s in %.0f ms: the arm is at the goal, nothing to move" % (planner_id, elapsed * 1e3)
        else:
            text = ("planned with %s in %.0f ms: %d points over %.2f s (velocity scaling %g)"
                    % (planner_id, elapsed * 1e3, len(plan.times), plan.duration, scaling))
        if search != planner_id:
            text += "; its last try searched with %s (%s found no path)" % (search, planner_id)
        if not self.collision_checked:
            text += "; collisions NOT checked (collision_check: false)"
        self.last_path = tuple(tuple(q) for q in plan.path)
        stream, previews = self._prepared[1:] if self._prepared[0] is plan else ((), ())
        return PlanOutcome(SUCCESS, text, plan, elapsed, planner_id, end, profile=prof, stream=stream,
                           previews=previews)


    def _at_goal(self, planner: Planner, start: Tuple[float, ...], target: Any) -> Optional[PlannedTrajectory]:
        """A one-point trajectory (at rest where the arm is) when a joint solution of the goal is within
        AT_GOAL of ``start`` on every joint, else None. The planner times such a move of 1e-6..1e-5 rad
        not at all (TOPP-RA finds no timing), and the arm reported at a named state is that close to it
        (its joints are the IK of the reported pose)."""
        near = [q for q in planner.goal_candidates(start, target)
                if max(abs(a - b) for a, b in zip(q, start)) <= AT_GOAL]
        if not near:
            return None
        zero = (0.0,) * len(start)
        return PlannedTrajectory(tuple(planner.names), (0.0,), (start,), (zero,), (zero,), (start,),
                                 planner.planner_name, {"total": 0.0})

    def _across_the_elbow(self, start: Sequence[float], goal: Sequence[float]) -> str:
        """"" -- or, with a Cartesian protocol and ``goal`` on the other side of the stretched elbow
        from ``start``, why that matters, in words."""
        rank = self._goal_preference()
        if rank is None or not rank(start, goal):
            return ""
        return ("; the goal (joint_3 %.1f deg) is across the stretched elbow (joint_3 %.1f deg) from the start "
                "(%.1f deg): the controller solves each pose nearest its previous target, which there is often "
                "the start's elbow branch -- a goal on the start's side, a path through a pose goal's other "
                "solutions, or a protocol with joint targets (v2) avoids it"
                % (math.degrees(goal[_ELBOW]), math.degrees(stretched_elbow(self.kin)), math.degrees(start[_ELBOW])))

    def _elbow_sides(self):
        """With a Cartesian protocol, :func:`elbow_side_legs` of the stretched elbow (None with joint
        targets)."""
        stretched = self._stretch()
        return None if stretched is None else elbow_side_legs(stretched)

    def _stretch(self) -> Optional[float]:
        """The stretched elbow's joint_3 with a Cartesian protocol (None with joint targets)."""
        return None if self._goal_preference() is None else stretched_elbow(self.kin)

    def _goal_preference(self):
        """With a Cartesian protocol, the rank of a pose goal's IK solution: 0 on the start's side of
        the stretched elbow, 1 across it. The controller solves each target nearest the previous
        one: across the stretch the two elbow branches of a pose lie either side of it, the nearer
        is the start's, so a stream that must change the branch is refused by the driver's check far
        more often than not (bench/planning.py: 4 of the last 10 failures). A joint goal is what it
        is; None (nearest first) with joint targets."""
        if self.core.wire.joint_targets:
            return None
        stretched = stretched_elbow(self.kin)
        if stretched is None:
            return None

        def rank(start: Sequence[float], q: Sequence[float]) -> int:
            side = math.remainder(start[_ELBOW] - stretched, 2.0 * math.pi)
            other = math.remainder(q[_ELBOW] - stretched, 2.0 * math.pi)
            return 0 if side * other >= 0.0 else 1
        return rank

    def _candidate_rank(self, wrist: bool):
        """The rank of a pose goal's IK solution the planner orders them by (lower first, then the
        nearest): with a Cartesian protocol, :meth:`_goal_preference`'s (the start's elbow branch
        first) and, while the plan keeps the wrist margin (``wrist``), the solutions with joint_5
        on the start's side of 0 before the others: the margin walls joint_5 = 0 off, and the nearest
        solution across it cost a try half its budget to find no path (bench/planning.py: 3 of
        10 pose goals; their next solutions, on the start's side, were planned in the rest). A start
        within the margin of 0 leaves both sides open. None with joint targets."""
        elbow = self._goal_preference()
        if elbow is None:
            return None
        if not wrist:
            return elbow

        def rank(start: Sequence[float], q: Sequence[float]) -> int:
            across = abs(start[_WRIST]) >= WRIST_MARGIN and start[_WRIST] * q[_WRIST] < 0.0
            return 2 * elbow(start, q) + int(across)
        return rank

    def _crossing_back(self, planner: Planner, validity: CellValidity, point: Tuple[float, ...],
                       goal: Tuple[float, ...]) -> Tuple[Tuple[float, ...], ...]:
        """The waypoints of the crossing of the stretched elbow from ``point`` (a retreat's end, just
        before the stretch where the last plan crossed it) to the joint goal ``goal`` nearest
        ``point`` by the sweep bound (:func:`elbow_crossings`: with ``point``'s other joints first, if
        valid -- the last plan crossed there), or ()."""
        found = elbow_crossings(point, goal, stretched_elbow(self.kin), self._planning_validity(
            validity, wrist_margin=False, elbow_margin=False), self.kin.limits)
        if not found:
            return ()
        return min(found, key=lambda pair: sum(w * abs(a - b) for w, a, b in zip(planner.weights, point, pair[0])))

    def _elbow_crossing(self, start: Tuple[float, ...], target: Any) -> Tuple[Tuple[Tuple[float, ...], ...], Any]:
        """(the two waypoints of :meth:`_elbow_crossings`' first crossing, or (), the target)."""
        crossings, target = self._elbow_crossings(start, target)
        return (crossings[0] if crossings else ()), target

    def _elbow_crossings(self, start: Tuple[float, ...], target: Any, across: bool = False
                         ) -> Tuple[Tuple[Tuple[Tuple[float, ...], ...], ...], Any]:
        """(:func:`elbow_crossings`: a try's each, the target) with a Cartesian protocol and a goal
        across the stretch from ``start`` -- a joint goal, a named state, or a pose with no valid
        solution on the start's side (the target then its valid solution the planner would take) or,
        ``across``, its nearest valid one across (its start's side walled in); else ((), ``target``)."""
        rank = self._goal_preference()
        stretched = stretched_elbow(self.kin)
        if rank is None or stretched is None:
            return (), target
        pose = not isinstance(target, str) and pose_target(self.kin, target) is not None
        goal = self.kin.named_states.get(target) if isinstance(target, str) else target
        if not pose and (goal is None or len(goal) != len(start) or not rank(start, goal)):
            return (), target     # (a goal on the start's side: no copy of the checker made)
        with self.core.planning_gate:
            validity = self.snapshot()
        if pose:
            planner = Planner(self.kin, validity, goal_preference=rank)
            valid = [q for q in planner.goal_candidates(start, target) if planner.is_valid(q)]
            if across:
                valid = [q for q in valid if rank(start, q)]
            if not valid or not rank(start, valid[0]):
                return (), target
            goal = valid[0]
        found = elbow_crossings(start, goal, stretched, self._planning_validity(
            validity, wrist_margin=False, elbow_margin=False), self.kin.limits)
        return found, (tuple(goal) if found else target)

    def _planning_validity(self, validity: CellValidity, wrist_margin: bool = True, elbow_margin: bool = True):
        """What the planner plans with (away from the start and the goal): ``validity`` padded by the
        planner's clearance and, with a Cartesian protocol, |joint_5| >= WRIST_MARGIN (``wrist_margin``)
        and joint_3 ELBOW_MARGIN from the stretched arm (``elbow_margin``). The margins wall joint_5 = 0
        and the stretch off, and a goal on the other side of one (joint_5 of the other sign, the
        other elbow branch, farther than the start's and goal's own zones) then has no path at all:
        :meth:`plan` drops the wrist's for a joint goal with joint_5 of the other sign, the elbow's
        for a plan through the stretch (:meth:`_elbow_crossing`), and both on its last try; without
        them the driver's stream check still decides whether the controller would run the plan."""
        strict = validity.copy()
        strict.set_padding(validity.padding + DEFAULT_CLEARANCE)
        if self.core.wire.joint_targets or not (wrist_margin or elbow_margin):
            return BatchValidity(lambda q: not strict.in_collision(q), strict.first_invalid)
        return margin_validity(strict, wrist_margin, stretched_elbow(self.kin) if elbow_margin else None)

    def driver_refusal(self, plan: PlannedTrajectory) -> str:
        """Why the driver would refuse ``plan``, "" when it would not (:func:`driver_sends`); what it
        sends for a plan it takes is kept for that plan's outcome. Call it without the planning gate."""
        refusal, stream, previews = driver_sends(self.core, self.kin, plan)
        if not refusal:
            self._prepared = (plan, stream, previews)
        return refusal


def plan_with_crossing(planner: Planner, start: Tuple[float, ...], target: Any,
                       crossing: Tuple[Tuple[float, ...], ...], before: Tuple[Tuple[float, ...], ...] = ()
                       ) -> PlannedTrajectory:
    """``planner``'s plan from ``start`` through ``before`` (a retreat's waypoints) to ``target``
    through ``crossing`` (:meth:`PlanActionCore._elbow_crossing`'s waypoints, or none). A crossing's plan comes to
    rest at its first waypoint, holds ELBOW_HOLD there (a pause: the next target goes out once the
    arm is at rest there, StreamSequencer.record) and turns joint_3 from rest: passed at speed,
    the stream's points around the stretch lay too far apart for the G2 to change branch on
    them, and the driver's stream check refused the plan (the hood cell's queries 37 and 38; a
    turn from 30 deg before the stretch at full speed refused at three of four crossings, the
    same turn from rest at the first waypoint at none); and a G2 that solves a target nearest
    its joints when it takes it (``current_joints``) solves the target past the stretch from
    there. The search before the hold gets half the budget when the legs after it search too,
    those the rest."""
    if not crossing:
        return planner.plan(start, target, via=before)
    near, past = crossing
    budget = planner.time_budget
    first = planner.plan(start, near, via=before,
                         time_budget=budget / 2.0 if planner.leg_searches(past, (target,)) else budget)
    left = max(budget - first.timings.get("plan", 0.0), 1e-3)
    # (the legs after the hold seeded as in one plan through all the waypoints: leg k, seed + k)
    seed = None if planner.seed is None else planner.seed + len(before) + 1
    return first.then(planner.plan(near, target, via=(past,), time_budget=left, seed=seed), ELBOW_HOLD)


def driver_sends(core: Any, kin: Kinematics, plan: PlannedTrajectory) -> Tuple[str, Tuple[Any, ...], Tuple[Any, ...]]:
    """What ``core`` (a DriverCore or the planning process's parts) would send for ``plan`` and why it
    would refuse it: ("", its stream points, its previews) or (the refusal, (), ()). Checked as
    ``submit_trajectory`` checks it (``core.prepare_trajectory``) -- a streaming protocol's stream (its
    points: their configurations with a Cartesian protocol, and their segments); v1's PTP moves between
    the plan's thinned stop points, each previewed as the controller runs it, a straight joint move,
    against the box and the cell (the plan's samples between two stop points are not what v1 runs).
    The checks take the planning gate."""
    if len(plan.positions) < 2:
        return "", (), ()
    from ..motion.trajectories import TrajectoryGoal, validate
    lim = kin.limits
    try:
        traj = validate(TrajectoryGoal.of(plan), tuple(plan.joint_names), plan.positions[0], lim.lower,
                        lim.upper, 0.0)
        _kept, points, previews = core.prepare_trajectory(traj, traj.positions[0])
    except VrDriverError as exc:
        return str(exc), (), ()
    return "", tuple(points), tuple(previews)


_STEP_WORDS = {"start": "cannot plan from here", "goal": "goal refused", "plan": "no path found",
               "time": "no timing found", "check": "the planned trajectory failed its check"}


def retry_planner(planner_id: str) -> str:
    """The search of a try after one that found no path with ``planner_id``: RETRY_PLANNER, or
    RRTConnect when that was the one."""
    return RETRY_PLANNER if planner_id != RETRY_PLANNER else "RRTConnect"


def retreat_waypoints(path: Optional[Tuple[Tuple[float, ...], ...]], start: Tuple[float, ...],
                      crossing: Tuple[Tuple[float, ...], ...], attempt: int,
                      replans: List[str], stretched: Optional[float] = None) -> Tuple[Tuple[float, ...], ...]:
    """Waypoints back along the last plan's ``path`` (its start last) -- for the last try of a plan
    from where that plan ended after every try before found no path: the arm got here along it,
    so it leads out of a narrow place (under the hood's top, between walls), and from its start
    the planner searches for what the straight legs back left of the budget. () otherwise: not
    the last try, a try failed for another reason, an elbow crossing's waypoints, no last plan
    or one that ended farther than RETREAT_NEAR from ``start`` (every joint; the arm stops near the
    plan's end, not on it). Nothing of it is taken on trust: every leg is checked (and, if
    not free, planned) by this plan's own validity, the cell as it is now, and the driver checks
    the plan's stream as any other's. ``stretched`` (the stretched elbow's joint_3, with a
    Cartesian protocol): the way back ends before the last plan's path crosses it -- its elbow
    crossing run backwards turns joint_3 from past the stretch to near it, where the controller
    keeps the branch it is on (the hood cell's query 41: refused)."""
    if attempt != ATTEMPTS - 1 or crossing or not path or len(path) < 2 \
            or max(abs(a - b) for a, b in zip(path[-1], start)) > RETREAT_NEAR \
            or len(replans) != attempt or not all(r.startswith("plan:") for r in replans):
        return ()
    back = []
    for q in reversed(path[:-1]):
        if stretched is not None and (q[_ELBOW] - stretched) * (start[_ELBOW] - stretched) <= 0.0:
            break
        back.append(tuple(q))
    return tuple(back)
