"""Named I/O signals on the PROFIBUS line: the signal map, its checks, and the codec of each type.
ROS-free.

A *signal map* (YAML beside the bus configuration) names the bits and words of the process images
of the I/O stations on the line (doc/io_line.md)::

    stations:
      io_island:                  # a name for logs and diagnostics (unique)
        address: 8                # the station's DP address; must be a slave of the bus config
        signals:
          gripper_close:  {direction: out, type: bit, byte: 0, bit: 0, safe: 0}
          gripper_closed: {direction: in,  type: bit, byte: 0, bit: 0}
          conveyor_speed: {direction: out, type: int16, byte: 1, byte_order: big, safe: 0}

Keys of a signal: ``direction`` (``in``: station -> master, ``out``: master -> station), ``type``
(:data:`TYPES`), ``byte`` (offset in the station's input or output image), ``bit`` (0..7, only and
always for ``bit``), ``byte_order`` (``big``, the PROFIBUS default, or ``little``; only for the
multi-byte types), ``safe`` (outputs only, default 0: the value the output takes when the station is
lost, before it is set again). Signal names are unique over the whole map (``set_io`` takes a name
only). Every check raises :class:`~vr_driver.errors.SignalMapError` naming the station and key, so
a bad map stops the node before anything is sent.

Values: ``bit`` 0 / 1, the integer types their range, ``float32`` a finite number that an IEEE
single holds (rounded to it). :meth:`Signal.parse` reads a value given as text (the ``set_io``
service), :meth:`Signal.check` a Python value, :meth:`Signal.read` / :meth:`Signal.write` take it
from / put it into a process image.
"""
from __future__ import annotations

import math
import re
import struct
from dataclasses import dataclass
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple, Union

from .errors import SignalMapError

#: bytes each way of the controller's own general-purpose I/O in the records of a protocol that
#: carries it (``controller_io``: 16 inputs, 16 outputs): the station the signal map may name at the
#: controller's address (driver.link.stations.ControllerIo serves it)
CONTROLLER_IO_LENGTH = 2

__all__ = ["TYPES", "DIRECTIONS", "Value", "Signal", "StationSignals", "SignalMap", "load_signal_map",
           "lengths_from_bus", "describe"]

Value = Union[int, float]

#: type name -> (struct code, size in bytes); "bit" is one bit of a byte
TYPES: Dict[str, Tuple[str, int]] = {
    "bit": ("B", 1), "uint8": ("B", 1), "int16": ("h", 2), "uint16": ("H", 2), "int32": ("i", 4),
    "float32": ("f", 4),
}
DIRECTIONS = ("in", "out")
BYTE_ORDERS = {"big": ">", "little": "<"}
_FLOAT32_MAX = struct.unpack(">f", b"\x7f\x7f\xff\xff")[0]
_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*\Z")
_SIGNAL_KEYS = ("direction", "type", "byte", "bit", "byte_order", "safe")
_STATION_KEYS = ("address", "signals")
_TRUE = ("1", "true", "on", "high")
_FALSE = ("0", "false", "off", "low")


def _kind(value: Any) -> str:
    return "nothing (null)" if value is None else "%s %r" % (type(value).__name__, value)


def _int_range(type_name: str) -> Tuple[int, int]:
    if type_name == "bit":
        return 0, 1
    size = TYPES[type_name][1]
    if type_name.startswith("u"):
        return 0, (1 << (8 * size)) - 1
    return -(1 << (8 * size - 1)), (1 << (8 * size - 1)) - 1


