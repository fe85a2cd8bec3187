#!/usr/bin/python3
"""The DP line benchmark: our master cycling 1, 2 and 4 stations on the virtual multi-drop line at
19.2 and 187.5 kbit/s (printed, never asserted).

    scripts/bench dp_line [-- --seconds 3 --stations 1 2 4 --bauds 19200 187500 | --quick]
    scripts/bench dp_line -- --stations 2 --bauds 19200 --rate 15 --latency-ms 1 16 32 --echo

The USB adapter (issue 44): ``--latency-ms MS...`` runs each configuration through the virtual line's
adapter model with that latency timer (replies handed to the master in bursts), ``--echo`` with the
adapter's echo, ``--turnaround-ms`` with its slow turnaround (vr_driver.controller.adapter_model);
``--rate HZ`` cycles at that asked rate as the bus process does (the next cycle at once when one ran
late) instead of back to back, and the table adds the ratio to it, the worst gap between two of the
controller's replies, the share of requests resent and the echoes recognised.

Stations: slave 4 the robot controller's image (14/14 bytes, Chk_Cfg 13 13 13 11 23 23 23 21),
slaves 8, 9, 10 virtual I/O islands (2/2 bytes, Chk_Cfg 11 21). They are plain DpSlaves served in one
helper process, each on its own pty; the line hub (vr_driver.controller.line) runs in a second process,
joins their ptys and PACES the line at the bit rate (each chunk takes 11 bits per character on the
wire, one direction at a time); our DpMaster runs here on the hub's pty, cycling every station in
turn, back to back, for ``--seconds`` after all stations reached Data_Exchange.

Per stations x baud it prints the measured cycles/s and milliseconds per cycle (bus time: every
station's request and reply through the paced line plus software latency), and the computed wire
time of one cycle: the characters of every Data_Exchange request and reply at 11 bits, plus per
station TSYN (33 bit) before the request and the slaves' maximum TSDR (60 bit) before the reply.
"""
from __future__ import annotations

import argparse
import logging
import os
import select
import subprocess
import sys
import threading
import time
from typing import Dict, List, Optional, Tuple

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
for _src in (os.path.join(REPO, "pyprofibus_vendor", "src"), os.path.join(REPO, "vr_driver", "src"),
             os.path.join(REPO, "panasonic_vr006l_support", "src")):
    if _src not in sys.path:
        sys.path.insert(0, _src)

from pyprofibus_vendor.dp_master import BusTiming, DpMaster, SlaveSpec  # noqa: E402
from pyprofibus_vendor.dp_slave import DpSlave, SlaveServer  # noqa: E402
from pyprofibus_vendor.phy_serial import SerialLink, open_pty_pair  # noqa: E402

MASTER = 2
ROBOT = (4, 0x06C6, bytes.fromhex("13 13 13 11 23 23 23 21"), 14)
ISLAND = (0x0F1A, bytes.fromhex("11 21"), 2)
ISLAND_ADDRESSES = (8, 9, 10)
MAX_TSDR = 60


def stations(n: int) -> List[Tuple[int, int, bytes, int]]:
    """(address, ident, cfg, bytes each way) of the first n stations."""
    return [ROBOT] + [(a, ISLAND[0], ISLAND[1], ISLAND[2]) for a in ISLAND_ADDRESSES[:n - 1]]


def wire_ms(n: int, baud: int) -> float:
    t = BusTiming.for_baud(baud)
    total = 0.0
    for _a, _i, _c, size in stations(n):
        chars = 2 * (size + 9)                      # SD2 request and reply with `size` data bytes
        total += t.chars(chars) + t.bits(t.tsyn_bits) + t.bits(MAX_TSDR)
    return total * 1e3


def serve(n: int) -> int:
    """Helper process: n slaves, each on its own pty; prints READY and the paths; stdin EOF stops."""
    logging.getLogger("pyprofibus_vendor").setLevel(logging.ERROR)
    stop = threading.Event()
    servers = []
    paths = []
    for address, ident, cfg, size in stations(n):
        pair = open_pty_pair()
        slave = DpSlave(address, ident, cfg)
        slave.on_outputs = (lambda s: lambda out: setattr(s, "inputs", bytes(x ^ 0xA5 for x in out)))(slave)
        server = SlaveServer(pair.master_link(), slave)
        threading.Thread(target=server.serve, args=(stop,), daemon=True).start()
        servers.append((server, pair))
        paths.append(pair.slave_path)
    print("READY", *paths, flush=True)
    sys.stdin.read()
    stop.set()
    return 0


class Proc:
    def __init__(self, args: List[str], what: str) -> None:
        self.proc = subprocess.Popen(args, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, bufsize=1)
        ready, _, _ = select.select([self.proc.stdout], [], [], 20.0)
        if not ready:
            self.close()
            raise RuntimeError("%s did not start in time" % what)
        self.words = self.proc.stdout.readline().split()

    def close(self) -> None:
        try:
            self.proc.stdin.close()
        except OSError:
            pass
        if self.proc.poll() is None:
            self.proc.terminate()
        try:
            self.proc.wait(5.0)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


