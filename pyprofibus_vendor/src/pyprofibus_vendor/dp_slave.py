"""DP-V0 slave engine, transport independent, plus servers that bind it to a link.

:class:`DpSlave` is driven by decoded telegrams (:meth:`DpSlave.handle`) and an
injected clock (:meth:`DpSlave.step` checks the watchdog); it never sleeps and
never raises on malformed requests -- it answers them as a slave would.

State machine (``_transition`` logs every change)::

    WAIT_PRM --Set_Prm(Lock, ident ok)--> WAIT_CFG --Chk_Cfg(equal)--> DATA_EXCH
       ^   Set_Prm ident/parameter mismatch: stay, diag Prm_Fault      |
       |   Chk_Cfg mismatch: stay in WAIT_CFG, diag Cfg_Fault          |
       +---- watchdog expired (no telegram from the locking master) ---+
       +---- Set_Prm with Unlock from the locking master --------------+
    a new Set_Prm from the locking master in DATA_EXCH -> WAIT_CFG

Per-state timeouts: WAIT_CFG and DATA_EXCH time out after the Set_Prm
watchdog time (if WD_On) without a valid request from the locking master;
the slave then drops its outputs to the safe image and sets Prm_Req.

Replies: FDL_Status -> SD1 ``OK``/slave; Set_Prm, Chk_Cfg, Set_Slave_Add ->
SC ``E5``; Slave_Diag, Get_Cfg, Rd_Inp, Rd_Outp -> data reply (SAPs swapped,
DL); Data_Exchange -> inputs with DL, or DH when new diagnosis is pending;
default SAP outside DATA_EXCH or from a foreign master, and unknown SAPs -> RS.
Repeated requests (same FCB, FCV=1) get the stored reply and are not executed
again (outputs are not handed to the application twice).

Servers: :class:`SlaveServer` reads telegrams from any :class:`~.phy.Link`
(pty master fd, memory link...) in a loop and writes the replies;
:class:`SlaveLink` is a thread-free in-process link whose ``send`` runs the
slave(s) directly, for deterministic tests with an injected clock.
"""
from __future__ import annotations

import enum
import logging
import threading
import time
from dataclasses import dataclass
from typing import Callable, Dict, Iterable, List, Optional, Sequence, Union

from .dp import (MAX_DIAG_LEN, ChkCfg, DiagStatus1, DiagStatus2, DiagStatus3, GcCommand,
                 GlobalControl, PrmStationStatus, Sap, SetPrm, SetSlaveAdd, SlaveDiag,
                 cfg_io_lengths, reply_frame)
from .errors import DpError, ProfibusError
from .fdl import (BROADCAST, Deframer, FcbResponder, Frame, FrameControl, RequestFunction,
                  RespondingLink, ResponseStatus, Sd1, Sd4, ShortAck)
from .phy import Link

__all__ = ["SlaveState", "SlaveCounters", "DpSlave", "SlaveServer", "SlaveLink"]

log = logging.getLogger(__name__)

Clock = Callable[[], float]


class SlaveState(enum.Enum):
    WAIT_PRM = "WAIT_PRM"
    WAIT_CFG = "WAIT_CFG"
    DATA_EXCH = "DATA_EXCH"


@dataclass
class SlaveCounters:
    requests: int = 0            # valid requests addressed to this slave (incl. broadcast)
    duplicates: int = 0          # repeated requests answered from the stored reply
    data_exchanges: int = 0      # executed Data_Exchange requests
    outputs_delivered: int = 0   # output images handed to the application
    prm_accepted: int = 0
    prm_faults: int = 0
    prm_refused: int = 0         # Set_Prm / Chk_Cfg / Data_Exchange from a foreign master
    cfg_accepted: int = 0
    cfg_faults: int = 0
    watchdog_expiries: int = 0
    global_controls: int = 0
    rejected: int = 0            # answered with RS / UE
    state_changes: int = 0


_SRD = (RequestFunction.SRD_LOW, RequestFunction.SRD_HIGH)
_SDN = (RequestFunction.SDN_LOW, RequestFunction.SDN_HIGH)


