"""`rosrun vr_driver commission --yes` against the virtual G2 over a REAL pty pair (real telegrams, the
tool in a process of its own, the controller's threads in this one), in settings that each change one
assumption about the G2 (doc/controller_program.md §10.9): the tool must find each -- the look-ahead
and the rules exactly, the speed unit within 2 %, the accelerations within 10 %, the loop period
within 1 ms -- and print the robot time of the run. The YAML it writes is read back and checked;
so is the joint_limits.yaml beside it.

The moves are short and fast (the virtual arm runs in real time) and each setting runs only the steps
its assumption needs besides the quick ones (the full run is the default setting's); settings run
one after the other (the timing of both ends must not depend on a neighbour's load)."""
from __future__ import annotations

import os
import subprocess
import sys
from typing import Any, Dict, List, Tuple

import pytest
import yaml

from vr_driver.commission.steps import STEP_NAMES
from vr_driver.controller.virtual_controller import VirtualController
from vr_driver.params import DriverParams, ParamError

from _priority import threads_at_real_time

HERE = os.path.dirname(os.path.abspath(__file__))
NODE = os.path.join(os.path.dirname(HERE), "nodes", "commission")
BAUD = 187500
CYCLE_RATE = 250.0
LOOP = 0.01

# quick sizes: degrees, percent, seconds (doc/commissioning.md has the real arm's)
QUICK = ["--watchdog-ms", "1000", "--heartbeat-time", "1.0", "--loop-move", "20", "--loop-percent", "30", "--speed-move", "25",
         "--speed-percent", "50", "--stream-step", "8", "--stream-percent", "50", "--config-percent", "100",
         "--ramp-move", "25", "--ramp-percent", "100", "--hold-time", "0.2",
         # the tool's bus at real-time priority where the system allows it (above the virtual G2's
         # HARDWARE_PRIORITY), as a user's commissioning would run it
         "--rt-priority", "20"]
MOTION = ["speed", "lookahead", "configuration", "ramps"]


def skip(*names: str) -> List[str]:
    return ["--skip", ",".join(names)] if names else []


#: SCHED_FIFO priority of the virtual G2's threads where allowed (as the virtual hardware's ROS nodes:
#: below the tool's own bus, --rt-priority 20)
HARDWARE_PRIORITY = 10


def run_commission(tmp_path, vc_options: Dict[str, Any], args: List[str], timeout: float = 120.0,
                   cycle_rate: float = CYCLE_RATE) -> Tuple[Dict[str, Any], str, VirtualController]:
    """Start the virtual G2 with ``vc_options``, run the tool against it, return (its YAML, its
    output, the controller)."""
    vc = VirtualController(protocol="v3", baud=vc_options.pop("baud", BAUD), loop_period=vc_options.pop("loop_period", LOOP),
                           **vc_options)
    out = tmp_path / "commissioning.yaml"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
    # the virtual G2 stands for hardware, which is never late: its threads at real-time priority
    # where the system allows it (the tool measures the loop period to 1 ms; a starved controller
    # thread once measured 15.5 ms for 10 ms in a loaded run) -- and this thread too while it waits
    # on the tool: at normal priority, preempted while it held the interpreter's lock (reading the
    # tool's output), it would hold the controller's threads back with it
    with threads_at_real_time(HARDWARE_PRIORITY):
        vc.start()
        try:
            proc = subprocess.run([sys.executable, NODE, "--port", vc.device_path, "--baud", str(vc.options.baud),
                                   "--cycle-rate", str(cycle_rate), "--yes", "--out", str(out)] + QUICK + args,
                                  stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env,
                                  timeout=timeout)
        finally:
            vc.stop()
    assert vc.error is None and vc.server_error is None, (vc.error, vc.server_error)
    assert proc.returncode == 0, proc.stdout[-3000:]
    assert "robot time: " in proc.stdout
    assert "scheduling: " in proc.stdout           # how the tool's bus was scheduled, in words
    with open(out, encoding="utf-8") as fh:
        doc = yaml.safe_load(fh)
    # the file is the driver's parameters as they are: DriverParams takes it (driver.launch loads it)
    assert doc["planning_limits"] == str(tmp_path / "joint_limits.yaml")
    params = DriverParams.from_dict(dict(doc, port="/dev/null"))
    assert params.protocol == doc["protocol"] and params.commissioning["date"] == doc["commissioning"]["date"]
    return doc, proc.stdout, vc


