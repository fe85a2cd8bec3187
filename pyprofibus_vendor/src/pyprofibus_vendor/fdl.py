"""FDL (layer 2) telegrams of PROFIBUS: encode, decode, stream deframing, FCB/FCV.

Telegram layouts (all bytes; ED = 0x16; FCS = sum of the bytes from DA through
the last data byte, modulo 256)::

    SD1  10 DA SA FC FCS ED                                   6 bytes, no data
    SD2  68 LE LEr 68 DA SA FC [DAE] [SAE] DU... FCS ED        LE + 6 bytes
         LE = LEr = 3 + len(DU incl. DAE/SAE), 4 <= LE <= 249
    SD3  A2 DA SA FC DU(8, DAE/SAE included) FCS ED           14 bytes
    SD4  DC DA SA                                             3 bytes (token)
    SC   E5                                                   1 byte (short acknowledge)

Addresses are 0..126, 127 is broadcast (destination only). Bit 7 of DA (SA)
set means a destination (source) address extension byte leads the data unit,
DAE before SAE. Extension byte: bit 7 "another extension follows", bit 6
"segment address", bits 5..0 the SAP (0..63). Only plain SAP extensions are
supported (the only kind DP uses); the others raise :class:`FrameError`.

Frame control (FC) byte::

    bit 7     reserved, 0
    bit 6     1 = request, 0 = response
    request:  bit 5 FCB, bit 4 FCV, bits 3..0 RequestFunction
    response: bits 5..4 StationType, bits 3..0 ResponseStatus

Everything that reads bytes raises a subclass of :class:`FrameError`
(:class:`FcsError`, :class:`TruncatedFrameError`) on malformed input.

FCB/FCV: :class:`FcbRequester` (one per requester->responder pair) toggles the
frame count bit per new request and keeps it for retries;
:class:`FcbResponder` recognises a repeated request (same FCB, FCV=1, same
source) and hands back the stored reply instead of executing twice.
"""
from __future__ import annotations

import enum
import logging
import time
from dataclasses import dataclass, field
from typing import Callable, Dict, List, Optional, Tuple, Union

from .errors import FcsError, FrameError, PhyError, TruncatedFrameError
from .phy import Link

__all__ = [
    "SD1", "SD2", "SD3", "SD4", "SC", "ED", "BROADCAST", "MAX_STATION", "DEFAULT_SLAVE_ADDRESS",
    "MAX_DU_LEN", "StartDelimiter", "FcBit", "RequestFunction", "ResponseStatus", "StationType",
    "FrameControl", "Sd1", "Sd2", "Sd3", "Sd4", "ShortAck", "Frame", "data_frame",
    "decode_frame", "frame_length", "fcs", "sd2_encode", "sd2_body", "sd2_data", "Deframer", "DeframerCounters",
    "FcbRequester", "FcbResponder", "RespondingLink",
]

log = logging.getLogger(__name__)


class StartDelimiter(enum.IntEnum):
    SD1 = 0x10
    SD2 = 0x68
    SD3 = 0xA2
    SD4 = 0xDC
    SC = 0xE5


SD1, SD2, SD3, SD4, SC = (StartDelimiter.SD1, StartDelimiter.SD2, StartDelimiter.SD3,
                          StartDelimiter.SD4, StartDelimiter.SC)
ED = 0x16
BROADCAST = 127
MAX_STATION = 126
DEFAULT_SLAVE_ADDRESS = 126
MAX_DU_LEN = 246          # data unit incl. DAE/SAE
_MIN_LE, _MAX_LE = 4, 249
_SD3_DU_LEN = 8
_EXT = 0x80               # address extension bit on DA/SA
_EXT_MORE = 0x80          # in an extension byte: another one follows
_EXT_SEGMENT = 0x40       # in an extension byte: segment address, not SAP


class FcBit(enum.IntFlag):
    """Bits of the FC byte."""

    RESERVED = 0x80
    REQUEST = 0x40
    FCB = 0x20
    FCV = 0x10


class RequestFunction(enum.IntEnum):
    """FC bits 3..0 of a request."""

    TIME_EVENT = 0x0
    SDA_LOW = 0x3
    SDN_LOW = 0x4
    SDA_HIGH = 0x5
    SDN_HIGH = 0x6
    MSRD = 0x7
    FDL_STATUS = 0x9
    SRD_LOW = 0xC
    SRD_HIGH = 0xD
    IDENT = 0xE
    LSAP_STATUS = 0xF


