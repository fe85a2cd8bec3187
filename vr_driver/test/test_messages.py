"""The generated messages: RobotStatus, RobotMode and TriState must stay wire-identical to
industrial_msgs (same MD5 sums), so ROS-Industrial tools subscribe to our robot_status unchanged;
FollowJointTrajectory and JointTolerance to control_msgs of ROS Noetic, so MoveIt's controller manager
can use our joint_trajectory_action.

Needs the catkin devel space (run through `make run_tests` or `scripts/env`); under plain pytest
without a built workspace the module is skipped with that reason."""
import pytest

msg = pytest.importorskip("vr_driver.msg", reason="vr_driver messages not built (run scripts/test)")

# MD5 sums of industrial_msgs 0.7.x (ROS-Industrial industrial_core), the reference definitions.
INDUSTRIAL_MSGS_MD5 = {
    "TriState": "deb03829f3c2d0f1b647fa38d7087952",
    "RobotMode": "24ac279e988b6b3db836e437e6ed1ba0",
    "RobotStatus": "b733cb45a38101840b75c4c0d6093d19",
}


@pytest.mark.parametrize("name", sorted(INDUSTRIAL_MSGS_MD5))
def test_status_messages_have_the_industrial_msgs_md5(name):
    assert getattr(msg, name)._md5sum == INDUSTRIAL_MSGS_MD5[name]


def test_robot_status_field_names_and_types():
    assert msg.RobotStatus.__slots__ == ["header", "mode", "e_stopped", "drives_powered",
                                         "motion_possible", "in_motion", "in_error", "error_code"]
    assert msg.RobotStatus._slot_types[1:] == ["vr_driver/RobotMode"] + ["vr_driver/TriState"] * 5 + ["int32"]


def test_tristate_and_mode_constants():
    assert (msg.TriState.UNKNOWN, msg.TriState.TRUE, msg.TriState.FALSE) == (-1, 1, 0)
    assert (msg.TriState.ON, msg.TriState.ENABLED, msg.TriState.OFF, msg.TriState.DISABLED) == (1, 1, 0, 0)
    assert (msg.RobotMode.UNKNOWN, msg.RobotMode.MANUAL, msg.RobotMode.AUTO) == (-1, 1, 2)


def test_move_to_pose_action_round_trips():
    from io import BytesIO
    goal = msg.MoveToPoseGoal(target=msg.CartesianPose(1120, 0, 725, 0, 45, 0),
                              move_type=msg.MoveToPoseGoal.CIRC, has_via=True,
                              via=msg.CartesianPose(1000, 200, 700, 0, 45, 0), preview_only=True)
    buf = BytesIO()
    goal.serialize(buf)
    back = msg.MoveToPoseGoal()
    back.deserialize(buf.getvalue())
    assert (back.target.x, back.via.y, back.move_type, back.has_via, back.preview_only) == \
        (1120, 200, 3, True, True)
    assert msg.MoveToPoseFeedback.PHASE_MOVING == "moving"


# MD5 sums of control_msgs/FollowJointTrajectory and control_msgs/JointTolerance as ROS Noetic ships
# them (control_msgs 1.5.x; unchanged since Melodic, when FollowJointTrajectoryResult gained
# error_string). Source: the `getMD5()` strings that rosserial writes into its generated ros_lib
# headers `control_msgs/<Type>.h` (the Noetic-era generator, `virtual ... override` style), found
# identical in the generated ROS 1 bindings of other client libraries (C#, Elixir, JavaScript) that
# embed the same sums. genmsg's MD5 of a message covers its constants and field types/names, with a
# nested message replaced by that message's own MD5, never by its package name, so our
# vr_driver/... copies carry the same sums when (and only when) every field, type and constant agrees.
CONTROL_MSGS_MD5 = {
    "FollowJointTrajectoryAction": "bc4f9b743838566551c0390c65f1a248",
    "FollowJointTrajectoryGoal": "69636787b6ecbde4d61d711979bc7ecb",
    "FollowJointTrajectoryActionGoal": "cff5c1d533bf2f82dd0138d57f4304bb",
    "FollowJointTrajectoryResult": "493383b18409bfb604b4e26c676401d2",
    "FollowJointTrajectoryActionResult": "c4fb3b000dc9da4fd99699380efcc5d9",
    "FollowJointTrajectoryFeedback": "10817c60c2486ef6b33e97dcd87f4474",
    "FollowJointTrajectoryActionFeedback": "d8920dc4eae9fc107e00999cce4be641",
    "JointTolerance": "f544fe9c16cf04547e135dd6063ff5be",
}
# control_msgs before error_string (ROS Indigo); a server with this sum would not talk to Noetic MoveIt
OLD_RESULT_WITHOUT_ERROR_STRING_MD5 = "6243274b5d629dc838814109754410d5"


