"""What a Cartesian wire can know of the arm's joints, per configuration. ROS-free, no I/O.

On the Cartesian protocols (v1, v3) the driver sends poses the controller solves with its own IK,
and the controller reports a pose back; both are rounded to the protocol's ``pose_resolution``
(v1 whole mm / deg, v3 0.1 mm / 0.01 deg). How far that rounding can put the joints off depends on
where the arm is: it is the joint error of half a unit in each of the six pose numbers (X, Y, Z,
and the Euler angles Rx, Ry, Rz of ``R = Rz Ry Rx``, :mod:`vr_driver.poses`), mapped through the
inverse of the arm's Jacobian. :class:`WireResolution` gives that bound per joint at any joints
``q`` (:meth:`WireResolution.errors`); :mod:`vr_driver.driver.motion.trajectories` builds the default
path and goal tolerances of a trajectory on it, point by point (``validate(..., resolution=...)``), and
:mod:`vr_driver.driver.joints.supervision` judges the run with them.

The bound, linearised: a pose error ``dP`` (mm, deg) is a TCP displacement ``dp = dP[:3]`` and a
rotation ``dw = E(Rx, Ry, Rz) dP[3:]`` in ``base`` (``E``'s columns are the Euler axes: the
rotation about Rz's axis, then Ry's turned by Rz, then Rx's turned by both -- unit vectors, so the
rotation error stays bounded at Ry = +-90 deg too, where the angles themselves are not). Moved to
the chain's tip (``tool0`` in ``base_link``: ``dp_tip = dp + dw x (p_tip - p_tcp)``) it is
``J(q) dq``. So ``dq = J^-1 A dP`` and the largest ``|dq_i|`` over the box ``|dP_j| <= h_j`` (half
a unit each) is ``sum_j |(J^-1 A)_ij| h_j`` -- exact for the linear map. Checked against the IK of
rounded poses in test_wire_resolution.py (the IK's error stays below the bound).

The wrist: near joint_5 = 0 the axes of joint_4 and joint_6 line up, and a pose fixes
``joint_4 + s * joint_6`` (``s`` = +1 when the two axes point the same way there, :attr:`sign`) but
hardly their split: ``J^-1``'s joint_4 and joint_6 rows grow as 1 / sin(joint_5) while their sum's
stays bounded. Inside :data:`WRIST_BAND` (``|joint_5| <`` 5 deg) joint_4 and joint_6 are judged by
that sum (:meth:`WireResolution.errors`' second value: the same bound for the sum); the individual
bounds there are capped at :data:`ERROR_CAP` (they say nothing). 5 deg: at its edge the split's
bound is 0.08-0.13 deg on v3 (0.7 deg at 1 deg), 6-8 deg on v1, where the controller's IK of a
whole-degree pose inside the band turns the split by tens of degrees (a pose the wire cannot tell
from the plan's); the sum's stays 0.008-0.01 deg (v3), 0.7-0.8 deg (v1).
"""
from __future__ import annotations

import math
from typing import List, Optional, Sequence, Tuple

import numpy as np

from ...kinematics.solver import Kinematics
from ...protocol.base import Protocol

__all__ = ["WireResolution", "WRIST_BAND", "WRIST", "ERROR_CAP", "euler_axes"]

#: [rad] |joint_5| below this: joint_4 and joint_6 are judged by their sum (the wrist band)
WRIST_BAND = math.radians(5.0)
#: indices of joint_4, joint_5, joint_6 in the controller's joint order
WRIST = (3, 4, 5)
#: [rad] the largest individual bound reported (near joint_5 = 0 joint_4's and joint_6's grow
#: without limit: half a turn already says the wire cannot tell them)
ERROR_CAP = math.pi
#: [rad] the Jacobian is evaluated at |joint_5| >= this (at joint_5 = 0 exactly it is singular; the
#: sum's bound and the other joints' are continuous there, and this close they have their limit)
_WRIST_FLOOR = 1e-3


def euler_axes(rx: float, ry: float, rz: float) -> np.ndarray:
    """3 x 3: the rotation vector [rad] of a small change of each of the controller's Euler angles
    (Rx, Ry, Rz in rad, ``R = Rz Ry Rx``), as columns: ``dw = euler_axes(...) @ (dRx, dRy, dRz)``."""
    cz, sz = math.cos(rz), math.sin(rz)
    cy, sy = math.cos(ry), math.sin(ry)
    # Rz Ry e_x, Rz e_y, e_z
    return np.array([[cz * cy, -sz, 0.0],
                     [sz * cy, cz, 0.0],
                     [-sy, 0.0, 1.0]])


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