class ResponseStatus(enum.IntEnum):
    """FC bits 3..0 of a response (acknowledgement / reply status)."""

    OK = 0x0   # positive acknowledgement
    UE = 0x1   # user error
    RR = 0x2   # no resources
    RS = 0x3   # SAP not activated
    DL = 0x8   # response data low
    NR = 0x9   # no response data
    DH = 0xA   # response data high (diagnosis pending)
    RDL = 0xC  # response data low, no resource for send data
    RDH = 0xD  # response data high, no resource for send data


class StationType(enum.IntEnum):
    """FC bits 5..4 of a response."""

    SLAVE = 0
    MASTER_NOT_READY = 1
    MASTER_READY = 2
    MASTER_IN_RING = 3


def _check_address(value: int, what: str, allow_broadcast: bool) -> None:
    top = BROADCAST if allow_broadcast else MAX_STATION
    if not isinstance(value, int) or not 0 <= value <= top:
        raise FrameError(f"{what} {value!r} out of range 0..{top}")


def _check_sap(value: Optional[int], what: str) -> None:
    if value is not None and (not isinstance(value, int) or not 0 <= value <= 63):
        raise FrameError(f"{what} {value!r} out of range 0..63")


def fcs(data: bytes) -> int:
    """Frame check sequence: arithmetic sum of ``data`` modulo 256."""
    return sum(data) & 0xFF


@dataclass(frozen=True)
class FrameControl:
    """The FC byte, decoded.

    For a request ``code`` is a :class:`RequestFunction` and ``fcb``/``fcv``
    are meaningful; for a response ``code`` is a :class:`ResponseStatus` and
    ``station_type`` is meaningful. Build with :meth:`req` / :meth:`resp`.
    """

    request: bool
    code: int
    fcb: bool = False
    fcv: bool = False
    station_type: StationType = StationType.SLAVE

    def __post_init__(self) -> None:
        enum_cls = RequestFunction if self.request else ResponseStatus
        try:
            object.__setattr__(self, "code", enum_cls(self.code))
            object.__setattr__(self, "station_type", StationType(self.station_type))
        except ValueError as exc:
            raise FrameError(f"invalid FC code {self.code!r} for a "
                             f"{'request' if self.request else 'response'}") from exc
        if not self.request and (self.fcb or self.fcv):
            raise FrameError("FCB/FCV only exist in requests")

    @classmethod
    def req(cls, function: int, fcb: bool = False, fcv: bool = False) -> "FrameControl":
        key = (True, function, bool(fcb), bool(fcv))
        fc = _FC_MADE.get(key) if cls is FrameControl else None
        if fc is None:
            fc = cls(True, function, fcb=bool(fcb), fcv=bool(fcv))
            if cls is FrameControl:
                _FC_MADE[key] = fc
        return fc

    @classmethod
    def resp(cls, status: int, station_type: int = StationType.SLAVE) -> "FrameControl":
        key = (False, status, station_type)
        fc = _FC_MADE.get(key) if cls is FrameControl else None
        if fc is None:
            fc = cls(False, status, station_type=StationType(station_type))
            if cls is FrameControl:
                _FC_MADE[key] = fc
        return fc

    @property
    def function(self) -> RequestFunction:
        if not self.request:
            raise FrameError("a response FC has no request function")
        return RequestFunction(self.code)

    @property
    def status(self) -> ResponseStatus:
        if self.request:
            raise FrameError("a request FC has no response status")
        return ResponseStatus(self.code)

    def encode(self) -> int:
        # plain ints: IntFlag arithmetic costs microseconds and this runs for every telegram
        if self.request:
            return (0x40 | (0x20 if self.fcb else 0) | (0x10 if self.fcv else 0)
                    | int(self.code))
        return (int(self.station_type) << 4) | int(self.code)

    @classmethod
    def decode(cls, byte: int) -> "FrameControl":
        if cls is FrameControl and type(byte) is int:
            fc = _FC_DECODED.get(byte)
            if fc is not None:
                return fc
        if not 0 <= byte <= 0xFF:
            raise FrameError(f"FC {byte!r} is not a byte")
        if byte & FcBit.RESERVED:
            raise FrameError(f"FC 0x{byte:02X}: reserved bit 7 set")
        if byte & FcBit.REQUEST:
            fc = cls(True, byte & 0x0F, fcb=bool(byte & FcBit.FCB), fcv=bool(byte & FcBit.FCV))
        else:
            fc = cls(False, byte & 0x0F, station_type=StationType((byte >> 4) & 0x03))
        if cls is FrameControl and type(byte) is int:
            _FC_DECODED[byte] = fc
        return fc

    def __str__(self) -> str:
        if self.request:
            return (f"{RequestFunction(self.code).name}"
                    f"(FCB={int(self.fcb)},FCV={int(self.fcv)})")
        return f"{ResponseStatus(self.code).name}({self.station_type.name})"


