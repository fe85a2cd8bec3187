#!/usr/bin/python3
"""Stale replies on the virtual line (printed, never asserted): how many Data_Exchange turns took a
reply that answered an earlier request (inputs a cycle old) -- through a USB adapter with a latency
timer, with and without echo (controller.adapter_model), over real ptys paced at 19.2 kbit/s.

    scripts/bench stale_replies [-- --seconds 15 --latency-ms 16]

Run it beside busy loops (e.g. two ``python3 -c 'while 1: pass'``) to see the resends of a loaded
machine. The station is our DpSlave (in a thread, on its own pty behind the line hub) whose inputs
are its outputs XOR 0xA5; the outputs change with every request, so a turn's inputs tell exactly
which request's reply ended it: ``stale`` counts the turns whose inputs are not their own request's.
``late_replies`` is the master's counter of the replies it skipped as an earlier transmission's.
Runs: echo; no echo; no echo with ``wire_timed`` (the hub paces the line at the bit rate, so a reply
read sooner than the wire allows is an earlier transmission's).
"""
from __future__ import annotations

import argparse
import logging
import tempfile
import threading
import time
from pathlib import Path

from pyprofibus_vendor.config import ROBOT_IDENT, default_robot_config
from pyprofibus_vendor.dp_master import DpMaster, SlaveSpec
from pyprofibus_vendor.dp_slave import DpSlave, SlaveServer
from pyprofibus_vendor.phy_serial import SerialLink, open_pty_pair

from vr_driver.controller.adapter_model import AdapterBehaviour
from vr_driver.controller.line import LineHub

BAUD, MASTER, SLAVE = 19200, 2, 4


def run(seconds: float, latency_ms: int, echo: bool, wire_timed: bool) -> str:
    cfg = default_robot_config("virtual", phy_type="memory").slave(SLAVE).cfg
    stop = threading.Event()
    pair = open_pty_pair()
    slave = DpSlave(SLAVE, ROBOT_IDENT, cfg)
    slave.on_outputs = lambda out: setattr(slave, "inputs", bytes(x ^ 0xA5 for x in out))
    server = SlaveServer(pair.master_link(), slave)
    thread = threading.Thread(target=server.serve, args=(stop,), daemon=True)
    thread.start()
    with tempfile.TemporaryDirectory() as tmp:
        hub = LineHub([pair.slave_path], pty_link=str(Path(tmp) / "line"), baud=BAUD,
                      adapter=AdapterBehaviour(latency_ms=latency_ms, echo=echo)).start()
        link = SerialLink(str(Path(tmp) / "line"), BAUD)
        master = DpMaster(link, MASTER, BAUD, dx_tolerance=0.5, retry_steps=True, backoff_max=0.3,
                          **({"wire_timed": True} if wire_timed else {}))
        robot = master.add_slave(SlaveSpec(SLAVE, ROBOT_IDENT, cfg, watchdog=0.3))
        seen = {"dx": 0, "stale": 0}
        real_done = master._dx_done

        def done(p, data, status, now) -> None:       # the request's outputs: its SD2 data unit
            seen["dx"] += 1
            if bytes(x ^ 0xA5 for x in data) != p.raw[7:-2]:
                seen["stale"] += 1
            real_done(p, data, status, now)

        master._dx_done = done
        try:
            if not master.wait_connected(SLAVE, 15.0):
                raise SystemExit("no Data_Exchange through the adapter")
            c = master.counters
            d0, s0, r0, q0, l0 = seen["dx"], seen["stale"], c.retries, c.requests, getattr(c, "late_replies", 0)
            end, n = time.monotonic() + seconds, 0
            while time.monotonic() < end:
                n += 1
                robot.outputs = n.to_bytes(2, "big") * 7
                master.cycle(timeout=1.0)
            return (f"{seconds:.0f} s, latency timer {latency_ms} ms, echo {echo}, wire_timed "
                    f"{wire_timed}: Data_Exchange "
                    f"replies {seen['dx'] - d0}, stale {seen['stale'] - s0}, late_replies "
                    f"{getattr(c, 'late_replies', 0) - l0}, retries {c.retries - r0} of {c.requests - q0} requests, "
                    f"connected {robot.connected}, losses {c.losses}")
        finally:
            master.close()
            hub.stop()
            stop.set()
            thread.join(2.0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=15.0)
    ap.add_argument("--latency-ms", type=int, default=16)
    args = ap.parse_args()
    logging.getLogger("pyprofibus_vendor").setLevel(logging.ERROR)
    for echo, timed in ((True, False), (False, False), (False, True)):
        print(run(args.seconds, args.latency_ms, echo, timed), flush=True)


if __name__ == "__main__":
    main()
