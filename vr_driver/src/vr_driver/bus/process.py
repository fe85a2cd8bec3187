"""The PROFIBUS bus in a process of its own.

The controller's card must hear from the master every cycle, well inside its watchdog (300 ms): at
the watchdog the G2 stops the arm and resets its program. In one Python interpreter with planning,
collision checks, validation and ROS callbacks, a bus thread waits for the interpreter lock behind
C++ calls that hold it for seconds (an OMPL plan); so the serial port and the DP master live here, in
a process that does nothing but cycle the bus.

**The bus process** (``python3 -m vr_driver.bus.process FD``, started by :class:`BusProcessMaster`)
opens the port, runs the :class:`~pyprofibus_vendor.dp_master.DpMaster` at the driver's cycle rate,
and reports every cycle (the slaves' states, state changes, inputs with their arrival times, the
counters, :mod:`~vr_driver.bus.health`) over a socket. It imports only the standard library and
pyprofibus_vendor. Where the system allows it runs with real-time priority (``rt_priority``:
SCHED_FIFO; see doc/reliability.md, "Real-time priority"), else at normal priority, and says which;
it is started, watched and stopped by :mod:`vr_driver.bus.worker`.

**The driver's side** is :class:`BusProcessMaster`, a stand-in for the DpMaster that the link
supervisor (vr_driver.driver.link.link) and the I/O line (vr_driver.driver.link.stations) use unchanged: its
:meth:`~BusProcessMaster.cycle` waits for the bus process's next report or its one wake-up (the
application's ``wake``, which the threads that post to the application set, or where it gives none
the master's own; :meth:`~BusProcessMaster.poke` sets the same) and
replays its state changes through ``on_state_change`` in order, its slaves' ``outputs`` go to the
bus process at once. The driver's loop is paced by the bus (``paced``), not the other way round.

Rules:

- **The bus never waits for the driver** beyond ``answer_wait`` (10 ms). It cycles at its rate with
  the outputs the driver sent last. When a cycle is due at once (a slow line whose cycle fills the
  period, as the thesis' 19.2 kbit/s with the I/O island), it first waits up to ``answer_wait`` for
  the driver's answer to the report it just posted (the driver sends it when it has set its
  outputs for that report), so that a decision made on a report goes out in the next cycle, not
  the one after: otherwise every target, acknowledgement and stop reached the controller a whole
  cycle (62 ms) later than the stepped world, where the driver decides between two cycles. A DP
  master repeats its output image every cycle anyway: a record repeated is never a command
  repeated (the protocols' handshake and sequence numbers count each command once). Reports go out
  through a thread of their own: a driver that does not read them never blocks a cycle (the newest
  report wins; state changes are kept in order).
- **Which record a cycle carried.** Every outputs message has a serial number; each report says
  the serial of the controller's record that its last answered Data_Exchange carried. The driver
  decides a record at each report and, woken by a request, between two reports: one made while a
  cycle was under way is replaced by the next report's before any telegram carried it, and the
  driver learns so from that report (:attr:`RemoteSlave.carried`) -- its stream then offers again
  what that record offered (vr_driver.driver.motion.streaming), instead of going on as if the controller
  could have read it (a stream's START replaced by its next target: the arm stood at point 1).
- **Exactly once across a reset.** When the controller's card leaves Data_Exchange (its watchdog, a
  new Set_Prm), its outputs become the idle record at once, and every outputs message carries the
  Data_Exchange session it was made for: one made before the driver learnt of the new session is
  dropped. The card's first records of a new session are the idle record, until the driver has
  seen the new session and decided anew.
- **The driver dies** (its socket ends) **or falls silent** for ``node_timeout``: the bus process
  sends the controller's stop record (the driver sends it beside each change of the outputs: the
  protocol's stop for what runs, vr_driver.protocol ``stop_record``) for ``stop_hold`` seconds,
  then closes the port and ends; the card's watchdog then makes the outputs safe.
- **The bus process dies**: the driver's next :meth:`~BusProcessMaster.cycle` raises
  :class:`~pyprofibus_vendor.errors.PhyError` naming it; the link supervisor reports a port error
  (robot_status, /diagnostics) and its reconnection starts a new bus process.
"""
from __future__ import annotations

