"""PROFIBUS-DP GSD (device database) files: parser, Cfg identifier decoding, Chk_Cfg builder, CLI.

A GSD file is ISO-8859-1 text made of ``Keyword = value`` lines:

* ``;`` starts a comment that runs to the end of the line (outside quoted strings);
* a ``\\`` at the end of a line continues the line on the next one;
* values are quoted strings, decimal or ``0x`` hexadecimal numbers, or comma-separated number lists;
* keywords are case-insensitive and may carry an index, e.g. ``Ext_User_Prm_Data_Const(0)``;
* blocks: ``Module = "name" 0x13 ... EndModule`` (Cfg identifier bytes after the name, then nested
  lines: an optional module reference number and module keywords), ``ExtUserPrmData = ref "name"
  ... EndExtUserPrmData`` (a User_Prm_Data field and its default), and text or diagnosis blocks
  (``PrmText``, ``UnitDiagType``, ``Unit_Diag_Area``, ``SlotDefinition`` ...) that are kept verbatim;
* the only preprocessor line understood is ``#Profibus_DP``.

``parse_gsd(text, source)`` / ``load_gsd(path)`` give a frozen :class:`Gsd`. Keywords this module
does not interpret are kept in ``Gsd.unknown`` (not an error). Every problem raises
:class:`~pyprofibus_vendor.errors.GsdError` whose message names the file, the line and the keyword.

Cfg identifier bytes (what Chk_Cfg sends) are decoded by :func:`decode_cfg`:

* general format (bits 5-4 != 00): bits 3-0 = length-1, bits 5-4 = direction (01 input, 10 output,
  11 input and output), bit 6 = length in words, bit 7 = consistency over the whole length;
* special format (bits 5-4 == 00): bits 7-6 = which length bytes follow (00 none, 01 an input length
  byte, 10 an output length byte, 11 an output then an input length byte), bits 3-0 = number of
  manufacturer bytes after them; a length byte has bits 5-0 = length-1, bit 6 words, bit 7 consistency.

"Input" is slave -> master and "output" is master -> slave (PROFIBUS's master-centric naming).

Command line: ``python3 -m pyprofibus_vendor.gsd FILE [--modules "a,b,..."] [--json]``.
"""
from __future__ import annotations

import argparse
import difflib
import json
import logging
import os
import re
import sys
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Union

from . import _cli
from . import dp as _dp
from .dp import CfgIdentifier
from .errors import ConfigError, DpError, GsdError

__all__ = [
    "STANDARD_BAUDRATES",
    "DP_MAX_IO_LEN",
    "DP_MAX_CFG_LEN",
    "DP_MAX_USER_PRM_DATA_LEN",
    "GsdParseError",
    "CfgIdentifier",
    "ExtUserPrm",
    "GsdBlock",
    "GsdModule",
    "Gsd",
    "parse_gsd",
    "load_gsd",
    "decode_cfg",
    "cfg_io_lengths",
    "build_chk_cfg",
    "build_user_prm_data",
    "baud_name",
    "format_hex",
    "main",
]

log = logging.getLogger(__name__)

#: The PROFIBUS-DP (RS-485) bit rates, in bit/s.
STANDARD_BAUDRATES: Tuple[int, ...] = (
    9600, 19200, 45450, 93750, 187500, 500000, 1500000, 3000000, 6000000, 12000000,
)
#: Most input (or output) bytes a DP-V0 slave can exchange.
DP_MAX_IO_LEN = 244
#: Most Cfg identifier bytes in one Chk_Cfg data unit.
DP_MAX_CFG_LEN = 244
#: Most User_Prm_Data bytes in one Set_Prm (the data unit minus the 7 standard octets).
DP_MAX_USER_PRM_DATA_LEN = 237

# GSD spelling of each rate, as used in the "<rate>_supp" and "MaxTsdr_<rate>" keywords (lower case).
_BAUD_KEYS: Dict[str, int] = {
    "9.6": 9600, "19.2": 19200, "45.45": 45450, "93.75": 93750, "187.5": 187500,
    "500": 500000, "1.5m": 1500000, "3m": 3000000, "6m": 6000000, "12m": 12000000,
}
_SUPP_RE = re.compile(r"([0-9.]+m?)_supp\Z")
_TSDR_RE = re.compile(r"maxtsdr_([0-9.]+m?)\Z")

# Keyword, optional "(index)", "=", value. ASCII only on purpose: GSD keywords are ASCII.
_KEYWORD_RE = re.compile(r"([A-Za-z0-9_.!]+)[ \t]*(?:\([ \t]*([0-9]+)[ \t]*\))?[ \t]*=[ \t]*(.*)\Z")
_BARE_WORD_RE = re.compile(r"[A-Za-z0-9_.!]+\Z")
_STRING_RE = re.compile(r'"([^"]*)"[ \t]*(.*)\Z')
_LIST_SPLIT_RE = re.compile(r"[ \t]*,[ \t]*|[ \t]+")

# Blocks kept verbatim: start keyword -> end keyword (lower case).
_TEXT_BLOCKS: Dict[str, str] = {
    "prmtext": "endprmtext",
    "unitdiagtype": "endunitdiagtype",
    "x_unitdiagtype": "x_endunitdiagtype",
    "slotdefinition": "endslotdefinition",
    "unit_diag_area": "unit_diag_area_end",
    "x_unit_diag_area": "x_unit_diag_area_end",
}
_ALL_BLOCK_ENDS = frozenset(list(_TEXT_BLOCKS.values()) + ["endmodule", "endextuserprmdata"])


# --------------------------------------------------------------------------------------------------
# Errors and small helpers
# --------------------------------------------------------------------------------------------------

