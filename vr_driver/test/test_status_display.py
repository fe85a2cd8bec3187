"""status_display: robot_status in words and colour for the RViz text marker."""
from vr_driver.msg import RobotMode, RobotStatus, TriState
from vr_driver.ros.status_display import GREEN, GREY, RED, YELLOW, status_text


def status(mode=2, e_stopped=0, drives=1, possible=1, moving=0, error=0, code=0):
    return RobotStatus(mode=RobotMode(mode), e_stopped=TriState(e_stopped), drives_powered=TriState(drives),
                       motion_possible=TriState(possible), in_motion=TriState(moving), in_error=TriState(error),
                       error_code=code)


def test_ready_is_green_and_says_so():
    text, color = status_text(status())
    assert text == "robot_status: AUTO, motion possible\ndrives on, e-stop released, standing"
    assert color == GREEN


def test_e_stop_and_error_are_red_and_named():
    text, color = status_text(status(e_stopped=1, possible=0))
    assert "E-STOP PRESSED" in text and "motion NOT possible" in text and color == RED
    text, color = status_text(status(error=1, possible=0, code=2))
    assert "ERROR (code 2)" in text and color == RED


def test_link_down_unknowns_and_no_status():
    text, color = status_text(status(mode=-1, e_stopped=-1, drives=-1, possible=0, moving=-1, error=1, code=1))
    assert text.startswith("robot_status: mode ?, motion NOT possible") and "ERROR (code 1)" in text
    assert color == RED
    text, color = status_text(status(mode=1, possible=0, drives=0))
    assert "MANUAL" in text and "drives off" in text and color == YELLOW
    assert status_text(None) == ("robot_status: none (driver not running?)", GREY)