@pytest.mark.parametrize("name", sorted(CONTROL_MSGS_MD5))
def test_follow_joint_trajectory_types_have_the_control_msgs_noetic_md5(name):
    assert getattr(msg, name)._md5sum == CONTROL_MSGS_MD5[name]


def test_the_result_is_the_noetic_one_with_error_string():
    assert msg.FollowJointTrajectoryResult._md5sum != OLD_RESULT_WITHOUT_ERROR_STRING_MD5
    assert msg.FollowJointTrajectoryResult.__slots__ == ["error_code", "error_string"]


def test_follow_joint_trajectory_fields_in_control_msgs_order():
    assert msg.FollowJointTrajectoryGoal.__slots__ == ["trajectory", "path_tolerance", "goal_tolerance",
                                                       "goal_time_tolerance"]
    assert msg.FollowJointTrajectoryGoal._slot_types == [
        "trajectory_msgs/JointTrajectory", "vr_driver/JointTolerance[]", "vr_driver/JointTolerance[]", "duration"]
    assert msg.FollowJointTrajectoryResult._slot_types == ["int32", "string"]
    assert msg.FollowJointTrajectoryFeedback.__slots__ == ["header", "joint_names", "desired", "actual", "error"]
    assert msg.FollowJointTrajectoryFeedback._slot_types == [
        "std_msgs/Header", "string[]"] + ["trajectory_msgs/JointTrajectoryPoint"] * 3
    assert msg.JointTolerance.__slots__ == ["name", "position", "velocity", "acceleration"]
    assert msg.JointTolerance._slot_types == ["string", "float64", "float64", "float64"]


def test_follow_joint_trajectory_error_codes():
    r = msg.FollowJointTrajectoryResult
    assert (r.SUCCESSFUL, r.INVALID_GOAL, r.INVALID_JOINTS, r.OLD_HEADER_TIMESTAMP, r.PATH_TOLERANCE_VIOLATED,
            r.GOAL_TOLERANCE_VIOLATED) == (0, -1, -2, -3, -4, -5)


def test_the_md5_ignores_the_package_name_but_not_a_field():
    """What makes the mirror work, shown with genmsg itself: the same text under another package has
    the same MD5; one changed field name does not."""
    import genmsg
    import genmsg.gentools
    import genmsg.msg_loader

    text = "string name\nfloat64 position\nfloat64 velocity\nfloat64 acceleration\n"

    def md5(package, body):
        ctx = genmsg.msg_loader.MsgContext.create_default()
        spec = genmsg.msg_loader.load_msg_from_string(ctx, body, package + "/JointTolerance")
        return genmsg.gentools.compute_md5(ctx, spec)

    assert md5("control_msgs", text) == md5("vr_driver", text) == CONTROL_MSGS_MD5["JointTolerance"]
    assert md5("control_msgs", text.replace("velocity", "speed")) != CONTROL_MSGS_MD5["JointTolerance"]


def test_follow_joint_trajectory_goal_round_trips():
    from io import BytesIO

    import genpy
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
    goal = msg.FollowJointTrajectoryGoal(
        trajectory=JointTrajectory(joint_names=["joint_%d" % i for i in range(1, 7)],
                                   points=[JointTrajectoryPoint(positions=[0.1] * 6,
                                                                time_from_start=genpy.Duration(1.5))]),
        path_tolerance=[msg.JointTolerance("joint_1", 0.01, -1.0, 0.0)],
        goal_time_tolerance=genpy.Duration(0.5))
    buf = BytesIO()
    goal.serialize(buf)
    back = msg.FollowJointTrajectoryGoal()
    back.deserialize(buf.getvalue())
    assert back.trajectory.joint_names[5] == "joint_6"
    assert back.trajectory.points[0].time_from_start == genpy.Duration(1.5)
    assert (back.path_tolerance[0].name, back.path_tolerance[0].velocity) == ("joint_1", -1.0)
    assert back.goal_time_tolerance == genpy.Duration(0.5)


def test_io_messages_and_services_carry_what_the_io_line_shows():
    """issue 18: io_states (IOStates of IOState), set_io (SetIO) and get_io (GetIO) as documented in
    doc/ros_api.md: every field name and type, and a round trip of a state."""
    srv = pytest.importorskip("vr_driver.srv", reason="vr_driver services not built (run scripts/test)")
    from io import BytesIO
    assert msg.IOState.__slots__ == ["name", "station", "type", "direction", "value", "online"]
    assert msg.IOState._slot_types == ["string"] * 5 + ["bool"]
    assert msg.IOStates.__slots__ == ["header", "signals"]
    assert msg.IOStates._slot_types == ["std_msgs/Header", "vr_driver/IOState[]"]
    assert (srv.SetIORequest.__slots__, srv.SetIOResponse.__slots__) == (["signal", "value"], ["success", "message"])
    assert (srv.GetIORequest.__slots__, srv.GetIOResponse.__slots__) == (["signal"], ["value", "success", "message"])
    states = msg.IOStates(signals=[msg.IOState("gripper_closed", "io_island", "bit", "in", "1", True)])
    buf = BytesIO()
    states.serialize(buf)
    back = msg.IOStates()
    back.deserialize(buf.getvalue())
    assert (back.signals[0].name, back.signals[0].value, back.signals[0].online) == ("gripper_closed", "1", True)


