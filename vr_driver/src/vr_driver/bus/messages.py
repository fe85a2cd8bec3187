"""The messages between the driver and its bus process (vr_driver.bus.process), one class each.

Each message is a frozen dataclass with :meth:`encode` (to bytes) and the module's :func:`decode`
(from bytes, with every field checked: a malformed message raises :class:`MessageError` naming
what is wrong, and changes nothing). On the wire a message is the pickle of a plain tuple: its
tag, then its fields in the order of its docstring's layout (nested messages as their own tuples).
The bus reports every cycle: a plain tuple pickles and loads as fast as the tagged tuples that went
before, and the parts that seldom change (the health summary) travel only when they changed.

The driver sends (:data:`TO_BUS`)::

    Start      ("config", settings: BusSettings)              the first message: open the port
    AddSlave   ("slave", spec: SlaveSpec)                     one more slave to cycle
    Outputs    ("out", address, session, data, stop, serial)  a slave's outputs (stop: the
                                                              controller's stop record or None)
    Answer     ("answer", seq)                                the outputs for report seq are set
    CycleAt    ("cycle_at", when)                             the next cycle no later than when
    Tick       ("tick",)                                      the driver is alive
    Close      ("close",)                                     end the bus process

The bus process sends (:data:`FROM_BUS`)::

    Opened     ("opened", scheduling, adapter: AdapterSetup or None)
    OpenFailed ("error", text, errno or None)                 the port cannot be opened
    Report     ("r", time, seq, carried, counters, slaves, health, dropped_events, events)
               counters: the MasterCounters' values in field order; slaves: SlaveReport tuples;
               health: a BusHealthSummary when it changed since the last report, else None;
               events: StateChange tuples, in order
    SlaveReport (address, state, since, session, inputs, inputs_time, diag, counters)
               diag: the slave's last Slave_Diag telegram (bytes) or None
    StateChange (address, old, new, reason, since, session)
    Failed     ("fail", text)                                 the port failed: the process ends

:class:`Channel` is one end of the socket: it sends a message and receives only the messages
meant for its side.
"""
from __future__ import annotations

import functools
import pickle
import typing
from dataclasses import dataclass, fields
from multiprocessing.connection import Connection
from typing import Callable, Dict, Optional, Tuple, Type, TypeVar, Union

from pyprofibus_vendor.adapter import AdapterSetup
from pyprofibus_vendor.dp import SlaveDiag
from pyprofibus_vendor.dp_master import BusTiming, SlaveSpec
from pyprofibus_vendor.errors import PhyError, ProfibusError
from pyprofibus_vendor.master_api import MasterCounters, MasterSlaveState, SlaveCounters

from .health import BusHealthSummary

__all__ = ["MessageError", "Message", "message", "BusSettings", "Start", "AddSlave", "Outputs", "Answer", "CycleAt", "Tick",
           "Close", "Opened", "OpenFailed", "SlaveReport", "StateChange", "Report", "Failed", "decode",
           "Channel", "driver_channel", "bus_channel", "TO_BUS", "FROM_BUS"]

_NUMBER = (int, float)
_NUMBER_TYPES = {int, float}
_MASTER_FIELDS = tuple(f.name for f in fields(MasterCounters))
_SLAVE_FIELDS = tuple(f.name for f in fields(SlaveCounters))


class MessageError(PhyError):
    """A message that is not one of the protocol's, or whose fields are not what it says."""


@dataclass(frozen=True)
class BusSettings:
    """Everything the bus process needs (sent to it at start)."""

    device: str
    baud: int
    master_address: int
    timing: BusTiming
    cycle_rate_hz: float
    controller: int                      # the controller's slave address
    idle_record: bytes                   # the controller's record that asks nothing
    watchdog: Optional[float]            # the card's watchdog [s] (None: off)
    backoff_max: float = 1.0
    dx_tolerance: float = 0.0
    retry_steps: bool = True
    rt_priority: int = 0                 # SCHED_FIFO priority (1..99); 0: normal scheduling
    node_timeout: float = 1.0            # [s] no word from the driver this long: it is dead
    stop_hold: float = 2.0               # [s] the stop record is sent this long before the end
    answer_wait: float = 0.01            # [s] a due cycle waits this long for the driver's answer

    @property
    def period(self) -> float:
        return 1.0 / self.cycle_rate_hz

    @property
    def cycle_timeout(self) -> float:
        return max(0.2, 2.0 / self.cycle_rate_hz)


