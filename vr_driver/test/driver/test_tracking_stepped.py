"""The driver's joints are the arm's on the Cartesian protocols (v1, v3): driver/joints/tracking.py stepped
with a fake clock, in one thread, against the virtual G2 (_world.World).

The controller reports only a pose; near joint_5 = 0 (the wrist singularity) a pose fixes
joint_4 + joint_6 but hardly joint_4 - joint_6. A sweep of joint_5 from +30 to -30 deg and back
(joint_4 and joint_6 turning the other way meanwhile) is run on v1 (two PTP moves to whole mm / deg
poses) and on v3 (one streamed trajectory out and back), with both settings of the controller's
configuration rule, a lost record and a corrupt one near the singularity. Every published
``joint_states`` sample is compared with the arm's true joints at the program loop that wrote the
record it came from: within ACCURACY in every joint -- joint_4 / joint_6 by their sum where
|joint_5| < BAND --, no step larger than the arm can move between the two records, and the arm
ends on the planned branch with the driver's joints on it too."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from vr_driver.driver import MoveRequest
from vr_driver.driver.joints.tracking import VELOCITY_MARGIN
from vr_driver.kinematics.preview import MovePreviewer, MotionSettings
from vr_driver.kinematics.solver import ConfigurationRule
from vr_driver.poses import ControllerPose, MoveType
from vr_driver.protocol.registry import get

from _world import World
from test_streaming_stepped import trajectory

DEG = math.pi / 180.0
#: every published sample within this of the arm's joints ...
ACCURACY = 0.5 * DEG
#: ... joint_4 and joint_6 by their sum where the arm's |joint_5| is below this: there the pose
#: leaves their split open (v1: a whole degree of rotation hides several degrees of it at 5 deg)
BAND = 5.0 * DEG
#: the sweep's ends: joint_5 +-30 deg, joint_4 and joint_6 turning apart on the way (their split
#: changes by 34 deg, their sum stays), the arm near home
Q_A = (0.1, 0.55, -0.2, 0.5, 30.0 * DEG, -0.7)
Q_B = (0.1, 0.55, -0.2, 0.8, -30.0 * DEG, -1.0)
#: ... and their split within this there: the commanded split holds, and the arm runs it
SPLIT = 2.0 * DEG
RULES = [rule.value for rule in ConfigurationRule]


class Truth:
    """The arm's joints at every program loop of the virtual G2, with the pose it wrote then."""

    def __init__(self, world: World) -> None:
        self.loops = []
        step = world.program.step

        def stepped(now):
            out = step(now)
            fb = world.program.last_feedback
            self.loops.append((now, tuple(world.arm.joints), None if fb is None else fb.pose))
            return out
        world.program.step = stepped

    def at(self, status, check=True):
        """(time, joints) of the last loop before ``status``'s bus cycle: the record it read
        (``check``: that record's pose is the status's)."""
        for t, q, pose in reversed(self.loops):
            if t <= status.time:
                assert pose == status.pose or not check, (pose, status.pose)
                return t, q
        raise AssertionError("no program loop before %.3f" % status.time)


class Corrupt:
    """Replaces the pose of the next record that arrives (once ``armed``) by one 40 mm / 7 deg off,
    as a record whose check the corruption passed."""

    def __init__(self, world: World) -> None:
        self.armed = False
        self.done_at = None
        link = world.core.link
        step = link.step

        def stepped(now):
            sample = step(now)
            if self.armed and sample.fresh is not None:
                fb = sample.fresh
                bad = replace(fb, x=fb.x + 40, rz=fb.rz - 7) if world.protocol == "v1" else \
                    replace(fb, tcp=(fb.tcp[0] + 400,) + fb.tcp[1:5] + (fb.tcp[5] - 700,))
                sample = replace(sample, fresh=bad, feedback=bad)
                self.armed, self.done_at = False, sample.time
            return sample
        link.step = stepped


#: the sweep's pace: v1 the planner's velocity scale (the virtual G2 runs the plan), v3 the
#: duration of each way [s]
PACE = {"v1": {"fast": 1.0, "slow": 0.1}, "v3": {"fast": 0.5, "slow": 6.0}}


