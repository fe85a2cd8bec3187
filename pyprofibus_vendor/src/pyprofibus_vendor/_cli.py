"""Shared command-line plumbing of the commissioning tools (``gsd``, ``master``, ``slave``, ``sniff``,
``scan``).

Every tool is run as ``python3 -m pyprofibus_vendor.<tool>``, has ``--help`` with a description and
an epilog listing its exit status, prints expected errors as one line ``error: <message>`` on
stderr (never a traceback) and uses one exit status scheme:

====  =============================================================================================
0     success
1     the operation failed (the slave did not reach Data_Exchange, a cycle failed, the GSD file is
      wrong, fewer telegrams than ``--count`` were seen, interrupted before the end ...)
2     usage or configuration error (unknown option, bad hex, a value out of range, a wrong output
      length, a bad ``--config`` file); nothing was sent on the bus
3     device error: the device (or sniff's input file) cannot be opened, or failed while in use
====  =============================================================================================

This module imports only :mod:`.errors` at import time (``gsd`` uses it too); the serial PHY is
imported when a device is opened.
"""
from __future__ import annotations

import argparse
import logging
import math
import os
import re
import sys
import textwrap
from typing import TYPE_CHECKING, Callable, Mapping, NoReturn, Optional, Sequence

from .errors import ConfigError, PhyError, ProfibusError

if TYPE_CHECKING:  # pragma: no cover
    from .phy_serial import SerialLink

__all__ = [
    "EXIT_OK", "EXIT_FAILED", "EXIT_USAGE", "EXIT_DEVICE", "EXIT_TEXT",
    "CliError", "UsageError", "DeviceError", "OperationFailed",
    "ToolParser", "make_parser", "exit_status_epilog", "run",
    "parse_int", "parse_hex", "address_arg", "ident_arg", "hex_arg", "cfg_arg", "baud_arg",
    "seconds_arg", "nonneg_seconds_arg", "count_arg", "hexstr", "open_serial", "setup_logging",
    "error", "warning",
]

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_USAGE = 2
EXIT_DEVICE = 3

#: The generic meaning of each exit status; tools refine the wording in their epilog.
EXIT_TEXT: Mapping[int, str] = {
    EXIT_OK: "success",
    EXIT_FAILED: "the operation failed",
    EXIT_USAGE: "usage or configuration error (bad option, bad hex, value out of range); "
                "nothing was sent",
    EXIT_DEVICE: "device error: the device cannot be opened or failed while in use",
}

MIN_BAUD = 9600
MAX_BAUD = 12_000_000
MAX_ADDRESS = 125


# --------------------------------------------------------------------------------------------------
# Errors that end a tool with a given exit status
# --------------------------------------------------------------------------------------------------

class CliError(Exception):
    """An expected error: print ``error: <message>`` and exit with ``code``."""

    code = EXIT_FAILED

    def __init__(self, message: str, code: Optional[int] = None) -> None:
        super().__init__(message)
        self.message = message
        if code is not None:
            self.code = code


class OperationFailed(CliError):
    code = EXIT_FAILED


class UsageError(CliError):
    code = EXIT_USAGE


class DeviceError(CliError):
    code = EXIT_DEVICE


def error(message: str) -> None:
    """Print one ``error:`` line on stderr."""
    print("error: %s" % message, file=sys.stderr, flush=True)


def warning(message: str) -> None:
    """Print one ``warning:`` line on stderr."""
    print("warning: %s" % message, file=sys.stderr, flush=True)


# --------------------------------------------------------------------------------------------------
# Argument parsing
# --------------------------------------------------------------------------------------------------

