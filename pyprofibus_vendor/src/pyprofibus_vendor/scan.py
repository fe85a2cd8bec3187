"""A live list of the stations on a PROFIBUS line: which bit rate the line runs at, which stations
answer there, and what each one is -- the first look at a line nobody has described. ROS-free.

Per bit rate (19.2 kbit/s first, then the other standard rates the port accepts, until a rate with a
station; ``all_rates`` goes on) :class:`Scanner` does, on a link it opens at that rate:

1. **listen** (``listen`` seconds) before sending anything. Telegrams of another master (a token,
   SD4 ``DC``, or a request from an address not ours) mean the line is someone else's: the scan
   sends nothing on it, lists the stations it heard answer and names that master
   (:attr:`RateResult.other_masters`); that rate is the line's. Bytes that form no telegram at this
   rate (a line busy at another rate; more than :data:`STRAY_BYTES`, which a port may see when it
   is opened) also keep it silent at this rate (:attr:`RateResult.foreign_bytes`).
2. **FDL status** (SD1, FC ``Request FDL Status``) to every address of ``addresses`` except its own:
   the reply's FC tells the station type (passive: a slave; active: a master not ready, ready for
   the ring or in the ring).
3. to each passive station, the two read-only DP services any master may use without
   parameterising it: **Slave_Diag** (SAP 60: ident number, the address of the master that
   parameterised it, its state in words) and **Get_Cfg** (SAP 59: its configuration, the Cfg
   identifier bytes). Never Set_Prm, Chk_Cfg or Data_Exchange: the scan changes no station.

The replies are matched to the GSD files given (by default those shipped in ``pyprofibus_vendor/gsd``):
the file with the station's ident number and, where the configuration is made of that file's
modules, the module names. Two properties of the adapter are measured on the way: whether it
**echoes** its own transmission (each request's bytes come back verbatim before the reply; the scan
skips them and says so) and the **reply latency** per station, from the write's return (the echo's
last byte when the adapter echoes: the request has left the adapter then) to the reply's first byte
-- the request's transmission, what the port and the adapter add and the station's turnaround: what
a master's reply timeout must cover.

A reply that comes after its window (a slow adapter) is still taken: it names its source, so the
station is listed (marked late) whatever was asked next.

:class:`Scanner` takes a function opening a :class:`~.phy.Link` at a rate (a serial port:
:func:`serial_opener`; tests: an in-memory line) and an injectable clock. ``python3 -m
pyprofibus_vendor.scan --device DEV`` runs it from the shell (:func:`main`).
"""
from __future__ import annotations

import argparse
import json
import logging
import os
import statistics
import sys
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, Iterable, List, Optional, Sequence, Tuple

from . import _cli
from .dp import MASTER_SAP, Sap, SlaveDiag, cfg_io_lengths, explain_diag, request_frame
from .errors import DpError, GsdError, PhyError
from .fdl import (Deframer, FcbRequester, Frame, FrameControl, RequestFunction, ResponseStatus, Sd1,
                  Sd4, ShortAck, StationType)
from .gsd import STANDARD_BAUDRATES, Gsd, load_gsd
from .phy import Link

__all__ = ["STRAY_BYTES", "RATE_ORDER", "REPLY_FLOOR_SERIAL", "REPLY_FLOOR_VIRTUAL", "DEFAULT_LISTEN", "DEFAULT_MASTER_ADDRESS",
           "GsdMatch", "StationFound", "RateResult", "ScanResult", "Scanner", "match_gsd", "shipped_gsds",
           "serial_opener", "default_reply_timeout", "build_parser", "scan_from_args", "format_result", "main"]

log = logging.getLogger(__name__)

Clock = Callable[[], float]
Opener = Callable[[int], Link]

#: the order rates are tried in: 19.2 kbit/s (the thesis' and the tools' default) first, then the
#: other standard rates from the slowest up
RATE_ORDER: Tuple[int, ...] = (19200,) + tuple(r for r in STANDARD_BAUDRATES if r != 19200)
#: reply window [s] on a real serial port: a USB adapter's latency timer (16 ms by default) and the
#: station's own turnaround, at any rate
REPLY_FLOOR_SERIAL = 0.05
#: reply window [s] on a pty or a network URL, where software latency dominates
REPLY_FLOOR_VIRTUAL = 0.1
#: bytes heard while listening that form no telegram and still let the scan send (a port being
#: opened, a line switching on, may show a character or two)
STRAY_BYTES = 2
#: seconds the scan listens on each rate before it sends
DEFAULT_LISTEN = 0.5
#: the scan's own station address: 0, a class 2 master's usual one (not the driver's 2, which a
#: running driver would hold)
DEFAULT_MASTER_ADDRESS = 0
_CHAR_BITS = 11

