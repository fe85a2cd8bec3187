"""``python3 -m pyprofibus_vendor.master``: bring one DP slave to Data_Exchange and exchange N cycles.

A commissioning check of one slave: open the device (a path or a pyserial URL), run our DP master
class 1 (FDL_Status, Slave_Diag, Set_Prm, Chk_Cfg, Slave_Diag) until the slave is in
Data_Exchange, send the given output bytes for ``--cycles`` Data_Exchange cycles, print the inputs
(hex) and the master's statistics. When the slave does not come up within ``--timeout``, the
reason is taken from its diagnosis (wrong ident, configuration fault, locked by another master...)
or from the missing replies (no answer). Every value is checked before anything is sent.

Settings can come from a bus configuration file (``--config``, see :mod:`.config`); explicit
options override the file. Exit status: see :mod:`._cli` (0 only when every cycle succeeded).
"""
from __future__ import annotations

import argparse
import json
import signal
import sys
import time
from dataclasses import dataclass
from typing import Any, Dict, List, Optional

from . import _cli
from ._cli import DeviceError, OperationFailed, UsageError, hexstr
from .errors import ConfigError, DpError, PhyError

__all__ = ["main", "build_parser"]

DEFAULT_BAUD = 19200
DEFAULT_MASTER_ADDRESS = 2
DEFAULT_TIMEOUT = 5.0
DEFAULT_WATCHDOG = 0.3
#: Reply timeout floor for a real serial line / for ptys and network URLs (software latency).
REPLY_FLOOR_SERIAL = 0.05
REPLY_FLOOR_VIRTUAL = 0.25

_DESCRIPTION = """\
Commissioning check of one PROFIBUS-DP slave: open the device, bring the slave to Data_Exchange
(FDL_Status, Slave_Diag, Set_Prm, Chk_Cfg, Slave_Diag), exchange --cycles Data_Exchange cycles
with the --out bytes, then print the inputs (hex) and the master's statistics.

If the slave does not reach Data_Exchange within --timeout, the reason is named from its
diagnosis (wrong ident, configuration fault, parameter fault, locked by another master) or from
the missing replies (no answer). All values are checked before anything is sent. With --config
the device, baud rate, addresses and the slave's settings come from a bus configuration file
(YAML or INI, as read by pyprofibus_vendor.config); options given explicitly override it."""

_EXAMPLES = [
    "python3 -m pyprofibus_vendor.master --device /dev/ttyUSB0 --addr 4 --ident 0x06C6 "
    "--cfg '13 13 13 11 23 23 23 21' --cycles 100 --out '01 00 02 00 03 00 04 00 05 00 06 00 07 00'",
    "python3 -m pyprofibus_vendor.master --config config/vr006l_bus.yaml --device /dev/pts/7 "
    "--cycles 20 --period 0.05",
]

_EXIT_MEANINGS = {
    _cli.EXIT_OK: "every cycle succeeded",
    _cli.EXIT_FAILED: "the slave did not reach Data_Exchange within --timeout, a cycle failed, "
                      "or interrupted",
    _cli.EXIT_USAGE: "usage or configuration error (bad option or hex, address/ident out of "
                     "range, --out length does not match the Cfg, bad --config file); nothing "
                     "was sent",
    _cli.EXIT_DEVICE: "the device cannot be opened or failed during the run",
}