def lookahead_words(text: str) -> str:
    """The tool's look-ahead step from its output, for a failing verdict's message (one fresh clone in
    ten found a look-ahead of 0 for the virtual G2's 1, beside the computing tests: the step's own
    figures say why)."""
    start = text.find("lookahead")
    return text[max(0, start - 200):start + 2500] if start >= 0 else text[-3000:]


def limits_of(doc: Dict[str, Any]) -> Dict[str, Any]:
    """The planner's limits the YAML names (planning_limits: the joint_limits.yaml beside it)."""
    with open(doc["planning_limits"], encoding="utf-8") as fh:
        return yaml.safe_load(fh)["joint_limits"]


def finding(doc: Dict[str, Any], assumption: str) -> Dict[str, Any]:
    rows = [f for f in doc["commissioning"]["findings"] if f["assumption"].startswith(assumption)]
    assert len(rows) == 1, (assumption, [f["assumption"] for f in doc["commissioning"]["findings"]])
    return rows[0]


def model_accelerations(kin) -> Tuple[float, ...]:
    return tuple(kin.limits.acceleration)


# ------------------------------------------------------------------------------------ the default

def test_default_g2_every_step_as_assumed(tmp_path, kin):
    doc, text, vc = run_commission(tmp_path, {}, [])
    assert doc["protocol"] == "v3" and doc["byte_order"] == "little"
    assert doc["controller"]["interpreter_lookahead"] == 1, lookahead_words(text)
    assert abs(doc["controller"]["loop_period"] - LOOP) < 0.001
    assert doc["controller"]["loop_blocks_during_move"] is False
    assert abs(doc["controller"]["speed_scale"] - 1.0) < 0.02
    assert doc["controller"]["configuration"] == "previous_target"
    assert doc["controller"]["send_ahead"] == "accepted" and doc["controller"]["unreachable"] == "skip"
    assert doc["controller"]["check_word"] is True and doc["controller"]["ring_size"] == 4
    for i, a in enumerate(model_accelerations(kin)):
        assert abs(doc["controller"]["accelerations"]["joint_%d" % (i + 1)] - a) <= 0.1 * a, doc["controller"]["accelerations"]
    assert doc["controller"]["ramp_shape"] == "linear"
    assert "stream_smooth" not in doc                      # the arm blends: the user's setting stays
    ident = doc["commissioning"]["controller"]
    assert ident["ident"] == "0x06C6" and ident["chk_cfg"] == "17 17 17 13 27 27 27"
    assert doc["commissioning"]["date"] and doc["commissioning"]["robot_time"] > 0
    steps = doc["commissioning"]["steps"]
    assert all(s["status"] == "done" for s in steps.values()), steps
    # the card's Data_Exchange status: never measured, listed with its reason
    dx = finding(doc, "the card's Data_Exchange status")
    assert "ok" not in dx and dx["measured"].startswith("not measurable from the bus")
    # every other row as assumed, except the loop's steadiness, which is this machine's load
    bad = [f for f in doc["commissioning"]["findings"] if f.get("ok") is not True
           and not f["assumption"].startswith(("program loop at rest", "the card's Data_Exchange status"))]
    # an unclear verdict ("run the step again, watch the arm": too few records near a point on a
    # loaded machine) is re-measured as the tool advises -- the look-ahead step alone, once -- and
    # must then be clear and as assumed; a verdict that is wrong (False) is never re-measured
    unclear = {f["assumption"] for f in bad if "ok" not in f or f.get("ok") is None}
    if unclear and unclear == {f["assumption"] for f in bad} and unclear <= {"smooth 0 (an exact stop)"}:
        (tmp_path / "again").mkdir()
        again, _text, _vc = run_commission(tmp_path / "again", {}, skip(*(n for n in STEP_NAMES if n != "lookahead")))
        bad = [f for f in again["commissioning"]["findings"] if f["assumption"] in unclear and f.get("ok") is not True]
    assert not bad, bad
    with open(tmp_path / "joint_limits.yaml", encoding="utf-8") as fh:
        limits = yaml.safe_load(fh)["joint_limits"]
    assert limits == limits_of(doc)
    for i, name in enumerate(kin.limits.names):
        assert limits[name]["max_velocity"] == pytest.approx(kin.limits.velocity[i], abs=1e-3)
        assert limits[name]["max_acceleration"] == doc["controller"]["accelerations"]["joint_%d" % (i + 1)]
    # every bus cycle logged
    lines = (tmp_path / "commissioning.cycles.jsonl").read_text().splitlines()
    assert len(lines) > 1000
    assert vc.program.bad_records >= 2                     # the corrupted and the torn record, ignored