def _check(tag: str, values: tuple, types: tuple, noun: str = "bus message",
           error: Type[Exception] = MessageError) -> None:
    """Each value of a message is of its field's type(s) (a tuple of types; None allowed where
    the types include type(None)); else ``error`` naming the ``noun`` (whose message), the tag
    and the field."""
    if len(values) != len(types):
        raise error("%s %r: %d fields, expected %d" % (noun, tag, len(values), len(types)))
    if all(map(isinstance, values, types)):
        return
    for i, (value, kind) in enumerate(zip(values, types)):
        if not isinstance(value, kind):
            raise error("%s %r: field %d is %s %r, expected %s" % (
                noun, tag, i + 1, type(value).__name__, value if len(repr(value)) < 60 else "...",
                " or ".join(k.__name__ for k in kind)))


class Message:
    """A message: ``TAG`` and ``TYPES`` (one tuple of accepted types per field); ``NOUN`` and
    ``ERROR`` say whose message a malformed one was, and raise what (the planning process's
    messages, vr_driver.driver.planning.plan_messages, are messages too)."""

    TAG = ""
    TYPES: tuple = ()
    NOUN = "bus message"
    ERROR: Type[Exception] = MessageError

    def values(self) -> tuple:
        """The fields as they go on the wire, in order."""
        return tuple(self.__dict__.values())

    def encode(self) -> bytes:
        return pickle.dumps((self.TAG,) + self.values(), pickle.HIGHEST_PROTOCOL)

    @classmethod
    def from_fields(cls, values: tuple) -> "Message":
        _check(cls.TAG, values, cls.TYPES, cls.NOUN, cls.ERROR)
        return cls(*values)  # type: ignore[call-arg]


_NONE = type(None)
M = TypeVar("M", bound=Message)


def _accepts(hint: object) -> tuple:
    """The types a field of type ``hint`` accepts on the wire (a float: an int too)."""
    kinds = typing.get_args(hint) if typing.get_origin(hint) is Union else (hint,)
    return tuple(t for k in kinds for t in (_NUMBER if k is float else (k,)))


def message(tag: str) -> Callable[[Type[M]], Type[M]]:
    """The class decorator of a message: a frozen dataclass with its ``TAG``, and the ``TYPES`` its
    fields accept read from their annotations."""
    def make(cls: Type[M]) -> Type[M]:
        cls = dataclass(frozen=True)(cls)
        cls.TAG = tag
        hints = typing.get_type_hints(cls)
        cls.TYPES = tuple(_accepts(hints[f.name]) for f in fields(cls))
        return cls
    return make


# ---------------------------------------------------------------------------- the driver's
@message("config")
class Start(Message):
    """("config", settings): the first message; the bus process opens the port."""

    settings: BusSettings


@message("slave")
class AddSlave(Message):
    """("slave", spec): one more slave to cycle."""

    spec: SlaveSpec


@message("out")
class Outputs(Message):
    """("out", address, session, data, stop, serial): a slave's outputs, made in Data_Exchange
    session ``session``; ``stop`` the controller's stop record for them (or None); ``serial``
    counts the outputs messages of that slave."""

    address: int
    session: int
    data: bytes
    stop: Optional[bytes]
    serial: int


@message("answer")
class Answer(Message):
    """("answer", seq): the driver has set its outputs for report ``seq``."""

    seq: int


@message("cycle_at")
class CycleAt(Message):
    """("cycle_at", when): the next cycle no later than ``when`` (the bus process's clock)."""

    when: float


