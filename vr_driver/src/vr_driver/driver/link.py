"""The link supervisor: the serial port, the DP master and the freshness of the controller's
records, stepped by the bus loop. ROS-free.

:meth:`LinkSupervisor.step` runs one bus iteration at ``now``: it opens (or reopens, every
``reconnect_period``) the port, runs one DP cycle with the outputs it was given, decodes a record
that arrived in this cycle, and returns a :class:`LinkSample` -- the link state, the controller's
latest good feedback (never older than ``link_timeout``) and the counters. It decides nothing
about motions; the :class:`~vr_driver.driver.sequencer.HandshakeSequencer` does, from the sample.

Rules:
- the link is CONNECTED while the slave is in Data_Exchange and the last good record of this
  Data_Exchange *session* is at most ``link_timeout`` old (a record lost or garbled in between is
  not a loss); records from before the session started never count;
- while the link is not CONNECTED the sample carries no feedback at all (the status must not show
  old good news);
- the first record of a session starts a new session number: the sequencer learns from it that
  everything in flight before was lost.

Other stations on the line (I/O islands, PLCs): ``stations`` (a
:class:`~vr_driver.driver.stations.IoLine`, optional) gets every master this supervisor creates
(:meth:`IoLine.add_slaves`) and is detached when the port closes; the DriverCore judges it after
each step. Only the controller's slave (``bus.slaves[0]``) decides the link state: the master's
state changes of another station never touch it.
"""
from __future__ import annotations

import collections
import enum
import errno
import logging
import math
import os
import re
from dataclasses import dataclass, replace
from typing import Any, Callable, Deque, Dict, Optional, Tuple

from pyprofibus_vendor.dp import DiagStatus1
from pyprofibus_vendor.dp_master import BusTiming, DpMaster, MasterSlaveState, SlaveSpec
from pyprofibus_vendor.errors import PhyError, ProfibusError
from pyprofibus_vendor.phy import Link

from ..bus.health import BusHealth, BusHealthSummary
from ..bus.process import BusProcessMaster, BusSettings, RemoteSlave
from ..errors import ProtocolError
from ..params import DriverParams
from ..protocol.common import FeedbackRecord
from .record_clock import RecordClock

log = logging.getLogger("vr_driver.driver")

__all__ = ["LinkState", "LinkCounters", "LinkSample", "LinkSupervisor", "open_serial_link",
           "ERROR_NONE", "ERROR_LINK", "ERROR_CONTROLLER", "ERROR_PROTOCOL", "PORT_ERROR_AFTER"]

# Error codes in RobotStatus.error_code (documented in doc/README.md).
ERROR_NONE = 0
ERROR_LINK = 1                     # link to the controller down (or the driver's status stale)
ERROR_CONTROLLER = 2               # the controller reports its error bit
ERROR_PROTOCOL = 3                 # the controller's feedback cannot be decoded

# a port that cannot be opened is a warning at first (a virtual controller may still be starting),
# an error once it has been missing this long [s]
PORT_ERROR_AFTER = 5.0


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

    @property
    def connected(self) -> bool:
        return self.state is LinkState.CONNECTED


def _port_hint(exc: BaseException) -> str:
    """What an error opening the port most likely means, for the errors with a clear remedy."""
    codes = set()
    seen: Optional[BaseException] = exc
    for _ in range(5):
        if seen is None:
            break
        if isinstance(getattr(seen, "errno", None), int):
            codes.add(seen.errno)
        seen = seen.__cause__ or seen.__context__
    text = str(exc)
    if codes & {errno.EACCES, errno.EPERM} or "Permission denied" in text:
        return (" (permission denied: the driver's user needs read and write access to the device, "
                "usually membership of its group, e.g. dialout)")
    if errno.EBUSY in codes or "Device or resource busy" in text:
        return " (the device is busy: another program has it open)"
    return ""


def _diag_words(diag: Any) -> str:
    from pyprofibus_vendor.dp import explain_diag
    try:
        return explain_diag(diag)
    except Exception:  # a diag we cannot explain is still worth showing raw
        return repr(diag)


