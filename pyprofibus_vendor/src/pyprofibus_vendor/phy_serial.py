"""Serial PHY on pyserial, a raw-fd link and a pty pair helper.

:class:`SerialLink` opens ``serial.serial_for_url(url)`` with 8E1 at any baud
from 9600 to 12 M, so plain device paths, ``loop://`` and
``socket://host:port`` all work. Reads never spin: with a file descriptor the
link waits in ``select``; URL handlers without one (``loop://``) use
pyserial's own blocking read with the timeout. On a POSIX tty (device path,
pty) the link reads, writes and flushes the file descriptor itself after
pyserial opened and configured it: pyserial's read/write add a ``select`` per
call, which is most of a PHY's cost per telegram.

Linux pty quirk: the pty driver drops ``PARENB``, and then ``tcsetattr``
fails with EINVAL whenever the same call does not also change the speed --
so re-opening a pty at the speed it already has fails inside pyserial. For a
pty this link first sets a different, unused speed (1200/2400 baud), then
lets pyserial open. If that still fails it falls back to no parity (with a
warning; a pty has no parity anyway). Any other failure is a
:class:`PhyError` naming the device.

After opening a device the link sets its low-latency mode and reads (and where allowed lowers)
a USB adapter's latency timer: :mod:`pyprofibus_vendor.adapter`; :attr:`SerialLink.adapter` says
what it found.

On real UARTs pyserial leaves input parity checking off; with
``check_parity=True`` (default) the link turns on ``INPCK | IGNPAR`` so
characters with a parity error are dropped by the driver and the frame fails
its checks instead of delivering a wrong byte.

:func:`open_pty_pair` creates a raw pty pair for tests and the virtual
controller; :class:`FdLink` serves the master side (a raw fd) of it.
"""
from __future__ import annotations

import errno
import logging
import os
import select
import stat
import termios
import tty
from dataclasses import dataclass
from typing import Optional

import serial

from .adapter import AdapterSetup, tune_port
from .errors import PhyError
from .phy import Link

__all__ = ["SerialLink", "FdLink", "PtyPair", "open_pty_pair", "is_pty"]

log = logging.getLogger(__name__)

_PTY_MAJORS = range(136, 144)   # Unix98 pty slaves (/dev/pts/N)
_WRITE_STALL = 5.0              # s without any progress before a write counts as failed


def is_pty(path: str) -> bool:
    """True if ``path`` is a pseudo-terminal slave device."""
    try:
        real = os.path.realpath(path)
        st = os.stat(real)
    except OSError:
        return False
    if not stat.S_ISCHR(st.st_mode):
        return False
    return real.startswith("/dev/pts/") or os.major(st.st_rdev) in _PTY_MAJORS


def _preset_other_speed(path: str) -> None:
    """Set a pty to a speed different from the one pyserial will set next."""
    fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    try:
        attr = termios.tcgetattr(fd)
        speed = termios.B1200 if attr[4] != termios.B1200 else termios.B2400
        attr[4] = attr[5] = speed
        termios.tcsetattr(fd, termios.TCSANOW, attr)
    finally:
        os.close(fd)


