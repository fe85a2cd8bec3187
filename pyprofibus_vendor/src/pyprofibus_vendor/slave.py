"""``python3 -m pyprofibus_vendor.slave``: a generic DP-V0 slave on a device or on a new pty.

The counterpart of the ``master`` tool for trying a master without hardware: our slave engine
(:class:`~.dp_slave.DpSlave` served by :class:`~.dp_slave.SlaveServer`) with a given address,
ident and Cfg, answering with fixed inputs (``--inputs``) or echoing the master's outputs
(``--echo``). With ``--pty`` it creates a pty pair and prints ``device: /dev/pts/N`` as the first
line; a master opens that path. It prints state changes, faults and watchdog expiry as they happen
and its counters on exit (SIGINT/SIGTERM or ``--duration``; exit status 0).
"""
from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
import time
from typing import Any, List, Optional

from . import _cli
from ._cli import DeviceError, UsageError, hexstr
from .errors import DpError, PhyError

__all__ = ["main", "build_parser"]

_DESCRIPTION = """\
A generic PROFIBUS-DP (DP-V0) slave for trying a master without hardware: answers FDL_Status,
Slave_Diag, Set_Prm, Chk_Cfg, Get_Cfg, Rd_Inp/Rd_Outp, Global_Control and Data_Exchange with the
given address, ident and Cfg bytes, checks the ident and the Cfg like a real slave and drops to
the safe state when its watchdog expires.

Serve an existing device (--device, e.g. one end of a socat pair or an RS-485 adapter), or a new
pty (--pty): the first line on stdout is then "device: /dev/pts/N", the path a master opens;
--link adds a symlink to it (removed on exit). Inputs (slave -> master) are --inputs HEX (fixed),
--echo (the last outputs, cut or zero-padded to the input length) or zeros. State changes,
faults and watchdog expiry are printed as they happen, the counters on exit. Runs until
SIGINT/SIGTERM or --duration."""

_EXAMPLES = [
    "python3 -m pyprofibus_vendor.slave --pty --link /tmp/vr006l --addr 4 --ident 0x06C6 "
    "--cfg '13 13 13 11 23 23 23 21' --echo",
    "python3 -m pyprofibus_vendor.slave --device /dev/ttyUSB1 --addr 8 --ident 0x4D14 --cfg 3D "
    "--inputs '00 01 02 03 04 05 06 07 08 09 0A 0B 0C 0D' --duration 60",
]

_EXIT_MEANINGS = {
    _cli.EXIT_OK: "stopped by SIGINT/SIGTERM or after --duration",
    _cli.EXIT_FAILED: "the slave could not be started",
    _cli.EXIT_USAGE: "usage error (bad option or hex, address/ident out of range, --inputs "
                     "length does not match the Cfg, --link path taken)",
    _cli.EXIT_DEVICE: "the device cannot be opened or failed while serving",
}


def build_parser() -> argparse.ArgumentParser:
    p = _cli.make_parser("slave", _DESCRIPTION, _EXIT_MEANINGS, _EXAMPLES)
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--device", metavar="DEV",
                       help="serve this serial device or pyserial URL")
    where.add_argument("--pty", action="store_true",
                       help="create a pty pair and serve it; prints 'device: PATH' first")
    p.add_argument("--link", metavar="PATH",
                   help="with --pty: make PATH a symlink to the pty device (removed on exit)")
    p.add_argument("--addr", metavar="N", type=_cli.address_arg, required=True,
                   help="station address, 0..125")
    p.add_argument("--ident", metavar="0xNNNN", type=_cli.ident_arg, required=True,
                   help="ident number, 0..0xFFFF")
    p.add_argument("--cfg", metavar="HEX", type=_cli.cfg_arg, required=True,
                   help="the slave's Cfg bytes (compared literally with Chk_Cfg)")
    inputs = p.add_mutually_exclusive_group()
    inputs.add_argument("--echo", action="store_true",
                        help="inputs = the last outputs, cut or zero-padded to the input length")
    inputs.add_argument("--inputs", metavar="HEX", type=_cli.hex_arg,
                        help="fixed input bytes (slave -> master); default zeros")
    p.add_argument("--baud", metavar="B", type=_cli.baud_arg, default=19200,
                   help="bit rate of --device (default 19200; a pty ignores it)")
    p.add_argument("--duration", metavar="S", type=_cli.seconds_arg,
                   help="stop after S seconds (default: run until SIGINT/SIGTERM)")
    p.add_argument("--show-outputs", action="store_true",
                   help="print every new output image the master sends")
    p.add_argument("-v", "--verbose", action="count", default=0,
                   help="log the slave engine's messages (-v) and telegram details (-vv) on stderr")
    return p


