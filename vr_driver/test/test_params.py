"""DriverParams: the documented config file is valid, defaults equal it, every bad value is
refused with a message naming the parameter."""
import math
import os
import pickle

import pytest
import yaml

from vr_driver.params import DriverParams, ParamError

CONFIG = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "config",
                      "vr_driver.yaml")


def load():
    with open(CONFIG) as f:
        return yaml.safe_load(f)


def test_config_file_is_valid_and_equals_the_built_in_defaults():
    data = load()
    assert DriverParams.from_dict(data) == DriverParams.from_dict({"port": "/dev/ttyUSB0",
                                                                   "baud": 19200,
                                                                   "master_address": 2,
                                                                   "watchdog_ms": 300})


def test_port_auto_is_the_virtual_controllers_link_of_this_launch(monkeypatch):
    """driver.launch passes sim_port (default auto) as both the controller's pty_link and the driver's
    port: both resolve it to <ROS log dir>/vr006l_virtual_g2_<master port>."""
    from vr_driver.controller.pty_link import auto_pty_link
    monkeypatch.setenv("ROS_MASTER_URI", "http://localhost:11517/")
    monkeypatch.setenv("ROS_LOG_DIR", "/var/tmp/roslogs")
    params = DriverParams.from_dict({"port": "auto"})
    assert params.port == "/var/tmp/roslogs/vr006l_virtual_g2_11517" == auto_pty_link()
    assert params.bus().phy.device == params.port
    monkeypatch.setenv("ROS_MASTER_URI", "http://localhost/")
    with pytest.raises(ParamError) as err:
        DriverParams.from_dict({"port": "auto"})
    assert "ROS_MASTER_URI" in str(err.value)


def test_config_file_documents_every_parameter():
    assert set(load()) == set(DriverParams.keys())
    with open(CONFIG) as f:
        for line in f:
            if line[:1].isalpha():       # a top-level key line carries its own comment
                assert "#" in line or line.rstrip().endswith(":"), line


def test_the_sections_hold_every_flat_key_once_and_read_flat():
    """DriverParams is made of sections (link, motion, checks, publishing), each with its own parser;
    the files stay flat: every section field is one flat key and a read-only flat attribute."""
    from dataclasses import FrozenInstanceError, fields

    from vr_driver.params import SECTIONS
    flat = [f.name for kind in SECTIONS.values() for f in fields(kind)]
    assert len(flat) == len(set(flat))                     # one section per key
    assert sorted(flat + ["commissioning", "controller"]) == list(DriverParams.keys())
    p = DriverParams.from_dict({"port": "/dev/x", "stop_timeout": 7.0, "scene": "", "status_rate": 5.0})
    assert (p.port, p.stop_timeout, p.status_rate) == (p.link.port, p.motion.stop_timeout, p.publishing.status_rate)
    assert (p.port, p.stop_timeout, p.status_rate) == ("/dev/x", 7.0, 5.0)
    assert p.base_frame == p.checks.base_frame == "base"
    with pytest.raises(FrozenInstanceError):
        p.port = "/dev/y"
    with pytest.raises(FrozenInstanceError):
        p.link = None


def test_flat_keywords_build_and_replace_into_their_sections():
    """``DriverParams(stop_timeout=...)`` and ``dataclasses.replace(params, scene="")`` (as plan_process
    does) put each keyword into its section and keep the others; an unknown keyword is a TypeError."""
    from dataclasses import replace
    p = DriverParams(stop_settle_time=0.5, stop_timeout=4.0, collision_check=False)
    assert (p.motion.stop_settle_time, p.motion.stop_timeout, p.checks.collision_check) == (0.5, 4.0, False)
    assert p.link == DriverParams().link
    q = replace(DriverParams.from_dict({"port": "/dev/x", "stop_timeout": 7.0}), io_signals="", port="/dev/z")
    assert (q.port, q.io_signals, q.stop_timeout) == ("/dev/z", "", 7.0)
    with pytest.raises(TypeError, match="no_such_key"):
        DriverParams(no_such_key=1)
    r = pickle.loads(pickle.dumps(q))                     # as a worker process gets it
    assert r == q and r.port == "/dev/z" and hash(r) == hash(q)