_STATION_WORDS = {
    StationType.SLAVE: "passive (a slave)",
    StationType.MASTER_NOT_READY: "active (a master, not ready)",
    StationType.MASTER_READY: "active (a master, ready for the token ring)",
    StationType.MASTER_IN_RING: "active (a master in the token ring)",
}


# ----------------------------------------------------------------------------------------- results

@dataclass(frozen=True)
class GsdMatch:
    """The GSD file of a station's ident number; ``modules``: the module names its configuration is
    made of (None: the configuration is not made of this file's modules, or was not read)."""

    file: str
    model: str
    vendor: str
    modules: Optional[Tuple[str, ...]] = None

    @property
    def name(self) -> str:
        return os.path.basename(self.file)


@dataclass
class StationFound:
    """One station that answered (see the module docstring)."""

    address: int
    station_type: StationType
    latencies: List[float] = field(default_factory=list)
    diag: Optional[SlaveDiag] = None
    cfg: Optional[bytes] = None
    gsd: Optional[GsdMatch] = None
    late: bool = False
    problems: List[str] = field(default_factory=list)

    @property
    def passive(self) -> bool:
        return self.station_type == StationType.SLAVE

    @property
    def ident(self) -> Optional[int]:
        return None if self.diag is None else self.diag.ident

    @property
    def owner(self) -> Optional[int]:
        """The address of the master that parameterised the station (Slave_Diag byte 4), or None."""
        return None if self.diag is None else self.diag.locked_by

    def to_dict(self) -> Dict[str, Any]:
        lengths = None
        if self.cfg is not None:
            try:
                lengths = cfg_io_lengths(self.cfg)
            except DpError:
                pass
        return {
            "address": self.address, "station_type": self.station_type.name.lower(),
            "ident": None if self.ident is None else "0x%04X" % self.ident,
            "owner": self.owner, "diag": None if self.diag is None else explain_diag(self.diag),
            "cfg": None if self.cfg is None else _cli.hexstr(self.cfg),
            "input_len": None if lengths is None else lengths[0],
            "output_len": None if lengths is None else lengths[1],
            "gsd": None if self.gsd is None else {"file": self.gsd.name, "model": self.gsd.model,
                                                  "modules": None if self.gsd.modules is None
                                                  else list(self.gsd.modules)},
            "latency_ms": None if not self.latencies else round(statistics.median(self.latencies) * 1e3, 3),
            "latency_max_ms": None if not self.latencies else round(max(self.latencies) * 1e3, 3),
            "late": self.late, "problems": list(self.problems),
        }


@dataclass
class RateResult:
    """What one bit rate showed."""

    rate: int
    opened: bool = True
    why_not: str = ""                 # the port refused the rate: its reason
    probed: int = 0                   # addresses asked
    seconds: float = 0.0
    stations: Dict[int, StationFound] = field(default_factory=dict)
    #: other masters heard: address -> what (token / a request to station N)
    other_masters: Dict[int, str] = field(default_factory=dict)
    #: stations heard answering another master (listening only)
    heard: List[int] = field(default_factory=list)
    foreign_bytes: int = 0            # bytes that formed no telegram at this rate, while listening
    garbage_bytes: int = 0            # such bytes in the replies
    requests: int = 0
    echoes: int = 0                   # requests that came back verbatim

    @property
    def silent(self) -> bool:
        """The scan sent nothing at this rate (another master, or foreign traffic)."""
        return bool(self.other_masters) or self.foreign_bytes > STRAY_BYTES

    @property
    def found(self) -> bool:
        """Stations answered or were heard, or another master speaks at this rate."""
        return bool(self.stations or self.heard or self.other_masters)

    def to_dict(self) -> Dict[str, Any]:
        return {"rate": self.rate, "opened": self.opened, "why_not": self.why_not, "probed": self.probed,
                "seconds": round(self.seconds, 3), "stations": [s.to_dict() for s in self.stations.values()],
                "other_masters": {str(k): v for k, v in self.other_masters.items()}, "heard": self.heard,
                "foreign_bytes": self.foreign_bytes, "garbage_bytes": self.garbage_bytes,
                "requests": self.requests, "echoes": self.echoes}


