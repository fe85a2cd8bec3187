"""``python3 -m pyprofibus_vendor.sniff``: decode PROFIBUS telegrams from a device, a file or stdin.

One line per telegram: a timestamp (seconds since the start), the frame type (SD1, SD2, SD3, SD4,
SC), DA/SA with their SAP extensions (``DA=8:60`` = station 8, SAP 60), the FC byte in words
(request function with FCB/FCV, or response status and station type), the DP service when the SAPs
(or, for replies without SAPs, the request just before) identify one, with a short decode (diag
bits in words, Set_Prm fields, Cfg identifiers...), and the data bytes. Bytes that form no
telegram are reported as ``garbage`` lines, malformed telegrams (bad FCS, bad ED...) as error
lines; nothing in the input makes the tool fail. ``--json`` prints one JSON object per line.

The decoding is also usable from Python: :class:`SniffDecoder` turns bytes into event dicts and
:func:`format_event` renders one as the text line.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import select
import signal
import sys
import time
from typing import Any, Callable, Dict, List, Optional, Union

from . import _cli
from ._cli import DeviceError, OperationFailed, UsageError, hexstr
from .dp import (ChkCfg, GcCommand, GlobalControl, PrmStationStatus, Sap,
                 SetPrm, SetSlaveAdd, SlaveDiag, decode_cfg, explain_diag)
from .errors import DpError, FcsError, FrameError
from .fdl import (ED, BROADCAST, Frame, RequestFunction, ResponseStatus, Sd1, Sd2, Sd3, Sd4,
                  ShortAck, StartDelimiter, StationType, decode_frame, frame_length)

__all__ = ["main", "build_parser", "SniffDecoder", "format_event", "parse_hex_dump_line"]

#: A partial telegram is given up after the line was quiet this long (device and stdin).
IDLE_FLUSH = 0.1

_KNOWN_SD = frozenset(int(sd) for sd in StartDelimiter)

SAP_NAMES: Dict[int, str] = {
    Sap.SET_SLAVE_ADD: "Set_Slave_Add", Sap.RD_INP: "Rd_Inp", Sap.RD_OUTP: "Rd_Outp",
    Sap.GLOBAL_CONTROL: "Global_Control", Sap.GET_CFG: "Get_Cfg", Sap.SLAVE_DIAG: "Slave_Diag",
    Sap.SET_PRM: "Set_Prm", Sap.CHK_CFG: "Chk_Cfg",
    49: "MSAC_C2 initiate", 50: "Alarm_Ack", 51: "MSAC_C1",
}

_FUNCTION_WORDS = {
    RequestFunction.TIME_EVENT: "time event", RequestFunction.SDA_LOW: "SDA low",
    RequestFunction.SDN_LOW: "SDN low", RequestFunction.SDA_HIGH: "SDA high",
    RequestFunction.SDN_HIGH: "SDN high", RequestFunction.MSRD: "MSRD",
    RequestFunction.FDL_STATUS: "FDL status", RequestFunction.SRD_LOW: "SRD low",
    RequestFunction.SRD_HIGH: "SRD high", RequestFunction.IDENT: "ident",
    RequestFunction.LSAP_STATUS: "LSAP status",
}

_STATUS_WORDS = {
    ResponseStatus.OK: "OK", ResponseStatus.UE: "UE user error",
    ResponseStatus.RR: "RR no resources", ResponseStatus.RS: "RS SAP not activated",
    ResponseStatus.DL: "DL data low", ResponseStatus.NR: "NR no data",
    ResponseStatus.DH: "DH data high (diag pending)", ResponseStatus.RDL: "RDL data low, no resources",
    ResponseStatus.RDH: "RDH data high, no resources",
}

_STATION_WORDS = {
    StationType.SLAVE: "slave", StationType.MASTER_NOT_READY: "master not ready",
    StationType.MASTER_READY: "master ready", StationType.MASTER_IN_RING: "master in ring",
}

_DATA_STATUS = (ResponseStatus.DL, ResponseStatus.DH, ResponseStatus.RDL, ResponseStatus.RDH)


# --------------------------------------------------------------------------------------------------
# Service decoding
# --------------------------------------------------------------------------------------------------

def _flags(value: int, enum_cls: Any) -> str:
    names = [m.name for m in enum_cls if value & m]
    return "|".join(names) if names else "none"


def _describe_cfg(cfg: bytes) -> str:
    idents = decode_cfg(cfg)
    n_in = sum(i.input_len for i in idents)
    n_out = sum(i.output_len for i in idents)
    parts = ["%s=%s" % (hexstr(i.raw), i.describe()) for i in idents]
    return "%s (in %d, out %d)" % ("; ".join(parts), n_in, n_out)


def _describe_prm(data: bytes) -> str:
    prm = SetPrm.decode(data)
    status = _flags(int(prm.station_status), PrmStationStatus)
    wd = prm.watchdog_time
    text = "%s, watchdog %s, min TSDR %d, ident 0x%04X, groups 0x%02X" % (
        status, "off" if wd is None else "%g ms (%d x %d)" % (wd * 1000, prm.wd_fact1, prm.wd_fact2),
        prm.min_tsdr, prm.ident, prm.group_ident)
    if prm.user_prm_data:
        text += ", User_Prm_Data %s" % hexstr(prm.user_prm_data)
    return text


def _decode_service(service: str, role: str, frame: Any) -> Optional[str]:
    """A short decode of a DP service's data, or None when there is nothing to say."""
    data = bytes(getattr(frame, "data", b""))
    status = None if frame.fc.request else frame.fc.status
    if role == "reply" and isinstance(frame, Sd1):
        if service == "FDL_Status":
            return "%s, %s" % (_STATION_WORDS[frame.fc.station_type], _STATUS_WORDS[status])
        if status == ResponseStatus.OK:
            return "acknowledged"
        if status not in _DATA_STATUS:
            return "refused: %s" % _STATUS_WORDS[status]
    if service == "Slave_Diag" and role == "reply":
        return explain_diag(SlaveDiag.decode(data))
    if service == "Set_Prm" and role == "request":
        return _describe_prm(data)
    if (service, role) in (("Chk_Cfg", "request"), ("Get_Cfg", "reply")):
        return _describe_cfg(ChkCfg.decode(data).cfg)
    if service == "Global_Control" and role == "request":
        gc = GlobalControl.decode(data)
        return "%s, group select 0x%02X" % (_flags(int(gc.command), GcCommand), gc.group_select)
    if service == "Set_Slave_Add" and role == "request":
        req = SetSlaveAdd.decode(data)
        return "new address %d, ident 0x%04X%s" % (req.new_address, req.ident,
                                                   ", no further change" if req.no_add_chg else "")
    if service == "Data_Exchange":
        if role == "request":
            return "%d output bytes" % len(data)
        text = "%d input bytes" % len(data)
        if status in (ResponseStatus.DH, ResponseStatus.RDH):
            text += ", new diagnosis pending"
        return text
    if service in ("Rd_Inp", "Rd_Outp") and role == "reply":
        return "%d bytes" % len(data)
    return None