class GsdParseError(GsdError):
    """A GSD problem located in a file: ``source``, ``line`` (1-based or None) and ``key`` (or None).

    ``str(err)`` reads ``"<source>:<line>: <key>: <reason>"``.
    """

    def __init__(self, source: str, line: Optional[int], key: Optional[str], reason: str) -> None:
        self.source = source
        self.line = line
        self.key = key
        self.reason = reason
        where = source if line is None else "%s:%d" % (source, line)
        super().__init__("%s: %s%s" % (where, "%s: " % key if key else "", reason))


def format_hex(data: bytes) -> str:
    """``b"\\x13\\x23"`` -> ``"13 23"``."""
    return " ".join("%02X" % b for b in data)


def baud_name(baud: int) -> str:
    """9600 -> ``"9.6k"``, 1500000 -> ``"1.5M"`` (for humans)."""
    if baud >= 1000000:
        text, unit = "%g" % (baud / 1e6), "M"
    else:
        text, unit = "%g" % (baud / 1e3), "k"
    return text + unit


#: a decimal or 0x-hex integer, or None (the package's one integer reader, in _cli)
_parse_int = _cli.int_or_none


def _parse_int_list(text: str) -> Optional[List[int]]:
    """``"0x13, 0x13 0x11"`` -> [0x13, 0x13, 0x11]; None when any item is not a number."""
    text = text.strip()
    if not text:
        return []
    values = []
    for item in _LIST_SPLIT_RE.split(text):
        value = _parse_int(item)
        if value is None:
            return None
        values.append(value)
    return values


# --------------------------------------------------------------------------------------------------
# Cfg identifier bytes
# --------------------------------------------------------------------------------------------------

def decode_cfg(cfg: bytes) -> Tuple[CfgIdentifier, ...]:
    """Split Chk_Cfg bytes into decoded identifiers (``dp.decode_cfg``); ConfigError when cut short."""
    try:
        return _dp.decode_cfg(cfg)
    except DpError as exc:
        raise ConfigError(str(exc)) from exc


def cfg_io_lengths(cfg: bytes) -> Tuple[int, int]:
    """Total (input_len, output_len) in bytes described by Chk_Cfg bytes; ConfigError when cut short."""
    try:
        return _dp.cfg_io_lengths(cfg)
    except DpError as exc:
        raise ConfigError(str(exc)) from exc


# --------------------------------------------------------------------------------------------------
# Result types
# --------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class ExtUserPrm:
    """One ``ExtUserPrmData`` definition: a field of User_Prm_Data and its default.

    ``data_type`` is ``Bit``, ``BitArea``, ``Unsigned8/16/32`` or ``Signed8/16/32``; ``bits`` is
    (first, last) for Bit/BitArea; multi-byte values are big-endian.
    """

    reference: int
    name: str
    data_type: str
    default: int
    minimum: Optional[int]
    maximum: Optional[int]
    bits: Optional[Tuple[int, int]]
    line: int

    @property
    def size(self) -> int:
        """Bytes the field occupies."""
        return _PRM_SIZES[self.data_type]


@dataclass(frozen=True)
class GsdBlock:
    """A block kept verbatim (PrmText, UnitDiagType, ...): its keyword, header value and lines."""

    keyword: str
    value: str
    line: int
    lines: Tuple[str, ...]


@dataclass(frozen=True)
class GsdModule:
    """A ``Module`` entry: name, Cfg identifier bytes, data lengths and nested keywords."""

    name: str
    cfg: bytes
    input_len: int
    output_len: int
    line: int
    reference: Optional[int] = None
    prm_data: bytes = b""
    extra: Mapping[str, str] = field(default_factory=lambda: MappingProxyType({}), hash=False)

    def describe(self) -> str:
        """``"in 4"`` style text for all identifiers of the module."""
        return "; ".join(i.describe() for i in decode_cfg(self.cfg))


