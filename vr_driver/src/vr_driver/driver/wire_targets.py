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
(the solution's change per step of each number, from the twelve one-step neighbours of the plain
rounding), until one lands within ``fine``, or after SEARCH_LIMIT of them one within GOOD_ENOUGH;
else all 729. Measured on random wrists within 3 deg of the singularity (v3): the worst plain
rounding 14.5 deg off, the chosen pose 0.44 deg off, most under 0.02 deg. The predicted order
against all 729 (40 random wrists within 0.5 deg of the singularity): the best of the grid among
the first 40 predicted in 37, among the first 80 in 38; the others within 0.06 deg of joint_5 = 0,
where the model is poor (one step there swings joint_4 - joint_6 by degrees). A target 0.2-0.45 deg
from the singularity now costs ~115 IK solutions (38 ms) instead of ~750 (0.27 s), which a goal
ending near it spent before its arm moved.

Pure computation on the driver's kinematics model; used by the stream preparation of the Cartesian
protocols (:mod:`.stream_prep`)."""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import List, Optional, Sequence, Tuple

import numpy as np

from ..errors import VrDriverError
from ..poses import ControllerPose

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


def wire_target(kin, protocol, joints: Sequence[float], seed: Sequence[float], fine: float = FINE,
                full_band: float = FULL_SEARCH_BAND, also: Sequence[Sequence[float]] = ()) -> WireTarget:
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
    base = protocol.wire_pose(kin.fk_pose(planned))
    mm, deg = protocol.pose_resolution
    sizes = (mm, mm, mm, deg, deg, deg)
    count = [0]
    known: dict = {}

    def pose_at(steps: Tuple[int, ...]) -> ControllerPose:
        """The wire pose ``steps`` (X Y Z Rx Ry Rz, in resolution steps) off the plain rounding."""
        if not any(steps):
            return base
        return protocol.wire_pose(ControllerPose(*(v + s * d for v, s, d in zip(base.as_tuple(), steps, sizes))))

    def solution(steps: Tuple[int, ...], s: Tuple[float, ...]) -> Tuple[float, ...]:
        """The controller's solution of the pose ``steps`` off the plain rounding, seeded with ``s``
        (each computed once: the coordinate search, the model and the grid meet the same poses);
        raises the kinematics' VrDriverError when it has none."""
        key = (steps, s)
        if key not in known:
            count[0] += 1
            try:
                known[key] = tuple(kin.ik_pose(pose_at(steps), seed=s))
            except VrDriverError as exc:
                known[key] = exc
        out = known[key]
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
            error = max(abs(a - b) for a, b in zip(q, planned))
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
        return WireTarget(best.pose, best.joints, best.error, best.steps, count[0])
    if best.error > fine:
        best = _coordinate_search(best, attempt, fine)
    if best.error > fine and abs(planned[WRIST_BEND]) < full_band:
        def solve(steps: Tuple[int, ...]) -> Optional[Tuple[float, ...]]:
            try:
                return solution(steps, seed)
            except VrDriverError:
                return None
        at_base = solve((0,) * 6)
        order = (predicted_order(planned, at_base, solve) if at_base is not None
                 else itertools.product(STEPS, repeat=6))
        for tried, steps in enumerate(order):
            if best.error <= fine or (tried >= SEARCH_LIMIT and best.error <= GOOD_ENOUGH):
                break
            if steps == best.steps:
                continue
            found = attempt(steps, best.error)
            if found is not None and _better(found, best):
                best = found
    return WireTarget(best.pose, best.joints, best.error, best.steps, count[0])


def predicted_order(planned: Sequence[float], at_base: Sequence[float], solve) -> List[Tuple[int, ...]]:
    """The 729 grid offsets (each number -1, 0, +1 step) in the order a linear model puts their
    solutions near ``planned``, nearest first: the solution at the plain rounding ``at_base`` plus, per
    number, its change per step (central differences of ``solve(offset)``, the controller's
    solution of the plain rounding moved by the offset, or None; a number whose neighbours cannot
    both be solved counts as changing nothing)."""
    q0 = np.asarray(at_base, dtype=float)
    rows = []
    for i in range(6):
        up = solve(tuple(1 if k == i else 0 for k in range(6)))
        down = solve(tuple(-1 if k == i else 0 for k in range(6)))
        rows.append((np.asarray(up) - np.asarray(down)) / 2.0 if up is not None and down is not None
                    else np.zeros(len(q0)))
    grid = np.array(list(itertools.product(STEPS, repeat=6)), dtype=float)
    predicted = q0[None, :] + grid @ np.array(rows)
    error = np.max(np.abs(predicted - np.asarray(planned, dtype=float)[None, :]), axis=1)
    order = np.argsort(error, kind="stable")
    return [tuple(int(v) for v in grid[i]) for i in order]


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