# --------------------------------------------------------------------------------------------------
# The decoder: bytes in, events (dicts) out
# --------------------------------------------------------------------------------------------------

class SniffDecoder:
    """Cut a byte stream into telegrams without ever raising on its content.

    :meth:`feed` returns events for everything the new bytes complete; :meth:`flush` (at the end
    of the input, or when the line went idle) also reports a partial telegram. Events are dicts
    with ``t`` (the time given), ``offset`` (byte offset in the stream), ``kind`` ('frame',
    'garbage' or 'error') and the decoded fields. ``counters`` counts frames, errors, FCS errors
    and garbage bytes.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self._offset = 0                     # stream offset of _buf[0]
        self._garbage = bytearray()
        self._garbage_offset = 0
        self._last_request: Optional[Dict[str, Any]] = None
        self.counters = {"frames": 0, "errors": 0, "fcs_errors": 0, "garbage_bytes": 0}

    @property
    def bytes_fed(self) -> int:
        """Stream offset just after the last byte fed."""
        return self._offset + len(self._buf)

    @property
    def pending(self) -> int:
        """Bytes held back (a telegram still being received)."""
        return len(self._buf)

    # -- public ---------------------------------------------------------------------------------
    def feed(self, data: bytes, t: float) -> List[Dict[str, Any]]:
        self._buf += data
        events: List[Dict[str, Any]] = []
        self._parse(t, events, final=False)
        self._flush_garbage(t, events)
        return events

    def flush(self, t: float) -> List[Dict[str, Any]]:
        events: List[Dict[str, Any]] = []
        self._parse(t, events, final=True)
        self._flush_garbage(t, events)
        return events

    # -- parsing --------------------------------------------------------------------------------
    def _consume(self, n: int) -> bytes:
        raw = bytes(self._buf[:n])
        del self._buf[:n]
        self._offset += n
        return raw

    def _to_garbage(self, n: int = 1) -> None:
        if not self._garbage:
            self._garbage_offset = self._offset
        self._garbage += self._consume(n)

    def _flush_garbage(self, t: float, events: List[Dict[str, Any]]) -> None:
        if self._garbage:
            self.counters["garbage_bytes"] += len(self._garbage)
            events.append({"t": t, "offset": self._garbage_offset, "kind": "garbage",
                           "type": "garbage", "length": len(self._garbage),
                           "raw": hexstr(self._garbage)})
            self._garbage.clear()

    def _complete_frame_at(self, pos: int) -> bool:
        """Whether a complete, valid telegram starts at ``_buf[pos]``."""
        buf = self._buf
        if buf[pos] not in _KNOWN_SD:
            return False
        try:
            n = frame_length(bytes(buf[pos:pos + 4]))
            if n is None or pos + n > len(buf):
                return False
            decode_frame(bytes(buf[pos:pos + n]))
        except FrameError:
            return False
        return True

    def _parse(self, t: float, events: List[Dict[str, Any]], final: bool) -> None:
        buf = self._buf
        while buf:
            if buf[0] not in _KNOWN_SD:
                self._to_garbage()
                continue
            try:
                n = frame_length(bytes(buf[:4]))
            except FrameError:          # e.g. an SD2 header whose LE and LEr differ
                self._to_garbage()
                continue
            if n is None or len(buf) < n:
                if not final:
                    return
                # the input ended inside this telegram: give up on it, keep what follows
                nxt = next((i for i in range(1, len(buf)) if self._complete_frame_at(i)), None)
                if nxt is not None:
                    self._to_garbage(nxt)
                    continue
                self._flush_garbage(t, events)
                offset = self._offset
                raw = self._consume(len(buf))
                need = "?" if n is None else str(n)
                self._error(events, t, offset, "truncated", "telegram cut short: %d of %s bytes"
                            % (len(raw), need), raw)
                continue
            raw = bytes(buf[:n])
            try:
                frame = decode_frame(raw)
            except FrameError as err:
                has_ed = raw[0] in (StartDelimiter.SD1, StartDelimiter.SD2, StartDelimiter.SD3) \
                    and raw[-1] == ED
                if not has_ed:          # not a telegram after all: resynchronise on the next byte
                    self._to_garbage()
                    continue
                self._flush_garbage(t, events)
                offset = self._offset
                self._consume(n)
                self._error(events, t, offset, "fcs" if isinstance(err, FcsError) else "format",
                            str(err), raw)
                continue
            self._flush_garbage(t, events)
            offset = self._offset
            self._consume(n)
            self.counters["frames"] += 1
            events.append(self._describe(frame, raw, t, offset))

    def _error(self, events: List[Dict[str, Any]], t: float, offset: int, kind: str,
               message: str, raw: bytes) -> None:
        self.counters["errors"] += 1
        if kind == "fcs":
            self.counters["fcs_errors"] += 1
        events.append({"t": t, "offset": offset, "kind": "error", "type": "error", "error": kind,
                       "message": message, "raw": hexstr(raw)})

    # -- describing a frame ---------------------------------------------------------------------
    def _describe(self, frame: Frame, raw: bytes, t: float, offset: int) -> Dict[str, Any]:
        ev: Dict[str, Any] = {"t": t, "offset": offset, "kind": "frame",
                              "type": StartDelimiter(raw[0]).name, "raw": hexstr(raw)}
        if isinstance(frame, ShortAck):
            req = self._last_request
            self._last_request = None
            ev["text"] = "short acknowledge"
            if req is not None:
                ev["service"] = req["service"]
                ev["role"] = "ack"
            return ev
        if isinstance(frame, Sd4):
            ev.update(da=frame.da, sa=frame.sa, text="token")
            self._last_request = None
            return ev
        assert isinstance(frame, (Sd1, Sd2, Sd3))
        fc = frame.fc
        dsap = getattr(frame, "dsap", None)
        ssap = getattr(frame, "ssap", None)
        data = bytes(getattr(frame, "data", b""))
        ev.update(da=frame.da, sa=frame.sa, fc=fc.encode(), request=fc.request)
        if dsap is not None:
            ev["dsap"] = dsap
        if ssap is not None:
            ev["ssap"] = ssap
        if fc.request:
            ev.update(function=RequestFunction(fc.code).name, fcb=fc.fcb, fcv=fc.fcv)
            ev["fc_text"] = "req %s FCB=%d FCV=%d" % (_FUNCTION_WORDS[fc.function], fc.fcb, fc.fcv)
        else:
            ev.update(status=ResponseStatus(fc.code).name,
                      station_type=_STATION_WORDS[fc.station_type])
            ev["fc_text"] = "resp %s, %s" % (_STATUS_WORDS[fc.status],
                                             _STATION_WORDS[fc.station_type])
        ev["data"] = hexstr(data)
        service, role = self._service(frame, dsap, ssap)
        if service is not None:
            ev["service"] = service
            ev["role"] = role
            try:
                decoded = _decode_service(service, role, frame)
            except (DpError, FrameError, ValueError) as err:
                decoded = "undecodable: %s" % err
            if decoded:
                ev["decode"] = decoded
        return ev

    def _service(self, frame: Any, dsap: Optional[int], ssap: Optional[int]) -> Any:
        """(service name, 'request'|'reply') or (None, None); tracks the pending request."""
        fc = frame.fc
        if fc.request:
            service: Optional[str] = None
            if dsap is not None:
                service = SAP_NAMES.get(dsap, "SAP %d" % dsap)
            elif fc.function == RequestFunction.FDL_STATUS:
                service = "FDL_Status"
            elif fc.function in (RequestFunction.SRD_HIGH, RequestFunction.SRD_LOW) \
                    and frame.da != BROADCAST:
                service = "Data_Exchange"
            expects_reply = fc.function not in (RequestFunction.SDN_LOW, RequestFunction.SDN_HIGH) \
                and frame.da != BROADCAST
            self._last_request = ({"service": service, "da": frame.da, "sa": frame.sa}
                                  if service is not None and expects_reply else None)
            return (service, "request") if service is not None else (None, None)
        req = self._last_request
        self._last_request = None
        if ssap is not None:
            return SAP_NAMES.get(ssap, "SAP %d" % ssap), "reply"
        if req is not None and req["da"] == frame.sa and req["sa"] == frame.da:
            return req["service"], "reply"
        return None, None


def format_event(ev: Dict[str, Any]) -> str:
    """The text line of one event."""
    stamp = "%10.6f" % ev["t"]
    kind = ev["kind"]
    if kind == "garbage":
        return "%s  ??   garbage, %d bytes: %s" % (stamp, ev["length"], ev["raw"])
    if kind == "error":
        what = {"fcs": "FCS error", "format": "bad telegram", "truncated": "truncated telegram",
                "hex": "bad hex dump line"}.get(ev["error"], ev["error"])
        tail = ": %s" % ev["raw"] if ev.get("raw") else ""
        return "%s  !!   %s (%s)%s" % (stamp, what, ev["message"], tail)
    parts = ["%s  %-3s " % (stamp, ev["type"])]
    if "da" in ev:
        da = "DA=%d%s" % (ev["da"], ":%d" % ev["dsap"] if "dsap" in ev else "")
        sa = "SA=%d%s" % (ev["sa"], ":%d" % ev["ssap"] if "ssap" in ev else "")
        parts.append("%-8s %-8s" % (da, sa))
    if "fc" in ev:
        parts.append("FC=%02X %s" % (ev["fc"], ev["fc_text"]))
    elif "text" in ev:
        parts.append(ev["text"])
    if "service" in ev:
        service = "%s %s" % (ev["service"], ev["role"])
        if ev.get("decode"):
            service += ": " + ev["decode"]
        parts.append("| " + service)
    if ev.get("data"):
        parts.append("| data %s" % ev["data"])
    return " ".join(parts)


# --------------------------------------------------------------------------------------------------
# Inputs: a device, a file or stdin (raw bytes or a hex dump)
# --------------------------------------------------------------------------------------------------

_XXD_RE = re.compile(r"\A\s*[0-9A-Fa-f]{4,}:\s")            # xxd: "00000010: 6805 0568 ..."
_HEXDUMP_C_RE = re.compile(r"\A[0-9A-Fa-f]{7,8}(?:\s\s|\s*\Z)")  # hexdump -C: "00000010  68 05 ..."
_TOKEN_SPLIT_RE = re.compile(r"[\s,:;]+")
_TOKEN_RE = re.compile(r"\A(?:0[xX])?([0-9A-Fa-f]+)\Z")
_PRINTABLE = frozenset(range(0x20, 0x7F)) | frozenset(b"\t\r\n\f\v")


def parse_hex_dump_line(line: str, hexdump_c: bool = False) -> bytes:
    """The bytes of one hex dump line: plain hex (``68 05 05 68``, ``0x68,0x05``, ``680505``),
    an ``xxd`` line or a ``hexdump -C`` line (offset and ASCII column dropped); ``#`` starts a
    comment. ValueError when the line holds something else."""
    line = line.split("#", 1)[0].rstrip()
    if not line.strip():
        return b""
    if _XXD_RE.match(line):
        line = line.split(":", 1)[1]
        line = re.split(r"\s{2,}", line.strip(), maxsplit=1)[0]
    elif "|" in line and _HEXDUMP_C_RE.match(line):
        line = line.split("|", 1)[0][8:]
    elif hexdump_c and _HEXDUMP_C_RE.match(line) and len(line.strip()) in (7, 8):
        return b""                                            # the final offset line
    out = bytearray()
    for token in _TOKEN_SPLIT_RE.split(line.strip()):
        if not token:
            continue
        match = _TOKEN_RE.match(token)
        if not match:
            raise ValueError("%r is not hex" % token)
        digits = match.group(1)
        if len(digits) % 2:
            raise ValueError("%r has an odd number of hex digits" % token)
        out += bytes.fromhex(digits)
    return bytes(out)


Item = Union[bytes, str]   # input bytes, or the message of a bad hex dump line


class _HexText:
    """Incremental hex dump decoder: text chunks in, items out (bytes, or an error message for a
    line that is not hex), in input order."""

    def __init__(self) -> None:
        self._pending = b""
        self.line_no = 0
        self._hexdump_c = False

    def _line(self, raw: bytes, items: List[Item]) -> None:
        self.line_no += 1
        text = raw.decode("ascii", "replace")
        if "|" in text:
            self._hexdump_c = True
        try:
            data = parse_hex_dump_line(text, self._hexdump_c)
        except ValueError as exc:
            items.append("line %d: %s" % (self.line_no, exc))
            return
        if data:
            if items and isinstance(items[-1], bytes):
                items[-1] += data
            else:
                items.append(data)

    def feed(self, chunk: bytes) -> List[Item]:
        lines = (self._pending + chunk).split(b"\n")
        self._pending = lines.pop()
        items: List[Item] = []
        for line in lines:
            self._line(line, items)
        return items

    def finish(self) -> List[Item]:
        rest, self._pending = self._pending, b""
        items: List[Item] = []
        if rest.strip():
            self._line(rest, items)
        return items


class _FileSource:
    """Reads a file or stdin (a pipe may deliver slowly: reads wait in select)."""

    def __init__(self, path: str, fmt: str) -> None:
        self.name = "stdin" if path == "-" else path
        if path == "-":
            self.fd = sys.stdin.buffer.fileno()
            self.owns = False
        else:
            try:
                self.fd = os.open(path, os.O_RDONLY)
            except OSError as exc:
                raise DeviceError("cannot open %s: %s" % (path, exc.strerror or exc)) from None
            if os.path.isdir(path):
                os.close(self.fd)
                raise DeviceError("cannot open %s: Is a directory" % path)
            self.owns = True
        self.fmt = fmt                 # auto | raw | hex
        self.hex: Optional[_HexText] = _HexText() if fmt == "hex" else None
        self.eof = False

    def read(self, timeout: float) -> Optional[List[Item]]:
        """Items read within ``timeout`` (maybe none), or None after the end of the input."""
        if self.eof:
            return None
        ready, _, _ = select.select([self.fd], [], [], max(0.0, timeout))
        if not ready:
            return []
        try:
            chunk = os.read(self.fd, 65536)
        except OSError as exc:
            raise DeviceError("cannot read %s: %s" % (self.name, exc.strerror or exc)) from None
        if not chunk:
            self.eof = True
            return self.hex.finish() if self.hex is not None else None
        if self.fmt == "auto":
            self.fmt = "hex" if all(b in _PRINTABLE for b in chunk) else "raw"
            if self.fmt == "hex":
                self.hex = _HexText()
        return self.hex.feed(chunk) if self.hex is not None else [chunk]

    def close(self) -> None:
        if self.owns:
            os.close(self.fd)


class _DeviceSource:
    eof = False              # a device never ends

    def __init__(self, device: str, baud: int) -> None:
        self.name = device
        self.link = _cli.open_serial(device, baud)

    def read(self, timeout: float) -> Optional[List[Item]]:
        data = self.link.recv(65536, max(0.0, timeout))
        return [data] if data else []

    def close(self) -> None:
        self.link.close()


# --------------------------------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------------------------------

_DESCRIPTION = """\
Decode PROFIBUS telegrams read from a device (a bus tap, an RS-485 adapter, a pty) or from a file
or stdin holding raw bytes or a hex dump. One line per telegram: timestamp (s since the start),
frame type (SD1 SD2 SD3 SD4 SC), DA and SA with their SAP extensions (DA=8:60 = station 8, SAP
60), the FC byte in words (request function and FCB/FCV, or response status and station type),
the DP service when the SAPs (or the request before a reply) identify one - Set_Prm, Chk_Cfg,
Slave_Diag, Get_Cfg, Global_Control, Data_Exchange, FDL_Status... - with a short decode, and the
data bytes.

