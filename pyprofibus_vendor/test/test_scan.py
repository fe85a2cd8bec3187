"""The live list (pyprofibus_vendor.scan) on an in-memory line with a fake clock: slave engines that
answer only at the line's own rate, an adapter that echoes, another master's token, a late reply,
GSD matching and the command's options. The real-pty runs are vr_driver/test/test_scan_line.py."""
from __future__ import annotations

import json
from typing import List, Optional, Sequence

import pytest

from pyprofibus_vendor import scan
from pyprofibus_vendor.dp import PrmStationStatus, Sap, SetPrm, request_frame
from pyprofibus_vendor.dp_slave import DpSlave
from pyprofibus_vendor.errors import PhyError
from pyprofibus_vendor.fdl import Frame, RespondingLink, Sd4, StationType
from pyprofibus_vendor.gsd import parse_gsd

from _helpers import ROBOT_CFG, ROBOT_IDENT, FakeClock

ISLAND_IDENT = 0x0F1A
ISLAND_CFG = bytes.fromhex("11 21")


class Line(RespondingLink):
    """One opening of the port at ``rate`` onto a line whose stations run at ``line_rate``; a
    request at another rate is garbage to them (no reply). ``echo``: the adapter hands back what it
    sends; ``preload``: bytes already on the line (another master); ``delay``: replies come that
    many seconds of the fake clock late."""

    def __init__(self, slaves: Sequence[DpSlave], line_rate: int, rate: int, clock: FakeClock, *,
                 echo: bool = False, preload: bytes = b"", delay: float = 0.0) -> None:
        super().__init__("test line")
        self.slaves = list(slaves)
        self.line_rate = line_rate
        self.rate = rate
        self.clock = clock
        self.echo = echo
        self.delay = delay
        self.sent: List[Frame] = []
        self._later: List[tuple] = []
        self._rx += preload

    def send(self, data: bytes) -> None:
        if self.echo:
            self._rx += data
        super().send(data)

    def respond(self, frame: Frame) -> Optional[bytes]:
        self.sent.append(frame)
        if self.rate != self.line_rate:
            return None
        for slave in self.slaves:
            reply = slave.handle(frame, self.clock())
            if reply is not None:
                if self.delay:
                    self._later.append((self.clock() + self.delay, reply.encode()))
                    return None
                return reply.encode()
        return None

    def recv(self, max_bytes: int = 4096, timeout: Optional[float] = 0.0) -> bytes:
        if not self._rx and self._later:             # wait until the next delayed reply, if it comes in time
            wait = min(d[0] for d in self._later) - self.clock()
            if 0 < wait <= (timeout or 0.0):
                self.clock.advance(wait)
        due = [d for d in self._later if d[0] <= self.clock()]
        for d in due:
            self._later.remove(d)
            self._rx += d[1]
        if not self._rx:
            self.clock.advance(timeout or 0.0)
            return b""
        self.clock.advance(0.0005)
        return super().recv(max_bytes, 0.0)


class Bus:
    """The port: opens a :class:`Line` per rate; ``refuse`` rates raise PhyError as a port would."""

    def __init__(self, slaves: Sequence[DpSlave], line_rate: int, refuse: Sequence[int] = (), **kw) -> None:
        self.clock = FakeClock()
        self.slaves = slaves
        self.line_rate = line_rate
        self.refuse = refuse
        self.kw = kw
        self.opened: List[Line] = []

    def open(self, rate: int) -> Line:
        if rate in self.refuse:
            raise PhyError("the adapter does not do %d baud" % rate)
        line = Line(self.slaves, self.line_rate, rate, self.clock, **self.kw)
        self.opened.append(line)
        return line


def stations(clock: FakeClock) -> List[DpSlave]:
    return [DpSlave(6, ROBOT_IDENT, ROBOT_CFG, clock=clock), DpSlave(9, ISLAND_IDENT, ISLAND_CFG, clock=clock)]


