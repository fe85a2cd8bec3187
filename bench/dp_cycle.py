#!/usr/bin/python3
"""The DP cycle benchmark: one 14/14-byte Data_Exchange per cycle over a pty pair (printed, never asserted).

    scripts/bench dp_cycle [-- --cycles 2000 --repeats 5 --hz-seconds 3 --baud 19200 | --quick]

Servers run in their own processes, each on its own fresh pty pair (the server holds the pty's
master fd and prints the slave path; clients open that path), so the master's CPU is measured in
the master's process only (time.process_time around the timed loop; servers report their own
process_time on request). Variants, alternated within each repeat, medians over the repeats:

  floor       the link's floor: a client writes the Data_Exchange request's bytes (SD2, 23 B) and
              reads the reply's byte count (23 B) from a server that just counts bytes and answers
              with a fixed reply -- no protocol logic on either side, blocking os.read/os.write.
  slave-only  the same bare client against OUR slave (DpSlave in a SlaveServer): pre-encoded
              requests with toggling FCB, no master logic (link + our slave; informational).
  ours        our master: DpMaster.cycle() on a SerialLink to OUR slave, outputs set and inputs
              checked every cycle (timed after wait_connected).
  pyprofibus  pyprofibus 1.13's DPM1 in $VR_PEER_PYTHON (pyprofibus_vendor/test/peers/
              pyprofibus_master.py) to OUR slave; the peer times its own exchange phase and CPU.

Then our master at a fixed 100 Hz (DpMaster.run(period=0.01)) for a few seconds -> % of one core,
and the software time per cycle beside the wire time of a 14/14 Data_Exchange (11 bits per
character, TSYN 33 bit before the request, TSDR between min and max) at 19.2 k, 187.5 k, 1.5 M.
A pty has no baud timing: the link floor bounds throughput, and --baud only sets the port.
Targets are printed as PASS/MISS lines. Exit status 1 only if a variant fails (error, mismatch).
"""
from __future__ import annotations

import argparse
import json
import logging
import os
import select
import statistics
import subprocess
import sys
import threading
import time
import tty
from typing import Dict, List, Optional

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
_SRC = os.path.join(REPO, "pyprofibus_vendor", "src")
if _SRC not in sys.path:
    sys.path.insert(0, _SRC)

from pyprofibus_vendor.dp import request_frame  # noqa: E402
from pyprofibus_vendor.dp_master import BusTiming, DpMaster, SlaveSpec  # noqa: E402
from pyprofibus_vendor.dp_slave import DpSlave, SlaveServer  # noqa: E402
from pyprofibus_vendor.fdl import FrameControl, ResponseStatus, Sd2  # noqa: E402
from pyprofibus_vendor.phy_serial import SerialLink, open_pty_pair  # noqa: E402

PEER = os.path.join(REPO, "pyprofibus_vendor", "test", "peers", "pyprofibus_master.py")
GSD = os.path.join(REPO, "pyprofibus_vendor", "gsd", "PAN06C6.gsd")
IDENT = 0x06C6
CFG = bytes.fromhex("13 13 13 11 23 23 23 21")   # 4 In x3, 2 In, 4 Out x3, 2 Out: 14/14 bytes
SIZE = 14
MASTER, SLAVE = 2, 4
XOR = 0xA5                                        # the slave application: inputs = outputs ^ 0xA5
WIRE_BAUDS = ((19200, "19.2k"), (187500, "187.5k"), (1500000, "1.5M"))


def dx_request(fcb: bool, fcv: bool = True, data: bytes = bytes(SIZE)) -> bytes:
    return request_frame(SLAVE, MASTER, fcb, fcv, None, data).encode()


def dx_reply(data: bytes = bytes(SIZE)) -> bytes:
    return Sd2(MASTER, SLAVE, FrameControl.resp(ResponseStatus.DL), data).encode()


def images(n: int, seed: int) -> List[bytes]:
    return [bytes(((i * 7 + k + seed) * 131) & 0xFF for k in range(SIZE)) for i in range(n)]


# -- servers (run as `dp_cycle.py --serve KIND` in their own process) ---------------------------

def _control(stop: threading.Event) -> None:
    """stdin: a line asks for this process's CPU time; EOF stops the server."""
    for line in sys.stdin:
        if line.strip() == "cpu":
            print("CPU %.9f" % time.process_time(), flush=True)
    stop.set()


