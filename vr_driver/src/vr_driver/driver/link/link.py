"""The link supervisor: the serial port, the DP master and the freshness of the controller's
records, stepped by the bus loop. ROS-free.

:meth:`LinkSupervisor.step` runs one bus iteration at ``now``: it opens (or reopens, every
``reconnect_period``) the port, runs one DP cycle with the outputs it was given, decodes a record
that arrived in this cycle, and returns a :class:`LinkSample` -- the link state, the controller's
latest good feedback (never older than ``link_timeout``) and the counters. It decides nothing
about motions; the :class:`~vr_driver.driver.motion.handshake.HandshakeSequencer` does, from the sample.

Rules:
- the link is CONNECTED while the slave is in Data_Exchange and the last good record of this
  Data_Exchange *session* is at most ``link_timeout`` old (a record lost or garbled in between is
  not a loss); records from before the session started never count;
- while the link is not CONNECTED the sample carries no feedback at all (the status must not show
  old good news);
- the first record of a session starts a new session number: the sequencer learns from it that
  everything in flight before was lost.

How the port and the DP master are opened, and when again: :mod:`~vr_driver.driver.link.link_port`;
why the controller's card is not in Data_Exchange, in words:
:class:`~vr_driver.driver.link.card_diagnosis.CardDiagnosis`.

Other stations on the line (I/O islands, PLCs): ``stations`` (a
:class:`~vr_driver.driver.link.stations.IoLine`, optional) gets every master this supervisor creates
(:meth:`IoLine.add_slaves`) and is detached when the port closes; the DriverCore judges it after
each step. Only the controller's slave (``bus.slaves[0]``) decides the link state: the master's
state changes of another station never touch it.
"""
from __future__ import annotations

import collections
import enum
import logging
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable, Deque, Dict, Optional, Tuple

from pyprofibus_vendor.dp_master import BusTiming, DpMaster
from pyprofibus_vendor.errors import ProfibusError
from pyprofibus_vendor.master_api import MasterApi, MasterSlaveState, SlaveView
from pyprofibus_vendor.phy import Link

from ...bus.health import BusHealth, BusHealthSummary
from ...bus.line_check import LineCheck, LineVerdict
from ...errors import ProtocolError
from ...params import DriverParams
from ...protocol.common import FeedbackRecord
from .card_diagnosis import CardDiagnosis, diag_words
from .link_port import (PORT_ERROR_AFTER, Reopening, controller_spec, idle_record, master_settings,
                        start_bus_process)
from .record_clock import RecordClock

if TYPE_CHECKING:
    from pyprofibus_vendor.config import BusConfig

log = logging.getLogger("vr_driver.driver")

__all__ = ["LinkState", "LinkCounters", "LinkSample", "LinkSupervisor", "open_serial_link",
           "ERROR_NONE", "ERROR_LINK", "ERROR_CONTROLLER", "ERROR_PROTOCOL", "PORT_ERROR_AFTER"]

# Error codes in RobotStatus.error_code (documented in doc/README.md).
ERROR_NONE = 0
ERROR_LINK = 1                     # link to the controller down (or the driver's status stale)
ERROR_CONTROLLER = 2               # the controller reports its error bit
ERROR_PROTOCOL = 3                 # the controller's feedback cannot be decoded


class LinkState(enum.Enum):
    STARTING = "starting"          # port not opened yet
    CONNECTING = "connecting"      # port open, DP slave not (yet) in Data_Exchange
    CONNECTED = "connected"        # Data_Exchange with fresh, valid feedback
    LOST = "lost"                  # was connected; feedback stale, slave silent or invalid data
    PORT_ERROR = "port_error"      # the port cannot be opened / died; reopening periodically
    STALE = "stale"                # the bus loop itself produced nothing for link_timeout


@dataclass
class LinkCounters:
    """Link counters and (filled in by the sequencer) target counters, as one record."""

    cycles: int = 0
    port_opens: int = 0
    port_errors: int = 0
    reconnect_attempts: int = 0
    losses: int = 0
    reconnects: int = 0
    protocol_errors: int = 0
    stalled_cycles: int = 0          # cycles longer than link_timeout: their record was dropped
    targets_sent: int = 0
    targets_done: int = 0
    targets_rejected: int = 0
    targets_aborted: int = 0