@dataclass(frozen=True)
class Signal:
    """One named signal: where it lives in which image of which station, and how it is coded."""

    name: str
    station: str
    address: int
    direction: str                 # "in" | "out"
    type: str                      # one of TYPES
    byte: int
    bit: Optional[int] = None      # 0..7 for "bit", else None
    byte_order: str = "big"
    safe: Optional[Value] = None   # outputs: the safe value (checked); inputs: None

    @property
    def size(self) -> int:
        return TYPES[self.type][1]

    @property
    def is_output(self) -> bool:
        return self.direction == "out"

    def _where(self, key: str = "") -> str:
        return "station %r signal %r%s" % (self.station, self.name, " key %r" % key if key else "")

    def bits(self) -> List[Tuple[int, int]]:
        """The (byte, bit) positions this signal occupies in its image."""
        if self.bit is not None:
            return [(self.byte, self.bit)]
        return [(b, i) for b in range(self.byte, self.byte + self.size) for i in range(8)]

    # ------------------------------------------------------------------------ values
    def check(self, value: Any, key: str = "value") -> Value:
        """``value`` as this signal's type (float32 rounded to single precision), or
        SignalMapError saying why it does not fit."""
        if self.type == "float32":
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise SignalMapError("%s: expected a number for float32, got %s" % (self._where(key), _kind(value)))
            value = float(value)
            if not math.isfinite(value) or abs(value) > _FLOAT32_MAX:
                raise SignalMapError("%s: %r does not fit a float32 (finite, |value| <= %g)"
                                     % (self._where(key), value, _FLOAT32_MAX))
            return struct.unpack(">f", struct.pack(">f", value))[0]
        if isinstance(value, bool) and self.type == "bit":
            return int(value)
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        if isinstance(value, bool) or not isinstance(value, int):
            raise SignalMapError("%s: expected an integer for %s, got %s" % (self._where(key), self.type, _kind(value)))
        lo, hi = _int_range(self.type)
        if not lo <= value <= hi:
            raise SignalMapError("%s: %d does not fit %s (%d..%d)" % (self._where(key), value, self.type, lo, hi))
        return value

    def parse(self, text: str) -> Value:
        """A value given as text (``set_io``): bit ``0 1 true false on off high low``; integers in
        decimal or ``0x`` hex; float32 a decimal number. SignalMapError if it does not fit."""
        if not isinstance(text, str):
            raise SignalMapError("%s: expected text, got %s" % (self._where("value"), _kind(text)))
        t = text.strip()
        if self.type == "bit":
            if t.lower() in _TRUE:
                return 1
            if t.lower() in _FALSE:
                return 0
            raise SignalMapError("%s: %r is not a bit value (0/1, true/false, on/off)" % (self._where("value"), text))
        if self.type == "float32":
            try:
                number: Any = float(t)
            except ValueError:
                raise SignalMapError("%s: %r is not a number" % (self._where("value"), text)) from None
            return self.check(number)
        if not re.match(r"[+-]?(0[xX][0-9a-fA-F]+|[0-9]+)\Z", t):
            raise SignalMapError("%s: %r is not an integer (decimal or 0x hex)" % (self._where("value"), text))
        return self.check(int(t, 0))

    def format(self, value: Value) -> str:
        """The text form of a value (what ``get_io`` answers)."""
        return repr(float(value)) if self.type == "float32" else str(int(value))

    # ------------------------------------------------------------------------ images
    def read(self, image: bytes) -> Value:
        """The value in a process image (input or output image of this signal's direction)."""
        if self.bit is not None:
            return (image[self.byte] >> self.bit) & 1
        code = BYTE_ORDERS[self.byte_order] + TYPES[self.type][0]
        return struct.unpack_from(code, image, self.byte)[0]

    def write(self, image: bytearray, value: Any) -> None:
        """Put ``value`` (checked first: a bad value changes nothing) into ``image``."""
        value = self.check(value)
        if self.bit is not None:
            mask = 1 << self.bit
            image[self.byte] = (image[self.byte] | mask) if value else (image[self.byte] & ~mask & 0xFF)
            return
        struct.pack_into(BYTE_ORDERS[self.byte_order] + TYPES[self.type][0], image, self.byte, value)


@dataclass(frozen=True)
class StationSignals:
    """The signals of one station and its image lengths (input = station -> master)."""

    name: str
    address: int
    input_len: int
    output_len: int
    signals: Tuple[Signal, ...]

    @property
    def outputs(self) -> Tuple[Signal, ...]:
        return tuple(s for s in self.signals if s.is_output)

    @property
    def inputs(self) -> Tuple[Signal, ...]:
        return tuple(s for s in self.signals if not s.is_output)

    def safe_image(self) -> bytes:
        """The output image with every output at its safe value (unmapped bits 0)."""
        image = bytearray(self.output_len)
        for s in self.outputs:
            s.write(image, s.safe)
        return bytes(image)


