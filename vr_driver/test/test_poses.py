"""Pose conventions: controller (mm, deg, R = Rz Ry Rx) <-> matrix <-> ROS (m, quaternion) <-> KDL."""
from __future__ import annotations

import math
import random

import numpy as np
import pytest

from panasonic_vr006l_support.model import rpy_matrix
from vr_driver.errors import PoseError, VrDriverError
from vr_driver.poses import (HOME_POSE, ControllerPose, FrameConventions, Workspace, controller_to_matrix,
                             controller_to_ros, invert_transform, kdl_frame_to_matrix, matrix_to_controller,
                             matrix_to_kdl_frame, matrix_to_quaternion, matrix_to_rpy, quaternion_slerp,
                             quaternion_to_matrix, ros_to_controller, rpy_to_matrix, wrap_angle, wrap_degrees)


def _random_pose(rng: random.Random) -> ControllerPose:
    return ControllerPose(rng.uniform(-1500, 1500), rng.uniform(-1500, 1500), rng.uniform(-200, 1500),
                          rng.uniform(-180, 180), rng.uniform(-89.9, 89.9), rng.uniform(-180, 180))


def test_rpy_matches_the_urdf_convention_of_the_support_model():
    rng = random.Random(1)
    for _ in range(50):
        rpy = [rng.uniform(-math.pi, math.pi) for _ in range(3)]
        assert np.allclose(rpy_to_matrix(*rpy), rpy_matrix(rpy), atol=1e-15)


def test_rpy_is_fixed_axes_x_then_y_then_z():
    # Rx 90 then (fixed) Z 90: the local y axis first goes to +z, and stays there under Rz
    r = rpy_to_matrix(math.pi / 2, 0.0, math.pi / 2)
    assert np.allclose(r @ [0, 1, 0], [0, 0, 1], atol=1e-12)
    assert np.allclose(r @ [1, 0, 0], [0, 1, 0], atol=1e-12)


def test_home_pose_points_the_flange_45_degrees_down():
    t = HOME_POSE.to_matrix()
    assert np.allclose(t[:3, 3], [1.120, 0.0, 0.725])
    x_axis = t[:3, 0]
    assert np.allclose(x_axis, [math.sqrt(0.5), 0.0, -math.sqrt(0.5)], atol=1e-12)


def test_controller_tuple_to_quaternion_and_back_round_trips():
    rng = random.Random(2)
    for _ in range(300):
        pose = _random_pose(rng)
        position, quaternion = controller_to_ros(pose.as_tuple())
        assert abs(sum(c * c for c in quaternion) - 1.0) < 1e-12
        assert quaternion[3] >= 0.0
        back = ros_to_controller(position, quaternion)
        assert np.allclose(back.as_tuple(), pose.as_tuple(), atol=1e-9)


def test_controller_to_matrix_round_trip_and_quaternion_agree():
    rng = random.Random(3)
    for _ in range(200):
        pose = _random_pose(rng)
        t = controller_to_matrix(pose)
        assert np.allclose(matrix_to_controller(t).as_tuple(), pose.as_tuple(), atol=1e-9)
        assert np.allclose(quaternion_to_matrix(matrix_to_quaternion(t[:3, :3])), t[:3, :3], atol=1e-12)


def test_known_quaternion():
    # Ry = 45 deg: q = (0, sin 22.5, 0, cos 22.5)
    _, q = HOME_POSE.to_ros()
    assert np.allclose(q, [0.0, math.sin(math.pi / 8), 0.0, math.cos(math.pi / 8)], atol=1e-12)


@pytest.mark.parametrize("ry", [90.0, -90.0])
def test_euler_extraction_is_stable_at_the_gimbal_lock(ry):
    rng = random.Random(4)
    for _ in range(50):
        rx, rz = rng.uniform(-180, 180), rng.uniform(-180, 180)
        r = rpy_to_matrix(math.radians(rx), math.radians(ry), math.radians(rz))
        angles = matrix_to_rpy(r)
        assert angles[0] == 0.0
        assert math.isclose(angles[1], math.radians(ry), abs_tol=1e-12)
        rebuilt = rpy_to_matrix(*angles)
        assert np.allclose(rebuilt, r, atol=1e-12)
        assert np.allclose(matrix_to_rpy(rebuilt), angles, atol=1e-12)


def test_euler_extraction_near_gimbal_lock_reproduces_the_matrix():
    for ry in (89.99999, -89.99999, 89.9999999999):
        r = rpy_to_matrix(0.3, math.radians(ry), -1.2)
        assert np.allclose(rpy_to_matrix(*matrix_to_rpy(r)), r, atol=1e-9)


def test_wrap():
    assert wrap_angle(math.pi) == pytest.approx(math.pi)
    assert wrap_angle(-math.pi) == pytest.approx(math.pi)
    assert wrap_angle(3 * math.pi / 2) == pytest.approx(-math.pi / 2)
    assert wrap_degrees(190.0) == pytest.approx(-170.0)
    assert wrap_degrees(-180.0) == pytest.approx(180.0)
    assert wrap_degrees(720.0 + 10.0) == pytest.approx(10.0)
    assert ControllerPose(0, 0, 0, 350, -370, 180).wrapped().as_tuple() == pytest.approx((0, 0, 0, -10, -10, 180))