class SerialLink(Link):
    """A byte link over pyserial (device path or pyserial URL), 8E1.

    ``parity`` defaults to even (PROFIBUS). Errors from pyserial/termios/OS are
    converted to :class:`PhyError`.
    """

    def __init__(self, url: str, baud: int = 19200, *, parity: str = serial.PARITY_EVEN,
                 check_parity: bool = True, exclusive: bool = False) -> None:
        if not isinstance(baud, int) or not 9600 <= baud <= 12_000_000:
            raise PhyError(f"{url}: baud {baud!r} outside 9600 .. 12000000")
        self.url = url
        self.baud = baud
        self.parity = parity
        self.check_parity = check_parity
        self.exclusive = exclusive
        self.is_pty = "://" not in url and is_pty(url)
        self._ser: Optional[serial.SerialBase] = None
        self._fd: Optional[int] = None
        self._raw = False
        self._timeout: Optional[float] = -1.0
        self.adapter: Optional[AdapterSetup] = None   # the adapter's low-latency mode, latency timer
        self._open()

    def _make(self, parity: str) -> serial.SerialBase:
        ser = serial.serial_for_url(self.url, do_not_open=True)
        ser.baudrate = self.baud
        ser.bytesize = serial.EIGHTBITS
        ser.parity = parity
        ser.stopbits = serial.STOPBITS_ONE
        ser.timeout = 0
        if self.exclusive:
            ser.exclusive = True
        ser.open()
        return ser

    def _open(self) -> None:
        if "://" not in self.url and not os.path.exists(self.url):
            raise PhyError(f"serial device {self.url} does not exist")
        try:
            if self.is_pty:
                _preset_other_speed(self.url)
            try:
                ser = self._make(self.parity)
            except termios.error as err:
                if not (self.is_pty and err.args and err.args[0] == errno.EINVAL):
                    raise
                log.warning("%s: pty rejects %s parity at %d baud (%s); using no parity, "
                            "a pty has no parity bit anyway", self.url, self.parity,
                            self.baud, err)
                ser = self._make(serial.PARITY_NONE)
        except (serial.SerialException, OSError, termios.error, ValueError) as err:
            hint = ""
            if isinstance(err, termios.error) and err.args and err.args[0] == errno.EINVAL:
                hint = " (termios EINVAL: the driver rejects these line settings)"
            raise PhyError(f"cannot open serial port {self.url} at {self.baud} baud: "
                           f"{err}{hint}") from err
        self._ser = ser
        try:
            self._fd = ser.fileno()
        except (AttributeError, NotImplementedError, serial.SerialException, OSError):
            self._fd = None
        # a POSIX tty: read/write the fd directly (pyserial's read/write add selects per call)
        self._raw = self._fd is not None and getattr(ser, "fd", None) == self._fd
        if self._fd is not None and self.check_parity and ser.parity != serial.PARITY_NONE \
                and not self.is_pty and hasattr(ser, "fd"):
            try:
                attr = termios.tcgetattr(self._fd)
                attr[0] |= termios.INPCK | termios.IGNPAR
                termios.tcsetattr(self._fd, termios.TCSANOW, attr)
            except termios.error as err:
                log.warning("%s: cannot enable input parity checking: %s", self.url, err)
        self._timeout = -1.0
        # a device (not a URL): low-latency mode and the adapter's latency timer (adapter.py)
        self.adapter = tune_port(self.url, self._fd, self.is_pty) if self._raw else None
        log.info("opened %s at %d baud, parity %s%s", self.url, self.baud, ser.parity,
                 "; " + self.adapter.describe() if self.adapter is not None else "")

    @property
    def serial(self) -> serial.SerialBase:
        if self._ser is None:
            raise PhyError(f"{self.url}: link is closed")
        return self._ser

    def reopen(self) -> None:
        """Close and open the port again (after the device came back)."""
        self.close()
        self._open()

    def _send_raw(self, fd: int, data: bytes) -> None:
        view = memoryview(data)
        while view:
            try:
                n = os.write(fd, view)
            except (BlockingIOError, InterruptedError):
                n = 0
            except OSError as err:
                raise PhyError(f"{self.url}: write failed: {err}") from err
            view = view[n:]
            if view and not select.select([], [fd], [], _WRITE_STALL)[1]:
                raise PhyError(f"{self.url}: write stalled for {_WRITE_STALL:.0f} s "
                               f"({len(view)} bytes left)")

    def send(self, data: bytes) -> None:
        ser = self.serial
        if self._raw:
            return self._send_raw(self._fd, bytes(data))  # type: ignore[arg-type]
        try:
            n = ser.write(data)
        except (serial.SerialException, OSError, termios.error) as err:
            raise PhyError(f"{self.url}: write failed: {err}") from err
        if n is not None and n != len(data):
            raise PhyError(f"{self.url}: wrote {n} of {len(data)} bytes")

    def recv(self, max_bytes: int = 4096, timeout: Optional[float] = 0.0) -> bytes:
        ser = self.serial
        try:
            if self._fd is not None:
                ready, _, _ = select.select([self._fd], [], [], timeout)
                if not ready:
                    return b""
                if not self._raw:
                    return bytes(ser.read(max_bytes))
                try:
                    data = os.read(self._fd, max_bytes)
                except (BlockingIOError, InterruptedError):
                    return b""
                if not data:   # readable but nothing to read: the device went away
                    raise PhyError(f"{self.url}: read failed: device reports readiness to "
                                   f"read but returned no data (disconnected?)")
                return data
            # no file descriptor (loop://): pyserial blocks for the first byte
            if timeout != self._timeout:
                ser.timeout = timeout
                self._timeout = timeout
            first = ser.read(1)
            if not first:
                return b""
            waiting = min(ser.in_waiting, max_bytes - 1)
            return bytes(first) + (bytes(ser.read(waiting)) if waiting > 0 else b"")
        except (serial.SerialException, OSError, termios.error, ValueError) as err:
            raise PhyError(f"{self.url}: read failed: {err}") from err

    def flush_input(self) -> None:
        try:
            if self._raw:
                termios.tcflush(self._fd, termios.TCIFLUSH)
                return
            self.serial.reset_input_buffer()
        except (serial.SerialException, OSError, termios.error) as err:
            raise PhyError(f"{self.url}: flush failed: {err}") from err

    def close(self) -> None:
        ser, self._ser = self._ser, None
        self._fd = None
        self._raw = False
        if ser is not None:
            try:
                ser.close()
            except (serial.SerialException, OSError, termios.error) as err:
                log.debug("%s: close: %s", self.url, err)

    @property
    def closed(self) -> bool:
        return self._ser is None