@dataclass(frozen=True)
class SignalMap:
    """Every station's signals; :meth:`signal` finds one by name."""

    stations: Tuple[StationSignals, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "_by_name", {s.name: s for st in self.stations for s in st.signals})

    @property
    def signals(self) -> Tuple[Signal, ...]:
        return tuple(s for st in self.stations for s in st.signals)

    def signal(self, name: str) -> Optional[Signal]:
        return self._by_name.get(name)  # type: ignore[attr-defined]

    def station(self, name: str) -> StationSignals:
        for st in self.stations:
            if st.name == name:
                return st
        raise KeyError(name)

    @classmethod
    def from_dict(cls, data: Any, lengths: Mapping[int, Tuple[int, int]]) -> "SignalMap":
        """Check ``data`` (the parsed YAML) against ``lengths`` (station address -> (input
        length, output length), e.g. :func:`lengths_from_bus`) and build the map."""
        if not isinstance(data, Mapping) or set(data) != {"stations"}:
            keys = sorted(map(str, data)) if isinstance(data, Mapping) else _kind(data)
            raise SignalMapError("signal map: expected exactly one top-level key 'stations', got %s" % (keys,))
        raw = data["stations"]
        if not isinstance(raw, Mapping) or not raw:
            raise SignalMapError("signal map key 'stations': expected a mapping of station names to "
                                 "stations, got %s" % _kind(raw))
        stations: List[StationSignals] = []
        names: Dict[str, str] = {}
        addresses: Dict[int, str] = {}
        for station_name, body in raw.items():
            st = _station(str(station_name), body, lengths)
            if st.address in addresses:
                raise SignalMapError("station %r key 'address': %d is already station %r"
                                     % (st.name, st.address, addresses[st.address]))
            addresses[st.address] = st.name
            for s in st.signals:
                if s.name in names:
                    raise SignalMapError("station %r signal %r: duplicate signal name (already in station %r)"
                                         % (st.name, s.name, names[s.name]))
                names[s.name] = st.name
            stations.append(st)
        return cls(tuple(stations))


def _check_entry(where: str, what: str, name: str, body: Any, expected: str, keys: Sequence[str]) -> None:
    """A station's or a signal's name and body: the name a letter followed by letters, digits or _,
    the body a mapping of ``keys`` only (``expected`` says what it should hold)."""
    if not _NAME.match(name):
        raise SignalMapError("%s: a %s name is a letter followed by letters, digits or _" % (where, what))
    if not isinstance(body, Mapping):
        raise SignalMapError("%s: expected %s, got %s" % (where, expected, _kind(body)))
    for key in body:
        if key not in keys:
            raise SignalMapError("%s key %r: unknown key (allowed: %s)" % (where, key, ", ".join(keys)))


def _station(name: str, body: Any, lengths: Mapping[int, Tuple[int, int]]) -> StationSignals:
    where = "station %r" % name
    _check_entry(where, "station", name, body, "a mapping with address and signals", _STATION_KEYS)
    address = body.get("address")
    if isinstance(address, bool) or not isinstance(address, int):
        raise SignalMapError("%s key 'address': expected the station's DP address, got %s" % (where, _kind(address)))
    if address not in lengths:
        raise SignalMapError("%s key 'address': no slave %d in the bus configuration (have %s)"
                             % (where, address, ", ".join(str(a) for a in sorted(lengths)) or "none"))
    n_in, n_out = lengths[address]
    raw = body.get("signals")
    if not isinstance(raw, Mapping) or not raw:
        raise SignalMapError("%s key 'signals': expected a mapping of signal names to signals, got %s"
                             % (where, _kind(raw)))
    signals = tuple(_signal(str(k), v, name, address, n_in, n_out) for k, v in raw.items())
    for direction in DIRECTIONS:
        taken: Dict[Tuple[int, int], str] = {}
        for s in signals:
            if s.direction != direction:
                continue
            for pos in s.bits():
                if pos in taken:
                    raise SignalMapError("%s signal %r: overlaps signal %r in the %s image at byte %d bit %d"
                                         % (where, s.name, taken[pos], "input" if direction == "in" else
                                            "output", pos[0], pos[1]))
                taken[pos] = s.name
    return StationSignals(name, address, n_in, n_out, signals)