class DpSlave:
    """A DP-V0 slave: state machine, diag, process image, watchdog.

    ``cfg`` is the slave's configuration (compared literally with Chk_Cfg);
    ``input_size``/``output_size`` default to what ``cfg`` describes
    (input = slave -> master). The application provides inputs either by
    setting :attr:`inputs` or with ``get_inputs()``; it receives outputs via
    ``on_outputs(bytes)`` and :attr:`outputs`. ``safe_outputs`` (default
    zeros) is delivered when the slave leaves Data_Exchange, on watchdog
    expiry and on Global_Control Clear_Data.
    """

    def __init__(
        self,
        address: int,
        ident: int,
        cfg: bytes,
        *,
        input_size: Optional[int] = None,
        output_size: Optional[int] = None,
        safe_outputs: Optional[bytes] = None,
        clock: Clock = time.monotonic,
        on_outputs: Optional[Callable[[bytes], None]] = None,
        get_inputs: Optional[Callable[[], bytes]] = None,
        prm_check: Optional[Callable[[SetPrm], bool]] = None,
        on_state_change: Optional[Callable[[SlaveState, SlaveState, str], None]] = None,
        address_changeable: bool = False,
    ) -> None:
        if not 0 <= address <= 126:
            raise DpError(f"slave address {address} out of range 0..126")
        if not 0 <= ident <= 0xFFFF:
            raise DpError(f"ident 0x{ident:X} out of range")
        self.cfg = ChkCfg(bytes(cfg)).cfg
        n_in, n_out = cfg_io_lengths(self.cfg)
        self.input_size = n_in if input_size is None else input_size
        self.output_size = n_out if output_size is None else output_size
        self.safe_outputs = bytes(self.output_size) if safe_outputs is None else bytes(safe_outputs)
        if len(self.safe_outputs) != self.output_size:
            raise DpError(f"safe image has {len(self.safe_outputs)} bytes, outputs are "
                          f"{self.output_size}")
        self.address = address
        self.ident = ident
        self.clock = clock
        self.on_outputs = on_outputs
        self.get_inputs = get_inputs
        self.prm_check = prm_check
        self.on_state_change = on_state_change
        self.address_changeable = address_changeable
        self.counters = SlaveCounters()
        self.min_tsdr = 11
        self._lock = threading.RLock()
        self._state = SlaveState.WAIT_PRM
        self._locker: Optional[int] = None
        self._prm: Optional[SetPrm] = None
        self._wd_time: Optional[float] = None
        self._last_master_rx = 0.0
        self._prm_fault = False
        self._cfg_fault = False
        self._stat_diag = False
        self._ext_diag = b""
        self._diag_pending = False
        self._freeze = False
        self._sync = False
        self._frozen_inputs: Optional[bytes] = None
        self._inputs = bytes(self.input_size)
        self._outputs = self.safe_outputs
        self._latest_outputs = self.safe_outputs
        self._fcb = FcbResponder()
        self._sap_handlers: Dict[int, Callable[[Frame, float], Optional[Frame]]] = {
            Sap.SET_PRM: self._on_set_prm,
            Sap.CHK_CFG: self._on_chk_cfg,
            Sap.SLAVE_DIAG: self._on_slave_diag,
            Sap.GET_CFG: self._on_get_cfg,
            Sap.RD_INP: self._on_rd_inp,
            Sap.RD_OUTP: self._on_rd_outp,
            Sap.SET_SLAVE_ADD: self._on_set_slave_add,
        }
        self._timeouts: Dict[SlaveState, Callable[[], Optional[float]]] = {
            SlaveState.WAIT_PRM: lambda: None,
            SlaveState.WAIT_CFG: lambda: self._wd_time,
            SlaveState.DATA_EXCH: lambda: self._wd_time,
        }

    # -- application side ---------------------------------------------------------
    @property
    def state(self) -> SlaveState:
        return self._state

    @property
    def locked_by(self) -> Optional[int]:
        return self._locker

    @property
    def prm(self) -> Optional[SetPrm]:
        """The accepted Set_Prm parameters, if any."""
        return self._prm

    @property
    def watchdog_time(self) -> Optional[float]:
        return self._wd_time

    @property
    def inputs(self) -> bytes:
        """The input image (slave -> master) sent in the next replies."""
        return self._inputs

    @inputs.setter
    def inputs(self, data: bytes) -> None:
        data = bytes(data)
        if len(data) != self.input_size:
            raise DpError(f"input image has {len(data)} bytes, expected {self.input_size}")
        with self._lock:
            self._inputs = data

    @property
    def outputs(self) -> bytes:
        """The output image (master -> slave) last handed to the application."""
        return self._outputs

    def set_diag(self, ext_diag: bytes = b"", stat_diag: bool = False) -> None:
        """Publish new (extended/static) diagnosis: the next Data_Exchange reply is DH."""
        with self._lock:
            ext = bytes(ext_diag)
            self._ext_diag = ext
            self._stat_diag = stat_diag
            self._diag_pending = True

    @property
    def diag_pending(self) -> bool:
        return self._diag_pending

    def diag(self) -> SlaveDiag:
        """The Slave_Diag this slave would answer now."""
        with self._lock:
            s1 = DiagStatus1(0)
            if self._state is not SlaveState.DATA_EXCH:
                s1 |= DiagStatus1.STATION_NOT_READY
            if self._cfg_fault:
                s1 |= DiagStatus1.CFG_FAULT
            if self._prm_fault:
                s1 |= DiagStatus1.PRM_FAULT
            ext = self._ext_diag
            s3 = DiagStatus3(0)
            if 6 + len(ext) > MAX_DIAG_LEN:
                ext = ext[:MAX_DIAG_LEN - 6]
                s3 |= DiagStatus3.EXT_DIAG_OVERFLOW
            if ext:
                s1 |= DiagStatus1.EXT_DIAG
            s2 = DiagStatus2.ALWAYS_ONE
            if self._state is SlaveState.WAIT_PRM:
                s2 |= DiagStatus2.PRM_REQ
            if self._stat_diag:
                s2 |= DiagStatus2.STAT_DIAG
            if self._wd_time is not None and self._state is not SlaveState.WAIT_PRM:
                s2 |= DiagStatus2.WD_ON
            if self._freeze:
                s2 |= DiagStatus2.FREEZE_MODE
            if self._sync:
                s2 |= DiagStatus2.SYNC_MODE
            master = 0xFF if self._locker is None else self._locker
            return SlaveDiag(s1, s2, s3, master, self.ident, ext)

    # -- state machine core --------------------------------------------------------
    def _transition(self, new: SlaveState, reason: str) -> None:
        old = self._state
        if old is new:
            return
        self._state = new
        self.counters.state_changes += 1
        log.info("slave %d: %s -> %s (%s)", self.address, old.value, new.value, reason)
        if new is not SlaveState.DATA_EXCH:
            self._freeze = self._sync = False
            self._frozen_inputs = None
            if old is SlaveState.DATA_EXCH:
                self._deliver(self.safe_outputs)
        if self.on_state_change is not None:
            self.on_state_change(old, new, reason)

    def _deliver(self, outputs: bytes) -> None:
        self._outputs = outputs
        self.counters.outputs_delivered += 1
        if self.on_outputs is not None:
            self.on_outputs(outputs)

    def _unlock(self, reason: str) -> None:
        self._locker = None
        self._wd_time = None
        self._transition(SlaveState.WAIT_PRM, reason)

    def next_deadline(self) -> Optional[float]:
        """Clock time at which :meth:`step` will act next (watchdog), or None."""
        timeout = self._timeouts[self._state]()
        return None if timeout is None else self._last_master_rx + timeout

    def step(self, now: Optional[float] = None) -> None:
        """Advance time: expire the watchdog if the locking master went silent."""
        now = self.clock() if now is None else now
        with self._lock:
            deadline = self.next_deadline()
            if deadline is not None and now > deadline:
                self.counters.watchdog_expiries += 1
                log.warning("slave %d: watchdog (%.3f s) expired without a telegram from "
                            "master %s; outputs safe, waiting for Set_Prm",
                            self.address, self._wd_time, self._locker)
                self._unlock("watchdog expired")

    def handle(self, frame: Frame, now: Optional[float] = None) -> Optional[Frame]:
        """Process one received telegram; return the reply telegram or None."""
        now = self.clock() if now is None else now
        with self._lock:
            self.step(now)
            if isinstance(frame, (Sd4, ShortAck)):
                return None
            if frame.da not in (self.address, BROADCAST) or not frame.fc.request:
                return None
            self.counters.requests += 1
            if frame.sa == self._locker:
                self._last_master_rx = now  # retrigger the watchdog
            func = frame.fc.function
            if func == RequestFunction.FDL_STATUS:
                if frame.da == BROADCAST:
                    return None
                return Sd1(frame.sa, self.address, FrameControl.resp(ResponseStatus.OK))
            if frame.da == BROADCAST or func in _SDN:
                self._on_sdn(frame, now)
                return None
            if func not in _SRD:
                return self._reject(frame, ResponseStatus.RS, f"function {func.name}")
            reply = self._fcb.handle(frame.sa, frame.fc, lambda: self._execute(frame, now))
            self.counters.duplicates = self._fcb.duplicates
            return reply

    # -- services -----------------------------------------------------------------
    def _reject(self, frame: Frame, status: ResponseStatus, why: str) -> Frame:
        self.counters.rejected += 1
        log.debug("slave %d: %s from %d -> %s", self.address, why, frame.sa, status.name)  # type: ignore[union-attr]
        return Sd1(frame.sa, self.address, FrameControl.resp(status))  # type: ignore[union-attr]

    def _execute(self, frame: Frame, now: float) -> Optional[Frame]:
        dsap = getattr(frame, "dsap", None)
        if dsap is None:
            return self._on_data_exchange(frame, now)
        handler = self._sap_handlers.get(dsap)
        if handler is None or getattr(frame, "ssap", None) is None:
            return self._reject(frame, ResponseStatus.RS, f"SAP {dsap}")
        return handler(frame, now)

    def _on_set_prm(self, frame: Frame, now: float) -> Frame:
        master = frame.sa  # type: ignore[union-attr]
        if self._locker not in (None, master):
            self.counters.prm_refused += 1
            log.warning("slave %d: Set_Prm from master %d refused, locked by master %d",
                        self.address, master, self._locker)
            return ShortAck()
        try:
            prm = SetPrm.decode(frame.data)  # type: ignore[union-attr]
        except DpError as err:
            return self._prm_failed(f"malformed Set_Prm: {err}")
        ss = prm.station_status
        if ss & PrmStationStatus.UNLOCK_REQ:
            self._prm = None
            self._unlock(f"unlocked by master {master}")
            return ShortAck()
        if not ss & PrmStationStatus.LOCK_REQ:
            if prm.min_tsdr:
                self.min_tsdr = prm.min_tsdr
            return ShortAck()
        if prm.ident != self.ident:
            return self._prm_failed(f"ident 0x{prm.ident:04X} != own 0x{self.ident:04X}")
        if ss & PrmStationStatus.WD_ON and (prm.wd_fact1 == 0 or prm.wd_fact2 == 0):
            return self._prm_failed("watchdog factor 0")
        if self.prm_check is not None and not self.prm_check(prm):
            return self._prm_failed(f"user parameters {prm.user_prm_data.hex(' ')} rejected")
        self._prm_fault = False
        self._cfg_fault = False
        self._prm = prm
        self._locker = master
        self._wd_time = prm.watchdog_time
        self._last_master_rx = now
        if prm.min_tsdr:
            self.min_tsdr = prm.min_tsdr
        self.counters.prm_accepted += 1
        self._transition(SlaveState.WAIT_CFG, f"parameterised by master {master}")
        return ShortAck()

    def _prm_failed(self, why: str) -> Frame:
        self.counters.prm_faults += 1
        self._prm_fault = True
        log.warning("slave %d: Prm_Fault: %s", self.address, why)
        self._prm = None
        self._unlock("parameter fault")
        return ShortAck()

    def _on_chk_cfg(self, frame: Frame, now: float) -> Frame:
        master = frame.sa  # type: ignore[union-attr]
        if self._locker != master:
            self.counters.prm_refused += 1
            log.warning("slave %d: Chk_Cfg from master %d ignored (locked by %s)",
                        self.address, master, self._locker)
            return ShortAck()
        cfg = bytes(frame.data)  # type: ignore[union-attr]
        if cfg != self.cfg:
            self.counters.cfg_faults += 1
            self._cfg_fault = True
            log.warning("slave %d: Cfg_Fault: got %s, expected %s", self.address,
                        cfg.hex(" ") or "(empty)", self.cfg.hex(" "))
            self._transition(SlaveState.WAIT_CFG, "configuration rejected")
            return ShortAck()
        self._cfg_fault = False
        self.counters.cfg_accepted += 1
        self._transition(SlaveState.DATA_EXCH, "configuration accepted")
        return ShortAck()

    def _on_slave_diag(self, frame: Frame, now: float) -> Frame:
        diag = self.diag()
        self._diag_pending = False
        return reply_frame(frame, self.address, diag.encode())

    def _on_get_cfg(self, frame: Frame, now: float) -> Frame:
        return reply_frame(frame, self.address, self.cfg)

    def _current_inputs(self) -> bytes:
        if self._frozen_inputs is not None:
            return self._frozen_inputs
        if self.get_inputs is not None:
            data = bytes(self.get_inputs())
            if len(data) != self.input_size:
                raise DpError(f"get_inputs() returned {len(data)} bytes, expected "
                              f"{self.input_size}")
            self._inputs = data
        return self._inputs

    def _on_rd_inp(self, frame: Frame, now: float) -> Frame:
        return reply_frame(frame, self.address, self._current_inputs())

    def _on_rd_outp(self, frame: Frame, now: float) -> Frame:
        return reply_frame(frame, self.address, self._outputs)

    def _on_set_slave_add(self, frame: Frame, now: float) -> Frame:
        try:
            req = SetSlaveAdd.decode(frame.data)  # type: ignore[union-attr]
        except DpError as err:
            return self._reject(frame, ResponseStatus.UE, f"malformed Set_Slave_Add: {err}")
        if (not self.address_changeable or self._state is not SlaveState.WAIT_PRM
                or req.ident != self.ident):
            self.counters.prm_refused += 1
            log.warning("slave %d: Set_Slave_Add to %d refused", self.address, req.new_address)
            return ShortAck()
        log.info("slave %d: address changed to %d", self.address, req.new_address)
        self.address = req.new_address
        self.address_changeable = not req.no_add_chg
        self._fcb.forget()
        return ShortAck()

    def _on_sdn(self, frame: Frame, now: float) -> None:
        if (getattr(frame, "dsap", None) != Sap.GLOBAL_CONTROL
                or getattr(frame, "ssap", None) is None):
            return
        if frame.sa != self._locker or self._state is not SlaveState.DATA_EXCH:  # type: ignore[union-attr]
            return
        try:
            gc = GlobalControl.decode(frame.data)  # type: ignore[union-attr]
        except DpError as err:
            log.debug("slave %d: bad Global_Control: %s", self.address, err)
            return
        group = self._prm.group_ident if self._prm is not None else 0
        if not gc.addresses_group(group):
            return
        self.counters.global_controls += 1
        ss = self._prm.station_status if self._prm is not None else PrmStationStatus(0)
        cmd = gc.command
        if cmd & GcCommand.UNSYNC:          # Unsync wins over Sync
            if self._sync:
                self._sync = False
                self._deliver(self._latest_outputs)
        elif cmd & GcCommand.SYNC and ss & PrmStationStatus.SYNC_REQ:
            self._sync = True
            self._deliver(self._latest_outputs)
        if cmd & GcCommand.UNFREEZE:
            self._freeze = False
            self._frozen_inputs = None
        elif cmd & GcCommand.FREEZE and ss & PrmStationStatus.FREEZE_REQ:
            self._freeze = True
            self._frozen_inputs = None
            self._frozen_inputs = self._current_inputs()
        if cmd & GcCommand.CLEAR_DATA:
            self._latest_outputs = self.safe_outputs
            self._deliver(self.safe_outputs)

    def _on_data_exchange(self, frame: Frame, now: float) -> Frame:
        if self._state is not SlaveState.DATA_EXCH or frame.sa != self._locker:  # type: ignore[union-attr]
            return self._reject(frame, ResponseStatus.RS, f"Data_Exchange in {self._state.value}")
        outputs = bytes(getattr(frame, "data", b""))
        if len(outputs) != self.output_size:
            return self._reject(frame, ResponseStatus.UE,
                                f"{len(outputs)} output bytes, expected {self.output_size}")
        self.counters.data_exchanges += 1
        self._latest_outputs = outputs
        if not self._sync:
            self._deliver(outputs)
        inputs = self._current_inputs()
        status = ResponseStatus.DH if self._diag_pending else ResponseStatus.DL
        if not inputs:
            if status == ResponseStatus.DH:
                return Sd1(frame.sa, self.address, FrameControl.resp(status))  # type: ignore[union-attr]
            return ShortAck()
        return reply_frame(frame, self.address, inputs, status)


