"""DP master class 1: per-slave state machines over one byte link.

Per slave (``_transition`` logs each change; handlers are in ``_handlers``,
per-state time limits in ``_state_limits``)::

    INIT ---FDL_Status OK---> WAIT_DIAG ---diag---> SET_PRM ---SC---> CHK_CFG ---SC--->
    CHECK_DIAG ---diag ready (no Prm_Req/Cfg_Fault/Prm_Fault, locked by us)---> DATA_EXCHANGE
    CHECK_DIAG ---not ready yet---> CHECK_DIAG (poll again, bounded by the state limit)
    DATA_EXCHANGE ---DH/RDH reply---> DX_DIAG ---diag ready---> DATA_EXCHANGE
    DATA_EXCHANGE ---no reply after the retries, within ``dx_tolerance``---> DATA_EXCHANGE
    any state ---no reply after the retries / RS / fault / state limit---> BACKOFF
    BACKOFF ---back-off time over---> INIT

Noisy lines (both options off by default, as the standard master behaves):

* ``dx_tolerance`` (seconds): a Data_Exchange that gets no valid reply after the retries does
  not end the connection while the last good Data_Exchange reply (or entering Data_Exchange) is
  less than ``dx_tolerance`` ago: the turn ends without new inputs, and the next request
  restarts the frame count (FCV=0) -- after a failed transaction the master cannot know whether
  the slave executed the last request; with FCV=0 the slave executes the next one as new instead
  of answering a "repetition" from its stored reply (stale inputs, outputs not delivered). A
  slave that left Data_Exchange answers RS and is re-initialised at once. So one lost telegram
  no longer drops the slave (and, through the Set_Prm that follows, the application behind it).
* ``retry_steps``: a Slave_Diag, Set_Prm or Chk_Cfg of the start-up sequence without a reply
  after the retries is sent again at the slave's next turn (frame count restarted) instead of
  restarting the whole sequence after a back-off; ``state_limit`` still ends an attempt that
  makes no progress.

Back-off grows with consecutive failed attempts; it starts again from ``backoff_min`` when a
station whose last attempt ended in a missing reply (or a state limit) answers FDL_Status again
-- it is there: a line that comes back is reconnected after a short back-off even after a long
outage. A reply that arrives garbled, with nothing of it left to complete, is repeated after
the idle time (TSYN) instead of after the whole slot time.

Late replies: a reply to an earlier transmission (an earlier request's, held by the adapter past
the next request) is skipped and counted (``late_replies``), not taken for the awaited one: with an
adapter that echoes, a reply counts only behind the request's own echo; the slave's repeat still
owed for a resend (the same bytes as the reply that ended the turn) is counted off; on a timed wire
(``wire_timed``: a serial device, not a pty) a reply read sooner after the request than the wire
allows is an earlier one's (vr_driver/doc/adapters.md, "Late replies").

A *turn* is one transaction with one slave (request, then reply or timeout
after ``max_retry`` repetitions with the same FCB); slaves take turns in
order and a completed round is a *cycle*. Slot time and retry limit come
from the baud rate (:class:`BusTiming`); on a pty or USB adapter software
latency dominates, so the reply timeout never goes below ``reply_timeout_floor``; a USB adapter
whose latency timer the link knows (:attr:`SerialLink.adapter`, pyprofibus_vendor.adapter) holds
each reply up to that long, so the wire time of a transaction is given that much more before a
resend (a 32 ms FTDI timer otherwise had a third of the requests resent at 19.2 kbit/s).

Outputs are latched (the application sets them whenever it likes; every
Data_Exchange sends the latest). Inputs are kept as the last good image
with its timestamp; only replies that passed every check (FCS, ED, LE,
addresses, FC, SAPs, exact length) are delivered.

The core is :meth:`DpMaster.step` (non-blocking, time injected); the
blocking API (:meth:`DpMaster.cycle`, :meth:`DpMaster.run_cycles`,
:meth:`DpMaster.run`) waits in ``link.recv``, a sleep or on an Event, never spinning.
"""
from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, Dict, List, Optional, Tuple

from .dp import (MASTER_SAP, DiagStatus1, DiagStatus2, GcCommand, GlobalControl,
                 Sap, SlaveDiag, explain_diag,
                 global_control_frame, request_frame)
from .errors import ConfigError, DpError, DpTimeoutError, PhyError, ProfibusError
from .fdl import (Deframer, FcbRequester, Frame, FrameControl, RequestFunction, ResponseStatus, Sd1,
                  Sd2, Sd3, ShortAck, StationType, sd2_data, sd2_encode)
from .master_api import (CONNECTED_STATES as _CONNECTED, MasterApi, MasterCounters, MasterSlaveState,
                         SlaveCounters, SlaveView, SlaveSpec)
from .phy import Link

if TYPE_CHECKING:
    from .adapter import AdapterSetup

__all__ = ["BusTiming", "SlaveSpec", "MasterSlaveState", "SlaveCounters", "MasterCounters",
           "SlaveHandle", "AcyclicRequest", "DpMaster"]

log = logging.getLogger(__name__)

# FC bytes of the Data_Exchange fast path (request: SRD high, FCB/FCV added per request; reply: DL)
_FC_SRD_HIGH = FrameControl.req(RequestFunction.SRD_HIGH).encode()
_FC_DL = FrameControl.resp(ResponseStatus.DL).encode()

Clock = Callable[[], float]

# baud -> (slot time, max TSDR) in bit times; IEC 61158 default bus parameters
_SLOT_TABLE = [
    (187_500, 100, 60),
    (500_000, 200, 100),
    (1_500_000, 300, 150),
    (3_000_000, 400, 250),
    (6_000_000, 600, 450),
    (12_000_000, 1000, 800),
]
_RETRY_TABLE = [(1_500_000, 1), (3_000_000, 2), (6_000_000, 3), (12_000_000, 4)]
_SHORT_PAUSE = 0.05   # s: run() sleeps plainly up to this long between cycles
STANDARD_BAUDS = (9600, 19200, 45450, 93750, 187500, 500000, 1500000, 3000000, 6000000,
                  12000000)


