"""Supervision of the I/O stations on the line (islands, PLCs beside the controller), stepped by the
bus loop. ROS-free.

:class:`IoLine` keeps, for every station of a :class:`~vr_driver.io_signals.SignalMap`, the state the
ROS interface shows (``io_states``, ``get_io``, ``/diagnostics``) and the output image the master
sends to it. It does not own the master: the bus loop's :class:`~pyprofibus_vendor.dp_master.DpMaster`
cycles every station on the one port (:meth:`IoLine.add_slaves` adds the stations' specs from the bus
configuration, :meth:`IoLine.attach` takes their handles; :meth:`IoLine.detach` when the port closes),
and after every cycle :meth:`IoLine.update` judges each station and returns an immutable
:class:`IoSnapshot`.

Rules (doc/io_line.md "Faults"):

- a station is *online* only while the master has it in Data_Exchange and its last good inputs are
  from this Data_Exchange session and at most ``input_timeout`` old; while it is not online every one
  of its signals reads None (an old value is never shown as live);
- a station going offline (leaving Data_Exchange -- at once, from the master's state change -- or
  inputs older than ``input_timeout``) is a *loss*: its output image falls back to the signals' safe
  values and stays there after the station returns, until a write sets an output again;
- :meth:`IoLine.write` is refused, with the reason and nothing changed, for an unknown name, an
  input signal, a value that does not fit the signal's type, or a station that is not online; a
  refused write is never kept to be sent later. An accepted write is in the image the master sends
  in its next Data_Exchange with the station.

Threads: the bus loop calls :meth:`update` / :meth:`attach` / :meth:`detach`; :meth:`write`,
:meth:`read` and :meth:`snapshot` may be called from any thread (service handlers).
"""
from __future__ import annotations

import logging
import threading
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, Optional, Tuple

from pyprofibus_vendor.dp import DiagStatus1, explain_diag
from pyprofibus_vendor.dp_master import SlaveSpec
from pyprofibus_vendor.master_api import MasterApi, MasterSlaveState, SlaveView

from ...errors import SignalMapError
from ...io_signals import CONTROLLER_IO_LENGTH, Signal, SignalMap, StationSignals, Value

log = logging.getLogger("vr_driver.driver")

__all__ = ["SignalState", "StationState", "IoSnapshot", "IoResult", "IoLine", "ControllerIo",
           "CONTROLLER_IO_LENGTH"]

_CONNECTED = (MasterSlaveState.DATA_EXCHANGE, MasterSlaveState.DX_DIAG)


@dataclass(frozen=True)
class SignalState:
    """One signal in a snapshot: ``value`` None while its station is offline."""

    name: str
    station: str
    direction: str
    type: str
    value: Optional[Value]
    online: bool

    @property
    def text(self) -> str:
        """The value as text (``get_io`` / ``io_states``), "" while offline."""
        if self.value is None:
            return ""
        return repr(float(self.value)) if self.type == "float32" else str(int(self.value))


@dataclass(frozen=True)
class StationState:
    """One station in a snapshot (the ``/diagnostics`` status of the station)."""

    name: str
    address: int
    online: bool
    dp_state: str               # the master's state of the slave (``closed`` without a port)
    reason: str                 # why it is offline ("" while online)
    diag: str                   # the station's last diagnosis in words ("" before the first)
    losses: int                 # times it went offline after being online
    outputs_safe: bool          # its output image holds the safe values (not set since the last loss)


@dataclass(frozen=True)
class IoSnapshot:
    """Every station and signal after a bus cycle. Equality ignores ``time``: ``snap != last`` means
    something the interface shows changed (``io_states`` is published on every change)."""

    time: float = field(compare=False)
    stations: Tuple[StationState, ...]
    signals: Tuple[SignalState, ...]

    def signal(self, name: str) -> Optional[SignalState]:
        for s in self.signals:
            if s.name == name:
                return s
        return None

    def station(self, name: str) -> Optional[StationState]:
        for s in self.stations:
            if s.name == name:
                return s
        return None


@dataclass(frozen=True)
class IoResult:
    """The answer to a write or a read: ``success``, ``message`` (the reason when refused), and
    for a read the value as text."""

    success: bool
    message: str
    value: str = ""


