"""The wire pose of a Cartesian stream target (protocol v3) chosen so that the controller's own IK of
it lands on the planned joints.

A Cartesian protocol carries a pose rounded to its resolution (v3: 0.1 mm, 0.01 deg); the G2 solves
that rounded pose with its IK, and moves its joints to the solution (a MOVEP interpolates joints).
Away from the wrist singularity the rounding costs a few thousandths of a degree. Near joint_5 = 0
the pose hardly fixes joint_4 - joint_6: a rounding of 0.01 deg can swing the solution's wrist by a
degree or more (measured: 1.4 deg at joint_5 = 0.1 deg, 0.3 deg at 0.8 deg), and the arm would leave
the plan there although every target is "the planned pose".

Each of the six numbers may be rounded up or down by one step without leaving the resolution's
bound, so there are 3^6 = 729 wire poses for one planned pose. :func:`wire_target` picks among them
the one whose solution by the controller's rule (seeded as the controller seeds it) lands nearest
the planned joints -- for a controller that solves a target nearest the arm's joints when it takes
it (``current_joints``), which the driver knows only to lie on a stretch of the planned path, from
every seed of that stretch it is given (the worst of them counts): first the plain rounding; when that is off by more than ``fine``, a coordinate
search over single steps (a few dozen IK solutions, ~0.3 ms each); within FULL_SEARCH_BAND of
joint_5 = 0, where the coordinate search can stall, the grid in the order a linear model predicts
(:class:`GridModel`), until one lands within ``fine``, or after SEARCH_LIMIT of them one within
GOOD_ENOUGH, or the model says no pose left can land nearer than the best found (its prediction
less its largest miss so far and MODEL_MARGIN); else all 729. The model is linear in
:func:`wrist_features` -- joint_1..3, joint_5 x (cos, sin) joint_4 and joint_4 + joint_6 -- in which
the controller's solution changes linearly with the pose even at joint_5 = 0, where joint_4 -
joint_6 is the angle of the wrist's small residual rotation and one step of the wire swings it by
degrees (a model linear in the joints themselves, used before, found the best pose late or never
there, and a goal ending on joint_5 = 0 solved all 729 poses, 0.6 s, before its arm moved; now
~30). Measured on random wrists within 0.45 deg of the singularity (v3): the prediction within 0.075
deg of the solution over the whole grid, the best pose the first or second predicted. Near a branch
boundary (a rounding lands on another elbow) no linear model holds: when a one-step neighbour is
solved on another branch (or not at all) the model is not trusted and the grid is searched to its
end. Measured before (random wrists within 3 deg): the worst plain rounding 14.5 deg off, the
chosen pose 0.44 deg off, most under 0.02 deg.

Pure computation on the driver's kinematics model; used by the stream preparation of the Cartesian
protocols (:mod:`.stream_prep`)."""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import List, Optional, Sequence, Tuple

import numpy as np

from ...errors import VrDriverError
from ...kinematics.ik import rotation_and_position
from ...kinematics.solver import Kinematics
from ...poses import ControllerPose

#: [rad] the widest joint turn between the joints a Cartesian stream's target is solved nearest and
#: the target (stream_thinning.split_long): the controller takes the solution nearest them, the planned
#: one only while a joint turns by well under half a turn in between -- previous_target: between
#: two points; current_joints: over the ring_size + 1 points before (stream_prep's docstring)
CARTESIAN_MAX_STEP = math.radians(90.0)
#: [rad] a solution this near the planned joints needs no search (the plain rounding of v3 costs
#: about 0.01 deg away from the singularity: searching there would cost 15 ms a target for nothing)
FINE = math.radians(0.02)
#: [rad] |joint_5| below which the grid search runs when the coordinate search did not reach FINE
FULL_SEARCH_BAND = math.radians(0.5)
#: grid poses the grid search solves, the most promising by the linear model first, before it takes
#: one within GOOD_ENOUGH; the rest of the grid only when none is (very near joint_5 = 0 the model is
#: poor and a split off by degrees would be refused as another configuration)
SEARCH_LIMIT = 96
#: [rad] ... and the error it then takes
GOOD_ENOUGH = math.radians(0.1)
#: the index of joint_5 (the wrist's bend) in the joint vector
WRIST_BEND = 4
#: the steps of one wire number (-1, 0, +1 of the protocol's resolution)
STEPS = (-1, 0, 1)


