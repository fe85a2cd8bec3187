"""ROS node `virtual_io_island`: the thin ROS edge of :class:`vr_driver.controller.io_island.VirtualIoIsland`.

Private parameters (defaults in brackets): ``~pty_link`` ["auto"] create a pty pair and symlink its
device end here (``auto``: this launch's own island link, ``controller.pty_link.resolve_link``; "" no symlink); ``~device`` [""] serve this existing device instead; ``~addr`` [8];
``~baud`` [19200]; ``~part_present`` [false] the part sensor at start.

Sets ``~device_path`` to the pty the line hub (or a master) opens. Service (std_srvs/SetBool)
``~set_part_present``: True puts a part in front of the sensor (input ``part_present`` = 1).
Topic ``~outputs`` (std_msgs/String, latched): the output image the island acts on and its DP state,
e.g. ``01 00 DATA_EXCH`` (safe image ``00 00`` outside Data_Exchange), published on every change
(checked every 20 ms) -- what a test reads to see the outputs go safe when the master falls silent.

Exit status: 0 on shutdown, 2 bad parameter, 3 device problem, 1 internal error.
"""
from __future__ import annotations

from typing import Any

import rospy
from std_msgs.msg import String
from std_srvs.srv import SetBool, SetBoolResponse

from ..controller.pty_link import AUTO_LINK
from ..controller.io_island import ISLAND_ADDRESS, VirtualIoIsland
from .support import (init_node, open_device, own_link, route_to_rosout, stop_on_signals, virtual_hardware_priority,
                      watch_simulator)

PARAMS = ("pty_link", "device", "addr", "baud", "part_present", "device_path", "rt_priority")


def main() -> int:
    stop = stop_on_signals()
    init_node("virtual_io_island", disable_signals=True)
    route_to_rosout("vr_driver", "pyprofibus_vendor")
    params = rospy.get_param("~", {}) or {}
    unknown = sorted(k for k in params if k not in PARAMS)
    if unknown:
        rospy.logwarn("virtual_io_island: ignoring unknown parameter(s) %s", ", ".join(unknown))
    device = params.get("device") or None

    def make() -> VirtualIoIsland:
        pty_link = None if device else own_link(params.get("pty_link", AUTO_LINK), "io_island")
        return VirtualIoIsland(device, address=params.get("addr", ISLAND_ADDRESS),
                               baud=params.get("baud", 19200), pty_link=pty_link)
    island, status = open_device("virtual_io_island", make)
    if island is None:
        return status
    island.set_part_present(bool(params.get("part_present", False)))

    def set_part_present(request: Any) -> Any:
        island.set_part_present(bool(request.data))
        return SetBoolResponse(success=True, message="part_present %d" % (1 if request.data else 0))

    service = rospy.Service("~set_part_present", SetBool, set_part_present)
    rospy.on_shutdown(island.request_stop)
    island.start()
    virtual_hardware_priority("virtual_io_island")        # once it runs: its set-up at normal priority
    rospy.set_param("~device_path", island.device_path)
    rospy.loginfo("virtual_io_island: DP slave %d on %s%s", island.address, island.device_path,
                  " (linked at %s)" % island.symlink if island.symlink else "")
    outputs_pub = rospy.Publisher("~outputs", String, queue_size=10, latch=True)
    shown = [""]

    def publish_outputs() -> None:
        now_shown = "%s %s" % (island.program.outputs.hex(" "), island.slave.state.name)
        if now_shown != shown[0]:
            shown[0] = now_shown
            rospy.loginfo("virtual_io_island: outputs %s", now_shown)
            outputs_pub.publish(String(data=now_shown))
    try:
        status = watch_simulator(island, "virtual_io_island", stop, 50.0, publish_outputs)
    finally:
        service.shutdown()
        island.stop()
    rospy.signal_shutdown("virtual I/O island stopped")
    return status
