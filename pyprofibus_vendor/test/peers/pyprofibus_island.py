"""Peer: pyprofibus 1.13's DP master (DPM1) sets an output of an I/O station and waits for an input.

Run ONLY with the test-peer interpreter ($VR_PEER_PYTHON); our packages never import pyprofibus.
Used by vr_driver/test/test_io_island_pyprofibus.py against the virtual I/O island:

    $VR_PEER_PYTHON pyprofibus_island.py --port /dev/pts/N --gsd VRIO0F1A.gsd --modules "16 DI" "16 DO" \
        --size 2 --slave 8 --output 0100 --until 0100/0100 [--timeout 15]

The station is configured from the GSD (pyprofibus_master.make_conf, the same quirk handling).
Once in Data_Exchange, every cycle sends the output image ``--output`` (hex) and reads the inputs;
it ends when ``inputs & MASK == VALUE`` (``--until VALUE/MASK``, hex).

Output (stdout, flushed): ``PEER READY``, ``PEER CONNECTED <s>``, ``PEER INPUTS <cycle> <s> <hex>``
whenever the inputs change, last ``PEER SUMMARY {json}`` (ok, cycles, connect_s, matched_s: seconds
from the first cycle with the output to the match, inputs, error). Exit status 0 only if ok.
"""
from __future__ import annotations

import argparse
import os
import sys
import termios
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from pyprofibus_master import finish, open_station, preset_pty_speed, say  # noqa: E402


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--port", required=True)
    p.add_argument("--gsd", required=True)
    p.add_argument("--modules", nargs="+", required=True)
    p.add_argument("--size", type=int, required=True, help="bytes each way")
    p.add_argument("--baud", type=int, default=19200)
    p.add_argument("--slave", type=int, default=8)
    p.add_argument("--master", type=int, default=2)
    p.add_argument("--watchdog-ms", type=int, default=1000)
    p.add_argument("--output", required=True, help="the output image to send (hex)")
    p.add_argument("--until", required=True, help="VALUE/MASK (hex): stop when inputs & MASK == VALUE")
    p.add_argument("--timeout", type=float, default=15.0)
    p.add_argument("--debug", type=int, default=0)
    args = p.parse_args(argv)
    out = bytes.fromhex(args.output)
    value, mask = (bytes.fromhex(x) for x in args.until.split("/"))

    from pyprofibus import DpError, ProfibusError

    t_start = time.monotonic()
    summary = {"ok": False, "cycles": 0, "connect_s": None, "matched_s": None, "inputs": None,
               "error": None}
    try:
        preset_pty_speed(args.port)
        master, desc = open_station(args, summary)
        t0 = None
        last = None
        while time.monotonic() < t_start + args.timeout:
            desc.setMasterOutData(out)
            try:
                handled = master.run()
            except DpError as err:
                say("RS", str(err).replace("\n", " "))
                continue
            if desc.isConnected() and summary["connect_s"] is None:
                summary["connect_s"] = round(time.monotonic() - t_start, 4)
                say("CONNECTED", summary["connect_s"])
            got = handled.getMasterInData() if handled is not None else None
            if got is None:
                continue
            got = bytes(got)
            summary["cycles"] += 1
            if t0 is None:
                t0 = time.monotonic()
            if got != last:
                last = got
                say("INPUTS", summary["cycles"], round(time.monotonic() - t0, 4), got.hex())
            if bytes(a & b for a, b in zip(got, mask)) == value:
                summary.update(ok=True, matched_s=round(time.monotonic() - t0, 4), inputs=got.hex())
                break
        else:
            summary["error"] = "TimeoutError: inputs %s never matched %s" % (last.hex() if last else None,
                                                                             args.until)
    except (ProfibusError, OSError, termios.error, ValueError) as err:
        summary["error"] = "%s: %s" % (type(err).__name__, str(err).replace("\n", " "))
    finally:
        status = finish(summary)
    return status


if __name__ == "__main__":
    sys.exit(main())