import errno as errno_mod
import logging
import os
import sys
import threading
import time
from dataclasses import replace
from multiprocessing.connection import Connection, wait
from typing import Any, Callable, Dict, List, Optional

from pyprofibus_vendor.adapter import AdapterSetup
from pyprofibus_vendor.dp_master import DpMaster, SlaveHandle, SlaveSpec
from pyprofibus_vendor.errors import DpError, PhyError, ProfibusError
from pyprofibus_vendor.master_api import (CONNECTED_STATES, MasterApi, MasterCounters, MasterSlaveState,
                                          SlaveCounters, SlaveView)
from pyprofibus_vendor.phy import Link

from .health import BusHealth, BusHealthSummary
from .worker import WorkerProcess, child_end, child_scheduling
from .messages import (AddSlave, Answer, BusSettings, Close, CycleAt, Failed, Message, MessageError,
                       OpenFailed, Opened, Outputs, Report, SlaveReport, Start, StateChange, Tick,
                       Channel, bus_channel, driver_channel)

log = logging.getLogger("vr_driver.bus")

__all__ = ["BusSettings", "BusProcessMaster", "PipeWake", "RemoteSlave", "BusServer", "main"]

#: state changes kept for a driver that does not read (the oldest are dropped beyond)
MAX_EVENTS = 1000
#: [s] how often the health summary (a sort of the last minute's gaps) is made
SUMMARY_PERIOD = 1.0


class _NodeGone(Exception):
    """The driver's end of the socket closed, or it fell silent."""


class _Close(Exception):
    """The driver asked the bus process to end."""


class _ReportSender:
    """Sends the reports from a thread of its own: the bus loop never blocks on a driver that does
    not read. The newest report replaces an unsent one; its state changes and a health summary
    it carried go on in the newer one."""

    def __init__(self, channel: Channel) -> None:
        self._channel = channel
        self._cond = threading.Condition()
        self._report: Optional[Report] = None
        self._final: Optional[Message] = None
        self.dropped_events = 0
        self.dead = False
        self._thread = threading.Thread(target=self._run, name="vr_driver-bus-reports", daemon=True)
        self._thread.start()

    def post(self, report: Report) -> None:
        with self._cond:
            unsent = self._report
            if unsent is not None:
                events = unsent.events + report.events
                if len(events) > MAX_EVENTS:
                    self.dropped_events += len(events) - MAX_EVENTS
                    events = events[len(events) - MAX_EVENTS:]
                report = replace(report, events=events, health=report.health or unsent.health,
                                 dropped_events=self.dropped_events)
            self._report = report
            self._cond.notify()

    def final(self, message: Message, timeout: float = 0.5) -> None:
        """Send ``message`` after what is pending, then stop; wait at most ``timeout``."""
        with self._cond:
            self._final = message
            self._cond.notify()
        self._thread.join(timeout)

    def _run(self) -> None:
        while True:
            with self._cond:
                while self._report is None and self._final is None:
                    self._cond.wait()
                report, final = self._report, self._final
                self._report = None
            try:
                if report is not None:
                    self._channel.send(report)
                if final is not None:
                    self._channel.send(final)
                    return
            except (OSError, ValueError, EOFError):
                self.dead = True
                return