Bytes that form no telegram are printed as "??" garbage lines, malformed telegrams (FCS, ED, LE
errors) and bad hex dump lines as "!!" lines; the tool does not stop on them. Hex dumps may be
plain hex bytes, xxd or hexdump -C output; '#' starts a comment. Stops at the end of the file,
after --count telegrams, after --duration seconds, or on SIGINT/SIGTERM; a summary goes to
stderr."""

_EXAMPLES = [
    "python3 -m pyprofibus_vendor.sniff --device /dev/ttyUSB1 --baud 19200 --duration 10",
    "python3 -m pyprofibus_vendor.sniff --file capture.hex --json",
    "socat -u /dev/ttyUSB1,raw,b19200 - | python3 -m pyprofibus_vendor.sniff --file - --count 50",
]

_EXIT_MEANINGS = {
    _cli.EXIT_OK: "done (end of input, --count reached, --duration over, or stopped by a signal)",
    _cli.EXIT_FAILED: "fewer telegrams than --count were seen",
    _cli.EXIT_USAGE: "usage error (bad option value)",
    _cli.EXIT_DEVICE: "the device or the file cannot be opened or read",
}


def build_parser() -> argparse.ArgumentParser:
    p = _cli.make_parser("sniff", _DESCRIPTION, _EXIT_MEANINGS, _EXAMPLES)
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--device", metavar="DEV", help="serial device or pyserial URL to listen on")
    where.add_argument("--file", metavar="FILE",
                       help="read raw bytes or a hex dump from FILE ('-' = stdin)")
    p.add_argument("--baud", metavar="B", type=_cli.baud_arg, default=19200,
                   help="bit rate of --device (default 19200)")
    p.add_argument("--format", choices=("auto", "raw", "hex"), default="auto",
                   help="what --file holds (default auto: text is a hex dump, else raw bytes)")
    p.add_argument("--count", metavar="N", type=_cli.count_arg,
                   help="stop after N telegrams (garbage and error lines do not count)")
    p.add_argument("--duration", metavar="S", type=_cli.seconds_arg, help="stop after S seconds")
    p.add_argument("--json", action="store_true", help="one JSON object per line")
    p.add_argument("-v", "--verbose", action="count", default=0,
                   help="log library messages on stderr")
    return p


class _Stop(Exception):
    pass


def _run(args: argparse.Namespace) -> int:
    _cli.line_buffered_stdout()
    _cli.setup_logging(args.verbose)
    if args.device is not None and args.format != "auto":
        raise UsageError("--format applies to --file only")

    def on_signal(signum: int, _frame: Any) -> None:
        raise _Stop()

    source: Any = (_DeviceSource(args.device, args.baud) if args.device is not None
                   else _FileSource(args.file, args.format))
    decoder = SniffDecoder()
    emit: Callable[[Dict[str, Any]], None]
    if args.json:
        def emit(ev: Dict[str, Any]) -> None:
            out = dict(ev)
            out["t"] = round(out["t"], 6)
            del out["kind"]
            print(json.dumps(out, sort_keys=True))
    else:
        def emit(ev: Dict[str, Any]) -> None:
            print(format_event(ev))

    start = time.monotonic()
    deadline = None if args.duration is None else start + args.duration
    seen = 0
    shown = {"frame": 0, "error": 0, "fcs": 0, "garbage": 0}
    last_rx = start
    old_int = signal.signal(signal.SIGINT, on_signal)
    old_term = signal.signal(signal.SIGTERM, on_signal)
    if args.device is not None:
        print("listening on %s at %d baud" % (args.device, args.baud), file=sys.stderr, flush=True)
    try:
        done = False
        while not done:
            now = time.monotonic()
            if deadline is not None and now >= deadline:
                break
            wait = IDLE_FLUSH if deadline is None else min(IDLE_FLUSH, deadline - now)
            items = source.read(wait)
            now = time.monotonic()
            t = now - start
            events: List[Dict[str, Any]] = []
            for item in items or []:
                if isinstance(item, str):
                    events.append({"t": t, "offset": decoder.bytes_fed, "kind": "error",
                                   "type": "error", "error": "hex", "message": item, "raw": ""})
                else:
                    last_rx = now
                    events += decoder.feed(item, t)
            if source.eof:
                events += decoder.flush(t)
                done = True
            elif not items and decoder.pending and now - last_rx >= IDLE_FLUSH:
                events += decoder.flush(t)
            for ev in events:
                emit(ev)
                shown[ev["kind"]] += ev.get("length", 1)
                if ev.get("error") == "fcs":
                    shown["fcs"] += 1
                if ev["kind"] == "frame":
                    seen += 1
                    if args.count is not None and seen >= args.count:
                        done = True
                        break
    except _Stop:
        pass
    finally:
        signal.signal(signal.SIGINT, old_int)
        signal.signal(signal.SIGTERM, old_term)
        source.close()
    print("summary: %d telegrams, %d errors (%d FCS), %d garbage bytes in %.3f s"
          % (shown["frame"], shown["error"], shown["fcs"], shown["garbage"],
             time.monotonic() - start), file=sys.stderr, flush=True)
    if args.count is not None and seen < args.count:
        raise OperationFailed("only %d of %d telegrams seen" % (seen, args.count))
    return _cli.EXIT_OK


def main(argv: Optional[List[str]] = None) -> int:
    """CLI entry point; returns the exit status."""
    return _cli.run(build_parser(), _run, argv)


if __name__ == "__main__":
    sys.exit(main())