@dataclass(frozen=True)
class Gsd:
    """A parsed GSD file. Field names follow the GSD keywords (``Max_Input_Len`` -> ``max_input_len``).

    ``None`` means the keyword was absent; the ``*_limit`` properties give the value that applies then.
    ``min_slave_interval`` is in units of 100 us. ``max_tsdr`` maps baud -> bit times.
    """

    source: str
    ident_number: int
    vendor_name: str = ""
    model_name: str = ""
    revision: str = ""
    gsd_revision: Optional[int] = None
    revision_number: Optional[int] = None
    protocol_ident: int = 0
    station_type: int = 0
    hardware_release: str = ""
    software_release: str = ""
    implementation_type: str = ""
    order_number: str = ""
    info_text: str = ""
    baud_rates: Tuple[int, ...] = ()
    max_tsdr: Mapping[int, int] = field(default_factory=lambda: MappingProxyType({}), hash=False)
    modular_station: bool = False
    max_module: Optional[int] = None
    max_input_len: Optional[int] = None
    max_output_len: Optional[int] = None
    max_data_len: Optional[int] = None
    max_diag_data_len: Optional[int] = None
    min_slave_interval: Optional[int] = None
    user_prm_data_len: int = 0
    user_prm_data: bytes = b""
    max_user_prm_data_len: Optional[int] = None
    fail_safe: bool = False
    freeze_supported: bool = False
    sync_supported: bool = False
    auto_baud_supported: bool = False
    set_slave_add_supported: bool = False
    modules: Tuple[GsdModule, ...] = ()
    ext_user_prm: Mapping[int, ExtUserPrm] = field(default_factory=lambda: MappingProxyType({}), hash=False)
    blocks: Tuple[GsdBlock, ...] = ()
    unknown: Mapping[str, str] = field(default_factory=lambda: MappingProxyType({}), hash=False)

    # ---- limits that apply -------------------------------------------------------------------
    @property
    def module_limit(self) -> int:
        """Max_Module, or 1 for a compact station / 244 for a modular one when absent."""
        if self.max_module is not None:
            return self.max_module
        return DP_MAX_CFG_LEN if self.modular_station else 1

    @property
    def input_limit(self) -> int:
        """Max_Input_Len, or the DP limit of 244 when absent."""
        return DP_MAX_IO_LEN if self.max_input_len is None else self.max_input_len

    @property
    def output_limit(self) -> int:
        """Max_Output_Len, or the DP limit of 244 when absent."""
        return DP_MAX_IO_LEN if self.max_output_len is None else self.max_output_len

    @property
    def data_limit(self) -> int:
        """Max_Data_Len (inputs + outputs), or input_limit + output_limit when absent."""
        if self.max_data_len is None:
            return self.input_limit + self.output_limit
        return self.max_data_len

    def supports_baud(self, baud: int) -> bool:
        """True when ``<rate>_supp = 1`` for this bit rate."""
        return baud in self.baud_rates

    def module(self, name: str) -> GsdModule:
        """The module called ``name`` (exact match first, then ignoring case and repeated blanks)."""
        for mod in self.modules:
            if mod.name == name:
                return mod
        wanted = " ".join(name.split()).casefold()
        for mod in self.modules:
            if " ".join(mod.name.split()).casefold() == wanted:
                return mod
        names = [m.name for m in self.modules]
        close = difflib.get_close_matches(name, names, n=3)
        hint = ("; did you mean %s?" % ", ".join(repr(c) for c in close)) if close else ""
        raise GsdParseError(self.source, None, "Module",
                            "unknown module %r%s (the file has %d modules: %s)"
                            % (name, hint, len(names), ", ".join(repr(n) for n in names) or "none"))

    # ---- output --------------------------------------------------------------------------------
    def to_dict(self) -> Dict[str, Any]:
        """A JSON-friendly dict (bytes as hex strings)."""
        return {
            "source": self.source,
            "vendor_name": self.vendor_name,
            "model_name": self.model_name,
            "revision": self.revision,
            "gsd_revision": self.gsd_revision,
            "ident_number": "0x%04X" % self.ident_number,
            "station_type": self.station_type,
            "protocol_ident": self.protocol_ident,
            "baud_rates": list(self.baud_rates),
            "max_tsdr": {str(k): v for k, v in sorted(self.max_tsdr.items())},
            "modular_station": self.modular_station,
            "max_module": self.max_module,
            "max_input_len": self.max_input_len,
            "max_output_len": self.max_output_len,
            "max_data_len": self.max_data_len,
            "max_diag_data_len": self.max_diag_data_len,
            "min_slave_interval": self.min_slave_interval,
            "user_prm_data_len": self.user_prm_data_len,
            "user_prm_data": format_hex(self.user_prm_data),
            "fail_safe": self.fail_safe,
            "freeze_supported": self.freeze_supported,
            "sync_supported": self.sync_supported,
            "auto_baud_supported": self.auto_baud_supported,
            "set_slave_add_supported": self.set_slave_add_supported,
            "modules": [
                {"name": m.name, "cfg": format_hex(m.cfg), "input_len": m.input_len,
                 "output_len": m.output_len, "line": m.line}
                for m in self.modules
            ],
            "unknown": dict(self.unknown),
        }

    def summary(self) -> str:
        """A multi-line description for humans."""
        def opt(value: Optional[int]) -> str:
            return "-" if value is None else str(value)

        def yes(flag: bool) -> str:
            return "yes" if flag else "no"

        station = {0: "DP slave", 1: "DP master"}.get(self.station_type, "type %d" % self.station_type)
        bauds = " ".join(baud_name(b) for b in self.baud_rates) or "none declared"
        tsdr = " ".join("%s=%d" % (baud_name(b), t) for b, t in sorted(self.max_tsdr.items())) or "-"
        lines = [
            "%s: %s %s" % (self.source, self.vendor_name or "?", self.model_name or "?"),
            "  Ident_Number      0x%04X" % self.ident_number,
            "  Revision          %s (GSD_Revision %s)" % (self.revision or "-", opt(self.gsd_revision)),
            "  Station_Type      %d (%s)" % (self.station_type, station),
            "  Baud rates        %s" % bauds,
            "  MaxTsdr (bits)    %s" % tsdr,
            "  Modular_Station   %s, Max_Module %s" % (yes(self.modular_station), opt(self.max_module)),
            "  Max lengths       input %s, output %s, data %s, diag %s"
            % (opt(self.max_input_len), opt(self.max_output_len), opt(self.max_data_len),
               opt(self.max_diag_data_len)),
            "  Min_Slave_Intervall %s x 100 us" % opt(self.min_slave_interval),
            "  Freeze/Sync/Fail_Safe  %s/%s/%s"
            % (yes(self.freeze_supported), yes(self.sync_supported), yes(self.fail_safe)),
            "  User_Prm_Data     %d byte(s)%s" % (
                self.user_prm_data_len,
                (": " + format_hex(self.user_prm_data)) if self.user_prm_data else ""),
            "  Modules (%d):" % len(self.modules),
        ]
        width = max([len(m.name) for m in self.modules] + [4]) + 2
        for mod in self.modules:
            lines.append("    %-*s Cfg %-12s in %3d  out %3d" % (
                width, '"%s"' % mod.name, format_hex(mod.cfg), mod.input_len, mod.output_len))
        if self.unknown:
            lines.append("  Other keywords    %d kept (%s)" % (
                len(self.unknown), ", ".join(sorted(self.unknown)[:8])
                + (", ..." if len(self.unknown) > 8 else "")))
        return "\n".join(lines)


# --------------------------------------------------------------------------------------------------
# Parser
# --------------------------------------------------------------------------------------------------

