"""``rosrun vr_driver scan``: the first contact with a G2 nobody has described (doc/scan.md). ROS-free:
it needs no roscore, only the serial port -- the driver node must not be running.

The generic part is pyprofibus_vendor's live list (:mod:`pyprofibus_vendor.scan`: the bit rate, every
station that answers, its ident number, owner and configuration, the GSD file, the adapter's echo
and reply latency). What this module adds is what concerns the G2 (:func:`g2_findings`):

- which station is the G2's card (ident 0x06C6, PAN06C6.gsd);
- which protocol of this driver its modules fit (:func:`protocol_fit`: the card's Get_Cfg against
  each protocol's Chk_Cfg, v1 the thesis' 14-byte configuration; a card with the right lengths but
  other modules is named as such: the driver's Chk_Cfg would meet Cfg_Fault);
- who owns it (a master that parameterised it must be stopped first), the other stations (I/O
  stations for a bus_config, doc/io_line.md);
- the exact command lines to run next (:func:`next_commands`): ``commission`` (protocol v3 only) and
  ``driver.launch`` with the port, the rate, the card's address and the protocol found.

Exit status: 0 a G2 card was found, 1 none (or no station at all), 2 bad arguments (nothing sent),
3 the port cannot be opened or is open by another process.
"""
from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Sequence, Tuple

from pyprofibus_vendor import _cli
from pyprofibus_vendor import scan as generic
from pyprofibus_vendor.config import ROBOT_IDENT, default_robot_config
from pyprofibus_vendor.dp import cfg_io_lengths
from pyprofibus_vendor.errors import DpError

from ..params import DEFAULT_PORT
from ..protocol import registry as protocols

__all__ = ["ProtocolFit", "G2Findings", "protocol_fit", "g2_findings", "next_commands", "build_parser", "main"]

#: the driver's own station address by default (the built-in bus config's master_address)
DRIVER_MASTER_ADDRESS = default_robot_config("virtual", phy_type="memory").master_address
#: the protocol commission measures (doc/commissioning.md): the G2 program and card of protocol v3
COMMISSION_PROTOCOL = "v3"


def protocol_cfg(name: str) -> bytes:
    """The Chk_Cfg the driver sends for protocol ``name`` (v1: the built-in bus config's)."""
    wire = protocols.get(name)
    return wire.chk_cfg or default_robot_config("virtual", phy_type="memory").slaves[0].cfg


@dataclass(frozen=True)
class ProtocolFit:
    """How a card's configuration fits this driver's protocols: ``protocol`` the one whose Chk_Cfg it
    equals (None: none); ``same_lengths`` the protocols whose record lengths it has with other
    modules (the driver's Chk_Cfg would be refused: Cfg_Fault)."""

    cfg: bytes
    protocol: Optional[str]
    same_lengths: Tuple[str, ...] = ()


def protocol_fit(cfg: bytes) -> ProtocolFit:
    """See :class:`ProtocolFit`."""
    exact = next((n for n in protocols.names() if protocol_cfg(n) == cfg), None)
    if exact is not None:
        return ProtocolFit(cfg, exact)
    try:
        lengths = cfg_io_lengths(cfg)
    except DpError:
        return ProtocolFit(cfg, None)
    same = tuple(n for n in protocols.names()
                 if (protocols.get(n).input_length, protocols.get(n).output_length) == lengths)
    return ProtocolFit(cfg, None, same)


@dataclass
class G2Findings:
    """What the scan says about the G2 (see the module docstring)."""

    device: str
    rate: Optional[int]
    g2: List[generic.StationFound] = field(default_factory=list)
    fits: Dict[int, ProtocolFit] = field(default_factory=dict)
    others: List[generic.StationFound] = field(default_factory=list)
    other_masters: Dict[int, str] = field(default_factory=dict)

    def to_dict(self) -> Dict[str, Any]:
        return {"g2": [{"address": s.address, "protocol": self.fits[s.address].protocol if s.address in self.fits
                        else None, "owner": s.owner} for s in self.g2],
                "others": [s.address for s in self.others], "commands": next_commands(self)}


def g2_findings(result: generic.ScanResult) -> G2Findings:
    found = G2Findings(result.device, result.rate, other_masters=result.other_masters)
    for st in result.stations:
        if st.passive and st.ident == ROBOT_IDENT:
            found.g2.append(st)
            if st.cfg is not None:
                found.fits[st.address] = protocol_fit(st.cfg)
        else:
            found.others.append(st)
    return found


def next_commands(found: G2Findings) -> List[str]:
    """The command lines to run next: for the first G2 card whose protocol is known, ``commission``
    (v3) and the driver's launch; nothing when there is no G2 or its protocol is none of ours."""
    if found.rate is None or found.other_masters:
        return []
    for st in found.g2:
        fit = found.fits.get(st.address)
        if fit is None or fit.protocol is None:
            continue
        where = "port:=%s baud:=%d slave_address:=%d" % (found.device, found.rate, st.address)
        if fit.protocol == COMMISSION_PROTOCOL:
            return ["rosrun vr_driver commission --port %s --baud %d --slave-address %d"
                    % (found.device, found.rate, st.address),
                    "roslaunch vr_driver driver.launch sim:=false %s commissioning:=commissioning.yaml" % where]
        return ["roslaunch vr_driver driver.launch sim:=false %s protocol:=%s" % (where, fit.protocol)]
    return []