class ToolParser(argparse.ArgumentParser):
    """An ArgumentParser whose usage errors are one line (``error: ... (see --help)``), exit 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, "error: %s (see --help)\n" % message)


def exit_status_epilog(meanings: Mapping[int, str], examples: Sequence[str] = ()) -> str:
    """The epilog text: optional examples, then ``Exit status:`` with one line per code."""
    lines = []
    if examples:
        lines.append("Examples:")
        lines += ["  " + e for e in examples]
        lines.append("")
    lines.append("Exit status:")
    lines += [textwrap.fill(meanings[code], 92, initial_indent="  %d  " % code,
                            subsequent_indent="     ") for code in sorted(meanings)]
    return "\n".join(lines)


def make_parser(tool: str, description: str, meanings: Mapping[int, str],
                examples: Sequence[str] = ()) -> ToolParser:
    """A :class:`ToolParser` for ``python3 -m pyprofibus_vendor.<tool>``."""
    paragraphs = [textwrap.fill(" ".join(p.split()), 92) for p in description.split("\n\n")]
    return ToolParser(prog="python3 -m pyprofibus_vendor.%s" % tool,
                      description="\n\n".join(paragraphs),
                      epilog=exit_status_epilog(meanings, examples),
                      formatter_class=argparse.RawDescriptionHelpFormatter)


def run(parser: argparse.ArgumentParser, body: Callable[[argparse.Namespace], int],
        argv: Optional[Sequence[str]] = None) -> int:
    """Parse ``argv`` and run ``body(args)``; map expected errors to one line and an exit status.

    ``--help`` returns 0 and usage errors 2 (argparse's SystemExit is caught, so ``main()`` can be
    called in-process). :class:`CliError` carries its own status; an uncaught
    :class:`~.errors.ConfigError` is a usage/configuration error (2), a
    :class:`~.errors.PhyError` a device error (3), any other :class:`~.errors.ProfibusError` a
    failed operation (1). A closed stdout (``| head``) ends the tool quietly.
    """
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return exc.code if isinstance(exc.code, int) else EXIT_USAGE
    try:
        return body(args)
    except CliError as exc:
        error(exc.message)
        return exc.code
    except ConfigError as exc:
        error(str(exc))
        return EXIT_USAGE
    except PhyError as exc:
        error(str(exc))
        return EXIT_DEVICE
    except ProfibusError as exc:
        error(str(exc))
        return EXIT_FAILED
    except KeyboardInterrupt:
        error("interrupted")
        return EXIT_FAILED
    except BrokenPipeError:
        # the reader went away: silence the final flush of stdout and stop
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
        except (OSError, ValueError):
            pass
        return EXIT_OK


def line_buffered_stdout() -> None:
    """Make stdout line buffered, so a reader (pipe, test) sees every line at once."""
    reconfigure = getattr(sys.stdout, "reconfigure", None)
    if reconfigure is not None:
        try:
            reconfigure(line_buffering=True)
        except (ValueError, OSError):  # pragma: no cover - exotic streams
            pass


def setup_logging(verbosity: int) -> None:
    """Library log messages on stderr: none by default (the tools print their own lines),
    INFO with ``-v``, DEBUG with ``-vv``."""
    level = {0: logging.CRITICAL + 1, 1: logging.INFO}.get(verbosity, logging.DEBUG)
    logging.basicConfig(level=level, stream=sys.stderr,
                        format="%(levelname)s %(name)s: %(message)s")
    logging.getLogger().setLevel(level)


# --------------------------------------------------------------------------------------------------
# Value parsers (usable as argparse ``type=``; they raise ArgumentTypeError with a clear message)
# --------------------------------------------------------------------------------------------------

_INT_RE = re.compile(r"\A(?:0[xX][0-9A-Fa-f]+|[0-9]+)\Z")
_SIGNED_INT_RE = re.compile(r"\A-?(?:0[xX][0-9A-Fa-f]+|[0-9]+)\Z")
_HEX_SPLIT_RE = re.compile(r"[\s,:;]+")
_HEX_TOKEN_RE = re.compile(r"\A(?:0[xX])?([0-9A-Fa-f]*)\Z")


def int_or_none(text: str, signed: bool = False) -> Optional[int]:
    """A decimal or ``0x`` hexadecimal integer (ASCII digits only; ``-`` first with ``signed``),
    or None when ``text`` is not one. The package's one reader of integers in text (command line,
    GSD files, INI configurations)."""
    text = text.strip()
    if not (_SIGNED_INT_RE if signed else _INT_RE).match(text):
        return None
    negative = text.startswith("-")
    body = text[1:] if negative else text
    value = int(body, 16) if body[:2] in ("0x", "0X") else int(body, 10)
    return -value if negative else value


def parse_int(text: str) -> int:
    """A decimal or ``0x`` hexadecimal integer; ArgumentTypeError otherwise."""
    value = int_or_none(text)
    if value is None:
        raise argparse.ArgumentTypeError("%r is not a number (decimal or 0x hex)" % text.strip())
    return value


def parse_hex(text: str) -> bytes:
    """Hex bytes: ``"01 02 ff"``, ``"0102FF"``, ``"0x01,0x02"``, ``"01:02"``; ValueError otherwise."""
    out = bytearray()
    for token in _HEX_SPLIT_RE.split(text.strip()):
        if not token:
            continue
        match = _HEX_TOKEN_RE.match(token)
        if not match or not match.group(1):
            raise ValueError("%r is not hex" % token)
        digits = match.group(1)
        if len(digits) % 2:
            raise ValueError("%r has an odd number of hex digits" % token)
        out += bytes.fromhex(digits)
    return bytes(out)


def hex_arg(text: str) -> bytes:
    """argparse type: hex bytes (may be empty)."""
    try:
        return parse_hex(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError("%s (write bytes like \"01 02 FF\" or \"0102FF\")"
                                         % exc) from None


def cfg_arg(text: str) -> bytes:
    """argparse type: Chk_Cfg identifier bytes (1..244 hex bytes, decodable)."""
    from .dp import MAX_USER_DATA, decode_cfg
    from .errors import DpError
    data = hex_arg(text)
    if not 1 <= len(data) <= MAX_USER_DATA:
        raise argparse.ArgumentTypeError("%d Cfg bytes, expected 1..%d" % (len(data), MAX_USER_DATA))
    try:
        decode_cfg(data)
    except DpError as exc:
        raise argparse.ArgumentTypeError("bad Cfg bytes %s: %s" % (hexstr(data), exc)) from None
    return data


def address_arg(text: str) -> int:
    """argparse type: a station address 0..125."""
    value = parse_int(text)
    if not 0 <= value <= MAX_ADDRESS:
        raise argparse.ArgumentTypeError("address %d is outside 0..%d" % (value, MAX_ADDRESS))
    return value


def ident_arg(text: str) -> int:
    """argparse type: an ident number 0..0xFFFF."""
    value = parse_int(text)
    if not 0 <= value <= 0xFFFF:
        raise argparse.ArgumentTypeError("ident 0x%X is outside 0x0000..0xFFFF" % value)
    return value


def baud_arg(text: str) -> int:
    """argparse type: a bit rate 9600..12000000."""
    value = parse_int(text)
    if not MIN_BAUD <= value <= MAX_BAUD:
        raise argparse.ArgumentTypeError("baud %d is outside %d..%d" % (value, MIN_BAUD, MAX_BAUD))
    return value


def _float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError("%r is not a number of seconds" % text) from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError("%r is not a finite number of seconds" % text)
    return value


def seconds_arg(text: str) -> float:
    """argparse type: seconds > 0."""
    value = _float(text)
    if value <= 0:
        raise argparse.ArgumentTypeError("%s s must be greater than 0" % text)
    return value


def nonneg_seconds_arg(text: str) -> float:
    """argparse type: seconds >= 0."""
    value = _float(text)
    if value < 0:
        raise argparse.ArgumentTypeError("%s s must not be negative" % text)
    return value


def count_arg(text: str) -> int:
    """argparse type: an integer >= 1."""
    value = parse_int(text)
    if value < 1:
        raise argparse.ArgumentTypeError("%d must be at least 1" % value)
    return value


def int_range_arg(lo: int, hi: int) -> Callable[[str], int]:
    """argparse type factory: an integer lo..hi."""
    def convert(text: str) -> int:
        value = parse_int(text)
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError("%d is outside %d..%d" % (value, lo, hi))
        return value
    return convert


# --------------------------------------------------------------------------------------------------
# Output and devices
# --------------------------------------------------------------------------------------------------

def hexstr(data: bytes) -> str:
    """``b"\\x01\\xff"`` -> ``"01 FF"``."""
    return " ".join("%02X" % b for b in data)


def check_device_path(device: str) -> None:
    """Raise :class:`DeviceError` (``cannot open DEV: <reason>``) unless ``device`` (a path, not a
    pyserial URL) exists and is readable and writable."""
    if "://" in device:
        return
    try:
        os.stat(device)
    except OSError as exc:
        raise DeviceError("cannot open %s: %s" % (device, exc.strerror or exc)) from None
    if os.path.isdir(device):
        raise DeviceError("cannot open %s: Is a directory" % device)
    if not os.access(device, os.R_OK | os.W_OK):
        raise DeviceError("cannot open %s: Permission denied (is the user in the dialout group?)"
                          % device)


def open_serial(device: str, baud: int) -> "SerialLink":
    """Open ``device`` (a path or a pyserial URL such as ``socket://host:port``) with 8E1 at
    ``baud``; :class:`DeviceError` with a one-line reason when that fails."""
    from .phy_serial import SerialLink
    check_device_path(device)
    try:
        return SerialLink(device, baud)
    except PhyError as exc:
        raise DeviceError(str(exc)) from None