def serve_slave() -> int:
    # between variants the masters go quiet and the slave's watchdog expires: expected here
    logging.getLogger("pyprofibus_vendor").setLevel(logging.ERROR)
    pair = open_pty_pair()
    slave = DpSlave(SLAVE, IDENT, CFG)

    def app(outputs: bytes) -> None:
        slave.inputs = bytes(b ^ XOR for b in outputs)
    slave.on_outputs = app
    server = SlaveServer(pair.master_link(), slave)
    stop = threading.Event()
    threading.Thread(target=_control, args=(stop,), daemon=True).start()
    print("READY", pair.slave_path, flush=True)
    try:
        server.serve(stop)
    finally:
        server.link.close()
        pair.close()
    return 0


def serve_echo(req_len: int, reply: bytes) -> int:
    pair = open_pty_pair()
    fd = pair.master_fd
    os.set_blocking(fd, True)
    stdin = sys.stdin.fileno()
    print("READY", pair.slave_path, flush=True)
    pending = 0
    ctrl = b""
    while True:
        ready, _, _ = select.select([fd, stdin], [], [])
        if fd in ready:
            try:
                pending += len(os.read(fd, 4096))
            except OSError:                 # EIO: no client has the pty open right now
                pass
            while pending >= req_len:
                pending -= req_len
                os.write(fd, reply)
        if stdin in ready:
            chunk = os.read(stdin, 256)
            if not chunk:
                break
            ctrl += chunk
            while b"\n" in ctrl:
                line, ctrl = ctrl.split(b"\n", 1)
                if line.strip() == b"cpu":
                    os.write(sys.stdout.fileno(), b"CPU %.9f\n" % time.process_time())
    pair.close()
    return 0


class Server:
    """A server process; :meth:`cpu` asks it for its process CPU time."""

    def __init__(self, *args: str) -> None:
        self.proc = subprocess.Popen([sys.executable, os.path.abspath(__file__), "--serve", *args],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                                     bufsize=1)
        line = self._line(10.0)
        if not line.startswith("READY "):
            raise RuntimeError(f"server {args}: expected READY, got {line!r}")
        self.path = line.split()[1]

    def _line(self, timeout: float) -> str:
        ready, _, _ = select.select([self.proc.stdout], [], [], timeout)
        if not ready:
            raise RuntimeError("server did not answer in time")
        return self.proc.stdout.readline().strip()

    def cpu(self) -> float:
        self.proc.stdin.write("cpu\n")
        self.proc.stdin.flush()
        line = self._line(5.0)
        if not line.startswith("CPU "):
            raise RuntimeError(f"server: expected CPU, got {line!r}")
        return float(line.split()[1])

    def close(self) -> None:
        try:
            self.proc.stdin.close()
            self.proc.wait(5.0)
        except (OSError, subprocess.TimeoutExpired):
            self.proc.kill()
            self.proc.wait()


# -- clients ------------------------------------------------------------------------------------

def bare_client(path: str, requests: List[bytes], reply_len: int, n: int) -> Dict:
    """n request/reply round trips with no protocol logic; returns wall and CPU."""
    fd = os.open(path, os.O_RDWR | os.O_NOCTTY)
    try:
        tty.setraw(fd)   # VMIN=1: a blocking read waits (pyserial leaves the pty at VMIN=0)
        k = len(requests)
        write, read = os.write, os.read
        w0, c0 = time.perf_counter(), time.process_time()
        for i in range(n):
            write(fd, requests[i % k])
            got = 0
            while got < reply_len:
                got += len(read(fd, 4096))
        wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    finally:
        os.close(fd)
    return {"cycles": n, "wall": wall, "cpu": cpu, "mismatches": 0}


def connect_master(path: str, baud: int) -> DpMaster:
    m = DpMaster(SerialLink(path, baud), MASTER, baud)
    m.add_slave(SlaveSpec(SLAVE, IDENT, CFG, watchdog=1.0))
    if not m.wait_connected(SLAVE, 10.0):
        m.close()
        raise RuntimeError("our master did not reach Data_Exchange with our slave in 10 s")
    return m


