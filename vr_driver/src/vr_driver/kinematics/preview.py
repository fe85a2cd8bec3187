"""Motion preview: joint trajectories for PTP, LIN and CIRC moves from the current joints. ROS-free.

- PTP: joint-space interpolation from the current joints to the IK solution of the target nearest to
  them (or to given goal joints).
- LIN: the TCP on the straight segment from its current pose to the target, orientation by slerp; IK
  per step (steps of at most ``max_cartesian_step`` / ``max_angular_step``), each seeded by the
  previous step.
- CIRC: the TCP on the arc from its current pose through the via point to the end point, orientation
  by slerp from the start to the end orientation (the via point's orientation is not used); IK per
  step as for LIN.

Timing: one trapezoidal profile s(t) (accelerate during ``ramp_fraction`` of the duration, cruise,
decelerate) shared by all joints, stretched until no joint exceeds ``velocity_scale`` x its velocity
limit between any two samples and the TCP does not exceed ``linear_speed`` / ``angular_speed``
(LIN, CIRC). The trajectory is piecewise linear in joint space between samples, so these checks are
exact for what is returned.

Rejections, each with the reason and the step (vr_driver.errors): ``UnreachableError`` /
``JointLimitError`` (a step has no IK solution within limits), ``MotionError`` (a joint jump larger
than ``max_joint_step`` between two samples: a configuration change or a singularity on the way; a
degenerate circle), ``NearSingularError`` (manipulability below ``min_manipulability`` on a
Cartesian path), ``PathDeviationError`` (the joint-space chord between two samples leaves the path by
more than ``path_tolerance``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, List, Optional, Sequence, Tuple

import numpy as np

from .. import validate
from ..errors import EnvelopeError, KinematicsError, MotionError, NearSingularError, PathDeviationError, PoseError
from .solver import Kinematics
from ..poses import ControllerPose, MoveType, Workspace, matrix_to_quaternion, quaternion_slerp, quaternion_to_matrix

__all__ = ["MoveType", "MotionSettings", "Trajectory", "MovePreviewer", "trapezoid_tau", "check_envelope"]


@dataclass(frozen=True)
class MotionSettings:
    """Interpolation and timing settings (SI units: m, rad, s)."""

    velocity_scale: float = 1.0          # fraction of the joint velocity limits, (0, 1]
    linear_speed: float = 0.25           # TCP speed limit for LIN / CIRC [m/s]
    angular_speed: float = 1.0           # TCP orientation speed limit for LIN / CIRC [rad/s]
    ramp_fraction: float = 0.2           # share of the duration spent accelerating (and decelerating)
    max_cartesian_step: float = 0.005    # LIN / CIRC sample spacing [m]
    max_angular_step: float = math.radians(2.0)  # LIN / CIRC sample spacing in orientation [rad]
    ptp_step: float = 0.02               # PTP sample spacing of the largest joint motion [rad]
    max_joint_step: float = 0.15         # a larger joint change between two Cartesian samples is a jump [rad]
    min_manipulability: float = 1e-3     # Cartesian paths below this are near-singular
    path_tolerance: float = 0.001        # allowed deviation of the chord midpoints from the path [m]

    def __post_init__(self) -> None:
        checks = {
            "velocity_scale": 0.0 < self.velocity_scale <= 1.0,
            "linear_speed": self.linear_speed > 0.0,
            "angular_speed": self.angular_speed > 0.0,
            "ramp_fraction": 0.0 <= self.ramp_fraction < 0.5,
            "max_cartesian_step": self.max_cartesian_step > 0.0,
            "max_angular_step": self.max_angular_step > 0.0,
            "ptp_step": self.ptp_step > 0.0,
            "max_joint_step": self.max_joint_step > 0.0,
            "min_manipulability": self.min_manipulability >= 0.0,
            "path_tolerance": self.path_tolerance > 0.0,
        }
        for name, ok in checks.items():
            value = getattr(self, name)
            if not (validate.as_finite(value, text=False) is not None and ok):
                raise MotionError("motion setting %s = %r is out of range" % (name, value))


def trapezoid_tau(s: float, ramp: float) -> float:
    """Normalised time tau in [0, 1] at which a trapezoidal profile with ramp share ``ramp``
    reaches the path parameter ``s`` in [0, 1] (peak speed 1 / (1 - ramp))."""
    s = min(1.0, max(0.0, s))
    if ramp <= 0.0:
        return s
    v = 1.0 / (1.0 - ramp)
    s_ramp = 0.5 * v * ramp
    if s <= s_ramp:
        return math.sqrt(2.0 * ramp * s / v)
    if s <= 1.0 - s_ramp:
        return ramp + (s - s_ramp) / v
    return 1.0 - math.sqrt(max(0.0, 2.0 * ramp * (1.0 - s) / v))


@dataclass(frozen=True, eq=False)
class Trajectory:
    """A timed joint trajectory with the TCP pose (in ``base``) at every sample."""

    move_type: MoveType
    joint_names: Tuple[str, ...]
    times: np.ndarray          # (N,) seconds from the start
    positions: np.ndarray      # (N, dof) radians
    tcp: np.ndarray            # (N, 4, 4) TCP in ``base``, metres

    @property
    def duration(self) -> float:
        return float(self.times[-1])

    @property
    def start(self) -> Tuple[float, ...]:
        return tuple(float(v) for v in self.positions[0])

    @property
    def goal(self) -> Tuple[float, ...]:
        return tuple(float(v) for v in self.positions[-1])

    def poses(self) -> List[ControllerPose]:
        return [ControllerPose.from_matrix(t) for t in self.tcp]

    def velocities(self) -> np.ndarray:
        """(N-1, dof) mean joint velocities between consecutive samples."""
        if len(self.times) < 2:
            return np.zeros((0, self.positions.shape[1]))
        return np.diff(self.positions, axis=0) / np.diff(self.times)[:, None]

    def __len__(self) -> int:
        return len(self.times)


class MovePreviewer:
    """Previews one move: builds the PTP / LIN / CIRC trajectory the controller will run, on a
    :class:`Kinematics` (its frame conventions, TCP and limits). Poses are controller poses
    (ControllerPose or (X, Y, Z mm, Rx, Ry, Rz deg)). No obstacles, no search: collision-free paths
    are planned by :class:`~vr_driver.kinematics.planner.Planner` (OMPL), the plan action runs it
    (:class:`~vr_driver.driver.planning.planning.PlanActionCore`)."""

    def __init__(self, kinematics: Kinematics, settings: Optional[MotionSettings] = None):
        self.kin = kinematics
        self.settings = settings or MotionSettings()
        self._vmax = np.array(kinematics.limits.velocity, dtype=float) * self.settings.velocity_scale

    # ----------------------------------------------------------------------------------- public
    def plan(self, move_type: Any, start_joints: Sequence[float], target: Any,
             via: Any = None) -> Trajectory:
        kind = MoveType.parse(move_type)
        if kind is MoveType.PTP:
            return self.ptp(start_joints, target)
        if kind is MoveType.LIN:
            return self.lin(start_joints, target)
        if via is None:
            raise MotionError("a CIRC move needs a via pose")
        return self.circ(start_joints, via, target)

    def estimate_duration(self, move_type: Any, start_joints: Sequence[float], target: Any,
                          via: Any = None) -> float:
        """Duration [s] of the move (the whole trajectory is planned, so errors surface here too)."""
        return self.plan(move_type, start_joints, target, via).duration

    def ptp(self, start_joints: Sequence[float], target: Any) -> Trajectory:
        """Joint interpolation to the IK solution of the target pose nearest the start joints."""
        start = self.kin.check_limits(start_joints)
        pose = self._pose(target, "target")
        try:
            goal = self.kin.ik_pose(pose, seed=start)
        except KinematicsError as exc:
            raise type(exc)("PTP target %s: %s" % (_fmt_pose(pose), exc)) from exc
        return self._ptp(start, goal)

    def ptp_joints(self, start_joints: Sequence[float], goal_joints: Sequence[float]) -> Trajectory:
        start = self.kin.check_limits(start_joints)
        goal = self.kin.check_limits(goal_joints)
        return self._ptp(start, goal)

    def lin(self, start_joints: Sequence[float], target: Any) -> Trajectory:
        start = self.kin.check_limits(start_joints)
        pose = self._pose(target, "target")
        t0 = self._tcp(start)
        t1 = pose.to_matrix()
        self._check_reachable(pose, start, "LIN target")
        p0, p1 = t0[:3, 3], t1[:3, 3]
        length = float(np.linalg.norm(p1 - p0))

        def position(s: float) -> np.ndarray:
            return p0 + s * (p1 - p0)

        def deviation(point: np.ndarray) -> float:
            d = p1 - p0
            if length < 1e-12:
                return float(np.linalg.norm(point - p0))
            s = min(1.0, max(0.0, float((point - p0) @ d) / (length * length)))
            return float(np.linalg.norm(point - (p0 + s * d)))

        return self._cartesian(MoveType.LIN, start, t0, t1, length, position, deviation)

    def circ(self, start_joints: Sequence[float], via: Any, target: Any) -> Trajectory:
        start = self.kin.check_limits(start_joints)
        via_pose = self._pose(via, "via")
        pose = self._pose(target, "target")
        t0 = self._tcp(start)
        t1 = pose.to_matrix()
        self._check_reachable(pose, start, "CIRC target")
        p0, pv, p2 = t0[:3, 3], via_pose.to_matrix()[:3, 3], t1[:3, 3]
        centre, normal, radius = _circle(p0, pv, p2)
        u = (p0 - centre) / radius
        v = np.cross(normal, u)

        def angle(p: np.ndarray) -> float:
            a = math.atan2(float((p - centre) @ v), float((p - centre) @ u))
            return a if a >= 0.0 else a + 2.0 * math.pi

        sweep = angle(p2)          # with this normal, start -> via -> end runs in the positive sense
        length = radius * sweep

        def position(s: float) -> np.ndarray:
            a = s * sweep
            return centre + radius * (math.cos(a) * u + math.sin(a) * v)

        def deviation(point: np.ndarray) -> float:
            rel = point - centre
            out_of_plane = float(rel @ normal)
            in_plane = rel - out_of_plane * normal
            return math.hypot(out_of_plane, float(np.linalg.norm(in_plane)) - radius)

        return self._cartesian(MoveType.CIRC, start, t0, t1, length, position, deviation)

    # ---------------------------------------------------------------------------------- helpers
    @staticmethod
    def _pose(value: Any, what: str) -> ControllerPose:
        if isinstance(value, ControllerPose):
            return value
        try:
            return ControllerPose.from_sequence(value)
        except PoseError as exc:
            raise PoseError("%s: %s" % (what, exc)) from exc

    def _tcp(self, q: Sequence[float]) -> np.ndarray:
        return self.kin.conventions.tip_to_tcp(self.kin.fk(q))

    def _check_reachable(self, pose: ControllerPose, seed: Sequence[float], what: str) -> None:
        """Fail before sampling when the end pose itself has no solution."""
        try:
            self.kin.ik_pose(pose, seed=seed)
        except KinematicsError as exc:
            raise type(exc)("%s %s: %s" % (what, _fmt_pose(pose), exc)) from exc

    def _ptp(self, start: Tuple[float, ...], goal: Tuple[float, ...]) -> Trajectory:
        q0, q1 = np.array(start), np.array(goal)
        span = float(np.max(np.abs(q1 - q0)))
        n = max(1, int(math.ceil(span / self.settings.ptp_step)))
        s = np.linspace(0.0, 1.0, n + 1)
        positions = q0[None, :] + s[:, None] * (q1 - q0)[None, :]
        tcp = np.array([self._tcp(q) for q in positions])
        return self._timed(MoveType.PTP, s, positions, tcp, 0.0, 0.0)

    def _cartesian(self, kind: MoveType, start, t0, t1, length, position, deviation) -> Trajectory:
        cfg = self.settings
        q_start, q_end = matrix_to_quaternion(t0[:3, :3]), matrix_to_quaternion(t1[:3, :3])
        r_rel = t0[:3, :3].T @ t1[:3, :3]
        turn = math.acos(max(-1.0, min(1.0, (float(np.trace(r_rel)) - 1.0) / 2.0)))
        n = max(1, int(math.ceil(length / cfg.max_cartesian_step)), int(math.ceil(turn / cfg.max_angular_step)))
        s_values = np.linspace(0.0, 1.0, n + 1)
        name = kind.name
        conv = self.kin.conventions
        positions = [np.array(start)]
        tcp = [t0]
        q_prev = start
        for k in range(1, n + 1):
            s = float(s_values[k])
            target = np.eye(4)
            target[:3, :3] = quaternion_to_matrix(quaternion_slerp(q_start, q_end, s))
            target[:3, 3] = position(s)
            where = "%s step %d of %d at %s" % (name, k, n, _fmt_point(target[:3, 3]))
            try:
                q = self.kin.ik(conv.tcp_to_tip(target), seed=q_prev)
            except KinematicsError as exc:
                raise type(exc)("%s: %s" % (where, exc)) from exc
            jump = np.abs(np.array(q) - np.array(q_prev))
            worst = int(np.argmax(jump))
            if jump[worst] > cfg.max_joint_step:
                raise MotionError("%s: %s jumps by %.3f rad (limit %.3f per step): a configuration change "
                                  "or a singularity on the way" % (where, self.kin.joint_names[worst],
                                                                    float(jump[worst]), cfg.max_joint_step))
            w = self.kin.manipulability(q)
            if w < cfg.min_manipulability:
                raise NearSingularError("%s: near a singularity (manipulability %.2g below %.2g)"
                                        % (where, w, cfg.min_manipulability))
            # the robot moves linearly in joint space between samples: check the chord's midpoint
            mid = self._tcp(0.5 * (np.array(q) + np.array(q_prev)))
            dev = deviation(mid[:3, 3])
            if dev > cfg.path_tolerance:
                raise PathDeviationError("%s: the path between samples deviates %.2f mm (tolerance %.2f mm)"
                                         % (where, dev * 1e3, cfg.path_tolerance * 1e3))
            positions.append(np.array(q))
            tcp.append(target)
            q_prev = q
        return self._timed(kind, s_values, np.array(positions), np.array(tcp), length, turn)

    def _timed(self, kind: MoveType, s: np.ndarray, positions: np.ndarray, tcp: np.ndarray,
               length: float, turn: float) -> Trajectory:
        cfg = self.settings
        lower, upper = np.array(self.kin.limits.lower), np.array(self.kin.limits.upper)
        outside = np.any((positions < lower[None, :] - 1e-9) | (positions > upper[None, :] + 1e-9), axis=1)
        if np.any(outside):
            k = int(np.argmax(outside))
            raise MotionError("%s trajectory leaves the joint limits at sample %d of %d: %s"
                              % (kind.name, k, len(positions) - 1,
                                 "; ".join(self.kin.limit_violations(positions[k]))))
        tau = np.array([trapezoid_tau(float(v), cfg.ramp_fraction) for v in s])
        dtau = np.diff(tau)
        dq = np.abs(np.diff(positions, axis=0))
        ds = np.diff(s)
        if len(dtau) == 0 or float(np.max(dq, initial=0.0)) == 0.0 and length == 0.0 and turn == 0.0:
            times = np.zeros(len(s))
            return Trajectory(kind, self.kin.joint_names, times, positions, tcp)
        need = [float(np.max(dq / (self._vmax[None, :] * dtau[:, None])))]
        if length > 0.0:
            need.append(float(np.max(ds * length / (cfg.linear_speed * dtau))))
        if turn > 0.0:
            need.append(float(np.max(ds * turn / (cfg.angular_speed * dtau))))
        duration = max(need)
        times = duration * tau
        traj = Trajectory(kind, self.kin.joint_names, times, positions, tcp)
        vel = np.abs(traj.velocities())
        if np.any(vel > self._vmax[None, :] * (1.0 + 1e-9)):  # cannot happen by construction: guard anyway
            raise MotionError("%s trajectory exceeds a joint velocity limit" % kind.name)
        return traj


def peak_tcp_speed(trajectory: Trajectory) -> float:
    """[mm/s] the TCP's largest speed along ``trajectory`` (between consecutive samples)."""
    if len(trajectory.times) < 2:
        return 0.0
    dt = np.diff(trajectory.times)
    dp = np.linalg.norm(np.diff(trajectory.tcp[:, :3, 3], axis=0), axis=1) * 1e3
    moving = dt > 0.0
    return float(np.max(dp[moving] / dt[moving], initial=0.0))


