"""What an application needs of a DP master and of its slaves, whichever master it is.

The :class:`~pyprofibus_vendor.dp_master.DpMaster` of this package cycles the bus in the
application's own process; an application may also put the bus in a process of its own and keep a
stand-in for the master on its side (vr_driver's bus process does). Both implement
:class:`MasterApi`, and their slaves are :class:`SlaveView` objects, so an application never asks which
one it has:

* :class:`SlaveView` -- one slave as the application sees it: its spec, state (and since when),
  counters, last diagnosis, the latched outputs (checked against the spec's length), the last good
  inputs with their arrival time, whether the outputs set last were carried by the last answered
  Data_Exchange (:attr:`~SlaveView.carried`), and the record that stops what the outputs set going
  (:attr:`~SlaveView.stop_outputs`, sent by a master that outlives its application);
* :class:`MasterApi` -- the master: its slaves, counters, one :meth:`~MasterApi.cycle`, and what
  only a master that keeps its own time does (:attr:`~MasterApi.paced`, :meth:`~MasterApi.poke`,
  :meth:`~MasterApi.cycle_at`, :meth:`~MasterApi.answered`, :attr:`~MasterApi.health`): a master in
  the application's process takes them as nothing to do.

The states and counters both report are defined here too.
"""
from __future__ import annotations

import enum
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable, List, Optional

from .dp import ChkCfg, PrmStationStatus, SetPrm, cfg_io_lengths, watchdog_factors
from .errors import ConfigError, DpError

if TYPE_CHECKING:
    from .adapter import AdapterSetup
    from .dp import SlaveDiag

__all__ = ["MasterSlaveState", "SlaveCounters", "MasterCounters", "SlaveSpec", "SlaveView", "MasterApi",
           "CONNECTED_STATES"]


class MasterSlaveState(enum.Enum):
    INIT = "INIT"                    # FDL_Status request
    WAIT_DIAG = "WAIT_DIAG"          # first Slave_Diag
    SET_PRM = "SET_PRM"
    CHK_CFG = "CHK_CFG"
    CHECK_DIAG = "CHECK_DIAG"        # Slave_Diag after Chk_Cfg
    DATA_EXCHANGE = "DATA_EXCHANGE"
    DX_DIAG = "DX_DIAG"              # Slave_Diag fetched after a DH reply
    BACKOFF = "BACKOFF"              # waiting before re-initialisation


CONNECTED_STATES = (MasterSlaveState.DATA_EXCHANGE, MasterSlaveState.DX_DIAG)
@dataclass
class SlaveCounters:
    requests: int = 0
    retries: int = 0
    timeouts: int = 0           # transactions without a valid reply after all retries
    invalid_replies: int = 0    # valid telegrams that were not an acceptable reply
    data_exchanges: int = 0     # good Data_Exchange replies
    diag_reads: int = 0
    losses: int = 0             # left Data_Exchange
    reconnects: int = 0         # came back to Data_Exchange after a loss
    state_changes: int = 0
    faults: int = 0             # init attempts ended by a fault or time limit
    dx_missed: int = 0          # Data_Exchange turns without a reply, tolerated (dx_tolerance)


@dataclass
class MasterCounters:
    cycles: int = 0
    requests: int = 0
    retries: int = 0
    timeouts: int = 0
    invalid_replies: int = 0
    unexpected_frames: int = 0  # telegrams read while nothing was awaited (bytes still
    # unread when the next request goes out are dropped uncounted but for echoes: TSYN, _drop_stale)
    reconnects: int = 0
    losses: int = 0
    state_changes: int = 0
    global_controls: int = 0
    phy_errors: int = 0
    overruns: int = 0           # fixed-rate loop cycles that started late
    fcs_errors: int = 0         # copied from the deframer
    garbage_bytes: int = 0      # copied from the deframer
    dx_missed: int = 0          # Data_Exchange turns without a reply, tolerated (dx_tolerance)
    echoes: int = 0             # requests from our own address read back: an RS-485 adapter that
    #                             echoes its transmission (skipped)
    dx_timed: int = 0           # good Data_Exchange replies timed (reply_wait below)
    reply_wait: float = 0.0     # [s] their summed time beyond the telegrams' time on the wire:
    #                             the station's delay plus what the adapter held them back
    late_replies: int = 0       # replies to an earlier transmission read while a request awaited
    #                             its own (before its echo, or the slave's repeat of the reply
    #                             before): skipped, not taken as its reply