@message("tick")
class Tick(Message):
    """("tick",): the driver is alive."""



@message("close")
class Close(Message):
    """("close",): end the bus process (the port is closed; nothing is sent after)."""



# ---------------------------------------------------------------------------- the bus process's
@message("opened")
class Opened(Message):
    """("opened", scheduling, adapter): the port is open; how the process is scheduled, in words,
    and the USB adapter's setup (pyprofibus_vendor.adapter) or None."""

    scheduling: str
    adapter: Optional[AdapterSetup]


@message("error")
class OpenFailed(Message):
    """("error", text, errno): the port cannot be opened; the OS error number where there is one."""

    text: str
    errno: Optional[int]


@message("fail")
class Failed(Message):
    """("fail", text): the port failed; the bus process ends."""

    text: str


@dataclass(frozen=True)
class StateChange:
    """(address, old, new, reason, since, session): a slave changed state (the master's event) at
    ``since``; ``session`` its Data_Exchange sessions so far."""

    address: int
    old: MasterSlaveState
    new: MasterSlaveState
    reason: str
    since: float
    session: int

    def values(self) -> tuple:
        return (self.address, self.old.value, self.new.value, self.reason, self.since, self.session)

    @classmethod
    def from_fields(cls, values: tuple) -> "StateChange":
        _check("state change", values, ((int,), (str,), (str,), (str,), _NUMBER, (int,)))
        address, old, new, reason, since, session = values
        return cls(address, _state(old), _state(new), reason, since, session)


@dataclass(frozen=True)
class SlaveReport:
    """(address, state, since, session, inputs, inputs_time, diag, counters): one slave after a
    cycle; ``diag`` its last Slave_Diag as the telegram's bytes (or None), ``counters`` the
    SlaveCounters' values in field order."""

    address: int
    state: MasterSlaveState
    since: float
    session: int
    inputs: Optional[bytes]
    inputs_time: Optional[float]
    diag: Optional[SlaveDiag]
    counters: SlaveCounters

    def values(self) -> tuple:
        return (self.address, self.state.value, self.since, self.session, self.inputs, self.inputs_time,
                None if self.diag is None else self.diag.encode(), tuple(vars(self.counters).values()))

    @classmethod
    def from_fields(cls, values: tuple) -> "SlaveReport":
        _check("slave report", values, ((int,), (str,), _NUMBER, (int,), (bytes, _NONE),
                                        (int, float, _NONE), (bytes, _NONE), (tuple,)))
        address, state, since, session, inputs, inputs_time, diag, counters = values
        return cls(address, _state(state), since, session, inputs, inputs_time,
                   None if diag is None else _diag(diag),
                   _counters(SlaveCounters, _SLAVE_FIELDS, counters))


@message("r")
class Report(Message):
    """("r", time, seq, carried, counters, slaves, health, dropped_events, events): the bus after a
    cycle -- report number ``seq``; ``carried`` the serial of the controller's outputs its last
    answered Data_Exchange carried; the master's counters, each slave, the health summary (None:
    unchanged since the last report), the state changes dropped for a driver that did not read,
    and the state changes since the last report, in order."""

    time: float
    seq: int
    carried: int
    counters: MasterCounters
    slaves: Tuple[SlaveReport, ...]
    health: Optional[BusHealthSummary]
    dropped_events: int
    events: Tuple[StateChange, ...]

    def values(self) -> tuple:
        return (self.time, self.seq, self.carried, tuple(vars(self.counters).values()),
                tuple(s.values() for s in self.slaves), self.health, self.dropped_events,
                tuple(e.values() for e in self.events))

    @classmethod
    def from_fields(cls, values: tuple) -> "Report":
        _check("r", values, (_NUMBER, (int,), (int,), (tuple,), (tuple,), (BusHealthSummary, _NONE),
                             (int,), (tuple,)))
        time, seq, carried, counters, slaves, health, dropped, events = values
        return cls(time, seq, carried, _counters(MasterCounters, _MASTER_FIELDS, counters),
                   tuple(SlaveReport.from_fields(_tuple(s, "slave report")) for s in slaves),
                   health, dropped, tuple(StateChange.from_fields(_tuple(e, "state change")) for e in events))