def test_each_section_parses_alone():
    """A section's parser checks its own values (and what it is given of the others: the bus's
    cycle rate, the plain joint names) with the same errors DriverParams.from_dict gives."""
    from vr_driver.params import CheckParams, LinkParams, MotionParams, PublishParams
    names = tuple("joint_%d" % i for i in range(1, 7))
    assert MotionParams.from_dict({}, 15.0, names) == MotionParams()
    with pytest.raises(ParamError, match="stop_settle_time.*two bus cycles .>= 0.2 s at cycle_rate 10 Hz"):
        MotionParams.from_dict({"stop_settle_time": 0.15}, 10.0, names)
    with pytest.raises(ParamError, match="link_timeout"):
        LinkParams.from_dict({"cycle_rate": 100.0, "link_timeout": 0.01})
    assert CheckParams.from_dict({"prefix": "left_"}).controller_joint_names[0] == "left_joint_1"
    with pytest.raises(ParamError, match="publish_markers"):
        PublishParams.from_dict({"publish_markers": 1})


def test_bus_overrides_reach_the_profibus_config():
    bus = DriverParams.from_dict({"port": "/tmp/vr_pty", "baud": 187500, "cycle_rate": 50.0,
                                  "watchdog_ms": 0, "allow_no_watchdog": True}).bus()
    assert bus.phy.device == "/tmp/vr_pty"
    assert bus.baud == 187500
    assert bus.cycle_rate_hz == 50.0
    (slave,) = bus.slaves
    assert (slave.address, slave.ident, slave.cfg.hex(" ")) == (4, 0x06C6, "13 13 13 11 23 23 23 21")
    assert slave.watchdog_ms is None


@pytest.mark.parametrize("name, value, words", [
    ("baud", 12345, "not a PROFIBUS-DP bit rate"),
    ("baud", "fast", "integer"),
    ("master_address", 4, "also the address"),
    ("master_address", 126, "[0, 125]"),
    ("cycle_rate", math.nan, "finite"),
    ("cycle_rate", 0, "(0, 1000]"),
    ("byte_order", "middle", "little, big"),
    ("link_timeout", 0.01, "two bus cycles"),
    ("reconnect_period", 2.0, "[0.05, 1]"),
    ("workspace", {"x": [1400, 100]}, "lower bound"),
    ("workspace", {"q": [0, 1]}, "unknown keys"),
    ("workspace", [1, 2], "mapping"),
    ("controller_joint_names", ["j1", "j2"], "6 distinct"),
    ("controller_joint_names", ["j"] * 6, "6 distinct"),
    ("tcp_offset", [0, 0, 0, 0, 0], "6 numbers"),
    ("tcp_offset", [0, 0, math.inf, 0, 0, 0], "finite"),
    ("publish_markers", "yes", "true or false"),
    ("bus_config", "/nonexistent/bus.yaml", "no such file"),
    ("status_rate", -1, "(0, 1000]"),
    ("base_frame", "", "empty"),
    ("speed", 1, "unknown parameter"),
])
def test_bad_values_name_the_parameter(name, value, words):
    with pytest.raises(ParamError) as err:
        DriverParams.from_dict({name: value}).bus()
    assert err.value.name == name
    assert ("~%s" % name) in str(err.value)
    assert words in str(err.value)


def test_bus_config_file_errors_are_reported_with_the_parameter(tmp_path):
    bad = tmp_path / "bus.yaml"
    bad.write_text("master_address: 2\nbaud: 19200\nphy: {type: serial, device: /dev/x}\nslaves: []\n")
    with pytest.raises(ParamError) as err:
        DriverParams.from_dict({"bus_config": str(bad)}).bus()
    assert err.value.name == "bus_config" and "at least one slave" in str(err.value)