def make_world(kin, protocol, rule, pace="fast", told=None):
    """The world with the virtual G2 at configuration ``rule`` and the driver told ``told`` (its
    ``controller/configuration``; default: the G2's own rule, as a commissioning file says)."""
    start = ControllerPose(*[float(round(v)) for v in kin.fk_pose(Q_A).as_tuple()])
    planner = MovePreviewer(kin, MotionSettings(velocity_scale=PACE["v1"][pace])) if protocol == "v1" else None
    told = rule if told is None else told
    world = World(kin, {"controller": {"configuration": told}}, protocol=protocol, initial_pose=start,
                  planner=planner)
    world.arm.configuration = ConfigurationRule.parse(rule)
    assert world.core.tracker.rule is ConfigurationRule.parse(told)
    world.ready()
    assert max(abs(a - b) for a, b in zip(world.arm.joints, Q_A)) < 2.0 * DEG
    return world


def published(world, since):
    """The joint_states samples since ``since``: one per new record, with valid joints."""
    out, last = [], None
    for s in world.statuses:
        if s.time < since or not s.joints_valid or s.record_time is None or s.record_time == last:
            continue
        last = s.record_time
        out.append(s)
    return out


class Verdict:
    """The published samples against the arm's joints (rad): ``worst`` error (joint_4 / joint_6 by
    their sum inside BAND) and where, ``split`` the worst error of joint_4 - joint_6 inside BAND,
    ``excess`` the largest step beyond what the arm can move between the two records' loops (its
    velocity limits), ``in_band`` how many samples were judged inside BAND."""

    def __init__(self, world, truth, samples, skip=()):
        vmax = np.array(world.kin.limits.velocity)
        self.worst, self.at, self.split, self.excess, self.in_band = 0.0, None, 0.0, -math.inf, 0
        prev = None
        for s in samples:
            t, q = truth.at(s, check=s.time not in skip)
            pub = np.array(s.joints)
            if s.time not in skip:
                err = np.abs(pub - np.array(q))
                if abs(q[4]) < BAND:
                    self.in_band += 1
                    self.split = max(self.split, abs(pub[3] - pub[5] - q[3] + q[5]))
                    err = np.array([err[0], err[1], err[2], abs(pub[3] + pub[5] - q[3] - q[5]), err[4]])
                if float(err.max()) > self.worst:
                    self.worst, self.at = float(err.max()), (s.time, [round(v / DEG, 2) for v in pub],
                                                             [round(v / DEG, 2) for v in q])
            if s.time in skip:
                continue
            if prev is not None:
                t0, pub0 = prev
                self.excess = max(self.excess, float(np.max(np.abs(pub - pub0) - vmax * (t - t0))))
            prev = (t, pub)

    def check(self):
        assert self.worst <= ACCURACY, (self.worst / DEG, self.at)
        assert self.split <= SPLIT, self.split / DEG
        # no step larger than the arm can move in the time (the two samples' own error aside)
        assert self.excess <= ACCURACY, self.excess / DEG


def sweep_v1(world, pace="fast"):
    """PTP to the whole mm / deg pose at Q_B, then back to the one at Q_A; the goal the controller
    solved last (nearest the previous target's joints)."""
    goals = []
    for q in (Q_B, Q_A):
        target = ControllerPose(*[float(round(v)) for v in world.kin.fk_pose(q).as_tuple()])
        job = world.core.submit(MoveRequest(MoveType.PTP, target))
        goals.append(job.preview.joint_target)
        assert world.finish(job, 60.0).success, job.result.reason
    return goals[-1]


def sweep_v3(world, pace="fast", n=20):
    """One trajectory out to Q_B and back to Q_A (a straight joint line each way, smooth in time)."""
    duration = PACE["v3"][pace]
    q0 = np.array(world.status().joints)
    out = np.array(Q_B)
    times, points = [], []
    for k in range(1, 2 * n + 1):
        u = k / n if k <= n else (2 * n - k) / n
        s = u * u * (3.0 - 2.0 * u)
        points.append(tuple(q0 + s * (out - q0)))
        times.append(duration * k / n)
    run = world.core.submit_trajectory(trajectory(world, times, points))
    world.run_until(lambda: run.done, 60.0, "sweep done")
    assert run.success, run.failure().result.reason
    return tuple(points[-1])


