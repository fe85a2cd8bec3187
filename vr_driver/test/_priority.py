"""Real-time priority for a test's own threads, where the system grants it.

A test that stands for hardware (the virtual G2 the commissioning tool times to the millisecond) or
for the driver's bus process (which runs at SCHED_FIFO where allowed, doc/reliability.md) can take
SCHED_FIFO for the threads it starts: on Linux the policy is a thread's and a new thread inherits
its creator's. ``scripts/test`` runs such tests beside the computing ones when ``chrt -f 1 true``
succeeds -- nothing at normal priority can then delay them -- and in the real-time phase otherwise.
"""
from __future__ import annotations

import contextlib
from typing import Iterator

from vr_driver.bus.worker import normal_scheduling, set_priority


@contextlib.contextmanager
def threads_at_real_time(priority: int) -> Iterator[bool]:
    """Within the block, the calling thread -- and every thread or process it starts there, for
    their whole lives -- at SCHED_FIFO ``priority`` where the system allows it (the bus process's
    own set_priority; yields whether it did); the calling thread back at normal scheduling after it."""
    granted = set_priority(priority).startswith("SCHED_FIFO")
    try:
        yield granted
    finally:
        if granted:
            normal_scheduling()
