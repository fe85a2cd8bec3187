"""The one exception tree of vr_driver.

    VrDriverError
    ├── ModelError               the robot description cannot be used (bad URDF/SRDF/YAML, no chain)
    ├── PoseError                a pose or joint vector with bad values (NaN, inf, wrong length,
    │                            unknown joint name, outside the workspace box); also a ValueError
    ├── KinematicsError          a kinematic question has no acceptable answer
    │   ├── UnreachableError     no joint solution reaches the pose (outside reach, or none found
    │   │   │                    within the time budget)
    │   │   └── IkTimeoutError   the numeric search spent its budget (also a TimeoutError)
    │   ├── NearSingularError    the configuration is too close to a singularity
    │   └── JointLimitError      the only solutions (or the given joints) violate a joint limit
    ├── MotionError              a motion cannot be generated (joint jump, bad via point, ...)
    │   └── PathDeviationError   the interpolated path leaves its tolerance
    └── ProtocolError            a 14-byte controller record cannot be encoded / decoded, or a
        │                        protocol parameter (byte order, move type) is invalid
        └── HandshakeError       the request handshake with the controller cannot proceed (not
            │                    ready, a target already in flight)
            ├── HandshakeTimeout the controller did not accept / finish / release in time
            └── TargetRejected   the controller answered REJECTED to a target

Motion planning re-raises kinematic errors unchanged when a single step fails (the message names
the step), so callers catch ``VrDriverError`` or one of its direct children. Foreign exceptions
(XML parser, YAML, PyKDL status codes) are converted at the boundary with ``raise ... from``.
"""
from __future__ import annotations

__all__ = [
    "VrDriverError",
    "ModelError",
    "PoseError",
    "KinematicsError",
    "UnreachableError",
    "IkTimeoutError",
    "NearSingularError",
    "JointLimitError",
    "MotionError",
    "PathDeviationError",
    "ProtocolError",
    "HandshakeError",
    "HandshakeTimeout",
    "TargetRejected",
]


class VrDriverError(Exception):
    """Base class of every error raised by vr_driver."""


class ModelError(VrDriverError):
    """The robot description (URDF, SRDF, kinematics.yaml) cannot be used; the message says why."""


class PoseError(VrDriverError, ValueError):
    """A pose or joint vector has a bad value: not finite, wrong length, unknown joint name, or
    outside the allowed range. The message names the field and the allowed range."""


class KinematicsError(VrDriverError):
    """A kinematic question (IK, singularity, limits) has no acceptable answer."""


class UnreachableError(KinematicsError):
    """No joint solution reaches the requested pose; the message says why (distance vs reach,
    orientation, or search exhausted)."""


class IkTimeoutError(UnreachableError, TimeoutError):
    """The numeric IK search spent its whole time budget without a solution."""


class NearSingularError(KinematicsError):
    """The configuration (or a motion step) is too close to a singularity."""


class JointLimitError(KinematicsError):
    """The pose is geometrically reachable, but only with joints outside their limits (or the given
    joint vector itself is outside the limits). The message names the joint and its range."""


class MotionError(VrDriverError):
    """A motion (PTP, LIN, CIRC) cannot be generated: a joint jump, a degenerate circle, ..."""


class PathDeviationError(MotionError):
    """The interpolated path leaves its tolerance around the programmed geometry."""


class ProtocolError(VrDriverError):
    """A controller record (DESIGN.md §4) cannot be encoded or decoded (wrong length, a flag byte not
    0/1, an unknown move type / state / status bit, a value outside int16), or a protocol parameter
    such as the byte order is invalid. The message names the byte or field and the allowed values."""


class HandshakeError(ProtocolError):
    """The request handshake cannot proceed: the controller is not READY (or not yet seen READY with
    the flag cleared), or a target is still in flight."""


class HandshakeTimeout(HandshakeError, TimeoutError):
    """The controller did not accept, finish or release a target within its time limit.

    ``target`` is the wire command (or None), ``stage`` one of "accept", "motion", "release",
    ``reason`` a sentence for the user."""

    def __init__(self, reason: str, target: object = None, stage: str = ""):
        super().__init__(reason)
        self.reason = reason
        self.target = target
        self.stage = stage


class TargetRejected(HandshakeError):
    """The controller answered REJECTED to a target. ``target`` is the wire command, ``reason`` a
    sentence (what the controller's status bits say, when known)."""

    def __init__(self, reason: str, target: object = None):
        super().__init__(reason)
        self.reason = reason
        self.target = target