SWEEP = {"v1": sweep_v1, "v3": sweep_v3}


@pytest.mark.parametrize("pace", ["fast", "slow"])
@pytest.mark.parametrize("rule", RULES)
@pytest.mark.parametrize("protocol", ["v1", "v3"])
def test_the_joints_follow_the_arm_through_the_wrist_singularity(kin, protocol, rule, pace):
    world = make_world(kin, protocol, rule, pace)
    truth = Truth(world)
    world.run_for(world.bus_period)
    since = world.now
    goal = SWEEP[protocol](world, pace)
    world.run_for(0.5)
    verdict = Verdict(world, truth, published(world, since))
    assert verdict.in_band >= (2 if pace == "fast" else 10), "too few samples near joint_5 = 0"
    verdict.check()
    # the arm ends on the planned branch, and the driver knows it
    assert max(abs(a - b) for a, b in zip(world.arm.joints, goal)) <= get(protocol).target_error
    assert max(abs(a - b) for a, b in zip(world.status().joints, world.arm.joints)) <= ACCURACY
    assert world.core.tracker.limited == 0


@pytest.mark.parametrize("protocol", ["v1", "v3"])
def test_lost_and_corrupt_records_near_the_singularity_change_no_branch(kin, protocol):
    """Two bus cycles without a reply where joint_5 first comes within 3 deg of 0, and a corrupt
    record (40 mm, 7 deg off) where it comes within BAND on the way back: the joints move no more
    than the arm can in the time, stay on its branch, and are the arm's again at the next record."""
    world = make_world(kin, protocol, "previous_target", "slow")
    truth = Truth(world)
    corrupt = Corrupt(world)
    state = {"cut": None, "back": False}
    world.run_for(world.bus_period)

    def watch(status):
        q5 = world.arm.joints[4]
        if state["cut"] is None and abs(q5) < 3.0 * DEG:
            state["cut"] = status.time
            world.link.cut = True
        elif state["cut"] is not None and world.link.cut and status.time > state["cut"] + 1.5 * world.bus_period:
            world.link.cut = False
        if q5 < -20.0 * DEG:
            state["back"] = True
        if state["back"] and corrupt.done_at is None and abs(q5) < BAND:
            corrupt.armed = True
    world.core.add_listener(watch)
    since = world.now
    goal = SWEEP[protocol](world, "slow")
    world.run_for(0.5)
    assert state["cut"] is not None and corrupt.done_at is not None
    assert world.core.link.counters.losses == 0          # ridden out: records lost, not the link
    samples = published(world, since)
    Verdict(world, truth, samples, skip=(corrupt.done_at,)).check()
    # the corrupt record: no further from the arm than the velocity limits allow in its time
    vmax = np.array(world.kin.limits.velocity)
    k = next(i for i, s in enumerate(samples) if s.time == corrupt.done_at)
    (t0, _q0), (t1, q1) = truth.at(samples[k - 1]), truth.at(samples[k], check=False)
    off = np.abs(np.array(samples[k].joints) - np.array(q1))
    assert np.all(off <= vmax * (t1 - t0) * VELOCITY_MARGIN + ACCURACY), off / DEG
    assert world.core.tracker.doubted == 1 and world.core.tracker.limited == 0     # not believed
    assert max(abs(a - b) for a, b in zip(world.arm.joints, goal)) <= get(protocol).target_error
    assert max(abs(a - b) for a, b in zip(world.status().joints, world.arm.joints)) <= ACCURACY