# FrameControl is immutable: the valid ones are made once (decode / req / resp are hot paths)
_FC_DECODED: Dict[int, FrameControl] = {}
_FC_MADE: Dict[tuple, FrameControl] = {}


# -- frames --------------------------------------------------------------------------


@dataclass(frozen=True)
class Sd1:
    """Fixed length telegram without data: ``10 DA SA FC FCS ED``."""

    da: int
    sa: int
    fc: FrameControl

    SD = StartDelimiter.SD1
    LENGTH = 6

    def __post_init__(self) -> None:
        _check_address(self.da, "DA", True)
        _check_address(self.sa, "SA", False)
        if not isinstance(self.fc, FrameControl):
            raise FrameError(f"fc must be a FrameControl, not {type(self.fc).__name__}")

    def encode(self) -> bytes:
        body = bytes((self.da, self.sa, self.fc.encode()))
        return bytes((SD1,)) + body + bytes((fcs(body), ED))

    @classmethod
    def decode(cls, data: bytes) -> "Sd1":
        data = bytes(data)
        _expect_sd(data, SD1)
        _expect_len(data, cls.LENGTH)
        _check_tail(data, 1, 4)
        da, sa = data[1], data[2]
        if (da | sa) & _EXT:
            raise FrameError("SD1 with address extension bit set (no data unit to hold it)")
        if sa == BROADCAST:
            raise FrameError("SA 127 (broadcast) is not a valid source address")
        return cls(da, sa, FrameControl.decode(data[3]))


@dataclass(frozen=True)
class _DataFrame:
    """Common part of SD2 and SD3: addresses, FC, optional SAPs and data."""

    da: int
    sa: int
    fc: FrameControl
    data: bytes = b""
    dsap: Optional[int] = None
    ssap: Optional[int] = None

    def __post_init__(self) -> None:
        _check_address(self.da, "DA", True)
        _check_address(self.sa, "SA", False)
        _check_sap(self.dsap, "DSAP")
        _check_sap(self.ssap, "SSAP")
        if not isinstance(self.fc, FrameControl):
            raise FrameError(f"fc must be a FrameControl, not {type(self.fc).__name__}")
        object.__setattr__(self, "data", bytes(self.data))

    @property
    def du(self) -> bytes:
        """The data unit as sent: [DAE] [SAE] data."""
        ext = bytes(s for s in (self.dsap, self.ssap) if s is not None)
        return ext + self.data

    def _body(self) -> bytes:
        da = self.da | (_EXT if self.dsap is not None else 0)
        sa = self.sa | (_EXT if self.ssap is not None else 0)
        return bytes((da, sa, self.fc.encode())) + self.du

    @staticmethod
    def _parse_body(body: bytes) -> Tuple[int, int, FrameControl, bytes, Optional[int], Optional[int]]:
        da, sa, fcb = body[0], body[1], body[2]
        du = body[3:]
        dsap = ssap = None
        pos = 0
        for is_dest, raw in ((True, da), (False, sa)):
            if not raw & _EXT:
                continue
            if pos >= len(du):
                raise FrameError("address extension bit set but the data unit is too short")
            ext = du[pos]
            pos += 1
            if ext & _EXT_MORE:
                raise FrameError(f"chained address extension 0x{ext:02X} not supported")
            if ext & _EXT_SEGMENT:
                raise FrameError(f"segment address extension 0x{ext:02X} not supported")
            if is_dest:
                dsap = ext & 0x3F
            else:
                ssap = ext & 0x3F
        if sa & 0x7F == BROADCAST:
            raise FrameError("SA 127 (broadcast) is not a valid source address")
        return da & 0x7F, sa & 0x7F, FrameControl.decode(fcb), du[pos:], dsap, ssap