@dataclass(frozen=True)
class LinkSample:
    """What one bus iteration learnt about the link."""

    time: float
    state: LinkState
    reason: str
    fresh: Optional[FeedbackRecord]              # a record that arrived in this iteration (decoded)
    feedback: Optional[FeedbackRecord]           # the latest good record while CONNECTED, else None
    feedback_time: Optional[float]         # when ``feedback`` arrived
    session: int                           # +1 every time the link becomes CONNECTED
    session_records: int                   # good records received in this session
    error_code: int
    error_reason: str
    cycled: bool                           # a DP cycle ran in this iteration
    record_time: Optional[float] = None    # when the controller's ``feedback`` was taken: the
    #                                        reply that carried it began then (its arrival less its
    #                                        time on the wire); what joint_states are stamped with
    carried: bool = True                   # the cycle carried the record set last (False: a bus
    #                                        process's cycle was under way when it was set; the
    #                                        record set next replaces it before any telegram does)
    outputs_serial: Optional[int] = None   # a bus process's: the serial of the record set last (None:
    #                                        an in-process master, whose cycle carries every record)
    carried_serial: Optional[int] = None   # ... and of the record its last answered cycle carried

    @property
    def connected(self) -> bool:
        return self.state is LinkState.CONNECTED


def open_serial_link(device: str, baud: int) -> Link:
    """Default link factory: the serial PHY (raises PhyError with the OS reason)."""
    from pyprofibus_vendor.phy_serial import SerialLink
    return SerialLink(device, baud)