class WireResolution:
    """The joint error a Cartesian protocol's pose resolution allows, per configuration, for the
    arm ``kin`` (the driver's model). ``wire`` (the protocol object): its ``pose_resolution`` (mm, deg) sets the
    box; its tolerance rule (``goal_tolerance_for`` / ``path_tolerance_for``) turns the bound into
    default tolerances (:func:`vr_driver.driver.motion.trajectories.validate`). Build with :meth:`of`:
    None for a protocol with joint targets (v2: its joints are exact to 0.001 deg everywhere)."""

    def __init__(self, kin: Kinematics, wire: Protocol, band: float = WRIST_BAND) -> None:
        self.kin = kin
        self.wire = wire
        self.band = float(band)
        mm, deg = wire.pose_resolution
        #: half a unit of each pose number, in m and rad
        self.half = np.array([mm / 2000.0] * 3 + [math.radians(deg) / 2.0] * 3)
        self.sign = self._wrist_sign()

    @classmethod
    def of(cls, kin: Kinematics, wire: Protocol) -> Optional["WireResolution"]:
        """The rule for the protocol ``wire`` on ``kin``; None where the protocol carries joint targets."""
        if wire.joint_targets:
            return None
        return cls(kin, wire)

    def _wrist_sign(self) -> float:
        """+1 when joint_4's and joint_6's axes point the same way at joint_5 = 0 (the pose fixes
        joint_4 + joint_6), -1 when opposite (joint_4 - joint_6)."""
        q = list(self.kin.named_states.get("home", self.kin.clamp((0.0,) * self.kin.dof)))
        q[WRIST[1]] = 0.0
        jac = self.kin.jacobian(self.kin.clamp(q))
        dot = float(jac[3:, WRIST[0]] @ jac[3:, WRIST[2]])
        return 1.0 if dot >= 0.0 else -1.0

    def in_band(self, q: Sequence[float]) -> bool:
        """joint_5 within :attr:`band` of 0: judge joint_4 and joint_6 by their sum."""
        return abs(q[WRIST[1]]) < self.band

    def sum_of(self, q: Sequence[float]) -> float:
        """joint_4 + sign * joint_6 [rad]: what the pose fixes near joint_5 = 0."""
        return q[WRIST[0]] + self.sign * q[WRIST[2]]

    def _linear(self, q: Sequence[float]) -> Tuple[np.ndarray, np.ndarray]:
        """(J, A) at ``q``: the Jacobian of the chain's tip and the 6 x 6 map from a change of the
        pose numbers (X, Y, Z in m; Rx, Ry, Rz in rad) to the tip's twist, so that ``J dq = A dP``."""
        q = list(q)
        j5 = q[WRIST[1]]
        if abs(j5) < _WRIST_FLOOR:
            q[WRIST[1]] = math.copysign(_WRIST_FLOOR, j5) if j5 else _WRIST_FLOOR
        conv = self.kin.conventions
        tip = self.kin.fk(q)
        tcp = conv.base_to_root(conv.tip_to_tcp(tip))
        pose = conv.tip_to_controller(tip)
        rot = conv.base_in_root[:3, :3]
        rx, ry, rz = (math.radians(v) for v in pose.as_tuple()[3:])
        omega = rot @ euler_axes(rx, ry, rz)
        a = np.zeros((6, 6))
        a[:3, :3] = rot
        a[:3, 3:] = -_skew(tip[:3, 3] - tcp[:3, 3]) @ omega      # dw x d = -d x dw
        a[3:, 3:] = omega
        return self.kin.jacobian(q), a

    def map(self, q: Sequence[float]) -> np.ndarray:
        """6 x 6: the joint change [rad] of a change of each pose number (X, Y, Z in m; Rx, Ry, Rz
        in rad), linearised at ``q`` (``J^-1 A``; the pseudo-inverse at a singularity)."""
        return self._maps([q])[0]

    def _maps(self, points: Sequence[Sequence[float]]) -> np.ndarray:
        pairs = [self._linear(q) for q in points]
        if not pairs:
            return np.zeros((0, 6, 6))
        jac = np.array([j for j, _a in pairs])
        a = np.array([a for _j, a in pairs])
        try:
            return np.linalg.solve(jac, a)
        except np.linalg.LinAlgError:           # a singular point (a stretched arm): one at a time
            return np.array([np.linalg.pinv(j, rcond=1e-12) @ m for j, m in zip(jac, a)])

    def _bounds(self, m: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        per_joint = np.minimum(np.abs(m) @ self.half, ERROR_CAP)
        wrist_sum = np.minimum(np.abs(m[..., WRIST[0], :] + self.sign * m[..., WRIST[2], :]) @ self.half,
                               ERROR_CAP)
        return per_joint, wrist_sum

    def errors(self, q: Sequence[float]) -> Tuple[Tuple[float, ...], float]:
        """The largest joint error [rad] the wire's rounding allows at ``q`` (half a unit in each of
        the six pose numbers, linearised), per joint (capped at :data:`ERROR_CAP`), and the same for
        joint_4 + sign * joint_6 (bounded near joint_5 = 0, where the individual ones are not)."""
        joints, sums = self.errors_along([q])
        return joints[0], sums[0]

    def errors_along(self, points: Sequence[Sequence[float]]) -> Tuple[List[Tuple[float, ...]], List[float]]:
        """:meth:`errors` at each of ``points``: (per-joint bounds, sum bounds)."""
        per_joint, wrist_sum = self._bounds(self._maps(points))
        return [tuple(float(v) for v in row) for row in per_joint], [float(v) for v in wrist_sum]

    def describe(self) -> str:
        """One line for the result's words: the band and what is judged there."""
        return ("joint_4 %s joint_6 judged by their sum within %.1f deg of joint_5 = 0 (the wrist "
                "singularity: the pose fixes only the sum)" % ("+" if self.sign > 0 else "-", math.degrees(self.band)))