# ------------------------------------------------------------------------------------ the changes

def test_no_lookahead(tmp_path):
    doc, text, _ = run_commission(tmp_path, {"interpreter_lookahead": 0}, skip("loop", "speed", "configuration", "ramps"))
    assert doc["controller"]["interpreter_lookahead"] == 0, lookahead_words(text)
    assert doc["stream_smooth"] == 0                       # the driver times every point as a stop
    row = finding(doc, "interpreter look-ahead")
    assert row.get("ok") is False and "string of stops" in row["consequence"]


def test_lookahead_2_and_a_slower_speed_unit(tmp_path):
    doc, text, _ = run_commission(tmp_path, {"interpreter_lookahead": 2, "speed_scale": 0.6},
                                  skip("loop", "configuration", "ramps"))
    # 1 and 2 look alike on the bus (the program's ring feeds the interpreter): ">= 1", written as 1
    assert doc["controller"]["interpreter_lookahead"] == 1, lookahead_words(text)
    assert ">= 1" in finding(doc, "interpreter look-ahead")["measured"]
    assert "stream_smooth" not in doc
    assert abs(doc["controller"]["speed_scale"] - 0.6) <= 0.02 * 0.6
    assert finding(doc, "MOVEP speed unit")["ok"] is False
    assert limits_of(doc)["joint_1"]["max_velocity"] == pytest.approx(0.6 * 2.09, rel=0.02)


@pytest.mark.parametrize("ramp_time, shape, axes, percent", [(0.5, "linear", "1,5", 100), (0.5, "s_curve", "2,6", 50),
                                                              (0.1, "s_curve", "3,4", 100)])
def test_ramps(tmp_path, kin, ramp_time, shape, axes, percent):
    # a ramp of 0.1 s is 10 loops of 10 ms: the S-shape is told from the linear one by a faster loop
    # (4 ms) and bus (500 Hz); a 0.5 s ramp at half speed (0.25 s) at the default ones. At full speed
    # a 0.5 s ramp reaches no cruise in the quick moves (25 deg; joint_1 needs 60 for its two ramps):
    # the tool says so and moves again, sized from the first move's peak speed
    fast = ramp_time < 0.2
    doc, text, _ = run_commission(
        tmp_path, {"ramp_time": ramp_time, "ramp_shape": shape, "loop_period": 0.004 if fast else LOOP},
        skip("loop", "lookahead", "configuration", "speed", "send_ahead")
        + ["--axes", axes, "--ramp-percent", str(percent)], cycle_rate=500.0 if fast else CYCLE_RATE)
    if not fast and percent == 100:
        assert "joint_1: no cruise speed in 25 deg at 100 %" in text, text[-3000:]
        assert "not measured" not in text, text[-3000:]
    want = {i + 1: v / ramp_time for i, v in enumerate(kin.limits.velocity)}
    got = doc["controller"]["accelerations"]
    assert set(got) == {"joint_%s" % a for a in axes.split(",")}
    # the step's own figures in a failure's message (a fresh clone beside the computing tests read
    # 4.71 for 4.18 rad/s^2 once in about twenty runs; its ramps' figures were not kept)
    step = text[text.find("ramps: per-axis"):][:3000]
    for name, a in got.items():
        axis = int(name.split("_")[1])
        assert abs(a - want[axis]) <= 0.1 * want[axis], (name, a, want[axis], step)
    assert doc["controller"]["ramp_shape"] == shape
    assert doc["controller"]["ramp_time"] == pytest.approx(ramp_time, rel=0.1)


def test_per_axis_accelerations(tmp_path, kin):
    acc = (8.0, 12.0, 15.0, 20.0, 30.0, 45.0)
    doc, text, _ = run_commission(tmp_path, {"accelerations": acc},
                                  skip("loop", "lookahead", "configuration", "speed", "send_ahead")
                                  + ["--ramp-percent", "60", "--ramp-move", "30"])
    for i, a in enumerate(acc):
        got = doc["controller"]["accelerations"]["joint_%d" % (i + 1)]
        assert abs(got - a) <= 0.1 * a, (i + 1, got, a)
        assert limits_of(doc)["joint_%d" % (i + 1)]["max_acceleration"] == got


