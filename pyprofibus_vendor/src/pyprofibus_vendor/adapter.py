"""The USB-RS-485 adapter under a serial port: its low-latency mode and latency timer (Linux).

A USB serial adapter does not hand received bytes to the PC as they arrive: the FTDI chips hold
them until their *latency timer* expires (16 ms by default) or a USB packet fills, and the kernel's
tty layer may defer them once more unless the port is in *low-latency mode*. On a 19.2 kbit/s
PROFIBUS line, where a Data_Exchange reply takes 15-20 ms on the wire, that wait is as long again
per request: the master's cycle rate drops without any error.

:func:`tune_port` is called by :class:`~pyprofibus_vendor.phy_serial.SerialLink` after it opened a
device (not a URL): it sets ``ASYNC_LOW_LATENCY`` with the TIOCGSERIAL / TIOCSSERIAL ioctls (what
``setserial DEV low_latency`` does) and reads the FTDI latency timer from sysfs
(``/sys/bus/usb-serial/devices/ttyUSBn/latency_timer``); where that file is writable (root, or a
udev rule that made it so) a timer above 1 ms is set to 1 ms. It never fails: what it could not do
is said in :attr:`AdapterSetup.notes` (a pty, for one, is no serial driver -- fine for the virtual
line). See vr_driver/doc/adapters.md.
"""
from __future__ import annotations

import errno
import fcntl
import os
from dataclasses import dataclass
from typing import Optional, Tuple

__all__ = ["AdapterSetup", "tune_port", "latency_timer_path", "ASYNC_LOW_LATENCY"]

TIOCGSERIAL = 0x541E
TIOCSSERIAL = 0x541F
ASYNC_LOW_LATENCY = 1 << 13
_FLAGS_OFFSET = 16                 # struct serial_struct: int type, line; unsigned port; int irq, flags
_SERIAL_STRUCT_BYTES = 128         # larger than the kernel's struct serial_struct on any arch
_SYSFS = "/sys/bus/usb-serial/devices"


@dataclass(frozen=True)
class AdapterSetup:
    """What :func:`tune_port` found and did on one device."""

    device: str
    low_latency: Optional[bool]           # True: on (set or already); False: could not; None: not tried
    latency_timer_ms: Optional[int]       # the FTDI latency timer now (None: the device has none)
    latency_timer_was: Optional[int]      # before this call set it (None: not changed)
    notes: Tuple[str, ...] = ()           # in words, one per finding

    def describe(self) -> str:
        return "; ".join(self.notes)


def latency_timer_path(device: str, sysfs: str = _SYSFS) -> Optional[str]:
    """The sysfs latency_timer file of ``device`` (a path or a symlink such as
    /dev/serial/by-id/...), or None when the device has none (not an FTDI-style USB adapter)."""
    name = os.path.basename(os.path.realpath(device))
    path = os.path.join(sysfs, name, "latency_timer")
    return path if os.path.exists(path) else None


def _set_low_latency(fd: int) -> Tuple[bool, str]:
    """Set ASYNC_LOW_LATENCY on ``fd``: (done, words)."""
    buf = bytearray(_SERIAL_STRUCT_BYTES)
    try:
        fcntl.ioctl(fd, TIOCGSERIAL, buf, True)
    except OSError as exc:
        if exc.errno in (errno.ENOTTY, errno.EINVAL):
            return False, "not a serial driver"
        return False, os.strerror(exc.errno or 0) or str(exc)
    flags = int.from_bytes(buf[_FLAGS_OFFSET:_FLAGS_OFFSET + 4], "little", signed=True)
    if flags & ASYNC_LOW_LATENCY:
        return True, "low-latency mode already on"
    buf[_FLAGS_OFFSET:_FLAGS_OFFSET + 4] = (flags | ASYNC_LOW_LATENCY).to_bytes(4, "little", signed=True)
    try:
        fcntl.ioctl(fd, TIOCSSERIAL, buf, True)
    except OSError as exc:
        return False, os.strerror(exc.errno or 0) or str(exc)
    return True, "low-latency mode set"


def tune_port(device: str, fd: int, is_pty: bool = False, sysfs: str = _SYSFS) -> AdapterSetup:
    """Low-latency mode on ``fd`` (the open ``device``) and its latency timer at 1 ms where the
    system allows; see the module docstring. Never raises."""
    notes = []
    done, words = _set_low_latency(fd)
    if done:
        notes.append("%s: %s" % (device, words))
    elif is_pty:
        notes.append("cannot set low-latency on %s: %s; fine for the virtual line" % (
            os.path.realpath(device), words))
    else:
        notes.append("cannot set low-latency on %s: %s (setserial %s low_latency, as root, does it; "
                     "see doc/adapters.md)" % (device, words, device))
    timer: Optional[int] = None
    was: Optional[int] = None
    path = latency_timer_path(device, sysfs)
    if path is not None:
        try:
            with open(path) as f:
                timer = int(f.read().strip())
        except (OSError, ValueError) as exc:
            notes.append("cannot read %s: %s" % (path, exc))
        if timer is not None and timer > 1:
            try:
                with open(path, "w") as f:
                    f.write("1")
                was, timer = timer, 1
                notes.append("%s: latency timer set from %d ms to 1 ms (%s)" % (device, was, path))
            except OSError as exc:
                notes.append("%s: the adapter's latency timer is %d ms and cannot be set here (%s): each "
                             "reply may wait up to that long in the adapter; set it to 1 ms with a udev "
                             "rule (doc/adapters.md)" % (device, timer, exc.strerror or exc))
        elif timer is not None:
            notes.append("%s: latency timer %d ms" % (device, timer))
    return AdapterSetup(device, done if not is_pty else False, timer, was, tuple(notes))