def build_parser() -> argparse.ArgumentParser:
    p = _cli.make_parser("master", _DESCRIPTION, _EXIT_MEANINGS, _EXAMPLES)
    p.add_argument("--device", metavar="DEV",
                   help="serial device or pyserial URL (socket://host:port, loop://)")
    p.add_argument("--addr", metavar="N", type=_cli.address_arg,
                   help="the slave's station address, 0..125")
    p.add_argument("--ident", metavar="0xNNNN", type=_cli.ident_arg,
                   help="the slave's ident number (as in its GSD), 0..0xFFFF")
    p.add_argument("--cfg", metavar="HEX", type=_cli.cfg_arg,
                   help="Chk_Cfg identifier bytes, e.g. '13 13 13 11 23 23 23 21'")
    p.add_argument("--cycles", metavar="N", type=_cli.count_arg, required=True,
                   help="number of Data_Exchange cycles to run after the slave is up")
    p.add_argument("--out", metavar="HEX", type=_cli.hex_arg,
                   help="output bytes (master -> slave) sent in every cycle; their number must "
                        "equal the Cfg's output length (default: zeros)")
    p.add_argument("--baud", metavar="B", type=_cli.baud_arg,
                   help="bit rate, 9600..12000000 (default %d)" % DEFAULT_BAUD)
    p.add_argument("--master-addr", metavar="N", type=_cli.address_arg,
                   help="this master's station address (default %d)" % DEFAULT_MASTER_ADDRESS)
    p.add_argument("--watchdog", metavar="S", type=_cli.nonneg_seconds_arg,
                   help="slave watchdog in seconds, 0 = off (default: %g s, at least 3 x --period)"
                        % DEFAULT_WATCHDOG)
    p.add_argument("--period", metavar="S", type=_cli.nonneg_seconds_arg,
                   help="time from one cycle start to the next (default 0: back to back; with "
                        "--config: 1 / cycle_rate_hz)")
    p.add_argument("--timeout", metavar="S", type=_cli.seconds_arg, default=DEFAULT_TIMEOUT,
                   help="give up when the slave is not in Data_Exchange after S seconds "
                        "(default %g); also the limit of each cycle" % DEFAULT_TIMEOUT)
    p.add_argument("--reply-timeout", metavar="S", type=_cli.seconds_arg,
                   help="minimum wait for a reply before a retry (software latency floor; default "
                        "%g s, %g s on a pty or a URL)" % (REPLY_FLOOR_SERIAL, REPLY_FLOOR_VIRTUAL))
    p.add_argument("--retries", metavar="N", type=_cli.int_range_arg(0, 7),
                   help="retries after a missing reply, 0..7 (default: from the baud rate)")
    p.add_argument("--config", metavar="FILE",
                   help="bus configuration file (.yaml/.yml/.ini/.conf); explicit options "
                        "override its values")
    p.add_argument("--json", action="store_true",
                   help="print the result (inputs and statistics) as one JSON object")
    p.add_argument("-v", "--verbose", action="count", default=0,
                   help="log the master's state changes (-v) and telegram details (-vv) on stderr")
    return p


# --------------------------------------------------------------------------------------------------
# Settings: options, optionally on top of a configuration file
# --------------------------------------------------------------------------------------------------

@dataclass
class Settings:
    device: str
    baud: int
    master_address: int
    address: int
    ident: int
    cfg: bytes
    input_len: int
    output_len: int
    outputs: bytes
    watchdog: Optional[float]
    period: float
    timeout: float
    reply_floor: float
    retries: Optional[int]
    slot_bits: Optional[int]
    user_prm_data: bytes = b""
    group_ident: int = 0
    sync: bool = False
    freeze: bool = False
    cycles: int = 1


def _from_config(path: str, args: argparse.Namespace) -> Dict[str, Any]:
    """The defaults that a configuration file provides (ConfigError -> usage error)."""
    from .config import load_config
    try:
        bus = load_config(path)
    except ConfigError as exc:
        raise UsageError(str(exc)) from None
    slave = bus.slaves[0]
    if args.addr is not None:
        slave = next((s for s in bus.slaves if s.address == args.addr), slave)
    out: Dict[str, Any] = {
        "baud": bus.baud, "master_address": bus.master_address, "address": slave.address,
        "ident": slave.ident, "cfg": slave.cfg,
        "watchdog": None if not slave.watchdog_ms else slave.watchdog_ms / 1000.0,
        "period": 1.0 / bus.cycle_rate_hz, "retries": bus.retry_limit,
        "slot_bits": bus.slot_time, "user_prm_data": slave.user_prm_data,
        "group_ident": slave.group_mask, "sync": slave.sync, "freeze": slave.freeze,
    }
    if bus.phy.type == "serial":
        out["device"] = bus.phy.device
    elif args.device is None:
        raise UsageError("%s: phy.type is %r; this tool needs a serial device: give --device"
                         % (path, bus.phy.type))
    return out


