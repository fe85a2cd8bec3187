"""The arm's joints on the Cartesian protocols (v1, v3): the controller takes poses, solves them
with its own IK and reports only a pose back. ROS-free, no I/O; it runs on the bus thread.

One pose has many joint solutions (J1 front / back, elbow up / down, the wrist flipped, J4..J6 a
turn on), and near joint_5 = 0 (the wrist singularity) a pose fixes joint_4 + joint_6 but hardly
their split joint_4 - joint_6: a fresh IK of each report lands on whichever solution lies nearest
its seed, with the split the rounding of the report dictates (v1 whole mm / deg, v3 0.1 mm /
0.01 deg). The driver's joints are the start of every plan and what ``joint_states`` tells every
client, so they must be the arm's (README "Reliability").

:class:`JointTracker` knows what the arm was told instead and reads each report against it:

- **The commanded path** (:meth:`JointTracker.follow`, from the job in flight once it went out):
  v1 the job's validated plan -- a PTP's goal as the controller solves the wire pose by the
  configuration rule (:class:`~vr_driver.kinematics.solver.ConfigurationRule`, the driver's
  ``controller/configuration``: nearest the previous target's joints, or the arm's when it takes
  it -- the tracker's joints when the driver saw the target taken), a LIN / CIRC along its path
  from where it starts; v3 the stream's points, each solved as the controller solves its wire pose by the same
  rule, joined by the straight joint moves the controller runs between them. Sampled at most
  SAMPLE_STEP apart in every joint, with the TCP pose of every sample.
- **Where on it the arm is** (each new record): the reported pose projected onto the path
  (position in mm and rotation in deg, both rounding units alike), searched forward from where the
  arm was last seen (SEARCH_BACK samples back, for the rounding); of the places within PATH_NEAR
  the earliest that fits within PATH_TIE as well as the best, so that a path that comes back
  through a pose (a sweep out and back) is not read on its way back.
- **The joints**: v3 at a commanded target (within a sample of the place) its joints as the
  controller solved its wire pose, where the report's rounding allows them: at rest there the arm
  stands at exactly that solution (the report is the target's wire pose, rounded alike), not at a
  place the rounding leaves a hundredth of a degree away (v1's whole mm / deg would leave a
  degree: its goal is not taken so). Else that place's joints where the report's rounding allows
  them (our FK within the report's cell: half a unit in each of X, Y, Z, CELL_ROTATION units of
  rotation); otherwise the joints nearest them that the report allows: first with the commanded
  split of joint_4 / joint_6 (their sum and the other joints from the IK of the pose: near the
  singularity the pose leaves the split open and the commanded one holds), else towards the IK
  solution nearest the commanded joints. A v3 report the path does not explain is first read
  against the job's next points (TAKEN_AHEAD past those seen taken: the controller may have taken
  them before the driver saw it). Off the path (no job yet, a report it still does not explain)
  the same from the last joints.
- **Never a step the arm cannot make**: each joint moves at most as far as the commanded path
  moved between the two places, plus its velocity limit x the time since the last record x
  VELOCITY_MARGIN (the controller samples the arm at its own loop, not at the record's stamp). A
  corrupt record (a pose the path does not explain) moves the joints that much at most -- never
  onto another branch -- and the next good one back; a lost record only lengthens the time.
- **The arm's branch, not the commanded one**: a place on the path whose joints lie farther from
  the last joints than that (the same pose a turn of a joint away, or with the wrist flipped) is
  not where the arm is: the controller solved a target otherwise than the rule the driver
  applies (a G2 whose rule differs from ``controller/configuration``). The report is read off the
  path, from the last joints, so that the joints stay on the arm's branch, and the first such
  report of a path is a warning naming the rule (:attr:`JointTracker.off_branch` counts them).

The cost per record: one projection (numpy over the path's samples near the last place), a few
FK, at most one IK (the solver's time budget); per target taken one IK and the FK of its samples.
"""
from __future__ import annotations

import logging
import math
from typing import Any, List, Optional, Sequence, Tuple

import numpy as np
import PyKDL as kdl

from ...errors import KinematicsError
from ...kinematics.solver import ConfigurationRule, Kinematics
from ...poses import ControllerPose, MoveType
from ...protocol.base import rounded_pose
from .resolution import WRIST_BAND

