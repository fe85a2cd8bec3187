"""Peer: pyprofibus 1.13's DP master (DPM1) driving one slave over a serial device.

Run ONLY with the test-peer interpreter ($VR_PEER_PYTHON, a venv holding pyprofibus 1.13);
our package never imports pyprofibus. Used by test/test_interop_pyprofibus.py and by
bench/dp_cycle.py.

    $VR_PEER_PYTHON pyprofibus_master.py --port /dev/pts/N --gsd PAN06C6.gsd \
        [--baud 19200] [--slave 4] [--master 2] [--cycles 300] [--xor 0xA5] [--timeout 15]
        [--watchdog-ms 1000] [--stall-at N --stall-s S] [--no-pty-preset] [--debug 0..2]

The slave is configured from the GSD with the robot's module list (Chk_Cfg
13 13 13 11 23 23 23 21, 14 bytes each way). Once in Data_Exchange, cycle i sends the
output image ``image(i, seed)`` and checks that the reply equals the image XOR ``--xor``
(what the test slave's application does). pyprofibus's run() is non-blocking, so the loop
calls it back to back (its intended use); the exchange phase is timed with
time.monotonic() and time.process_time() (this process only).

Output (stdout, flushed; pyprofibus's own messages may appear in between):

    PEER READY <port> <baud>               PHY open, master initialised
    PEER CONNECTED <seconds since start>   the slave reached Data_Exchange
    PEER MISMATCH <i> <got hex> <want hex> a reply that is not the expected one
    PEER STALL <i> <seconds>               fault injection: the application pauses here
    PEER RS <i> <message>                  pyprofibus raised DpError out of run() (see below)
    PEER SUMMARY {json}                    last line: ok, cycles, mismatches, rs_errors,
                                           reconnects, sent_sha256, wall_s, cpu_s,
                                           cycles_per_s, cpu_us_per_cycle, connect_s, error

Exit status 0 only if ``ok`` (all cycles done in time, no mismatch).

Deviations of pyprofibus 1.13 handled here (reported by the summary, never hidden):

* Linux pty + 8E1: the pty driver drops PARENB and tcsetattr() then fails with EINVAL unless
  the same call changes the speed. pyserial applies the settings on every open; pyprofibus
  opens at 9600 and re-opens at the configured rate. Before that, this script sets the pty
  to 1200 baud (2400 if it already is at 1200), so both of pyprofibus's opens change the
  speed and succeed however often the pty was used before. (Without it, a second run at
  9600 baud on the same pty dies with a raw termios.error (22) from pyserial's open, which
  pyprofibus does not wrap into a PhyError.)
* A slave answering Data_Exchange with RS (SAP not activated -- the standard's answer
  outside Data_Exch, e.g. after its watchdog expired) makes pyprofibus raise DpError out of
  run() instead of re-parameterising the slave. The loop catches it, counts it (rs_errors)
  and keeps calling run(), whose own fault handling then re-initialises the slave.
"""
from __future__ import annotations

import argparse
import hashlib
import io
import json
import os
import struct
import sys
import termios
import time

ROBOT_MODULES = ["4 Bytes In", "4 Bytes In", "4 Bytes In", "2 Bytes In",
                 "4 Bytes Out", "4 Bytes Out", "4 Bytes Out", "2 Bytes Out"]


def say(*words: object) -> None:
    print("PEER", *words, flush=True)


