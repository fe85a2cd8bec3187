"""Opening the controller's port for the :class:`~vr_driver.driver.link.link.LinkSupervisor`: the
controller's DP slave, the DP master's settings, the bus process (the node's default), and when
to try again after a port that cannot be opened. ROS-free.

The supervisor decides *whether* it opens the port (and judges what comes of it); this module
says *how*: :func:`controller_spec` and :func:`master_settings` (the same for an in-process
:class:`~pyprofibus_vendor.dp_master.DpMaster` and for a bus process), :func:`start_bus_process`
(a :class:`~vr_driver.bus.process.BusProcessMaster` for the device, refused at once when there
is no such device), and :class:`Reopening` (every ``reconnect_period``; a port that cannot be
opened is a warning at first, an error once it has been missing for :data:`PORT_ERROR_AFTER`).
"""
from __future__ import annotations

import errno
import logging
import os
from dataclasses import replace
from typing import TYPE_CHECKING, Any, Callable, Dict, Optional

from pyprofibus_vendor.dp_master import BusTiming, SlaveSpec
from pyprofibus_vendor.errors import PhyError

from ...bus.process import BusProcessMaster, BusSettings
from ...params import DriverParams

if TYPE_CHECKING:
    from pyprofibus_vendor.config import BusConfig, SlaveConfig

log = logging.getLogger("vr_driver.driver")

__all__ = ["PORT_ERROR_AFTER", "Reopening", "controller_spec", "idle_record", "master_settings",
           "port_hint", "start_bus_process"]

# a port that cannot be opened is a warning at first (a virtual controller may still be starting),
# an error once it has been missing this long [s]
PORT_ERROR_AFTER = 5.0


def idle_record(params: DriverParams) -> bytes:
    """The record that asks nothing of the controller (the flag at 0 / both slots empty)."""
    return params.wire.idle_record(params.byte_order)


def port_hint(exc: BaseException) -> str:
    """What an error opening the port most likely means, for the errors with a clear remedy."""
    codes = set()
    seen: Optional[BaseException] = exc
    for _ in range(5):
        if seen is None:
            break
        if isinstance(getattr(seen, "errno", None), int):
            codes.add(seen.errno)
        seen = seen.__cause__ or seen.__context__
    text = str(exc)
    if codes & {errno.EACCES, errno.EPERM} or "Permission denied" in text:
        return (" (permission denied: the driver's user needs read and write access to the device, "
                "usually membership of its group, e.g. dialout)")
    if errno.EBUSY in codes or "Device or resource busy" in text:
        return " (the device is busy: another program has it open)"
    return ""


def controller_spec(slave_config: SlaveConfig) -> SlaveSpec:
    """The DP master's spec of the controller's slave (the bus config's ``slaves[0]``)."""
    sc = slave_config
    return SlaveSpec(sc.address, sc.ident, sc.cfg, user_prm_data=sc.user_prm_data,
                     group_ident=sc.group_mask,
                     watchdog=None if not sc.watchdog_ms else sc.watchdog_ms / 1000.0)


def master_settings(params: DriverParams, bus: BusConfig) -> Dict[str, Any]:
    """The DP master's keyword settings from the bus config and the driver's parameters (the
    same for an in-process master and a bus process)."""
    timing = BusTiming.for_baud(bus.baud, bus.retry_limit)
    if bus.slot_time is not None:
        timing = replace(timing, slot_bits=bus.slot_time)
    # dx_tolerance: a Data_Exchange without a reply (a corrupted telegram) does not drop the
    # slave -- and with its Set_Prm the controller's program session -- before the link counts
    # as lost here anyway (link_timeout without a good record); retry_steps: a lost reply in
    # the start-up sequence repeats that step instead of restarting it after a back-off
    return dict(timing=timing, backoff_max=min(1.0, params.reconnect_period),
                dx_tolerance=params.link_timeout, retry_steps=True)


def start_bus_process(params: DriverParams, bus: BusConfig, spec: SlaveSpec, settings: Dict[str, Any],
                      on_state_change: Callable[..., None], wake: Optional[Any] = None) -> BusProcessMaster:
    """The serial port and the DP master in a process of their own (:mod:`vr_driver.bus.process`);
    ``wake``: the requests' wake-up its cycle waits for too (the inbox's). Raises PhyError for a
    device that is not there."""
    device = bus.phy.device
    # a device that is not there (an unplugged adapter, a virtual controller not started yet) is
    # said here, as the serial link says it, without starting a process for it at every reconnect
    # attempt (each start holds the bus loop: the status went stale)
    if "://" not in device and not os.path.exists(device):
        raise PhyError("serial device %s does not exist" % device)
    return BusProcessMaster(BusSettings(
        device=device, baud=bus.baud, master_address=bus.master_address,
        cycle_rate_hz=bus.cycle_rate_hz, controller=spec.address,
        idle_record=idle_record(params), watchdog=spec.watchdog,
        rt_priority=params.bus_rt_priority, node_timeout=params.bus_node_timeout,
        stop_hold=params.bus_stop_hold, **settings),
        on_state_change=on_state_change, wake=wake)


class Reopening:
    """When the link supervisor opens its port again -- ``period`` after it failed, was dropped or
    could not be opened -- and how loudly it says that the port cannot be opened: a warning when
    the reason is new, an error once (when the same reason has held for PORT_ERROR_AFTER)."""

    def __init__(self, period: float) -> None:
        self.period = period
        self.next_open = 0.0                 # clock time of the next attempt
        self._missing_since = 0.0            # the port could not be opened, for this reason, since
        self._error_logged = False

    def due(self, now: float) -> bool:
        return now >= self.next_open

    def later(self, now: float) -> None:
        """The port failed or was dropped at ``now``: the next attempt a period later."""
        self.next_open = now + self.period

    def cannot_open(self, now: float, device: str, exc: BaseException, last_reason: str) -> str:
        """Opening ``device`` failed with ``exc`` at ``now``: the next attempt a period later, the
        warning or error when due. Returns the reason in words (``last_reason``: the link's
        reason until now; the same reason again is not logged again)."""
        self.later(now)
        reason = "cannot open %s: %s%s" % (device, exc, port_hint(exc))
        if reason != last_reason:
            self._missing_since = now
            log.warning("%s (retrying every %.2g s)", reason, self.period)
        elif now - self._missing_since >= PORT_ERROR_AFTER and not self._error_logged:
            log.error("%s for %.0f s now (still retrying every %.2g s)", reason,
                      now - self._missing_since, self.period)
        self._error_logged = now - self._missing_since >= PORT_ERROR_AFTER
        return reason
