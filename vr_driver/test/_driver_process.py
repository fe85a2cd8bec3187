"""A driver (DriverCore, its bus process) in a process of its own, for tests that kill it.

    python3 _driver_process.py PORT PROTOCOL BAUD X Y Z RX RY RZ

Connects, waits until motion is possible, prints ``BUS <pid>`` (its bus process), sends one PTP
to the pose and prints ``MOVING`` once the controller runs it; then waits to be killed. Every line
is flushed: the test reads them as events.
"""
from __future__ import annotations

import sys
import threading
import time

from vr_driver.driver import DriverCore, JobPhase, MoveRequest
from vr_driver.params import DriverParams
from vr_driver.poses import ControllerPose, MoveType


def main(argv):
    port, protocol, baud = argv[0], argv[1], int(argv[2])
    target = ControllerPose(*(float(v) for v in argv[3:9]))
    params = DriverParams.from_dict({"port": port, "baud": baud, "protocol": protocol, "cycle_rate": 50.0,
                                     "link_timeout": 1.0, "reconnect_period": 0.2, "watchdog_ms": 1000,
                                     "bus_stop_hold": 1.5})
    core = DriverCore(params)
    ready = threading.Event()
    core.add_listener(lambda s: ready.set() if s.motion_possible and s.joints_valid else None)
    core.start()
    if not ready.wait(30.0):
        print("NOT READY %s" % core.status().link_reason, flush=True)
        return 1
    if not protocol_streams(params):
        end = time.monotonic() + 10.0
        while not core.handshake.ready and time.monotonic() < end:
            time.sleep(0.01)
    print("BUS %d" % core.link._master.pid, flush=True)
    job = core.submit(MoveRequest(MoveType.PTP, target))
    if job.wait_change(JobPhase.QUEUED, 10.0) is JobPhase.QUEUED:
        print("NOT SENT", flush=True)
        return 1
    end = time.monotonic() + 10.0
    while job.phase is not JobPhase.MOVING and not job.done and time.monotonic() < end:
        job.wait_change(job.phase, 0.5)
    print("MOVING" if job.phase is JobPhase.MOVING else "NOT MOVING %s" % job.phase, flush=True)
    threading.Event().wait()
    return 0


def protocol_streams(params):
    return params.wire.streams


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