def _logical_lines(text: str, source: str) -> List[Tuple[int, str]]:
    """Strip comments, join ``\\`` continuations; return (first physical line number, text) pairs."""
    result: List[Tuple[int, str]] = []
    pieces: List[str] = []
    start = 0
    in_quote = False
    for number, raw in enumerate(re.split(r"\r\n|\r|\n", text), 1):
        if not pieces:
            start = number
        kept = []
        for ch in raw:
            if ch == '"':
                in_quote = not in_quote
            elif ch == ";" and not in_quote:
                break
            kept.append(ch)
        part = "".join(kept).rstrip()
        if part.endswith("\\"):
            # inside a string the continuation joins directly, elsewhere it separates tokens
            pieces.append(part[:-1] if in_quote else part[:-1] + " ")
            continue
        if in_quote:
            raise GsdParseError(source, number, None, "unterminated string (missing closing '\"')")
        pieces.append(part)
        line = "".join(pieces).strip()
        pieces = []
        if line:
            result.append((start, line))
    if pieces:
        line = "".join(pieces).strip()
        if in_quote:
            raise GsdParseError(source, start, None, "unterminated string (missing closing '\"')")
        if line:
            result.append((start, line))
    return result


def _conv_string(value: str) -> str:
    match = _STRING_RE.match(value)
    if not match or match.group(2):
        raise ValueError("expected a quoted string, got %r" % value)
    return match.group(1)


def _conv_uint(lo: int, hi: int) -> Callable[[str], int]:
    def conv(value: str) -> int:
        number = _parse_int(value)
        if number is None:
            raise ValueError("bad number %r (expected decimal or 0x hex)" % value)
        if not lo <= number <= hi:
            raise ValueError("%d is outside %d..%d" % (number, lo, hi))
        return number
    return conv


def _conv_bool(value: str) -> bool:
    number = _parse_int(value)
    if number not in (0, 1):
        raise ValueError("expected 0 or 1, got %r" % value)
    return bool(number)


def _conv_bytes(value: str) -> bytes:
    numbers = _parse_int_list(value)
    if numbers is None:
        raise ValueError("bad byte list %r (expected numbers separated by commas)" % value)
    if any(n > 0xFF for n in numbers):
        raise ValueError("byte value above 0xFF in %r" % value)
    return bytes(numbers)


# keyword (lower case) -> (attribute, converter)
_SCALARS: Dict[str, Tuple[str, Callable[[str], Any]]] = {
    "vendor_name": ("vendor_name", _conv_string),
    "model_name": ("model_name", _conv_string),
    "revision": ("revision", _conv_string),
    "hardware_release": ("hardware_release", _conv_string),
    "software_release": ("software_release", _conv_string),
    "implementation_type": ("implementation_type", _conv_string),
    "ordernumber": ("order_number", _conv_string),
    "info_text": ("info_text", _conv_string),
    "gsd_revision": ("gsd_revision", _conv_uint(0, 255)),
    "revision_number": ("revision_number", _conv_uint(0, 255)),
    "ident_number": ("ident_number", _conv_uint(0, 0xFFFF)),
    "protocol_ident": ("protocol_ident", _conv_uint(0, 255)),
    "station_type": ("station_type", _conv_uint(0, 255)),
    "modular_station": ("modular_station", _conv_bool),
    "max_module": ("max_module", _conv_uint(1, DP_MAX_CFG_LEN)),
    "max_input_len": ("max_input_len", _conv_uint(0, DP_MAX_IO_LEN)),
    "max_output_len": ("max_output_len", _conv_uint(0, DP_MAX_IO_LEN)),
    "max_data_len": ("max_data_len", _conv_uint(0, 2 * DP_MAX_IO_LEN)),
    "max_diag_data_len": ("max_diag_data_len", _conv_uint(6, 244)),
    "min_slave_intervall": ("min_slave_interval", _conv_uint(1, 0xFFFF)),
    "user_prm_data_len": ("user_prm_data_len", _conv_uint(0, DP_MAX_USER_PRM_DATA_LEN)),
    "user_prm_data": ("user_prm_data", _conv_bytes),
    "max_user_prm_data_len": ("max_user_prm_data_len", _conv_uint(0, DP_MAX_USER_PRM_DATA_LEN)),
    "fail_safe": ("fail_safe", _conv_bool),
    "freeze_mode_supp": ("freeze_supported", _conv_bool),
    "sync_mode_supp": ("sync_supported", _conv_bool),
    "auto_baud_supp": ("auto_baud_supported", _conv_bool),
    "set_slave_add_supp": ("set_slave_add_supported", _conv_bool),
}

# ExtUserPrmData data-type line, e.g. "Bit(3) 1 0-1", "BitArea(0-3) 2 0-7", "Unsigned16 100 0-1000",
# "Unsigned8 1 1,2,4".
_PRM_TYPE_RE = re.compile(
    r"(Bit|BitArea|Unsigned8|Unsigned16|Unsigned32|Signed8|Signed16|Signed32)"
    r"(?:[ \t]*\([ \t]*([0-9]+)(?:[ \t]*-[ \t]*([0-9]+))?[ \t]*\))?"
    r"[ \t]+(-?(?:0[xX][0-9A-Fa-f]+|[0-9]+))(?:[ \t]+(.*))?\Z", re.IGNORECASE)
_PRM_RANGE_RE = re.compile(r"(-?(?:0[xX][0-9A-Fa-f]+|[0-9]+))[ \t]*-[ \t]*(-?(?:0[xX][0-9A-Fa-f]+|[0-9]+))\Z")
_PRM_SIZES = {"Bit": 1, "BitArea": 1, "Unsigned8": 1, "Unsigned16": 2, "Unsigned32": 4,
              "Signed8": 1, "Signed16": 2, "Signed32": 4}
_PRM_TYPE_NAMES = {n.lower(): n for n in _PRM_SIZES}