@dataclass(frozen=True)
class WireTarget:
    """``pose``: the wire pose to send (on the protocol's grid); ``joints``: the controller's
    solution of it (seeded as given); ``error``: [rad] its largest joint difference from the planned
    joints; ``steps``: the offset from the plain rounding, in resolution steps (X Y Z Rx Ry Rz);
    ``solved``: IK solutions computed to find it."""
    pose: ControllerPose
    joints: Tuple[float, ...]
    error: float
    steps: Tuple[int, ...]
    solved: int


class WireMemo:
    """What :func:`wire_target` computes for one planned point, kept for the next call on the same
    stream (one plan's check: :func:`~.streaming.split_long`'s ``reaches`` and then
    ``CartesianStreams.with_poses`` meet the same points, with the same seeds or others): the plain
    rounding of a planned point's pose, each wire pose near it with its tip frame, and the
    controller's solution of each (pose, seed) -- or its VrDriverError. Pure functions of their keys
    for one kinematics model and one protocol: a memo must not outlive the stream check it was made
    for (the model's TCP or conventions may change between two), nor serve two models."""

    def __init__(self) -> None:
        #: planned joints -> the plain rounding of their pose
        self.base: dict = {}
        #: (planned joints, steps) -> (the wire pose, its tip frame in the chain root, that frame as
        #: the IK's (rotation, position) target)
        self.poses: dict = {}
        #: (planned joints, steps, seed) -> the controller's solution (a joint tuple) or its VrDriverError
        self.solved: dict = {}