class BusServer:
    """The bus process's loop (see the module docstring). ``link``: the open serial link; tests may
    run it in a thread with an in-memory link and a Pipe."""

    def __init__(self, conn: Connection, link: Link, settings: BusSettings, scheduling: str = "",
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.conn = conn
        self.channel = bus_channel(conn)
        self.link = link
        self.settings = settings
        self.clock = clock
        self.master = DpMaster(link, settings.master_address, settings.baud, clock=clock,
                               timing=settings.timing, backoff_max=settings.backoff_max,
                               dx_tolerance=settings.dx_tolerance, retry_steps=settings.retry_steps,
                               on_state_change=self._on_state)
        self.sessions: Dict[int, int] = {}
        self._events: List[StateChange] = []
        self.health = BusHealth(settings.period, settings.watchdog, scheduling=scheduling)
        now = clock()
        self._summary: Optional[BusHealthSummary] = self.health.summary(now)   # None: sent already
        self._summary_at = now
        self._stop_record: Optional[bytes] = None
        self._serials: Dict[int, int] = {}        # per slave: the serial of its outputs now
        self._carried = 0                         # the serial the controller's last answered exchange carried
        self._report_seq = 0                      # the last report posted (its number)
        self._reported_at = now
        self._answered = 0                        # the last report the driver answered
        self.unanswered = 0                       # cycles begun without the answer (answer_wait over)
        self._next = now
        self._last_heard = now
        self._last_reply: Optional[float] = None
        self._sender = _ReportSender(self.channel)
        self._handlers: Dict[type, Callable[..., None]] = {
            Outputs: self._on_outputs, AddSlave: self._on_add_slave, Answer: self._on_answer,
            CycleAt: self._on_cycle_at, Tick: self._on_tick, Close: self._on_close}

    # ------------------------------------------------------------------ the driver's messages
    def _handle(self, msg: Message) -> None:
        handler = self._handlers.get(type(msg))
        if handler is None:
            log.error("bus message %s not expected once the bus runs (ignored)", type(msg).__name__)
            return
        handler(msg)

    def _on_outputs(self, msg: Outputs) -> None:
        address = msg.address
        if address == self.settings.controller:
            if msg.session != self.sessions.get(address):
                return          # made before the driver learnt of this Data_Exchange session
            if msg.stop is not None:
                self._stop_record = msg.stop
        try:
            self.master.slave(address).outputs = msg.data
            self._serials[address] = msg.serial
        except (DpError, ProfibusError) as exc:
            log.error("outputs for slave %d refused: %s", address, exc)

    def _on_add_slave(self, msg: AddSlave) -> None:
        spec = msg.spec
        try:
            handle = self.master.add_slave(spec)
        except ProfibusError as exc:
            log.error("slave %d refused: %s", spec.address, exc)
            return
        self.sessions[spec.address] = 0
        if spec.address == self.settings.controller:
            handle.outputs = self.settings.idle_record

    def _on_answer(self, msg: Answer) -> None:
        self._answered = max(self._answered, msg.seq)

    def _on_cycle_at(self, msg: CycleAt) -> None:
        self._next = min(self._next, float(msg.when))

    def _on_tick(self, msg: Tick) -> None:
        """Only that the driver is alive (heard: _drain notes when)."""

    def _on_close(self, msg: Close) -> None:
        raise _Close()

    def _drain(self) -> None:
        """Every message waiting now; _NodeGone when the driver's end closed. A malformed message
        is logged and changes nothing."""
        try:
            while self.channel.poll(0):
                try:
                    msg = self.channel.recv()
                except MessageError as exc:
                    log.error("%s (ignored)", exc)
                    continue
                self._last_heard = self.clock()
                self._handle(msg)
        except (EOFError, OSError) as exc:
            raise _NodeGone("the driver's end of the bus socket closed (%s)" % (
                type(exc).__name__ if not str(exc) else exc)) from None

    # ------------------------------------------------------------------ the master's events
    def _on_state(self, slave: SlaveHandle, old: MasterSlaveState, new: MasterSlaveState, reason: str) -> None:
        address = slave.address
        if new in CONNECTED_STATES and old not in CONNECTED_STATES:
            self.sessions[address] = self.sessions.get(address, 0) + 1
        elif old in CONNECTED_STATES and new not in CONNECTED_STATES and address == self.settings.controller:
            slave.outputs = self.settings.idle_record      # exactly once across a reset
            self._serials[address] = 0
            self.health.session_ended()
        self._events.append(StateChange(address, old, new, reason, slave.state_since,
                                        self.sessions.get(address, 0)))

    # ------------------------------------------------------------------ the loop
    def run(self) -> int:
        """Cycle until the driver closes (0), dies (2) or the port fails (1)."""
        try:
            while True:
                self._drain()
                if self.clock() - self._last_heard > self.settings.node_timeout:
                    raise _NodeGone("no word from the driver for %.1f s" % (self.clock() - self._last_heard))
                if not self._cycle():
                    return 1
                self._wait()
        except _Close:
            self._end()
            return 0
        except _NodeGone as exc:
            self._stop_arm(str(exc))
            return 2

    def _cycle(self) -> bool:
        serial = self._serials.get(self.settings.controller, 0)   # the record this cycle carries
        try:
            self.master.cycle(timeout=self.settings.cycle_timeout)
        except ProfibusError as exc:
            log.error("serial port %s failed: %s", self.settings.device, exc)
            self._sender.final(Failed("serial port %s failed: %s" % (self.settings.device, exc)))
            self._close_link()
            return False
        now = self.clock()
        try:
            ctrl = self.master.slave(self.settings.controller)
        except ProfibusError:
            ctrl = None
        if ctrl is not None and ctrl.connected and ctrl.inputs_time is not None \
                and ctrl.inputs_time != self._last_reply:
            self._last_reply = ctrl.inputs_time
            self.health.reply(ctrl.inputs_time)
            self._carried = serial
        if now - self._summary_at >= SUMMARY_PERIOD:
            self._summary, self._summary_at = self.health.summary(now), now
        self._report_seq += 1
        self._reported_at = now
        self._sender.post(self._report(now))
        return True

    def _report(self, now: float) -> Report:
        """This cycle's report (the health summary only when it is new; the state changes since the
        last report)."""
        slaves = []
        for address, sessions in self.sessions.items():
            s = self.master.slave(address)
            slaves.append(SlaveReport(address, s.state, s.state_since, sessions, s.inputs, s.inputs_time,
                                      s.last_diag, SlaveCounters(*vars(s.counters).values())))
        events, self._events = tuple(self._events), []
        summary, self._summary = self._summary, None
        return Report(now, self._report_seq, self._carried, MasterCounters(*vars(self.master.counters).values()), tuple(slaves),
                      summary, self._sender.dropped_events, events)

    def _wait(self) -> None:
        """Until the next cycle is due; messages are handled meanwhile (one may bring it forward)."""
        period = self.settings.period
        self._next += period
        now = self.clock()
        if self._next < now:
            self._next = now                    # late: the rate resumes from here
        while True:
            left = self._next - self.clock()
            if left <= 0:
                left = self._reported_at + self.settings.answer_wait - self.clock()
                if self._answered >= self._report_seq:
                    return
                if left <= 0:
                    self.unanswered += 1
                    return
            if self.conn.poll(left):
                self._drain()

    def _stop_arm(self, why: str) -> None:
        """The driver is gone: the stop record for stop_hold, then the end."""
        record = self._stop_record
        log.error("%s: %s, then closing the port (the card's watchdog makes the outputs safe)", why,
                  "sending the controller's stop for %.1f s" % self.settings.stop_hold if record is not None
                  else "nothing was running")
        if record is not None:
            try:
                self.master.slave(self.settings.controller).outputs = record
            except ProfibusError as exc:
                log.error("cannot send the stop record: %s", exc)
            end = self.clock() + self.settings.stop_hold
            while self.clock() < end:
                try:
                    self.master.cycle(timeout=self.settings.cycle_timeout)
                except ProfibusError as exc:
                    log.error("serial port failed while stopping the arm: %s", exc)
                    break
                time.sleep(max(0.0, min(self.settings.period, end - self.clock())))
        self._close_link()

    def _end(self) -> None:
        self._close_link()

    def _close_link(self) -> None:
        try:
            self.link.close()
        except Exception:  # closing a dead port may fail; nothing to do about it
            pass


# ---------------------------------------------------------------------------- the driver's side
class RemoteSlave(SlaveView):
    """The driver's view of one slave of the bus process (a
    :class:`~pyprofibus_vendor.master_api.SlaveView`, as the DpMaster's). Setting :attr:`outputs`
    sends them to the bus process, tagged with the Data_Exchange session they were made in, with
    the :attr:`stop_outputs` for them."""

    def __init__(self, master: "BusProcessMaster", spec: SlaveSpec, now: float) -> None:
        super().__init__(spec, now)
        self._master = master
        self.session = 0                       # the bus process's Data_Exchange session count
        self.serial = 0                             # of the last outputs message sent
        self.carried_serial = 0                     # of the outputs the last answered exchange carried
        self._sent: Optional[tuple] = None          # (session, outputs, stop) sent last

    def _put_outputs(self, data: bytes) -> None:
        self._outputs = data
        sent = (self.session, data, self.stop_outputs)
        if sent != self._sent:
            self._sent = sent
            self.serial += 1
            try:
                self._master.send(Outputs(self.address, self.session, data, self.stop_outputs, self.serial))
            except PhyError:
                pass        # the bus process is gone: the bus thread's next cycle() says so

    @property
    def carried(self) -> bool:
        """The last answered Data_Exchange carried the outputs set last (False: they were set after
        that cycle began; the next one carries them, unless newer ones replace them first)."""
        return self.carried_serial >= self.serial


class PipeWake:
    """A wake-up for a :meth:`BusProcessMaster.cycle` waiting for the next report, where the application
    gives none of its own: a pipe a byte is written to at each :meth:`set` (safe from any thread and
    from a signal handler), read by ``select`` (:meth:`fileno`), emptied by :meth:`clear`."""

    def __init__(self) -> None:
        self._read, self._write = os.pipe()
        os.set_blocking(self._read, False)
        os.set_blocking(self._write, False)

    def set(self) -> None:
        try:
            os.write(self._write, b"!")
        except OSError:
            pass             # a wake is pending already (a full pipe), or closed

    def fileno(self) -> int:
        return self._read

    def clear(self) -> None:
        try:
            while os.read(self._read, 64):
                pass
        except OSError:
            pass

    def close(self) -> None:
        fds, (self._read, self._write) = (self._read, self._write), (-1, -1)    # (a set after it: EBADF)
        for fd in fds:
            try:
                os.close(fd)
            except OSError:
                pass


class BusProcessMaster(MasterApi):
    """The DpMaster stand-in of the driver's side (see the module docstring): the same
    :class:`~pyprofibus_vendor.master_api.MasterApi`. Raises OSError or PhyError with the bus
    process's reason when it cannot open the port."""

    #: the bus keeps its own time: the driver's loop waits in :meth:`cycle`, never a period on top
    paced = True

    def __init__(self, settings: BusSettings,
                 on_state_change: Optional[Callable[..., None]] = None,
                 clock: Callable[[], float] = time.monotonic, start_timeout: float = 10.0,
                 wake: Optional[Any] = None) -> None:
        """``wake``: the application's wake-up (anything with ``set()``, ``fileno()`` readable when
        it was set, and ``clear()``: the driver's inbox's), so that the threads that post to the
        application wake :meth:`cycle` without calling into the master; None: the master's own
        (:class:`PipeWake`). :meth:`poke` sets it: one wake-up either way."""
        self.settings = settings
        self._own_wake = PipeWake() if wake is None else None
        self._wake = wake if wake is not None else self._own_wake
        self.on_state_change = on_state_change
        self.clock = clock
        self.counters = MasterCounters()
        self.health: Optional[BusHealthSummary] = None
        self.scheduling = ""
        self._adapter: Optional[AdapterSetup] = None
        self.reports = 0
        self._slaves: Dict[int, RemoteSlave] = {}
        self._urgent = False
        self._closed = False
        self._report_seq = 0                 # the last report applied
        self._send_lock = threading.Lock()
        # a new interpreter with its end of a socket pair, in a session of its own (bus.worker)
        self._worker = WorkerProcess("vr_driver.bus.process", what="bus process", new_session=True)
        self._conn = self._worker.conn
        self._channel = driver_channel(self._conn)
        try:
            self._channel.send(Start(settings))
            if not self._channel.poll(start_timeout):
                raise PhyError("the bus process did not answer within %.0f s" % start_timeout)
            reply = self._channel.recv()
        except (OSError, EOFError, PhyError) as exc:
            self.close()
            if isinstance(exc, PhyError):
                raise
            raise PhyError("the bus process ended at its start (%s)" % self._exit_status()) from None
        if isinstance(reply, OpenFailed):
            self.close()
            if reply.errno:
                raise OSError(reply.errno, reply.text)
            raise PhyError(reply.text)
        if not isinstance(reply, Opened):
            self.close()
            raise PhyError("the bus process answered its start with %s" % type(reply).__name__)
        self.scheduling = reply.scheduling
        self._adapter = reply.adapter
        log.info("bus process %d: %s on %s at %d bit/s", self.pid, self.scheduling,
                 settings.device, settings.baud)

    @property
    def pid(self) -> int:
        return self._worker.pid

    @property
    def adapter(self) -> Optional[AdapterSetup]:
        """The port's AdapterSetup (pyprofibus_vendor.adapter) as the bus process found it, or None."""
        return self._adapter

    # ------------------------------------------------------------------ what the driver calls
    def add_slave(self, spec: SlaveSpec) -> RemoteSlave:
        slave = RemoteSlave(self, spec, self.clock())
        self._slaves[spec.address] = slave
        self.send(AddSlave(spec))
        return slave

    @property
    def slaves(self) -> List[RemoteSlave]:  # type: ignore[override]
        """Every slave added, in order (as DpMaster.slaves)."""
        return list(self._slaves.values())

    def slave(self, address: int) -> RemoteSlave:
        try:
            return self._slaves[address]
        except KeyError:
            raise DpError("no slave %d configured" % address) from None

    def send(self, message: Message) -> None:
        """One message to the bus process (any thread: set_io sets an I/O station's outputs from a
        service thread while the bus thread sends the controller's; one message at a time)."""
        with self._send_lock:
            if self._closed:
                return
            try:
                self._channel.send(message)
            except (OSError, ValueError):
                raise PhyError("the bus process is gone (%s)" % self._exit_status()) from None

    def poke(self) -> None:
        """Wake a :meth:`cycle` waiting for the next report (a request was posted): sets the wake-up
        (the application's, else the master's own); the cycle after it is asked of the bus process
        at once, with the outputs decided meanwhile."""
        self._wake.set()

    def cycle_at(self, when: float) -> None:
        """Ask for the next bus cycle no later than ``when`` (clock time)."""
        self.send(CycleAt(when))

    def cycle(self, timeout: Optional[float] = None) -> bool:
        """Wait for the bus process's next report (at most ``timeout``) and take every report that
        came: state changes replayed in order, then the slaves' latest state and inputs. Returns
        False when no report came (woken, or the timeout). PhyError when the bus process
        is gone or sent a malformed message."""
        if self._urgent:
            self._urgent = False
            self.send(CycleAt(0.0))
        self.send(Tick())
        woken = self._wake.fileno()
        ready = wait([self._conn, woken], timeout)
        if woken in ready:
            self._wake.clear()
            self._urgent = True
        return self._receive() if self._conn in ready else False

    def close(self) -> None:
        with self._send_lock:
            if self._closed:
                return
            self._closed = True
            try:
                self._channel.send(Close())
            except (OSError, ValueError):
                pass
            self._conn.close()
        self._worker.stop()          # Close sent, EOF: 1 s to end, then SIGTERM, then SIGKILL (bus.worker)
        if self._own_wake is not None:
            self._own_wake.close()

    # ------------------------------------------------------------------ reports
    def _exit_status(self) -> str:
        return self._worker.exit_words()

    def _receive(self) -> bool:
        got = False
        try:
            while self._channel.poll(0):
                msg = self._channel.recv()
                if isinstance(msg, Report):
                    self._apply(msg)
                    got = True
                elif isinstance(msg, Failed):
                    raise PhyError(msg.text)
        except (EOFError, OSError):
            self._worker.wait(0.5)
            raise PhyError("the bus process ended (%s)" % self._exit_status()) from None
        return got

    def answered(self) -> None:
        """The driver has set its outputs for the last report it took: the bus process may begin the
        next cycle (it waits at most ``answer_wait`` for this)."""
        self.send(Answer(self._report_seq))

    def _apply(self, report: Report) -> None:
        self.reports += 1
        self._report_seq = report.seq
        controller = self._slaves.get(self.settings.controller)
        if controller is not None:
            controller.carried_serial = report.carried
        for event in report.events:
            slave = self._slaves.get(event.address)
            if slave is None:
                continue
            slave.state, slave.state_since, slave.session = event.new, event.since, event.session
            if self.on_state_change is not None:
                self.on_state_change(slave, event.old, event.new, event.reason)
        for s in report.slaves:
            slave = self._slaves.get(s.address)
            if slave is None:
                continue
            slave.state, slave.state_since, slave.session = s.state, s.since, s.session
            slave._inputs, slave._inputs_time, slave.last_diag = s.inputs, s.inputs_time, s.diag
            slave.counters = s.counters
        self.counters = report.counters
        if report.health is not None:
            self.health = report.health


# ---------------------------------------------------------------------------- the process
def _open_serial(device: str, baud: int) -> Link:
    from pyprofibus_vendor.phy_serial import SerialLink
    return SerialLink(device, baud)


def main(argv: Optional[List[str]] = None) -> int:
    """The bus process: ``python3 -m vr_driver.bus.process FD`` (FD: its end of the socket)."""
    argv = sys.argv[1:] if argv is None else argv
    logging.basicConfig(level=logging.INFO, stream=sys.stderr,
                        format="[vr_driver bus %(process)d] %(levelname)s %(message)s")
    logging.getLogger("pyprofibus_vendor").setLevel(logging.WARNING)
    conn = child_end(int(argv[0]))      # the driver's Ctrl-C is the driver's: we see it end
    channel = bus_channel(conn)
    try:
        start = channel.recv()
    except (EOFError, OSError):
        return 0
    except MessageError as exc:
        channel.send(OpenFailed("the bus process's start refused: %s" % exc, None))
        return 1
    if not isinstance(start, Start):
        channel.send(OpenFailed("the bus process's first message must be its start, not %s"
                                % type(start).__name__, None))
        return 1
    settings = start.settings
    scheduling = child_scheduling(settings.rt_priority)
    try:
        link = _open_serial(settings.device, settings.baud)
    except (ProfibusError, OSError, ValueError) as exc:
        code = getattr(exc, "errno", None)
        seen = exc.__cause__ or exc.__context__
        if not isinstance(code, int) and seen is not None:
            code = getattr(seen, "errno", None)
        channel.send(OpenFailed(str(exc), code if isinstance(code, int) and code in errno_mod.errorcode else None))
        return 1
    channel.send(Opened(scheduling, link.adapter))
    if not scheduling.startswith("SCHED_FIFO"):
        log.warning("%s", scheduling)
    return BusServer(conn, link, settings, "process %d, %s" % (os.getpid(), scheduling)).run()


if __name__ == "__main__":
    sys.exit(main())