def _signal(name: str, body: Any, station: str, address: int, n_in: int, n_out: int) -> Signal:
    where = "station %r signal %r" % (station, name)
    _check_entry(where, "signal", name, body, "a mapping (direction, type, byte, ...)", _SIGNAL_KEYS)
    for key in ("direction", "type", "byte"):
        if key not in body:
            raise SignalMapError("%s key %r: required key is missing" % (where, key))
    direction = body["direction"]
    if direction not in DIRECTIONS:
        raise SignalMapError("%s key 'direction': %s is not one of in, out" % (where, _kind(direction)))
    type_name = body["type"]
    if type_name not in TYPES:
        raise SignalMapError("%s key 'type': %s is not one of %s" % (where, _kind(type_name), ", ".join(TYPES)))
    byte = body["byte"]
    if isinstance(byte, bool) or not isinstance(byte, int) or byte < 0:
        raise SignalMapError("%s key 'byte': expected a byte offset >= 0, got %s" % (where, _kind(byte)))
    size = TYPES[type_name][1]
    length = n_in if direction == "in" else n_out
    if byte + size > length:
        raise SignalMapError("%s key 'byte': %s at byte %d needs bytes %d..%d, past the end of the station's "
                             "%d-byte %s image" % (where, type_name, byte, byte, byte + size - 1, length,
                                                   "input" if direction == "in" else "output"))
    bit = body.get("bit")
    if type_name == "bit":
        if bit is None:
            raise SignalMapError("%s key 'bit': a bit signal needs its bit offset (0..7)" % where)
        if isinstance(bit, bool) or not isinstance(bit, int) or not 0 <= bit <= 7:
            raise SignalMapError("%s key 'bit': expected 0..7, got %s" % (where, _kind(bit)))
    elif "bit" in body:
        raise SignalMapError("%s key 'bit': only a signal of type bit has a bit offset (this one is %s)"
                             % (where, type_name))
    order = body.get("byte_order", "big")
    if "byte_order" in body and size == 1:
        raise SignalMapError("%s key 'byte_order': a 1-byte %s has no byte order" % (where, type_name))
    if order not in BYTE_ORDERS:
        raise SignalMapError("%s key 'byte_order': %s is not one of big, little" % (where, _kind(order)))
    if direction == "in" and "safe" in body:
        raise SignalMapError("%s key 'safe': only outputs have a safe value (this is an input)" % where)
    signal = Signal(name, station, address, direction, type_name, byte, bit, order, None)
    if direction == "out":
        safe = signal.check(body.get("safe", 0), "safe")
        signal = Signal(name, station, address, direction, type_name, byte, bit, order, safe)
    return signal


def lengths_from_bus(bus: Any) -> Dict[int, Tuple[int, int]]:
    """Station address -> (input length, output length) from a
    :class:`~pyprofibus_vendor.config.BusConfig` (or anything with ``slaves`` of that shape)."""
    return {s.address: (s.input_len, s.output_len) for s in bus.slaves}


def load_signal_map(path: str, lengths: Mapping[int, Tuple[int, int]]) -> SignalMap:
    """Read and check a signal map YAML file. SignalMapError names the file and the key (a key
    given twice is an error too: YAML alone would keep the last one silently)."""
    from pyprofibus_vendor.config import _read_yaml      # the bus config's reader: duplicate keys refused
    from pyprofibus_vendor.errors import ConfigError
    try:
        with open(path, encoding="utf-8") as fh:
            data, _lines = _read_yaml(fh.read(), path)
    except ConfigError as exc:                 # its message names the file and line already
        raise SignalMapError("signal map %s" % exc) from exc
    except OSError as exc:
        raise SignalMapError("signal map %s: %s" % (path, exc)) from exc
    try:
        return SignalMap.from_dict(data, lengths)
    except SignalMapError as exc:
        raise SignalMapError("signal map %s: %s" % (path, exc)) from exc


def describe(signals: Sequence[Signal]) -> str:
    """One line per signal (for logs and the docs' examples)."""
    out = []
    for s in signals:
        where = "byte %d" % s.byte + (" bit %d" % s.bit if s.bit is not None else "")
        out.append("%-20s %-3s %-7s %s%s" % (s.name, s.direction, s.type, where,
                                             "  safe %s" % s.format(s.safe) if s.is_output else ""))
    return "\n".join(out)