def fit(data: bytes, size: int) -> bytes:
    """``data`` cut or zero-padded to ``size`` bytes."""
    return bytes(data[:size]) + bytes(max(0, size - len(data)))


def _stamp(start: float) -> str:
    return "%9.3f" % (time.monotonic() - start)


class _Reporter:
    """Prints what the slave does: state changes, faults, watchdog expiry, new outputs."""

    def __init__(self, show_outputs: bool) -> None:
        self.start = time.monotonic()
        self.show_outputs = show_outputs
        self.slave: Any = None
        self.watchdog: Optional[float] = None
        self.master: Optional[int] = None
        self._last_outputs: Optional[bytes] = None

    def line(self, text: str) -> None:
        print("%s %s" % (_stamp(self.start), text))

    def on_state_change(self, old: Any, new: Any, reason: str) -> None:
        from .dp_slave import SlaveState
        if new is not SlaveState.WAIT_PRM and self.slave is not None \
                and self.slave.locked_by is not None:
            self.watchdog = self.slave.watchdog_time
            self.master = self.slave.locked_by
        if reason == "watchdog expired":
            self.line("watchdog expired: no telegram from master %s for %s; outputs set to the "
                      "safe image, waiting for Set_Prm"
                      % (self.master, "?" if self.watchdog is None else "%.3f s" % self.watchdog))
        self.line("state: %s -> %s (%s)" % (old.value, new.value, reason))

    def on_outputs(self, data: bytes) -> None:
        if self.show_outputs and data != self._last_outputs:
            self._last_outputs = data
            self.line("outputs: %s" % (hexstr(data) or "(none)"))


def _make_slave(args: argparse.Namespace, reporter: _Reporter) -> Any:
    """A DpSlave that also reports Prm/Cfg faults and refusals (the engine only logs those)."""
    from .dp import Sap, SetPrm
    from .dp_slave import DpSlave

    class ToolSlave(DpSlave):
        def handle(self, frame: Any, now: Optional[float] = None) -> Any:
            c = self.counters
            before = (c.prm_faults, c.cfg_faults, c.prm_refused)
            reply = super().handle(frame, now)
            if (c.prm_faults, c.cfg_faults, c.prm_refused) != before:
                reporter.line(self._describe_fault(frame, before))
            return reply

        def _describe_fault(self, frame: Any, before: Any) -> str:
            c = self.counters
            data = bytes(getattr(frame, "data", b""))
            if c.prm_faults != before[0]:
                try:
                    prm = SetPrm.decode(data)
                except DpError as err:
                    return "parameter fault: malformed Set_Prm from master %d: %s" % (frame.sa, err)
                if prm.ident != self.ident:
                    return ("parameter fault: Set_Prm from master %d carries ident 0x%04X, own "
                            "ident is 0x%04X" % (frame.sa, prm.ident, self.ident))
                return "parameter fault: Set_Prm %s from master %d rejected" % (hexstr(data),
                                                                                frame.sa)
            if c.cfg_faults != before[1]:
                return ("configuration fault: Chk_Cfg from master %d sent %s, own Cfg is %s"
                        % (frame.sa, hexstr(data) or "(empty)", hexstr(self.cfg)))
            dsap = getattr(frame, "dsap", None)
            what = {Sap.SET_PRM: "Set_Prm", Sap.CHK_CFG: "Chk_Cfg",
                    Sap.SET_SLAVE_ADD: "Set_Slave_Add"}.get(dsap, "request")
            if self.locked_by is None:
                return ("%s from master %d ignored: not parameterised (no Set_Prm accepted)"
                        % (what, frame.sa))
            return "%s from master %d refused: locked by master %d" % (what, frame.sa,
                                                                       self.locked_by)

    slave = ToolSlave(args.addr, args.ident, args.cfg, on_state_change=reporter.on_state_change,
                      on_outputs=reporter.on_outputs)
    reporter.slave = slave
    if args.inputs is not None:
        if len(args.inputs) != slave.input_size:
            raise UsageError("--inputs has %d bytes, but the Cfg %s declares %d input bytes "
                             "(slave -> master)" % (len(args.inputs), hexstr(args.cfg),
                                                    slave.input_size))
        slave.inputs = args.inputs
    elif args.echo:
        slave.get_inputs = lambda: fit(slave.outputs, slave.input_size)
    return slave