def format_findings(found: G2Findings) -> List[str]:
    lines: List[str] = []
    v3 = protocol_cfg(COMMISSION_PROTOCOL)
    if found.other_masters:
        lines.append("the driver needs the line alone: stop master %s first (the scan sent nothing while it "
                     "held the token)" % ", ".join(str(a) for a in sorted(found.other_masters)))
    if not found.g2:
        if found.rate is not None and not found.other_masters:
            lines.append("no station has the G2 card's ident 0x%04X (PAN06C6.gsd): is the card's station on this "
                         "line, powered, and its ident the thesis' one?" % ROBOT_IDENT)
    for st in found.g2:
        fit = found.fits.get(st.address)
        head = "the G2 card: station %d (ident 0x%04X, PAN06C6.gsd)" % (st.address, ROBOT_IDENT)
        if fit is None:
            lines.append(head + ": its configuration could not be read (Get_Cfg)")
        elif fit.protocol is not None:
            lines.append(head + ": its modules fit protocol %s (Chk_Cfg %s)" % (fit.protocol, _cli.hexstr(fit.cfg)))
            if fit.protocol != COMMISSION_PROTOCOL:
                lines.append("  commission measures protocol %s only: configure the card's modules as Chk_Cfg %s "
                             "and load the v3 program (doc/controller_program.md section 10.8) to commission it"
                             % (COMMISSION_PROTOCOL, _cli.hexstr(v3)))
        elif fit.same_lengths:
            lines.append(head + ": its modules (Chk_Cfg %s) have the record lengths of protocol %s but other "
                         "modules: the driver's Chk_Cfg would be refused (Cfg_Fault); configure them as %s"
                         % (_cli.hexstr(fit.cfg), "/".join(fit.same_lengths), " or ".join(
                             "%s %s" % (n, _cli.hexstr(protocol_cfg(n))) for n in fit.same_lengths)))
        else:
            lines.append(head + ": its modules (Chk_Cfg %s) fit none of this driver's protocols (%s); "
                         "configure them as protocol v3's, Chk_Cfg %s" % (
                             _cli.hexstr(fit.cfg), ", ".join(protocols.names()), _cli.hexstr(v3)))
        if st.address == DRIVER_MASTER_ADDRESS:
            lines.append("  the driver's own address is %d too (master_address): give the driver another one, "
                         "master_address: 1 in a copy of config/vr_driver.yaml (driver.launch config:=FILE), and "
                         "commission a --bus-config file with master_address: 1" % DRIVER_MASTER_ADDRESS)
        if st.owner is not None:
            lines.append("  it is parameterised by master %d: stop that master (a running driver?) before "
                         "the driver or commission take the line" % st.owner)
    for st in found.others:
        if st.passive:
            what = st.gsd.name if st.gsd is not None else (
                "ident 0x%04X, no GSD file given for it" % st.ident if st.ident is not None else "ident unknown")
            lines.append("station %d (%s): not the G2; an I/O station joins the driver's line through a bus_config "
                         "and a signal map (doc/io_line.md)" % (st.address, what))
        else:
            lines.append("station %d: a master; the driver needs the line alone" % st.address)
    if len(found.g2) > 1:
        lines.append("%d G2 cards on this line: one driver per card (doc/multi_robot.md); the commands below are "
                     "for station %d" % (len(found.g2), found.g2[0].address))
    commands = next_commands(found)
    if commands:
        lines.append("next:")
        lines += ["  " + c for c in commands]
    return lines


# ------------------------------------------------------------------------------------- the command

_DESCRIPTION = """\
rosrun vr_driver scan: find the G2 on a PROFIBUS line nobody has described. Tries the bit rates the
port accepts (19.2 kbit/s first), lists every station that answers (address, station type, ident,
owner, configuration, GSD file), says which is the G2's card and which protocol (v1 / v2 / v3) its
modules fit, whether the adapter echoes and its reply latency, and prints the commission and driver
command lines to run next. Read-only: never Set_Prm, Chk_Cfg or Data_Exchange; nothing is sent when
another master holds the token. Needs no roscore; stop the driver first (doc/scan.md)."""

_EXIT = {
    _cli.EXIT_OK: "a G2 card was found",
    _cli.EXIT_FAILED: "no G2 card (no station, another master's line, or none with ident 0x06C6), or interrupted",
    _cli.EXIT_USAGE: "usage error (bad option, address or rate); nothing was sent",
    _cli.EXIT_DEVICE: "the port cannot be opened, failed, or is open by another process",
}


def build_parser() -> argparse.ArgumentParser:
    p = _cli.ToolParser(prog="scan", description=_DESCRIPTION,
                        epilog=_cli.exit_status_epilog(_EXIT, [
                            "rosrun vr_driver scan", "rosrun vr_driver scan --device /dev/ttyUSB1 --all-rates",
                            "rosrun vr_driver scan --rates 19200,93750 --addresses 1..20"]),
                        formatter_class=argparse.RawDescriptionHelpFormatter)
    generic.add_scan_arguments(p, device_default=DEFAULT_PORT)
    return p


def _body(args: argparse.Namespace) -> int:
    from .bus import port_users
    _cli.setup_logging(args.verbose)
    _cli.line_buffered_stdout()
    users = port_users(args.device)
    if users:
        raise _cli.DeviceError("%s is open by %s -- stop the driver (and anything else on the port) first: the "
                               "scan needs the port alone" % (args.device, "; ".join(
                                   "pid %d (%s)" % (pid, cmd[:80]) for pid, cmd in users)))
    result = generic.scan_from_args(args)
    found = g2_findings(result)
    if args.json:
        data = result.to_dict()
        data.update(found.to_dict())
        print(json.dumps(data, sort_keys=True))
    else:
        for line in generic.format_result(result) + format_findings(found):
            print(line)
    return _cli.EXIT_OK if found.g2 else _cli.EXIT_FAILED


def main(argv: Optional[Sequence[str]] = None) -> int:
    return _cli.run(build_parser(), _body, argv)


if __name__ == "__main__":
    sys.exit(main())
