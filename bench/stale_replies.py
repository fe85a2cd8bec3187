#!/usr/bin/python3
"""Late replies on the virtual line (printed, never asserted): how many Data_Exchange turns took a
reply read before their request's own echo -- necessarily an earlier transmission's reply, inputs a
cycle old -- through an echoing USB adapter with a latency timer (controller.adapter_model), over
real ptys at 19.2 kbit/s.

    scripts/bench stale_replies [-- --seconds 20 --latency-ms 16]

Run it beside busy loops (e.g. two ``python3 -c 'while 1: pass'``) to see the resends of a loaded
machine. The link's bytes are parsed a second time beside the master (its own Deframer), chunk by
chunk as the master reads them: ``exposed`` counts new requests that had an earlier transmission's
reply read before their own echo; ``taken`` the Data_Exchange turns that ended while their
request's echo was not read yet (a lower bound of the stale replies taken: a chunk is judged as a
whole); ``late_replies`` the master's counter of the replies it skipped.
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from pyprofibus_vendor.config import ROBOT_IDENT, default_robot_config
from pyprofibus_vendor.dp_master import DpMaster, SlaveSpec
from pyprofibus_vendor.fdl import Deframer
from pyprofibus_vendor.phy_serial import SerialLink

from vr_driver.controller.adapter_model import AdapterBehaviour
from vr_driver.controller.line import LineHub
from vr_driver.controller.program import VirtualController

BAUD, MASTER, SLAVE = 19200, 2, 4


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--latency-ms", type=int, default=16)
    args = ap.parse_args()
    cfg = default_robot_config("virtual", phy_type="memory").slave(SLAVE).cfg
    with tempfile.TemporaryDirectory() as tmp:
        g2 = VirtualController(pty_link=str(Path(tmp) / "g2"), baud=BAUD).start()
        hub = LineHub([str(Path(tmp) / "g2")], pty_link=str(Path(tmp) / "line"), baud=BAUD,
                      adapter=AdapterBehaviour(latency_ms=args.latency_ms, echo=True)).start()
        link = SerialLink(str(Path(tmp) / "line"), BAUD)
        master = DpMaster(link, MASTER, BAUD, dx_tolerance=0.5, retry_steps=True, backoff_max=0.3)
        robot = master.add_slave(SlaveSpec(SLAVE, ROBOT_IDENT, cfg, watchdog=0.3))
        seen = {"tx": b"", "own_echo": False, "reply_first": False, "new": 0, "exposed": 0,
                "taken": 0, "dx": 0}
        spy = Deframer()
        real_send, real_recv, real_done = link.send, link.recv, master._dx_done

        def send(data: bytes) -> None:
            if bytes(data) != seen["tx"]:               # a new request (not a resend)
                seen["new"] += 1
                seen["own_echo"] = seen["reply_first"] = False
            seen["tx"] = bytes(data)
            real_send(data)

        def recv(n: int = 4096, timeout: float = 0.0) -> bytes:
            data = real_recv(n, timeout)
            for frame in spy.feed(data) if data else ():
                if frame.encode() == seen["tx"]:
                    seen["own_echo"] = True
                elif not seen["own_echo"] and getattr(frame, "da", None) == MASTER \
                        and not frame.fc.request and not seen["reply_first"]:
                    seen["reply_first"] = True
                    seen["exposed"] += 1
            return data

        def done(p, data, status, now) -> None:
            seen["dx"] += 1
            if not seen["own_echo"]:
                seen["taken"] += 1
            real_done(p, data, status, now)

        link.send, link.recv, master._dx_done = send, recv, done
        try:
            if not master.wait_connected(SLAVE, 15.0):
                raise SystemExit("no Data_Exchange through the adapter")
            c = master.counters
            n0, e0, t0, d0, r0, q0 = (seen["new"], seen["exposed"], seen["taken"], seen["dx"],
                                      c.retries, c.requests)
            l0 = getattr(c, "late_replies", 0)
            end = time.monotonic() + args.seconds
            while time.monotonic() < end:
                master.cycle(timeout=1.0)
            print(f"{args.seconds:.0f} s, latency timer {args.latency_ms} ms, echo: "
                  f"new requests {seen['new'] - n0}, exposed {seen['exposed'] - e0}, "
                  f"Data_Exchange replies {seen['dx'] - d0}, taken before their echo "
                  f"{seen['taken'] - t0}, late_replies {getattr(c, 'late_replies', 0) - l0}, "
                  f"retries {c.retries - r0} of {c.requests - q0} requests, "
                  f"connected {robot.connected}, losses {c.losses}")
        finally:
            master.close()
            hub.stop()
            g2.stop()


if __name__ == "__main__":
    main()