@pytest.mark.parametrize("rule", RULES)
def test_after_a_stop_the_rule_decides_the_branch_and_the_joints_follow_it(kin, rule):
    """v1: a PTP turning joint_6 by +3 rad is stopped about a third of the way; the next PTP's
    target has its joint_6 solutions a full turn apart for the two rules -- nearest the previous
    target (the unreached one: previous_target) or nearest where the arm stopped (current_joints).
    The virtual G2 runs the one its rule gives; the driver, applying the same rule to what it sent,
    publishes the arm's joints all the way."""
    world = make_world(kin, "v1", rule, "slow")
    truth = Truth(world)
    world.run_for(world.bus_period)
    q_a = tuple(world.arm.joints)
    far = q_a[:5] + (q_a[5] + 3.0,)
    job = world.core.submit(MoveRequest(MoveType.PTP, kin.fk_pose(far)))
    world.run_until(lambda: world.arm.joints[5] > q_a[5] + 0.8, 30.0, "a third of the turn")
    world.core.cancel(job, "test: stop")
    world.finish(job)
    stopped = tuple(world.arm.joints)
    assert 0.8 < stopped[5] - q_a[5] < 1.6 and not world.arm.moving
    previous = tuple(job.preview.joint_target)                  # the target the arm never reached
    # joint_6's solutions: 0.5 rad below the start (nearest the stop), a turn above (nearest the
    # unreached target)
    goal = q_a[:5] + (q_a[5] - 0.5,)
    target = ControllerPose(*[float(round(v)) for v in kin.fk_pose(goal).as_tuple()])
    by_rule = {r: kin.ik_pose(target, seed=ConfigurationRule.parse(r).seed(previous, stopped)) for r in RULES}
    assert abs(by_rule["previous_target"][5] - by_rule["current_joints"][5]) > 6.0, by_rule
    since = world.now
    job = world.core.submit(MoveRequest(MoveType.PTP, target))
    assert world.finish(job, 60.0).success, job.result.reason
    world.run_for(0.5)
    assert max(abs(a - b) for a, b in zip(world.arm.joints, by_rule[rule])) < 1e-6      # the G2's rule
    Verdict(world, truth, published(world, since)).check()
    assert max(abs(a - b) for a, b in zip(world.status().joints, world.arm.joints)) <= ACCURACY


#: (the virtual G2's rule, the driver's controller/configuration, the stream's points [deg of joint_6
#: from the start], where the arm ends [deg])
TAKEN_AHEAD_CASES = [
    ("previous_target", "previous_target", [80, 160, 240], 240.0),
    ("current_joints", "current_joints", list(range(20, 241, 20)), 240.0),
    ("current_joints", "previous_target", [80, 160, 240], -120.0),
]


@pytest.mark.parametrize("rule, told, stream, ends", TAKEN_AHEAD_CASES,
                         ids=["previous_target", "current_joints", "current_joints-told-previous_target"])
def test_v3_targets_taken_ahead_are_solved_by_the_rule_and_the_joints_follow_it(kin, rule, told, stream, ends, caplog):
    """v3: a stream turning joint_6 by 240 deg (12 planned points 20 deg apart); the ring takes
    four targets while the arm is still near the start. Told previous_target, the driver keeps
    three targets 80 deg apart: the third one's pose is solved at +240 deg nearest the previous
    target, but at -120 deg nearest the arm. Told current_joints, it keeps points at most
    90 / (ring_size + 1) = 18 deg apart -- every planned point -- so that the arm, up to five points
    behind when the G2 takes a target, is nearest the planned solution: the arm turns +240 deg as
    planned. The G2 at current_joints with the driver told previous_target (a commissioning not
    applied): the arm turns back on its last segment, and the driver's joints follow it -- off the
    commanded path, which has the same pose a turn away -- with a warning that names the rule.
    Every published sample is the arm's joints."""
    world = make_world(kin, "v3", rule, told=told)
    truth = Truth(world)
    world.run_for(world.bus_period)
    q0 = np.array(world.status().joints)
    n = 12
    points = [tuple(q0 + np.array([0.0] * 5 + [240.0 * DEG * k / n])) for k in range(1, n + 1)]
    times = [3.0 * k / n for k in range(1, n + 1)]
    since = world.now
    run = world.core.submit_trajectory(trajectory(world, times, points))
    assert [round((p.joints[5] - q0[5]) / DEG) for p in run.jobs[0].points] == stream
    world.run_until(lambda: run.done, 60.0, "stream done")
    world.run_for(0.5)
    turned = (world.arm.joints[5] - q0[5]) / DEG
    assert turned == pytest.approx(ends, abs=0.1)
    Verdict(world, truth, published(world, since)).check()
    assert max(abs(a - b) for a, b in zip(world.status().joints, world.arm.joints)) <= ACCURACY
    warned = [r.getMessage() for r in caplog.records if "only on another branch" in r.getMessage()]
    if rule == told:
        assert world.core.tracker.off_branch == 0 and not warned
    else:
        assert world.core.tracker.off_branch >= 1
        assert len(warned) == 1 and "controller/configuration previous_target" in warned[0], warned