@dataclass
class ScanResult:
    """Every rate tried, in order; :attr:`rate` the line's (the first with a station)."""

    device: str
    master_address: int
    addresses: Tuple[int, ...]
    rates: List[RateResult] = field(default_factory=list)

    @property
    def found(self) -> Optional[RateResult]:
        """The first rate at which stations answered or were heard, or another master spoke."""
        return next((r for r in self.rates if r.found), None)

    @property
    def rate(self) -> Optional[int]:
        found = self.found
        return None if found is None else found.rate

    @property
    def stations(self) -> List[StationFound]:
        found = self.found
        return [] if found is None else [found.stations[a] for a in sorted(found.stations)]

    @property
    def other_masters(self) -> Dict[int, str]:
        out: Dict[int, str] = {}
        for r in self.rates:
            out.update(r.other_masters)
        return out

    @property
    def echo(self) -> Optional[bool]:
        """True: the adapter echoed every request; False: none; None: no request was sent."""
        requests = sum(r.requests for r in self.rates)
        if not requests:
            return None
        return sum(r.echoes for r in self.rates) * 2 > requests

    def to_dict(self) -> Dict[str, Any]:
        return {"device": self.device, "master_address": self.master_address, "rate": self.rate,
                "echo": self.echo, "other_masters": {str(k): v for k, v in self.other_masters.items()},
                "rates": [r.to_dict() for r in self.rates]}


# -------------------------------------------------------------------------------------------- GSDs

def shipped_gsds() -> List[Gsd]:
    """The GSD files shipped with this package (the first directory of the GSD search path that has
    any; one per file name). A file that does not parse is skipped with a warning."""
    from .config import _gsd_dirs
    seen: Dict[str, Gsd] = {}
    for directory in _gsd_dirs():
        if not directory.is_dir():
            continue
        for path in sorted(directory.iterdir()):
            if path.suffix.lower() != ".gsd" or path.name.lower() in seen:
                continue
            try:
                seen[path.name.lower()] = load_gsd(path)
            except GsdError as exc:
                log.warning("skipping %s: %s", path, exc)
    return list(seen.values())


def _modules_of(gsd: Gsd, cfg: bytes) -> Optional[Tuple[str, ...]]:
    """The module names whose Cfg bytes, in order, make ``cfg`` (longest module first at each
    place), or None when no such sequence exists."""
    modules = sorted((m for m in gsd.modules if m.cfg), key=lambda m: -len(m.cfg))
    out: List[str] = []
    pos = 0
    while pos < len(cfg):
        module = next((m for m in modules if cfg.startswith(m.cfg, pos)), None)
        if module is None:
            return None
        out.append(module.name)
        pos += len(module.cfg)
    return tuple(out)


def match_gsd(gsds: Iterable[Gsd], ident: Optional[int], cfg: Optional[bytes]) -> Optional[GsdMatch]:
    """The GSD of ``ident`` among ``gsds`` (the first whose modules make ``cfg``, else the first of
    the ident), or None."""
    if ident is None:
        return None
    candidates = [g for g in gsds if g.ident_number == ident]
    best = None
    for gsd in candidates:
        modules = _modules_of(gsd, cfg) if cfg else None
        match = GsdMatch(gsd.source, gsd.model_name, gsd.vendor_name, modules)
        if modules is not None:
            return match
        best = best or match
    return best


# ----------------------------------------------------------------------------------------- scanner

def default_reply_timeout(rate: int, virtual: bool) -> float:
    """The reply window at ``rate``: the floor (:data:`REPLY_FLOOR_SERIAL`, or
    :data:`REPLY_FLOOR_VIRTUAL` on a pty / URL) or four slot times of 100 bits with a 10-character
    reply, whichever is longer."""
    floor = REPLY_FLOOR_VIRTUAL if virtual else REPLY_FLOOR_SERIAL
    return max(floor, 4 * 100.0 / rate + 10 * _CHAR_BITS / rate)


class _Abort(Exception):
    """Another master spoke: stop sending at this rate."""


