"""The node `interface`'s own /diagnostics (ROS adapter only; every figure comes from the core's
:class:`vr_driver.driver.DriverStatus`):

- ``link``: connected and the cycle rate, or the link state and its reason; the device, the baud
  rate, the slave's state, the master's and the link's counters, the last slave diagnosis;
- ``controller``: the G2's state and status bits (ERROR on an error or an e-stop, WARN when motion
  is not possible, STALE without feedback), the pose, why no motion, the model check, the target
  counters, the queue, and the commissioned controller's notes;
- ``bus``: the card's view of the master, the gaps between its Data_Exchange replies over the
  last minute (vr_driver.bus.health), WARN when one passed half its watchdog; the cycle rate the
  line really gives against ``cycle_rate`` and the USB adapter (vr_driver.bus.line_check), WARN
  with the cause and the fix when it stays under.

The other parts of the node add their tasks to the same :attr:`DriverDiagnostics.updater` (I/O
stations, joint_command, collision).
"""
from __future__ import annotations

from typing import Sequence

import diagnostic_updater
from diagnostic_msgs.msg import DiagnosticStatus

from ..driver import DriverCore, LinkState
from ..protocol.common import StatusBits


def _add_controller_notes(stat, notes: Sequence[str]):
    """The commissioned G2's differences and what the driver does about each
    (:func:`vr_driver.driver.checks.commissioned.controller_notes`), one entry each, on the controller's
    diagnostics (also logged at every connect)."""
    for k, note in enumerate(notes, 1):
        stat.add("commissioning %d" % k, note)
    return stat


class DriverDiagnostics:
    """The diagnostic_updater of the node with its link, controller and bus tasks, published every
    ``period`` s (the node's timer calls ``updater.force_update()``)."""

    def __init__(self, core: DriverCore, period: float) -> None:
        self.core = core
        self.updater = diagnostic_updater.Updater()
        self.updater.setHardwareID("Panasonic G2 (PROFIBUS-DP slave %d on %s)"
                                   % (core.slave_config.address, core.bus.phy.device))
        self.updater.add("link", self.link)
        self.updater.add("controller", self.controller)
        self.updater.add("bus", self.bus)
        self.updater.period = period

    def link(self, stat):
        s = self.core.status()
        if s.link is LinkState.CONNECTED:
            stat.summary(DiagnosticStatus.OK, "connected, %.1f cycles/s" % s.cycle_rate)
        else:
            stat.summary(DiagnosticStatus.ERROR, "%s: %s" % (s.link.value, s.link_reason))
        stat.add("link state", s.link.value)
        stat.add("link reason", s.link_reason)
        stat.add("device", self.core.bus.phy.device)
        stat.add("baud", str(self.core.bus.baud))
        stat.add("slave state", s.slave_state)
        stat.add("cycle rate [1/s]", "%.1f" % s.cycle_rate)
        for key in ("cycles", "retries", "timeouts", "fcs_errors", "invalid_replies", "losses",
                    "reconnects", "phy_errors", "echoes", "unexpected_frames"):
            if key in s.master_counters:
                stat.add("bus %s" % key.replace("_", " "), str(s.master_counters[key]))
        c = s.counters
        for key in ("port_opens", "port_errors", "reconnect_attempts", "losses", "reconnects",
                    "protocol_errors", "stalled_cycles"):
            stat.add("link %s" % key.replace("_", " "), str(getattr(c, key)))
        if s.last_diag:
            stat.add("last slave diag", s.last_diag)
        return stat

    def bus(self, stat):
        """The card's view of the master: the gaps between its Data_Exchange replies over the last
        minute (vr_driver.bus.health), WARN when one passed half its watchdog."""
        h = self.core.status().bus_health
        if h is None:
            stat.summary(DiagnosticStatus.WARN, "no bus yet (the port is not open)")
            return stat
        if h.late:
            stat.summary(DiagnosticStatus.WARN, "a gap of %.0f ms between two Data_Exchange cycles in the "
                         "last minute: more than half the card's watchdog (%.0f ms)" % (
                             1e3 * h.max_gap, 1e3 * h.watchdog))
        else:
            stat.summary(DiagnosticStatus.OK, h.describe())
        stat.add("longest gap, last minute [ms]", "%.1f" % (1e3 * h.max_gap))
        stat.add("jitter p99, last minute [ms]", "%.1f" % (1e3 * h.jitter_p99))
        stat.add("jitter max, last minute [ms]", "%.1f" % (1e3 * h.jitter_max))
        stat.add("nominal period [ms]", "%.1f" % (1e3 * h.period))
        stat.add("watchdog [ms]", "off" if h.watchdog is None else "%.0f" % (1e3 * h.watchdog))
        stat.add("watchdog margin [ms]", "-" if h.margin is None else "%.1f" % (1e3 * h.margin))
        stat.add("replies, last minute", str(h.replies))
        stat.add("longest gap since start [ms]", "%.1f" % (1e3 * h.worst_gap))
        stat.add("gaps past half the watchdog since start", str(h.late_gaps))
        stat.add("bus process", h.scheduling)
        line = self.core.status().line
        if line is not None:
            # the rate the line really gives against cycle_rate, and the USB adapter (bus/line_check.py)
            if line.slow:
                stat.mergeSummary(DiagnosticStatus.WARN, line.summary)
            elif line.echoes:
                stat.mergeSummary(DiagnosticStatus.OK, "the adapter echoes its transmission (%d frames)"
                                  % line.echoes)
            stat.add("line", line.summary)
            stat.add("cycle rate asked [1/s]", "%.1f" % line.asked)
            stat.add("cycle rate measured [1/s]", "%.1f" % line.measured)
            stat.add("cycle rate the telegrams allow [1/s]", "%.1f" % line.line_max)
            stat.add("reply beyond the wire, mean [ms]", "-" if line.reply_wait is None
                     else "%.1f" % (1e3 * line.reply_wait))
            stat.add("requests resent [%]", "%.1f" % (100 * line.resent))
            stat.add("adapter echoes", str(line.echoes))
            stat.add("adapter", line.adapter or "-")
        return stat

    def controller(self, stat):
        s = self.core.status()
        fb = s.feedback
        if fb is None:
            stat.summary(DiagnosticStatus.STALE, "no feedback (%s)" % s.link_reason)
        else:
            level = DiagnosticStatus.OK if s.motion_possible else DiagnosticStatus.WARN
            if fb.status & (StatusBits.ERROR | StatusBits.ESTOP):
                level = DiagnosticStatus.ERROR
            stat.summary(level, "%s; %s" % (fb.state.name, fb.status.describe()))
            stat.add("pose", " ".join(str(v) for v in fb.values))
            stat.add("why no motion", s.why_no_motion() or "-")
        check = s.model_check
        if check is not None:
            stat.add("model check", check.describe())
            if not check.ok and fb is not None:
                stat.mergeSummary(DiagnosticStatus.WARN, "the model differs from the controller's by "
                                  "%.2f mm / %.3f deg" % (check.position_mm, check.angle_deg))
        for key in ("targets_sent", "targets_done", "targets_rejected", "targets_aborted"):
            stat.add(key.replace("_", " "), str(getattr(s.counters, key)))
        stat.add("queue", str(s.queue_length))
        return _add_controller_notes(stat, self.core.controller_notes)
