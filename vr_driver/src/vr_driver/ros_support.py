"""Route the ROS-free core's Python logging to rosout (for the nodes; imports rospy)."""
from __future__ import annotations

import logging

import rospy


class RosoutHandler(logging.Handler):
    """A logging handler that emits each record through rospy's log functions."""

    def emit(self, record: logging.LogRecord) -> None:
        text = self.format(record)
        if record.levelno >= logging.CRITICAL:
            rospy.logfatal("%s", text)
        elif record.levelno >= logging.ERROR:
            rospy.logerr("%s", text)
        elif record.levelno >= logging.WARNING:
            rospy.logwarn("%s", text)
        elif record.levelno >= logging.INFO:
            rospy.loginfo("%s", text)
        else:
            rospy.logdebug("%s", text)


def route_to_rosout(*names: str, level: int = logging.INFO) -> None:
    """Send the named loggers to rosout only (no propagation, so nothing is logged twice)."""
    for name in names:
        logger = logging.getLogger(name)
        logger.handlers = [h for h in logger.handlers if not isinstance(h, RosoutHandler)]
        logger.addHandler(RosoutHandler())
        logger.setLevel(level)
        logger.propagate = False