def _explain(handle: SlaveView, reason: str) -> str:
    """The master's reason for ending an attempt with a station, with what it most likely means."""
    diag = handle.last_diag
    spec = handle.spec
    if reason.startswith("diag:") and diag is not None:
        if diag.ident != spec.ident:
            return ("the station at address %d reports ident 0x%04X, the bus configuration expects 0x%04X "
                    "(another device at this address?): %s" % (handle.address, diag.ident, spec.ident, reason))
        if diag.status1 & DiagStatus1.CFG_FAULT:
            return ("the station rejects the configuration %s (%s bytes in / %s out): its modules differ from "
                    "the bus configuration: %s" % (spec.cfg.hex(" "), spec.input_size, spec.output_size, reason))
        if diag.status1 & DiagStatus1.PRM_FAULT:
            return "the station rejects the parameters (Set_Prm): %s" % reason
    if reason.startswith("no reply"):
        return "%s: is the station powered, connected and set to address %d?" % (reason, handle.address)
    return reason


class _Counters:
    def __init__(self) -> None:
        self.losses = 0


class _Spec:
    input_size = output_size = CONTROLLER_IO_LENGTH


class _State:
    def __init__(self, value: str) -> None:
        self.value = value


class ControllerIo:
    """The robot controller's own general-purpose I/O (protocol v2, doc/controller_program.md §9.5)
    as an I/O station of :class:`IoLine`: it has the shape of a master's slave handle, but its
    inputs come from the v2 feedback and its outputs go into the v2 command. The bus loop calls
    :meth:`refresh` with each link sample before :meth:`IoLine.update`; ``set_outputs(value)``
    puts the outputs word into the next command."""

    spec = _Spec()
    last_diag = None

    def __init__(self, address: int, set_outputs: Callable[[int], None]) -> None:
        self.address = address
        self._set_outputs = set_outputs
        self.counters = _Counters()
        self.connected = False
        self.state = _State("no link")
        self.state_since: Optional[float] = None
        self.inputs: Optional[bytes] = None
        self.inputs_time: Optional[float] = None
        self._outputs = bytes(CONTROLLER_IO_LENGTH)

    @property
    def outputs(self) -> bytes:
        return self._outputs

    @outputs.setter
    def outputs(self, data: bytes) -> None:
        self._outputs = bytes(data)
        self._set_outputs(int.from_bytes(self._outputs, "little"))

    def refresh(self, connected: bool, feedback: Any, feedback_time: Optional[float], now: float) -> None:
        """The link's sample of this bus iteration: connected (Data_Exchange with fresh v2
        feedback), the feedback and when it arrived."""
        if connected and feedback is not None:
            if not self.connected:
                self.state_since = now
            self.connected = True
            self.state = _State("DATA_EXCHANGE")
            self.inputs = int(feedback.inputs).to_bytes(CONTROLLER_IO_LENGTH, "little")
            self.inputs_time = feedback_time
        else:
            if self.connected:
                self.counters.losses += 1
            self.connected = False
            self.state = _State("no link to the controller")
            self.inputs = None


class _Station:
    """Mutable per-station state (guarded by the IoLine's lock)."""

    def __init__(self, signals: StationSignals) -> None:
        self.signals = signals
        self.safe = signals.safe_image()
        self.image = bytearray(self.safe)
        self.outputs_safe = True
        self.handle: Optional[SlaveView] = None
        self.session_start: Optional[float] = None   # entered Data_Exchange (this session)
        self.seen_losses = 0                        # the master's loss counter at the last update
        self.online = False
        self.reason = "no port"
        self.dp_reason = ""                          # the master's last reason for ending an attempt
        self.losses = 0
        self.inputs: Optional[bytes] = None          # the inputs shown (None while offline)