class Scanner:
    """See the module docstring. ``open_link(rate)`` gives a link at that rate (PhyError: the port
    refuses the rate); ``reply_timeout(rate)`` the reply window. :meth:`scan` runs it."""

    #: Slave_Diag and Get_Cfg are asked again this often without a reply (FDL status is not: a
    #: missing station would cost the time twice, and a late reply still names its station)
    SERVICE_RETRIES = 1

    def __init__(self, open_link: Opener, *, device: str = "", rates: Sequence[int] = RATE_ORDER,
                 addresses: Sequence[int] = tuple(range(126)), master_address: int = DEFAULT_MASTER_ADDRESS,
                 reply_timeout: Callable[[int], float] = lambda rate: default_reply_timeout(rate, False),
                 listen: float = DEFAULT_LISTEN, all_rates: bool = False, gsds: Sequence[Gsd] = (),
                 clock: Clock = time.monotonic, progress: Optional[Callable[[str], None]] = None) -> None:
        if not rates:
            raise ValueError("no bit rate to try")
        bad = [a for a in addresses if not 0 <= a <= 125]
        if bad:
            raise ValueError("addresses outside 0..125: %s" % bad)
        if not 0 <= master_address <= 125:
            raise ValueError("master address %d outside 0..125" % master_address)
        if listen < 0:
            raise ValueError("listen time %r < 0" % listen)
        self.open_link = open_link
        self.device = device
        self.rates = tuple(rates)
        self.addresses = tuple(sorted(set(addresses)))
        self.master_address = master_address
        self.reply_timeout = reply_timeout
        self.listen = listen
        self.all_rates = all_rates
        self.gsds = list(gsds)
        self.clock = clock
        self.progress = progress or (lambda text: None)
        # per rate
        self._link: Optional[Link] = None
        self._res = RateResult(0)
        self._deframer = Deframer()
        self._rate = 0

    # ---------------------------------------------------------------------------- whole scan
    def scan(self) -> ScanResult:
        result = ScanResult(self.device, self.master_address, self.addresses)
        for rate in self.rates:
            r = self.scan_rate(rate)
            result.rates.append(r)
            if r.found and not self.all_rates:
                break
        return result

    def scan_rate(self, rate: int) -> RateResult:
        """Listen, then (if the line is ours) probe every address at ``rate``."""
        self._res = res = RateResult(rate)
        self._rate = rate
        self._deframer = Deframer()
        start = self.clock()
        try:
            self._link = self.open_link(rate)
        except PhyError as exc:
            res.opened, res.why_not = False, str(exc)
            self.progress("rate %d: the port refuses it (%s)" % (rate, exc))
            return res
        try:
            self.progress("rate %d: listening %.2g s" % (rate, self.listen))
            self._listen(self.listen)
            if not res.silent:
                try:
                    self._probe_all()
                except _Abort:
                    self._listen(self.listen)      # what that master does: the stations it polls
        finally:
            self._link.close()
            self._link = None
            res.seconds = self.clock() - start
        return res

    # ----------------------------------------------------------------------------- receiving
    def _listen(self, seconds: float) -> None:
        deadline = self.clock() + seconds
        while True:
            left = deadline - self.clock()
            if left <= 0:
                break
            data = self._link.recv(4096, left)        # type: ignore[union-attr]
            if data:
                for frame in self._feed(data, listening=True):
                    self._foreign(frame)
        self._res.foreign_bytes += self._deframer.discard_partial()

    def _feed(self, data: bytes, listening: bool) -> List[Frame]:
        before = self._deframer.counters.garbage_bytes
        frames = self._deframer.feed(data)
        lost = self._deframer.counters.garbage_bytes - before
        if listening:
            self._res.foreign_bytes += lost
        else:
            self._res.garbage_bytes += lost
        return frames

    def _foreign(self, frame: Frame) -> bool:
        """Note a telegram that is no reply to us; True when it came from another master."""
        res = self._res
        if isinstance(frame, Sd4):
            res.other_masters.setdefault(frame.sa, "passes the token to station %d" % frame.da)
            return True
        if isinstance(frame, ShortAck):
            return False
        if frame.fc.request:
            if frame.sa != self.master_address:
                res.other_masters.setdefault(frame.sa, "sends requests (to station %d)" % frame.da)
                return True
            return False
        if frame.da == self.master_address:
            self._reply_from(frame, late=True)
        elif frame.sa not in res.heard:
            res.heard.append(frame.sa)
        return False

    def _reply_from(self, frame: Frame, late: bool) -> StationFound:
        st = self._res.stations.get(frame.sa)                           # type: ignore[union-attr]
        if st is None:
            st = StationFound(frame.sa, frame.fc.station_type, late=late)  # type: ignore[union-attr]
            self._res.stations[frame.sa] = st                           # type: ignore[union-attr]
        return st

    def _answers(self, f: Frame, address: int, sap: Optional[int]) -> bool:
        """``f`` is the reply of ``address`` to our request (to ``sap``: its data from that SAP or a
        refusal; a stale reply to an earlier request of ours is not)."""
        if isinstance(f, (Sd4, ShortAck)) or f.fc.request or f.da != self.master_address or f.sa != address:
            return False
        if sap is None:
            return True
        if isinstance(f, Sd1):
            return f.fc.status != ResponseStatus.OK
        return getattr(f, "ssap", None) == sap

    def _transact(self, frame: Frame, address: int, sap: Optional[int] = None) -> Tuple[Optional[Frame], Optional[float]]:
        """Send ``frame``; the reply from ``address`` to us and its latency, or (None, None).
        Telegrams of another master raise _Abort; late replies of other stations are noted."""
        link = self._link
        assert link is not None
        data = link.recv(4096, 0.0)        # what arrived since: late replies, another master
        while data:
            for f in self._feed(data, listening=False):
                if self._foreign(f):
                    raise _Abort()
            data = link.recv(4096, 0.0)
        self._deframer.discard_partial()
        raw = frame.encode()
        window = self.reply_timeout(self._rate)
        sent = self.clock()
        link.send(raw)
        self._res.requests += 1
        line_end = sent
        echo_pos = 0
        echoing = True
        first: Optional[float] = None
        deadline = sent + len(raw) * _CHAR_BITS / self._rate + window
        extended = False
        while True:
            now = self.clock()
            if now >= deadline:
                if self._deframer.pending and self._deframer.bytes_needed() != 0 and not extended:
                    deadline, extended = now + window, True     # a telegram is arriving: let it finish
                    continue
                break
            data = link.recv(4096, deadline - now)
            if not data:
                continue
            at = self.clock()
            if echoing:
                n = 0
                while n < len(data) and echo_pos + n < len(raw) and data[n] == raw[echo_pos + n]:
                    n += 1
                if echo_pos + n == len(raw):
                    echoing = False
                    self._res.echoes += 1
                    line_end = at                  # the echo's last byte: the request left the adapter
                    deadline = line_end + window
                    data = data[n:]
                elif n == len(data):
                    echo_pos += n                  # so far the echo: wait for the rest
                    continue
                else:                              # not an echo: those bytes are the reply's
                    data = raw[:echo_pos] + data
                    echoing = False
            if not data:
                continue
            if first is None:
                first = at
            for f in self._feed(data, listening=False):
                if self._answers(f, address, sap):
                    return f, first - line_end
                if self._foreign(f):
                    raise _Abort()
        self._deframer.discard_partial()
        return None, None

    # ------------------------------------------------------------------------------- probing
    def _probe_all(self) -> None:
        res = self._res
        todo = [a for a in self.addresses if a != self.master_address]
        self.progress("rate %d: FDL status to %d addresses" % (self._rate, len(todo)))
        for address in todo:
            res.probed += 1
            reply, latency = self._transact(
                Sd1(address, self.master_address, FrameControl.req(RequestFunction.FDL_STATUS)), address)
            if reply is None:
                continue
            st = self._reply_from(reply, late=False)
            st.late = False
            if latency is not None:
                st.latencies.append(latency)
            self.progress("rate %d: station %d answers: %s" % (self._rate, address, _STATION_WORDS[st.station_type]))
        self._collect_late()
        for address in sorted(res.stations):
            st = res.stations[address]
            if st.passive:
                self._read_slave(st)

    def _collect_late(self) -> None:
        """Wait one reply window for replies still under way (the last addresses' when late)."""
        link = self._link
        assert link is not None
        deadline = self.clock() + self.reply_timeout(self._rate)
        while True:
            left = deadline - self.clock()
            if left <= 0:
                return
            data = link.recv(4096, left)
            for f in self._feed(data, listening=False) if data else ():
                if self._foreign(f):
                    raise _Abort()

    def _service(self, st: StationFound, fcb: FcbRequester, sap: Sap) -> Optional[bytes]:
        fc_bits = fcb.bits()
        frame = request_frame(st.address, self.master_address, fc_bits[0], fc_bits[1], sap)
        name = sap.name.title()
        for _ in range(1 + self.SERVICE_RETRIES):       # a retry keeps the FCB: the station answers it once
            reply, latency = self._transact(frame, st.address, int(sap))
            if reply is not None:
                break
        else:
            st.problems.append("no reply to %s (%d tries)" % (name, 1 + self.SERVICE_RETRIES))
            return None
        fcb.acknowledge()
        if latency is not None:
            st.latencies.append(latency)
        data = getattr(reply, "data", None)
        if data is None or getattr(reply, "ssap", None) != int(sap) or getattr(reply, "dsap", None) != MASTER_SAP:
            st.problems.append("%s refused (reply %s)" % (name, reply.fc))   # type: ignore[union-attr]
            return None
        return bytes(data)

    def _read_slave(self, st: StationFound) -> None:
        fcb = FcbRequester()
        data = self._service(st, fcb, Sap.SLAVE_DIAG)
        if data is not None:
            try:
                st.diag = SlaveDiag.decode(data)
            except DpError as exc:
                st.problems.append("Slave_Diag unreadable: %s" % exc)
        st.cfg = self._service(st, fcb, Sap.GET_CFG)
        st.gsd = match_gsd(self.gsds, st.ident, st.cfg)


