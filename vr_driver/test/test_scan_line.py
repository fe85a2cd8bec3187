"""`rosrun vr_driver scan` (its executable, a process of its own) on the virtual line over REAL ptys: the
line runs at a rate the test draws and carries the virtual G2 (a protocol the test draws) and the
virtual I/O island at addresses the test draws. The scan must find the rate (the line garbles the
others, as a wire would), both stations, the G2's protocol, the island's GSD file and print the next
command lines; through a relay that echoes what the scan sends, the echo must be named.

The draw is printed in every assertion message (the seed: SCAN_SEED=N to run one again)."""
from __future__ import annotations

import os
import random
import subprocess
import sys
import time
from typing import List, Optional

from pyprofibus_vendor.phy_serial import SerialLink, open_pty_pair

from vr_driver.controller.io_island import VirtualIoIsland
from vr_driver.controller.adapter_model import AdapterBehaviour
from vr_driver.controller.line import LineHub
from vr_driver.controller.line_rate import tty_speed
from vr_driver.controller.virtual_controller import VirtualController
from vr_driver.commission.scan import protocol_cfg

TEST = os.path.dirname(os.path.abspath(__file__))
PKG = os.path.dirname(TEST)
REPO = os.path.dirname(PKG)
SCAN = os.path.join(PKG, "nodes", "scan")
PYTHONPATH = os.pathsep.join([os.path.join(PKG, "src"), os.path.join(REPO, "pyprofibus_vendor", "src"),
                              os.path.join(REPO, "panasonic_vr006l_support", "src")])
RATES = (19200, 45450, 93750, 187500, 500000)
#: the driver's own station address (and the virtual G2's master's): a G2 there is test_scan_findings.py's
DRIVER_MASTER = 2
SEED = int(os.environ.get("SCAN_SEED") or random.SystemRandom().randrange(1 << 30))


class Line:
    """The virtual G2 and island on the line hub, at ``rate``."""

    def __init__(self, tmp, rate: int, g2: int, island: int, protocol: str,
                 adapter: Optional[AdapterBehaviour] = None) -> None:
        self.controller = VirtualController(pty_link=str(tmp / "g2"), address=g2, baud=rate, protocol=protocol).start()
        self.island = VirtualIoIsland(pty_link=str(tmp / "island"), address=island, baud=rate).start()
        self.hub = LineHub([str(tmp / "g2"), str(tmp / "island")], pty_link=str(tmp / "line"), rate=rate,
                           reopen_period=0.05, adapter=adapter).start()
        self.path = str(tmp / "line")
        deadline = time.monotonic() + 10.0
        while len(self.hub.connected()) < 2:                  # the hub opens both at its first step
            assert time.monotonic() < deadline, "the hub did not join both stations"
            time.sleep(0.01)

    def close(self) -> None:
        self.hub.stop()
        self.island.stop()
        self.controller.stop()
        assert self.hub.error is None


def run_scan(device: str, *args: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=PYTHONPATH)
    return subprocess.run([sys.executable, SCAN, "--device", device, "--listen", "0.1", "--reply-timeout", "0.05",
                           *args], env=env, capture_output=True, text=True, timeout=120)


def lines_of(out: str, start: str) -> List[str]:
    """The lines of the block that starts with a line containing ``start`` (its indented lines)."""
    lines = out.splitlines()
    i = next(i for i, line in enumerate(lines) if start in line)
    block = [lines[i]]
    for line in lines[i + 1:]:
        if not line.startswith("    "):
            break
        block.append(line)
    return block


def test_tty_speed_reads_the_rate_pyserial_set_on_a_pty():
    pty = open_pty_pair()
    try:
        for rate in (9600, 19200, 45450, 93750, 187500, 500000, 1500000, 12000000):
            link = SerialLink(pty.slave_path, rate)
            assert (tty_speed(pty.keep_fd), tty_speed(pty.master_fd)) == (rate, rate)
            link.close()
    finally:
        pty.close()


