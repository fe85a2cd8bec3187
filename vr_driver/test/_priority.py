"""Real-time priority for a test's own threads, where the system grants it.

A test that stands for hardware (the virtual G2 the commissioning tool times to the millisecond) or
for the driver's bus process (which runs at SCHED_FIFO where allowed, doc/reliability.md) can take
SCHED_FIFO for the threads it starts: on Linux the policy is a thread's and a new thread inherits
its creator's. ``scripts/test`` runs such tests beside the computing ones when ``chrt -f 1 true``
succeeds -- nothing at normal priority can then delay them -- and in the real-time phase otherwise.
"""
from __future__ import annotations

import contextlib
import os
from typing import Iterator


@contextlib.contextmanager
def threads_at_real_time(priority: int) -> Iterator[bool]:
    """Within the block, the calling thread -- and every thread or process it starts there, for
    their whole lives -- at SCHED_FIFO ``priority`` where the system allows it (yields whether it
    did); the calling thread back at normal scheduling after it."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
        granted = True
    except (PermissionError, OSError, AttributeError):
        granted = False
    try:
        yield granted
    finally:
        if granted:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