# ------------------------------------------------------------------------------------------ output

def _ms(seconds: float) -> str:
    return "%.1f ms" % (seconds * 1e3)


def describe_station(st: StationFound, rate: int, echo: bool = False) -> List[str]:
    """Lines about one station, found at ``rate`` (``echo``: through an adapter that echoes)."""
    head = "station %d: %s" % (st.address, _STATION_WORDS[st.station_type])
    if st.late:
        head += ", answered late (after its reply window)"
    lines = [head]
    if st.diag is not None:
        owner = st.owner
        lines.append("  ident 0x%04X; %s" % (
            st.diag.ident, "not parameterised by any master" if owner is None
            else "parameterised by master %d (read only: the scan leaves it alone)" % owner))
        lines.append("  diagnosis: %s" % explain_diag(st.diag))
    if st.cfg is not None:
        try:
            n_in, n_out = cfg_io_lengths(st.cfg)
            sizes = " (%d bytes in, %d out)" % (n_in, n_out)
        except DpError:
            sizes = ""
        lines.append("  configuration (Get_Cfg): %s%s" % (_cli.hexstr(st.cfg), sizes))
    if st.gsd is not None:
        text = "  GSD: %s (%s, %s)" % (st.gsd.name, st.gsd.model, st.gsd.vendor)
        if st.gsd.modules is not None:
            text += "; modules: %s" % ", ".join(st.gsd.modules)
        elif st.cfg is not None:
            text += "; the configuration is not made of its modules"
        lines.append(text)
    elif st.passive and st.ident is not None:
        lines.append("  GSD: none of the files given has ident 0x%04X" % st.ident)
    if st.latencies:
        lines.append("  reply latency: median %s, max %s over %d replies (%s to the reply's first byte; an FDL "
                     "status request alone takes %s on the wire at this rate)" % (
                         _ms(statistics.median(st.latencies)), _ms(max(st.latencies)), len(st.latencies),
                         "the echo's end" if echo else "the write", _ms(6 * _CHAR_BITS / rate)))
    for problem in st.problems:
        lines.append("  problem: %s" % problem)
    return lines