class _Parser:
    """Single-use parser: ``_Parser(source).parse(text) -> Gsd``."""

    def __init__(self, source: str) -> None:
        self.source = source
        self.values: Dict[str, Any] = {}
        self.seen: Dict[str, int] = {}            # known keyword -> line (duplicate detection)
        self.bauds: Dict[int, bool] = {}
        self.tsdr: Dict[int, int] = {}
        self.modules: List[GsdModule] = []
        self.module_prm_ops: List[List[Tuple[int, str, int, int]]] = []   # per module
        self.module_prm_len: List[Optional[int]] = []
        self.station_prm_ops: List[Tuple[int, str, int, int]] = []       # (line, kind, offset, value)
        self.ext_prm: Dict[int, ExtUserPrm] = {}
        self.blocks: List[GsdBlock] = []
        self.unknown: Dict[str, str] = {}

    def error(self, line: Optional[int], key: Optional[str], reason: str) -> GsdParseError:
        return GsdParseError(self.source, line, key, reason)

    # ---- entry ----------------------------------------------------------------------------------
    def parse(self, text: str) -> Gsd:
        lines = _logical_lines(text, self.source)
        pos = 0
        while pos < len(lines):
            number, line = lines[pos]
            pos += 1
            if line.startswith("#"):
                if line.lower() != "#profibus_dp":
                    raise self.error(number, None, "unsupported preprocessor line %r "
                                                   "(only #Profibus_DP is understood)" % line)
                continue
            match = _KEYWORD_RE.match(line)
            if not match:
                word = line.lower()
                if word in _ALL_BLOCK_ENDS:
                    raise self.error(number, line, "block end without a matching block start")
                raise self.error(number, None, "expected 'Keyword = value', got %r" % line)
            keyword, index, value = match.group(1), match.group(2), match.group(3).strip()
            lower = keyword.lower()
            if lower == "module" and index is None:
                pos = self._module(lines, pos, number, value)
            elif lower == "extuserprmdata" and index is None:
                pos = self._ext_user_prm(lines, pos, number, keyword, value)
            elif lower in _TEXT_BLOCKS and index is None:
                pos = self._text_block(lines, pos, number, keyword, value)
            else:
                self._keyword(number, keyword, index, value, self.station_prm_ops)
        return self._finish()

    # ---- single keywords -----------------------------------------------------------------------
    def _keyword(self, number: int, keyword: str, index: Optional[str], value: str,
                 prm_ops: List[Tuple[int, str, int, int]]) -> None:
        lower = keyword.lower()
        shown = keyword if index is None else "%s(%s)" % (keyword, index)
        if index is not None and lower in ("ext_user_prm_data_const", "ext_user_prm_data_ref"):
            self._prm_op(number, lower, int(index), value, prm_ops, shown)
            return
        if index is None and lower in _SCALARS:
            attr, conv = _SCALARS[lower]
            self._check_duplicate(number, lower, shown)
            try:
                self.values[attr] = conv(value)
            except ValueError as exc:
                raise self.error(number, shown, str(exc)) from None
            return
        supp = _SUPP_RE.match(lower) if index is None else None
        if supp and supp.group(1) in _BAUD_KEYS:
            self._check_duplicate(number, lower, shown)
            try:
                self.bauds[_BAUD_KEYS[supp.group(1)]] = _conv_bool(value)
            except ValueError as exc:
                raise self.error(number, shown, str(exc)) from None
            return
        tsdr = _TSDR_RE.match(lower) if index is None else None
        if tsdr and tsdr.group(1) in _BAUD_KEYS:
            self._check_duplicate(number, lower, shown)
            try:
                self.tsdr[_BAUD_KEYS[tsdr.group(1)]] = _conv_uint(0, 0xFFFF)(value)
            except ValueError as exc:
                raise self.error(number, shown, str(exc)) from None
            return
        if shown in self.unknown:
            log.debug("%s:%d: %s repeated; keeping the last value", self.source, number, shown)
        self.unknown[shown] = value

    def _check_duplicate(self, number: int, lower: str, shown: str) -> None:
        if lower in self.seen:
            raise self.error(number, shown, "given twice (first on line %d)" % self.seen[lower])
        self.seen[lower] = number

    def _prm_op(self, number: int, lower: str, offset: int, value: str,
                ops: List[Tuple[int, str, int, int]], shown: str) -> None:
        if lower == "ext_user_prm_data_ref":
            ref = _parse_int(value)
            if ref is None:
                raise self.error(number, shown, "bad reference number %r" % value)
            ops.append((number, "ref", offset, ref))
            return
        try:
            data = _conv_bytes(value)
        except ValueError as exc:
            raise self.error(number, shown, str(exc)) from None
        for i, byte in enumerate(data):
            ops.append((number, "const", offset + i, byte))

    # ---- blocks -------------------------------------------------------------------------------
    def _block_lines(self, lines: List[Tuple[int, str]], pos: int, start: int, keyword: str,
                     end: str, what: str) -> Tuple[List[Tuple[int, str]], int]:
        """Collect lines up to ``end``; returns (body, position after the end line)."""
        body = []
        while pos < len(lines):
            number, line = lines[pos]
            pos += 1
            word = line.lower()
            if word == end:
                return body, pos
            if word in _ALL_BLOCK_ENDS:
                raise self.error(number, line, "found inside %s started on line %d "
                                               "(expected %s)" % (what, start, _end_name(end)))
            head = _KEYWORD_RE.match(line)
            if head and head.group(2) is None and (
                    head.group(1).lower() in ("module", "extuserprmdata")
                    or head.group(1).lower() in _TEXT_BLOCKS):
                raise self.error(number, head.group(1), "new block inside %s started on line %d "
                                                        "(missing %s)" % (what, start, _end_name(end)))
            body.append((number, line))
        raise self.error(start, keyword, "unterminated %s: missing %s before the end of the file"
                         % (what, _end_name(end)))

    def _module(self, lines: List[Tuple[int, str]], pos: int, start: int, value: str) -> int:
        match = _STRING_RE.match(value)
        if not match:
            raise self.error(start, "Module", "expected '\"name\" cfg-bytes...', got %r" % value)
        name, cfg_text = match.group(1), match.group(2)
        numbers = _parse_int_list(cfg_text)
        if numbers is None:
            raise self.error(start, "Module", "module %r: bad Cfg byte list %r" % (name, cfg_text))
        if not numbers:
            raise self.error(start, "Module", "module %r has no Cfg bytes" % name)
        if any(n > 0xFF for n in numbers):
            raise self.error(start, "Module", "module %r: Cfg byte above 0xFF in %r" % (name, cfg_text))
        cfg = bytes(numbers)
        try:
            in_len, out_len = cfg_io_lengths(cfg)
        except ConfigError as exc:
            raise self.error(start, "Module", "module %r: %s" % (name, exc)) from None
        body, pos = self._block_lines(lines, pos, start, "Module", "endmodule", "Module %r" % name)
        reference = None
        prm_len: Optional[int] = None
        prm_ops: List[Tuple[int, str, int, int]] = []
        extra: Dict[str, str] = {}
        for number, line in body:
            ref = _parse_int(line)
            if ref is not None:
                reference = ref
                continue
            kw = _KEYWORD_RE.match(line)
            if not kw:
                if _BARE_WORD_RE.match(line):   # e.g. DP-V1 Data_Area_Beg / Data_Area_End
                    extra[line] = ""
                    continue
                raise self.error(number, None, "in Module %r: expected 'Keyword = value' or a "
                                               "module reference number, got %r" % (name, line))
            keyword, index, kw_value = kw.group(1), kw.group(2), kw.group(3).strip()
            lower = keyword.lower()
            shown = keyword if index is None else "%s(%s)" % (keyword, index)
            if index is not None and lower in ("ext_user_prm_data_const", "ext_user_prm_data_ref"):
                self._prm_op(number, lower, int(index), kw_value, prm_ops, shown)
            elif lower == "ext_module_prm_data_len" and index is None:
                try:
                    prm_len = _conv_uint(0, DP_MAX_USER_PRM_DATA_LEN)(kw_value)
                except ValueError as exc:
                    raise self.error(number, shown, str(exc)) from None
            else:
                extra[shown] = kw_value
        if any(m.name == name for m in self.modules):
            log.warning("%s:%d: module name %r used twice; lookups find the first one",
                        self.source, start, name)
        self.modules.append(GsdModule(
            name=name, cfg=cfg, input_len=in_len, output_len=out_len, line=start,
            reference=reference, extra=MappingProxyType(extra)))
        self.module_prm_ops.append(prm_ops)
        self.module_prm_len.append(prm_len)
        return pos

    def _ext_user_prm(self, lines: List[Tuple[int, str]], pos: int, start: int, keyword: str,
                      value: str) -> int:
        head = re.match(r"(0[xX][0-9A-Fa-f]+|[0-9]+)[ \t]*(.*)\Z", value)
        if not head:
            raise self.error(start, keyword, "expected 'reference \"name\"', got %r" % value)
        reference = _parse_int(head.group(1))
        assert reference is not None
        name_match = _STRING_RE.match(head.group(2))
        name = name_match.group(1) if name_match else head.group(2).strip()
        body, pos = self._block_lines(lines, pos, start, keyword, "endextuserprmdata",
                                      "ExtUserPrmData %d" % reference)
        definition: Optional[ExtUserPrm] = None
        for number, line in body:
            typ = _PRM_TYPE_RE.match(line)
            if typ:
                definition = self._prm_definition(number, reference, name, typ)
            elif not _KEYWORD_RE.match(line):   # Prm_Text_Ref = n, Changeable = 0 ... are fine
                raise self.error(number, None, "in ExtUserPrmData %d: expected a data type line "
                                               "such as 'Unsigned8 0 0-255', got %r" % (reference, line))
        if definition is None:
            raise self.error(start, keyword, "ExtUserPrmData %d has no data type line" % reference)
        if reference in self.ext_prm:
            raise self.error(start, keyword, "reference %d defined twice (first on line %d)"
                             % (reference, self.ext_prm[reference].line))
        self.ext_prm[reference] = definition
        return pos

    def _prm_definition(self, number: int, reference: int, name: str, typ: re.Match[str]) -> ExtUserPrm:
        where = "ExtUserPrmData %d" % reference
        data_type = _PRM_TYPE_NAMES[typ.group(1).lower()]
        bits: Optional[Tuple[int, int]] = None
        if data_type in ("Bit", "BitArea"):
            if typ.group(2) is None:
                raise self.error(number, where, "%s needs a bit position, e.g. Bit(0)" % data_type)
            first = int(typ.group(2))
            last = int(typ.group(3)) if typ.group(3) is not None else first
            if data_type == "Bit" and typ.group(3) is not None:
                raise self.error(number, where, "Bit() takes one bit number; use BitArea(a-b)")
            if not 0 <= first <= last <= 7:
                raise self.error(number, where, "bit range %d-%d is outside 0-7" % (first, last))
            bits = (first, last)
        elif typ.group(2) is not None:
            raise self.error(number, where, "%s takes no bit position" % data_type)
        default = _parse_int(typ.group(4), signed=True)
        assert default is not None
        minimum = maximum = None
        allowed = (typ.group(5) or "").strip()
        if allowed:
            rng = _PRM_RANGE_RE.match(allowed)
            if rng:
                minimum, maximum = _parse_int(rng.group(1), True), _parse_int(rng.group(2), True)
            else:
                choices = [_parse_int(v, True) for v in re.split(r"[ \t]*,[ \t]*", allowed)]
                if any(c is None for c in choices):
                    raise self.error(number, where, "bad allowed values %r" % allowed)
                minimum, maximum = min(choices), max(choices)  # type: ignore[type-var]
        definition = ExtUserPrm(reference=reference, name=name, data_type=data_type, default=default,
                                minimum=minimum, maximum=maximum, bits=bits, line=number)
        lo, hi = _field_range(definition)
        if not lo <= default <= hi:
            raise self.error(number, where, "default %d does not fit %s (%d..%d)"
                             % (default, data_type if bits is None else
                                "%s(%d-%d)" % (data_type, bits[0], bits[1]), lo, hi))
        return definition

    def _text_block(self, lines: List[Tuple[int, str]], pos: int, start: int, keyword: str,
                    value: str) -> int:
        end = _TEXT_BLOCKS[keyword.lower()]
        body, pos = self._block_lines(lines, pos, start, keyword, end, keyword)
        self.blocks.append(GsdBlock(keyword=keyword, value=value, line=start,
                                    lines=tuple(line for _, line in body)))
        return pos

    # ---- User_Prm_Data defaults -----------------------------------------------------------------
    def _apply_prm(self, base: bytes, length: Optional[int], ops: List[Tuple[int, str, int, int]],
                   what: str) -> bytes:
        data = bytearray(base)
        for number, kind, offset, value in ops:
            if kind == "const":
                size, fields = 1, None
            else:
                definition = self.ext_prm.get(value)
                if definition is None:
                    raise self.error(number, "Ext_User_Prm_Data_Ref(%d)" % offset,
                                     "no ExtUserPrmData with reference %d" % value)
                size, fields = definition.size, definition
            if length is not None and offset + size > length:
                raise self.error(number, "Ext_User_Prm_Data_%s(%d)" % ("Const" if kind == "const" else "Ref",
                                                                         offset),
                                 "offset %d is beyond %s = %d" % (offset, what, length))
            if offset + size > DP_MAX_USER_PRM_DATA_LEN:
                raise self.error(number, "Ext_User_Prm_Data(%d)" % offset,
                                 "offset %d is beyond the 237-byte User_Prm_Data limit" % offset)
            if len(data) < offset + size:
                data.extend(b"\x00" * (offset + size - len(data)))
            if fields is None:
                data[offset] = value
            elif fields.bits is not None:
                first, last = fields.bits
                mask = ((1 << (last - first + 1)) - 1) << first
                data[offset] = (data[offset] & ~mask & 0xFF) | ((fields.default << first) & mask)
            else:
                raw = fields.default & ((1 << (8 * size)) - 1)
                data[offset:offset + size] = raw.to_bytes(size, "big")
        if length is not None and len(data) < length:
            data.extend(b"\x00" * (length - len(data)))
        return bytes(data)

    # ---- result -------------------------------------------------------------------------------
    def _finish(self) -> Gsd:
        if "ident_number" not in self.values:
            raise self.error(None, "Ident_Number", "missing (every GSD must declare Ident_Number)")
        values = dict(self.values)
        data = values.get("user_prm_data", b"")
        length = values.get("user_prm_data_len")
        if length is not None and len(data) > length:
            raise self.error(self.seen.get("user_prm_data"), "User_Prm_Data",
                             "%d bytes but User_Prm_Data_Len = %d" % (len(data), length))
        data = self._apply_prm(data, length, self.station_prm_ops, "User_Prm_Data_Len")
        values["user_prm_data"] = data
        values["user_prm_data_len"] = len(data)
        modules = []
        for mod, ops, prm_len in zip(self.modules, self.module_prm_ops, self.module_prm_len):
            if ops or prm_len:
                prm = self._apply_prm(b"", prm_len, ops, "Ext_Module_Prm_Data_Len of module %r" % mod.name)
                mod = GsdModule(name=mod.name, cfg=mod.cfg, input_len=mod.input_len,
                                output_len=mod.output_len, line=mod.line, reference=mod.reference,
                                prm_data=prm, extra=mod.extra)
            modules.append(mod)
        if values.get("max_data_len") == 0:
            log.debug("%s: Max_Data_Len = 0 read as 'not given'", self.source)
            values["max_data_len"] = None
        return Gsd(
            source=self.source,
            baud_rates=tuple(sorted(b for b, ok in self.bauds.items() if ok)),
            max_tsdr=MappingProxyType(dict(sorted(self.tsdr.items()))),
            modules=tuple(modules),
            ext_user_prm=MappingProxyType(dict(self.ext_prm)),
            blocks=tuple(self.blocks),
            unknown=MappingProxyType(dict(self.unknown)),
            **values,
        )