def idle_record(params: DriverParams) -> bytes:
    """The record that asks nothing of the controller (the flag at 0 / both slots empty)."""
    return params.wire.idle_record(params.byte_order)


def open_serial_link(device: str, baud: int) -> Link:
    """Default link factory: the serial PHY (raises PhyError with the OS reason)."""
    from pyprofibus_vendor.phy_serial import SerialLink
    return SerialLink(device, baud)


class LinkSupervisor:
    """See the module docstring. One thread (the bus loop) calls :meth:`step`; the read-outs
    (:attr:`counters`, :meth:`master_counters`, :attr:`slave_state`, :attr:`last_diag`) are for
    the same thread's status snapshot."""

    def __init__(self, params: DriverParams, bus: Any, clock: Callable[[], float],
                 open_link: Callable[[str, int], Link] = open_serial_link,
                 stations: Optional[Any] = None) -> None:
        self.params = params
        self.bus = bus
        self.slave_config = bus.slaves[0]
        self.stations = stations             # IoLine of the other stations on the line, or None
        self.clock = clock
        self.open_link = open_link
        self.counters = LinkCounters()
        # the controller's records, decoded by the protocol (vr_driver.protocol)
        wire, order = params.wire, params.byte_order
        self._decode: Callable[[bytes], Any] = lambda data: wire.decode_feedback(data, order)
        self._link: Optional[Link] = None
        self._master: Optional[DpMaster] = None
        self._slave = None
        self._state = LinkState.STARTING
        self._reason = "not started"
        self._next_open = 0.0
        self._session = 0
        self._session_start = 0.0           # the slave (re)entered Data_Exchange
        self._session_records = 0            # good records received in this DP session
        self._record_time: Optional[float] = None    # when the last record (good or bad) arrived
        self._good_time: Optional[float] = None      # when the last good record arrived
        self._feedback: Optional[FeedbackRecord] = None
        self._bad_record = ""                # why the last record could not be decoded
        self._slave_reason = ""
        self._logged_slave_reason = ""
        self._garbage_seen = 0
        self._port_missing_since = 0.0
        self._port_error_logged = False
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
        if isinstance(master, BusProcessMaster):
            return master.health
        if self.health is not None and now - self._health_at >= 1.0:
            self._health_summary, self._health_at = self.health.summary(now), now
        return self._health_summary

    def master_counters(self) -> Dict[str, int]:
        return dict(vars(self._master.counters)) if self._master is not None else {}

    @property
    def slave_state(self) -> str:
        return self._slave.state.value if self._slave is not None else "closed"

    @property
    def last_diag(self) -> str:
        slave = self._slave
        return _diag_words(slave.last_diag) if slave is not None and slave.last_diag is not None else ""

    @property
    def paced(self) -> bool:
        """True when the master keeps the bus's time itself (a bus process): :meth:`step` then
        waits for its next cycle, and the caller's loop must not sleep a period on top."""
        return bool(getattr(self._master, "paced", False))

    def poke(self) -> None:
        """Wake a :meth:`step` waiting for a paced master's next cycle (a request was posted).
        Safe from any thread and from a signal handler."""
        master = self._master
        if master is not None and hasattr(master, "poke"):
            master.poke()

    def cycle_at(self, when: float) -> None:
        """Ask a paced master for its next cycle no later than ``when`` (clock time)."""
        master = self._master
        if isinstance(master, BusProcessMaster):
            try:
                master.cycle_at(when)
            except ProfibusError:
                pass           # the bus process is gone: the next step says so

    def set_outputs(self, record: bytes) -> None:
        """The record sent in the next DP cycles (to a bus process with the record that stops
        what it sets going: sent there if the driver dies)."""
        slave = self._slave
        if slave is None:
            return
        if isinstance(slave, RemoteSlave) and record != self._stop_source:
            self._stop_source = record
            try:
                slave.stop_outputs = self._wire.stop_record(record, self.params.byte_order)
            except ProtocolError as exc:    # never: the record was encoded by the same protocol
                log.error("no stop record for %s: %s", record.hex(), exc)
        slave.outputs = record

    # ----------------------------------------------------------------------- the step
    def step(self, now: float) -> LinkSample:
        """One bus iteration: open the port if due, run one DP cycle, judge the record."""
        if self._master is None:
            if now >= self._next_open:
                self._open(now)
            if self._master is None:
                return self._sample(now, None, cycled=False)
        master = self._master
        begin = now
        try:
            ran = master.cycle(timeout=max(0.2, 2.0 / self.bus.cycle_rate_hz))
        except ProfibusError as exc:
            self.counters.port_errors += 1
            self.close()
            now = self.clock()
            self._next_open = now + self.params.reconnect_period
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
            return self._sample(now, self._judge(now), cycled=bool(ran))
        self.counters.cycles += 1
        self._cycle_times.append((now, self.counters.cycles))
        stalled = now - begin > self.params.link_timeout
        if stalled:
            self.counters.stalled_cycles += 1
            log.warning("a bus cycle took %.2f s (the process was stopped or starved): the record "
                        "it brought may be that old and is not used", now - begin)
        fresh = self._judge(now, stalled)
        return self._sample(now, fresh, cycled=True)

    def _judge(self, now: float, stalled: bool = False) -> Optional[FeedbackRecord]:
        """Take the cycle's record if a new one arrived; update the link state. ``stalled``: the
        cycle took longer than ``link_timeout`` -- its reply may have waited in the port's buffer
        all that time (a process stopped and resumed), so it is not fresh news and is dropped."""
        slave = self._slave
        fresh: Optional[FeedbackRecord] = None
        reason = ""
        if slave is None or not slave.connected:
            state = slave.state.value if slave is not None else "none"
            reason = self._slave_reason or "controller's PROFIBUS card not in Data_Exchange (%s)" % state
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
                master = self._master
                if master is not None:        # garbled bytes are counted from the last good record
                    self._garbage_seen = master.counters.garbage_bytes + master.counters.fcs_errors
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
            self._slave_reason = ""
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
            error_code=self._error_code, error_reason=self._error_reason, cycled=cycled)

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
        timing = BusTiming.for_baud(self.bus.baud, self.bus.retry_limit)
        if self.bus.slot_time is not None:
            timing = replace(timing, slot_bits=self.bus.slot_time)
        sc = self.slave_config
        spec = SlaveSpec(sc.address, sc.ident, sc.cfg, user_prm_data=sc.user_prm_data,
                         group_ident=sc.group_mask,
                         watchdog=None if not sc.watchdog_ms else sc.watchdog_ms / 1000.0)
        # dx_tolerance: a Data_Exchange without a reply (a corrupted telegram) does not drop the
        # slave -- and with its Set_Prm the controller's program session -- before the link counts
        # as lost here anyway (link_timeout without a good record); retry_steps: a lost reply in
        # the start-up sequence repeats that step instead of restarting it after a back-off
        settings = dict(timing=timing, backoff_max=min(1.0, self.params.reconnect_period),
                        dx_tolerance=self.params.link_timeout, retry_steps=True)
        link: Optional[Link] = None
        try:
            if self.uses_bus_process:
                # a device that is not there (an unplugged adapter, a virtual controller not started
                # yet) is said here, as the serial link says it, without starting a process for it
                # at every reconnect attempt (each start holds the bus loop: the status went stale)
                if "://" not in device and not os.path.exists(device):
                    raise PhyError("serial device %s does not exist" % device)
                master: Any = BusProcessMaster(BusSettings(
                    device=device, baud=baud, master_address=self.bus.master_address,
                    cycle_rate_hz=self.bus.cycle_rate_hz, controller=sc.address,
                    idle_record=idle_record(self.params), watchdog=spec.watchdog,
                    rt_priority=self.params.bus_rt_priority, node_timeout=self.params.bus_node_timeout,
                    stop_hold=self.params.bus_stop_hold, **settings),
                    on_state_change=self._on_slave_state)
            else:
                link = self.open_link(device, baud)
        except (ProfibusError, OSError, ValueError) as exc:
            self._next_open = now + self.params.reconnect_period
            reason = "cannot open %s: %s%s" % (device, exc, _port_hint(exc))
            if reason != self._reason:
                self._port_missing_since = now
                log.warning("%s (retrying every %.2g s)", reason, self.params.reconnect_period)
            elif now - self._port_missing_since >= PORT_ERROR_AFTER and not self._port_error_logged:
                log.error("%s for %.0f s now (still retrying every %.2g s)", reason,
                          now - self._port_missing_since, self.params.reconnect_period)
            self._port_error_logged = now - self._port_missing_since >= PORT_ERROR_AFTER
            self._down(LinkState.PORT_ERROR, reason)
            return
        self.counters.port_opens += 1
        self._slave_reason = ""
        self._garbage_seen = 0
        if link is not None:
            master = DpMaster(link, self.bus.master_address, self.bus.baud, clock=self.clock,
                              on_state_change=self._on_slave_state, **settings)
        self.health = BusHealth(1.0 / self.bus.cycle_rate_hz, spec.watchdog,
                                scheduling=getattr(master, "scheduling", "") or "in the driver's process")
        self._slave = master.add_slave(spec)
        self._slave.outputs = idle_record(self.params)
        self._master = master
        self._link = link
        if self.stations is not None:
            self.stations.add_slaves(master, self.bus)   # the I/O stations, cycled by the same master
        log.info("opened %s at %d bit/s; bringing slave %d (ident 0x%04X) to Data_Exchange",
                 device, baud, sc.address, sc.ident)
        self._down(LinkState.CONNECTING, "port open, waiting for the controller's PROFIBUS card")

    def close(self) -> None:
        link, master = self._link, self._master
        self._link, self._master, self._slave = None, None, None
        if self.stations is not None:
            self.stations.detach()
        if isinstance(master, BusProcessMaster):
            master.close()
        if link is not None:
            try:
                link.close()
            except Exception:  # closing a dead port may fail; nothing to do about it
                pass

    def fail(self, reason: str) -> None:
        """Drop the link after an internal error: close the port, reopen after the period."""
        self.close()
        self._next_open = self.clock() + self.params.reconnect_period
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
            self._slave_reason = "controller's PROFIBUS card (slave %d): %s" % (
                slave.address, self._explain_failure(slave, reason))
            key = re.sub(r"[0-9]+(\.[0-9]+)?", "#", self._slave_reason)   # not for new numbers
            if key != self._logged_slave_reason:
                self._logged_slave_reason = key
                log.warning("%s", self._slave_reason)
        elif new in connected:
            self._logged_slave_reason = ""

    def _explain_failure(self, slave, reason: str) -> str:
        """The master's reason for ending an attempt, with what it most likely means."""
        diag = slave.last_diag
        sc = self.slave_config
        master = self._master
        garbage = master.counters.garbage_bytes + master.counters.fcs_errors if master is not None else 0
        garbled, self._garbage_seen = garbage > self._garbage_seen, garbage
        if reason.startswith("diag:") and diag is not None:
            if diag.ident != sc.ident:
                hint = ("the station at address %d reports ident 0x%04X, the driver expects 0x%04X "
                        "(another device at this address, or the wrong slave_address?)"
                        % (slave.address, diag.ident, sc.ident))
            elif diag.status1 & DiagStatus1.CFG_FAULT:
                hint = ("the card rejects the configuration %s (%d bytes in / %d out): its modules "
                        "differ from the bus config" % (sc.cfg.hex(" "), slave.spec.input_size,
                                                        slave.spec.output_size))
            elif diag.status1 & DiagStatus1.PRM_FAULT:
                hint = "the card rejects the parameters (Set_Prm: ident, watchdog, user data)"
            else:
                hint = ""
            return "%s%s (diag bytes %s)" % (hint + "; " if hint else "", reason,
                                             diag.encode()[:3].hex(" "))
        if reason.startswith("no reply"):
            if garbled:
                hint = ("bytes arrive but form no valid telegram: wrong baud rate or parity at the "
                        "other end, or a noisy line")
            else:
                hint = ("nothing valid received: is the controller on, the cable connected, the card "
                        "at address %d and %d bit/s?" % (slave.address, self.bus.baud))
            return "%s; %s" % (reason, hint)
        extra = "; diag: %s" % _diag_words(diag) if diag is not None else ""
        return reason + extra