class FdLink(Link):
    """A byte link over a raw file descriptor (e.g. the master side of a pty).

    Reads wait in ``select``; EIO/EBADF and friends become :class:`PhyError`.
    The fd is closed by :meth:`close` if ``owns_fd``.
    """

    def __init__(self, fd: int, owns_fd: bool = True, name: str = "fd") -> None:
        self.fd: Optional[int] = fd
        self.owns_fd = owns_fd
        self.name = name
        os.set_blocking(fd, False)

    def _fd(self) -> int:
        if self.fd is None:
            raise PhyError(f"{self.name}: link is closed")
        return self.fd

    def send(self, data: bytes) -> None:
        fd = self._fd()
        view = memoryview(bytes(data))
        while view:
            try:
                n = os.write(fd, view)
            except BlockingIOError:
                select.select([], [fd], [], 1.0)
                continue
            except OSError as err:
                raise PhyError(f"{self.name}: write failed: {err}") from err
            view = view[n:]

    def recv(self, max_bytes: int = 4096, timeout: Optional[float] = 0.0) -> bytes:
        fd = self._fd()
        try:
            ready, _, _ = select.select([fd], [], [], timeout)
            if not ready:
                return b""
            data = os.read(fd, max_bytes)
        except BlockingIOError:
            return b""
        except (OSError, ValueError) as err:
            raise PhyError(f"{self.name}: read failed: {err}") from err
        if not data:
            raise PhyError(f"{self.name}: end of file (peer closed)")
        return data

    def flush_input(self) -> None:
        fd = self._fd()
        try:
            termios.tcflush(fd, termios.TCIFLUSH)
        except termios.error:
            Link.flush_input(self)  # not a tty: read and discard

    def close(self) -> None:
        fd, self.fd = self.fd, None
        if fd is not None and self.owns_fd:
            try:
                os.close(fd)
            except OSError:
                pass

    @property
    def closed(self) -> bool:
        return self.fd is None


@dataclass
class PtyPair:
    """A raw pty pair: serve ``master_fd`` (e.g. with :class:`FdLink`), open
    ``slave_path`` with :class:`SerialLink`. ``keep_fd`` is a slave-side fd held
    open so the master side does not see EIO while no client has the path open."""

    master_fd: int
    slave_path: str
    keep_fd: int
    _master_taken: bool = False

    def master_link(self) -> FdLink:
        """An :class:`FdLink` on the master fd; the link then owns (closes) the fd."""
        if self._master_taken:
            raise PhyError(f"the master fd of {self.slave_path} is already owned by a link")
        self._master_taken = True
        return FdLink(self.master_fd, owns_fd=True, name=f"pty-master({self.slave_path})")

    def close(self) -> None:
        """Close the keeper fd, and the master fd unless a link owns it."""
        fds = [self.keep_fd] + ([] if self._master_taken else [self.master_fd])
        self.keep_fd = -1
        self._master_taken = True
        for fd in fds:
            if fd >= 0:
                try:
                    os.close(fd)
                except OSError:
                    pass


def open_pty_pair() -> PtyPair:
    """Create a pty pair in raw mode; see :class:`PtyPair`."""
    try:
        master_fd, slave_fd = os.openpty()
        tty.setraw(master_fd)
        tty.setraw(slave_fd)
        path = os.ttyname(slave_fd)
    except (OSError, termios.error) as err:
        raise PhyError(f"cannot create a pty pair: {err}") from err
    return PtyPair(master_fd, path, slave_fd)