def run_ours(path: str, baud: int, n: int, seed: int) -> Dict:
    outs = images(n, seed)
    wants = [bytes(b ^ XOR for b in o) for o in outs]
    m = connect_master(path, baud)
    try:
        h = m.slave(SLAVE)
        cycle = m.cycle
        mismatches = 0
        w0, c0 = time.perf_counter(), time.process_time()
        for i in range(n):
            h.outputs = outs[i]
            if not cycle(5.0):
                raise RuntimeError(f"our master: cycle {i} did not complete in 5 s")
            if h.inputs != wants[i]:
                mismatches += 1
        wall, cpu = time.perf_counter() - w0, time.process_time() - c0
        lost = h.counters.losses
    finally:
        m.close()
    return {"cycles": n, "wall": wall, "cpu": cpu, "mismatches": mismatches + lost}


def run_slave_only(path: str, baud: int, n: int) -> Dict:
    """Bare client against our slave: connect with our master, then continue its FCB sequence."""
    m = connect_master(path, baud)
    fcb, _ = m.slave(SLAVE).fcb.bits()
    m.close()
    requests = [dx_request(fcb), dx_request(not fcb)]
    return bare_client(path, requests, len(dx_reply()), n)


def run_pyprofibus(peer_python: str, path: str, baud: int, n: int, seed: int) -> Dict:
    cmd = [peer_python, PEER, "--port", path, "--gsd", GSD, "--baud", str(baud),
           "--slave", str(SLAVE), "--master", str(MASTER), "--xor", hex(XOR),
           "--cycles", str(n), "--seed", str(seed), "--watchdog-ms", "1000",
           "--timeout", str(max(30.0, n / 200.0))]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=max(60.0, n / 100.0))
    summary = None
    for line in res.stdout.splitlines():
        if line.startswith("PEER SUMMARY "):
            summary = json.loads(line[len("PEER SUMMARY "):])
    if summary is None or not summary.get("ok"):
        tail = "\n".join((res.stdout + res.stderr).splitlines()[-15:])
        raise RuntimeError(f"pyprofibus peer failed (exit {res.returncode}):\n{tail}")
    return {"cycles": summary["cycles"], "wall": summary["wall_s"], "cpu": summary["cpu_s"],
            "mismatches": summary["mismatches"], "rs_errors": summary["rs_errors"]}


# -- report ---------------------------------------------------------------------------------------

def wire_time(baud: int, req_chars: int, reply_chars: int) -> Dict:
    t = BusTiming.for_baud(baud)
    base = t.tsyn_bits + 11 * (req_chars + reply_chars)
    return {"min": t.bits(base + t.min_tsdr_bits), "max": t.bits(base + t.max_tsdr_bits),
            "tsdr": (t.min_tsdr_bits, t.max_tsdr_bits), "tsyn": t.tsyn_bits}


def hz_floor(path: str, reply_len: int, request: bytes, seconds: float) -> Dict:
    """The environment's floor at 100 Hz: a bare round trip, then time.sleep to the next period."""
    fd = os.open(path, os.O_RDWR | os.O_NOCTTY)
    try:
        tty.setraw(fd)
        n = 0
        w0, c0 = time.monotonic(), time.process_time()
        next_start = w0
        end = w0 + seconds
        while next_start < end:
            os.write(fd, request)
            got = 0
            while got < reply_len:
                got += len(os.read(fd, 4096))
            n += 1
            next_start += 0.01
            left = next_start - time.monotonic()
            if left > 0:
                time.sleep(left)
        wall, cpu = time.monotonic() - w0, time.process_time() - c0
    finally:
        os.close(fd)
    return {"cycles": n, "wall": wall, "cpu": cpu}


def hz_run(path: str, baud: int, seconds: float, slave: Server) -> Dict:
    m = connect_master(path, baud)
    h = m.slave(SLAVE)
    outs = images(256, 99)
    starts: List[float] = []
    stop = threading.Event()
    end = time.monotonic() + seconds

    def on_cycle(master: DpMaster) -> None:
        now = time.monotonic()
        starts.append(now)
        h.outputs = outs[len(starts) & 0xFF]
        if now >= end:
            stop.set()
    try:
        s0 = slave.cpu()
        w0, c0 = time.monotonic(), time.process_time()
        m.run(0.01, stop, on_cycle)
        wall, cpu = time.monotonic() - w0, time.process_time() - c0
        s1 = slave.cpu()
        overruns, losses = m.counters.overruns, h.counters.losses
    finally:
        m.close()
    periods = [b - a for a, b in zip(starts, starts[1:])]
    dev = sorted(abs(p - 0.01) for p in periods) or [0.0]
    return {"cycles": len(starts), "wall": wall, "cpu": cpu, "slave_cpu": s1 - s0,
            "overruns": overruns, "losses": losses,
            "jitter_p99": dev[min(len(dev) - 1, int(0.99 * len(dev)))], "jitter_max": dev[-1]}


