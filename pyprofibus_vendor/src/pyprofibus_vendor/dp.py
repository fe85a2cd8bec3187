"""DP-V0 services (layer 7 of PROFIBUS-DP) carried in FDL telegrams.

Each service runs on a slave SAP; the master uses SSAP 62. A request is an SRD
(high) telegram ``DA|0x80 SA|0x80 FC DSAP=service SSAP=62 payload``; the reply
swaps the SAPs (DSAP 62, SSAP = service). Data_Exchange uses the default SAP
(no extension bytes).

=====  ================  ===============================================  =================
SAP    service           request payload                                  reply
=====  ================  ===============================================  =================
55     Set_Slave_Add     new_addr, ident_hi, ident_lo, No_Add_Chg, [rem]  SC
56     Rd_Inp            --                                               input bytes
57     Rd_Outp           --                                               output bytes
58     Global_Control    Control_Command, Group_Select (SDN, no reply)    --
59     Get_Cfg           --                                               cfg bytes
60     Slave_Diag        --                                               >= 6 diag bytes
61     Set_Prm           see :class:`SetPrm`                              SC
62     Chk_Cfg           cfg bytes                                        SC
--     Data_Exchange     output bytes (master -> slave)                   input bytes (DL/DH)
=====  ================  ===============================================  =================

Slave_Diag payload::

    0  station status 1  (DiagStatus1)
    1  station status 2  (DiagStatus2, bit 2 always 1)
    2  station status 3  (DiagStatus3)
    3  master address    (0xFF: not parameterised)
    4  ident number high
    5  ident number low
    6… extended diagnosis blocks (header bits 7..6: 00 device, 01 identifier,
       10 channel; device/identifier: bits 5..0 = block length incl. header;
       channel blocks are 3 bytes)

Set_Prm payload::

    0  station status (PrmStationStatus: WD_On, Freeze_Req, Sync_Req, Unlock_Req, Lock_Req)
    1  WD_Fact_1 (1..255)      watchdog = 10 ms * WD_Fact_1 * WD_Fact_2
    2  WD_Fact_2 (1..255)
    3  min TSDR in bit times (0 = keep)
    4  ident high   5  ident low
    6  Group_Ident (bit n = group n+1)
    7… User_Prm_Data (<= 237 bytes)

"Input" means slave -> master and "output" master -> slave (master-centric).
Every ``decode`` raises :class:`DpError` (or ``FrameError`` for FDL problems)
on malformed input.
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import List, Optional, Tuple

from .errors import ConfigError, DpError
from .fdl import (BROADCAST, Frame, FrameControl, RequestFunction, ResponseStatus, ShortAck,
                  data_frame)

__all__ = [
    "Sap", "MASTER_SAP", "MAX_USER_DATA", "MAX_DIAG_LEN", "MAX_USER_PRM_LEN",
    "DiagStatus1", "DiagStatus2", "DiagStatus3", "PrmStationStatus", "GcCommand",
    "SlaveDiag", "ExtDiagBlock", "parse_ext_diag", "explain_diag",
    "SetPrm", "ChkCfg", "GetCfg", "DataExchange", "GlobalControl", "SetSlaveAdd",
    "cfg_io_lengths", "watchdog_factors", "request_frame", "reply_frame", "short_ack",
]

MASTER_SAP = 62
MAX_USER_DATA = 244
MAX_DIAG_LEN = 244
MAX_USER_PRM_LEN = 237


class Sap(enum.IntEnum):
    """Service access points of a DP-V0 slave."""

    SET_SLAVE_ADD = 55
    RD_INP = 56
    RD_OUTP = 57
    GLOBAL_CONTROL = 58
    GET_CFG = 59
    SLAVE_DIAG = 60
    SET_PRM = 61
    CHK_CFG = 62


class DiagStatus1(enum.IntFlag):
    STATION_NON_EXISTENT = 0x01   # set by the master
    STATION_NOT_READY = 0x02
    CFG_FAULT = 0x04
    EXT_DIAG = 0x08
    NOT_SUPPORTED = 0x10
    INVALID_SLAVE_RESPONSE = 0x20  # set by the master
    PRM_FAULT = 0x40
    MASTER_LOCK = 0x80            # set by the master (byte 4 names another master)


class DiagStatus2(enum.IntFlag):
    PRM_REQ = 0x01
    STAT_DIAG = 0x02
    ALWAYS_ONE = 0x04
    WD_ON = 0x08
    FREEZE_MODE = 0x10
    SYNC_MODE = 0x20
    RESERVED = 0x40
    DEACTIVATED = 0x80            # set by the master


class DiagStatus3(enum.IntFlag):
    EXT_DIAG_OVERFLOW = 0x80


class PrmStationStatus(enum.IntFlag):
    """Byte 1 of Set_Prm."""

    WD_ON = 0x08
    FREEZE_REQ = 0x10
    SYNC_REQ = 0x20
    UNLOCK_REQ = 0x40
    LOCK_REQ = 0x80


class GcCommand(enum.IntFlag):
    """Control_Command of Global_Control."""

    CLEAR_DATA = 0x02
    UNFREEZE = 0x04
    FREEZE = 0x08
    UNSYNC = 0x10
    SYNC = 0x20


_DIAG_WORDS = {
    "STATION_NON_EXISTENT": "station does not exist",
    "STATION_NOT_READY": "station not ready for data exchange",
    "CFG_FAULT": "configuration fault (Chk_Cfg bytes rejected)",
    "EXT_DIAG": "extended diagnosis present",
    "NOT_SUPPORTED": "requested function not supported",
    "INVALID_SLAVE_RESPONSE": "invalid slave response",
    "PRM_FAULT": "parameter fault (Set_Prm rejected: wrong ident or parameters)",
    "MASTER_LOCK": "locked by another master",
    "PRM_REQ": "slave requests new parameters",
    "STAT_DIAG": "static diagnosis (keep reading diag)",
    "WD_ON": "watchdog on",
    "FREEZE_MODE": "freeze mode",
    "SYNC_MODE": "sync mode",
    "DEACTIVATED": "slave deactivated",
    "EXT_DIAG_OVERFLOW": "extended diagnosis overflow",
}


def _flag_words(flags: enum.IntFlag, enum_cls: type) -> List[str]:
    return [_DIAG_WORDS[m.name] for m in enum_cls if m.name in _DIAG_WORDS and flags & m]


@dataclass(frozen=True)
class ExtDiagBlock:
    """One extended diagnosis block: ``kind`` is 'device', 'identifier' or 'channel'."""

    kind: str
    data: bytes


def parse_ext_diag(data: bytes) -> List[ExtDiagBlock]:
    """Split extended diagnosis bytes into blocks. Raises DpError on a bad header."""
    blocks: List[ExtDiagBlock] = []
    pos = 0
    while pos < len(data):
        head = data[pos]
        kind_bits = head >> 6
        if kind_bits == 0b10:
            n = 3
            kind = "channel"
        elif kind_bits in (0b00, 0b01):
            n = head & 0x3F
            kind = "device" if kind_bits == 0 else "identifier"
            if n < 1:
                raise DpError(f"ext diag block header 0x{head:02X} at {pos}: length 0")
        else:
            raise DpError(f"ext diag block header 0x{head:02X} at {pos}: reserved type")
        if pos + n > len(data):
            raise DpError(f"ext diag block at {pos} needs {n} bytes, {len(data) - pos} left")
        blocks.append(ExtDiagBlock(kind, bytes(data[pos:pos + n])))
        pos += n
    return blocks


@dataclass(frozen=True)
class SlaveDiag:
    """Slave_Diag response payload (layout in the module docstring)."""

    status1: DiagStatus1 = DiagStatus1(0)
    status2: DiagStatus2 = DiagStatus2.ALWAYS_ONE
    status3: DiagStatus3 = DiagStatus3(0)
    master_address: int = 0xFF
    ident: int = 0
    ext_diag: bytes = b""

    def __post_init__(self) -> None:
        for name, cls in (("status1", DiagStatus1), ("status2", DiagStatus2),
                          ("status3", DiagStatus3)):
            v = int(getattr(self, name))
            if not 0 <= v <= 0xFF:
                raise DpError(f"diag {name} {v} is not a byte")
            object.__setattr__(self, name, cls(v))
        if not 0 <= self.master_address <= 0xFF:
            raise DpError(f"diag master address {self.master_address} is not a byte")
        if not 0 <= self.ident <= 0xFFFF:
            raise DpError(f"ident 0x{self.ident:X} out of range")
        object.__setattr__(self, "ext_diag", bytes(self.ext_diag))
        if 6 + len(self.ext_diag) > MAX_DIAG_LEN:
            raise DpError(f"diag longer than {MAX_DIAG_LEN} bytes")

    def encode(self) -> bytes:
        return bytes((int(self.status1), int(self.status2), int(self.status3),
                      self.master_address, self.ident >> 8, self.ident & 0xFF)) + self.ext_diag

    @classmethod
    def decode(cls, data: bytes) -> "SlaveDiag":
        data = bytes(data)
        if len(data) < 6:
            raise DpError(f"Slave_Diag needs at least 6 bytes, got {len(data)}")
        if len(data) > MAX_DIAG_LEN:
            raise DpError(f"Slave_Diag of {len(data)} bytes exceeds {MAX_DIAG_LEN}")
        return cls(DiagStatus1(data[0]), DiagStatus2(data[1]), DiagStatus3(data[2]),
                   data[3], (data[4] << 8) | data[5], data[6:])

    @property
    def locked_by(self) -> Optional[int]:
        """Address of the master that parameterised the slave, or None."""
        return None if self.master_address == 0xFF else self.master_address

    def ready_for(self, master_address: int) -> bool:
        """True when the slave is ready for Data_Exchange with this master."""
        bad1 = (DiagStatus1.STATION_NOT_READY | DiagStatus1.CFG_FAULT | DiagStatus1.PRM_FAULT
                | DiagStatus1.NOT_SUPPORTED | DiagStatus1.STATION_NON_EXISTENT)
        bad2 = DiagStatus2.PRM_REQ | DiagStatus2.STAT_DIAG | DiagStatus2.DEACTIVATED
        return (not (self.status1 & bad1) and not (self.status2 & bad2)
                and self.master_address == master_address)

    def words(self, master_address: Optional[int] = None) -> List[str]:
        """The set bits in words. With ``master_address`` the master-side
        Master_Lock (byte 4 names another master) is derived, too."""
        out = _flag_words(self.status1, DiagStatus1)
        if (master_address is not None and self.locked_by not in (None, master_address)
                and not self.status1 & DiagStatus1.MASTER_LOCK):
            out.append(f"locked by another master ({self.master_address})")
        if not self.status2 & DiagStatus2.ALWAYS_ONE:
            out.append("always-one bit of byte 2 is clear (invalid diag)")
        out += _flag_words(self.status2, DiagStatus2)
        out += _flag_words(self.status3, DiagStatus3)
        return out


def explain_diag(diag: SlaveDiag, master_address: Optional[int] = None) -> str:
    """One log line describing a Slave_Diag in words."""
    words = diag.words(master_address)
    owner = "none" if diag.locked_by is None else str(diag.locked_by)
    text = (f"ident 0x{diag.ident:04X}, master {owner}, "
            f"bytes {diag.encode()[:3].hex(' ')}: " + ("; ".join(words) if words else "ok"))
    if diag.ext_diag:
        try:
            blocks = parse_ext_diag(diag.ext_diag)
            text += "; ext diag: " + ", ".join(f"{b.kind} {b.data.hex(' ')}" for b in blocks)
        except DpError as err:
            text += f"; ext diag {diag.ext_diag.hex(' ')} (unparsable: {err})"
    return text


@dataclass(frozen=True)
class SetPrm:
    """Set_Prm request payload (layout in the module docstring)."""

    ident: int
    station_status: PrmStationStatus = PrmStationStatus.LOCK_REQ | PrmStationStatus.WD_ON
    wd_fact1: int = 30
    wd_fact2: int = 1
    min_tsdr: int = 0
    group_ident: int = 0
    user_prm_data: bytes = b""

    def __post_init__(self) -> None:
        object.__setattr__(self, "station_status", PrmStationStatus(int(self.station_status) & 0xFF))
        for name in ("wd_fact1", "wd_fact2", "min_tsdr", "group_ident"):
            v = getattr(self, name)
            if not isinstance(v, int) or not 0 <= v <= 0xFF:
                raise DpError(f"Set_Prm {name} {v!r} is not a byte")
        if not 0 <= self.ident <= 0xFFFF:
            raise DpError(f"Set_Prm ident 0x{self.ident:X} out of range")
        object.__setattr__(self, "user_prm_data", bytes(self.user_prm_data))
        if len(self.user_prm_data) > MAX_USER_PRM_LEN:
            raise DpError(f"User_Prm_Data of {len(self.user_prm_data)} bytes exceeds "
                          f"{MAX_USER_PRM_LEN}")

    @property
    def watchdog_time(self) -> Optional[float]:
        """Watchdog time in seconds, or None when WD_On is clear."""
        if not self.station_status & PrmStationStatus.WD_ON:
            return None
        return 0.01 * self.wd_fact1 * self.wd_fact2

    def encode(self) -> bytes:
        return bytes((int(self.station_status), self.wd_fact1, self.wd_fact2, self.min_tsdr,
                      self.ident >> 8, self.ident & 0xFF, self.group_ident)) + self.user_prm_data

    @classmethod
    def decode(cls, data: bytes) -> "SetPrm":
        data = bytes(data)
        if len(data) < 7:
            raise DpError(f"Set_Prm needs at least 7 bytes, got {len(data)}")
        return cls(ident=(data[4] << 8) | data[5], station_status=PrmStationStatus(data[0]),
                   wd_fact1=data[1], wd_fact2=data[2], min_tsdr=data[3], group_ident=data[6],
                   user_prm_data=data[7:])


def watchdog_factors(seconds: float) -> Tuple[int, int]:
    """WD_Fact_1, WD_Fact_2 (each 1..255) for the smallest watchdog >= ``seconds``
    with the 10 ms base. Raises ConfigError unless 0 < seconds <= 650.25."""
    units = math.ceil(round(seconds / 0.01, 6))
    if seconds <= 0 or not 1 <= units <= 255 * 255:
        raise ConfigError(f"watchdog time {seconds} s outside 0.01 .. 650.25 s")
    if units <= 255:
        return units, 1
    best: Optional[Tuple[int, int]] = None
    for f2 in range(math.ceil(units / 255), 256):
        f1 = math.ceil(units / f2)
        if f1 <= 255 and (best is None or f1 * f2 < best[0] * best[1]):
            best = (f1, f2)
            if f1 * f2 == units:
                break
    assert best is not None
    return best


def _check_cfg(cfg: bytes, what: str) -> bytes:
    cfg = bytes(cfg)
    if not 1 <= len(cfg) <= MAX_USER_DATA:
        raise DpError(f"{what}: {len(cfg)} cfg bytes, expected 1..{MAX_USER_DATA}")
    return cfg


@dataclass(frozen=True)
class ChkCfg:
    """Chk_Cfg request payload: the identifier bytes the master expects."""

    cfg: bytes

    def __post_init__(self) -> None:
        object.__setattr__(self, "cfg", _check_cfg(self.cfg, "Chk_Cfg"))

    def encode(self) -> bytes:
        return self.cfg

    @classmethod
    def decode(cls, data: bytes) -> "ChkCfg":
        return cls(bytes(data))


@dataclass(frozen=True)
class GetCfg:
    """Get_Cfg response payload: the identifier bytes the slave uses."""

    cfg: bytes

    def __post_init__(self) -> None:
        object.__setattr__(self, "cfg", _check_cfg(self.cfg, "Get_Cfg"))

    def encode(self) -> bytes:
        return self.cfg

    @classmethod
    def decode(cls, data: bytes) -> "GetCfg":
        return cls(bytes(data))


@dataclass(frozen=True)
class CfgIdentifier:
    """One decoded Cfg identifier (one byte in the general format; header + length/manufacturer
    bytes in the special format). Lengths are in bytes; input = slave -> master."""

    raw: bytes
    input_len: int
    output_len: int
    words: bool
    consistent: bool
    special: bool
    manufacturer_data: bytes = b""

    def describe(self) -> str:
        """Short human text, e.g. ``"in 4"``, ``"in/out 14 consistent"``, ``"empty slot"``."""
        if self.input_len and self.output_len and self.input_len == self.output_len and not self.special:
            text = "in/out %d" % self.input_len
        else:
            parts = []
            if self.output_len:
                parts.append("out %d" % self.output_len)
            if self.input_len:
                parts.append("in %d" % self.input_len)
            text = ", ".join(parts) if parts else "empty slot"
        if self.words:
            text += " (words)"
        if self.consistent:
            text += " consistent"
        if self.manufacturer_data:
            text += " +%d manufacturer bytes" % len(self.manufacturer_data)
        return text


def decode_cfg(cfg: bytes) -> Tuple[CfgIdentifier, ...]:
    """Split Chk_Cfg bytes into identifiers and decode each one.

    Raises DpError when a special-format identifier is cut short.
    """
    data = bytes(cfg)
    result = []
    pos = 0
    while pos < len(data):
        start = pos
        head = data[pos]
        pos += 1
        direction = (head >> 4) & 0x03
        if direction:  # general format
            units = (head & 0x0F) + 1
            words = bool(head & 0x40)
            length = units * 2 if words else units
            result.append(CfgIdentifier(
                raw=data[start:pos],
                input_len=length if direction in (1, 3) else 0,
                output_len=length if direction in (2, 3) else 0,
                words=words,
                consistent=bool(head & 0x80),
                special=False,
            ))
            continue
        # special format: 00 none, 01 input, 10 output, 11 output then input
        length_kinds = {0: (), 1: ("in",), 2: ("out",), 3: ("out", "in")}[head >> 6]
        n_manufacturer = head & 0x0F
        needed = len(length_kinds) + n_manufacturer
        if pos + needed > len(data):
            raise DpError(
                "Cfg identifier 0x%02X at offset %d needs %d more byte(s), only %d left"
                % (head, start, needed, len(data) - pos))
        lengths = {"in": 0, "out": 0}
        words = consistent = False
        for kind in length_kinds:
            byte = data[pos]
            pos += 1
            units = (byte & 0x3F) + 1
            lengths[kind] = units * 2 if byte & 0x40 else units
            words = words or bool(byte & 0x40)
            consistent = consistent or bool(byte & 0x80)
        manufacturer = data[pos:pos + n_manufacturer]
        pos += n_manufacturer
        result.append(CfgIdentifier(
            raw=data[start:pos],
            input_len=lengths["in"],
            output_len=lengths["out"],
            words=words,
            consistent=consistent,
            special=True,
            manufacturer_data=manufacturer,
        ))
    return tuple(result)


def cfg_io_lengths(cfg: bytes) -> Tuple[int, int]:
    """Total (input_len, output_len) in bytes described by Chk_Cfg bytes."""
    idents = decode_cfg(cfg)
    return sum(i.input_len for i in idents), sum(i.output_len for i in idents)


@dataclass(frozen=True)
class DataExchange:
    """Data_Exchange payload: outputs in the request, inputs in the reply."""

    data: bytes = b""

    def __post_init__(self) -> None:
        object.__setattr__(self, "data", bytes(self.data))
        if len(self.data) > MAX_USER_DATA:
            raise DpError(f"Data_Exchange of {len(self.data)} bytes exceeds {MAX_USER_DATA}")

    def encode(self) -> bytes:
        return self.data

    @classmethod
    def decode(cls, data: bytes) -> "DataExchange":
        return cls(bytes(data))


@dataclass(frozen=True)
class GlobalControl:
    """Global_Control payload: Control_Command, Group_Select (0 = all groups)."""

    command: GcCommand = GcCommand(0)
    group_select: int = 0

    def __post_init__(self) -> None:
        if not 0 <= int(self.command) <= 0xFF or not 0 <= self.group_select <= 0xFF:
            raise DpError("Global_Control command and group must be bytes")
        object.__setattr__(self, "command", GcCommand(int(self.command)))

    def addresses_group(self, group_ident: int) -> bool:
        """Whether a slave in ``group_ident`` (Set_Prm byte 7) is addressed."""
        return self.group_select == 0 or bool(self.group_select & group_ident)

    def encode(self) -> bytes:
        return bytes((int(self.command), self.group_select))

    @classmethod
    def decode(cls, data: bytes) -> "GlobalControl":
        data = bytes(data)
        if len(data) != 2:
            raise DpError(f"Global_Control needs 2 bytes, got {len(data)}")
        return cls(GcCommand(data[0]), data[1])


@dataclass(frozen=True)
class SetSlaveAdd:
    """Set_Slave_Add payload: new address, ident, No_Add_Chg, remaining data."""

    new_address: int
    ident: int
    no_add_chg: bool = False
    rem_data: bytes = b""

    def __post_init__(self) -> None:
        if not 0 <= self.new_address <= 125:
            raise DpError(f"new slave address {self.new_address} out of range 0..125")
        if not 0 <= self.ident <= 0xFFFF:
            raise DpError(f"ident 0x{self.ident:X} out of range")
        object.__setattr__(self, "rem_data", bytes(self.rem_data))

    def encode(self) -> bytes:
        return bytes((self.new_address, self.ident >> 8, self.ident & 0xFF,
                      1 if self.no_add_chg else 0)) + self.rem_data

    @classmethod
    def decode(cls, data: bytes) -> "SetSlaveAdd":
        data = bytes(data)
        if len(data) < 4:
            raise DpError(f"Set_Slave_Add needs at least 4 bytes, got {len(data)}")
        return cls(data[0], (data[1] << 8) | data[2], bool(data[3]), data[4:])


# -- mapping onto FDL telegrams ----------------------------------------------------------


def request_frame(da: int, sa: int, fcb: bool, fcv: bool, sap: Optional[int],
                  payload: bytes = b"", function: int = RequestFunction.SRD_HIGH) -> Frame:
    """A DP request telegram. ``sap`` None is the default SAP (Data_Exchange)."""
    fc = FrameControl.req(function, fcb=fcb, fcv=fcv)
    if sap is None:
        return data_frame(da, sa, fc, payload)
    return data_frame(da, sa, fc, payload, dsap=int(sap), ssap=MASTER_SAP)


def global_control_frame(sa: int, gc: GlobalControl, da: int = BROADCAST) -> Frame:
    """Global_Control as SDN (high) to broadcast (or one slave); FCV=0."""
    return request_frame(da, sa, False, False, Sap.GLOBAL_CONTROL, gc.encode(),
                         function=RequestFunction.SDN_HIGH)


def reply_frame(request: Frame, own_address: int, payload: bytes,
                status: int = ResponseStatus.DL) -> Frame:
    """The slave's data reply to a DP ``request`` (SAPs swapped)."""
    dsap = getattr(request, "ssap", None)
    ssap = getattr(request, "dsap", None)
    return data_frame(request.sa, own_address, FrameControl.resp(status), payload, dsap, ssap)  # type: ignore[union-attr]


def short_ack() -> ShortAck:
    return ShortAck()


__all__.append("global_control_frame")