# -- binding to links ------------------------------------------------------------------

SlaveSet = Union[DpSlave, Sequence[DpSlave]]


def _as_list(slaves: SlaveSet) -> List[DpSlave]:
    return [slaves] if isinstance(slaves, DpSlave) else list(slaves)


def _dispatch(slaves: Iterable[DpSlave], frame: Frame, now: float) -> Optional[Frame]:
    reply = None
    for slave in slaves:
        r = slave.handle(frame, now)
        if r is not None and reply is None:
            reply = r
    return reply


class SlaveLink(RespondingLink):
    """A thread-free in-process link with slave engine(s) at the far end.

    Bytes sent are deframed and handled at once by the slaves (with the
    slaves' own clocks); their replies become readable by :meth:`recv`. When
    nothing is buffered, ``recv`` simply lets the timeout pass (nothing else
    could produce bytes meanwhile); ``timeout=None`` would wait for ever and
    raises :class:`PhyError` instead.
    """

    wait_when_empty = True

    def __init__(self, slaves: SlaveSet) -> None:
        super().__init__("slave link")
        self.slaves = _as_list(slaves)
        if not self.slaves:
            raise DpError("SlaveLink needs at least one slave")

    def respond(self, frame: Frame) -> Optional[bytes]:
        reply = _dispatch(self.slaves, frame, self.slaves[0].clock())
        return None if reply is None else reply.encode()


