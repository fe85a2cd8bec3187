"""ROS node ``status_display``: shows ``robot_status`` in RViz as a text marker over the robot.

The driver publishes ``robot_status`` (vr_driver/RobotStatus) but RViz has no display for it; this
node turns each change into one ``visualization_msgs/Marker`` (TEXT_VIEW_FACING, latched) on
``~marker`` (``/status_display/marker``), in ``~frame`` [``base``] at ``~height`` [1.65] m above the
frame's origin. Green: motion possible; red: in error or e-stopped; yellow: anything else; grey: no
robot_status for ``~stale_after`` [2.0] s. It needs nothing from the driver but its topic.
"""
from __future__ import annotations

import threading
from typing import Any, Optional, Tuple

_TRI = {1: True, 0: False}
_MODES = {1: "MANUAL", 2: "AUTO"}

GREEN = (0.2, 0.9, 0.3, 1.0)
RED = (1.0, 0.25, 0.2, 1.0)
YELLOW = (1.0, 0.85, 0.2, 1.0)
GREY = (0.6, 0.6, 0.6, 1.0)


def _tri(value: int, yes: str, no: str) -> str:
    state = _TRI.get(value)
    return "%s ?" % yes.split()[0] if state is None else (yes if state else no)


def status_text(status: Optional[Any]) -> Tuple[str, Tuple[float, float, float, float]]:
    """(text, rgba) for a RobotStatus message (None: nothing heard from the driver)."""
    if status is None:
        return "robot_status: none (driver not running?)", GREY
    lines = [
        "robot_status: %s, %s" % (_MODES.get(status.mode.val, "mode ?"),
                                  _tri(status.motion_possible.val, "motion possible", "motion NOT possible")),
        "drives %s, %s, %s" % (_tri(status.drives_powered.val, "on", "off"),
                               _tri(status.e_stopped.val, "E-STOP PRESSED", "e-stop released"),
                               _tri(status.in_motion.val, "moving", "standing")),
    ]
    if _TRI.get(status.in_error.val):
        lines.append("ERROR (code %d)" % status.error_code)
    elif status.in_error.val not in _TRI:
        lines.append("error state unknown")
    if _TRI.get(status.in_error.val) or _TRI.get(status.e_stopped.val):
        color = RED
    elif _TRI.get(status.motion_possible.val):
        color = GREEN
    else:
        color = YELLOW
    return "\n".join(lines), color


def main() -> int:
    import rospy
    from visualization_msgs.msg import Marker

    from vr_driver.msg import RobotStatus

    from .support import init_node
    init_node("status_display")
    frame = rospy.get_param("~frame", "base")
    height = float(rospy.get_param("~height", 1.65))
    stale_after = float(rospy.get_param("~stale_after", 2.0))
    pub = rospy.Publisher("~marker", Marker, queue_size=1, latch=True)
    lock = threading.Lock()
    state = {"last": None, "shown": None, "heard": None}

    def show(status: Optional[Any]) -> None:
        text, rgba = status_text(status)
        with lock:
            if (text, rgba) == state["shown"]:
                return
            state["shown"] = (text, rgba)
        m = Marker()
        m.header.frame_id = frame
        m.header.stamp = rospy.Time(0)
        m.ns, m.id, m.type, m.action = "robot_status", 0, Marker.TEXT_VIEW_FACING, Marker.ADD
        m.pose.position.z = height
        m.pose.orientation.w = 1.0
        m.scale.z = 0.09
        m.color.r, m.color.g, m.color.b, m.color.a = rgba
        m.text = text
        pub.publish(m)

    def on_status(msg: Any) -> None:
        state["heard"] = rospy.get_time()
        show(msg)

    rospy.Subscriber("robot_status", RobotStatus, on_status, queue_size=1)
    show(None)
    rate = rospy.Rate(2.0)
    while not rospy.is_shutdown():
        heard = state["heard"]
        if heard is not None and rospy.get_time() - heard > stale_after:
            show(None)
        try:
            rate.sleep()
        except rospy.ROSInterruptException:
            break
    return 0