def test_the_built_in_bus_puts_the_g2_at_slave_address_a_bus_config_must_have_it(tmp_path):
    # a card at another address than 4 (what rosrun vr_driver scan finds) needs no bus config of its own
    (slave,) = DriverParams.from_dict({"slave_address": 6, "protocol": "v3"}).bus().slaves
    assert (slave.address, slave.cfg.hex(" ")) == (6, "17 17 17 13 27 27 27")
    bus = tmp_path / "bus.yaml"
    bus.write_text("master_address: 2\nbaud: 19200\nphy: {type: serial, device: /dev/x}\n"
                   "slaves:\n  - {name: r, address: 4, gsd: PAN06C6.gsd, cfg: '13 13 13 11 23 23 23 21'}\n")
    with pytest.raises(ParamError) as err:
        DriverParams.from_dict({"bus_config": str(bus), "slave_address": 5}).bus()
    assert err.value.name == "slave_address" and "no such slave in the bus config (have 4)" in str(err.value)


def test_wrong_io_length_is_refused(tmp_path):
    bus = tmp_path / "bus.yaml"
    bus.write_text("master_address: 2\nbaud: 19200\nphy: {type: serial, device: /dev/x}\n"
                   "slaves:\n  - {name: r, address: 4, gsd: PAN06C6.gsd, cfg: '13 23'}\n")
    with pytest.raises(ParamError) as err:
        DriverParams.from_dict({"bus_config": str(bus)}).bus()
    assert "protocol v1 needs 14 bytes in / 14 out" in str(err.value)


@pytest.mark.parametrize("values, words", [
    ({"watchdog_ms": 10}, "at least two bus cycles (>= 134 ms at cycle_rate 15 Hz)"),
    ({"watchdog_ms": 30, "cycle_rate": 50.0, "link_timeout": 0.3}, ">= 40 ms"),
    ({"watchdog_ms": 650000}, "must not exceed link_timeout (500 ms)"),
    ({"watchdog_ms": 600, "link_timeout": 0.5}, "must not exceed link_timeout"),
    ({"watchdog_ms": 0}, "allow_no_watchdog: true"),
])
def test_watchdog_is_checked_against_the_bus_cycle_and_link_timeout(values, words):
    with pytest.raises(ParamError) as err:
        DriverParams.from_dict(values)
    assert err.value.name == "watchdog_ms" and words in str(err.value), str(err.value)


def test_watchdog_from_the_bus_config_is_checked_too(tmp_path):
    """A bus config with a watchdog the cycle cannot keep: refused, naming where it came from."""
    from pyprofibus_vendor.config import default_robot_config
    data = default_robot_config("/dev/ttyUSB0").to_dict()
    data["slaves"][0]["watchdog_ms"] = 20
    import yaml
    path = tmp_path / "bus.yaml"
    path.write_text(yaml.safe_dump(data))
    params = DriverParams.from_dict({"bus_config": str(path)})
    with pytest.raises(ParamError) as err:
        params.bus()
    assert err.value.name == "watchdog_ms" and "bus config" in str(err.value)


def test_no_watchdog_only_when_allowed():
    params = DriverParams.from_dict({"watchdog_ms": 0, "allow_no_watchdog": True})
    assert params.bus().slaves[0].watchdog_ms is None
    assert DriverParams.from_dict({"watchdog_ms": 100, "cycle_rate": 20.0}).watchdog_ms == 100


@pytest.mark.parametrize("values, name", [
    ({"stop_settle_time": 0.05}, "stop_settle_time"),          # less than two 15 Hz cycles
    ({"stop_settle_time": 0.0}, "stop_settle_time"),
    ({"stop_timeout": 0.2}, "stop_timeout"),                   # not longer than the settle time
    ({"stop_timeout": float("nan")}, "stop_timeout"),
])
def test_stop_settings_are_checked(values, name):
    with pytest.raises(ParamError) as err:
        DriverParams.from_dict(values)
    assert err.value.name == name