def _end_name(end: str) -> str:
    names = {"endmodule": "EndModule", "endextuserprmdata": "EndExtUserPrmData",
             "endprmtext": "EndPrmText", "endunitdiagtype": "EndUnitDiagType",
             "x_endunitdiagtype": "X_EndUnitDiagType", "endslotdefinition": "EndSlotDefinition",
             "unit_diag_area_end": "Unit_Diag_Area_End", "x_unit_diag_area_end": "X_Unit_Diag_Area_End"}
    return names.get(end, end)


def _field_range(definition: ExtUserPrm) -> Tuple[int, int]:
    if definition.bits is not None:
        return 0, (1 << (definition.bits[1] - definition.bits[0] + 1)) - 1
    width = 8 * definition.size
    if definition.data_type.startswith("Signed"):
        return -(1 << (width - 1)), (1 << (width - 1)) - 1
    return 0, (1 << width) - 1


def parse_gsd(text: str, source: str = "<gsd>") -> Gsd:
    """Parse GSD text. ``source`` names the file in error messages. Raises GsdError."""
    if not isinstance(text, str):
        raise GsdError("%s: GSD text must be str, not %s (decode ISO-8859-1 first, or use load_gsd)"
                       % (source, type(text).__name__))
    if text.startswith("\ufeff"):
        text = text[1:]
    return _Parser(source).parse(text)