def _tuple(value: object, what: str) -> tuple:
    if not isinstance(value, tuple):
        raise MessageError("bus message: a %s is %s, expected a tuple" % (what, type(value).__name__))
    return value


@functools.lru_cache(maxsize=64)
def _diag(data: bytes) -> SlaveDiag:
    """A Slave_Diag from its bytes (a slave's diagnosis seldom changes: the same bytes every report
    give the same frozen object, decoded once)."""
    try:
        return SlaveDiag.decode(data)
    except ProfibusError as exc:
        raise MessageError("bus message: a slave's diagnosis %s: %s" % (data.hex(" "), exc)) from None


def _state(value: str) -> MasterSlaveState:
    try:
        return MasterSlaveState(value)
    except ValueError:
        raise MessageError("bus message: no slave state %r" % value) from None


def _counters(kind: Type[Union[MasterCounters, SlaveCounters]], names: Tuple[str, ...],
              values: tuple) -> Union[MasterCounters, SlaveCounters]:
    if len(values) != len(names) or not set(map(type, values)) <= _NUMBER_TYPES:
        raise MessageError("bus message: %s %r, expected %d numbers (%s)" % (
            kind.__name__, values, len(names), ", ".join(names)))
    return kind(*values)


#: what the driver sends, and what the bus process sends, by tag
TO_BUS: Dict[str, Type[Message]] = {m.TAG: m for m in (Start, AddSlave, Outputs, Answer, CycleAt, Tick, Close)}
FROM_BUS: Dict[str, Type[Message]] = {m.TAG: m for m in (Opened, OpenFailed, Report, Failed)}


def decode(data: bytes, kinds: Dict[str, Type[Message]]) -> Message:
    """The message in ``data`` (one of ``kinds``: :data:`TO_BUS` or :data:`FROM_BUS`, or another
    protocol's); :class:`MessageError` (their ``ERROR``) when it is none of them or a field is wrong."""
    first = next(iter(kinds.values()))
    noun, error = first.NOUN, first.ERROR
    try:
        raw = pickle.loads(data)
    except Exception as exc:  # a pickle that does not load raises anything its content makes
        raise error("%s does not load: %s: %s" % (noun, type(exc).__name__, exc)) from None
    if not isinstance(raw, tuple) or not raw or not isinstance(raw[0], str):
        raise error("%s %.60r is not a tagged tuple" % (noun, raw))
    kind = kinds.get(raw[0])
    if kind is None:
        raise error("%s %r unknown here (expected one of %s)" % (noun, raw[0], ", ".join(sorted(kinds))))
    return kind.from_fields(raw[1:])


class Channel:
    """One end of the driver's socket to its bus process (or to its planning process): sends any
    message, receives only those meant for this side (``kinds``). The connection's OSError/EOFError
    pass through (the other end is gone); a malformed message raises :class:`MessageError` (the
    kinds' ``ERROR``)."""

    def __init__(self, conn: Connection, kinds: Dict[str, Type[Message]]) -> None:
        self.conn = conn
        self.kinds = kinds

    def send(self, message: Message) -> None:
        self.conn.send_bytes(message.encode())

    def recv(self) -> Message:
        return decode(self.conn.recv_bytes(), self.kinds)

    def poll(self, timeout: float = 0.0) -> bool:
        return self.conn.poll(timeout)

    def close(self) -> None:
        self.conn.close()


def driver_channel(conn: Connection) -> Channel:
    """The driver's end (the client): receives what the bus process sends."""
    return Channel(conn, FROM_BUS)


def bus_channel(conn: Connection) -> Channel:
    """The bus process's end (the server): receives what the driver sends."""
    return Channel(conn, TO_BUS)