def at_tcp_speed(trajectory: Trajectory, speed: Optional[float]) -> Trajectory:
    """``trajectory`` slowed down evenly (its times stretched) so that the TCP never moves faster than
    ``speed`` [mm/s]: how a program with a constant move speed runs a move (the v1 program's MOVEP /
    MOVEL speed, doc/controller_program.md section 10.9) -- never faster than the arm's own profile;
    None or a move whose TCP stays slower: unchanged."""
    peak = peak_tcp_speed(trajectory)
    if speed is None or peak <= speed:
        return trajectory
    return Trajectory(trajectory.move_type, trajectory.joint_names, trajectory.times * (peak / speed),
                      trajectory.positions, trajectory.tcp)


#: [mm, deg] how far a path sample may lie beyond a bound of the workspace box: float noise only.
#: A target on a bound (bounds are inclusive) is reached as FK(IK(pose)), a few 1e-13 mm off; the
#: next move starts there and must not be refused for it (that left the arm unable to move at all)
ENVELOPE_EPS = 1e-6


def check_envelope(trajectory: Trajectory, workspace: Workspace) -> None:
    """Every sample of ``trajectory`` (its TCP in ``base``) inside the workspace box, or
    EnvelopeError naming the first sample outside, its time and the field. Positions are checked
    on all samples at once; orientations (Rx, Ry, Rz are always within +-180) only when the box's
    angle range is narrower than that. The trajectory is piecewise linear in joint space between
    samples (what the arm follows), so a violation between two samples is bounded by the chord
    sag between them (well under a millimetre at the planner's sample spacing)."""
    tcp = trajectory.tcp
    if len(tcp) == 0:
        return
    xyz = tcp[:, :3, 3] * 1e3
    lo = np.array([workspace.x[0], workspace.y[0], workspace.z[0]]) - ENVELOPE_EPS
    hi = np.array([workspace.x[1], workspace.y[1], workspace.z[1]]) + ENVELOPE_EPS
    bad = np.any((xyz < lo[None, :]) | (xyz > hi[None, :]), axis=1)
    first = int(np.argmax(bad)) if np.any(bad) else None
    if workspace.angle[0] > -180.0 or workspace.angle[1] < 180.0:
        limit = len(tcp) if first is None else first
        for k in range(limit):
            if workspace.excess(ControllerPose.from_matrix(tcp[k])) > ENVELOPE_EPS:
                first = k
                break
    if first is None:
        return
    pose = ControllerPose.from_matrix(tcp[first])
    try:
        workspace.check(pose)
        why = "outside the workspace"
    except PoseError as exc:
        why = str(exc)
    raise EnvelopeError("%s path leaves the workspace at sample %d of %d (t = %.2f s, %s): %s"
                        % (trajectory.move_type.name, first, len(tcp) - 1,
                           float(trajectory.times[first]), _fmt_pose(pose), why))