# -- the SD2 codec: bytes level, shared by Sd2 and the DP master's Data_Exchange fast path --------

def sd2_encode(da: int, sa: int, fc: int, du: bytes) -> bytes:
    """The SD2 telegram ``68 LE LE 68 DA SA FC DU FCS 16`` from its raw header bytes (DA and SA
    with their extension bits, the FC byte) and data unit (DAE / SAE included).

    No checks: :class:`Sd2` validated the fields, the master built them; a data unit of 1..246
    bytes and header bytes 0..255 give a valid telegram."""
    le = len(du) + 3
    return bytes((0x68, le, le, 0x68, da, sa, fc)) + du + bytes(((da + sa + fc + sum(du)) & 0xFF, 0x16))


def sd2_body(data: bytes) -> bytes:
    """The body ``DA SA FC DU`` of ``data``, one complete SD2 telegram, after checking its framing
    (start delimiters, LE = LEr within 4..249, exact length, FCS, ED). Raises
    :class:`TruncatedFrameError`, :class:`FcsError` or :class:`FrameError`."""
    _expect_sd(data, SD2)
    if len(data) < 4:
        raise TruncatedFrameError(f"SD2 header needs 4 bytes, got {len(data)}")
    le, ler = data[1], data[2]
    if le != ler:
        raise FrameError(f"SD2 LE 0x{le:02X} != LEr 0x{ler:02X}")
    if not _MIN_LE <= le <= _MAX_LE:
        raise FrameError(f"SD2 LE {le} not in {_MIN_LE}..{_MAX_LE}")
    if data[3] != SD2:
        raise FrameError(f"SD2 repeated start delimiter is 0x{data[3]:02X}, not 0x68")
    _expect_len(data, le + 6)
    _check_tail(data, 4, 4 + le)
    return data[4:4 + le]


def sd2_data(data: bytes, da: int, sa: int, fc: int) -> Optional[bytes]:
    """The data unit of ``data`` if it is exactly one valid SD2 telegram (the framing checks of
    :func:`sd2_body`) whose raw DA, SA and FC bytes are ``da``, ``sa`` and ``fc``; else None.

    The receive fast path: one pass of comparisons, no exception and no objects, for a caller
    that knows which reply it expects (e.g. the master's Data_Exchange: no SAPs, FC DL). Anything
    else -- None -- goes through the :class:`Deframer` and :class:`Sd2` with their errors."""
    le = len(data) - 6        # 0x68 = SD2, 0x16 = ED as plain ints: cheaper to compare than the enum
    if (not _MIN_LE <= le <= _MAX_LE or data[1] != le or data[2] != le or data[4] != da or data[5] != sa
            or data[6] != fc or data[0] != 0x68 or data[3] != 0x68 or data[-1] != 0x16
            or (sum(data[4:-2]) & 0xFF) != data[-2]):
        return None
    return bytes(data[7:-2])


@dataclass(frozen=True)
class Sd2(_DataFrame):
    """Variable length telegram: ``68 LE LEr 68 DA SA FC [DAE][SAE] data FCS 16``."""

    SD = StartDelimiter.SD2

    def __post_init__(self) -> None:
        super().__post_init__()
        n = len(self.du)
        if not 1 <= n <= MAX_DU_LEN:
            raise FrameError(f"SD2 data unit length {n} not in 1..{MAX_DU_LEN}")

    def encode(self) -> bytes:
        da = self.da | (_EXT if self.dsap is not None else 0)
        sa = self.sa | (_EXT if self.ssap is not None else 0)
        return sd2_encode(da, sa, self.fc.encode(), self.du)

    @classmethod
    def decode(cls, data: bytes) -> "Sd2":
        return cls(*cls._parse_body(sd2_body(bytes(data))))