def load_gsd(path: Union[str, "os.PathLike[str]"]) -> Gsd:
    """Read and parse a GSD file (ISO-8859-1). Raises GsdError naming the file."""
    name = str(path)
    try:
        with open(name, "rb") as handle:
            raw = handle.read()
    except OSError as exc:
        raise GsdParseError(name, None, None, "cannot read GSD file: %s" % (exc.strerror or exc)) from exc
    if raw.startswith(b"\xef\xbb\xbf"):
        raw = raw[3:]
    return parse_gsd(raw.decode("iso-8859-1"), source=name)


# --------------------------------------------------------------------------------------------------
# Chk_Cfg / User_Prm_Data for a module selection
# --------------------------------------------------------------------------------------------------

def _selected_modules(gsd: Gsd, module_names: Sequence[str]) -> List[GsdModule]:
    if isinstance(module_names, (str, bytes)):
        raise GsdParseError(gsd.source, None, "modules",
                            "expected a list of module names, got the single string %r" % (module_names,))
    names = list(module_names)
    if not names:
        raise GsdParseError(gsd.source, None, "modules", "no modules selected")
    for name in names:
        if not isinstance(name, str):
            raise GsdParseError(gsd.source, None, "modules", "module names must be strings, got %r" % (name,))
    return [gsd.module(name) for name in names]