def scanner(bus: Bus, **kw) -> scan.Scanner:
    kw.setdefault("addresses", range(16))
    kw.setdefault("gsds", scan.shipped_gsds())
    kw.setdefault("listen", 0.05)
    return scan.Scanner(bus.open, clock=bus.clock, reply_timeout=lambda rate: 0.02, **kw)


def make_bus(line_rate: int = 93750, **kw) -> Bus:
    bus = Bus([], line_rate, **kw)
    bus.slaves = stations(bus.clock)
    return bus


def test_the_rate_and_both_stations_are_found_and_matched_to_their_gsd_files():
    bus = make_bus(93750)
    result = scanner(bus, rates=(19200, 45450, 93750, 187500)).scan()
    assert [r.rate for r in result.rates] == [19200, 45450, 93750]          # stops at the first rate found
    assert result.rate == 93750
    assert [r.probed for r in result.rates] == [15, 15, 15]                  # 0..15 but its own address 0
    g2, island = result.stations
    assert (g2.address, island.address) == (6, 9)
    assert g2.station_type == StationType.SLAVE and g2.ident == ROBOT_IDENT and g2.owner is None
    assert g2.cfg == ROBOT_CFG and island.cfg == ISLAND_CFG
    assert g2.gsd.name == "PAN06C6.gsd" and island.gsd.name == "VRIO0F1A.gsd"
    assert island.gsd.modules == ("16 DI", "16 DO")
    assert g2.gsd.modules == ("4 Bytes In",) * 3 + ("2 Bytes In",) + ("4 Bytes Out",) * 3 + ("2 Bytes Out",)
    assert len(g2.latencies) == 3 and not g2.problems and not g2.late
    assert result.echo is False
    # read only: FDL status, Slave_Diag (SAP 60) and Get_Cfg (SAP 59), nothing else
    saps = {getattr(f, "dsap", None) for line in bus.opened for f in line.sent}
    assert saps == {None, 59, 60}
    assert all(s.state.name == "WAIT_PRM" for s in bus.slaves)
    text = "\n".join(scan.format_result(result))
    assert "bit rate: 93750 bit/s" in text and "GSD: VRIO0F1A.gsd" in text and "modules: 16 DI, 16 DO" in text
    assert "rate 19200: 15 addresses probed" in text and "no station answers" in text


def test_all_rates_goes_on_and_a_refused_rate_is_named():
    bus = make_bus(19200, refuse=(45450,))
    result = scanner(bus, rates=(19200, 45450, 93750), all_rates=True).scan()
    assert [(r.rate, r.opened, len(r.stations)) for r in result.rates] == [(19200, True, 2), (45450, False, 0),
                                                                           (93750, True, 0)]
    assert result.rate == 19200
    text = "\n".join(scan.format_result(result))
    assert "rate 45450: the port refuses it: the adapter does not do 45450 baud" in text


def test_an_echoing_adapter_is_named_and_its_echo_skipped():
    bus = make_bus(19200, echo=True)
    result = scanner(bus, rates=(19200,)).scan()
    assert [s.address for s in result.stations] == [6, 9]
    assert result.stations[0].cfg == ROBOT_CFG
    assert result.echo is True and result.rates[0].echoes == result.rates[0].requests == 15 + 2 * 2
    assert "the adapter echoes its transmission" in "\n".join(scan.format_result(result))


def test_another_masters_token_keeps_the_scan_silent():
    token = Sd4(5, 2).encode() * 3
    bus = make_bus(19200, preload=token)
    result = scanner(bus, rates=(19200, 93750)).scan()
    r = result.rates[0]
    assert r.other_masters == {2: "passes the token to station 5"} and r.silent
    assert r.requests == 0 and bus.opened[0].sent == []                   # nothing sent at 19200
    assert result.other_masters == {2: "passes the token to station 5"}
    assert "another master (address 2) holds the token" in "\n".join(scan.format_result(result))