@dataclass(frozen=True)
class BusTiming:
    """Bus timing derived from the baud rate (times in bit times)."""

    baud: int
    slot_bits: int
    max_tsdr_bits: int
    max_retry: int
    min_tsdr_bits: int = 11
    tsyn_bits: int = 33

    @classmethod
    def for_baud(cls, baud: int, max_retry: Optional[int] = None) -> "BusTiming":
        if not isinstance(baud, int) or not 9600 <= baud <= 12_000_000:
            raise ConfigError(f"baud {baud!r} outside 9600 .. 12000000")
        slot, tsdr = next((s, t) for top, s, t in _SLOT_TABLE if baud <= top)
        retry = next(r for top, r in _RETRY_TABLE if baud <= top)
        if baud not in STANDARD_BAUDS:
            log.warning("baud %d is not a PROFIBUS standard rate", baud)
        return cls(baud, slot, tsdr, retry if max_retry is None else max_retry)

    def bits(self, n: float) -> float:
        """Seconds for ``n`` bit times."""
        return n / self.baud

    def chars(self, n: int) -> float:
        """Seconds on the wire for ``n`` characters of 11 bits."""
        return n * 11 / self.baud

    @property
    def slot_time(self) -> float:
        return self.bits(self.slot_bits)


_STEP_STATES = (MasterSlaveState.WAIT_DIAG, MasterSlaveState.SET_PRM, MasterSlaveState.CHK_CFG,
                MasterSlaveState.CHECK_DIAG, MasterSlaveState.DX_DIAG)


#: where a telegram's source address is, by its start delimiter (SD1, SD2, SD3)
_SA_AT = {0x10: 2, 0x68: 5, 0xA2: 2}
_STALE_READS = 8    # reads of stale bytes before a request at most (then they are flushed unseen)


@dataclass
class AcyclicRequest:
    """A queued Get_Cfg / Rd_Inp / Rd_Outp, executed in a Data_Exchange turn."""

    sap: Sap
    done: bool = False
    result: Optional[bytes] = None
    error: Optional[ProfibusError] = None


class SlaveHandle(SlaveView):
    """The master's view of one slave (read by the application; :class:`SlaveView` with the
    master's own bookkeeping)."""

    def __init__(self, spec: SlaveSpec, now: float) -> None:
        super().__init__(spec, now)
        self.fcb = FcbRequester()
        self.backoff_until = now
        self.failures = 0           # consecutive failed (re)initialisations
        self.failed_by_timeout = False   # the last failure was a missing reply
        self.dx_ok_time = now       # last good Data_Exchange reply (or entering Data_Exchange)
        self.was_connected = False
        self.jobs: List[AcyclicRequest] = []
        self._lock = threading.Lock()

    def _put_outputs(self, data: bytes) -> None:
        with self._lock:
            self._outputs = data

    def _store_inputs(self, data: bytes, now: float) -> None:
        with self._lock:
            self._inputs = data
            self._inputs_time = now


@dataclass
class _Pending:
    slave: SlaveHandle
    kind: str                 # fdl_status | diag | set_prm | chk_cfg | dx | job
    raw: bytes
    deadline: float
    timeout: float
    retries: int = 0
    job: Optional[AcyclicRequest] = None
    sent: float = 0.0         # when the request (or its last retry) went out
    await_echo: bool = False  # the adapter echoes: a reply counts only after this request's echo
    replies: int = 0          # replies from the slave read while this request awaited its own


def _on_a_wire(link: Link) -> bool:
    """``link`` is a serial device (not a pty, not a URL): its bytes take their time on the wire."""
    return link.adapter is not None and getattr(link, "is_pty", True) is False


def _adapter_latency(link: Link) -> float:
    """[s] the latency timer of the USB adapter under ``link`` where it is known, else 0."""
    ms = link.adapter.latency_timer_ms if link.adapter is not None else None
    return ms / 1000.0 if isinstance(ms, int) and ms > 0 else 0.0


