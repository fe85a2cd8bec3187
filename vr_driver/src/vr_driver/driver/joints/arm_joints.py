"""The arm's joints as the bus loop knows them, record by record (ROS-free, no I/O, no clock of its
own; bus thread only): :class:`ArmJoints` reads them from each controller record -- v2 reports
them, v1 and v3 report only a pose, which :class:`~vr_driver.driver.joints.tracking.JointTracker` reads
against what was sent -- and, once per connection where the protocol reports both the joints and
the pose, checks our model against the controller's (:class:`~vr_driver.driver.motion.status.ModelCheck`).
"""
from __future__ import annotations

import logging
from typing import Optional, Tuple

from ...kinematics.solver import Kinematics
from ...params import DriverParams
from ...protocol.base import Protocol
from ..motion.jobs import MoveJob
from ..link.link import LinkSample
from ..motion.status import ModelCheck
from .tracking import JointTracker

log = logging.getLogger("vr_driver.driver")

__all__ = ["ArmJoints"]


class ArmJoints:
    """The joints of the controller's latest record (:attr:`joints`, :attr:`valid`) and the model
    check of the latest connection (:attr:`model_check`); stepped by :meth:`update` once per bus
    iteration."""

    def __init__(self, params: DriverParams, kinematics: Kinematics, wire: Protocol) -> None:
        self.params = params
        self.kin = kinematics
        self.wire = wire
        # the joints of the reported pose (v1, v3): the commanded branch, the configuration held,
        # each target solved by the controller's configuration rule (controller/configuration)
        self.tracker = JointTracker(kinematics, self.wire.pose_resolution,
                                    rule=params.controller.configuration)
        self.joints: Optional[Tuple[float, ...]] = None
        self.valid = False
        self.model_check: Optional[ModelCheck] = None

    def update(self, sample: LinkSample, job: Optional[MoveJob]) -> Optional[Tuple[float, ...]]:
        """Read ``sample`` (``job``: the sequencer's job in flight, which the tracker follows) and
        return its joints; None while the link is down. Then the model check (:meth:`check_model`)."""
        joints = self._read(sample, job)
        self.check_model(sample, joints)
        return joints

    def _read(self, sample: LinkSample, job: Optional[MoveJob]) -> Optional[Tuple[float, ...]]:
        """The joints of the controller's latest record; None while the link is down. v2 reports
        them; v1 and v3 report only a pose, which :class:`~vr_driver.driver.joints.tracking.JointTracker`
        reads against what was sent (the branch the controller is on, the commanded configuration
        where the pose leaves it open, no step the arm cannot make). A few milliseconds at most
        (the solver's time budget)."""
        fb = sample.feedback
        if fb is None:
            self.valid = False               # (the tracker keeps the last joints as its reference)
            return None
        reported = self.wire.feedback_joints(fb)
        if reported is not None:            # v2 reports the joints themselves (0.001 deg)
            self.joints, self.valid = reported, True
            return self.joints
        self.tracker.follow(job)
        joints = self.tracker.update(fb.pose, sample.record_time if sample.record_time is not None
                                     else sample.time)
        self.joints, self.valid = self.tracker.joints, joints is not None
        return joints

    def check_model(self, sample: LinkSample, joints: Optional[Tuple[float, ...]]) -> None:
        """Once per connection (the first record of a link session) where the protocol reports the
        joints and the pose: the reported pose against our FK of the reported joints. One FK on the
        bus thread per connection. A mismatch is a warning in the log (and /diagnostics)."""
        fb = sample.fresh
        if fb is None or joints is None or not self.wire.reports_joints:
            return
        if self.model_check is not None and self.model_check.session == sample.session:
            return
        ours = self.kin.fk_pose(joints).as_tuple()
        theirs = fb.pose.as_tuple()
        d_pos = max(abs(a - b) for a, b in zip(ours[:3], theirs[:3]))
        d_ang = max(abs((a - b + 180.0) % 360.0 - 180.0) for a, b in zip(ours[3:], theirs[3:]))
        check = ModelCheck(sample.session, d_pos, d_ang, d_pos <= self.params.model_check_position
                           and d_ang <= self.params.model_check_angle, tuple(joints))
        self.model_check = check
        if check.ok:
            log.info("model check: %s", check.describe())
        else:
            log.warning("model check: %s", check.describe())
