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
    │   ├── EnvelopeError        a previewed path leaves the workspace box (names the sample)
    │   ├── CollisionError       a path would make the arm hit itself or an object of the scene
    │   │                        (names the sample, the links and the object)
    │   └── PathDeviationError   the interpolated path leaves its tolerance
    ├── ProtocolError            a 14-byte controller record cannot be encoded / decoded, or a
    │   │                        protocol parameter (byte order, move type) is invalid
    │   └── HandshakeError       the request handshake with the controller cannot proceed (not
    │       │                    ready, a target already in flight)
    │       ├── HandshakeTimeout the controller did not accept / finish / release in time
    │       └── TargetRejected   the controller answered REJECTED to a target
    ├── CsrError                 a .csr program, or an input of the .csr exporter, is malformed or
    │                            holds a value the format cannot take (names source, line, field);
    │                            also a ValueError
    ├── CsrConversionError       valid waypoints that cannot be exported (unreachable, outside the
    │                            joint limits or the workspace box); ``problems`` lists each one
    ├── SignalMapError           an I/O signal map (io_signals) entry is invalid, or a value does
    │                            not fit a signal's type (names the station and key); also a
    │                            ValueError
    ├── SceneError               a cell (collision scene) file or object is invalid (names the
    │                            entry and key); also a ValueError
    └── MissingDependency        an optional library (pinocchio, coal, OMPL, TOPP-RA: collision-aware
                                 planning) is not installed; names the package and scripts/setup;
                                 also an ImportError

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
    "EnvelopeError",
    "CollisionError",
    "PathDeviationError",
    "ProtocolError",
    "HandshakeError",
    "HandshakeTimeout",
    "TargetRejected",
    "CsrError",
    "CsrConversionError",
    "SignalMapError",
    "SceneError",
    "MissingDependency",
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


class EnvelopeError(MotionError):
    """A previewed path leaves the workspace box (the message names the first sample outside)."""


class CollisionError(MotionError):
    """A path (a move's preview, a trajectory, a joint_command step) would make the arm collide with
    itself (a link pair the SRDF does not disable) or with an object of the scene, within the
    collision padding. The message names where (the sample, or the chord between two samples, and
    its time when known), the link(s) and the other link or object. ``contacts``: the checker's
    Contact tuples at the first colliding configuration; ``sample``: the index of the sample at or
    after which it collides (None: not known); ``time`` [s] from the path's start (None: not known)."""

    def __init__(self, message: str, contacts=(), sample=None, time=None):
        super().__init__(message)
        self.contacts = tuple(contacts)
        self.sample = sample
        self.time = time


class PathDeviationError(MotionError):
    """The interpolated path leaves its tolerance around the programmed geometry."""


class ProtocolError(VrDriverError):
    """A controller record (doc/controller_program.md) cannot be encoded or decoded (wrong length, a flag byte not
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


class CsrError(VrDriverError, ValueError):
    """A ``.csr`` program (or an input of the exporter: waypoint YAML / CSV, a trajectory) is
    malformed, or a value cannot be written in the format (too long, a comma in a text field, a
    speed out of range). ``source`` is the file name ("" if none), ``line`` the 1-based line
    (0 = not known), ``field`` what is wrong (e.g. ``"MOVEL speed"``, ``"Comment"``), ``reason`` a
    sentence naming the allowed values. ``str()`` reads ``source:line: field: reason``."""

    def __init__(self, reason: str, line: int = 0, field: str = "", source: str = ""):
        self.reason = reason
        self.line = int(line or 0)
        self.field = field
        self.source = source
        super().__init__(self._text())

    def _text(self) -> str:
        if self.source and self.line:
            where = "%s:%d: " % (self.source, self.line)
        elif self.line:
            where = "line %d: " % self.line
        elif self.source:
            where = "%s: " % self.source
        else:
            where = ""
        return where + ("%s: " % self.field if self.field else "") + self.reason

    def located(self, line: int = 0, source: str = "", field: str = "") -> "CsrError":
        """The same error with a line / source / field filled in where it had none."""
        return CsrError(self.reason, self.line or line, self.field or field, self.source or source)


class CsrConversionError(VrDriverError):
    """Waypoints that are well formed but cannot be exported: unreachable poses, joints outside
    their limits, poses outside the workspace box. ``problems`` holds one located CsrError per
    refused waypoint, in input order; the message names the first and the count."""

    def __init__(self, problems):
        self.problems = tuple(problems)
        first = str(self.problems[0]) if self.problems else "no problems"
        more = len(self.problems) - 1
        super().__init__(first + (" (and %d more)" % more if more > 0 else ""))


class SignalMapError(VrDriverError, ValueError):
    """An I/O signal map is invalid (unknown key or type, overlap, offset past the station's image,
    duplicate name, safe value that does not fit), or a value does not fit a signal's type. The
    message names the station and the key."""


class SceneError(VrDriverError, ValueError):
    """A collision scene (vr_driver.kinematics.scene: a cell YAML, or an object added in code) is
    invalid: unknown key, missing key, a value that is not a finite number, a size <= 0, a duplicate
    or unknown name. The message names the file, the entry and the key."""


class MissingDependency(VrDriverError, ImportError):
    """An optional library a feature needs is not importable (collision-aware planning: pinocchio,
    coal, OMPL, TOPP-RA, Python >= 3.10 wheels from PyPI). ``package`` is the PyPI name, ``module`` the
    import name; the message names both and the command that installs them (scripts/setup)."""

    def __init__(self, package: str, module: str = "", feature: str = "", reason: str = ""):
        self.package = package
        self.module = module or package
        self.feature = feature
        text = "%s needs the Python package %s (import %s), which is not usable here%s: run scripts/setup " \
               "(it installs it from PyPI, pinned; Python >= 3.10)" % (
                   feature or "this feature", package, self.module, " (%s)" % reason if reason else "")
        super().__init__(text)