@dataclass(frozen=True)
class Sd3(_DataFrame):
    """Fixed length telegram with 8 data unit bytes: ``A2 DA SA FC DU(8) FCS 16``."""

    SD = StartDelimiter.SD3
    LENGTH = 14

    def __post_init__(self) -> None:
        super().__post_init__()
        if len(self.du) != _SD3_DU_LEN:
            raise FrameError(f"SD3 data unit must be {_SD3_DU_LEN} bytes, got {len(self.du)}")

    def encode(self) -> bytes:
        body = self._body()
        return bytes((SD3,)) + body + bytes((fcs(body), ED))

    @classmethod
    def decode(cls, data: bytes) -> "Sd3":
        data = bytes(data)
        _expect_sd(data, SD3)
        _expect_len(data, cls.LENGTH)
        _check_tail(data, 1, 12)
        return cls(*cls._parse_body(data[1:12]))


@dataclass(frozen=True)
class Sd4:
    """Token telegram: ``DC DA SA``."""

    da: int
    sa: int

    SD = StartDelimiter.SD4
    LENGTH = 3

    def __post_init__(self) -> None:
        _check_address(self.da, "token DA", False)
        _check_address(self.sa, "token SA", False)

    def encode(self) -> bytes:
        return bytes((SD4, self.da, self.sa))

    @classmethod
    def decode(cls, data: bytes) -> "Sd4":
        data = bytes(data)
        _expect_sd(data, SD4)
        _expect_len(data, cls.LENGTH)
        if data[1] > MAX_STATION or data[2] > MAX_STATION:
            raise FrameError(f"token addresses {data[1]}/{data[2]} out of range 0..{MAX_STATION}")
        return cls(data[1], data[2])


@dataclass(frozen=True)
class ShortAck:
    """Short acknowledge: the single byte ``E5``."""

    SD = StartDelimiter.SC
    LENGTH = 1

    def encode(self) -> bytes:
        return bytes((SC,))

    @classmethod
    def decode(cls, data: bytes) -> "ShortAck":
        data = bytes(data)
        _expect_sd(data, SC)
        _expect_len(data, cls.LENGTH)
        return cls()


Frame = Union[Sd1, Sd2, Sd3, Sd4, ShortAck]


def _expect_sd(data: bytes, sd: int) -> None:
    if not data:
        raise TruncatedFrameError("empty telegram")
    if data[0] != sd:
        raise FrameError(f"start delimiter 0x{data[0]:02X}, expected 0x{sd:02X}")


def _expect_len(data: bytes, n: int) -> None:
    if len(data) < n:
        raise TruncatedFrameError(f"telegram truncated: {len(data)} of {n} bytes")
    if len(data) > n:
        raise FrameError(f"{len(data) - n} trailing bytes after a {n}-byte telegram")


def _check_tail(data: bytes, start: int, end: int) -> None:
    """Check FCS over data[start:end] (the byte at ``end``) and ED after it."""
    if data[end + 1] != ED:
        raise FrameError(f"end delimiter 0x{data[end + 1]:02X}, expected 0x16")
    want = fcs(data[start:end])
    if data[end] != want:
        raise FcsError(f"FCS 0x{data[end]:02X}, computed 0x{want:02X}")


def data_frame(da: int, sa: int, fc: FrameControl, data: bytes = b"",
               dsap: Optional[int] = None, ssap: Optional[int] = None) -> Frame:
    """The frame type the standard prescribes for this content.

    Empty data unit -> SD1, exactly 8 data unit bytes (SAP bytes included) ->
    SD3, otherwise SD2.
    """
    n = len(data) + (dsap is not None) + (ssap is not None)
    if n == 0:
        return Sd1(da, sa, fc)
    if n == _SD3_DU_LEN:
        return Sd3(da, sa, fc, bytes(data), dsap, ssap)
    return Sd2(da, sa, fc, bytes(data), dsap, ssap)


_FIXED_LEN = {SD1: Sd1.LENGTH, SD3: Sd3.LENGTH, SD4: Sd4.LENGTH, SC: ShortAck.LENGTH}
_DECODERS: Dict[int, Callable[[bytes], Frame]] = {
    SD1: Sd1.decode, SD2: Sd2.decode, SD3: Sd3.decode, SD4: Sd4.decode, SC: ShortAck.decode,
}