@dataclass(frozen=True)
class SlaveSpec:
    """What the master needs to know about one slave.

    ``watchdog`` (seconds, None = off) becomes WD_Fact_1/2; sizes default to
    what ``cfg`` describes (input = slave -> master).
    """

    address: int
    ident: int
    cfg: bytes
    input_size: Optional[int] = None
    output_size: Optional[int] = None
    watchdog: Optional[float] = 0.3
    user_prm_data: bytes = b""
    group_ident: int = 0
    min_tsdr: int = 0
    sync_req: bool = False
    freeze_req: bool = False

    def __post_init__(self) -> None:
        if not 0 <= self.address <= 125:
            raise ConfigError(f"slave address {self.address} out of range 0..125")
        if not 0 <= self.ident <= 0xFFFF:
            raise ConfigError(f"ident 0x{self.ident:X} out of range")
        try:
            cfg = ChkCfg(bytes(self.cfg)).cfg
            n_in, n_out = cfg_io_lengths(cfg)
        except DpError as err:
            raise ConfigError(f"slave {self.address}: bad cfg: {err}") from err
        object.__setattr__(self, "cfg", cfg)
        object.__setattr__(self, "user_prm_data", bytes(self.user_prm_data))
        if self.input_size is None:
            object.__setattr__(self, "input_size", n_in)
        if self.output_size is None:
            object.__setattr__(self, "output_size", n_out)
        if self.watchdog is not None:
            watchdog_factors(self.watchdog)  # validates the range

    @classmethod
    def from_config(cls, slave: "Any") -> "SlaveSpec":
        """The spec of a :class:`~.config.SlaveConfig` (its Cfg, lengths, watchdog, Set_Prm
        settings); ``watchdog_ms`` None or 0 = watchdog off."""
        return cls(slave.address, slave.ident, slave.cfg, input_size=slave.input_len,
                   output_size=slave.output_len,
                   watchdog=slave.watchdog_ms / 1000.0 if slave.watchdog_ms else None,
                   user_prm_data=slave.user_prm_data, group_ident=slave.group_mask,
                   sync_req=slave.sync, freeze_req=slave.freeze)

    def set_prm(self) -> SetPrm:
        status = PrmStationStatus.LOCK_REQ
        f1 = f2 = 1
        if self.watchdog is not None:
            status |= PrmStationStatus.WD_ON
            f1, f2 = watchdog_factors(self.watchdog)
        if self.sync_req:
            status |= PrmStationStatus.SYNC_REQ
        if self.freeze_req:
            status |= PrmStationStatus.FREEZE_REQ
        return SetPrm(self.ident, status, f1, f2, self.min_tsdr, self.group_ident,
                      self.user_prm_data)


class SlaveView:
    """One slave as the application sees it (see the module docstring). Setting :attr:`outputs`
    checks their length and hands them to :meth:`_put_outputs`, the master's own way of taking
    them."""

    def __init__(self, spec: "SlaveSpec", now: float) -> None:
        self.spec = spec
        self.address = spec.address
        self.state = MasterSlaveState.INIT
        self.state_since = now
        self.counters = SlaveCounters()
        self.last_diag: Optional["SlaveDiag"] = None
        #: the record that stops what :attr:`outputs` set going (None: nothing runs); a master in a
        #: process of its own sends it when its application dies, one in the application's ignores it
        self.stop_outputs: Optional[bytes] = None
        self._outputs = bytes(spec.output_size or 0)
        self._inputs: Optional[bytes] = None
        self._inputs_time: Optional[float] = None
        #: a master in a process of its own numbers the output images it is given: the serial of the
        #: one set last, and of the one its last answered Data_Exchange carried (None: a master in the
        #: application's thread, whose cycle carries every image it was given before it began)
        self.serial: Optional[int] = None
        self.carried_serial: Optional[int] = None

    @property
    def connected(self) -> bool:
        """True while the slave is in Data_Exchange (or fetching diag from it)."""
        return self.state in CONNECTED_STATES

    @property
    def outputs(self) -> bytes:
        """The latched output image sent in every Data_Exchange."""
        return self._outputs

    @outputs.setter
    def outputs(self, data: bytes) -> None:
        data = bytes(data)
        if len(data) != self.spec.output_size:
            raise DpError(f"slave {self.address}: {len(data)} output bytes, expected "
                          f"{self.spec.output_size}")
        self._put_outputs(data)

    def _put_outputs(self, data: bytes) -> None:
        self._outputs = data

    @property
    def carried(self) -> bool:
        """The last answered Data_Exchange carried the outputs set last (a master cycling in the
        application's own thread: always, it sends what was set before the cycle began)."""
        return True

    @property
    def inputs(self) -> Optional[bytes]:
        """Last good input image, or None before the first one."""
        return self._inputs

    @property
    def inputs_time(self) -> Optional[float]:
        """Clock time when :attr:`inputs` arrived."""
        return self._inputs_time

    def inputs_age(self, now: float) -> Optional[float]:
        return None if self._inputs_time is None else now - self._inputs_time


class MasterApi(ABC):
    """A DP master as an application drives it (see the module docstring)."""

    #: True: the master keeps the bus's time itself (:meth:`cycle` waits for its next cycle; the
    #: caller must not sleep a period on top)
    paced = False
    #: how the bus is scheduled, in words ("": in the application's process, as it is)
    scheduling = ""
    #: the bus's health as the master measures it itself (a master in a process of its own does;
    #: its type is that process's), None where the application measures it
    health: Optional[object] = None
    slaves: List[SlaveView]
    counters: MasterCounters
    #: called with (slave, old state, new state, reason) at each state change of a slave
    on_state_change: Optional[Callable[[SlaveView, MasterSlaveState, MasterSlaveState, str], None]]

    @property
    def adapter(self) -> Optional["AdapterSetup"]:
        """The USB adapter under the port (pyprofibus_vendor.adapter), None where unknown."""
        return None

    @abstractmethod
    def add_slave(self, spec: "SlaveSpec") -> SlaveView:
        """Configure one more slave; its handle."""

    @abstractmethod
    def slave(self, address: int) -> SlaveView:
        """The handle of a configured slave (DpError when there is none)."""

    @abstractmethod
    def cycle(self, timeout: Optional[float] = None) -> bool:
        """One bus cycle (or, paced, the next one the master ran); False when ``timeout`` passed
        first (or, paced, a :meth:`poke` woke it). PhyError when the port or the bus is gone."""

    @abstractmethod
    def close(self) -> None:
        """Close the port (or end the bus process). Idempotent."""

    def poke(self) -> None:
        """Wake a :meth:`cycle` waiting for the next cycle (safe from any thread and from a signal
        handler). Nothing to do where the caller's thread runs the cycles."""

    def cycle_at(self, when: float) -> None:
        """Ask for the next cycle no later than ``when`` (clock time); nothing where the caller's
        thread runs the cycles."""

    def answered(self) -> None:
        """The application has set its outputs for the last cycle it took: a paced master may begin
        the next one. Nothing where the caller's thread runs the cycles."""