def test_foreign_bytes_at_a_rate_keep_it_silent():
    bus = make_bus(19200, preload=b"\x00\xff\x13\x37")
    result = scanner(bus, rates=(19200,)).scan()
    assert result.rates[0].foreign_bytes == 4 and result.rates[0].requests == 0
    assert "form no telegram at this rate" in "\n".join(scan.format_result(result))


def test_a_stray_byte_or_two_do_not_keep_the_scan_silent():
    bus = make_bus(19200, preload=b"\x00\xff")
    result = scanner(bus, rates=(19200,)).scan()
    assert result.rates[0].foreign_bytes == 2 and [s.address for s in result.stations] == [6, 9]
    assert "(2 stray bytes heard before)" in "\n".join(scan.format_result(result))


def test_a_late_reply_still_names_its_station():
    bus = make_bus(19200, delay=0.03)          # every reply after its 0.02 s window
    result = scanner(bus, rates=(19200,)).scan()
    assert [s.address for s in result.stations] == [6, 9]
    assert all(s.late for s in result.stations)
    # Slave_Diag and Get_Cfg are asked twice (same FCB): the first reply, late, answers the second try
    assert result.stations[0].cfg == ROBOT_CFG and result.stations[1].gsd.name == "VRIO0F1A.gsd"


def test_a_station_locked_by_another_master_is_named_as_such_and_left_alone():
    bus = make_bus(19200)
    g2 = bus.slaves[0]
    prm = SetPrm(ROBOT_IDENT, station_status=PrmStationStatus.LOCK_REQ).encode()   # no watchdog
    assert g2.handle(request_frame(6, 3, True, False, Sap.SET_PRM, prm), bus.clock()) is not None
    assert g2.state.name == "WAIT_CFG"
    result = scanner(bus, rates=(19200,)).scan()
    assert result.stations[0].owner == 3 and g2.state.name == "WAIT_CFG"     # still master 3's
    assert "parameterised by master 3 (read only" in "\n".join(scan.format_result(result))


def test_gsd_matching_by_ident_and_modules():
    gsd = parse_gsd('#Profibus_DP\nIdent_Number = 0x1234\nModel_Name = "m"\nModule = "A" 0x10\nEndModule\n'
                    'Module = "AB" 0x10 0x20\nEndModule\nModule = "B" 0x20\nEndModule\n')
    assert scan.match_gsd([gsd], 0x1234, bytes.fromhex("10 20 20")).modules == ("AB", "B")
    assert scan.match_gsd([gsd], 0x1234, bytes.fromhex("30")).modules is None
    assert scan.match_gsd([gsd], 0x4321, b"\x10") is None


def test_the_command_checks_its_options_before_opening_anything(capsys):
    assert scan.main(["--device", "/dev/null/nothing"]) == 3
    assert scan.main(["--device", "/dev/null", "--addresses", "9..3"]) == 2
    assert scan.main(["--device", "/dev/null", "--rates", "100"]) == 2
    assert scan.main(["--device", "/dev/null", "--addresses", "0", "--master-addr", "0"]) == 2
    err = capsys.readouterr().err
    assert "runs backwards" in err and "outside 9600..12000000" in err and "besides the scan's own" in err


def test_json_result_is_complete():
    bus = make_bus(19200)
    result = scanner(bus, rates=(19200,)).scan()
    data = json.loads(json.dumps(result.to_dict()))
    assert data["rate"] == 19200 and data["echo"] is False
    st = data["rates"][0]["stations"]
    assert [s["address"] for s in st] == [6, 9] and st[1]["gsd"]["file"] == "VRIO0F1A.gsd"
    assert st[0]["ident"] == "0x06C6" and st[0]["input_len"] == 14


def test_bad_scanner_settings_are_refused():
    with pytest.raises(ValueError):
        scan.Scanner(lambda r: None, addresses=[130])
    with pytest.raises(ValueError):
        scan.Scanner(lambda r: None, rates=())