# issue 26, the ROS-Industrial driver interface: industrial_msgs 0.7.x (ROS-Industrial industrial_core,
# the `industrial_msgs` package). Source: the `_md5sum` attributes of the genpy-generated Python of
# industrial_msgs (`industrial_msgs/msg/_ServiceReturnCode.py`, `_DeviceInfo.py`,
# `industrial_msgs/srv/_StopMotion.py`, `_StartMotion.py`, `_CmdJointTrajectory.py`,
# `_GetRobotInfo.py`: the service class's own `_md5sum` and its request / response classes'),
# the same sums as the `getMD5()` strings of rosserial's ros_lib headers `industrial_msgs/<Type>.h`
# and the `md5sum()` of gennodejs's industrial_msgs/msg/*.js. A service's MD5 covers its request
# and response text (nested types by their own MD5), so StopMotion and StartMotion (empty request,
# one ServiceReturnCode) share one sum.
INDUSTRIAL_MSGS_MSG_MD5 = {
    "ServiceReturnCode": "85a4e241266be66b1e1426b03083a412",
    "DeviceInfo": "373ed7fa0fac92d443be9cd5198e80f0",
}
INDUSTRIAL_MSGS_SRV_MD5 = {
    # service: (service, request, response)
    "StopMotion": ("50b1f38f75f5677e5692f3b3e7e1ea48", "d41d8cd98f00b204e9800998ecf8427e",
                   "50b1f38f75f5677e5692f3b3e7e1ea48"),
    "StartMotion": ("50b1f38f75f5677e5692f3b3e7e1ea48", "d41d8cd98f00b204e9800998ecf8427e",
                    "50b1f38f75f5677e5692f3b3e7e1ea48"),
    "CmdJointTrajectory": ("94fdf82abbbb1071bc31be1a2aea4fcd", "2a0eff76c870e8595636c2a562ca298e",
                           "50b1f38f75f5677e5692f3b3e7e1ea48"),
    "GetRobotInfo": ("5db3230b3e61c85a320b999ffd7f3b3f", "d41d8cd98f00b204e9800998ecf8427e",
                     "5db3230b3e61c85a320b999ffd7f3b3f"),
}


@pytest.mark.parametrize("name", sorted(INDUSTRIAL_MSGS_MSG_MD5))
def test_ros_industrial_messages_have_the_industrial_msgs_md5(name):
    assert getattr(msg, name)._md5sum == INDUSTRIAL_MSGS_MSG_MD5[name]


@pytest.mark.parametrize("name", sorted(INDUSTRIAL_MSGS_SRV_MD5))
def test_ros_industrial_services_have_the_industrial_msgs_md5(name):
    srv = pytest.importorskip("vr_driver.srv", reason="vr_driver services not built (run scripts/test)")
    service = getattr(srv, name)
    assert (service._md5sum, service._request_class._md5sum, service._response_class._md5sum) == \
        INDUSTRIAL_MSGS_SRV_MD5[name]


def test_feedback_states_uses_the_control_msgs_feedback_type():
    """feedback_states publishes the action's own feedback message: its MD5 is
    control_msgs/FollowJointTrajectoryFeedback's (pinned above with the action), which is what
    ROS-Industrial's industrial_robot_client subscribes to."""
    from vr_driver.ros.industrial import FEEDBACK_STATES_TYPE
    assert FEEDBACK_STATES_TYPE._md5sum == CONTROL_MSGS_MD5["FollowJointTrajectoryFeedback"]
    assert FEEDBACK_STATES_TYPE._type == "vr_driver/FollowJointTrajectoryFeedback"


def test_service_return_code_and_robot_info_fields():
    srv = pytest.importorskip("vr_driver.srv", reason="vr_driver services not built (run scripts/test)")
    assert (msg.ServiceReturnCode.SUCCESS, msg.ServiceReturnCode.FAILURE) == (1, -1)
    assert msg.ServiceReturnCode._slot_types == ["int8"]
    assert msg.DeviceInfo.__slots__ == ["model", "serial_number", "hw_version", "sw_version", "address"]
    assert srv.GetRobotInfoResponse.__slots__ == ["controller", "robots", "code"]
    assert srv.CmdJointTrajectoryRequest._slot_types == ["trajectory_msgs/JointTrajectory"]
    assert srv.StopMotionRequest.__slots__ == [] and srv.StopMotionResponse.__slots__ == ["code"]