def format_result(result: ScanResult) -> List[str]:
    """The scan in lines of text (the generic part; vr_driver adds what concerns the G2)."""
    lines: List[str] = []
    for r in result.rates:
        if not r.opened:
            lines.append("rate %d: the port refuses it: %s" % (r.rate, r.why_not))
            continue
        if r.other_masters:
            for address, what in sorted(r.other_masters.items()):
                lines.append("rate %d: another master (address %d) holds the token: it %s -- the scan "
                             "sent nothing more at this rate" % (r.rate, address, what))
            if r.heard:
                lines.append("rate %d: stations heard answering it: %s" % (r.rate, ", ".join(map(str, sorted(r.heard)))))
        elif r.silent:
            lines.append("rate %d: %d bytes on the line form no telegram at this rate (another master at "
                         "another rate?) -- the scan sent nothing at this rate" % (r.rate, r.foreign_bytes))
        else:
            stray = " (%d stray bytes heard before)" % r.foreign_bytes if r.foreign_bytes else ""
            lines.append("rate %d: %d addresses probed in %.1f s%s: %s" % (
                r.rate, r.probed, r.seconds, stray,
                "no station answers" if not r.stations else "%d station%s" % (len(r.stations), "s" * (len(r.stations) > 1))))
        for address in sorted(r.stations):
            lines += ["  " + line for line in describe_station(r.stations[address], r.rate, r.echoes * 2 > r.requests)]
        if r.garbage_bytes:
            lines.append("  %d received bytes formed no telegram" % r.garbage_bytes)
    echo = result.echo
    if echo:
        lines.append("the adapter echoes its transmission: each request came back verbatim before the reply "
                     "(%d of %d requests); the scan skipped the echo, and a master on this adapter must too"
                     % (sum(r.echoes for r in result.rates), sum(r.requests for r in result.rates)))
    elif echo is False:
        lines.append("the adapter does not echo its transmission")
    if result.rate is None:
        lines.append("no station answered at any rate tried: check the adapter, wiring, termination and "
                     "that the stations are powered")
    else:
        tried = [r.rate for r in result.rates]
        lines.append("bit rate: %d bit/s%s" % (result.rate, "" if result.found is result.rates[-1] or len(tried) == 1
                                                 else " (the rates after it were tried too)"))
    return lines


