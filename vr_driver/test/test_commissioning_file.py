"""The commissioning's file as the driver takes it: written by the tool's own writer
(vr_driver.commission.report, as `rosrun vr_driver commission` writes it), read by DriverParams, and
loaded by ``driver.launch commissioning:=FILE`` (``roslaunch --dump-params``: the whole launch
resolved, no master, no node) into the driver node's private namespace -- over the config file's
values, with the planner's limits from the joint_limits.yaml beside it -- where DriverParams accepts
the node's parameters as the node would get them. Without ``commissioning`` nothing changes."""
from __future__ import annotations

import datetime
import os
import subprocess
from typing import Any, Dict

import pytest
import yaml

from vr_driver.commission.report import joint_limits, write_joint_limits, write_yaml
from vr_driver.commission.steps import Finding, StepResult
from vr_driver.params import DriverParams

HERE = os.path.dirname(os.path.abspath(__file__))
LAUNCH = os.path.join(os.path.dirname(HERE), "launch", "driver.launch")
NODE = "/interface/"

#: what a commissioning of an older G2 measured (the tool's ``measured`` keys)
MEASURED = {"byte_order": "big", "check_word": True, "loop_period": 0.0102, "loop_period_spread": 0.0004,
            "loop_blocks_during_move": False, "send_ahead": "refused", "speed_scale": 0.6012,
            "ring_size": 4, "interpreter_lookahead": 1, "configuration": "previous_target",
            "accelerations": {1: 4.18, 2: 4.2, 3: 4.3, 4: 7.6, 5: 10.5, 6: 10.4}, "ramp_time": 0.5,
            "ramp_shape": "linear", "unreachable": "skip"}


def commissioning_files(tmp_path, kin, measured=MEASURED, not_measured=None) -> str:
    lim = kin.limits
    limits = joint_limits(lim.names, lim.velocity, lim.acceleration, measured)
    path = str(tmp_path / "g2.yaml")
    beside = str(tmp_path / "joint_limits.yaml")
    results = [StepResult("card", findings=[Finding("byte order", "little", "big", "byte_order: big", False)],
                          seconds=2.5),
               StepResult("configuration", status="skipped"),
               StepResult("unreachable", findings=[Finding("unreachable pose", "refused", "not measured", "-")])]
    identity = {"protocol": "v3", "ident": "0x06C6", "station_address": 4, "chk_cfg": "17 17 17 13 27 27 27",
                "baud": 19200, "diag": None}
    write_yaml(path, measured, identity, results, beside, 61.3,
               date=datetime.datetime(2025, 3, 4, 14, 5, tzinfo=datetime.timezone.utc), not_measured=not_measured)
    write_joint_limits(beside, limits, path, sorted(measured.get("accelerations", {})))
    return path


def dump(*args: str) -> Dict[str, Any]:
    res = subprocess.run(["roslaunch", "--dump-params", LAUNCH] + list(args), capture_output=True, text=True,
                         timeout=120)
    assert res.returncode == 0 and "Unable to load" not in res.stderr, res.stderr[-2000:]
    return yaml.safe_load(res.stdout)


def node_params(dumped: Dict[str, Any]) -> Dict[str, Any]:
    """The interface node's private parameters as ``rospy.get_param("~")`` returns them (nested)."""
    out: Dict[str, Any] = {}
    for key, value in dumped.items():
        if not key.startswith(NODE):
            continue
        *parents, leaf = key[len(NODE):].split("/")
        node = out
        for p in parents:
            node = node.setdefault(p, {})
        node[leaf] = value
    return out


def test_the_file_is_driver_params(tmp_path, kin):
    path = commissioning_files(tmp_path, kin)
    with open(path, encoding="utf-8") as fh:
        text = fh.read()
    assert text.startswith("# Written by `rosrun vr_driver commission` on 2025-03-04")
    doc = yaml.safe_load(text)
    assert "null" not in text and None not in doc["commissioning"]["controller"].values()
    params = DriverParams.from_dict(dict(doc, port="/dev/null"))
    assert params.protocol == "v3" and params.byte_order == "big"
    facts = params.controller
    assert facts.speed_scale == pytest.approx(0.6012) and facts.send_ahead == "refused"
    assert facts.acceleration("joint_5") == 10.5 and facts.ramp_time == 0.5
    assert params.planning_limits == str(tmp_path / "joint_limits.yaml")
    assert params.commissioning["robot_time"] == 61.3
    assert params.wire.send_ahead == 1