def main(argv: Optional[List[str]] = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--cycles", type=int, default=2000, help="cycles per variant and repeat (2000)")
    p.add_argument("--repeats", type=int, default=5, help="repeats; medians are printed (5)")
    p.add_argument("--hz-seconds", type=float, default=3.0, help="length of the 100 Hz run (3 s)")
    p.add_argument("--baud", type=int, default=19200, help="baud set on the pty (no effect on timing)")
    p.add_argument("--quick", action="store_true", help="smoke run: 300 cycles, 1 repeat, 1 s at 100 Hz")
    p.add_argument("--serve", choices=("slave", "echo"), help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    req, reply = dx_request(True), dx_reply()
    if args.serve == "slave":
        return serve_slave()
    if args.serve == "echo":
        return serve_echo(len(req), reply)
    if args.quick:
        args.cycles, args.repeats, args.hz_seconds = 300, 1, 1.0
    if args.cycles < 10 or args.repeats < 1 or args.hz_seconds <= 0:
        p.error("need --cycles >= 10, --repeats >= 1, --hz-seconds > 0")
    peer_python = os.environ.get("VR_PEER_PYTHON")

    print("DP cycle benchmark: 14/14-byte Data_Exchange (request %d B, reply %d B), pty pairs, "
          "port set to %d baud, %d repeat(s) x %d cycles, variants alternated, medians"
          % (len(req), len(reply), args.baud, args.repeats, args.cycles))
    echo = Server("echo")
    slave = Server("slave")
    results: Dict[str, List[Dict]] = {"floor": [], "slave-only": [], "ours": [], "pyprofibus": []}
    failed = False
    started = time.perf_counter()
    try:
        for r in range(args.repeats):
            variants = [
                ("floor", echo, lambda: bare_client(echo.path, [req], len(reply), args.cycles)),
                ("slave-only", slave, lambda: run_slave_only(slave.path, args.baud, args.cycles)),
                ("ours", slave, lambda: run_ours(slave.path, args.baud, args.cycles, r)),
            ]
            if peer_python:
                variants.append(("pyprofibus", slave, lambda: run_pyprofibus(
                    peer_python, slave.path, args.baud, args.cycles, r)))
            for name, server, fn in variants:
                s0 = server.cpu()
                try:
                    res = fn()
                except (RuntimeError, OSError, subprocess.TimeoutExpired) as err:
                    print(f"{name}: FAILED in repeat {r + 1}: {err}")
                    failed = True
                    continue
                res["server_cpu"] = server.cpu() - s0
                if res["mismatches"]:
                    print(f"{name}: {res['mismatches']} mismatching/lost cycles in repeat {r + 1}")
                    failed = True
                results[name].append(res)
        hz_bare = hz_floor(echo.path, len(reply), req, args.hz_seconds)
        hz = hz_run(slave.path, args.baud, args.hz_seconds, slave)
    finally:
        echo.close()
        slave.close()

    med: Dict[str, Dict[str, float]] = {}
    print("%-12s %12s %14s %14s %12s  %s" % ("variant", "cycles/s", "master CPU", "server CPU",
                                             "wall us", "(medians; CPU in us per cycle)"))
    labels = {"floor": "bare echo, no protocol logic", "slave-only": "bare client -> our slave",
              "ours": "DpMaster.cycle() -> our slave",
              "pyprofibus": "pyprofibus 1.13 DPM1.run() -> our slave"}
    for name, runs in results.items():
        if not runs:
            if name == "pyprofibus" and not peer_python:
                print("%-12s skipped: VR_PEER_PYTHON unset (run through scripts/bench)" % name)
            continue
        m = {"rate": statistics.median(x["cycles"] / x["wall"] for x in runs),
             "cpu": statistics.median(x["cpu"] / x["cycles"] * 1e6 for x in runs),
             "server": statistics.median(x["server_cpu"] / x["cycles"] * 1e6 for x in runs),
             "wall": statistics.median(x["wall"] / x["cycles"] * 1e6 for x in runs)}
        med[name] = m
        print("%-12s %12.0f %14.1f %14.1f %12.1f  %s" % (name, m["rate"], m["cpu"], m["server"],
                                                        m["wall"], labels[name]))
    if "pyprofibus" in results and results["pyprofibus"]:
        print("(pyprofibus: server CPU includes its start-up handshake; rs_errors %d)"
              % sum(x.get("rs_errors", 0) for x in results["pyprofibus"]))

    def ratio(a: str, b: str, key: str) -> Optional[float]:
        return med[a][key] / med[b][key] if a in med and b in med and med[b][key] else None

    def show(label: str, value: Optional[float]) -> None:
        print("ratio %-36s %s" % (label + ":", "n/a" if value is None else "%.3f" % value))
    r_floor = ratio("ours", "floor", "rate")
    r_slave = ratio("ours", "slave-only", "rate")
    r_py = ratio("ours", "pyprofibus", "rate")
    r_cpu = ratio("ours", "pyprofibus", "cpu")
    show("ours/floor cycles/s", r_floor)
    show("ours/slave-only cycles/s", r_slave)
    show("ours/pyprofibus cycles/s", r_py)
    show("ours/pyprofibus CPU per cycle", r_cpu)

    core = hz["cpu"] / hz["wall"] * 100.0
    print("100 Hz: DpMaster.run(period=0.01) for %.1f s: %d cycles (%.1f/s), master %.2f %% of one "
          "core (%.1f us CPU per cycle), slave process %.2f %%, period jitter p99 %.3f ms max "
          "%.3f ms, overruns %d, losses %d"
          % (hz["wall"], hz["cycles"], hz["cycles"] / hz["wall"], core,
             hz["cpu"] / max(1, hz["cycles"]) * 1e6, hz["slave_cpu"] / hz["wall"] * 100.0,
             hz["jitter_p99"] * 1e3, hz["jitter_max"] * 1e3, hz["overruns"], hz["losses"]))
    print("100 Hz floor: bare round trip to the echo server + time.sleep for %.1f s: %.2f %% of one "
          "core (%.1f us CPU per cycle; each wake-up from a sleep costs CPU on this machine)"
          % (hz_bare["wall"], hz_bare["cpu"] / hz_bare["wall"] * 100.0,
             hz_bare["cpu"] / max(1, hz_bare["cycles"]) * 1e6))
    if hz["losses"]:
        failed = True

    print("wire time of one 14/14 Data_Exchange: TSYN %d bit + %d chars x 11 bit + TSDR "
          "(min..max bit), vs our software per cycle (master CPU %s us, pty round trip %s us)"
          % (BusTiming.tsyn_bits, len(req) + len(reply),
             "%.1f" % med["ours"]["cpu"] if "ours" in med else "n/a",
             "%.1f" % med["ours"]["wall"] if "ours" in med else "n/a"))
    for baud, label in WIRE_BAUDS:
        w = wire_time(baud, len(req), len(reply))
        line = ("wire %-6s TSDR %3d..%3d bit: %9.1f .. %9.1f us  (max %6.0f cycles/s)"
                % (label, w["tsdr"][0], w["tsdr"][1], w["min"] * 1e6, w["max"] * 1e6,
                   1.0 / w["min"]))
        if "ours" in med:
            line += ("  master CPU = %5.1f %% of the wire time, pty round trip = %6.1f %%"
                     % (med["ours"]["cpu"] / (w["min"] * 1e6) * 100.0,
                        med["ours"]["wall"] / (w["min"] * 1e6) * 100.0))
        print(line)

    def target(ok: Optional[bool], text: str, value: str) -> None:
        print("%s %s (%s)" % ("n/a " if ok is None else ("PASS" if ok else "MISS"), text, value))
    target(None if r_floor is None else r_floor >= 0.9, "ours >= 90 % of the link floor cycles/s",
           "n/a" if r_floor is None else "%.1f %%" % (r_floor * 100))
    target(None if r_py is None else r_py > 1.0, "ours above pyprofibus cycles/s",
           "n/a" if r_py is None else "%.2fx" % r_py)
    target(None if r_cpu is None else r_cpu <= 0.5, "our CPU per cycle <= 1/2 of pyprofibus's",
           "n/a" if r_cpu is None else "%.2fx" % r_cpu)
    target(core < 2.0, "100 Hz below 2 % of one core", "%.2f %%" % core)
    print("python %s, %d CPUs, load %.2f, wall time %.1f s%s"
          % (sys.version.split()[0], os.cpu_count() or 0, os.getloadavg()[0],
             time.perf_counter() - started, "; FAILED (see above)" if failed else ""))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