# ------------------------------------------------------------------------------------- the command

_DESCRIPTION = """\
A live list of the PROFIBUS line on DEVICE: tries the standard bit rates the port accepts (19.2
kbit/s first, then from the slowest up) and stops at the first at which a station answers
(--all-rates: tries every one); at each it first listens, and sends nothing when another master's
telegrams (or traffic at another rate) are heard. It sends FDL status to every address and, to
each passive station, Slave_Diag and Get_Cfg: ident number, owner, configuration; the GSD file of
the ident among those shipped (and --gsd); whether the adapter echoes its own transmission; the
reply latency per station. Read-only: no Set_Prm, no Chk_Cfg, no Data_Exchange."""

_EXIT = {
    _cli.EXIT_OK: "at least one station answered (or was heard answering another master)",
    _cli.EXIT_FAILED: "no station at any rate tried, or interrupted",
    _cli.EXIT_USAGE: "usage error (bad option, address or rate); nothing was sent",
    _cli.EXIT_DEVICE: "the device cannot be opened or failed while in use",
}


def _address_list(text: str) -> Tuple[int, ...]:
    out: List[int] = []
    for part in text.replace(" ", "").split(","):
        if not part:
            continue
        lo, _, hi = part.partition("..")
        try:
            first = _cli.address_arg(lo)
            last = _cli.address_arg(hi) if hi else first
        except argparse.ArgumentTypeError as exc:
            raise argparse.ArgumentTypeError("%s in %r" % (exc, text)) from None
        if last < first:
            raise argparse.ArgumentTypeError("range %s runs backwards" % part)
        out += range(first, last + 1)
    if not out:
        raise argparse.ArgumentTypeError("no address in %r" % text)
    return tuple(sorted(set(out)))


def _rate_list(text: str) -> Tuple[int, ...]:
    out: List[int] = []
    for part in text.replace(" ", "").split(","):
        if part:
            rate = _cli.baud_arg(part)
            if rate not in out:
                out.append(rate)
    if not out:
        raise argparse.ArgumentTypeError("no rate in %r" % text)
    return tuple(out)