def test_the_configuration_rule_is_a_parameter_of_the_virtual_g2():
    from vr_driver.controller.options import SimOptions
    from vr_driver.controller.simulator import SimError
    from vr_driver.controller.stream_arm import SimStreamArm
    from vr_driver.errors import MotionError
    assert SimOptions().configuration == "previous_target"
    assert SimOptions.from_mapping({"configuration": "Current_Joints"}).configuration == "current_joints"
    with pytest.raises(SimError, match="configuration.*previous_target or current_joints"):
        SimOptions(configuration="nearest_home")
    with pytest.raises(MotionError, match="configuration"):
        SimStreamArm(configuration="nearest_home")


def test_a_record_farther_than_the_arm_can_move_is_believed_only_when_the_next_agrees(kin):
    """The tracker alone, without a commanded path: a single record 40 deg of joint_1 away (the
    arm cannot turn that far in 50 ms) changes nothing; when the next records agree, the joints go
    there as fast as the arm can, and stay once there."""
    from vr_driver.driver.joints.tracking import JointTracker
    tracker = JointTracker(kin, (1.0, 1.0))
    here = (0.1, 0.55, -0.2, 0.5, 30.0 * DEG, -0.7)
    there = (0.1 + 40.0 * DEG,) + here[1:]

    def report(q):
        return ControllerPose(*[float(round(v)) for v in kin.fk_pose(q).as_tuple()])
    t = 100.0
    start = tracker.update(report(here), t)
    assert max(abs(a - b) for a, b in zip(start, here)) < 1.5 * DEG
    t += 0.05
    assert tracker.update(report(there), t) == start and tracker.doubted == 1       # not believed
    assert tracker.update(report(here), t + 0.05) == pytest.approx(start)           # a corrupt one
    t += 0.05
    steps = []
    for _ in range(20):
        t += 0.05
        before = tracker.joints
        tracker.update(report(there), t)
        steps.append(abs(tracker.joints[0] - before[0]))
    # the first record there is doubted again (the one before agreed with the joints); the next
    # one moves as far as the arm can in the time of both, then one record's worth each
    room = kin.limits.velocity[0] * 0.05 * VELOCITY_MARGIN
    assert tracker.doubted == 2 and tracker.limited >= 2
    assert steps[0] == 0.0 and steps[1] <= 2 * room + 1e-9, [round(s / DEG, 2) for s in steps]
    assert max(steps[2:]) <= room + 1e-9 and steps[-1] == 0.0, [round(s / DEG, 2) for s in steps]
    assert abs(tracker.joints[0] - there[0]) < 1.5 * DEG


@pytest.mark.parametrize("rule", RULES)
def test_v3_at_rest_at_a_target_the_joints_are_the_controllers_solution_of_its_wire_pose(kin, rule):
    """v3: a 30-point stream ending at rest. The arm stands exactly at the controller's IK solution
    of the last target's wire pose (0.1 mm / 0.01 deg) and the report is that same rounded pose:
    the driver publishes that solution, not a planned point a hundredth of a degree away."""
    world = make_world(kin, "v3", rule)
    world.run_for(world.bus_period)
    q0 = np.array(world.status().joints)
    n = 30
    points = [tuple(q0 + np.array([0.3, -0.2, 0.25, 0.4, -0.3, 0.5]) * math.sin(0.5 * math.pi * k / n))
              for k in range(1, n + 1)]
    times = [3.0 * k / n for k in range(1, n + 1)]
    run = world.core.submit_trajectory(trajectory(world, times, points))
    world.run_until(lambda: run.done, 60.0, "stream done")
    world.run_for(0.5)
    assert not world.arm.moving
    off = max(abs(a - b) for a, b in zip(world.status().joints, world.arm.joints))
    assert off < 1e-6, off / DEG