def test_kdl_frame_round_trip():
    t = ControllerPose(100, -200, 300, 10, 20, 30).to_matrix()
    f = matrix_to_kdl_frame(t)
    assert np.allclose(kdl_frame_to_matrix(f), t, atol=1e-15)
    assert np.allclose(f.M.GetRPY(), np.radians([10, 20, 30]), atol=1e-12)


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -float("inf"), "a", None, True])
def test_bad_values_raise_pose_error_naming_the_field(bad):
    with pytest.raises(PoseError, match=r"Ry \[deg\]"):
        ControllerPose(1, 2, 3, 4, bad, 6)


def test_wrong_length_raises_pose_error():
    with pytest.raises(PoseError, match=r"6 values \(X, Y, Z, Rx, Ry, Rz\), got 5"):
        ControllerPose.from_sequence([1, 2, 3, 4, 5])
    with pytest.raises(PoseError, match="4 values"):
        ros_to_controller((0, 0, 0), (0, 0, 1))
    with pytest.raises(PoseError, match="unit quaternion"):
        ros_to_controller((0, 0, 0), (0, 0, 2, 0))
    with pytest.raises(PoseError):
        ros_to_controller((0, float("nan"), 0), (0, 0, 0, 1))


def test_pose_error_is_in_the_tree_and_a_value_error():
    assert issubclass(PoseError, VrDriverError) and issubclass(PoseError, ValueError)


def test_workspace_check_names_the_field_and_range():
    ws = Workspace()
    assert ws.check(HOME_POSE) is HOME_POSE
    with pytest.raises(PoseError, match=r"X = 50 mm is outside the workspace \[100, 1400\] mm"):
        ws.check(ControllerPose(50, 0, 500, 0, 0, 0))
    with pytest.raises(PoseError, match=r"Y = -901 mm .*\[-900, 900\]"):
        ws.check(ControllerPose(500, -901, 500, 0, 0, 0))
    with pytest.raises(PoseError, match=r"Z = 1400.5 mm"):
        ws.check(ControllerPose(500, 0, 1400.5, 0, 0, 0))
    with pytest.raises(PoseError, match=r"Rz = 181 deg .*\[-180, 180\] deg"):
        ws.check(ControllerPose(500, 0, 500, 0, 0, 181))
    assert not ws.contains(ControllerPose(500, 0, -1, 0, 0, 0))
    custom = Workspace.from_dict({"z": [-100, 100]})
    assert custom.contains(ControllerPose(500, 0, -50, 0, 0, 0))
    with pytest.raises(PoseError, match="unknown keys"):
        Workspace.from_dict({"w": [0, 1]})
    with pytest.raises(PoseError, match="lower bound"):
        Workspace(x=(10.0, 0.0))


def test_slerp_endpoints_and_midpoint():
    q0 = ControllerPose(0, 0, 0, 0, 0, 0).to_ros()[1]
    q1 = ControllerPose(0, 0, 0, 0, 0, 90).to_ros()[1]
    assert np.allclose(quaternion_slerp(q0, q1, 0.0), q0)
    assert np.allclose(quaternion_slerp(q0, q1, 1.0), q1)
    mid = quaternion_to_matrix(quaternion_slerp(q0, q1, 0.5))
    assert np.allclose(mid, rpy_to_matrix(0, 0, math.radians(45)), atol=1e-12)


def test_frame_conventions_tcp_and_base_offsets():
    base_in_root = controller_to_matrix((0, 0, 100, 0, 0, 0))       # base 0.1 m above base_link
    flange_in_tip = invert_transform(controller_to_matrix((0, 0, 0, 180, -90, 0)))  # tool0 = flange rpy(pi,-pi/2,0)
    conv = FrameConventions(base_in_root, flange_in_tip)
    tip = conv.controller_to_tip(HOME_POSE)
    # tool0 z axis = flange x axis; the position is only shifted by the base offset
    assert np.allclose(tip[:3, 3], [1.120, 0.0, 0.825])
    assert np.allclose(tip[:3, 2], HOME_POSE.to_matrix()[:3, 0], atol=1e-12)
    assert np.allclose(conv.tip_to_controller(tip).as_tuple(), HOME_POSE.as_tuple(), atol=1e-9)
    # a 100 mm TCP along the flange x axis moves the TCP 100 mm along the flange's pointing direction
    tool = conv.with_tcp((100, 0, 0, 0, 0, 0))
    tip_same = conv.controller_to_tip(HOME_POSE)
    tcp_pose = tool.tip_to_controller(tip_same)
    d = math.sqrt(0.5) * 100
    assert np.allclose(tcp_pose.as_tuple(), (1120 + d, 0, 725 - d, 0, 45, 0), atol=1e-9)
    assert np.allclose(conv.root_to_base(conv.base_to_root(tip)), tip)
    with pytest.raises(PoseError, match="not a rotation"):
        FrameConventions(tcp_in_flange=np.diag([2.0, 1.0, 1.0, 1.0]))