@dataclass
class ServerCounters:
    frames: int = 0
    replies: int = 0
    idle_discards: int = 0


class SlaveServer:
    """Serve slave engine(s) on a byte link (pty master fd, memory link, serial).

    :meth:`serve` loops until ``stop`` is set: it blocks in ``link.recv``
    (bounded by ``poll`` seconds and the next watchdog deadline), deframes, lets
    the slaves answer and writes the replies. A partial telegram left alone for
    ``idle_reset`` seconds is discarded (the line went idle mid-frame). Input
    is flushed on start (a pty buffers the master's backlog while nobody reads).
    :class:`PhyError` from the link ends the loop and propagates.
    """

    def __init__(self, link: Link, slaves: SlaveSet, *, poll: float = 0.05,
                 idle_reset: float = 0.02, flush_on_start: bool = True,
                 clock: Optional[Clock] = None) -> None:
        self.link = link
        self.slaves = _as_list(slaves)
        if not self.slaves:
            raise DpError("SlaveServer needs at least one slave")
        self.poll = poll
        self.idle_reset = idle_reset
        self.flush_on_start = flush_on_start
        self.clock = clock or self.slaves[0].clock
        self.deframer = Deframer()
        self.counters = ServerCounters()
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None
        self.error: Optional[BaseException] = None

    def serve(self, stop: Optional[threading.Event] = None) -> None:
        stop = stop or self._stop
        if self.flush_on_start:
            self.link.flush_input()
        last_rx = self.clock()
        while not stop.is_set():
            now = self.clock()
            timeout = self.poll
            for slave in self.slaves:
                deadline = slave.next_deadline()
                if deadline is not None:
                    timeout = min(timeout, max(0.0, deadline - now) + 1e-3)
            if self.deframer.pending:
                timeout = min(timeout, max(0.0, last_rx + self.idle_reset - now))
            data = self.link.recv(4096, timeout)
            if not data:
                # bytes that came while this process was not running (recv timed out, then the
                # scheduler kept us off the CPU): read them before judging the watchdog, which
                # must expire only when the master was silent, not when we were
                data = self.link.recv(4096, 0.0)
            now = self.clock()
            if data:
                last_rx = now
                for frame in self.deframer.feed(data):
                    self.counters.frames += 1
                    reply = _dispatch(self.slaves, frame, now)
                    if reply is not None:
                        self.link.send(reply.encode())
                        self.counters.replies += 1
            elif self.deframer.pending and now - last_rx >= self.idle_reset:
                self.counters.idle_discards += 1
                self.deframer.discard_partial()
            for slave in self.slaves:
                slave.step(now)

    def serve_forever(self) -> None:
        self.serve(self._stop)

    def start(self) -> threading.Thread:
        """Run :meth:`serve` in a daemon thread; errors end up in :attr:`error`."""
        def run() -> None:
            try:
                self.serve(self._stop)
            except ProfibusError as err:  # link failure: record and end
                self.error = err
                log.error("slave server stopped: %s", err)
        self._stop.clear()
        self._thread = threading.Thread(target=run, name="dp-slave-server", daemon=True)
        self._thread.start()
        return self._thread

    def stop(self, timeout: float = 2.0) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)
            self._thread = None