def frame_length(head: bytes) -> Optional[int]:
    """Total length of the telegram starting at ``head[0]``.

    Returns ``None`` when more header bytes are needed (SD2 needs 4). Raises
    :class:`FrameError` for an unknown start delimiter or an invalid SD2 header.
    """
    if not head:
        return None
    sd = head[0]
    if sd in _FIXED_LEN:
        return _FIXED_LEN[sd]
    if sd != SD2:
        raise FrameError(f"unknown start delimiter 0x{sd:02X}")
    if len(head) < 4:
        return None
    le, ler = head[1], head[2]
    if le != ler:
        raise FrameError(f"SD2 LE 0x{le:02X} != LEr 0x{ler:02X}")
    if not _MIN_LE <= le <= _MAX_LE:
        raise FrameError(f"SD2 LE {le} not in {_MIN_LE}..{_MAX_LE}")
    if head[3] != SD2:
        raise FrameError(f"SD2 repeated start delimiter is 0x{head[3]:02X}, not 0x68")
    return le + 6


def decode_frame(data: bytes) -> Frame:
    """Decode exactly one complete telegram of any type."""
    data = bytes(data)
    if not data:
        raise TruncatedFrameError("empty telegram")
    decoder = _DECODERS.get(data[0])
    if decoder is None:
        raise FrameError(f"unknown start delimiter 0x{data[0]:02X}")
    return decoder(data)


# -- stream deframing ------------------------------------------------------------


@dataclass
class DeframerCounters:
    frames: int = 0          # complete, valid telegrams returned
    garbage_bytes: int = 0   # bytes discarded while searching for a telegram
    fcs_errors: int = 0      # candidate telegrams whose FCS was wrong
    format_errors: int = 0   # candidates with a bad LE/LEr/ED/address/FC...


class Deframer:
    """Cut a byte stream (arriving in arbitrary chunks) into telegrams.

    :meth:`feed` returns every telegram completed by the new bytes. When the
    bytes at the head of the buffer do not form a valid telegram, the first byte
    is discarded and the search restarts at the next one (resynchronisation);
    :attr:`counters` says what was thrown away and why. :meth:`discard_partial`
    drops an incomplete telegram (call it when the line went idle).
    """

    MAX_BUFFER = 4096

    def __init__(self) -> None:
        self._buf = bytearray()
        self.counters = DeframerCounters()
        self.last_error: Optional[FrameError] = None

    @property
    def pending(self) -> int:
        """Number of buffered bytes that do not yet form a telegram."""
        return len(self._buf)

    def reset(self) -> None:
        """Forget buffered bytes without counting them (e.g. before a new request)."""
        self._buf.clear()

    def head(self, n: int) -> bytes:
        """The first ``n`` buffered bytes (of the telegram being received)."""
        return bytes(self._buf[:n])

    def bytes_needed(self) -> Optional[int]:
        """Bytes still missing for the telegram being received (0: none
        started; None: not known yet, an SD2 header is incomplete)."""
        if not self._buf:
            return 0
        try:
            n = frame_length(self._buf[:4])
        except FrameError:
            return 0
        return None if n is None else max(0, n - len(self._buf))

    def discard_partial(self) -> int:
        """Drop buffered bytes of an incomplete telegram; count them as garbage."""
        n = len(self._buf)
        self.counters.garbage_bytes += n
        self._buf.clear()
        return n

    def _skip(self, err: Optional[FrameError]) -> None:
        self.counters.garbage_bytes += 1
        del self._buf[0]
        if err is not None:
            self.last_error = err
            if isinstance(err, FcsError):
                self.counters.fcs_errors += 1
            else:
                self.counters.format_errors += 1
            log.debug("deframer: discarding byte, %s", err)

    def feed(self, chunk: bytes) -> List[Frame]:
        self._buf += chunk
        out: List[Frame] = []
        while self._buf:
            try:
                n = frame_length(self._buf[:4])
            except FrameError as err:
                # an unknown SD is plain garbage; a bad SD2 header is a format error
                self._skip(err if self._buf[0] == SD2 else None)
                continue
            if n is None or len(self._buf) < n:
                break
            try:
                frame = decode_frame(bytes(self._buf[:n]))
            except FrameError as err:
                self._skip(err)
                continue
            del self._buf[:n]
            self.counters.frames += 1
            out.append(frame)
        if len(self._buf) > self.MAX_BUFFER:  # cannot happen with valid LE; defensive
            self.discard_partial()
        return out