def resolve_settings(args: argparse.Namespace) -> Settings:
    """Merge options over the configuration file and check everything; UsageError on a problem."""
    from .dp import cfg_io_lengths, watchdog_factors
    base: Dict[str, Any] = _from_config(args.config, args) if args.config else {}

    def pick(option: Any, key: str, default: Any = None) -> Any:
        return option if option is not None else base.get(key, default)

    missing = [flag for flag, key, value in (("--device", "device", args.device),
                                             ("--addr", "address", args.addr),
                                             ("--ident", "ident", args.ident),
                                             ("--cfg", "cfg", args.cfg))
               if value is None and key not in base]
    if missing:
        raise UsageError("missing %s (or give --config FILE)" % ", ".join(missing))
    address = pick(args.addr, "address")
    master_address = pick(args.master_addr, "master_address", DEFAULT_MASTER_ADDRESS)
    if master_address == address:
        raise UsageError("--master-addr %d is the slave's address; the two must differ" % address)
    cfg = pick(args.cfg, "cfg")
    input_len, output_len = cfg_io_lengths(cfg)
    outputs = args.out if args.out is not None else bytes(output_len)
    if len(outputs) != output_len:
        raise UsageError("--out has %d bytes, but the Cfg %s declares %d output bytes "
                         "(master -> slave)" % (len(outputs), hexstr(cfg), output_len))
    period = pick(args.period, "period", 0.0)
    if args.watchdog is not None:
        watchdog: Optional[float] = args.watchdog or None
    elif "watchdog" in base:
        watchdog = base["watchdog"]
    else:
        watchdog = max(DEFAULT_WATCHDOG, 3 * period)
    if watchdog is not None:
        try:
            watchdog_factors(watchdog)
        except ConfigError as exc:
            raise UsageError("--watchdog: %s" % exc) from None
        if watchdog <= period:
            raise UsageError("the watchdog (%g s) must be longer than --period (%g s), or the "
                             "slave drops its outputs between cycles" % (watchdog, period))
    device = pick(args.device, "device")
    virtual = "://" in device or _is_pty(device)
    floor = args.reply_timeout or (REPLY_FLOOR_VIRTUAL if virtual else REPLY_FLOOR_SERIAL)
    return Settings(
        device=device, baud=pick(args.baud, "baud", DEFAULT_BAUD), master_address=master_address,
        address=address, ident=pick(args.ident, "ident"), cfg=cfg, input_len=input_len,
        output_len=output_len, outputs=outputs, watchdog=watchdog, period=period,
        timeout=args.timeout, reply_floor=floor, retries=pick(args.retries, "retries"),
        slot_bits=base.get("slot_bits"), user_prm_data=base.get("user_prm_data", b""),
        group_ident=base.get("group_ident", 0), sync=base.get("sync", False),
        freeze=base.get("freeze", False), cycles=args.cycles)


def _is_pty(path: str) -> bool:
    from .phy_serial import is_pty
    return is_pty(path)


# --------------------------------------------------------------------------------------------------
# The run
# --------------------------------------------------------------------------------------------------

