"""The I/O line's ROS interface of the node `interface` (ROS adapter only; the supervision and the
checks are in :class:`vr_driver.driver.link.stations.IoLine`, doc/io_line.md):

- service ``set_io`` (vr_driver/SetIO): set an output signal by name, the value as text. Refused --
  ``success: false``, the reason, nothing sent and nothing kept to be sent later -- for an unknown
  name, an input signal, a value that does not fit its type, a station not in Data_Exchange, or a
  bus loop that stalled (its view of the stations is older than ``link_timeout``);
- service ``get_io`` (vr_driver/GetIO): a signal's value as text (refused while its station is
  offline: never an old value as live);
- topic ``io_states`` (vr_driver/IOStates, latched): every signal with its value, direction and
  whether its station is online, published at once on every change (from the bus thread) and at
  ``io_states_rate``;
- ``/diagnostics``: one status per station (online or the reason, DP state, last diagnosis in
  words, losses, outputs at their safe values).

Without ``io_signals`` the services exist and refuse every request saying so; nothing is published.
"""
from __future__ import annotations

import threading
from typing import Any, Optional, Tuple

import rospy
from diagnostic_msgs.msg import DiagnosticStatus

from vr_driver.msg import IOState, IOStates
from vr_driver.srv import GetIO, GetIOResponse, SetIO, SetIOResponse

from ..driver import DriverCore
from ..driver.link.stations import IoResult, IoSnapshot
from ..params import DriverParams


class IoServer:
    def __init__(self, core: DriverCore, params: DriverParams, diag: Any) -> None:
        self.core = core
        self.io = core.io
        self.params = params
        self._lock = threading.Lock()
        self._last: Optional[Tuple[Tuple[str, str, bool], ...]] = None   # what io_states showed last
        self._timer: Optional[rospy.Timer] = None
        self.pub = None
        if self.io is not None:
            self.pub = rospy.Publisher("io_states", IOStates, queue_size=10, latch=True)
            for station in self.io.map.stations:
                diag.add("I/O station %s" % station.name,
                         lambda stat, name=station.name: self._diag_station(stat, name))
        self.set_srv = rospy.Service("set_io", SetIO, self._set_io)
        self.get_srv = rospy.Service("get_io", GetIO, self._get_io)

    def start(self) -> None:
        mapped = {st.address for st in self.io.map.stations} if self.io is not None else set()
        idle = [s for s in self.core.bus.slaves[1:] if s.address not in mapped]
        if idle:
            rospy.logwarn("interface: slave(s) %s of the bus config have no station in ~io_signals%s: "
                          "not cycled", ", ".join("%d (%s)" % (s.address, s.name) for s in idle),
                          "" if self.io is not None else " (empty)")
        if self.io is None:
            return
        self.core.add_listener(lambda _status: self._publish(force=False))
        self._timer = rospy.Timer(rospy.Duration(1.0 / self.params.io_states_rate),
                                  lambda _e: self._publish(force=True))
        rospy.loginfo("interface: I/O signals %s",
                      "; ".join("%s (slave %d): %s" % (st.name, st.address,
                                                      ", ".join(s.name for s in st.signals))
                                for st in self.io.map.stations))

    def shutdown(self) -> None:
        if self._timer is not None:
            self._timer.shutdown()

    # ------------------------------------------------------------------ the stations' view
    def _stale(self, snap: IoSnapshot) -> str:
        """Why the snapshot cannot be believed ("" when it can): the bus loop produced nothing
        for ``link_timeout`` (a stopped or starved process)."""
        age = self.core.clock() - snap.time
        if age > self.params.link_timeout:
            return "the driver's view of the I/O stations is %.2f s old (the bus loop stalled)" % age
        return ""

    def _publish(self, force: bool) -> None:
        """io_states when what it shows changed (``force``: anyway, the fixed rate)."""
        snap = self.io.snapshot()
        stale = bool(self._stale(snap))
        shown = tuple((s.name, "" if stale else s.text, s.online and not stale) for s in snap.signals)
        with self._lock:
            if not force and shown == self._last:
                return
            self._last = shown
        msg = IOStates()
        msg.header.stamp = rospy.Time.now()
        msg.signals = [IOState(name=s.name, station=s.station, type=s.type, direction=s.direction,
                               value=text, online=online)
                       for s, (_name, text, online) in zip(snap.signals, shown)]
        self.pub.publish(msg)

    # ------------------------------------------------------------------ services
    def _refusal(self) -> str:
        if self.io is None:
            return "no I/O signals configured (the parameter ~io_signals is empty)"
        return self._stale(self.io.snapshot())

    def _set_io(self, req: Any) -> SetIOResponse:
        why = self._refusal()
        result = IoResult(False, "%s: %s not set, nothing sent" % (why, req.signal)) if why \
            else self.io.write(req.signal, req.value)
        if result.success:
            rospy.loginfo("set_io %s", result.message)
            self._publish(force=False)
        else:
            rospy.logwarn("set_io %r = %r refused: %s", req.signal, req.value, result.message)
        return SetIOResponse(success=result.success, message=result.message)

    def _get_io(self, req: Any) -> GetIOResponse:
        why = self._refusal()
        result = IoResult(False, why) if why else self.io.read(req.signal)
        return GetIOResponse(value=result.value, success=result.success, message=result.message)

    # ------------------------------------------------------------------ diagnostics
    def _diag_station(self, stat: Any, name: str) -> Any:
        snap = self.io.snapshot()
        st = snap.station(name)
        stale = self._stale(snap)
        if stale:
            stat.summary(DiagnosticStatus.STALE, stale)
        elif st.online:
            stat.summary(DiagnosticStatus.OK, "online (Data_Exchange)%s"
                         % ("; outputs at their safe values until set" if st.outputs_safe else ""))
        else:
            stat.summary(DiagnosticStatus.ERROR, "offline: %s; outputs at their safe values" % st.reason)
        stat.add("address", str(st.address))
        stat.add("online", str(st.online and not stale).lower())
        stat.add("DP state", st.dp_state)
        stat.add("reason", st.reason or "-")
        stat.add("diagnosis", st.diag or "-")
        stat.add("losses", str(st.losses))
        stat.add("outputs safe", str(st.outputs_safe).lower())
        return stat