def build_chk_cfg(gsd: Gsd, module_names: Sequence[str]) -> bytes:
    """Chk_Cfg bytes for ``module_names`` in the given order (the order the slave expects).

    Checks the selection against Max_Module, Max_Input_Len, Max_Output_Len, Max_Data_Len and the
    244-byte Cfg limit; a GsdError names the limit that overflows.
    """
    modules = _selected_modules(gsd, module_names)
    in_len = sum(m.input_len for m in modules)
    out_len = sum(m.output_len for m in modules)
    cfg = b"".join(m.cfg for m in modules)
    checks = (
        ("Max_Module", len(modules), gsd.module_limit, "modules"),
        ("Max_Input_Len", in_len, gsd.input_limit, "input bytes"),
        ("Max_Output_Len", out_len, gsd.output_limit, "output bytes"),
        ("Max_Data_Len", in_len + out_len, gsd.data_limit, "input + output bytes"),
        ("Chk_Cfg length", len(cfg), DP_MAX_CFG_LEN, "Cfg bytes"),
    )
    for key, value, limit, unit in checks:
        if value > limit:
            raise GsdParseError(gsd.source, None, key, "%d %s exceed %s = %d (selection: %s)"
                                % (value, unit, key, limit, ", ".join(m.name for m in modules)))
    return cfg


def build_user_prm_data(gsd: Gsd, module_names: Sequence[str] = ()) -> bytes:
    """Default User_Prm_Data: the station part followed by each selected module's part."""
    modules = _selected_modules(gsd, module_names) if module_names else []
    data = gsd.user_prm_data + b"".join(m.prm_data for m in modules)
    limit = gsd.max_user_prm_data_len if gsd.max_user_prm_data_len is not None else DP_MAX_USER_PRM_DATA_LEN
    if len(data) > limit:
        raise GsdParseError(gsd.source, None, "Max_User_Prm_Data_Len",
                            "%d User_Prm_Data bytes exceed %d" % (len(data), limit))
    return data


# --------------------------------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------------------------------

def _arg_parser() -> argparse.ArgumentParser:
    parser = _cli.make_parser(
        "gsd",
        "Show what a PROFIBUS-DP GSD file declares and, with --modules, the Chk_Cfg bytes and "
        "data lengths of a module selection.",
        {_cli.EXIT_OK: "ok",
         _cli.EXIT_FAILED: "the GSD file cannot be read or is wrong, or the module selection does "
                           "not fit it",
         _cli.EXIT_USAGE: "usage error"},
        examples=['python3 -m pyprofibus_vendor.gsd gsd/PAN06C6.gsd',
                  'python3 -m pyprofibus_vendor.gsd gsd/PAN06C6.gsd --json '
                  '--modules "4 Bytes In,4 Bytes In,4 Bytes In,2 Bytes In,'
                  '4 Bytes Out,4 Bytes Out,4 Bytes Out,2 Bytes Out"'])
    parser.add_argument("file", help="GSD file (ISO-8859-1 text)")
    parser.add_argument("--modules", metavar="NAMES",
                        help='comma-separated module names in Chk_Cfg order, e.g. '
                             '"4 Bytes In,4 Bytes In,2 Bytes Out"')
    parser.add_argument("--json", action="store_true", help="print JSON instead of text")
    return parser


def _run_cli(args: argparse.Namespace) -> int:
    try:
        gsd = load_gsd(args.file)
        selection = None
        if args.modules is not None:
            names = [n.strip() for n in args.modules.split(",") if n.strip()]
            cfg = build_chk_cfg(gsd, names)
            in_len, out_len = cfg_io_lengths(cfg)
            selection = {"modules": names, "chk_cfg": format_hex(cfg),
                         "input_len": in_len, "output_len": out_len,
                         "user_prm_data": format_hex(build_user_prm_data(gsd, names))}
    except ConfigError as exc:  # the GSD file is what this tool checks: its faults are status 1
        raise _cli.OperationFailed(str(exc)) from None
    if args.json:
        out = gsd.to_dict()
        if selection is not None:
            out["selection"] = selection
        print(json.dumps(out, indent=2, sort_keys=True))
        return _cli.EXIT_OK
    print(gsd.summary())
    if selection is not None:
        print("Selection (%d modules): %s" % (len(selection["modules"]), ", ".join(selection["modules"])))
        print("  Chk_Cfg           %s" % selection["chk_cfg"])
        print("  Input  (slave -> master) %d bytes" % selection["input_len"])
        print("  Output (master -> slave) %d bytes" % selection["output_len"])
        if selection["user_prm_data"]:
            print("  User_Prm_Data     %s" % selection["user_prm_data"])
    return _cli.EXIT_OK


def main(argv: Optional[Sequence[str]] = None) -> int:
    """CLI entry point; returns the exit status (see :mod:`._cli` for the scheme)."""
    return _cli.run(_arg_parser(), _run_cli, argv)


if __name__ == "__main__":
    sys.exit(main())
