"""The one exception tree of pyprofibus_vendor.

    ProfibusError
    ├── PhyError                 the byte link failed (port missing, closed, I/O error)
    │   └── PhyTimeoutError      (also a TimeoutError)
    ├── FdlError                 FDL layer problems
    │   ├── FrameError           a malformed telegram (bad SD, LE/LEr, FCS, ED, address, SAP...)
    │   │   ├── FcsError         the frame check sequence does not match
    │   │   └── TruncatedFrameError  the bytes end before the frame does
    │   └── FdlTimeoutError      no reply within the slot time after all retries (also a TimeoutError)
    ├── DpError                  DP service / state machine problems (wrong ident, Cfg rejected...)
    │   └── DpTimeoutError       (also a TimeoutError)
    └── ConfigError              a wrong configuration value (also a ValueError)
        └── GsdError             a GSD file that cannot be parsed or is inconsistent

Foreign exceptions (pyserial, OSError, termios) are converted at the boundary with ``raise ... from``.
Modules may add subclasses below these; callers catch ``ProfibusError`` or one of its direct children.
"""
from __future__ import annotations

__all__ = [
    "ProfibusError",
    "PhyError",
    "PhyTimeoutError",
    "FdlError",
    "FrameError",
    "FcsError",
    "TruncatedFrameError",
    "FdlTimeoutError",
    "DpError",
    "DpTimeoutError",
    "ConfigError",
    "GsdError",
]


class ProfibusError(Exception):
    """Base class of every error raised by pyprofibus_vendor."""


class PhyError(ProfibusError):
    """The physical byte link failed."""


class PhyTimeoutError(PhyError, TimeoutError):
    """The physical link did not deliver in time."""


class FdlError(ProfibusError):
    """An FDL (layer 2) error."""


class FrameError(FdlError):
    """A telegram is malformed; the message says which check failed."""


class FcsError(FrameError):
    """The frame check sequence (sum mod 256) does not match the frame."""


class TruncatedFrameError(FrameError):
    """The byte string ends before the frame it starts is complete."""


class FdlTimeoutError(FdlError, TimeoutError):
    """No (valid) reply arrived within the slot time, after every retry."""


class DpError(ProfibusError):
    """A DP (layer 7 / DPV0) service or state machine error."""


class DpTimeoutError(DpError, TimeoutError):
    """A DP state did not complete within its time limit."""


class ConfigError(ProfibusError, ValueError):
    """A configuration value is wrong; the message names the key."""


class GsdError(ConfigError):
    """A GSD file cannot be parsed, or its content is inconsistent."""