def wire_target(kin, wire, joints: Sequence[float], seed: Sequence[float], fine: float = FINE,
                full_band: float = FULL_SEARCH_BAND, also: Sequence[Sequence[float]] = (),
                memo: Optional[WireMemo] = None) -> WireTarget:
    """The wire pose for the planned ``joints`` whose solution by the controller's IK seeded with
    ``seed`` (its configuration rule: the previous target's solution, or its joints now) lands
    nearest ``joints``. ``also``: further seeds the controller may take instead (``current_joints``:
    the arm's joints anywhere on the stretch of the plan it may be on when the controller takes the
    target); a pose's error is then the worst over all seeds, and ``joints`` of the result the
    solution from the worst seed (the first one when they agree). A neighbour that cannot be solved
    is passed over; when the plain rounding cannot (a pose 0.1 mm past the stretched arm's reach),
    every neighbour is tried. Raises the kinematics' VrDriverError when none can be solved (the
    caller names the point)."""
    planned = tuple(float(v) for v in joints)
    seed = tuple(float(v) for v in seed)
    seeds = [seed]
    for other in also:
        other = tuple(float(v) for v in other)
        if other not in seeds:
            seeds.append(other)
    if memo is None:
        memo = WireMemo()
    base = memo.base.get(planned)
    if base is None:
        base = memo.base[planned] = wire.wire_pose(kin.fk_pose(planned))
    mm, deg = wire.pose_resolution
    sizes = (mm, mm, mm, deg, deg, deg)
    nearest = _analytic_nearest(kin)
    tcp_to_tip = kin.conventions.tcp_to_tip

    def tip_frame(pose: ControllerPose) -> np.ndarray:
        """``kin.conventions.controller_to_tip(pose)`` of a wire pose (a ControllerPose of finite
        floats: its 4x4 built without checking its numbers again -- the same floats, a fifth of a
        neighbour's cost was the checks)."""
        t = np.eye(4)
        t[:3, :3] = pose.rotation()
        t[:3, 3] = pose.position_m
        return tcp_to_tip(t)
    used: set = set()               # the solutions this call asked for (WireTarget.solved counts them)

    def framed(steps: Tuple[int, ...]) -> Tuple[ControllerPose, object, object]:
        """The wire pose ``steps`` (X Y Z Rx Ry Rz, in resolution steps) off the plain rounding, its
        tip frame (what ``kin.ik_pose`` solves) and that as the IK's target (None until
        :func:`solution` first splits it), each made once per memo."""
        key = (planned, steps)
        out = memo.poses.get(key)
        if out is None:
            pose = base if not any(steps) else wire.wire_pose(
                ControllerPose(*(v + s * d for v, s, d in zip(base.as_tuple(), steps, sizes))))
            out = memo.poses[key] = (pose, tip_frame(pose), None)
        return out

    def pose_at(steps: Tuple[int, ...]) -> ControllerPose:
        """The wire pose ``steps`` off the plain rounding."""
        return framed(steps)[0]

    def solution(steps: Tuple[int, ...], s: Tuple[float, ...]) -> Tuple[float, ...]:
        """The controller's solution of the pose ``steps`` off the plain rounding, seeded with ``s``
        (each computed once: the coordinate search, the model and the grid meet the same poses, and
        a stream check's calls the same points); raises the kinematics' VrDriverError when it has
        none."""
        key = (planned, steps, s)
        used.add(key)
        if key not in memo.solved:
            try:
                if nearest is None:
                    memo.solved[key] = tuple(kin.ik(framed(steps)[1], seed=s))      # = kin.ik_pose(pose, seed=s)
                else:
                    pose, tip, rp = framed(steps)
                    if rp is None:          # (split here: its PoseError is the solution's, as kin.ik's)
                        rp = rotation_and_position(tip)
                        memo.poses[(planned, steps)] = (pose, tip, rp)
                    memo.solved[key] = tuple(nearest(rp[0], rp[1], kin.joint_vector(s), 0.0, 0.0))
            except VrDriverError as exc:
                memo.solved[key] = exc
        out = memo.solved[key]
        if isinstance(out, VrDriverError):
            raise out
        return out

    def attempt(steps: Tuple[int, ...], bound: float = math.inf) -> Optional[WireTarget]:
        """The pose ``steps`` off the plain rounding, solved from every seed -- from the first only
        when that is already farther than ``bound`` off the plan (it cannot be the better one)."""
        worst: Optional[Tuple[float, Tuple[float, ...]]] = None
        for s in seeds:
            try:
                q = solution(steps, s)
            except VrDriverError:
                if not any(steps):
                    raise
                return None
            error = _error(q, planned)
            if worst is None or error > worst[0]:
                worst = (error, q)
            if worst[0] > bound:
                break
        assert worst is not None
        return WireTarget(pose_at(steps), worst[1], worst[0], steps, 0)

    try:
        best = attempt((0,) * 6)
    except VrDriverError as exc:
        # the rounding pushed the pose past the stretched arm's reach (0.1 mm is enough there): a
        # neighbour rounded the other way may be inside it
        best = None
        for steps in itertools.product(STEPS, repeat=6):
            found = attempt(steps) if any(steps) else None
            if found is not None and (best is None or _better(found, best)):
                best = found
        if best is None:
            raise exc
        return WireTarget(best.pose, best.joints, best.error, best.steps, len(used))
    if best.error > fine:
        best = _coordinate_search(best, attempt, fine)
    if best.error > fine and abs(planned[WRIST_BEND]) < full_band:
        def solve(steps: Tuple[int, ...]) -> Optional[Tuple[float, ...]]:
            try:
                return solution(steps, seed)
            except VrDriverError:
                return None
        at_base = solve((0,) * 6)
        model = GridModel(planned, at_base, solve, seed) if at_base is not None else None
        order = model.order if model is not None else \
            [(steps, math.nan) for steps in itertools.product(STEPS, repeat=6)]
        missed = 0.0                 # the model's largest miss so far on the poses solved
        for tried, (steps, predicted) in enumerate(order):
            if best.error <= fine or (tried >= SEARCH_LIMIT and best.error <= GOOD_ENOUGH):
                break
            if model is not None and model.trusted and predicted - missed - MODEL_MARGIN > best.error:
                break                # nothing left can land nearer (the order is by the prediction)
            if steps == best.steps:
                continue
            found = attempt(steps, best.error)
            if found is not None and _better(found, best):
                best = found
            q = solve(steps)
            if q is None:
                continue
            missed = max(missed, abs(_error(q, planned) - predicted))
    return WireTarget(best.pose, best.joints, best.error, best.steps, len(used))