def test_protocol_v2_uses_the_v2_modules_of_the_built_in_bus():
    bus = DriverParams.from_dict({"protocol": "v2", "port": "/dev/x"}).bus()
    slave = bus.slaves[0]
    assert (slave.input_len, slave.output_len) == (72, 72)
    assert slave.cfg == bytes([0x5F, 0x5F, 0x17, 0x6F, 0x6F, 0x27])
    v1 = DriverParams.from_dict({"port": "/dev/x"}).bus().slaves[0]
    assert (v1.input_len, v1.output_len) == (14, 14)


def test_protocol_v2_refuses_a_14_byte_bus_config(tmp_path):
    bus = tmp_path / "bus.yaml"
    bus.write_text("master_address: 2\nbaud: 19200\nphy: {type: serial, device: /dev/x}\n"
                   "slaves:\n  - {name: r, address: 4, gsd: PAN06C6.gsd, "
                   "cfg: '13 13 13 11 23 23 23 21'}\n")
    with pytest.raises(ParamError) as err:
        DriverParams.from_dict({"bus_config": str(bus), "protocol": "v2"}).bus()
    assert err.value.name == "bus_config"
    assert "protocol v2 needs 72 bytes in / 72 out; the configured modules give 14 in / 14 out" in str(err.value)


@pytest.mark.parametrize("values, name", [
    ({"protocol": "v9"}, "protocol"), ({"stream_smooth": 11}, "stream_smooth"),
    ({"stream_smooth": 1.5}, "stream_smooth"), ({"stream_path_tolerance": -0.1}, "stream_path_tolerance"),
])
def test_stream_params_checked(values, name):
    with pytest.raises(ParamError) as err:
        DriverParams.from_dict(values)
    assert err.value.name == name


TRUE_MODEL = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "true_model_example.yaml")


def test_model_file_is_checked_at_start_naming_the_parameter(tmp_path):
    """``model``: a kinematics YAML (e.g. calibrate fit --write's); a missing or bad file is refused
    naming ``model`` (and the file's key); a good one is accepted and becomes the driver's model."""
    assert DriverParams.from_dict({}).model == ""
    with pytest.raises(ParamError) as err:
        DriverParams.from_dict({"model": str(tmp_path / "none.yaml")})
    assert err.value.name == "model" and "no such file" in str(err.value)
    bad = tmp_path / "bad.yaml"
    with open(TRUE_MODEL) as f:
        data = yaml.safe_load(f)
    del data["geometry"]["upper_arm"]
    bad.write_text(yaml.safe_dump(data))
    with pytest.raises(ParamError) as err:
        DriverParams.from_dict({"model": str(bad)})
    assert err.value.name == "model" and "~model" in str(err.value) and "upper_arm" in str(err.value)
    with pytest.raises(ParamError) as err:
        DriverParams.from_dict({"model": 3})
    assert err.value.name == "model"
    params = DriverParams.from_dict({"model": TRUE_MODEL})
    assert params.model == TRUE_MODEL


@pytest.mark.parametrize("name, value, words", [
    ("planner_id", "Dijkstra", "must be one of RRTConnect"),
    ("planner_id", 3, "expected a string"),
    ("planning_time", 0, "(0, 60]"),
    ("planning_time", math.nan, "finite"),
    ("planning_time", 61, "(0, 60]"),
    ("velocity_scaling", 0.0, "(0, 1]"),
    ("velocity_scaling", 1.5, "(0, 1]"),
    ("velocity_scaling", "fast", "finite"),
])
def test_plan_action_defaults_are_checked(name, value, words):
    """The plan action's defaults (planner_id, planning_time, velocity_scaling): a bad one stops the
    node naming it; good ones are kept."""
    with pytest.raises(ParamError) as err:
        DriverParams.from_dict({name: value})
    assert err.value.name == name
    assert words in str(err.value)
    p = DriverParams.from_dict({"planner_id": "PRM", "planning_time": 2.5, "velocity_scaling": 0.5})
    assert (p.planner_id, p.planning_time, p.velocity_scaling) == ("PRM", 2.5, 0.5)
    d = DriverParams()
    assert (d.planner_id, d.planning_time, d.velocity_scaling) == ("RRTConnect", 1.0, 0.1)
