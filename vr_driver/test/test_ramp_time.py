"""The arm's acceleration: one set of joint limits (panasonic_vr006l_support's kinematics_vr006l.yaml)
behind Kinematics.limits.acceleration and the virtual arm's default ramp time; the ``ramp_time``
option of the virtual controller (an older controller ramps slower, e.g. 0.5 s)."""
from __future__ import annotations

import math

import pytest

from panasonic_vr006l_support import joint_limits as model_limits
from vr_driver.controller.arm import SimArm
from vr_driver.controller.cli import main
from vr_driver.controller.options import SimOptions
from vr_driver.controller.simulator import SimError
from vr_driver.controller.virtual_controller import VirtualController
from vr_driver.controller.stream_arm import DEFAULT_RAMP_TIME, SimStreamArm, StreamTarget
from vr_driver.errors import ModelError, MotionError
from vr_driver.kinematics.solver import Kinematics

START = (0.0, 0.4, -0.3, 0.0, 0.6, 0.0)


def test_the_model_set_gives_the_accelerations_and_the_ramp_of_a_tenth_of_a_second(kin):
    acc = model_limits.accelerations()
    assert kin.limits.acceleration == tuple(acc[n] for n in kin.limits.names)
    assert kin.limits.acceleration == (20.9, 20.9, 20.9, 20.9, 52.3, 52.3)
    for v, a in zip(kin.limits.velocity, kin.limits.acceleration):
        assert v / a == pytest.approx(0.1, abs=1e-12)          # the documented assumption
    assert kin.limits.ramp_time == DEFAULT_RAMP_TIME == 0.1     # exactly the ramp the arm always had


def test_kinematics_accelerations_by_prefix_given_or_unknown(kin):
    left = Kinematics.default(prefix="left_")
    assert left.limits.names[0] == "left_joint_1" and left.limits.acceleration == kin.limits.acceleration
    given = Kinematics(kin.model, kin.base, kin.tip, accelerations={"joint_1": 1.0, "joint_5": 2.0})
    assert given.limits.acceleration[:2] == (1.0, math.inf) and given.limits.acceleration[4] == 2.0
    assert given.limits.ramp_time == pytest.approx(max(2.09 / 1.0, 5.23 / 2.0))
    unknown = Kinematics(kin.model, kin.base, kin.tip, accelerations={})
    assert unknown.limits.ramp_time is None
    assert SimStreamArm(unknown, initial_joints=START).ramp_time == DEFAULT_RAMP_TIME
    for bad in (0.0, -1.0, float("nan"), "fast"):
        with pytest.raises(ModelError, match="joint_2"):
            Kinematics(kin.model, kin.base, kin.tip, accelerations={"joint_2": bad})


def _rest_to_rest(kin, ramp_time):
    t = [0.0]
    arm = SimStreamArm(kin, initial_joints=START, clock=lambda: t[0], ramp_time=ramp_time)
    goal = [q + d for q, d in zip(START, (1.5, 0.0, 0.0, 0.0, 0.0, 0.0))]
    arm.push(StreamTarget(1, tuple(round(math.degrees(q) * 1000) for q in goal), 1000, 0, 0.0), now=0.0)
    done = []
    while not done and t[0] < 10.0:
        t[0] += 0.001
        done = arm.step(t[0])
    assert done and done[0].seq == 1
    return arm, done[0].end_time - done[0].start_time


def test_the_default_ramp_is_the_model_s_and_a_slower_one_lengthens_a_move_by_its_difference(kin):
    arm, fast = _rest_to_rest(kin, None)
    assert arm.ramp_time == 0.1
    arm, slow = _rest_to_rest(kin, 0.5)
    assert arm.ramp_time == 0.5
    t0 = math.radians(round(math.degrees(1.5) * 1000) / 1000) / 2.09    # J1 at full speed
    assert fast == pytest.approx(t0 + 0.1, abs=2e-3)        # rest to rest: T0 + r
    assert t0 > 0.5 and slow == pytest.approx(t0 + 0.5, abs=2e-3)    # (a move shorter than the ramp ramps over T0)


def test_ramp_time_option_is_checked_and_reaches_the_streaming_arm(kin):
    assert SimOptions().ramp_time is None
    assert SimOptions(ramp_time="0.5").ramp_time == 0.5
    assert SimOptions.from_mapping({"protocol": "v3", "ramp_time": 0.5}).ramp_time == 0.5
    for bad in (0, -0.1, float("nan"), float("inf"), "slow", True):
        with pytest.raises(SimError, match="ramp_time must be a finite number > 0"):
            SimOptions(ramp_time=bad)
    assert main(["--protocol", "v3", "--ramp-time", "0"]) == 2
    assert main(["--protocol", "v2", "--ramp-time", "nan"]) == 2
    for protocol in ("v2", "v3"):
        for given, expected in ((None, 0.1), (0.5, 0.5)):
            vc = VirtualController(kinematics=kin, protocol=protocol, ramp_time=given)
            try:
                assert isinstance(vc.arm, SimStreamArm) and vc.arm.ramp_time == expected
                assert vc.options.ramp_time == given
            finally:
                vc.stop()
    vc = VirtualController(kinematics=kin, protocol="v1", ramp_time=0.5)     # v1's arm: a share of each move
    try:
        assert isinstance(vc.arm, SimArm)
    finally:
        vc.stop()
    with pytest.raises(MotionError):
        SimStreamArm(kin, ramp_time=float("inf"))