def image(i: int, seed: int, size: int) -> bytes:
    """The output image of cycle i (deterministic; 7 little-endian words for 14 bytes)."""
    words = [((i * 7 + k + seed) * 2654435761 >> 7) & 0xFFFF for k in range((size + 1) // 2)]
    return struct.pack("<%dH" % len(words), *words)[:size]


def preset_pty_speed(path: str) -> bool:
    """Give a pty a speed that neither of pyprofibus's opens uses (the PARENB quirk)."""
    real = os.path.realpath(path)
    if not real.startswith("/dev/pts/"):
        return False
    fd = os.open(real, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    try:
        attr = termios.tcgetattr(fd)
        speed = termios.B2400 if attr[4] == termios.B1200 else termios.B1200
        attr[4] = attr[5] = speed
        termios.tcsetattr(fd, termios.TCSANOW, attr)
    finally:
        os.close(fd)
    return True


def make_conf(args: argparse.Namespace) -> str:
    lines = [
        "[PROFIBUS]", "debug = %d" % args.debug, "",
        "[PHY]", "type = serial", "dev = %s" % args.port, "baud = %d" % args.baud, "",
        "[DP]", "master_class = 1", "master_addr = %d" % args.master, "",
        "[SLAVE_0]", "name = robot", "addr = %d" % args.slave, "gsd = %s" % args.gsd,
        "sync_mode = 0", "freeze_mode = 0", "watchdog_ms = %d" % args.watchdog_ms,
        # pyprofibus names sizes from the slave's view: input = master -> slave
        "input_size = %d" % args.size, "output_size = %d" % args.size,
    ]
    lines += ["module_%d = %s" % (n, name) for n, name in enumerate(args.modules)]
    return "\n".join(lines) + "\n"


def open_station(args: argparse.Namespace, summary: dict):
    """pyprofibus's DP master for the one station of ``args`` (make_conf), initialised; says READY.
    Returns (master, slave description); ``summary["master"]`` holds the master as soon as it exists,
    so that :func:`finish` destroys it also when the set-up fails half way."""
    from pyprofibus import PbConf
    conf = PbConf(io.StringIO(make_conf(args)), "peer.conf")
    master = summary["master"] = conf.makeDPM()
    desc = conf.slaveConfs[0].makeDpSlaveDesc()
    master.addSlave(desc)
    master.initialize()
    say("READY", args.port, args.baud)
    return master, desc


def finish(summary: dict) -> int:
    """Destroy the master (if any), say the SUMMARY (without it) and return the exit status."""
    master = summary.pop("master", None)
    if master is not None:
        try:
            master.destroy()
        except Exception as err:  # noqa: BLE001 -- report, the summary must still come
            summary["error"] = summary["error"] or "destroy: %s" % err
    say("SUMMARY", json.dumps(summary, sort_keys=True))
    return 0 if summary["ok"] else 1


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--port", required=True)
    p.add_argument("--gsd", required=True)
    p.add_argument("--baud", type=int, default=19200)
    p.add_argument("--slave", type=int, default=4)
    p.add_argument("--master", type=int, default=2)
    p.add_argument("--size", type=int, default=14, help="bytes each way (default 14)")
    p.add_argument("--modules", nargs="+", default=ROBOT_MODULES,
                   help="GSD module names in Chk_Cfg order (default: the robot's list)")
    p.add_argument("--cycles", type=int, default=300)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--xor", type=lambda s: int(s, 0), default=0xA5,
                   help="the slave returns outputs XOR this byte (default 0xA5)")
    p.add_argument("--watchdog-ms", type=int, default=1000)
    p.add_argument("--timeout", type=float, default=15.0, help="give up after this many s")
    p.add_argument("--stall-at", type=int, default=-1,
                   help="fault injection: before cycle N the application stalls ...")
    p.add_argument("--stall-s", type=float, default=0.0,
                   help="... for this many seconds (longer than the watchdog: the slave drops out)")
    p.add_argument("--debug", type=int, default=0, help="pyprofibus debug level (0..2)")
    p.add_argument("--no-pty-preset", action="store_true",
                   help="do not apply the pty speed work-around (to show the quirk)")
    args = p.parse_args(argv)

    # only here: the peer interpreter has pyprofibus, ours must not need it
    from pyprofibus import DpError, ProfibusError

    t_start = time.monotonic()
    deadline = t_start + args.timeout
    summary = {"ok": False, "cycles": 0, "mismatches": 0, "rs_errors": 0, "reconnects": 0,
               "sent_sha256": None, "wall_s": None, "cpu_s": None, "cycles_per_s": None,
               "cpu_us_per_cycle": None, "connect_s": None, "pty_preset": False,
               "chk_cfg": None, "error": None}
    try:
        if not args.no_pty_preset:
            summary["pty_preset"] = preset_pty_speed(args.port)
        master, desc = open_station(args, summary)
        summary["chk_cfg"] = bytes(desc.chkCfgTelegram.getDU()).hex()

        sent = hashlib.sha256()
        mask = args.xor & 0xFF
        # the images and expected replies, computed before the timed phase
        outs = [image(n, args.seed, args.size) for n in range(args.cycles)] + [b""]
        wants = [bytes(b ^ mask for b in o) for o in outs]
        i = 0
        out, want = outs[0], wants[0]
        connected = False
        t0 = c0 = None
        while i < args.cycles:
            if time.monotonic() >= deadline:
                raise TimeoutError("%d of %d cycles after %.1f s" % (i, args.cycles, args.timeout))
            desc.setMasterOutData(out)   # not latched by pyprofibus: set before every run()
            try:
                handled = master.run()
            except DpError as err:       # RS reply in Data_Exchange (see the module doc)
                summary["rs_errors"] += 1
                say("RS", i, str(err).replace("\n", " "))
                continue
            now_connected = desc.isConnected()
            if now_connected and not connected:
                if t0 is None:
                    summary["connect_s"] = round(time.monotonic() - t_start, 4)
                    say("CONNECTED", summary["connect_s"])
                    t0, c0 = time.monotonic(), time.process_time()
                else:
                    summary["reconnects"] += 1
            connected = now_connected
            if handled is None:
                continue
            got = handled.getMasterInData()
            if got is None:
                continue
            got = bytes(got)
            if got != want:
                summary["mismatches"] += 1
                say("MISMATCH", i, got.hex(), want.hex())
            sent.update(out)
            i += 1
            out, want = outs[i], wants[i]
            if i == args.stall_at and args.stall_s > 0:
                say("STALL", i, args.stall_s)
                time.sleep(args.stall_s)  # the simulated application hiccup (not a sync)
        wall = time.monotonic() - t0
        cpu = time.process_time() - c0
        summary.update(cycles=i, sent_sha256=sent.hexdigest(), wall_s=round(wall, 6),
                       cpu_s=round(cpu, 6),
                       cycles_per_s=round(i / wall, 2) if wall > 0 else None,
                       cpu_us_per_cycle=round(cpu / i * 1e6, 2) if i else None)
        summary["ok"] = summary["mismatches"] == 0
    except (ProfibusError, OSError, TimeoutError, termios.error, ValueError) as err:
        summary["error"] = "%s: %s" % (type(err).__name__, str(err).replace("\n", " "))
    finally:
        status = finish(summary)
    return status


if __name__ == "__main__":
    sys.exit(main())