log = logging.getLogger("vr_driver.driver")

__all__ = ["JointTracker", "CommandedPath", "VELOCITY_MARGIN", "PATH_NEAR", "PATH_TIE", "SAMPLE_STEP",
           "CELL_ROTATION", "TAKEN_AHEAD"]

#: [rad] the exact IK solution of a report may lie this far from the joints the tracker settled on
#: and still replace them (JointTracker._exact): the report's rounding, never another branch
EXACT_NEAR = math.radians(1.0)
#: the chain index of joint_5 (the wrist bend)
_WRIST5 = 4
#: a joint moves at most its velocity limit x the time between two records x this (the controller
#: writes its record at its own program loop: two records' samples may lie a loop further apart
#: than their stamps)
VELOCITY_MARGIN = 1.5
#: [mm, deg] a reported pose this near the commanded path (projected onto it) lies on it: the
#: report's rounding, a blended corner of a stream, the chord between two samples
PATH_NEAR = 5.0
#: [mm, deg] of two places on the path that fit a report this nearly as well, the earlier is the one
PATH_TIE = 1.0
#: [rad] the widest joint step between two samples of a commanded path (v3's straight segments are
#: sampled at it; a v1 plan's samples are closer)
SAMPLE_STEP = math.radians(2.0)
#: path samples before the last place the search for the next one begins at
SEARCH_BACK = 2
#: [units of the report's angle resolution] the rotation its rounding can hide: half a unit in each
#: of Rx, Ry, Rz, which near Ry = +-90 deg add up along one axis (sqrt(1 + 0.25) = 1.12)
CELL_ROTATION = 1.15
#: [units of the report's position resolution] per axis
CELL_POSITION = 0.5
#: the cell's margin for float noise (a share of it)
CELL_SLACK = 0.05
#: halvings of the search for the joints nearest the commanded ones that the report allows, at
#: most; it stops once the step is below BISECT_RESOLUTION [rad]
BISECT_STEPS = 8
BISECT_RESOLUTION = 1e-4
#: [rad] a PTP goal solved by the rule this near the plan's goal is the plan's
GOAL_EPS = 1e-6
#: v3: points past those the driver saw taken that the controller may have taken already: the
#: acknowledgement of a record comes two records late and v3 sends one target ahead, and the arm
#: (the virtual G2 at speed_factor 100, a real one after a bus stall) can reach them before the
#: driver's next record -- a report beyond the path is read against them before it is doubted
TAKEN_AHEAD = 4

_TWO_PI = 2.0 * math.pi


def _kdl_frame(t: np.ndarray) -> "kdl.Frame":
    return kdl.Frame(kdl.Rotation(*[float(v) for v in t[:3, :3].reshape(-1)]),
                     kdl.Vector(*[float(v) for v in t[:3, 3]]))


