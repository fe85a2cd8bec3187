"""Where a simulated DP station serves the bus: :class:`SimPort` (a pty pair it creates, optionally
symlinked; an existing device; or any link), the symlink's lock (``<link>.lock`` holding the pid,
so two stations never serve one link) and this launch's own link (``auto``,
:func:`auto_pty_link`: the virtual controller and the driver resolve it alike). ROS-free."""
from __future__ import annotations

import logging
import os
from typing import Mapping, Optional, Union

from pyprofibus_vendor.errors import ProfibusError
from pyprofibus_vendor.phy import Link
from pyprofibus_vendor.phy_serial import PtyPair, SerialLink, open_pty_pair

from ..params import AUTO_LINK, LinkNameError, auto_link
from ..params import resolve_link as params_resolve_link
from .simulator import SimDeviceError, SimError

__all__ = ["AUTO_LINK", "auto_pty_link", "resolve_link", "pid_alive", "SimPort"]

log = logging.getLogger(__name__)

def auto_pty_link(environ: Optional[Mapping[str, str]] = None, station: str = "g2") -> str:
    """This launch's pty link of ``station`` (:func:`vr_driver.params.auto_link`: the driver
    resolves its ``port: auto`` with the same function); SimError where it cannot be named."""
    try:
        return auto_link(environ, station)
    except LinkNameError as exc:
        raise SimError(str(exc)) from None


def resolve_link(value: str, station: str = "g2") -> str:
    """A pty link given as a parameter: ``auto`` is this launch's link of ``station``, ``auto:NAME``
    this launch's link of station NAME (:func:`auto_pty_link`); anything else is a path."""
    try:
        return params_resolve_link(value, station)
    except LinkNameError as exc:
        raise SimError(str(exc)) from None


def _remove_quietly(path: str) -> None:
    try:
        os.unlink(path)
    except OSError:
        pass


def pid_alive(pid: int) -> bool:
    """True while the process ``pid`` lives (also another user's)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:          # another user's live process
        return True
    return True


def _take_link_lock(path: str) -> str:
    """Create ``path.lock`` holding our pid; refuse (SimDeviceError) while another live process
    holds it. A lock whose process is gone is stale and taken over. Returns the lock's path."""
    lock = path + ".lock"
    for _ in range(3):
        try:
            fd = os.open(lock, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        except FileExistsError:
            try:
                with open(lock) as f:
                    text = f.read().strip()
            except FileNotFoundError:
                continue                 # released meanwhile: try again
            except OSError as exc:
                raise SimDeviceError("cannot read the pty link lock %s: %s" % (lock, exc)) from exc
            if text.isdigit() and pid_alive(int(text)):
                raise SimDeviceError(
                    "pty link %s is in use by the live process %s (lock %s): another virtual controller "
                    "serves it; give this one another link (sim_port:=..., --pty-link)" % (path, text, lock))
            try:
                os.unlink(lock)          # stale (its process is gone) or unreadable: take it over
            except FileNotFoundError:
                pass
            continue
        except OSError as exc:
            raise SimDeviceError("cannot create the pty link lock %s: %s" % (lock, exc)) from exc
        with os.fdopen(fd, "w") as f:
            f.write("%d\n" % os.getpid())
        return lock
    raise SimDeviceError("cannot take the pty link lock %s: it keeps changing" % lock)


# -------------------------------------------------------------------------------- the whole device

class SimPort:
    """Where a simulated DP station serves the bus (shared by the virtual controller and the virtual
    I/O island, :mod:`vr_driver.controller.io_island`).

    ``link``: None creates a raw pty pair -- masters (or the line hub, :mod:`pyprofibus_vendor.line`)
    open :attr:`device_path`; with ``pty_link`` a symlink to it is made there (replacing a stale
    symlink, never another file; guarded by ``<pty_link>.lock`` holding our pid) and removed by
    :meth:`close`. A string serves that existing device (``SerialLink(link, baud)``). A
    :class:`~pyprofibus_vendor.phy.Link` is used as it is (the caller closes it).
    SimDeviceError when the pty, device or symlink cannot be made."""

    def __init__(self, link: Union[None, str, Link], baud: int, pty_link: Optional[str] = None) -> None:
        if pty_link is not None and link is not None:
            raise SimError("pty_link is only for a pty the station creates (link=None)")
        self.pty: Optional[PtyPair] = None
        self.symlink: Optional[str] = None
        self.device_path = ""                     # what a master opens (pty slave path or the device)
        self._owns_link = False
        self.link = self._open(link, baud, pty_link)

    def _open(self, link: Union[None, str, Link], baud: int, pty_link: Optional[str]) -> Link:
        if isinstance(link, Link):
            return link
        if isinstance(link, str):
            try:
                made = SerialLink(link, baud)
            except ProfibusError as exc:
                raise SimDeviceError(str(exc)) from exc
            self._owns_link = True
            self.device_path = link
            return made
        try:
            self.pty = open_pty_pair()
        except ProfibusError as exc:
            raise SimDeviceError(str(exc)) from exc
        self.device_path = self.pty.slave_path
        if pty_link:
            try:
                self._make_symlink(pty_link, self.pty.slave_path)
            except SimDeviceError:
                self.pty.close()
                raise
        self._owns_link = True
        return self.pty.master_link()

    def _make_symlink(self, path: str, target: str) -> None:
        if os.path.lexists(path) and not os.path.islink(path):
            raise SimDeviceError("pty link %s exists and is not a symlink: not replacing it" % path)
        lock = _take_link_lock(path)
        tmp = "%s.%d.tmp" % (path, os.getpid())
        try:
            if os.path.lexists(tmp):
                os.unlink(tmp)
            os.symlink(target, tmp)
            os.replace(tmp, path)
        except OSError as exc:
            _remove_quietly(lock)
            raise SimDeviceError("cannot create the pty link %s -> %s: %s" % (path, target, exc)) from exc
        self.symlink = path

    def close(self) -> None:
        """Close what this object opened, remove the pty symlink and its lock. Idempotent."""
        if self._owns_link:
            self.link.close()
            self._owns_link = False
        if self.pty is not None:
            self.pty.close()
            self.pty = None
        if self.symlink is not None:
            try:
                if os.path.islink(self.symlink):
                    os.unlink(self.symlink)
            except OSError as exc:
                log.warning("cannot remove the pty link %s: %s", self.symlink, exc)
            _remove_quietly(self.symlink + ".lock")
            self.symlink = None
