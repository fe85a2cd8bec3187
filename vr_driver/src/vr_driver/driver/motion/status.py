"""What the driver core says of itself: :class:`DriverStatus` (the immutable snapshot of one bus
iteration, all the node publishes), :class:`ModelCheck` (our model against the controller's, once
per connection) and :class:`DriverError` (a request the driver refuses). ROS-free, no I/O: the bus
loop (:mod:`vr_driver.driver.bus_loop`) makes the snapshots, the node reads them."""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Dict, Optional, Tuple

from ...bus.health import BusHealthSummary
from ...bus.line_check import LineVerdict
from ...errors import VrDriverError
from ...poses import ControllerPose
from ...protocol.common import FeedbackRecord
from .inbox import MotionSnapshot, no_link, stale_reason
from .jobs import MoveJob
from ..link.link import ERROR_LINK, LinkCounters, LinkState
from .sequencer import why_no_motion

__all__ = ["DriverError", "DriverStatus", "ModelCheck"]


class DriverError(VrDriverError):
    """A request the driver refuses (not connected, e-stop, bad input...). The message says why."""


@dataclass(frozen=True)
class ModelCheck:
    """Our model against the controller's, at a connection (protocols that report both the joints
    and the pose: v2): how far the reported pose lies from our FK of the reported joints."""

    session: int                       # the link session it was made in
    position_mm: float                 # the largest of |dX|, |dY|, |dZ|
    angle_deg: float                   # the largest of |dRx|, |dRy|, |dRz| (wrapped)
    ok: bool                           # within model_check_position / model_check_angle
    joints: Tuple[float, ...]          # the reported joints it was made at [rad]

    def describe(self) -> str:
        text = "the controller's pose is %.3f mm / %.3f deg from our model's FK of its joints" % (
            self.position_mm, self.angle_deg)
        if not self.ok:
            text += (": the model's dimensions (panasonic_vr006l_support/config/kinematics_vr006l.yaml) "
                     "are not the robot's -- Cartesian targets, the workspace box and the RViz preview "
                     "are off by about that much; calibrate the model (README, The robot model)")
        return text


@dataclass(frozen=True)
class DriverStatus:
    """A consistent snapshot of everything the node publishes."""

    time: float
    link: LinkState
    link_reason: str
    feedback: Optional[FeedbackRecord]              # None unless the link is CONNECTED
    pose: Optional[ControllerPose]
    joints: Optional[Tuple[float, ...]]
    joints_valid: bool
    job: Optional[MoveJob]
    queue_length: int
    cycle_rate: float                          # measured DP cycles per second
    counters: LinkCounters
    master_counters: Dict[str, int]
    slave_state: str
    last_diag: str
    error_code: int
    error_reason: str
    feedback_time: Optional[float] = None     # clock time the feedback record arrived (None: none)
    record_time: Optional[float] = None       # clock time the controller's record was taken: the
    #                                           reply that brought it began then (arrival less its
    #                                           time on the wire); a new value = a new sample
    settling: bool = False                    # a stopped move is waiting for the arm to be at rest
    model_check: Optional[ModelCheck] = None  # the model against the controller (v2), latest connection
    bus_health: Optional[BusHealthSummary] = None   # the gaps between the card's replies, last minute
    line: Optional[LineVerdict] = None         # the rate the line gives against cycle_rate; the adapter

    @property
    def connected(self) -> bool:
        return self.link is LinkState.CONNECTED

    @property
    def motion_possible(self) -> bool:
        fb = self.feedback
        if fb is None or not self.connected:
            return False
        return not why_no_motion(fb)

    def why_no_motion(self) -> str:
        """Why motion is not possible now ("" when it is)."""
        if not self.connected or self.feedback is None:
            return no_link(self.link.value, self.link_reason)
        return why_no_motion(self.feedback)

    def for_requests(self, limit: float) -> MotionSnapshot:
        """What a request reads of this snapshot before it posts (the inbox's
        :class:`~vr_driver.driver.motion.inbox.MotionSnapshot`), read as this one is with ``limit``."""
        return MotionSnapshot(self.time, self.motion_possible, self.why_no_motion(), self.joints, self.joints_valid,
                              self.link_reason or self.link.value, self.cycle_rate, self.feedback_time, limit)

    def stale(self, now: float, limit: float) -> "DriverStatus":
        """This snapshot as it must be read at ``now``: unchanged while it and its feedback are at
        most ``limit`` seconds old; otherwise a lost link -- no feedback, no pose, no joints, in
        error -- never a repeat of old good news."""
        reason = stale_reason(now, self.time, self.feedback_time, limit)
        if not reason:
            return self
        return replace(self, link=LinkState.STALE, link_reason=reason, feedback=None, pose=None,
                       joints_valid=False, error_code=ERROR_LINK, error_reason=reason,
                       feedback_time=None, record_time=None)
