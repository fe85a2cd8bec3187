"""vr_driver.validate: the one set of value checks, and the modules that used to carry copies of it
(params, csr.fields, controller.options, protocol.v1, poses, controller.arm, terminal.pose_input) keep their error types
and wording while sharing it."""
from __future__ import annotations

import math
import os
import subprocess
import sys

import numpy as np
import pytest

import vr_driver.protocol.v1 as protocol
import vr_driver.terminal.pose_input as pose_input
from vr_driver import validate
from vr_driver.controller.options import SimOptions
from vr_driver.controller.simulator import SimError
from vr_driver.csr.fields import _integer as csr_integer
from vr_driver.csr.fields import _number as csr_number
from vr_driver.controller.program_v3 import SendAhead
from vr_driver.controller.session import Unreachable
from vr_driver.controller.stream_arm import RampShape
from vr_driver.errors import CsrError, HandshakeError, MotionError, PoseError, VrDriverError
from vr_driver.kinematics.solver import ConfigurationRule
from vr_driver.params import DriverParams, ParamError
from vr_driver.poses import ControllerPose, MoveType, finite_number
from vr_driver.terminal.pose_input import PoseRequest


def _fail(got):
    return ValueError("bad" if got is None else "out %r" % (got,))


# ------------------------------------------------------------------------------------ the checks

@pytest.mark.parametrize("value", [None, True, False, np.bool_(True), "x", "nan", float("inf"), -math.inf,
                                   math.nan, [1.0], object(), 10 ** 400])
def test_not_finite_numbers(value):
    assert validate.as_finite(value) is None
    with pytest.raises(ValueError, match="^bad$"):
        validate.number(value, _fail)


@pytest.mark.parametrize("value, expected", [(1, 1.0), (-2.5, -2.5), (np.float32(0.5), 0.5), (" 1e3 ", 1000.0)])
def test_finite_numbers(value, expected):
    assert validate.number(value, _fail) == expected and isinstance(validate.number(value, _fail), float)


def test_text_false_takes_only_int_and_float():
    assert validate.as_finite("1.5", text=False) is None and validate.as_finite(1.5, text=False) == 1.5
    assert validate.as_finite(np.float64(2.0), text=False) == 2.0          # a float subclass


def test_number_range_and_open_lower_bound():
    assert validate.number(0.0, _fail, 0.0, 1.0) == 0.0
    with pytest.raises(ValueError, match="^out 0.0$"):
        validate.number(0.0, _fail, 0.0, 1.0, lo_open=True)
    with pytest.raises(ValueError, match="^out 1.5$"):
        validate.number("1.5", _fail, 0.0, 1.0)
    assert validate.number(1e9, _fail, 0.0) == 1e9                          # hi None: open-ended


@pytest.mark.parametrize("value, kwargs, expected", [
    (7, {}, 7), (np.int64(-3), {}, -3), (True, {}, None), (7.0, {}, None), ("7", {}, None),
    (" -12 ", {"text": True}, -12), ("1.0", {"text": True}, None), ("0x10", {"text": True}, None),
    (12.0, {"integral": True}, 12), (12.5, {"integral": True}, None), (math.inf, {"integral": True}, None),
    (math.nan, {"integral": True}, None), (np.bool_(False), {"integral": True, "text": True}, None),
])
def test_as_integer(value, kwargs, expected):
    assert validate.as_integer(value, **kwargs) == expected


def test_integer_range():
    assert validate.integer(5, _fail, 0, 5) == 5
    with pytest.raises(ValueError, match="^out 6$"):
        validate.integer(6, _fail, 0, 5)
    with pytest.raises(ValueError, match="^bad$"):
        validate.integer("5", _fail, 0, 5)


def test_choice_takes_a_member_or_its_word_and_names_the_words_otherwise():
    shape = validate.choice(RampShape, " S_Curve ", _fail)
    assert shape is RampShape.S_CURVE and validate.choice(RampShape, shape, _fail) is shape
    with pytest.raises(ValueError, match="^words: linear or s_curve$") as caught:
        validate.choice(RampShape, "cubic", lambda words: ValueError("words: " + words))
    assert caught.value.__cause__ is None and caught.value.__suppress_context__


@pytest.mark.parametrize("kind, value, error, message", [
    (RampShape, "cubic", MotionError, "ramp_shape must be linear or s_curve, got 'cubic'"),
    (SendAhead, 3, MotionError, "send_ahead must be accepted or refused, got 3"),
    (Unreachable, None, VrDriverError, "unreachable must be skip or alarm_halt, got None"),
    (MoveType, "spline", MotionError, "unknown move type 'spline' (ptp, lin, circ)"),
    (ConfigurationRule, "nearest", PoseError,
     "unknown configuration rule 'nearest' (previous_target or current_joints)"),
])
def test_enum_parse_keeps_each_enums_error_and_words(kind, value, error, message):
    """The enums whose ``parse`` is :func:`validate.choice_parser`: each its own error type and
    message, word for word; a member or its word (any case) is taken."""
    with pytest.raises(error) as caught:
        kind.parse(value)
    assert str(caught.value) == message
    first = list(kind)[0]
    assert kind.parse(first) is first and kind.parse(" %s " % first.value.upper()) is first