# -- FCB / FCV ---------------------------------------------------------------------


class FcbRequester:
    """Frame count bit state of one requester towards one responder.

    The first request after (re)start carries FCB=1, FCV=0. After each good
    reply call :meth:`acknowledge`: the next request toggles FCB with FCV=1. A
    retry (no reply) simply uses :meth:`bits` again, i.e. the same FCB.
    """

    def __init__(self) -> None:
        self._fcb = True
        self._fcv = False

    def reset(self) -> None:
        self._fcb, self._fcv = True, False

    def bits(self) -> Tuple[bool, bool]:
        """``(fcb, fcv)`` for the current (new or repeated) request."""
        return self._fcb, self._fcv

    def fc(self, function: int) -> FrameControl:
        return FrameControl.req(function, fcb=self._fcb, fcv=self._fcv)

    def acknowledge(self) -> None:
        """A reply to the current request arrived: advance to the next FCB."""
        self._fcb = not self._fcb
        self._fcv = True


@dataclass
class _Remembered:
    fcb: bool
    reply: Optional[Frame]


@dataclass
class FcbResponder:
    """Duplicate detection on the responder side, per requesting station.

    :meth:`handle` executes a request through ``execute`` unless it is a
    repetition (FCV=1 and the same FCB as the previous request of that
    source), in which case the stored reply is returned and ``execute`` is not
    called. ``duplicates`` counts the repetitions served.
    """

    duplicates: int = 0
    _last: Dict[int, _Remembered] = field(default_factory=dict)

    def is_repeat(self, sa: int, fc: FrameControl) -> bool:
        prev = self._last.get(sa)
        return bool(fc.fcv and prev is not None and prev.fcb == fc.fcb)

    def handle(self, sa: int, fc: FrameControl,
               execute: Callable[[], Optional[Frame]]) -> Optional[Frame]:
        if self.is_repeat(sa, fc):
            self.duplicates += 1
            return self._last[sa].reply
        reply = execute()
        self._last[sa] = _Remembered(fc.fcb, reply)
        return reply

    def forget(self, sa: Optional[int] = None) -> None:
        if sa is None:
            self._last.clear()
        else:
            self._last.pop(sa, None)


class RespondingLink(Link):
    """A thread-free in-process link whose far end answers frames synchronously.

    Bytes sent are deframed; each complete frame goes to :meth:`respond`, and the bytes it returns
    (if any) become readable by :meth:`recv`. Subclasses define ``respond``. With nothing buffered,
    ``recv`` returns ``b""`` at once unless ``wait_when_empty`` is set, in which case it lets the
    timeout pass first (nothing else could produce bytes meanwhile); ``timeout=None`` would wait
    for ever and raises :class:`PhyError` instead.
    """

    wait_when_empty = False

    def __init__(self, name: str = "responding link") -> None:
        self.name = name
        self.deframer = Deframer()
        self._rx = bytearray()
        self._closed = False

    def respond(self, frame: Frame) -> Optional[bytes]:  # pragma: no cover - abstract
        raise NotImplementedError

    def send(self, data: bytes) -> None:
        if self._closed:
            raise PhyError("%s closed" % self.name)
        for frame in self.deframer.feed(bytes(data)):
            reply = self.respond(frame)
            if reply:
                self._rx += reply

    def recv(self, max_bytes: int = 4096, timeout: Optional[float] = 0.0) -> bytes:
        if self._closed:
            raise PhyError("%s closed" % self.name)
        if not self._rx:
            if not self.wait_when_empty:
                return b""
            if timeout is None:
                raise PhyError("%s: recv(timeout=None) with nothing to receive" % self.name)
            if timeout > 0:
                time.sleep(timeout)  # nothing can arrive: a blocking read just times out
            return b""
        out = bytes(self._rx[:max_bytes])
        del self._rx[:max_bytes]
        return out

    def flush_input(self) -> None:
        self._rx.clear()

    def close(self) -> None:
        self._closed = True

    @property
    def closed(self) -> bool:
        return self._closed
