"""issue 19: the name prefix (several robots in one ROS graph) reaches every name the driver
produces or checks -- joint_states names, the tool_pose / marker frame, the kinematic chain and its
joint limits, FollowJointTrajectory and joint_path_command checks, the .csr exporter's joint order,
the virtual controller's pty link per namespace, the pose terminal's --ns -- and the empty prefix
gives exactly today's names."""
from __future__ import annotations

import contextlib
import io
import os
import socket
import tempfile
import threading

import numpy
import pytest
import yaml

from vr_driver import csr
from vr_driver.controller.pty_link import auto_pty_link
from vr_driver.driver import DriverCore, DriverError
from vr_driver.driver.motion.trajectories import INVALID_JOINTS, TrajectoryError, TrajectoryGoal, validate
from vr_driver.kinematics.solver import Kinematics
from vr_driver.params import DriverParams, ParamError
from vr_driver.terminal.pose_input import build_arg_parser, in_namespace

TODAY_JOINTS = ("joint_1", "joint_2", "joint_3", "joint_4", "joint_5", "joint_6")
LEFT_JOINTS = tuple("left_" + n for n in TODAY_JOINTS)


@pytest.fixture(scope="module")
def kin_plain():
    return Kinematics.default()


@pytest.fixture(scope="module")
def kin_left():
    return Kinematics.default(prefix="left_")


# ------------------------------------------------------------------------------------ parameters
def test_the_empty_prefix_gives_exactly_todays_names():
    for params in (DriverParams(), DriverParams.from_dict({}), DriverParams.from_dict({"prefix": ""})):
        assert params.prefix == ""
        assert params.controller_joint_names == TODAY_JOINTS
        assert params.base_frame == "base"


def test_a_prefix_goes_in_front_of_the_joint_names_and_the_base_frame():
    params = DriverParams.from_dict({"prefix": "left_"})
    assert params.controller_joint_names == LEFT_JOINTS
    assert params.base_frame == "left_base"
    custom = DriverParams.from_dict({"prefix": "arm2_", "base_frame": "g2",
                                     "controller_joint_names": ["a", "b", "c", "d", "e", "f"]})
    assert custom.controller_joint_names == ("arm2_a", "arm2_b", "arm2_c", "arm2_d", "arm2_e", "arm2_f")
    assert custom.base_frame == "arm2_g2"


@pytest.mark.parametrize("bad", ["1left_", "left/", "/left_", "le ft", "left-", "ä_", 5, None, ["a_"]])
def test_a_bad_prefix_is_refused_naming_the_parameter(bad):
    with pytest.raises(ParamError) as err:
        DriverParams.from_dict({"prefix": bad})
    assert err.value.name == "prefix"
    assert "prefix" in str(err.value)


# ------------------------------------------------------------------------------------ kinematics
def test_the_prefixed_chain_and_limits_are_read_from_the_prefixed_urdf(kin_plain, kin_left):
    assert (kin_plain.base, kin_plain.tip, kin_plain.joint_names) == ("base_link", "tool0", TODAY_JOINTS)
    assert (kin_left.base, kin_left.tip) == ("left_base_link", "left_tool0")
    assert kin_left.joint_names == LEFT_JOINTS
    assert [j.name for j in kin_left.chain_joints][:6] == list(LEFT_JOINTS)
    assert kin_left.limits.lower == kin_plain.limits.lower
    assert kin_left.limits.upper == kin_plain.limits.upper
    assert kin_left.limits.velocity == kin_plain.limits.velocity
    # the frames `left_base` and `left_flange` were found (`flange` is turned against tool0: not
    # the identity a missing frame falls back to)
    assert (kin_left.conventions.base_in_root == kin_plain.conventions.base_in_root).all()
    assert (kin_left.conventions.flange_in_tip == kin_plain.conventions.flange_in_tip).all()
    assert not numpy.allclose(kin_left.conventions.flange_in_tip, numpy.eye(4))
    q = (0.1, 0.5, -0.3, 0.2, 0.4, -0.1)
    assert kin_left.fk_pose(q) == kin_plain.fk_pose(q)
    # the SRDF's named states (plain joint names) are keyed by the prefixed joints
    assert kin_left.named_states == kin_plain.named_states and kin_left.named_states
    assert kin_left.joint_vector(dict(zip(LEFT_JOINTS, q))) == q
    with pytest.raises(Exception) as err:
        kin_left.joint_vector(dict(zip(TODAY_JOINTS, q)))
    assert "left_joint_1" in str(err.value)


# ------------------------------------------------------------------------------------ the core
def test_the_core_checks_joint_paths_and_trajectories_against_the_prefixed_names():
    params = DriverParams.from_dict({"prefix": "arm1_", "port": "/nonexistent/vr_pty"})
    core = DriverCore(params)                     # never started: nothing opens the port
    assert core.joint_names == ("arm1_joint_1", "arm1_joint_2", "arm1_joint_3", "arm1_joint_4",
                                "arm1_joint_5", "arm1_joint_6")
    assert core.kin.joint_names == core.joint_names
    arm2 = ["arm2_joint_%d" % i for i in range(1, 7)]
    with pytest.raises(DriverError) as err:
        core.submit_joint_path(arm2, [[0.0] * 6])
    assert "arm2_joint_1" in str(err.value) and "arm1_joint_1" in str(err.value)
    assert core.sequencer.view.tail_joints is None          # nothing queued
    with pytest.raises(TrajectoryError) as err:
        validate(TrajectoryGoal(joint_names=tuple(arm2), positions=((0.0,) * 6,), times=(1.0,)),
                 core.joint_names, (0.0,) * 6, core.kin.limits.lower, core.kin.limits.upper, 0.0)
    assert err.value.code == INVALID_JOINTS
    assert "unknown arm2_joint_1" in str(err.value) and "missing arm1_joint_1" in str(err.value)