def test_validate_imports_without_kdl_and_ros():
    src = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "src")
    script = ("import sys\nfor n in ('PyKDL', 'rospy', 'rospkg'): sys.modules[n] = None\n"
              "sys.path.insert(0, %r)\nimport vr_driver.validate\nprint('ok')" % src)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and proc.stdout.strip() == "ok", proc.stderr


# --------------------------------------------------------- each caller keeps its error and wording

def test_params_keep_param_error_wording():
    with pytest.raises(ParamError, match=r"~cycle_rate = 'fast': expected a finite number"):
        DriverParams.from_dict({"cycle_rate": "fast"})           # strings are no parameter numbers
    with pytest.raises(ParamError, match=r"~cycle_rate = 0\.0: must be in \(0, 1000\]"):
        DriverParams.from_dict({"cycle_rate": 0.0})
    with pytest.raises(ParamError, match=r"~baud = True: expected an integer"):
        DriverParams.from_dict({"baud": True})
    with pytest.raises(ParamError, match=r"~slave_address = 126: must be in \[0, 125\]"):
        DriverParams.from_dict({"slave_address": 126})
    with pytest.raises(ParamError, match=r"~cycle_rate = 1e\+400|~cycle_rate = \d+: expected a finite number"):
        DriverParams.from_dict({"cycle_rate": 10 ** 400})        # no OverflowError


def test_csr_fields_keep_csr_error_wording():
    assert csr_number(" 2.5 ", "speed") == 2.5 and csr_integer(" -1 ", "smooth", -1, 10) == -1
    with pytest.raises(CsrError, match="must be a finite number, got 'inf'") as err:
        csr_number("inf", "speed")
    assert err.value.field == "speed"
    with pytest.raises(CsrError, match=r"11 is outside \[-1, 10\]"):
        csr_integer(11, "smooth", -1, 10)
    with pytest.raises(CsrError, match="must be an integer, got True"):
        csr_integer(True, "smooth")


def test_sim_options_keep_sim_error_wording():
    assert SimOptions(address="5", baud=19200.0).address == 5
    with pytest.raises(SimError, match=r"speed_factor must be a finite number > 0, got 0"):
        SimOptions(speed_factor=0)
    with pytest.raises(SimError, match=r"addr must be an integer in 0\.\.125, got 4\.5"):
        SimOptions(address=4.5)
    with pytest.raises(SimError, match=r"addr must be an integer in 0\.\.125, got inf"):
        SimOptions(address=math.inf)                                 # was an OverflowError
    with pytest.raises(SimError, match=r"addr = 126 is outside 0\.\.125"):
        SimOptions(address=126)
    with pytest.raises(SimError, match=r"brake_time must be a finite number >= 0 \(seconds\), got -1"):
        SimOptions(brake_time=-1)


def test_protocol_and_poses_keep_their_errors():
    with pytest.raises(HandshakeError, match="accept_timeout must be a positive number of seconds, got 0"):
        protocol.MasterHandshake(accept_timeout=0)
    with pytest.raises(PoseError, match="x must be a finite number, got True"):
        finite_number(True, "x")
    with pytest.raises(protocol.ProtocolError, match=r"command X = 40000 is outside the int16 range"):
        protocol.Command(40000, 0, 0, 0, 0, 0, True, protocol.WireMoveType.PTP)
    with pytest.raises(protocol.ProtocolError, match="command X must be an integer"):
        protocol.Command(1.0, 0, 0, 0, 0, 0, True, protocol.WireMoveType.PTP)


def test_sim_arm_keeps_motion_error_wording():
    from vr_driver.controller.arm import SimArm
    with pytest.raises(MotionError, match="speed_factor must be a finite number > 0, got '2'"):
        SimArm(speed_factor="2")
    with pytest.raises(MotionError, match="brake_time must be a finite number >= 0, got nan"):
        SimArm(brake_time=math.nan)


# ------------------------------------------------------------------- one round_half_away

def test_pose_input_rounds_with_protocols_function():
    assert not hasattr(pose_input, "_round_half_away")
    assert pose_input.round_half_away is protocol.round_half_away
    values = (0.5, -0.5, 2.5, -2.5, 0.49999999999999994, 1120.5, -179.5)
    request = PoseRequest(MoveType.PTP, ControllerPose(*values[:6]))
    assert request.sent_values() == [tuple(protocol.round_half_away(v) for v in values[:6])]
    assert request.sent_values() == [(1, -1, 3, -3, 0, 1121)]