def _make_link(path: str, target: str) -> None:
    """Create the --link symlink; an old symlink is replaced, anything else is an error."""
    if os.path.lexists(path):
        if not os.path.islink(path):
            raise UsageError("--link %s exists and is not a symlink; not replacing it" % path)
        os.unlink(path)
    try:
        os.symlink(target, path)
    except OSError as exc:
        raise UsageError("cannot create --link %s: %s" % (path, exc.strerror or exc)) from None


def _remove_link(path: str, target: str) -> None:
    try:
        if os.path.islink(path) and os.readlink(path) == target:
            os.unlink(path)
    except OSError:
        pass


def _print_counters(slave: Any, server: Any) -> None:
    from dataclasses import asdict
    print("counters:")
    rows: List[Any] = list(asdict(slave.counters).items())
    rows += [("frames", server.counters.frames), ("replies", server.counters.replies),
             ("fcs_errors", server.deframer.counters.fcs_errors),
             ("garbage_bytes", server.deframer.counters.garbage_bytes),
             ("idle_discards", server.counters.idle_discards)]
    for name, value in rows:
        print("  %-18s %s" % (name, value))
    print("final state: %s" % slave.state.value)


def _run(args: argparse.Namespace) -> int:
    from .dp_slave import SlaveServer
    from .phy_serial import open_pty_pair
    _cli.line_buffered_stdout()
    _cli.setup_logging(args.verbose)
    if args.link and not args.pty:
        raise UsageError("--link needs --pty")
    reporter = _Reporter(args.show_outputs)
    slave = _make_slave(args, reporter)           # validates before any device is touched
    stop = threading.Event()
    pair = None
    link_path = None
    if args.pty:
        pair = open_pty_pair()
        device = pair.slave_path
        link = pair.master_link()
    else:
        device = args.device
        link = _cli.open_serial(args.device, args.baud)
    try:
        if args.pty:
            if args.link:
                _make_link(args.link, device)
                link_path = args.link
            print("device: %s" % device)
            if link_path:
                print("link: %s -> %s" % (link_path, device))
        mode = ("echo" if args.echo else "fixed %s" % (hexstr(slave.inputs) or "(none)")
                if args.inputs is not None else "zeros")
        print("slave: address %d, ident 0x%04X, Cfg %s (%d in, %d out), inputs %s"
              % (args.addr, args.ident, hexstr(args.cfg), slave.input_size, slave.output_size,
                 mode))

        def on_signal(signum: int, _frame: Any) -> None:
            stop.set()

        signal.signal(signal.SIGINT, on_signal)
        signal.signal(signal.SIGTERM, on_signal)
        timer = None
        if args.duration:
            timer = threading.Timer(args.duration, stop.set)
            timer.daemon = True
            timer.start()
        server = SlaveServer(link, slave)
        reporter.line("serving on %s" % device)
        failure: Optional[str] = None
        try:
            server.serve(stop)
        except PhyError as exc:
            failure = str(exc)
        finally:
            if timer is not None:
                timer.cancel()
        _print_counters(slave, server)
        if failure is not None:
            raise DeviceError("%s failed while serving: %s" % (device, failure))
        return _cli.EXIT_OK
    finally:
        link.close()
        if pair is not None:
            pair.close()
        if link_path:
            _remove_link(link_path, device)


def main(argv: Optional[List[str]] = None) -> int:
    """CLI entry point; returns the exit status."""
    return _cli.run(build_parser(), _run, argv)


if __name__ == "__main__":
    sys.exit(main())