# ------------------------------------------------------------------------------------ the pty link
def test_the_virtual_controller_link_is_one_per_namespace():
    env = {"ROS_MASTER_URI": "http://localhost:11517", "ROS_LOG_DIR": "/var/tmp/l"}
    assert auto_pty_link(env) == "/var/tmp/l/vr006l_virtual_g2_11517"                 # as today
    assert auto_pty_link(dict(env, ROS_NAMESPACE="")) == "/var/tmp/l/vr006l_virtual_g2_11517"
    assert auto_pty_link(dict(env, ROS_NAMESPACE="/arm1")) == "/var/tmp/l/vr006l_virtual_g2_11517_arm1"
    assert auto_pty_link(dict(env, ROS_NAMESPACE="/arm2")) == "/var/tmp/l/vr006l_virtual_g2_11517_arm2"
    assert auto_pty_link(dict(env, ROS_NAMESPACE="/cell/arm1/")) == "/var/tmp/l/vr006l_virtual_g2_11517_cell_arm1"


def test_a_socket_url_is_a_port_the_driver_opens(monkeypatch):
    """doc/multi_robot.md: a serial line reached over the network (an RS-485 / TCP converter, or ser2net):
    the port is pyserial's socket:// URL; the driver's link opens it (a real TCP connection)."""
    from vr_driver.driver.link.link import open_serial_link
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    accepted = []
    thread = threading.Thread(target=lambda: accepted.append(server.accept()[0]), daemon=True)
    thread.start()
    url = "socket://127.0.0.1:%d" % server.getsockname()[1]
    params = DriverParams.from_dict({"port": url, "prefix": "arm2_"})
    assert params.bus().phy.device == url
    link = open_serial_link(params.bus().phy.device, params.bus().baud)
    try:
        thread.join(5.0)
        assert accepted, "the driver's link did not connect to %s" % url
    finally:
        link.close()
        for conn in accepted:
            conn.close()
        server.close()


# ------------------------------------------------------------------------------------ .csr exporter
def _export(folder, trajectory, config=None):
    wp = os.path.join(folder, "traj.yaml")
    with open(wp, "w") as f:
        yaml.safe_dump(trajectory, f)
    # a fixed create / update time: two exports a second apart must not differ in it (a trajectory
    # dump has no program block, so only --date sets it)
    argv = [wp, "-o", "-", "--date", "2024-01-01T12:00:00"]
    if config is not None:
        path = os.path.join(folder, "driver.yaml")
        with open(path, "w") as f:
            yaml.safe_dump(config, f)
        argv += ["--driver-config", path]
    out, err = io.BytesIO(), io.StringIO()

    class Out:
        buffer = out

        @staticmethod
        def write(text):
            out.write(text.encode())

        @staticmethod
        def flush():
            pass
    with contextlib.redirect_stdout(Out), contextlib.redirect_stderr(err):
        code = csr.main(argv)
    return code, out.getvalue(), err.getvalue()


def test_the_csr_exporter_orders_the_prefixed_joints_of_the_driver_config():
    q = [[0.0, 0.6, -0.3, 0.0, 0.4, 0.0], [0.2, 0.5, -0.2, 0.1, 0.5, -0.1]]
    order = [2, 0, 5, 1, 4, 3]                                   # shuffled, as a JointTrajectory may be

    def traj(prefix):
        return {"joint_names": ["%sjoint_%d" % (prefix, i + 1) for i in order],
                "points": [{"positions": [p[i] for i in order]} for p in q]}
    with tempfile.TemporaryDirectory() as tmp:
        code, plain, err = _export(tmp, traj(""))
        assert code == 0, err
        code, left, err = _export(tmp, traj("left_"), {"prefix": "left_"})
        assert code == 0, err
        assert left == plain and b"MOVEP" in plain
        code, _, err = _export(tmp, traj(""), {"prefix": "left_"})
        assert code == 2 and "misses left_joint_1" in err, err
        code, _, err = _export(tmp, traj("left_"))
        assert code == 2 and "misses joint_1" in err, err


# ------------------------------------------------------------------------------------ pose terminal
def test_the_pose_terminal_ns_puts_the_drivers_names_in_that_namespace():
    parser = build_arg_parser()
    assert parser.parse_args([]).ns == ""
    assert parser.parse_args(["--ns", "arm1"]).ns == "arm1"
    for name in ("move_to_pose", "stop_motion", "robot_status", "tool_pose", "joint_states", "interface"):
        assert in_namespace("", name) == name                       # as today
        assert in_namespace("arm1", name) == "arm1/" + name
        assert in_namespace("/cell/arm2/", name) == "/cell/arm2/" + name
    assert in_namespace("arm1", "/diagnostics") == "/diagnostics"


@pytest.mark.parametrize("bad", ["arm 1", "1arm", "arm1//x", "arm-1", "a/../b"])
def test_the_pose_terminal_refuses_a_bad_namespace(bad, capsys):
    with pytest.raises(SystemExit) as exc:
        build_arg_parser().parse_args(["--ns", bad])
    assert exc.value.code == 2
    assert "not a ROS namespace" in capsys.readouterr().err