class IoLine:
    """See the module docstring. ``input_timeout`` (s): the oldest inputs a station may have and
    still count as online (the driver's ``link_timeout`` is a good value)."""

    def __init__(self, signal_map: SignalMap, input_timeout: float) -> None:
        if not input_timeout > 0:
            raise SignalMapError("input_timeout must be > 0 seconds, got %r" % (input_timeout,))
        self.map = signal_map
        self.input_timeout = float(input_timeout)
        self._stations: Dict[int, _Station] = {st.address: _Station(st) for st in signal_map.stations}
        self._lock = threading.RLock()
        self._master: Optional[MasterApi] = None
        self._chained: Optional[Callable[..., None]] = None
        self._local: Dict[int, Any] = {}          # stations not cycled by the master (ControllerIo)
        self._snapshot = self._make_snapshot(0.0)

    def add_local(self, handle: Any) -> None:
        """A station whose handle is not the master's (the controller's own I/O): never added to
        the master, judged like the others."""
        if handle.address not in self._stations:
            raise SignalMapError("no station with address %d in the signal map" % handle.address)
        self._local[handle.address] = handle

    # ------------------------------------------------------------------------ the master
    def add_slaves(self, master: MasterApi, bus: Any) -> None:
        """Add every station of the map to ``master`` from the bus configuration ``bus`` (a
        :class:`~pyprofibus_vendor.config.BusConfig`; each station's address must be one of its
        slaves), then :meth:`attach` it."""
        for address in self._stations:
            if address not in self._local:
                master.add_slave(SlaveSpec.from_config(bus.slave(address)))
        self.attach(master)

    def attach(self, master: MasterApi) -> None:
        """Take the stations' handles from ``master`` (every station must be one of its slaves;
        checked lengths) and follow its state changes (the master's own ``on_state_change`` keeps
        being called). Each station starts offline with its safe outputs."""
        with self._lock:
            self.detach()
            for address, st in self._stations.items():
                handle = self._local.get(address) or master.slave(address)
                if (handle.spec.input_size, handle.spec.output_size) != (st.signals.input_len, st.signals.output_len):
                    raise SignalMapError("station %r: the master has %s bytes in / %s out for slave %d, the signal "
                                         "map %d / %d" % (st.signals.name, handle.spec.input_size,
                                                          handle.spec.output_size, address,
                                                          st.signals.input_len, st.signals.output_len))
                st.handle = handle
                st.seen_losses = handle.counters.losses
                st.session_start = handle.state_since if handle.connected else None
                st.reason = "not in Data_Exchange yet (%s)" % handle.state.value
                self._fall_back(st, "port (re)opened")
            self._master = master
            self._chained = master.on_state_change
            master.on_state_change = self._on_state_change

    def detach(self) -> None:
        """The master is gone (port closed): every station offline, outputs safe."""
        with self._lock:
            master, self._master = self._master, None
            if master is not None and master.on_state_change == self._on_state_change:
                master.on_state_change = self._chained
            self._chained = None
            for st in self._stations.values():
                if st.handle is not None:
                    self._offline(st, "no port")
                    st.handle = None
                st.reason = "no port"

    def _on_state_change(self, handle: SlaveView, old: MasterSlaveState, new: MasterSlaveState,
                         reason: str) -> None:
        """The master's per-slave state changes (in the bus loop, inside the cycle): a station
        leaving Data_Exchange falls back at once; one entering it starts a new session."""
        try:
            with self._lock:
                st = self._stations.get(handle.address)
                if st is not None and st.handle is handle:
                    if new in _CONNECTED and old not in _CONNECTED:
                        st.session_start = handle.state_since
                    elif old in _CONNECTED and new not in _CONNECTED:
                        st.seen_losses = handle.counters.losses
                        st.session_start = None
                        self._offline(st, "left Data_Exchange: %s" % reason)
                    if new is MasterSlaveState.BACKOFF:
                        st.dp_reason = _explain(handle, reason)
        finally:
            if self._chained is not None:
                self._chained(handle, old, new, reason)

    # ------------------------------------------------------------------------ the bus loop
    def update(self, now: float) -> IoSnapshot:
        """Judge every station after a bus cycle at ``now``; the new snapshot."""
        with self._lock:
            for st in self._stations.values():
                self._judge(st, now)
            self._snapshot = self._make_snapshot(now)
            return self._snapshot

    def _judge(self, st: _Station, now: float) -> None:
        h = st.handle
        if h is None:
            return self._offline(st, "no port")
        if h.counters.losses != st.seen_losses:       # lost and back between two updates
            st.seen_losses = h.counters.losses
            st.session_start = now if h.connected else None   # inputs before now: not of this session
            self._offline(st, "left Data_Exchange and came back")
        if not h.connected:
            why = "not in Data_Exchange (%s)" % h.state.value
            if st.dp_reason:
                why += ": " + st.dp_reason
            return self._offline(st, why)
        if st.session_start is None:       # back in Data_Exchange, its start not seen (no state hook):
            st.session_start = now         # believe inputs from this update on
        at = h.inputs_time
        if at is None or at < st.session_start:
            return self._offline(st, "in Data_Exchange, no inputs of this session yet")
        if now - at > self.input_timeout:
            return self._offline(st, "no fresh inputs for %.2f s (input_timeout %.2f s)"
                                 % (now - at, self.input_timeout))
        if not st.online:
            log.info("I/O station %s (slave %d) online%s", st.signals.name, st.signals.address,
                     "; outputs at their safe values until set" if st.outputs_safe and st.losses else "")
        st.online, st.reason, st.inputs = True, "", h.inputs

    def _offline(self, st: _Station, reason: str) -> None:
        if st.online:
            st.losses += 1
            log.warning("I/O station %s (slave %d) offline: %s; outputs to their safe values",
                        st.signals.name, st.signals.address, reason)
            self._fall_back(st, reason)
        st.online, st.reason, st.inputs = False, reason, None

    def _fall_back(self, st: _Station, reason: str) -> None:
        st.image[:] = st.safe
        st.outputs_safe = True
        if st.handle is not None:
            st.handle.outputs = bytes(st.image)

    # ------------------------------------------------------------------------ requests
    def write(self, name: str, value: Any) -> IoResult:
        """Set an output: ``value`` as text (``set_io``: parsed per the signal's type) or a Python
        value. Refused (success False, the reason, nothing changed) for an unknown name, an input,
        a value that does not fit, a station not online."""
        signal = self.map.signal(name) if isinstance(name, str) else None
        if signal is None:
            return IoResult(False, "unknown signal %r (known: %s)"
                            % (name, ", ".join(s.name for s in self.map.signals)))
        if not signal.is_output:
            return IoResult(False, "signal %r is an input of station %r: it cannot be set"
                            % (name, signal.station))
        try:
            checked = signal.parse(value) if isinstance(value, str) else signal.check(value)
        except SignalMapError as exc:
            return IoResult(False, str(exc))
        with self._lock:
            st = self._stations[signal.address]
            h = st.handle
            if not st.online or h is None or not h.connected:
                return IoResult(False, "station %r (slave %d) is not in Data_Exchange (%s): %s not set, "
                                "nothing sent" % (signal.station, signal.address, st.reason or "offline", name))
            signal.write(st.image, checked)
            st.outputs_safe = False
            h.outputs = bytes(st.image)
            self._snapshot = self._make_snapshot(self._snapshot.time)
        return IoResult(True, "%s = %s (sent in the next cycle)" % (name, signal.format(checked)),
                        signal.format(checked))

    def read(self, name: str) -> IoResult:
        """A signal's value as text from the latest snapshot (``get_io``); refused for an unknown
        name or an offline station."""
        state = self._snapshot.signal(name) if isinstance(name, str) else None
        if state is None:
            return IoResult(False, "unknown signal %r (known: %s)"
                            % (name, ", ".join(s.name for s in self.map.signals)))
        if not state.online:
            st = self._snapshot.station(state.station)
            return IoResult(False, "station %r is offline (%s): no value for %s"
                            % (state.station, st.reason if st is not None else "", name))
        return IoResult(True, "", state.text)

    def snapshot(self) -> IoSnapshot:
        return self._snapshot

    def _make_snapshot(self, now: float) -> IoSnapshot:
        stations = []
        signals = []
        for st in self._stations.values():
            h = st.handle
            diag = ""
            if h is not None and h.last_diag is not None:
                diag = explain_diag(h.last_diag)
            stations.append(StationState(st.signals.name, st.signals.address, st.online,
                                         h.state.value if h is not None else "closed", st.reason, diag,
                                         st.losses, st.outputs_safe))
            for s in st.signals.signals:
                signals.append(SignalState(s.name, s.station, s.direction, s.type,
                                           self._value(st, s), st.online))
        return IoSnapshot(now, tuple(stations), tuple(signals))

    @staticmethod
    def _value(st: _Station, s: Signal) -> Optional[Value]:
        if not st.online:
            return None
        if s.is_output:
            return s.read(st.image)
        return s.read(st.inputs) if st.inputs is not None else None
