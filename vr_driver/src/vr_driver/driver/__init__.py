"""The driver core (ROS-free): a link supervisor and a motion sequencer, stepped by a clock and
composed by :class:`DriverCore`.

    jobs.py       MoveRequest, Preview, MoveJob, JobPhase, JobResult, SubmitMode
    link.py       LinkSupervisor: port, DP master, session, freshness, counters -> LinkSample
    sequencer.py  MotionSequencer: queue, handshake, stops at rest, outcomes -> the record to send
    core.py       DriverCore: the bus loop steps the two; requests validate and plan off the bus
"""
from __future__ import annotations

from .core import DriverCore, DriverError, DriverStatus
from .jobs import JobPhase, JobResult, MoveJob, MoveRequest, Preview, SubmitMode
from .link import (ERROR_CONTROLLER, ERROR_LINK, ERROR_NONE, ERROR_PROTOCOL, LinkCounters, LinkSample,
                   LinkState, LinkSupervisor, open_serial_link)
from .sequencer import (SESSION_RECORDS_BEFORE_REQUEST, START_TOLERANCE, MotionSequencer,
                        SequencerView, why_no_motion)

__all__ = [
    "DriverCore", "DriverError", "DriverStatus",
    "JobPhase", "JobResult", "MoveJob", "MoveRequest", "Preview", "SubmitMode",
    "ERROR_CONTROLLER", "ERROR_LINK", "ERROR_NONE", "ERROR_PROTOCOL", "LinkCounters", "LinkSample",
    "LinkState", "LinkSupervisor", "open_serial_link",
    "SESSION_RECORDS_BEFORE_REQUEST", "START_TOLERANCE", "MotionSequencer", "SequencerView",
    "why_no_motion",
]