class _Run:
    """One master run: connect, exchange, report."""

    def __init__(self, settings: Settings, as_json: bool) -> None:
        from .dp_master import BusTiming, DpMaster, SlaveSpec
        self.s = settings
        self.as_json = as_json
        self.spec = SlaveSpec(settings.address, settings.ident, settings.cfg,
                              watchdog=settings.watchdog, user_prm_data=settings.user_prm_data,
                              group_ident=settings.group_ident, sync_req=settings.sync,
                              freeze_req=settings.freeze)
        timing = BusTiming.for_baud(settings.baud, settings.retries)
        if settings.slot_bits is not None:
            timing = BusTiming(timing.baud, settings.slot_bits, timing.max_tsdr_bits,
                               timing.max_retry)
        self.link = _cli.open_serial(settings.device, settings.baud)
        self.master = DpMaster(self.link, settings.master_address, settings.baud, timing=timing,
                               reply_timeout_floor=settings.reply_floor,
                               on_state_change=self._on_state_change)
        self.handle = self.master.add_slave(self.spec)
        self.handle.outputs = settings.outputs
        self.connected_once = False
        self.failures: List[str] = []          # reasons the slave fell back (before connecting)
        self.run_events: List[str] = []        # reasons it left Data_Exchange (after connecting)
        self.ok = 0
        self.failed = 0
        self.connect_time: Optional[float] = None
        self.exchange_time = 0.0
        self.cycle_times: List[float] = []

    def say(self, text: str) -> None:
        if not self.as_json:
            print(text)

    def _on_state_change(self, slave: Any, old: Any, new: Any, reason: str) -> None:
        from .dp_master import MasterSlaveState
        if new is MasterSlaveState.BACKOFF:
            (self.run_events if self.connected_once else self.failures).append(reason)
            if self.connected_once:
                _cli.warning("slave %d left Data_Exchange: %s" % (slave.address, reason))

    # -- connect ------------------------------------------------------------------------------
    def connect(self) -> None:
        start = time.monotonic()
        deadline = start + self.s.timeout
        while not self.handle.connected:
            left = deadline - time.monotonic()
            if left <= 0:
                raise OperationFailed(self.explain_no_connection())
            self.master.cycle(timeout=left)
        self.connected_once = True
        self.connect_time = time.monotonic() - start
        diag = self.handle.last_diag
        self.say("connected: slave %d in Data_Exchange after %.3f s%s"
                 % (self.s.address, self.connect_time,
                    "" if diag is None else " (diag %s)" % hexstr(diag.encode())))

    def explain_no_connection(self) -> str:
        """Why the slave did not come up, in words, from its diag or the missing replies."""
        from .dp import DiagStatus1, explain_diag
        s = self.s
        diag = self.handle.last_diag
        head = "slave %d did not reach Data_Exchange within %g s" % (s.address, s.timeout)
        last = self.failures[-1] if self.failures else None
        if diag is None:
            if not self.failures or all(r.startswith("no reply to FDL_Status") for r in self.failures):
                return ("%s: no answer from station %d on %s at %d baud (no reply to FDL_Status; "
                        "check the address, the baud rate, wiring and termination)"
                        % (head, s.address, s.device, s.baud))
            return "%s: %s" % (head, last)
        words = "slave diag: " + explain_diag(diag, s.master_address)
        if diag.ident != s.ident:
            return ("%s: wrong ident: the slave reports ident 0x%04X, the master was given "
                    "0x%04X (Set_Prm is refused with Prm_Fault)\n  %s"
                    % (head, diag.ident, s.ident, words))
        if diag.status1 & DiagStatus1.CFG_FAULT:
            actual = self.probe_get_cfg()
            hint = "" if actual is None else "; Get_Cfg says the slave uses %s" % hexstr(actual)
            return ("%s: configuration fault (Cfg_Fault): the slave rejects Chk_Cfg %s%s\n  %s"
                    % (head, hexstr(s.cfg), hint, words))
        if diag.status1 & DiagStatus1.PRM_FAULT:
            return ("%s: parameter fault (Prm_Fault): the slave rejects Set_Prm %s\n  %s"
                    % (head, hexstr(self.spec.set_prm().encode()), words))
        if diag.locked_by not in (None, s.master_address):
            return "%s: locked by another master (%d)\n  %s" % (head, diag.master_address, words)
        if diag.status1 & DiagStatus1.NOT_SUPPORTED:
            return "%s: the slave does not support a requested function\n  %s" % (head, words)
        return "%s: %s\n  %s" % (head, last or "not ready", words)

    def probe_get_cfg(self, wait: float = 0.3) -> Optional[bytes]:
        """Ask the slave for the Cfg bytes it uses (Get_Cfg, best effort)."""
        from .dp import Sap, request_frame
        from .fdl import Deframer, Sd2, Sd3
        frame = request_frame(self.s.address, self.s.master_address, True, False, Sap.GET_CFG)
        deframer = Deframer()
        try:
            self.link.flush_input()
            self.link.send(frame.encode())
            end = time.monotonic() + max(wait, self.s.reply_floor)
            while True:
                left = end - time.monotonic()
                if left <= 0:
                    return None
                for reply in deframer.feed(self.link.recv(4096, left)):
                    if (isinstance(reply, (Sd2, Sd3)) and not reply.fc.request
                            and reply.sa == self.s.address and reply.ssap == Sap.GET_CFG):
                        return reply.data
        except PhyError:
            return None

    # -- exchange -----------------------------------------------------------------------------
    def exchange(self) -> None:
        from .dp_master import MasterSlaveState
        h = self.handle
        shown: Optional[bytes] = None
        start = time.monotonic()
        next_start = start
        try:
            while self.ok + self.failed < self.s.cycles:
                before = h.counters.data_exchanges
                was = h.state
                t0 = time.monotonic()
                done = self.master.cycle(timeout=self.s.timeout)
                t1 = time.monotonic()
                if h.counters.data_exchanges > before:
                    self.ok += 1
                    self.cycle_times.append(t1 - t0)
                    if h.inputs != shown:
                        shown = h.inputs
                        self.say("cycle %d: inputs %s" % (self.ok + self.failed,
                                                          hexstr(shown or b"") or "(none)"))
                elif done and was is MasterSlaveState.DX_DIAG and h.connected:
                    continue  # a diag fetch after a DH reply: not a Data_Exchange cycle
                else:
                    self.failed += 1
                if self.s.period:
                    next_start += self.s.period
                    pause = next_start - time.monotonic()
                    if pause > 0:
                        time.sleep(pause)
                    else:
                        next_start = time.monotonic()
        finally:
            self.exchange_time = time.monotonic() - start

    # -- report -------------------------------------------------------------------------------
    def statistics(self) -> Dict[str, Any]:
        c = self.master.counters
        times = self.cycle_times
        return {
            "cycles_ok": self.ok,
            "cycles_failed": self.failed,
            "cycles_wanted": self.s.cycles,
            "requests": c.requests,
            "retries": c.retries,
            "timeouts": c.timeouts,
            "fcs_errors": c.fcs_errors,
            "garbage_bytes": c.garbage_bytes,
            "invalid_replies": c.invalid_replies,
            "unexpected_frames": c.unexpected_frames,
            "losses": c.losses,
            "reconnects": c.reconnects,
            "diag_reads": self.handle.counters.diag_reads,
            "connect_time_s": None if self.connect_time is None else round(self.connect_time, 6),
            "exchange_time_s": round(self.exchange_time, 6),
            "cycles_per_s": (round(self.ok / self.exchange_time, 2)
                             if self.exchange_time > 0 and self.ok else 0.0),
            "cycle_ms_avg": round(1000 * sum(times) / len(times), 3) if times else None,
            "cycle_ms_max": round(1000 * max(times), 3) if times else None,
        }

    def report(self) -> None:
        stats = self.statistics()
        inputs = self.handle.inputs
        if self.as_json:
            result = {"device": self.s.device, "baud": self.s.baud,
                      "master_address": self.s.master_address, "address": self.s.address,
                      "ident": "0x%04X" % self.s.ident, "cfg": hexstr(self.s.cfg),
                      "outputs": hexstr(self.s.outputs),
                      "inputs": None if inputs is None else hexstr(inputs),
                      "connected": self.connected_once,
                      "diag": None if self.handle.last_diag is None
                      else hexstr(self.handle.last_diag.encode()),
                      "statistics": stats}
            print(json.dumps(result, sort_keys=True))
            return
        print("inputs: %s" % ("(none received)" if inputs is None else hexstr(inputs) or "(empty)"))
        print("statistics:")
        rows = [
            ("cycles ok", "%d of %d" % (stats["cycles_ok"], stats["cycles_wanted"])),
            ("cycles failed", stats["cycles_failed"]),
            ("requests", stats["requests"]),
            ("retries", stats["retries"]),
            ("timeouts", stats["timeouts"]),
            ("FCS errors", stats["fcs_errors"]),
            ("garbage bytes", stats["garbage_bytes"]),
            ("invalid replies", stats["invalid_replies"]),
            ("unexpected frames", stats["unexpected_frames"]),
            ("losses", stats["losses"]),
            ("reconnects", stats["reconnects"]),
            ("diag reads", stats["diag_reads"]),
            ("connect time", "-" if stats["connect_time_s"] is None
             else "%.3f s" % stats["connect_time_s"]),
            ("exchange time", "%.3f s" % stats["exchange_time_s"]),
            ("cycles/s", "%.1f" % stats["cycles_per_s"]),
            ("cycle time", "-" if stats["cycle_ms_avg"] is None
             else "avg %.2f ms, max %.2f ms" % (stats["cycle_ms_avg"], stats["cycle_ms_max"])),
        ]
        for name, value in rows:
            print("  %-18s %s" % (name, value))


