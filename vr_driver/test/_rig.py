"""Shared by the DriverCore tests (test_driver.py, test_port_faults.py): the driver's parameters on a
test pty, and waiting on its status with a deadline, woken by every status it publishes."""
from __future__ import annotations

import threading
import time
from typing import Callable

from vr_driver.driver import DriverCore, DriverStatus
from vr_driver.params import DriverParams

BAUD = 187500


def rig_params(path: str) -> DriverParams:
    """Settings for a driver on the pty at ``path``: a 50 Hz bus, a fast reconnect, and a 1 s
    watchdog / link timeout. The rig runs the virtual controller in the test's own process, so the
    driver's bus thread, the controller's server and program threads and the test's planning share
    one interpreter lock; on a loaded 2-core machine a 300 ms watchdog fired now and then (a lost
    link in a test about something else). Loss detection itself is tested with the stepped core."""
    return DriverParams.from_dict({
        "port": path, "baud": BAUD, "cycle_rate": 50.0, "link_timeout": 1.0,
        "reconnect_period": 0.2, "watchdog_ms": 1000, "accept_timeout": 1.0})


class StatusWaiter:
    """Waits until a DriverCore's status satisfies a predicate (raises AssertionError on timeout)."""

    def __init__(self, core: DriverCore) -> None:
        self.core = core
        self._cond = threading.Condition()
        core.add_listener(self._wake)

    def _wake(self, _status: DriverStatus) -> None:
        with self._cond:
            self._cond.notify_all()

    def wait_status(self, predicate: Callable[[DriverStatus], bool], timeout: float) -> DriverStatus:
        end = time.monotonic() + timeout
        with self._cond:
            while True:
                status = self.core.status()
                if predicate(status):
                    return status
                left = end - time.monotonic()
                if left <= 0:
                    raise AssertionError("status condition not met within %.1f s; last: %s: %s; %s"
                                         % (timeout, status.link.value, status.link_reason,
                                            status.feedback))
                self._cond.wait(left)

    def wait_ready(self, timeout: float = 5.0) -> DriverStatus:
        """Link up, motion possible, joints known and the handshake ready for a target."""
        return self.wait_status(lambda s: s.motion_possible and s.joints_valid
                                and self.core.handshake.ready, timeout)
