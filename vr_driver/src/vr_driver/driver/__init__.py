"""The driver core (ROS-free): a link supervisor and a motion sequencer, stepped by a clock and
composed by :class:`DriverCore`. One room per job, each importing only the rooms listed before it:

    own_thread.py   OwnThread: the start / join of the bus loop's and the planning thread's threads
    link/           the bus side
      link.py         LinkSupervisor: port, DP master, session, freshness, counters -> LinkSample
      link_port.py, card_diagnosis.py, record_clock.py, stations.py  its parts; the controller's I/O
    motion/         the motion side
      jobs.py         MoveRequest, Preview, MoveJob, JobPhase, JobResult, SubmitMode
      sequencer.py    SequencerBase: queue, stops at rest, outcomes -> the record to send (no protocol's records)
      handshake.py    HandshakeSequencer (v1): the same through the request / done handshake
      streaming.py    StreamSequencer (v2, v3): the same for streamed targets, the stream job's life
      stream_points.py  a plan made a timed stream (speeds, corner levels, pauses held)
      stream_thinning.py  which planned points a stream keeps (thinning, Cartesian steps, elbow skip)
      status.py       DriverStatus (the snapshot the node publishes), ModelCheck, DriverError
    joints/         the arm's joints
      arm_joints.py   ArmJoints: the joints of each record (tracking.py's JointTracker), the model check
    checks/         a job's way in
      job_control.py  JobControl: submit, cancel, stop, prepare_trajectory; the planning thread
      path_checks.py  PathChecks: previews, the workspace box, the cell (scene_guard.py)
      stream_prep.py  JointStreams (v2), CartesianStreams (v3): a path made a checked stream (the
                      protocol's stream family, registered in sequencers.py)
      wire_targets.py the wire pose of a v3 target the G2 solves on the plan (near joint_5 = 0)
      commissioned.py what the driver does with the commissioning file's G2 facts (speeds, look-ahead)
    bus_loop.py     BusLoop: one iteration steps link, joints and sequencer; the bus thread
    core.py         DriverCore: owns and wires the parts; the one object the node talks to
    planning/       the plan action and its worker process (imports the rest; nothing imports it)
"""
from __future__ import annotations

from .core import DriverCore
from .motion.jobs import JobPhase, JobResult, MoveJob, MoveRequest, Preview, SubmitMode
from .link.link import (ERROR_CONTROLLER, ERROR_LINK, ERROR_NONE, ERROR_PROTOCOL, LinkCounters, LinkSample,
                   LinkState, LinkSupervisor, open_serial_link)
from .motion.handshake import HandshakeSequencer
from .motion.sequencer import SESSION_RECORDS_BEFORE_REQUEST, START_TOLERANCE, SequencerView, why_no_motion
from . import sequencers  # noqa: F401  (registers each built-in protocol's sequencer and stream family with it)
from .motion.status import DriverError, DriverStatus

__all__ = [
    "DriverCore", "DriverError", "DriverStatus",
    "JobPhase", "JobResult", "MoveJob", "MoveRequest", "Preview", "SubmitMode",
    "ERROR_CONTROLLER", "ERROR_LINK", "ERROR_NONE", "ERROR_PROTOCOL", "LinkCounters", "LinkSample",
    "LinkState", "LinkSupervisor", "open_serial_link",
    "SESSION_RECORDS_BEFORE_REQUEST", "START_TOLERANCE", "HandshakeSequencer", "SequencerView",
    "why_no_motion",
]