def _circle(p0: np.ndarray, p1: np.ndarray, p2: np.ndarray) -> Tuple[np.ndarray, np.ndarray, float]:
    """(centre, unit normal, radius) of the circle through three points, normal = (p1-p0) x (p2-p0)."""
    a, b = p1 - p0, p2 - p0
    n = np.cross(a, b)
    nn = float(n @ n)
    if min(float(np.linalg.norm(a)), float(np.linalg.norm(b)), float(np.linalg.norm(p2 - p1))) < 1e-6:
        raise MotionError("CIRC: the start, via and end points must be distinct (at least 1 um apart)")
    if nn < 1e-12 * float(a @ a) * float(b @ b) or nn < 1e-18:
        raise MotionError("CIRC: the start, via and end points are collinear; use LIN")
    centre = p0 + (float(a @ a) * np.cross(b, n) + float(b @ b) * np.cross(n, a)) / (2.0 * nn)
    return centre, n / math.sqrt(nn), float(np.linalg.norm(p0 - centre))


def _fmt_point(p: Sequence[float]) -> str:
    return "(%.1f, %.1f, %.1f) mm" % (p[0] * 1e3, p[1] * 1e3, p[2] * 1e3)


def _fmt_pose(pose: ControllerPose) -> str:
    return "(%.1f, %.1f, %.1f mm, %.1f, %.1f, %.1f deg)" % pose.as_tuple()