def add_scan_arguments(p: argparse.ArgumentParser, device_default: Optional[str] = None) -> None:
    """The scan's options (shared with vr_driver's ``scan``); ``--device`` is required unless a
    default is given."""
    if device_default is None:
        p.add_argument("--device", required=True, help="the serial port (or a pyserial URL)")
    else:
        p.add_argument("--device", default=device_default,
                       help="the serial port (or a pyserial URL; default %s)" % device_default)
    p.add_argument("--rates", type=_rate_list, default=RATE_ORDER, metavar="R1,R2,...",
                   help="the bit rates to try, in order (default: 19200, then the other standard rates "
                        "from 9600 up)")
    p.add_argument("--all-rates", action="store_true", help="try every rate, not only up to the first with a station")
    p.add_argument("--addresses", type=_address_list, default=tuple(range(126)), metavar="A..B,C",
                   help="the addresses to probe (default 0..125), e.g. 0..15 or 3..9,20")
    p.add_argument("--master-addr", type=_cli.address_arg, default=DEFAULT_MASTER_ADDRESS, metavar="N",
                   help="the scan's own address, not probed (default %d)" % DEFAULT_MASTER_ADDRESS)
    p.add_argument("--reply-timeout", type=_cli.seconds_arg, default=None, metavar="S",
                   help="reply window per request (default %g s, %g s on a pty or a URL, or 4 slot times "
                        "if longer)" % (REPLY_FLOOR_SERIAL, REPLY_FLOOR_VIRTUAL))
    p.add_argument("--listen", type=_cli.nonneg_seconds_arg, default=DEFAULT_LISTEN, metavar="S",
                   help="seconds to listen at each rate before sending (default %g)" % DEFAULT_LISTEN)
    p.add_argument("--gsd", action="append", default=[], metavar="FILE",
                   help="a GSD file to match idents against, beside the shipped ones (repeatable)")
    p.add_argument("--json", action="store_true", help="print the result as one JSON object")
    p.add_argument("-v", "--verbose", action="count", default=0, help="progress on stderr (-vv: debug)")


def build_parser() -> argparse.ArgumentParser:
    p = _cli.make_parser("scan", _DESCRIPTION, _EXIT, [
        "python3 -m pyprofibus_vendor.scan --device /dev/ttyUSB0",
        "python3 -m pyprofibus_vendor.scan --device /dev/ttyUSB0 --rates 19200,93750 --addresses 0..15 --all-rates"])
    add_scan_arguments(p)
    return p


def serial_opener(device: str) -> Opener:
    """Opens ``device`` at a rate (8E1): a PhyError when the port refuses the rate."""
    from .phy_serial import SerialLink

    def open_at(rate: int) -> Link:
        return SerialLink(device, rate)
    return open_at


def scan_from_args(args: argparse.Namespace) -> ScanResult:
    """Check the options, then scan (the shared body of both ``scan`` commands)."""
    from .phy_serial import is_pty
    _cli.check_device_path(args.device)
    gsds = shipped_gsds()
    for path in args.gsd:
        try:
            gsds.insert(0, load_gsd(path))
        except GsdError as exc:
            raise _cli.UsageError(str(exc)) from None
    virtual = "://" in args.device or is_pty(args.device)
    fixed = args.reply_timeout

    def window(rate: int) -> float:
        return fixed if fixed is not None else default_reply_timeout(rate, virtual)
    addresses = [a for a in args.addresses if a != args.master_addr]
    if not addresses:
        raise _cli.UsageError("no address to probe besides the scan's own (%d)" % args.master_addr)
    progress = (lambda text: print(text, file=sys.stderr, flush=True)) if args.verbose else None
    scanner = Scanner(serial_opener(args.device), device=args.device, rates=args.rates, addresses=args.addresses,
                      master_address=args.master_addr, reply_timeout=window, listen=args.listen,
                      all_rates=args.all_rates, gsds=gsds, progress=progress)
    try:
        result = scanner.scan()
    except PhyError as exc:
        raise _cli.DeviceError(str(exc)) from None
    if all(not r.opened for r in result.rates):
        raise _cli.DeviceError("cannot open %s at any rate tried: %s" % (args.device, result.rates[0].why_not))
    return result


def _body(args: argparse.Namespace) -> int:
    _cli.setup_logging(args.verbose)
    _cli.line_buffered_stdout()
    result = scan_from_args(args)
    if args.json:
        print(json.dumps(result.to_dict(), sort_keys=True))
    else:
        for line in format_result(result):
            print(line)
    return _cli.EXIT_OK if result.rate is not None else _cli.EXIT_FAILED


def main(argv: Optional[Sequence[str]] = None) -> int:
    return _cli.run(build_parser(), _body, argv)


if __name__ == "__main__":
    sys.exit(main())


__all__ += ["add_scan_arguments", "describe_station"]