def _run(args: argparse.Namespace) -> int:
    _cli.line_buffered_stdout()
    _cli.setup_logging(args.verbose)
    settings = resolve_settings(args)
    signal.signal(signal.SIGINT, signal.default_int_handler)   # also when started with SIGINT ignored
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    try:
        run = _Run(settings, args.json)
    except DpError as exc:  # e.g. SlaveSpec rejects a combination: still a usage problem
        raise UsageError(str(exc)) from None
    try:
        s = settings
        run.say("master %d, slave %d on %s at %d baud: ident 0x%04X, Chk_Cfg %s (%d in, %d out), "
                "watchdog %s, outputs %s" % (s.master_address, s.address, s.device, s.baud, s.ident,
                                             hexstr(s.cfg), s.input_len, s.output_len,
                                             "off" if s.watchdog is None else "%g s" % s.watchdog,
                                             hexstr(s.outputs) or "(none)"))
        try:
            run.connect()
        except KeyboardInterrupt:
            raise OperationFailed("interrupted before slave %d reached Data_Exchange"
                                  % s.address) from None
        interrupted = False
        try:
            run.exchange()
        except KeyboardInterrupt:
            interrupted = True
        except PhyError as exc:
            run.report()
            raise DeviceError("device failed after %d of %d cycles: %s"
                              % (run.ok + run.failed, args.cycles, exc)) from None
        run.report()
        if interrupted:
            raise OperationFailed("interrupted after %d of %d cycles" % (run.ok + run.failed,
                                                                          args.cycles))
        if run.failed:
            first = run.run_events[0] if run.run_events else "no valid Data_Exchange reply"
            raise OperationFailed("%d of %d cycles failed (first problem: %s)"
                                  % (run.failed, args.cycles, first))
        return _cli.EXIT_OK
    except PhyError as exc:
        raise DeviceError(str(exc)) from None
    finally:
        run.master.close()


def main(argv: Optional[List[str]] = None) -> int:
    """CLI entry point; returns the exit status."""
    return _cli.run(build_parser(), _run, argv)


if __name__ == "__main__":
    sys.exit(main())