def test_driver_launch_commissioning_sets_the_node_parameters(tmp_path, kin):
    path = commissioning_files(tmp_path, kin)
    dumped = dump("commissioning:=" + path)
    mine = node_params(dumped)
    # the file over the config file's values; the planner's limits beside it; v3 by default
    assert mine["protocol"] == "v3" and mine["byte_order"] == "big"
    assert mine["planning_limits"] == str(tmp_path / "joint_limits.yaml")
    assert mine["controller"]["speed_scale"] == pytest.approx(0.6012)
    assert mine["controller"]["accelerations"]["joint_1"] == 4.18
    assert mine["commissioning"]["controller"]["ident"] == "0x06C6"
    assert dumped["/virtual_controller/protocol"] == "v3"
    # the parameter server holds no None (roslaunch could not set it)
    nones = [k for k, v in dumped.items() if v is None]
    assert not nones, nones
    # what the node gets is valid, and is the commissioning's
    params = DriverParams.from_dict(dict(mine, port="/dev/null"))
    with open(path, encoding="utf-8") as fh:
        assert params.controller == DriverParams.from_dict(dict(yaml.safe_load(fh), port="/dev/null")).controller
    assert params.stream_smooth == 3                     # the config file's: the arm blends
    # an explicit protocol still wins
    assert node_params(dump("commissioning:=" + path, "protocol:=v1"))["protocol"] == "v1"


def test_driver_launch_without_commissioning_changes_nothing():
    mine = node_params(dump())
    assert mine["protocol"] == "v1" and mine["planning_limits"] == ""
    params = DriverParams.from_dict(dict(mine, port="/dev/null"))
    assert params.controller == DriverParams.from_dict({}).controller
    assert params.commissioning == {}


def test_no_lookahead_file_sets_stream_smooth_0(tmp_path, kin):
    path = commissioning_files(tmp_path, kin, dict(MEASURED, interpreter_lookahead=0))
    mine = node_params(dump("commissioning:=" + path))
    assert mine["stream_smooth"] == 0 and mine["controller"]["interpreter_lookahead"] == 0
    assert DriverParams.from_dict(dict(mine, port="/dev/null")).stream_smooth == 0


def test_what_the_bus_hid_is_not_measured_in_the_file_and_the_driver(tmp_path, kin):
    """A program loop that blocked during a MOVE hid the look-ahead and the ring: the file lists them
    under controller/not_measured (the reasons under commissioning/not_measured), writes no value for
    them, and loads through driver.launch; the driver keeps the assumptions, and on v3 runs every
    stream point as a stop. An unknown key is refused by name."""
    hidden = {k: v for k, v in MEASURED.items() if k not in ("interpreter_lookahead", "ring_size")}
    why = "the program loop blocks during a MOVE"
    path = commissioning_files(tmp_path, kin, hidden, {"interpreter_lookahead": why, "ring_size": why})
    with open(path, encoding="utf-8") as fh:
        doc = yaml.safe_load(fh)
    assert doc["controller"]["not_measured"] == ["interpreter_lookahead", "ring_size"]
    assert "interpreter_lookahead" not in doc["controller"] and "ring_size" not in doc["controller"]
    assert doc["commissioning"]["not_measured"]["ring_size"] == why
    mine = node_params(dump("commissioning:=" + path))
    params = DriverParams.from_dict(dict(mine, port="/dev/null"))
    assert params.protocol == "v3" and params.stream_smooth == 0
    assert params.controller.not_measured == ("interpreter_lookahead", "ring_size")
    assert params.controller.interpreter_lookahead == 1 and params.controller.ring_size == 4
    from vr_driver.params import ParamError
    with pytest.raises(ParamError) as err:
        DriverParams.from_dict({"port": "/dev/null", "controller": {"not_measured": ["lookahead"]}})
    assert err.value.name == "controller/not_measured" and "no controller key" in str(err.value)
