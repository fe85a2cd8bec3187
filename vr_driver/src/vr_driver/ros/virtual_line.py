"""ROS node `virtual_line`: the thin ROS edge of :class:`vr_driver.controller.line.LineHub`, the hub that
joins the ptys of the simulated stations into one multi-drop PROFIBUS line.

Private parameters: ``~stations`` [["auto", "auto:io_island"]] the stations' pty paths; ``auto`` is this
launch's virtual controller link, ``auto:NAME`` this launch's link of station NAME
(``controller.pty_link.auto_pty_link(station=NAME)``); ``~pty_link`` ["auto"] where the master's pty is
linked (``auto``: ``<ROS log dir>/vr006l_virtual_line_<master port>``; the driver's ``port``);
``~baud`` [0] pace the line at this bit rate (0: as fast as the ptys); ``~rate`` [0] the stations' bit rate: a
master whose port is set to another one meets garbled characters and no reply, as on a wire (0: any rate's
bytes pass; :mod:`vr_driver.controller.line_rate`).
The USB adapter on the master's side
(vr_driver.controller.adapter_model, doc/adapters.md): ``~latency_ms`` [0] its latency timer, ``~echo`` [false]
it echoes the master's transmission, ``~turnaround_ms`` [0] its receiver deaf this long after sending.

Sets ``~device_path`` (the master's pty). Exit status: 0 on shutdown, 2 bad parameter, 3 device problem.
"""
from __future__ import annotations

import threading
from typing import List

import rospy

from pyprofibus_vendor.errors import PhyError

from ..controller.pty_link import AUTO_LINK, resolve_link
from ..controller.simulator import EXIT_DEVICE, EXIT_OK, SimError
from .support import init_node, open_device, own_link, route_to_rosout, stop_on_signals, virtual_hardware_priority
from ..controller.adapter_model import AdapterBehaviour
from ..controller.line import LineHub


def main() -> int:
    stop = stop_on_signals()
    init_node("virtual_line", disable_signals=True)
    route_to_rosout("vr_driver", "pyprofibus_vendor")

    def make() -> LineHub:
        raw = rospy.get_param("~stations", [AUTO_LINK, AUTO_LINK + ":io_island"])
        if not isinstance(raw, list) or not all(isinstance(p, str) and p for p in raw):
            raise SimError("~stations must be a list of pty paths, got %r" % (raw,))
        stations: List[str] = [resolve_link(p) for p in raw]
        baud = int(rospy.get_param("~baud", 0)) or None
        rate = int(rospy.get_param("~rate", 0)) or None
        try:
            adapter = AdapterBehaviour(latency_ms=float(rospy.get_param("~latency_ms", 0.0)),
                                       echo=bool(rospy.get_param("~echo", False)),
                                       turnaround_ms=float(rospy.get_param("~turnaround_ms", 0.0)))
        except (TypeError, ValueError) as exc:
            raise SimError("~latency_ms / ~echo / ~turnaround_ms: %s" % exc) from None
        return LineHub(stations, pty_link=own_link(rospy.get_param("~pty_link", AUTO_LINK), "line"), baud=baud,
                       rate=rate, adapter=adapter)
    hub, status = open_device("virtual_line", make)
    if hub is None:
        return status
    rospy.set_param("~device_path", hub.device_path)
    rospy.loginfo("virtual_line: master end %s%s; stations %s; adapter: %s", hub.device_path,
                  " (linked at %s)" % hub.symlink if hub.symlink else "", ", ".join(s.path for s in hub.stations),
                  hub.adapter.behaviour.describe() if hub.adapter is not None else "a perfect one")
    halt = threading.Event()
    rospy.on_shutdown(halt.set)
    virtual_hardware_priority("virtual_line")             # once it is made: its set-up at normal priority
    status = EXIT_OK
    try:
        while not rospy.is_shutdown() and not stop.is_set() and not halt.is_set():
            hub.step(0.05)
    except PhyError as exc:
        rospy.logfatal("virtual_line: device error: %s", exc)
        status = EXIT_DEVICE
    finally:
        hub.stop()
    rospy.signal_shutdown("virtual line stopped")
    return status