def test_loop_blocking_during_a_move(tmp_path):
    doc, text, _ = run_commission(tmp_path, {"loop_blocks_during_move": True}, skip("configuration", "ramps"))
    assert doc["controller"]["loop_blocks_during_move"] is True
    row = finding(doc, "program loop during a MOVE")
    assert row.get("ok") is False and "protocol v1" in row["consequence"]
    # what the blocking loop hides is not measured, never a value (a look-ahead of 0, a ring of 1)
    assert "interpreter_lookahead" not in doc["controller"] and "ring_size" not in doc["controller"]
    assert {"interpreter_lookahead", "ring_size"} <= set(doc["controller"]["not_measured"])
    assert "loop blocks during a MOVE" in doc["commissioning"]["not_measured"]["interpreter_lookahead"]
    assert doc["stream_smooth"] == 0
    if "speed_scale" in doc["controller"]:
        assert abs(doc["controller"]["speed_scale"] - 1.0) <= 0.05       # from the move times: the ramps cancel
    else:   # a bus cycle late at a move's start or end (beside the suite's real-time tests): said, no figure
        assert "came late" in doc["commissioning"]["not_measured"]["speed_scale"], text[-3000:]
    # the protocol that works with it; v3 with this G2 is refused at start, in words
    assert doc["protocol"] == "v1"
    with pytest.raises(ParamError) as err:
        DriverParams.from_dict(dict(doc, protocol="v3"))
    assert err.value.name == "controller/loop_blocks_during_move" and "use protocol v1" in str(err.value)


def test_a_jittery_loop_through_20_cycles_per_second(tmp_path):
    """The issue's G2: a 16 ms loop, +-4 ms (a true spread of 2.3 ms), the tool at 19.2 kbit/s and 20
    cycles/s -- a bus cycle three loops long. Before, it printed a spread of 0.02-0.07 ms and "steady";
    now "irregular" with the spread, or "not resolved" in words, never "steady" -- in 10 s at rest (a
    jittery loop shows sooner than a steady one is proven; the step watches longer where it must). (The
    pty carries the bytes without their wire time: test/driver/test_commission_stepped.py runs the
    paced line, five seeds each of more loops.)"""
    doc, text, _ = run_commission(tmp_path, {"baud": 19200, "loop_period": 0.016, "loop_jitter": 0.004,
                                             "loop_jitter_seed": 1},
                                  skip("check_word", "send_ahead", "unreachable", *MOTION) + ["--heartbeat-time", "10"],
                                  cycle_rate=20.0)
    row = finding(doc, "program loop at rest")
    assert "steady" not in row["measured"], row
    assert abs(doc["controller"]["loop_period"] - 0.016) < 0.001
    if "ok" in row:
        assert row["ok"] is False and "irregular: spread" in row["measured"]
        assert 0.0015 <= doc["controller"]["loop_period_spread"] <= 0.0037, doc["controller"]
    else:
        assert "spread not resolved" in row["measured"]
        assert "loop_period_spread" in doc["controller"]["not_measured"]


def test_byte_order_send_ahead_and_loop_period(tmp_path):
    doc, text, vc = run_commission(tmp_path, {"byte_order": "big", "send_ahead": "refused", "loop_period": 0.004},
                                   skip(*MOTION))
    assert doc["byte_order"] == "big"
    assert "trying big" in text
    assert finding(doc, "byte order")["ok"] is False
    assert doc["controller"]["check_word"] is True
    assert doc["controller"]["send_ahead"] == "refused"
    assert "controller/send_ahead: refused" in finding(doc, "a target sent ahead")["consequence"]
    # the driver told so sends one target per acknowledgement
    assert DriverParams.from_dict(dict(doc, port="/dev/null")).wire.send_ahead == 1
    assert abs(doc["controller"]["loop_period"] - 0.004) < 0.001
    assert doc["controller"]["loop_blocks_during_move"] is False


def test_configuration_current_joints_and_an_alarm(tmp_path):
    doc, text, _ = run_commission(tmp_path, {"configuration": "current_joints", "unreachable": "alarm_halt"},
                                  skip("loop", "speed", "lookahead", "ramps"))
    assert doc["controller"]["configuration"] == "current_joints"
    assert doc["controller"]["unreachable"] == "alarm_halt"
    assert "reset the alarm at the pendant" in text