def measure(n: int, baud: int, seconds: float, adapter: Optional[List[str]] = None,
            rate: float = 0.0) -> Dict[str, Optional[float]]:
    slaves = Proc([sys.executable, os.path.abspath(__file__), "--serve", str(n)], "the stations")
    env_path = os.pathsep.join(sys.path)
    hub = None
    master = None
    try:
        if slaves.words[:1] != ["READY"]:
            raise RuntimeError("stations: %r" % slaves.words)
        hub = Proc(["env", "PYTHONPATH=" + env_path, sys.executable, "-m", "vr_driver.controller.line", "--baud",
                    str(baud)] + (adapter or []) + slaves.words[1:], "the line hub")
        master = DpMaster(SerialLink(hub.words[0], baud), MASTER, baud)
        handles = [master.add_slave(SlaveSpec(a, i, c, watchdog=1.0)) for a, i, c, _s in stations(n)]
        end = time.monotonic() + 15.0
        while not all(h.connected for h in handles):
            if time.monotonic() > end:
                raise RuntimeError("not every station reached Data_Exchange in 15 s: %s"
                                   % [(h.address, h.state.value) for h in handles])
            master.cycle(timeout=1.0)
        exchanges = [h.counters.data_exchanges for h in handles]
        c = master.counters
        c0, r0, q0, e0 = c.cycles, c.retries, c.requests, c.echoes
        t0 = time.monotonic()
        robot, last, worst = handles[0], handles[0].inputs_time, 0.0
        period = 1.0 / rate if rate > 0 else 0.0
        due = t0
        while time.monotonic() - t0 < seconds:
            master.cycle(timeout=1.0)
            if robot.inputs_time != last:
                if last is not None:
                    worst = max(worst, robot.inputs_time - last)
                last = robot.inputs_time
            if period:                       # as the bus process: at the asked rate, at once when late
                due = max(due + period, time.monotonic())
                time.sleep(max(0.0, due - time.monotonic()))
        wall = time.monotonic() - t0
        cycles = c.cycles - c0
        missed = sum(1 for h, e in zip(handles, exchanges) if h.counters.data_exchanges - e < cycles * 0.9)
        return {"cycles": cycles, "cps": cycles / wall, "ms": wall / cycles * 1e3 if cycles else None,
                "wire_ms": wire_ms(n, baud), "short": missed,
                "lost": sum(h.counters.losses for h in handles), "worst_gap_ms": worst * 1e3,
                "resent": (c.retries - r0) / max(1, c.requests - q0), "echoes": c.echoes - e0}
    finally:
        if master is not None:
            master.close()
        for proc in (hub, slaves):
            if proc is not None:
                proc.close()


def main(argv: Optional[List[str]] = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seconds", type=float, default=3.0, help="timed cycling per configuration (3 s)")
    p.add_argument("--stations", type=int, nargs="+", default=[1, 2, 4], choices=(1, 2, 3, 4))
    p.add_argument("--bauds", type=int, nargs="+", default=[19200, 187500])
    p.add_argument("--quick", action="store_true", help="smoke run: 0.5 s per configuration")
    p.add_argument("--rate", type=float, default=0.0, help="cycle at this asked rate [1/s] (0: back to back)")
    p.add_argument("--latency-ms", type=float, nargs="+", default=[0.0], metavar="MS",
                   help="the adapter's latency timer of each run (the virtual line's adapter model)")
    p.add_argument("--echo", action="store_true", help="the adapter echoes the master's transmission")
    p.add_argument("--turnaround-ms", type=float, default=0.0, metavar="MS",
                   help="the adapter's receiver deaf this long after sending")
    p.add_argument("--serve", type=int, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.serve:
        return serve(args.serve)
    seconds = 0.5 if args.quick else args.seconds
    logging.basicConfig(level=logging.ERROR)
    adapter_runs = args.latency_ms != [0.0] or args.echo or args.turnaround_ms or args.rate
    print("our DpMaster on the virtual line (hub paced at the bit rate), %.1f s per configuration%s" % (
        seconds, ", asked %.1f cycles/s" % args.rate if args.rate else ", back to back"))
    if adapter_runs:
        print("%-9s %-8s %-8s %-5s %9s %7s %11s %13s %13s %7s %7s  %s" % (
            "stations", "baud", "latency", "echo", "cycles/s", "/asked", "ms/cycle", "wire ms/cycle",
            "worst gap ms", "resent", "echoes", "notes"))
    else:
        print("%-9s %-8s %9s %11s %13s  %s" % ("stations", "baud", "cycles/s", "ms/cycle", "wire ms/cycle", "notes"))
    status = 0
    for baud in args.bauds:
        for n in args.stations:
            for latency in args.latency_ms:
                extra = ["--latency-ms", str(latency), "--turnaround-ms", str(args.turnaround_ms)] + \
                    (["--echo"] if args.echo else [])
                try:
                    r = measure(n, baud, seconds, extra, args.rate)
                except (RuntimeError, OSError) as exc:
                    print("%-9d %-8d FAILED: %s" % (n, baud, exc))
                    status = 1
                    continue
                notes = "every station every cycle" if not r["short"] and not r["lost"] else \
                    "%d station(s) short of exchanges, %d loss(es)" % (r["short"], r["lost"])
                if adapter_runs:
                    print("%-9d %-8d %-8s %-5s %9.1f %7s %11.2f %13.2f %13.1f %6.0f%% %7d  %s" % (
                        n, baud, "%g ms" % latency, "yes" if args.echo else "no", r["cps"],
                        "%.2f" % (r["cps"] / args.rate) if args.rate else "-", r["ms"], r["wire_ms"],
                        r["worst_gap_ms"], 100 * r["resent"], r["echoes"], notes))
                else:
                    print("%-9d %-8d %9.1f %11.2f %13.2f  %s" % (n, baud, r["cps"], r["ms"], r["wire_ms"], notes))
    return status


if __name__ == "__main__":
    sys.exit(main())