class LinkSupervisor:
    """See the module docstring. One thread (the bus loop) calls :meth:`step`; the read-outs
    (:attr:`counters`, :meth:`master_counters`, :attr:`slave_state`, :attr:`last_diag`) are for
    the same thread's status snapshot."""

    def __init__(self, params: DriverParams, bus: BusConfig, clock: Callable[[], float],
                 open_link: Callable[[str, int], Link] = open_serial_link,
                 stations: Optional[Any] = None, wake: Optional[Any] = None) -> None:
        self.params = params
        self.bus = bus
        self.slave_config = bus.slaves[0]
        self.stations = stations             # IoLine of the other stations on the line, or None
        self.wake = wake                     # the requests' wake-up (the inbox's): a bus process's master waits for it beside its reports
        self.clock, self.open_link = clock, open_link
        self.counters = LinkCounters()
        # the controller's records, decoded by the protocol (vr_driver.protocol)
        wire, order = params.wire, params.byte_order
        self._decode: Callable[[bytes], Any] = lambda data: wire.decode_feedback(data, order)
        self._master: Optional[MasterApi] = None
        self._slave: Optional[SlaveView] = None
        self._state = LinkState.STARTING
        self._reason = "not started"
        self._session = 0
        self._session_start = 0.0           # the slave (re)entered Data_Exchange
        self._session_records = 0            # good records received in this DP session
        self._record_time: Optional[float] = None    # when the last record (good or bad) arrived
        self._good_time: Optional[float] = None      # when the last good record arrived
        self._feedback: Optional[FeedbackRecord] = None
        self._bad_record = ""                # why the last record could not be decoded
        # why the controller's card is not in Data_Exchange; when to open the port again
        self._diagnosis = CardDiagnosis(self.slave_config, bus.baud)
        self._reopen = Reopening(params.reconnect_period)
        self._error_code = ERROR_LINK
        self._error_reason = "not started"
        self._cycle_times: Deque[Tuple[float, int]] = collections.deque(maxlen=50)
        # the serial port and the DP master in a process of their own (vr_driver.bus.process):
        # the node's default; an injected link factory (tests' in-memory links) stays in-process
        self.uses_bus_process = bool(params.bus_process) and open_link is open_serial_link
        # the gaps between the card's Data_Exchange replies (in-process: fed here; a bus process
        # measures them itself and reports its summary)
        self.health: Optional[BusHealth] = None
        self._health_summary: Optional[BusHealthSummary] = None
        self._health_at = -math.inf
        # a reply's time on the wire (SD2 telegram: 9 characters of frame + the controller's record,
        # 11 bits each): a record arrives this long after the card began sending it
        self.reply_time = BusTiming.for_baud(bus.baud).chars(9 + self.slave_config.input_len)
        # when the controller took each record: from its heartbeat where the protocol has one
        self.record_clock = RecordClock()
        self._wire = wire
        self._record_stamp: Optional[float] = None
        self._stop_source = b""
        # the rate the line really gives against cycle_rate, and the adapter (bus/line_check.py)
        self.line_check: Optional[LineCheck] = None

    # ----------------------------------------------------------------------- read-outs
    @property
    def state(self) -> LinkState:
        return self._state

    @property
    def cycle_rate(self) -> float:
        """Bus cycles per second over the last 50 (a bus process's own count where there is one)."""
        times = self._cycle_times
        if len(times) > 1 and times[-1][0] > times[0][0]:
            return (times[-1][1] - times[0][1]) / (times[-1][0] - times[0][0])
        return 0.0

    def health_summary(self, now: float) -> Optional[BusHealthSummary]:
        """The bus's health over the last minute (None before the port was opened): the bus
        process's report, or (in-process) this supervisor's own, made at most once a second."""
        master = self._master
        if master is not None and master.paced:
            return master.health         # a bus process measures the gaps itself
        if self.health is not None and now - self._health_at >= 1.0:
            self._health_summary, self._health_at = self.health.summary(now), now
        return self._health_summary

    def line_verdict(self) -> Optional[LineVerdict]:
        """The cycle rate against the asked one and the adapter, in words (None before a port)."""
        return self.line_check.verdict() if self.line_check is not None else None

    def _check_line(self, now: float) -> None:
        if self.line_check is not None and self._master is not None:
            self.line_check.update(now, vars(self._master.counters), self._state is LinkState.CONNECTED)

    def master_counters(self) -> Dict[str, int]:
        return dict(vars(self._master.counters)) if self._master is not None else {}

    @property
    def slave_state(self) -> str:
        return self._slave.state.value if self._slave is not None else "closed"

    @property
    def last_diag(self) -> str:
        slave = self._slave
        return diag_words(slave.last_diag) if slave is not None and slave.last_diag is not None else ""

    @property
    def paced(self) -> bool:
        """True when the master keeps the bus's time itself (a bus process): :meth:`step` then
        waits for its next cycle, and the caller's loop must not sleep a period on top."""
        return self._master is not None and self._master.paced

    def cycle_at(self, when: float) -> None:
        """Ask a paced master for its next cycle no later than ``when`` (clock time)."""
        master = self._master
        if master is not None:
            try:
                master.cycle_at(when)
            except ProfibusError:
                pass           # the bus process is gone: the next step says so

    def set_outputs(self, record: bytes) -> None:
        """The record sent in the next DP cycles (to a bus process with the record that stops
        what it sets going: sent there if the driver dies), and then the bus process told that the
        driver has answered its last report (it waits at most its ``answer_wait`` for that)."""
        slave = self._slave
        if slave is None:
            return
        if record != self._stop_source:
            self._stop_source = record
            try:
                slave.stop_outputs = self._wire.stop_record(record, self.params.byte_order)
            except ProtocolError as exc:    # never: the record was encoded by the same protocol
                log.error("no stop record for %s: %s", record.hex(), exc)
        slave.outputs = record
        if self._master is not None:
            try:
                self._master.answered()
            except ProfibusError:
                pass           # the bus process is gone: the next step says so

    # ----------------------------------------------------------------------- the step
    def step(self, now: float) -> LinkSample:
        """One bus iteration: open the port if due, run one DP cycle, judge the record."""
        if self._master is None:
            if self._reopen.due(now):
                self._open(now)
            if self._master is None:
                return self._sample(now, None, cycled=False)
        master = self._master
        begin = now
        try:
            ran = master.cycle(timeout=self._cycle_timeout())
        except ProfibusError as exc:
            self.counters.port_errors += 1
            self.close()
            now = self.clock()
            self._reopen.later(now)
            self._down(LinkState.PORT_ERROR, "serial port %s failed: %s" % (self.bus.phy.device, exc))
            return self._sample(now, None, cycled=False)
        now = self.clock()
        if self.paced:
            # the bus process cycles on its own: its records carry their true arrival times, so a
            # slow step here is never old news taken as fresh (no stall rule); woken without a
            # report (a request was posted), nothing new to judge but the timers
            if ran:
                self.counters.cycles += 1
                self._cycle_times.append((now, master.counters.cycles))
            fresh = self._judge(now)
            if ran:
                self._check_line(now)
            return self._sample(now, fresh, cycled=bool(ran))
        self.counters.cycles += 1
        self._cycle_times.append((now, self.counters.cycles))
        stalled = now - begin > self.params.link_timeout
        if stalled:
            self.counters.stalled_cycles += 1
            log.warning("a bus cycle took %.2f s (the process was stopped or starved): the record "
                        "it brought may be that old and is not used", now - begin)
        fresh = self._judge(now, stalled)
        self._check_line(now)
        return self._sample(now, fresh, cycled=True)

    def _cycle_timeout(self) -> float:
        """How long one step may wait for the master's cycle: in Data_Exchange, until the cycle
        under way ends (two periods, at least 0.2 s: a slow line's telegrams); while the card is
        brought up or backs off (the link down or reconnecting), one bus period -- the cycle goes on
        at the next step, and the status keeps its rate (it stood still for the back-off's 0.2 s,
        20 periods at 100 Hz)."""
        period = 1.0 / self.bus.cycle_rate_hz
        slave = self._slave
        if slave is not None and slave.connected:
            return max(0.2, 2.0 * period)
        return period

    def _judge(self, now: float, stalled: bool = False) -> Optional[FeedbackRecord]:
        """Take the cycle's record if a new one arrived; update the link state. ``stalled``: the
        cycle took longer than ``link_timeout`` -- its reply may have waited in the port's buffer
        all that time (a process stopped and resumed), so it is not fresh news and is dropped."""
        slave = self._slave
        fresh: Optional[FeedbackRecord] = None
        reason = ""
        if slave is None or not slave.connected:
            state = slave.state.value if slave is not None else "none"
            reason = self._diagnosis.reason or "controller's PROFIBUS card not in Data_Exchange (%s)" % state
        else:
            data, at = slave.inputs, slave.inputs_time
            new = data is not None and at is not None and at >= self._session_start \
                and at != self._record_time
            if new:
                self._record_time = at               # consumed (a stalled cycle's: not believed)
                if self.health is not None and not self.paced:
                    self.health.reply(at)
            if new and not stalled:
                try:
                    fresh = self._decode(data)
                    self._bad_record = ""
                except ProtocolError as exc:
                    self.counters.protocol_errors += 1
                    if not self._bad_record:
                        log.warning("invalid feedback from the controller (ignored while the link "
                                    "holds): %s", exc)
                    self._bad_record = "invalid feedback from the controller: %s" % exc
            if fresh is not None:
                self._good_time = at
                if self._state is not LinkState.CONNECTED:
                    self.record_clock.reset()        # a new session: the program may have restarted
                self._record_stamp = self.record_clock.stamp(at - self.reply_time,
                                                             self._wire.feedback_heartbeat(fresh))
                self._session_records += 1
                self._diagnosis.good_record(self._master)
            last = max(self._session_start, self._good_time or 0.0)
            if self._good_time is None or self._good_time < self._session_start \
                    or now - last > self.params.link_timeout:
                reason = self._bad_record or \
                    "no fresh data from the controller for %.2f s" % (now - last)
        if reason:
            was = self._state
            self._down(LinkState.LOST if was in (LinkState.CONNECTED, LinkState.LOST)
                       else LinkState.CONNECTING, reason)
            if self._bad_record and reason == self._bad_record:
                self._error_code, self._error_reason = ERROR_PROTOCOL, reason
            return None
        if fresh is not None:
            if self._state is not LinkState.CONNECTED:
                if self.counters.losses:
                    self.counters.reconnects += 1
                self._session += 1
                log.info("link to the controller up: %s", fresh.describe())
            self._diagnosis.link_up()
            self._state, self._reason = LinkState.CONNECTED, "Data_Exchange"
            self._feedback = fresh
            self._error_code, self._error_reason = 0, ""
        return fresh

    def _sample(self, now: float, fresh: Optional[FeedbackRecord], cycled: bool) -> LinkSample:
        connected = self._state is LinkState.CONNECTED and self._feedback is not None
        return LinkSample(
            time=now, state=self._state, reason=self._reason, fresh=fresh,
            feedback=self._feedback if connected else None,
            feedback_time=self._good_time if connected else None,
            record_time=self._record_stamp if connected else None,
            session=self._session, session_records=self._session_records,
            error_code=self._error_code, error_reason=self._error_reason, cycled=cycled,
            carried=self._slave.carried if self._slave is not None else True,
            outputs_serial=self._slave.serial if self._slave is not None else None,
            carried_serial=self._slave.carried_serial if self._slave is not None else None)

    def _down(self, state: LinkState, reason: str) -> None:
        if self._state is LinkState.CONNECTED and state is not LinkState.CONNECTED:
            self.counters.losses += 1
            log.error("link to the controller lost: %s", reason)
        self._state, self._reason = state, reason
        self._feedback = None
        self._error_code, self._error_reason = ERROR_LINK, reason

    # ----------------------------------------------------------------------- port and master
    def _open(self, now: float) -> None:
        device, baud = self.bus.phy.device, self.bus.baud
        self.counters.reconnect_attempts += 1
        sc = self.slave_config
        spec = controller_spec(sc)
        settings = master_settings(self.params, self.bus)
        link: Optional[Link] = None
        try:
            if self.uses_bus_process:
                master: MasterApi = start_bus_process(self.params, self.bus, spec, settings, self._on_slave_state,
                                                      self.wake)
            else:
                link = self.open_link(device, baud)
        except (ProfibusError, OSError, ValueError) as exc:
            self._down(LinkState.PORT_ERROR, self._reopen.cannot_open(now, device, exc, self._reason))
            return
        self.counters.port_opens += 1
        self._diagnosis.port_opened()
        if link is not None:
            master = DpMaster(link, self.bus.master_address, self.bus.baud, clock=self.clock,
                              on_state_change=self._on_slave_state, **settings)
        self.health = BusHealth(1.0 / self.bus.cycle_rate_hz, spec.watchdog,
                                scheduling=master.scheduling or "in the driver's process")
        self._slave = master.add_slave(spec)
        self._slave.outputs = idle_record(self.params)
        self._master = master
        if self.stations is not None:
            self.stations.add_slaves(master, self.bus)   # the I/O stations, cycled by the same master
        self.line_check = LineCheck(
            baud, self.bus.cycle_rate_hz,
            [(s.spec.output_size or 0, s.spec.input_size or 0) for s in master.slaves],
            master.adapter)
        log.info("opened %s at %d bit/s; bringing slave %d (ident 0x%04X) to Data_Exchange",
                 device, baud, sc.address, sc.ident)
        self._down(LinkState.CONNECTING, "port open, waiting for the controller's PROFIBUS card")

    def close(self) -> None:
        master = self._master
        self._master, self._slave = None, None
        if self.stations is not None:
            self.stations.detach()
        if master is not None:
            try:
                master.close()      # the port with it (or the bus process)
            except Exception:  # closing a dead port may fail; nothing to do about it
                pass

    def fail(self, reason: str) -> None:
        """Drop the link after an internal error: close the port, reopen after the period."""
        self.close()
        self._reopen.later(self.clock())
        self._down(LinkState.PORT_ERROR, reason)

    def _on_slave_state(self, slave, old: MasterSlaveState, new: MasterSlaveState, reason: str) -> None:
        """The DP master's per-slave state changes: keep the last reason for the status (the
        controller's only: the I/O stations have their own supervision)."""
        if slave.address != self.slave_config.address:
            return
        if new is MasterSlaveState.INIT:
            self.counters.reconnect_attempts += 1
        connected = (MasterSlaveState.DATA_EXCHANGE, MasterSlaveState.DX_DIAG)
        if new in connected and old not in connected:
            self._session_start = slave.state_since   # records from before are of the old session
            self._session_records = 0
        elif old in connected and new not in connected:
            # exactly once across a reset: the card's next Data_Exchange (after the watchdog or a
            # new Set_Prm restarted the controller's program) carries the idle record, never the
            # command that was in the outputs before -- the sequencer sends anew from there
            slave.outputs = idle_record(self.params)
            if self.health is not None:
                self.health.session_ended()
        if new is MasterSlaveState.BACKOFF:
            self._diagnosis.attempt_failed(slave, reason, self._master)
        elif new in connected:
            self._diagnosis.data_exchange()