class DpMaster(MasterApi):
    """DP master class 1 on one link (:class:`~pyprofibus_vendor.master_api.MasterApi`).

    Typical use (one slave on a serial device)::

        link = SerialLink("/dev/ttyUSB0", 19200)
        master = DpMaster(link, address=2, baud=19200)
        robot = master.add_slave(SlaveSpec(4, 0x06C6, bytes.fromhex("1313131123232321")))
        robot.outputs = bytes(14)
        master.run_cycles(10)
        print(robot.connected, robot.inputs, master.counters)
    """

    def __init__(self, link: Link, address: int = 2, baud: int = 19200, *,
                 clock: Clock = time.monotonic, timing: Optional[BusTiming] = None,
                 max_retry: Optional[int] = None, reply_timeout_floor: float = 0.05,
                 backoff_min: float = 0.1, backoff_max: float = 1.0,
                 state_limit: float = 1.0, dx_tolerance: float = 0.0, retry_steps: bool = False,
                 wire_timed: Optional[bool] = None,
                 on_state_change: Optional[Callable[[SlaveHandle, MasterSlaveState,
                                                     MasterSlaveState, str], None]] = None
                 ) -> None:
        if not 0 <= address <= 125:
            raise ConfigError(f"master address {address} out of range 0..125")
        self.link = link
        self.address = address
        self.timing = timing or BusTiming.for_baud(baud, max_retry)
        if max_retry is not None and timing is not None:
            self.timing = BusTiming(self.timing.baud, self.timing.slot_bits,
                                    self.timing.max_tsdr_bits, max_retry)
        self.clock = clock
        self.reply_timeout_floor = reply_timeout_floor
        self.rx_latency = _adapter_latency(link)   # [s] the adapter may hold a reply this long
        # a reply read sooner after its request's transmission than the wire allows (the request,
        # TSDR min, the reply) answers an earlier transmission: judged on a link whose bytes take
        # their time on the wire (None: a serial device, not a pty -- a pty has no baud timing)
        self._wire_timed_auto = wire_timed is None
        self.wire_timed = _on_a_wire(link) if wire_timed is None else bool(wire_timed)
        self.backoff_min = backoff_min
        self.backoff_max = backoff_max
        if not dx_tolerance >= 0.0:
            raise ConfigError(f"dx_tolerance {dx_tolerance!r} must be >= 0 seconds")
        self.dx_tolerance = dx_tolerance
        self.retry_steps = retry_steps
        self.on_state_change = on_state_change
        self.counters = MasterCounters()
        self.deframer = Deframer()
        self.slaves: List[SlaveHandle] = []
        self._by_addr: Dict[int, SlaveHandle] = {}
        self._turn = 0
        self._turns = 0               # completed turns (for step() bookkeeping)
        self._pending: Optional[_Pending] = None
        self._gc_queue: List[GlobalControl] = []
        self._sent_in_round = False
        self._round_idle = False
        self._timeouts: Dict[Tuple[int, int], float] = {}   # by request/reply length, for
        self._timeouts_for: Optional[Tuple[BusTiming, float, float]] = None   # these settings
        # telling a late reply to an earlier transmission from the awaited one (_feed): the adapter
        # echoes (an echo was read, and no reply since without one); an echo was read since the last
        # transmission; the replies to a finished turn's later tries that may still come (the
        # slave's repeats of the reply that ended it: its bytes)
        self._echoing = False
        self._echo_since_tx = False
        self._repeats = 0
        self._repeat_of = b""
        self._handlers: Dict[MasterSlaveState, Callable[[SlaveHandle, float], bool]] = {
            MasterSlaveState.INIT: self._do_init,
            MasterSlaveState.WAIT_DIAG: self._do_diag,
            MasterSlaveState.SET_PRM: self._do_set_prm,
            MasterSlaveState.CHK_CFG: self._do_chk_cfg,
            MasterSlaveState.CHECK_DIAG: self._do_diag,
            MasterSlaveState.DATA_EXCHANGE: self._do_data_exchange,
            MasterSlaveState.DX_DIAG: self._do_diag,
            MasterSlaveState.BACKOFF: self._do_backoff,
        }
        self._state_limits: Dict[MasterSlaveState, Optional[float]] = {
            MasterSlaveState.INIT: None,
            MasterSlaveState.WAIT_DIAG: state_limit,
            MasterSlaveState.SET_PRM: state_limit,
            MasterSlaveState.CHK_CFG: state_limit,
            MasterSlaveState.CHECK_DIAG: state_limit,
            MasterSlaveState.DATA_EXCHANGE: None,
            MasterSlaveState.DX_DIAG: state_limit,
            MasterSlaveState.BACKOFF: None,
        }
        self._reply_handlers: Dict[str, Callable[[_Pending, Frame, float], None]] = {
            "fdl_status": self._on_fdl_status,
            "diag": self._on_diag,
            "set_prm": self._on_ack,
            "chk_cfg": self._on_ack,
            "dx": self._on_dx,
            "job": self._on_job,
        }

    # -- configuration / application API -------------------------------------------------
    def add_slave(self, spec: SlaveSpec) -> SlaveHandle:
        if spec.address == self.address or spec.address in self._by_addr:
            raise ConfigError(f"slave address {spec.address} already in use")
        handle = SlaveHandle(spec, self.clock())
        self.slaves.append(handle)
        self._by_addr[spec.address] = handle
        log.info("master %d: slave %d ident 0x%04X cfg %s (%d in / %d out bytes), "
                 "Set_Prm %s", self.address, spec.address, spec.ident, spec.cfg.hex(" "),
                 spec.input_size, spec.output_size, spec.set_prm().encode().hex(" "))
        return handle

    def slave(self, address: int) -> SlaveHandle:
        try:
            return self._by_addr[address]
        except KeyError:
            raise ConfigError(f"no slave {address} configured") from None

    def set_outputs(self, address: int, data: bytes) -> None:
        self.slave(address).outputs = data

    def inputs(self, address: int) -> Tuple[Optional[bytes], Optional[float]]:
        """``(last good inputs, age in seconds)`` of one slave."""
        h = self.slave(address)
        return h.inputs, h.inputs_age(self.clock())

    def global_control(self, command: GcCommand, group_select: int = 0) -> None:
        """Queue a broadcast Global_Control; it goes out before the next turn."""
        self._gc_queue.append(GlobalControl(GcCommand(command), group_select))

    def request(self, address: int, sap: Sap) -> AcyclicRequest:
        """Queue Get_Cfg / Rd_Inp / Rd_Outp; runs in the slave's next DX turn."""
        if sap not in (Sap.GET_CFG, Sap.RD_INP, Sap.RD_OUTP):
            raise ConfigError(f"SAP {sap} is not an acyclic read service")
        job = AcyclicRequest(Sap(sap))
        self.slave(address).jobs.append(job)
        return job

    @property
    def adapter(self) -> Optional[AdapterSetup]:
        return self.link.adapter

    def replace_link(self, link: Link) -> None:
        """Continue on a new link (e.g. a reopened serial port)."""
        self.link = link
        self.rx_latency = _adapter_latency(link)
        if self._wire_timed_auto:
            self.wire_timed = _on_a_wire(link)
        self._pending = None
        self.deframer.reset()
        self._echoing = self._echo_since_tx = False
        self._repeats = 0

    def close(self) -> None:
        self.link.close()

    # -- state machine core -----------------------------------------------------------
    def _transition(self, slave: SlaveHandle, new: MasterSlaveState, reason: str,
                    now: float) -> None:
        old = slave.state
        if old is new:
            return
        slave.state = new
        slave.state_since = now
        slave.counters.state_changes += 1
        self.counters.state_changes += 1
        level = logging.INFO
        if old in _CONNECTED and new not in _CONNECTED:
            slave.counters.losses += 1
            self.counters.losses += 1
            level = logging.WARNING
        if new is MasterSlaveState.DATA_EXCHANGE and old not in _CONNECTED:
            slave.dx_ok_time = now
            if slave.was_connected:
                slave.counters.reconnects += 1
                self.counters.reconnects += 1
            slave.was_connected = True
            slave.failures = 0
        log.log(level, "slave %d: %s -> %s (%s)", slave.address, old.value, new.value, reason)
        if self.on_state_change is not None:
            self.on_state_change(slave, old, new, reason)

    def _fail(self, slave: SlaveHandle, reason: str, now: float, timeout: bool = False) -> None:
        """End the current attempt: back off, then start again at INIT. ``timeout``: it ended
        because a reply was missing (not because the slave refused or reported a fault)."""
        slave.failures += 1
        slave.failed_by_timeout = timeout
        if slave.state is not MasterSlaveState.INIT:
            slave.counters.faults += 1
        delay = 0.0 if slave.state in _CONNECTED else min(
            self.backoff_max, self.backoff_min * 2 ** max(0, slave.failures - 1))
        slave.backoff_until = now + delay
        slave.fcb.reset()
        for job in slave.jobs:
            job.done, job.error = True, DpError(f"slave {slave.address} lost: {reason}")
        slave.jobs.clear()
        self._transition(slave, MasterSlaveState.BACKOFF,
                         f"{reason}; retry in {delay:.2f} s", now)

    def _reply_timeout(self, request_len: int, reply_len: int) -> float:
        if self._timeouts_for != (self.timing, self.reply_timeout_floor, self.rx_latency):  # settings changed
            self._timeouts.clear()
            self._timeouts_for = (self.timing, self.reply_timeout_floor, self.rx_latency)
        key = (request_len, reply_len)
        timeout = self._timeouts.get(key)
        if timeout is None:
            t = self.timing
            wire = t.chars(request_len + reply_len) + t.bits(t.tsyn_bits) + t.slot_time
            timeout = self._timeouts[key] = max(self.reply_timeout_floor, wire + self.rx_latency)
        return timeout

    def _send(self, slave: SlaveHandle, kind: str, raw: bytes, reply_len: int,
              now: float, job: Optional[AcyclicRequest] = None) -> None:
        timeout = self._reply_timeout(len(raw), reply_len)
        self._pending = _Pending(slave, kind, raw, now + timeout, timeout, job=job, sent=now)
        self._transmit(raw)
        slave.counters.requests += 1
        self.counters.requests += 1
        self._sent_in_round = True

    def _transmit(self, raw: bytes) -> None:
        # TSYN: the line must be quiet before a request; drop stale bytes
        self._drop_stale()
        if self._pending is not None:
            # an adapter that echoes reads this transmission back before its reply (the bytes come
            # in line order), so a reply read before that echo answers an earlier transmission --
            # also one of a turn that ended without a reply. One that stops echoing costs one
            # resend: a reply read with no echo at all since the transmission ends the expectation
            self._pending.await_echo = self._echoing
        self._echo_since_tx = False
        self.link.send(raw)

    def _drop_stale(self) -> None:
        """Drop the bytes left unread from earlier turns -- after counting the echoes among them
        (an adapter's read-back of an earlier transmission, behind a late reply that ended its
        turn: the echo is the adapter's, not lost). They are read, not flushed unseen: a burst
        arriving between a read and a flush would go uncounted. The rest (late replies, garbage)
        was never awaited: it is not counted as garbage or as errors."""
        for _ in range(_STALE_READS):
            data = self.link.recv(4096, 0.0)
            if not data:
                break
            kept = vars(self.deframer.counters).copy()
            for frame in self.deframer.feed(data):
                if self._is_echo(frame):
                    self.counters.echoes += 1
                    self._echoing = self._echo_since_tx = True
                else:
                    self._is_repeat(frame)      # a repeat read here cannot be taken for a reply
            vars(self.deframer.counters).update(kept)
        else:
            self.link.flush_input()     # a line that keeps talking: drop the rest unseen
        if self.deframer.pending:
            # an incomplete telegram (the adapter handed over a full USB packet, the rest waits for
            # its timer): the start of an echo when its source address is ours
            head = self.deframer.head(6)
            at = _SA_AT.get(head[0])
            if at is not None and len(head) > at and head[at] & 0x7F == self.address:
                self.counters.echoes += 1
                self._echoing = self._echo_since_tx = True
        self.deframer.reset()

    def _is_echo(self, frame: Frame) -> bool:
        # a request from our own address is one we sent, read back: an adapter that echoes
        # what it transmits (its receiver stays on while it sends) -- usually the request just
        # sent, at the start of its window; a late one (an earlier try's echo held in the adapter
        # past a resend, or behind a reply that ended the turn) too. Not a telegram of another station
        return isinstance(frame, (Sd1, Sd2, Sd3)) and frame.fc.request and frame.sa == self.address

    def _is_repeat(self, frame: Frame) -> bool:
        """``frame`` is one of the slave's repeats still owed for the turn before (a later try's
        reply: the same bytes as the reply that ended that turn); counts it off."""
        if self._repeats and frame.encode() == self._repeat_of:
            self._repeats -= 1
            return True
        return False

    def _end_turn(self) -> None:
        self._pending = None
        self._repeats = 0     # a reply that ended the turn sets them again (_feed)
        self._turns += 1
        self._turn += 1
        if self._turn >= len(self.slaves):
            self._turn = 0
            self.counters.cycles += 1
            self._round_idle = not self._sent_in_round
            self._sent_in_round = False

    def step(self, now: Optional[float] = None) -> float:
        """Do whatever is due at ``now`` without blocking.

        Returns the clock time at which calling again makes sense (``now``
        when there is more to do right away). :class:`PhyError` from the link
        propagates after every slave was marked lost.
        """
        now = self.clock() if now is None else now
        try:
            return self._step(now)
        except PhyError:
            self.counters.phy_errors += 1
            self._pending = None
            for s in self.slaves:
                if s.state is not MasterSlaveState.BACKOFF:
                    self._fail(s, "link failed", now)
            raise

    def _step(self, now: float) -> float:
        turns = self._turns
        if self._pending is not None:   # otherwise the next request flushes the input anyway
            self._poll_rx(now, 0.0)
        if self._turns != turns:
            return now  # a reply completed a turn: let the caller see it first
        if self._pending is not None:
            if now < self._pending.deadline:
                return self._pending.deadline
            self._on_timeout(now)
            return now
        if self._gc_queue:
            gc = self._gc_queue.pop(0)
            self._transmit(global_control_frame(self.address, gc).encode())
            self.counters.global_controls += 1
            log.info("master %d: Global_Control %s group 0x%02X", self.address,
                     gc.command, gc.group_select)
            return now
        if not self.slaves:
            return now + 1.0
        slave = self.slaves[self._turn]
        limit = self._state_limits[slave.state]
        if limit is not None and now - slave.state_since > limit:
            self._fail(slave, f"state {slave.state.value} took longer than {limit} s", now,
                       timeout=True)
            self._end_turn()
            return now
        sent = self._handlers[slave.state](slave, now)
        if not sent:
            self._end_turn()
            if self._turn == 0 and self._round_idle:
                return self.next_wakeup(now)
            return now
        # a request went out: nothing to do before its reply or deadline
        return self._pending.deadline if self._pending is not None else now

    def next_wakeup(self, now: float) -> float:
        """Earliest time something is due (pending deadline, end of a back-off)."""
        if self._pending is not None:
            return self._pending.deadline
        if self._gc_queue:
            return now
        times = [s.backoff_until if s.state is MasterSlaveState.BACKOFF else now
                 for s in self.slaves]
        return max(now, min(times)) if times else now + 1.0

    # -- receiving ------------------------------------------------------------------------
    def _poll_rx(self, now: float, timeout: float) -> None:
        data = self.link.recv(4096, timeout)
        if data:
            self._feed(data, now)

    def _too_early(self, p: _Pending, reply_len: int, read_at: float) -> bool:
        """A reply of ``reply_len`` bytes read at ``read_at`` came sooner after ``p``'s (last)
        transmission than the wire allows: it answers an earlier one (only on a timed wire)."""
        t = self.timing
        return read_at < p.sent + t.chars(len(p.raw) + reply_len) + t.bits(t.min_tsdr_bits)

    def _feed(self, data: bytes, now: float) -> None:
        p = self._pending
        read_at = self.clock() if self.wire_timed else 0.0   # the bytes were here by then
        if (p is not None and p.kind == "dx" and not self.deframer.pending and not p.await_echo
                and not self._repeats
                and not (self.wire_timed and self._too_early(p, len(data), read_at))):
            # the usual good Data_Exchange reply, checked on the raw bytes: SD2 to us from the
            # slave, FC DL (response, slave, no diagnosis), no SAPs, correct framing, FCS and ED;
            # its length is checked on delivery. Anything else -- other lengths, DH, SD1 / SD3 / SC,
            # split or merged chunks, errors, a reply that may answer an earlier transmission (its
            # echo not read yet, a repeat owed) -- takes the general path through the deframer.
            inputs = sd2_data(data, self.address, p.slave.address, _FC_DL)
            if inputs is not None and len(inputs) == (p.slave.spec.input_size or 0):
                self._dx_done(p, inputs, ResponseStatus.DL, now)
                if p.retries > p.replies:   # a later try's reply may still come: a repeat
                    self._repeats, self._repeat_of = p.retries - p.replies, bytes(data)
                return
        garbage = self.deframer.counters.garbage_bytes
        frames = self.deframer.feed(data)
        self.counters.fcs_errors = self.deframer.counters.fcs_errors
        self.counters.garbage_bytes = self.deframer.counters.garbage_bytes
        ended = False
        for frame in frames:
            pending = self._pending
            if self._is_echo(frame):
                self.counters.echoes += 1
                self._echoing = self._echo_since_tx = True
                if pending is not None and pending.await_echo and frame.encode() == pending.raw:
                    # what follows answers this request -- or, from a slave that answered late
                    # (beyond its TSDR), an earlier one: the repeats owed stay owed
                    pending.await_echo = False
                continue
            if ended:
                self._is_repeat(frame)  # after the reply that ended the turn: a later try's reply
                continue                # (not awaited)
            if pending is None:
                self.counters.unexpected_frames += 1
                continue
            if not self._addressed_to_us(pending, frame):
                self.counters.unexpected_frames += 1
                continue
            pending.replies += 1
            if (pending.await_echo or self._is_repeat(frame) or self.wire_timed
                    and self._too_early(pending, len(frame.encode()), read_at)):
                # a reply to an earlier transmission: read before this request's echo, the slave's
                # repeat of the reply that ended the turn before (a later try's, late), or read
                # sooner than the wire allows; taking it would deliver old inputs and advance the
                # FCB on the wrong reply
                self.counters.late_replies += 1
                if not self._echo_since_tx:     # no echo before it: the adapter may have stopped
                    self._echoing = False
                log.debug("slave %d: a late reply to an earlier transmission skipped",
                          pending.slave.address)
                continue
            self._reply_handlers[pending.kind](pending, frame, now)
            # the turn finished: the rest of the chunk is no reply to wait for, but an echo in
            # it (a resend's, read after the first try's late reply) is still counted, and the
            # slave's repeats (replies to the later tries) counted off
            # (one reply a transmission: those of its tries not read yet; a reply skipped in this
            # turn counts as one of them, else a slave whose inputs stay the same would have each
            # fresh reply taken for the repeat owed since a resend, and be resent for ever)
            ended = self._pending is None
            if ended and pending.retries >= pending.replies:
                self._repeats = pending.retries + 1 - pending.replies
                self._repeat_of = frame.encode()
        if self._pending is not None:
            need = self.deframer.bytes_needed()
            if need:  # a reply is arriving: give it time to complete
                extra = self.timing.chars(need) + self.reply_timeout_floor
                self._pending.deadline = max(self._pending.deadline, now + extra)
            elif self.deframer.counters.garbage_bytes != garbage and not self.deframer.pending:
                # a reply came but was garbled and nothing of it is left to complete: repeat
                # after the idle time (TSYN), not after the whole slot time
                idle = max(self.timing.bits(self.timing.tsyn_bits), 0.001)
                self._pending.deadline = min(self._pending.deadline, now + idle)

    def _addressed_to_us(self, pending: _Pending, frame: Frame) -> bool:
        if isinstance(frame, ShortAck):
            return True
        if not isinstance(frame, (Sd1, Sd2, Sd3)):
            return False
        return (not frame.fc.request and frame.da == self.address
                and frame.sa == pending.slave.address)

    def _invalid(self, pending: _Pending, why: str) -> None:
        """A telegram that is not an acceptable reply: ignore it, keep waiting."""
        pending.slave.counters.invalid_replies += 1
        self.counters.invalid_replies += 1
        log.debug("slave %d: ignoring reply: %s", pending.slave.address, why)

    def _on_timeout(self, now: float) -> None:
        p = self._pending
        assert p is not None
        if p.retries < self.timing.max_retry:
            p.retries += 1
            p.slave.counters.retries += 1
            self.counters.retries += 1
            p.deadline = now + p.timeout
            p.sent = now
            self._transmit(p.raw)  # same bytes, same FCB
            return
        p.slave.counters.timeouts += 1
        self.counters.timeouts += 1
        slave = p.slave
        if (p.kind == "dx" and self.dx_tolerance > 0.0
                and now - slave.dx_ok_time < self.dx_tolerance):
            # keep Data_Exchange; restart the frame count (see the module docstring)
            slave.counters.dx_missed += 1
            self.counters.dx_missed += 1
            slave.fcb.reset()
            log.debug("slave %d: no reply to Data_Exchange after %d retries (tolerated, last "
                      "good reply %.3f s ago)", slave.address, p.retries, now - slave.dx_ok_time)
            self._end_turn()
            return
        if self.retry_steps and p.kind in ("diag", "set_prm", "chk_cfg") \
                and slave.state in _STEP_STATES:
            # the station answered FDL_Status: ask again next turn, bounded by the state limit
            slave.fcb.reset()
            log.debug("slave %d: no reply to %s after %d retries; asking again (%s)",
                      slave.address, p.kind, p.retries, slave.state.value)
            self._end_turn()
            return
        if p.job is not None:
            slave.jobs.remove(p.job)
            p.job.done, p.job.error = True, DpTimeoutError(
                f"slave {slave.address}: no reply to {p.job.sap.name}")
        self._pending = None
        what = {"fdl_status": "FDL_Status", "diag": "Slave_Diag", "set_prm": "Set_Prm",
                "chk_cfg": "Chk_Cfg", "dx": "Data_Exchange", "job": "acyclic request"}[p.kind]
        extra = ""
        if p.kind == "dx" and self.dx_tolerance > 0.0:
            extra = f" (no good Data_Exchange reply for {now - slave.dx_ok_time:.2f} s)"
        self._fail(slave, f"no reply to {what} after {p.retries} retries{extra}", now,
                   timeout=True)
        self._end_turn()

    # -- request handlers (one per state) -----------------------------------------------
    def _do_init(self, slave: SlaveHandle, now: float) -> bool:
        slave.fcb.reset()
        frame = Sd1(slave.address, self.address, FrameControl.req(RequestFunction.FDL_STATUS))
        self._send(slave, "fdl_status", frame.encode(), 6, now)
        return True

    def _do_backoff(self, slave: SlaveHandle, now: float) -> bool:
        if now < slave.backoff_until:
            return False
        self._transition(slave, MasterSlaveState.INIT, "back-off over", now)
        return self._do_init(slave, now)

    def _sap_request(self, slave: SlaveHandle, kind: str, sap: Sap, payload: bytes,
                     reply_len: int, now: float, job: Optional[AcyclicRequest] = None) -> bool:
        fcb, fcv = slave.fcb.bits()
        frame = request_frame(slave.address, self.address, fcb, fcv, sap, payload)
        self._send(slave, kind, frame.encode(), reply_len, now, job)
        return True

    def _do_diag(self, slave: SlaveHandle, now: float) -> bool:
        return self._sap_request(slave, "diag", Sap.SLAVE_DIAG, b"", 6 + 2 + 9, now)

    def _do_set_prm(self, slave: SlaveHandle, now: float) -> bool:
        return self._sap_request(slave, "set_prm", Sap.SET_PRM, slave.spec.set_prm().encode(),
                                 1, now)

    def _do_chk_cfg(self, slave: SlaveHandle, now: float) -> bool:
        return self._sap_request(slave, "chk_cfg", Sap.CHK_CFG, slave.spec.cfg, 1, now)

    def _do_data_exchange(self, slave: SlaveHandle, now: float) -> bool:
        if slave.jobs:
            job = slave.jobs[0]
            return self._sap_request(slave, "job", job.sap, b"", 255, now, job)
        self._send(slave, "dx", self._dx_request(slave), (slave.spec.input_size or 0) + 9, now)
        return True

    def _dx_request(self, slave: SlaveHandle) -> bytes:
        """The Data_Exchange request (SRD high, default SAP, the latched outputs) as bytes.

        The SD2 case -- every cycle of the usual slave -- goes straight to the codec
        (:func:`~.fdl.sd2_encode`, the same bytes as ``request_frame(...).encode()`` without
        building frame objects); empty or 8-byte outputs (SD1 / SD3) go through :func:`request_frame`.
        """
        fcb, fcv = slave.fcb.bits()
        data = slave.outputs
        n = len(data)
        if n == 0 or n == 8:
            return request_frame(slave.address, self.address, fcb, fcv, None, data).encode()
        return sd2_encode(slave.address, self.address,
                          _FC_SRD_HIGH | (0x20 if fcb else 0) | (0x10 if fcv else 0), data)

    # -- reply handlers -------------------------------------------------------------------
    def _on_fdl_status(self, p: _Pending, frame: Frame, now: float) -> None:
        if not isinstance(frame, Sd1):
            return self._invalid(p, f"FDL_Status answered with {type(frame).__name__}")
        slave = p.slave
        self._pending = None
        if frame.fc.status != ResponseStatus.OK or frame.fc.station_type != StationType.SLAVE:
            self._fail(slave, f"FDL_Status reply {frame.fc} (not a ready slave)", now)
        else:
            if slave.failed_by_timeout:     # it answers again: back off briefly from now on
                slave.failures = 0
                slave.failed_by_timeout = False
            self._transition(slave, MasterSlaveState.WAIT_DIAG, "station answers FDL_Status",
                             now)
        self._end_turn()

    def _sap_reply_data(self, p: _Pending, frame: Frame, sap: int) -> Optional[bytes]:
        """The payload of a good SAP data reply, or None (counted as invalid)."""
        if not isinstance(frame, (Sd2, Sd3)):
            self._invalid(p, f"{type(frame).__name__} instead of a data reply")
            return None
        if frame.fc.status not in (ResponseStatus.DL, ResponseStatus.DH,
                                   ResponseStatus.RDL, ResponseStatus.RDH):
            self._invalid(p, f"reply status {frame.fc}")
            return None
        if frame.dsap != MASTER_SAP or frame.ssap != sap:
            self._invalid(p, f"reply SAPs {frame.dsap}/{frame.ssap}, expected {MASTER_SAP}/{sap}")
            return None
        return frame.data

    def _refused(self, p: _Pending, frame: Frame, now: float) -> bool:
        """An SD1 negative reply (RS/UE/RR/NR...) ends the attempt."""
        if isinstance(frame, Sd1) and frame.fc.status not in (ResponseStatus.OK,):
            slave = p.slave
            self._pending = None
            slave.fcb.acknowledge()
            self._fail(slave, f"{p.kind} refused by the slave ({frame.fc})", now)
            self._end_turn()
            return True
        return False

    def _on_diag(self, p: _Pending, frame: Frame, now: float) -> None:
        if self._refused(p, frame, now):
            return
        data = self._sap_reply_data(p, frame, Sap.SLAVE_DIAG)
        if data is None:
            return
        try:
            diag = SlaveDiag.decode(data)
        except DpError as err:
            return self._invalid(p, f"bad diag: {err}")
        slave = p.slave
        self._pending = None
        slave.fcb.acknowledge()
        slave.counters.diag_reads += 1
        if diag != slave.last_diag:
            log.info("slave %d diag: %s", slave.address, explain_diag(diag, self.address))
            if diag.ident != slave.spec.ident:      # once per change, not on every read
                log.error("slave %d reports ident 0x%04X, configured 0x%04X", slave.address,
                          diag.ident, slave.spec.ident)
        slave.last_diag = diag
        foreign = diag.locked_by not in (None, self.address)
        state = slave.state
        if foreign and not diag.status2 & DiagStatus2.PRM_REQ:
            self._fail(slave, f"locked by another master ({diag.master_address})", now)
        elif state is MasterSlaveState.WAIT_DIAG:
            self._transition(slave, MasterSlaveState.SET_PRM, "diag read", now)
        elif diag.ready_for(self.address):
            self._transition(slave, MasterSlaveState.DATA_EXCHANGE, "slave ready", now)
        elif (diag.status1 & (DiagStatus1.PRM_FAULT | DiagStatus1.CFG_FAULT
                              | DiagStatus1.NOT_SUPPORTED)
              or diag.status2 & DiagStatus2.PRM_REQ or diag.locked_by != self.address
              or state is MasterSlaveState.DX_DIAG
              and diag.status1 & DiagStatus1.STATION_NOT_READY):
            self._fail(slave, "diag: " + "; ".join(diag.words(self.address)), now)
        # else: not ready yet / static diag -> read diag again next turn
        self._end_turn()

    def _on_ack(self, p: _Pending, frame: Frame, now: float) -> None:
        if self._refused(p, frame, now):
            return
        if not isinstance(frame, (ShortAck, Sd1)):
            return self._invalid(p, f"{type(frame).__name__} instead of an acknowledgement")
        slave = p.slave
        self._pending = None
        slave.fcb.acknowledge()
        if p.kind == "set_prm":
            self._transition(slave, MasterSlaveState.CHK_CFG, "Set_Prm acknowledged", now)
        else:
            self._transition(slave, MasterSlaveState.CHECK_DIAG, "Chk_Cfg acknowledged", now)
        self._end_turn()

    def _on_dx(self, p: _Pending, frame: Frame, now: float) -> None:
        slave = p.slave
        n_in = slave.spec.input_size or 0
        if isinstance(frame, ShortAck):
            if n_in:
                return self._invalid(p, "short ack instead of input data")
            status = ResponseStatus.DL
            data = b""
        elif isinstance(frame, Sd1):
            status = frame.fc.status
            if status not in (ResponseStatus.DL, ResponseStatus.DH, ResponseStatus.OK):
                self._refused(p, frame, now)
                return
            if n_in:
                return self._invalid(p, "no input data in the reply")
            data = b""
        else:
            assert isinstance(frame, (Sd2, Sd3))
            status = frame.fc.status
            if frame.dsap is not None or frame.ssap is not None:
                return self._invalid(p, "Data_Exchange reply with SAPs")
            if status not in (ResponseStatus.DL, ResponseStatus.DH, ResponseStatus.RDL,
                              ResponseStatus.RDH):
                return self._invalid(p, f"Data_Exchange reply status {frame.fc}")
            if len(frame.data) != n_in:
                return self._invalid(p, f"{len(frame.data)} input bytes, expected {n_in}")
            data = frame.data
        self._dx_done(p, data, status, now)

    def _dx_done(self, p: _Pending, data: bytes, status: ResponseStatus, now: float) -> None:
        """A good Data_Exchange reply: deliver the inputs, end the turn."""
        slave = p.slave
        self._pending = None
        # the reply's time beyond both telegrams' time on the wire (9 characters of SD2 framing)
        self.counters.dx_timed += 1
        self.counters.reply_wait += max(0.0, now - p.sent - self.timing.chars(len(p.raw) + len(data) + 9))
        slave.fcb.acknowledge()
        slave._store_inputs(data, now)
        slave.dx_ok_time = now
        slave.counters.data_exchanges += 1
        if status in (ResponseStatus.DH, ResponseStatus.RDH):
            self._transition(slave, MasterSlaveState.DX_DIAG, "slave signals new diagnosis",
                             now)
        self._end_turn()

    def _on_job(self, p: _Pending, frame: Frame, now: float) -> None:
        job = p.job
        assert job is not None
        if isinstance(frame, Sd1) and frame.fc.status != ResponseStatus.OK:
            self._pending = None
            p.slave.fcb.acknowledge()
            p.slave.jobs.remove(job)
            job.done, job.error = True, DpError(f"{job.sap.name} refused ({frame.fc})")
            self._end_turn()
            return
        data = self._sap_reply_data(p, frame, job.sap)
        if data is None:
            return
        self._pending = None
        p.slave.fcb.acknowledge()
        p.slave.jobs.remove(job)
        job.done, job.result = True, bytes(data)
        self._end_turn()

    # -- blocking API -----------------------------------------------------------------------
    def _wait(self, until: float) -> None:
        """Block until bytes arrive or ``until`` (clock time) passes."""
        left = until - self.clock()
        if left > 0:
            data = self.link.recv(4096, left)
            if data:
                self._feed(data, self.clock())

    def cycle(self, timeout: Optional[float] = None) -> bool:
        """Run until every slave had one turn (one bus cycle). Blocks in the link.

        If nothing was sent in the round (all slaves backing off) it also waits
        for the earliest back-off end, so a loop of cycles never spins. Returns
        False if ``timeout`` seconds passed first.
        """
        start = self.clock()
        end = None if timeout is None else start + timeout
        target = self.counters.cycles + 1
        while self.counters.cycles < target:
            now = self.clock()
            if end is not None and now >= end:
                return False
            wake = self.step(now)
            if wake > now:
                self._wait(wake if end is None else min(wake, end))
        if self._round_idle:
            now = self.clock()
            wake = self.next_wakeup(now)
            self._wait(wake if end is None else min(wake, end))
        return True

    def run_cycles(self, n: int, on_cycle: Optional[Callable[["DpMaster"], None]] = None
                   ) -> None:
        for _ in range(n):
            self.cycle()
            if on_cycle is not None:
                on_cycle(self)

    def run(self, period: float, stop: threading.Event,
            on_cycle: Optional[Callable[["DpMaster"], None]] = None) -> None:
        """Fixed-rate loop: one cycle every ``period`` seconds until ``stop`` is set.

        ``stop`` is checked before every cycle. Pauses of up to 50 ms (typical bus
        periods) are plain sleeps, so a stop set meanwhile takes effect at the next cycle
        boundary (Event.wait runs threading.Condition's Python code and allocates a lock
        on every call, a measurable share of a 100 Hz loop's CPU); longer pauses end as
        soon as ``stop`` is set.
        """
        next_start = self.clock()
        while not stop.is_set():
            self.cycle(timeout=max(period, 1.0))
            if on_cycle is not None:
                on_cycle(self)
            next_start += period
            now = self.clock()
            if next_start < now:
                self.counters.overruns += 1
                next_start = now
            elif next_start - now <= _SHORT_PAUSE:
                time.sleep(next_start - now)
            else:
                stop.wait(next_start - now)

    def wait_for(self, job: AcyclicRequest, timeout: float = 2.0) -> bytes:
        """Run cycles until ``job`` is done; return its data or raise its error."""
        end = self.clock() + timeout
        while not job.done:
            if self.clock() >= end:
                raise DpTimeoutError(f"{job.sap.name} not done within {timeout} s")
            self.cycle(timeout=max(0.0, end - self.clock()))
        if job.error is not None:
            raise job.error
        assert job.result is not None
        return job.result

    def get_cfg(self, address: int, timeout: float = 2.0) -> bytes:
        return self.wait_for(self.request(address, Sap.GET_CFG), timeout)

    def read_inputs(self, address: int, timeout: float = 2.0) -> bytes:
        return self.wait_for(self.request(address, Sap.RD_INP), timeout)

    def read_outputs(self, address: int, timeout: float = 2.0) -> bytes:
        return self.wait_for(self.request(address, Sap.RD_OUTP), timeout)

    def wait_connected(self, address: int, timeout: float = 5.0) -> bool:
        """Run cycles until the slave is in Data_Exchange (True) or timeout (False)."""
        end = self.clock() + timeout
        slave = self.slave(address)
        while not slave.connected:
            left = end - self.clock()
            if left <= 0:
                return False
            self.cycle(timeout=left)
        return True

