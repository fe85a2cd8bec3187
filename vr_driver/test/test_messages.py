"""The generated messages: RobotStatus, RobotMode and TriState must stay wire-identical to
industrial_msgs (same MD5 sums), so ROS-Industrial tools subscribe to our robot_status unchanged.

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