def _analytic_nearest(kin):
    """``kin.ik`` without its wrapper, where that is all it does -- the analytic solver's solution
    nearest a validated seed, of a target already split into (rotation, position)
    (``IkSolver.nearest``: what ``Kinematics.ik`` calls with the seed validated, its deadline unused
    by the analytic solver): the search solves each wire pose from one or more seeds, and the
    target's split and checks per solution were an eighth of an IK's time. None (``kin.ik`` is
    called): a model without the analytic solver, or one whose ``ik`` is another."""
    solver = getattr(kin, "ik_solver", None)
    if type(kin).ik is not Kinematics.ik or solver is None or solver.analytic is None:
        return None
    return solver.nearest


#: [rad] the margin the grid search adds to the model's largest miss so far before it trusts the
#: model's word that no pose left can land nearer than the best one found
MODEL_MARGIN = math.radians(0.1)
#: [rad] the model is trusted only when every one-step neighbour of the plain rounding was solved
#: with joint_1..joint_3 within this of its solution (one branch: near a branch boundary a rounding
#: may land on another, and no linear model holds there)
ONE_BRANCH = math.radians(1.0)


def _error(q: Sequence[float], planned: Sequence[float]) -> float:
    return max(abs(a - b) for a, b in zip(q, planned))


def wrist_features(q: Sequence[float]) -> np.ndarray:
    """The joints in coordinates in which the controller's solution changes linearly with the wire
    pose, even at joint_5 = 0: joint_1..3, joint_5 x (cos, sin) joint_4 -- the wrist's residual
    rotation out of joint_4 + joint_6, which a pose fixes -- and joint_4 + joint_6. (Near joint_5 = 0
    joint_4 - joint_6 is the angle of that residual: not linear in the pose, linear through it.)
    The same for both wrist branches (joint_5 negated, joint_4 and joint_6 half a turn on)."""
    return np.array([q[0], q[1], q[2], q[4] * math.cos(q[3]), q[4] * math.sin(q[3]), q[3] + q[5]])


def joints_of(features: np.ndarray, seed: Sequence[float]) -> Tuple[float, ...]:
    """The joints of :func:`wrist_features` on the wrist branch (and turns) nearest ``seed``, as the
    controller's IK chooses them."""
    four = math.atan2(features[4], features[3])
    bend = math.hypot(features[3], features[4])
    choices = []
    for j4, j5 in ((four, bend), (four + math.pi, -bend)):
        j4 = seed[3] + math.remainder(j4 - seed[3], 2.0 * math.pi)
        j6 = seed[5] + math.remainder(features[5] - j4 - seed[5], 2.0 * math.pi)
        choices.append(((j4 - seed[3]) ** 2 + (j5 - seed[4]) ** 2 + (j6 - seed[5]) ** 2, j4, j5, j6))
    _d, j4, j5, j6 = min(choices)
    return (float(features[0]), float(features[1]), float(features[2]), j4, j5, j6)