def test_scan_finds_the_drawn_rate_stations_protocol_gsd_and_prints_the_next_commands(tmp_path):
    rng = random.Random(SEED)
    rate = rng.choice(RATES[1:])                              # never the first tried: the search must move on
    g2 = rng.choice([a for a in range(1, 16) if a != DRIVER_MASTER])
    island = rng.choice([a for a in range(1, 16) if a != g2])
    protocol = rng.choice(("v1", "v2", "v3"))
    drawn = "SCAN_SEED=%d: rate %d, G2 at %d (%s), island at %d" % (SEED, rate, g2, protocol, island)
    line = Line(tmp_path, rate, g2, island, protocol)
    try:
        run = run_scan(line.path, "--rates", ",".join(map(str, RATES)), "--addresses", "0..15")
        off_rate = line.hub.counters.off_rate_chunks
    finally:
        line.close()
    out = run.stdout
    info = "%s\nstdout:\n%s\nstderr:\n%s" % (drawn, out, run.stderr)
    assert run.returncode == 0, info
    for wrong in RATES[:RATES.index(rate)]:                   # tried first, no answer: the line garbled them
        assert "rate %d: 15 addresses probed" % wrong in out and "no station answers" in out, info
    assert off_rate > 0, info
    assert "rate %d: 15 addresses probed" % rate in out and "bit rate: %d bit/s" % rate in out, info
    later = RATES[RATES.index(rate) + 1:]
    assert not any(line.startswith("rate %d:" % r) for r in later for line in out.splitlines()), info  # stopped
    g2_block = "\n".join(lines_of(out, "station %d: passive" % g2))
    assert "ident 0x06C6" in g2_block and "GSD: PAN06C6.gsd" in g2_block, info
    assert "configuration (Get_Cfg): %s" % " ".join("%02X" % b for b in protocol_cfg(protocol)) in g2_block, info
    island_block = "\n".join(lines_of(out, "station %d: passive" % island))
    assert "ident 0x0F1A" in island_block and "GSD: VRIO0F1A.gsd" in island_block, info
    assert "modules: 16 DI, 16 DO" in island_block, info
    assert "the G2 card: station %d (ident 0x06C6, PAN06C6.gsd): its modules fit protocol %s" % (g2, protocol) in out, info
    assert "station %d (VRIO0F1A.gsd): not the G2" % island in out, info
    assert "the adapter does not echo its transmission" in out, info
    where = "port:=%s baud:=%d slave_address:=%d" % (line.path, rate, g2)
    if protocol == "v3":
        assert ("next:\n  rosrun vr_driver commission --port %s --baud %d --slave-address %d\n"
                "  roslaunch vr_driver driver.launch sim:=false %s commissioning:=commissioning.yaml"
                % (line.path, rate, g2, where)) in out, info
    else:
        assert "next:\n  roslaunch vr_driver driver.launch sim:=false %s protocol:=%s" % (where, protocol) in out, info
        assert "commission measures protocol v3 only" in out, info


def test_scan_through_an_echoing_adapter_names_the_echo(tmp_path):
    rng = random.Random(SEED + 1)
    g2 = rng.choice([a for a in range(1, 8) if a != DRIVER_MASTER])
    island = rng.choice([a for a in range(1, 8) if a != g2])
    drawn = "SCAN_SEED=%d: rate 45450, G2 at %d (v3), island at %d" % (SEED, g2, island)
    # the line's USB adapter model echoes what the master writes (at the master's rate, whatever the line's)
    line = Line(tmp_path, 45450, g2, island, "v3", adapter=AdapterBehaviour(echo=True))
    try:
        run = run_scan(line.path, "--rates", "19200,45450", "--addresses", "0..7")
    finally:
        line.close()
    out = run.stdout
    info = "%s\nstdout:\n%s\nstderr:\n%s" % (drawn, out, run.stderr)
    assert run.returncode == 0 and line.hub.adapter.counters.echoed > 0, info
    assert "the adapter echoes its transmission: each request came back verbatim before the reply" in out, info
    assert "bit rate: 45450 bit/s" in out and "station %d: passive" % island in out, info
    assert "the G2 card: station %d (ident 0x06C6, PAN06C6.gsd): its modules fit protocol v3" % g2 in out, info
    assert "rosrun vr_driver commission --port %s --baud 45450 --slave-address %d" % (line.path, g2) in out, info


def test_scan_without_a_g2_says_so_and_fails(tmp_path):
    island = VirtualIoIsland(pty_link=str(tmp_path / "island"), address=3).start()
    hub = LineHub([str(tmp_path / "island")], pty_link=str(tmp_path / "line"), rate=19200).start()
    try:
        deadline = time.monotonic() + 10.0
        while not hub.connected():
            assert time.monotonic() < deadline, "the hub did not join the island"
            time.sleep(0.01)
        run = run_scan(str(tmp_path / "line"), "--rates", "19200", "--addresses", "1..4")
    finally:
        hub.stop()
        island.stop()
    assert run.returncode == 1, run.stdout + run.stderr
    assert "no station has the G2 card's ident 0x06C6" in run.stdout and "next:" not in run.stdout