def _rotvec_deg(m: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Rotation vectors [deg] (k, 3) and angles [deg] (k,) of rotation matrices (k, 3, 3)."""
    trace = m[:, 0, 0] + m[:, 1, 1] + m[:, 2, 2]
    angle = np.arccos(np.clip(0.5 * (trace - 1.0), -1.0, 1.0))
    skew = 0.5 * np.stack([m[:, 2, 1] - m[:, 1, 2], m[:, 0, 2] - m[:, 2, 0], m[:, 1, 0] - m[:, 0, 1]], axis=1)
    sin = np.sin(angle)
    scale = np.where(sin > 1e-9, angle / np.maximum(sin, 1e-12), 1.0)
    return np.degrees(skew * scale[:, None]), np.degrees(angle)


class CommandedPath:
    """The joints the arm was commanded through, in order, sampled, with the TCP pose of every
    sample (position [mm], rotation in ``base``), and where on it the arm was last seen
    (:attr:`cursor`: samples from the start, fractional). ``key`` names what it was made from."""

    def __init__(self, key: Any, joints: np.ndarray, position: np.ndarray, rotation: np.ndarray) -> None:
        self.key = key
        self.q = np.zeros((0, joints.shape[1]))
        self.p = np.zeros((0, 3))
        self.r = np.zeros((0, 3, 3))
        self._step_p = np.zeros((0, 3))
        self._step_r = np.zeros((0, 3))
        self.cursor = 0.0
        self.seen_moving = False          # the arm was seen past its start (it took the target)
        self.targets: List[Tuple[float, ...]] = []   # v3: each point as the controller solves it
        self.target_samples: List[int] = []          # ... and its sample
        self.extend(joints, position, rotation)

    def __len__(self) -> int:
        return len(self.q)

    @property
    def goal(self) -> Tuple[float, ...]:
        return tuple(float(v) for v in self.q[-1])

    def extend(self, joints: np.ndarray, position: np.ndarray, rotation: np.ndarray) -> None:
        """Append samples (joints (k, dof), TCP position (k, 3) mm, rotation (k, 3, 3))."""
        first = len(self.q)
        self.q = np.concatenate([self.q, np.asarray(joints, dtype=float)])
        self.p = np.concatenate([self.p, np.asarray(position, dtype=float)])
        self.r = np.concatenate([self.r, np.asarray(rotation, dtype=float)])
        lo = max(0, first - 1)
        if len(self.q) - lo >= 2:
            rel = np.einsum("kji,kjl->kil", self.r[lo:-1], self.r[lo + 1:])
            step_r, _ = _rotvec_deg(rel)
            self._step_p = np.concatenate([self._step_p, self.p[lo + 1:] - self.p[lo:-1]])
            self._step_r = np.concatenate([self._step_r, step_r])

    def joints_at(self, place: float) -> Tuple[float, ...]:
        """The joints at ``place`` (samples from the start; linear between two samples, as the arm
        moves between a plan's samples)."""
        i = min(max(int(math.floor(place)), 0), len(self.q) - 1)
        a = place - i
        q = self.q[i] if a <= 0.0 or i + 1 >= len(self.q) else self.q[i] + a * (self.q[i + 1] - self.q[i])
        return tuple(float(v) for v in q)

    def target_near(self, place: float) -> Optional[Tuple[float, ...]]:
        """The joints of the commanded target (as the controller solved its wire pose) within one
        sample of ``place``, the nearest; None when none is."""
        best, best_d = None, 1.0 + 1e-9
        for k in reversed(self.target_samples):
            d = abs(k - place)
            if d <= best_d:
                best, best_d = k, d
            if k < place - 1.0:
                break
        return None if best is None else tuple(float(v) for v in self.q[best])

    def locate(self, position: np.ndarray, rotation: np.ndarray) -> Optional[float]:
        """Where on the path (samples from the start) the TCP pose (position [mm], rotation) lies:
        see the module docstring. None when no place from SEARCH_BACK samples before the cursor on
        lies within PATH_NEAR."""
        n = len(self.q)
        lo = max(0, int(math.floor(self.cursor)) - SEARCH_BACK)
        if n == 1 or lo >= n - 1:
            i = n - 1
            d = self.p[i] - position
            rel = (self.r[i].T @ rotation)[None]
            _, angle = _rotvec_deg(rel)
            off = math.sqrt(float(d @ d) + float(angle[0]) ** 2)
            return float(i) if off <= PATH_NEAR else None
        rel = np.einsum("kji,jl->kil", self.r[lo:n - 1], rotation)
        dr, angle = _rotvec_deg(rel)
        dp = position[None, :] - self.p[lo:n - 1]
        sp, sr = self._step_p[lo:], self._step_r[lo:]
        span = np.einsum("ki,ki->k", sp, sp) + np.einsum("ki,ki->k", sr, sr)
        along = np.einsum("ki,ki->k", dp, sp) + np.einsum("ki,ki->k", dr, sr)
        a = np.where(span > 0.0, np.clip(along / np.where(span > 0.0, span, 1.0), 0.0, 1.0), 0.0)
        off = np.sqrt(np.einsum("ki,ki->k", dp - a[:, None] * sp, dp - a[:, None] * sp)
                      + np.einsum("ki,ki->k", dr - a[:, None] * sr, dr - a[:, None] * sr))
        off[angle > 90.0] = np.inf               # (the small-angle projection means nothing there)
        best = float(np.min(off))
        if best > PATH_NEAR:
            return None
        k = int(np.argmax(off <= best + PATH_TIE))     # the earliest place that fits as well
        while k + 1 < len(off) and off[k + 1] <= off[k]:
            k += 1                                       # ... at its own best fit
        return lo + k + float(a[k])


class JointTracker:
    """The joints of the arm on a Cartesian protocol (see the module docstring). ``kin``: the
    driver's model; ``pose_resolution``: (mm, deg) of a reported pose (the protocol's); ``rule``:
    the controller's configuration rule (its documented assumption by default); ``velocity``: the
    joint velocity limits [rad/s] (default: the model's).

    Call :meth:`follow` with the job in flight and then :meth:`update` with each record's pose and
    time; :attr:`joints` / :attr:`valid` are the result. One thread (the bus thread)."""

    def __init__(self, kin: Kinematics, pose_resolution: Tuple[float, float] = (1.0, 1.0),
                 rule: Any = ConfigurationRule.PREVIOUS_TARGET, velocity: Optional[Sequence[float]] = None,
                 margin: float = VELOCITY_MARGIN) -> None:
        self.kin = kin
        self.rule = ConfigurationRule.parse(rule)
        mm, deg = pose_resolution
        self.resolution = (float(mm), float(deg))
        self.cell = (CELL_POSITION * mm * (1.0 + CELL_SLACK) + 1e-6, CELL_ROTATION * deg * (1.0 + CELL_SLACK) + 1e-6)
        self.vmax = np.array(kin.limits.velocity if velocity is None else velocity, dtype=float)
        conventions = kin.conventions       # TCP in base = root_in_base * tip * tcp_in_tip
        self._root_in_base = _kdl_frame(conventions.root_to_base(np.eye(4)))
        self._tcp_in_tip = _kdl_frame(conventions.tip_to_tcp(conventions.base_to_root(np.eye(4))))
        self.margin = float(margin)
        self.joints: Optional[Tuple[float, ...]] = None
        self.valid = False
        self.path: Optional[CommandedPath] = None
        self.doubted = 0                  # records not believed: beyond what the arm can move
        self.off_branch = 0               # records whose place on the path the arm cannot be at
        self._warned: Any = None          # the key of the path the last off-branch warning was of
        self.limited = 0                  # records whose step the velocity limits held back
        self._far = False                 # the last record lay farther than the arm can move
        self._pose: Optional[Tuple[float, ...]] = None     # the last record's pose (mm, deg)
        self._stamp: Optional[float] = None                # ... and its time
        self._previous: Optional[Tuple[float, ...]] = None  # the last target the controller took
        self._job: Any = None                              # v3: the stream job the path is of

    # ------------------------------------------------------------------------ what was sent
    def follow(self, job: Any) -> None:
        """Take the commanded path from ``job`` (a MoveJob, the one in flight; None: keep the
        last): once any of it went out to the controller."""
        if job is None or not job.sent:
            return
        if job.points:
            self._follow_stream(job)
        elif job.preview is not None:
            self._follow_move(job)

    def _previous_target(self) -> Optional[Tuple[float, ...]]:
        """The joints of the last target the controller took (that of the path before, when the
        arm was seen on it; None before any)."""
        old = self.path
        if old is not None and (old.seen_moving or old.cursor > 0.0):
            self._previous = old.goal
        return self._previous

    def _follow_move(self, job: Any) -> None:
        """v1: the job's plan; a PTP to the goal the controller solves by the rule."""
        key = (job.id, id(job.preview))
        if self.path is not None and self.path.key == key:
            if job.phase.name in ("MOVING", "STOPPING", "SUCCEEDED"):
                self.path.seen_moving = True
            return
        previous = self._previous_target()
        traj = job.preview.trajectory
        q = np.asarray(traj.positions, dtype=float)
        tcp = np.asarray(traj.tcp, dtype=float)
        position, rotation = tcp[:, :3, 3] * 1000.0, tcp[:, :3, :3]
        if traj.move_type is MoveType.PTP:
            current = self.joints if self.joints is not None else tuple(q[0])
            goal = self._solve(job.preview.target, self.rule.seed(previous, current))
            if goal is not None and max(abs(a - b) for a, b in zip(goal, q[-1])) > GOAL_EPS:
                q = self._line(current, goal)      # not the plan's goal: the controller's
                position, rotation = self._tcp_many(q)
        self.path = CommandedPath(key, q, position, rotation)

    def _follow_stream(self, job: Any) -> None:
        """v3: the points the controller took (and the one it may take with this record), each as
        it solves it, joined by straight joint moves. A live job's points are taken only as far as
        the controller took them (the last one may still be replaced)."""
        path = self.path
        if path is None or path.key != job.id:
            start = self.joints if self.joints is not None else tuple(job.start)
            q = np.array([start], dtype=float)
            position, rotation = self._tcp_many(q)
            self._previous_target()
            path = self.path = CommandedPath(job.id, q, position, rotation)
        self._job = job
        self._take(path, job, min(len(job.points), job.points_taken + (0 if job.live else 1)))

    def _take(self, path: CommandedPath, job: Any, upto: int) -> None:
        """Append the job's points up to ``upto`` (exclusive) to ``path``, each solved by the rule."""
        while len(path.targets) < upto:
            point = job.points[len(path.targets)]
            previous = path.targets[-1] if path.targets else None     # (none: the arm's joints)
            seed = self.rule.seed(previous, self.joints if self.joints is not None else path.goal)
            pose = self._wire_pose(point.pose if point.pose is not None else self.kin.fk_pose(point.joints))
            solved = self._solve(pose, seed)
            target = solved if solved is not None else tuple(point.joints)
            q = self._line(path.goal, target)[1:]
            if len(q):
                path.extend(q, *self._tcp_many(q))
            path.targets.append(target)
            path.target_samples.append(len(path) - 1)

    def _take_ahead(self) -> bool:
        """v3: append the job's points the controller may have taken that the driver has not seen
        taken (TAKEN_AHEAD; a live job's last point may still be replaced); whether any were."""
        job, path = self._job, self.path
        if job is None or path is None or path.key != job.id:
            return False
        last = len(job.points) - (1 if job.live and not job.closed else 0)
        upto = min(last, job.points_taken + TAKEN_AHEAD)
        if upto <= len(path.targets):
            return False
        self._take(path, job, upto)
        return True

    # ------------------------------------------------------------------------ each record
    def update(self, pose: ControllerPose, stamp: float) -> Optional[Tuple[float, ...]]:
        """The joints at the record taken at ``stamp`` [s] reporting ``pose``; None when none
        (the pose has no solution). The same pose as the record before: the same joints (a new
        stamp)."""
        values = pose.as_tuple()
        if values == self._pose and self.joints is not None:
            self._stamp, self._far = stamp, False
            return self.joints if self.valid else None
        dt = None if self._stamp is None else max(0.0, stamp - self._stamp)
        position = values[:3]
        rotation = tuple(float(v) for v in pose.rotation().reshape(-1))
        last = self.joints
        ref, moved = last, None
        at_target = False
        path = self.path
        place = None if path is None else path.locate(np.array(position), np.reshape(rotation, (3, 3)))
        if place is None and path is not None and self._take_ahead():
            place = path.locate(np.array(position), np.reshape(rotation, (3, 3)))
        if place is not None:
            ref = path.joints_at(place)
            moved = np.abs(np.subtract(ref, path.joints_at(path.cursor)))
            target = path.target_near(place)
            if target is not None and self._fits(target, position, rotation):
                ref = target          # (at rest there: exactly where the controller's IK put the arm)
                at_target = True
            if last is not None and dt is not None and self._beyond(ref, last, moved, dt):
                # the place has the report's pose, but on another branch than the arm's (a joint a
                # turn away, the wrist flipped): the arm left the commanded path -- a controller
                # that solved a target otherwise than the driver's rule -- read it off the path
                self._off_branch(path, ref, last)
                place, ref, moved, at_target = None, last, None, False
        if ref is None:               # the first record: nothing to go by but the pose itself
            q = self._solve(pose, self.kin.named_states.get("home", self.kin.clamp((0.0,) * self.kin.dof)))
        else:
            q = self._fit(pose, position, rotation, ref)
        if q is None:
            if self.valid:
                log.warning("no joint solution for the reported pose %s", pose)
            self._pose, self._stamp, self.valid = values, stamp, False
            return None
        far = False
        if last is not None and dt is not None:
            room = self.vmax * dt * self.margin + (moved if moved is not None else 0.0)
            far = bool(np.any(np.abs(np.subtract(q, last)) > room))
            if far and not self._far:
                # farther than the arm can move since the last record: a corrupt record, or the
                # arm not where it was told to go -- believed only when the next record agrees
                self._far = True
                self.doubted += 1
                return self.joints if self.valid else None
            if far:                 # it did: towards it as fast as the arm can go
                self.limited += 1
                q = tuple(float(v) for v in np.asarray(last) + np.clip(np.subtract(q, last), -room, room))
        self._far = far
        if (at_target or place is None) and not far:
            # at a commanded target, or with no commanded path to go by (the job ended: the arm
            # rests where it stopped): the exact solution of the report, on the settled branch
            q = self._exact(pose, q)
        if place is not None:
            path.cursor = place
            path.seen_moving = path.seen_moving or place > 0.0
        # (a step held back: the same pose is read again with the next record, until reached)
        self._pose, self._stamp = (None if far else values), stamp
        self.joints, self.valid = q, True
        return q

    def _off_branch(self, path: CommandedPath, ref: Sequence[float], last: Sequence[float]) -> None:
        """Count a report :meth:`_beyond` the arm's reach on ``path``; the first of a path is a
        warning naming the rule the driver applies (a controller whose rule differs runs targets
        on branches the driver did not check)."""
        self.off_branch += 1
        if self._warned == path.key:
            return
        self._warned = path.key
        off = np.abs(np.subtract(ref, last))
        worst = int(np.argmax(off))
        log.warning("the arm's reported pose lies on the commanded path only on another branch (joint %d "
                    "%.0f deg from the arm's): the controller solved a target otherwise than its configuration "
                    "rule as the driver applies it (controller/configuration %s; doc/commissioning.md) -- the "
                    "joints follow the arm, off the commanded path", worst + 1, math.degrees(off[worst]),
                    self.rule.value)

    def _beyond(self, ref: Sequence[float], last: Sequence[float], moved: np.ndarray, dt: float) -> bool:
        """Whether the joints ``ref`` of a place on the commanded path lie farther from the last
        joints than the arm can have moved since (the path's own motion between the two places
        ``moved``, plus the velocity limits x ``dt`` x the margin, plus EXACT_NEAR for the
        rounding): the same pose on another branch."""
        room = moved + self.vmax * dt * self.margin + EXACT_NEAR
        return bool(np.any(np.abs(np.subtract(ref, last)) > room))

    def _fit(self, pose: ControllerPose, position: Sequence[float], rotation: Sequence[float],
             ref: Sequence[float]) -> Optional[Tuple[float, ...]]:
        """The joints nearest ``ref`` that the report allows (module docstring)."""
        ref = tuple(float(v) for v in ref)
        if self._fits(ref, position, rotation):
            return ref
        try:
            # the IK solution nearest ref, or within the rounding just past the reach
            solved = self.kin.track_pose(pose, ref, near=(0.0, 0.0))
        except KinematicsError:
            return None
        held = self._held_split(solved, ref)
        if held is not None and self._fits(held, position, rotation):
            return self._nearest(ref, held, position, rotation)
        return self._nearest(held if held is not None else ref, solved, position, rotation)

    def _held_split(self, solved: Sequence[float], ref: Sequence[float]) -> Optional[Tuple[float, ...]]:
        """``solved`` with the split joint_4 - joint_6 of ``ref`` (their sum kept, a whole number
        of half turns each: the wrist flipped with joint_5 negated where that is nearer ``ref``);
        None for a chain without a wrist of six joints or outside the limits."""
        if len(solved) != 6:
            return None
        total, split = solved[3] + solved[5], ref[3] - ref[5]
        k0 = round((ref[3] + ref[5] - total) / _TWO_PI)
        best, best_d = None, math.inf
        lower, upper = self.kin.limits.lower, self.kin.limits.upper
        for k in (k0 - 1, k0, k0 + 1):
            s = total + k * _TWO_PI
            q = (solved[0], solved[1], solved[2], 0.5 * (s + split), solved[4] * (-1.0) ** (k % 2),
                 0.5 * (s - split))
            if not all(lo - 1e-9 <= v <= hi + 1e-9 for v, lo, hi in zip(q, lower, upper)):
                continue
            d = sum((a - b) ** 2 for a, b in zip(q, ref))
            if d < best_d:
                best, best_d = q, d
        return best

    def _nearest(self, start: Sequence[float], end: Sequence[float], position: Sequence[float],
                 rotation: Sequence[float]) -> Tuple[float, ...]:
        """The point of the straight joint line from ``start`` towards ``end`` (which the report
        allows) nearest ``start`` that the report allows (bisection)."""
        a, b = np.asarray(start, dtype=float), np.asarray(end, dtype=float)
        lo, hi = 0.0, 1.0
        span = float(np.max(np.abs(b - a)))
        for _ in range(min(BISECT_STEPS, max(0, int(math.ceil(math.log2(max(span, 1e-12) / BISECT_RESOLUTION)))))):
            mid = 0.5 * (lo + hi)
            if self._fits(tuple(a + mid * (b - a)), position, rotation):
                hi = mid
            else:
                lo = mid
        return tuple(float(v) for v in a + hi * (b - a))

    # ------------------------------------------------------------------------ kinematics
    def _exact(self, pose: ControllerPose, q: Tuple[float, ...]) -> Tuple[float, ...]:
        """Outside the wrist band: the IK solution of the reported pose nearest ``q`` (its branch),
        where it lies within :data:`EXACT_NEAR` of ``q`` on every joint; else ``q``. The joints the
        tracker settles on explain the report within its rounding; this makes them its exact
        solution, so that at rest at a target -- where the arm stands exactly at the controller's
        IK of the pose it reports -- they are the arm's joints, not off by the rounding (0.01 deg at
        v3's resolution). Inside the band the pose leaves joint_4 - joint_6 open: the commanded
        split holds (module docstring)."""
        if abs(q[_WRIST5]) < WRIST_BAND:
            return q
        exact = self._solve(pose, q)
        if exact is None or max(abs(a - b) for a, b in zip(exact, q)) > EXACT_NEAR:
            return q
        return exact

    def _solve(self, pose: ControllerPose, seed: Sequence[float]) -> Optional[Tuple[float, ...]]:
        """A Cartesian target as the controller solves it: the IK solution nearest ``seed``."""
        try:
            return self.kin.ik_pose(pose, seed=tuple(seed))
        except KinematicsError:
            return None

    def _wire_pose(self, pose: ControllerPose) -> ControllerPose:
        """``pose`` as a Cartesian target carries it to the controller, which solves that: each field
        rounded half away from zero to the pose resolution (Protocol.wire_pose; a point's pose
        rounded already stays as it is)."""
        return rounded_pose(pose, self.resolution)

    def _tcp(self, q: Sequence[float]) -> Tuple[Tuple[float, ...], Tuple[float, ...]]:
        """(TCP position [mm], rotation row-major) in ``base`` at joints ``q`` (KDL, no numpy: it
        runs a few times per record)."""
        f = self._root_in_base * self.kin.fk_frame(q) * self._tcp_in_tip
        m, p = f.M, f.p
        return ((p[0] * 1000.0, p[1] * 1000.0, p[2] * 1000.0),
                (m[0, 0], m[0, 1], m[0, 2], m[1, 0], m[1, 1], m[1, 2], m[2, 0], m[2, 1], m[2, 2]))

    def _tcp_many(self, q: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        pairs = [self._tcp(row) for row in q]
        return (np.array([p for p, _ in pairs], dtype=float).reshape(-1, 3),
                np.array([r for _, r in pairs], dtype=float).reshape(-1, 3, 3))

    def _fits(self, q: Sequence[float], position: Sequence[float], rotation: Sequence[float]) -> bool:
        """Whether the report's rounding allows joints ``q``: their TCP within the report's cell
        (``rotation`` row-major)."""
        p, r = self._tcp(q)
        cell_p, cell_r = self.cell
        if abs(p[0] - position[0]) > cell_p or abs(p[1] - position[1]) > cell_p or abs(p[2] - position[2]) > cell_p:
            return False
        cos = 0.5 * (sum(a * b for a, b in zip(r, rotation)) - 1.0)
        return math.degrees(math.acos(max(-1.0, min(1.0, cos)))) <= cell_r

    @staticmethod
    def _line(start: Sequence[float], goal: Sequence[float]) -> np.ndarray:
        """The straight joint move from ``start`` to ``goal``, at most SAMPLE_STEP between samples."""
        a, b = np.asarray(start, dtype=float), np.asarray(goal, dtype=float)
        n = max(1, int(math.ceil(float(np.max(np.abs(b - a), initial=0.0)) / SAMPLE_STEP)))
        return a[None, :] + np.linspace(0.0, 1.0, n + 1)[:, None] * (b - a)[None, :]