def grid_joints(features: np.ndarray, seed: Sequence[float]) -> np.ndarray:
    """:func:`joints_of` for many rows of :func:`wrist_features` at once (a row of joints each): the
    729 predictions of a :class:`GridModel` in one array operation (one row at a time took ~5 ms,
    the most of a target near joint_5 = 0 before its goal could start)."""
    s3, s4, s5 = float(seed[3]), float(seed[4]), float(seed[5])
    four = np.arctan2(features[:, 4], features[:, 3])
    bend = np.hypot(features[:, 3], features[:, 4])

    def branch(j4: np.ndarray, j5: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        j4 = s3 + _remainder(j4 - s3)
        j6 = s5 + _remainder(features[:, 5] - j4 - s5)
        return (j4 - s3) ** 2 + (j5 - s4) ** 2 + (j6 - s5) ** 2, j4, j5, j6
    da, a4, a5, a6 = branch(four, bend)
    db, b4, b5, b6 = branch(four + math.pi, -bend)
    first = da <= db
    return np.column_stack((features[:, 0], features[:, 1], features[:, 2], np.where(first, a4, b4),
                            np.where(first, a5, b5), np.where(first, a6, b6)))


def _remainder(x: np.ndarray) -> np.ndarray:
    """``math.remainder(x, 2 pi)`` element by element (the nearest multiple taken off; halves to even)."""
    return x - TWO_PI * np.round(x / TWO_PI)


TWO_PI = 2.0 * math.pi
#: the 729 offsets of the grid (each number -1, 0, +1 step), as ints and as floats
_GRID_STEPS = np.array(list(itertools.product(STEPS, repeat=6)), dtype=int)
_GRID = _GRID_STEPS.astype(float)


class GridModel:
    """The 729 grid offsets (each number -1, 0, +1 step) with the error a linear model predicts for
    the controller's solution of each, nearest the plan first (:attr:`order`: (offset, predicted
    error)). The model: the solution at the plain rounding ``at_base`` plus, per number, the change
    per step of its :func:`wrist_features` (central differences of ``solve(offset)``, the controller's
    solution of the plain rounding moved by the offset, or None; a number whose neighbours cannot
    both be solved counts as changing nothing). In those coordinates the solution is linear in the
    pose at joint_5 = 0 too (measured on random wrists within 0.45 deg of it: the prediction within
    0.075 deg of the solution over all 729, the best pose the first predicted). :attr:`trusted`: every
    neighbour solved on the branch of ``at_base``. ``seed``: the controller's seed (its IK takes the
    wrist branch nearest it)."""

    def __init__(self, planned: Sequence[float], at_base: Sequence[float], solve,
                 seed: Sequence[float]) -> None:
        f0 = wrist_features(at_base)
        rows = []
        trusted = True
        for i in range(6):
            up = solve(tuple(1 if k == i else 0 for k in range(6)))
            down = solve(tuple(-1 if k == i else 0 for k in range(6)))
            if up is None or down is None:
                trusted = False
                rows.append(np.zeros(6))
                continue
            if max(abs(a - b) for q in (up, down) for a, b in zip(q[:3], at_base[:3])) > ONE_BRANCH:
                trusted = False
            fu, fd = wrist_features(up), wrist_features(down)
            row = (fu - fd) / 2.0
            row[5] = math.remainder(fu[5] - fd[5], 2.0 * math.pi) / 2.0
            rows.append(row)
        self.trusted = trusted
        predicted = f0[None, :] + _GRID @ np.array(rows)
        errors = np.max(np.abs(grid_joints(predicted, seed) - np.asarray(planned, dtype=float)[None, :]), axis=1)
        order = np.argsort(errors, kind="stable")
        self.order: List[Tuple[Tuple[int, ...], float]] = list(zip(
            map(tuple, _GRID_STEPS[order].tolist()), errors[order].tolist()))


def _better(a: WireTarget, b: WireTarget) -> bool:
    """``a`` nearer the plan than ``b``; on a tie the smaller offset from the plain rounding."""
    if a.error != b.error:
        return a.error < b.error
    return sum(map(abs, a.steps)) < sum(map(abs, b.steps))


def _coordinate_search(best: WireTarget, attempt, fine: float) -> WireTarget:
    """One step at a time in the number that helps most, each number within one step of the plain
    rounding, until no single step helps (or the solution is within ``fine``)."""
    while best.error > fine:
        improved = best
        for i in range(6):
            for d in (-1, 1):
                s = best.steps[i] + d
                if abs(s) > 1:
                    continue
                found = attempt(best.steps[:i] + (s,) + best.steps[i + 1:], improved.error)
                if found is not None and _better(found, improved):
                    improved = found
        if improved is best:
            break
        best = improved
    return best
