"""Pose conventions: the one module that converts between the controller's and ROS's pose forms.

Controller pose (the G2's Cartesian pose, what the operator types and the controller reports)::

    (X, Y, Z in mm, Rx, Ry, Rz in degrees), rotation R = Rz(Rz) . Ry(Ry) . Rx(Rx)

i.e. fixed axes X, then Y, then Z: the same convention as URDF ``rpy`` and ``KDL::Rotation::RPY``.
It is the pose of the TCP in the controller frame ``base``. The TCP is the ``flange`` frame (x out of
the flange, ROS-Industrial) followed by a configurable TCP offset (flange -> TCP, default identity),
so the home pose (1120, 0, 725, 0, 45, 0) has the flange pointing 45 degrees down.

ROS pose: position in metres + unit quaternion (x, y, z, w), same frame (``base``).

The kinematic chain (SRDF group ``manipulator``) runs from ``base_link`` to ``tool0``;
:class:`FrameConventions` maps a controller pose to that chain's tip pose and back, using the fixed
transforms ``base_link -> base`` and ``tool0 -> flange`` read from the URDF.

Matrices are numpy arrays: 3x3 rotations, 4x4 homogeneous transforms. ROS-free; PyKDL is imported
only by the two KDL conversion functions.
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Tuple

import numpy as np

from . import validate
from .errors import MotionError, PoseError

__all__ = [
    "CONTROLLER_FIELDS",
    "ControllerPose",
    "Workspace",
    "FrameConventions",
    "HOME_POSE",
    "MoveType",
    "wrap_angle",
    "wrap_degrees",
    "rpy_to_matrix",
    "matrix_to_rpy",
    "matrix_to_quaternion",
    "quaternion_to_matrix",
    "quaternion_slerp",
    "make_transform",
    "invert_transform",
    "check_transform",
    "controller_to_matrix",
    "matrix_to_controller",
    "controller_to_ros",
    "ros_to_controller",
    "matrix_to_ros",
    "ros_to_matrix",
    "matrix_to_kdl_frame",
    "kdl_frame_to_matrix",
]

class MoveType(enum.Enum):
    """The controller's motion kinds: PTP (joint-interpolated), LIN (straight), CIRC (arc through
    a via point). Lives here, in the vocabulary, so that the wire codec needs no kinematics."""

    PTP = "ptp"
    LIN = "lin"
    CIRC = "circ"

    parse = validate.choice_parser(MotionError, "unknown move type {value!r} (ptp, lin, circ)")


CONTROLLER_FIELDS = ("x", "y", "z", "rx", "ry", "rz")
_UNITS = ("mm", "mm", "mm", "deg", "deg", "deg")

#: below this |cos(Ry)| the Euler extraction treats the rotation as gimbal-locked (Ry = +-90 deg)
GIMBAL_EPS = 1e-9


# --------------------------------------------------------------------------------------------- scalars

def finite_number(value: Any, name: str) -> float:
    """``value`` as a float, or PoseError naming ``name`` when it is not a finite real number
    (:func:`vr_driver.validate.as_finite`: numeric strings count, bools and None do not)."""
    return validate.number(value, lambda _: PoseError("%s must be a finite number, got %r" % (name, value)))


def _vector(values: Any, length: int, name: str) -> Tuple[float, ...]:
    """``values`` as a tuple of ``length`` finite floats, or PoseError saying what is wrong."""
    try:
        items = list(np.asarray(values, dtype=object).reshape(-1)) if isinstance(values, np.ndarray) \
            else list(values)
    except TypeError as exc:
        raise PoseError("%s must be a sequence of %d numbers, got %r" % (name, length, values)) from exc
    if len(items) != length:
        raise PoseError("%s must have %d values, got %d" % (name, length, len(items)))
    return tuple(finite_number(v, "%s[%d]" % (name, i)) for i, v in enumerate(items))


def _label(name: str) -> str:
    """'x' -> 'X', 'rx' -> 'Rx' (the controller's spelling)."""
    return name.upper() if len(name) == 1 else name.capitalize()


def wrap_angle(angle: float) -> float:
    """``angle`` (radians) wrapped into (-pi, pi]."""
    wrapped = math.fmod(angle + math.pi, 2.0 * math.pi)
    if wrapped <= 0.0:
        wrapped += 2.0 * math.pi
    return wrapped - math.pi


def wrap_degrees(angle: float) -> float:
    """``angle`` (degrees) wrapped into (-180, 180]."""
    wrapped = math.fmod(angle + 180.0, 360.0)
    if wrapped <= 0.0:
        wrapped += 360.0
    return wrapped - 180.0


# ------------------------------------------------------------------------------------------- rotations

def rpy_to_matrix(rx: float, ry: float, rz: float) -> np.ndarray:
    """R = Rz(rz) Ry(ry) Rx(rx) (radians; fixed axes X, then Y, then Z, as URDF rpy)."""
    cr, sr = math.cos(rx), math.sin(rx)
    cp, sp = math.cos(ry), math.sin(ry)
    cy, sy = math.cos(rz), math.sin(rz)
    return np.array([
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ])


def matrix_to_rpy(rotation: Any) -> Tuple[float, float, float]:
    """(rx, ry, rz) in radians with R = Rz Ry Rx; ry in [-pi/2, pi/2], rx and rz in (-pi, pi].

    Round-trip stable: ``matrix_to_rpy(rpy_to_matrix(*matrix_to_rpy(R)))`` returns the same angles.
    At the gimbal lock (ry = +-90 deg) only rz -+ rx is defined; we report rx = 0 and put the whole
    rotation about the vertical into rz.
    """
    r = np.asarray(rotation, dtype=float)
    r20 = max(-1.0, min(1.0, float(r[2, 0])))
    cos_ry = math.hypot(float(r[0, 0]), float(r[1, 0]))
    if cos_ry > GIMBAL_EPS:
        ry = math.atan2(-r20, cos_ry)
        rx = math.atan2(float(r[2, 1]), float(r[2, 2]))
        rz = math.atan2(float(r[1, 0]), float(r[0, 0]))
    else:
        # R = [[0, s*sin(rx - s*rz)..]]: with rx = 0, R[0,1] = -sin(rz), R[1,1] = cos(rz) for both signs
        ry = math.copysign(math.pi / 2.0, -r20)
        rx = 0.0
        rz = math.atan2(-float(r[0, 1]), float(r[1, 1]))
    return wrap_angle(rx), ry, wrap_angle(rz)


def matrix_to_quaternion(rotation: Any) -> Tuple[float, float, float, float]:
    """Unit quaternion (x, y, z, w) of a rotation matrix, with w >= 0 (Shepperd's method)."""
    r = np.asarray(rotation, dtype=float)
    m00, m01, m02 = float(r[0, 0]), float(r[0, 1]), float(r[0, 2])
    m10, m11, m12 = float(r[1, 0]), float(r[1, 1]), float(r[1, 2])
    m20, m21, m22 = float(r[2, 0]), float(r[2, 1]), float(r[2, 2])
    trace = m00 + m11 + m22
    if trace > 0.0:
        s = 2.0 * math.sqrt(trace + 1.0)
        w, x, y, z = 0.25 * s, (m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s
    elif m00 >= m11 and m00 >= m22:
        s = 2.0 * math.sqrt(max(1.0 + m00 - m11 - m22, 0.0))
        w, x, y, z = (m21 - m12) / s, 0.25 * s, (m01 + m10) / s, (m02 + m20) / s
    elif m11 >= m22:
        s = 2.0 * math.sqrt(max(1.0 + m11 - m00 - m22, 0.0))
        w, x, y, z = (m02 - m20) / s, (m01 + m10) / s, 0.25 * s, (m12 + m21) / s
    else:
        s = 2.0 * math.sqrt(max(1.0 + m22 - m00 - m11, 0.0))
        w, x, y, z = (m10 - m01) / s, (m02 + m20) / s, (m12 + m21) / s, 0.25 * s
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    if w < 0.0:
        norm = -norm
    return x / norm, y / norm, z / norm, w / norm


def _unit_quaternion(quaternion: Any, name: str = "quaternion") -> Tuple[float, float, float, float]:
    x, y, z, w = _vector(quaternion, 4, name)
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    if norm < 1e-9:
        raise PoseError("%s (x, y, z, w) must not be zero" % name)
    if abs(norm - 1.0) > 1e-3:
        raise PoseError("%s (x, y, z, w) must be a unit quaternion, its norm is %.6g" % (name, norm))
    return x / norm, y / norm, z / norm, w / norm


def quaternion_to_matrix(quaternion: Any) -> np.ndarray:
    """Rotation matrix of a quaternion (x, y, z, w); it must have norm 1 within 1e-3 (renormalised)."""
    x, y, z, w = _unit_quaternion(quaternion)
    return np.array([
        [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w)],
        [2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w)],
        [2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y)],
    ])


def quaternion_slerp(q0: Any, q1: Any, t: float) -> Tuple[float, float, float, float]:
    """Spherical interpolation between unit quaternions (x, y, z, w) along the shorter arc, t in [0, 1]."""
    a = np.array(_unit_quaternion(q0, "q0"))
    b = np.array(_unit_quaternion(q1, "q1"))
    dot = float(a @ b)
    if dot < 0.0:
        b, dot = -b, -dot
    if dot > 0.9995:  # nearly the same rotation: linear interpolation is exact enough
        out = a + t * (b - a)
    else:
        theta = math.acos(min(1.0, dot))
        out = (math.sin((1.0 - t) * theta) * a + math.sin(t * theta) * b) / math.sin(theta)
    out = out / np.linalg.norm(out)
    return float(out[0]), float(out[1]), float(out[2]), float(out[3])


# ---------------------------------------------------------------------------------------- transforms

def make_transform(rotation: Any = None, translation: Any = (0.0, 0.0, 0.0)) -> np.ndarray:
    """4x4 homogeneous transform from a 3x3 rotation (default identity) and a translation (metres)."""
    t = np.eye(4)
    if rotation is not None:
        t[:3, :3] = np.asarray(rotation, dtype=float)
    t[:3, 3] = _vector(translation, 3, "translation")
    return t


def invert_transform(transform: Any) -> np.ndarray:
    t = np.asarray(transform, dtype=float)
    out = np.eye(4)
    out[:3, :3] = t[:3, :3].T
    out[:3, 3] = -t[:3, :3].T @ t[:3, 3]
    return out


def check_transform(transform: Any, name: str = "transform") -> np.ndarray:
    """``transform`` as a 4x4 float array; PoseError unless finite with an orthonormal rotation."""
    try:
        t = np.array(transform, dtype=float)
    except (TypeError, ValueError) as exc:
        raise PoseError("%s must be a 4x4 matrix of numbers" % name) from exc
    if t.shape != (4, 4):
        raise PoseError("%s must be a 4x4 matrix, got shape %s" % (name, t.shape))
    if not np.all(np.isfinite(t)):
        raise PoseError("%s contains NaN or inf" % name)
    r = t[:3, :3]
    if np.max(np.abs(r @ r.T - np.eye(3))) > 1e-6 or np.linalg.det(r) < 0.0:
        raise PoseError("%s: the 3x3 block is not a rotation matrix" % name)
    if np.max(np.abs(t[3] - (0.0, 0.0, 0.0, 1.0))) > 1e-12:
        raise PoseError("%s: the last row must be (0, 0, 0, 1)" % name)
    return t


# ------------------------------------------------------------------------------------ controller pose

@dataclass(frozen=True)
class ControllerPose:
    """The controller's Cartesian pose: X, Y, Z in mm; Rx, Ry, Rz in degrees (R = Rz Ry Rx).

    Every field must be a finite number (PoseError names the field otherwise). The angles are kept
    as given; :meth:`wrapped` returns them in (-180, 180].
    """

    x: float
    y: float
    z: float
    rx: float
    ry: float
    rz: float

    def __post_init__(self) -> None:
        if all(type(v) is float and math.isfinite(v) for v in (self.x, self.y, self.z, self.rx, self.ry, self.rz)):
            return      # already what the checks below make of a value (a goal's stream makes thousands)
        for name, unit in zip(CONTROLLER_FIELDS, _UNITS):
            label = "%s [%s]" % (_label(name), unit)
            object.__setattr__(self, name, finite_number(getattr(self, name), label))

    @classmethod
    def from_sequence(cls, values: Any) -> "ControllerPose":
        """From (X, Y, Z, Rx, Ry, Rz); PoseError on a wrong length or a bad value."""
        if isinstance(values, ControllerPose):
            return values
        try:
            items = list(values)
        except TypeError as exc:
            raise PoseError("a controller pose is 6 numbers (X, Y, Z, Rx, Ry, Rz), got %r" % (values,)) from exc
        if len(items) != 6:
            raise PoseError("a controller pose must have 6 values (X, Y, Z, Rx, Ry, Rz), got %d" % len(items))
        return cls(*items)

    def as_tuple(self) -> Tuple[float, float, float, float, float, float]:
        return (self.x, self.y, self.z, self.rx, self.ry, self.rz)

    def wrapped(self) -> "ControllerPose":
        return ControllerPose(self.x, self.y, self.z,
                              wrap_degrees(self.rx), wrap_degrees(self.ry), wrap_degrees(self.rz))

    @property
    def position_m(self) -> Tuple[float, float, float]:
        return (self.x / 1000.0, self.y / 1000.0, self.z / 1000.0)

    def rotation(self) -> np.ndarray:
        return rpy_to_matrix(math.radians(self.rx), math.radians(self.ry), math.radians(self.rz))

    def to_matrix(self) -> np.ndarray:
        """4x4 transform (metres) of the TCP in ``base``."""
        return make_transform(self.rotation(), self.position_m)

    @classmethod
    def from_matrix(cls, transform: Any) -> "ControllerPose":
        t = np.asarray(transform, dtype=float)
        rx, ry, rz = matrix_to_rpy(t[:3, :3])
        # "+ 0.0" turns -0.0 into 0.0 (cleaner printing; equal values anyway)
        return cls(float(t[0, 3]) * 1000.0 + 0.0, float(t[1, 3]) * 1000.0 + 0.0, float(t[2, 3]) * 1000.0 + 0.0,
                   math.degrees(rx) + 0.0, math.degrees(ry) + 0.0, math.degrees(rz) + 0.0)

    def to_ros(self) -> Tuple[Tuple[float, float, float], Tuple[float, float, float, float]]:
        """(position in m, quaternion (x, y, z, w))."""
        return self.position_m, matrix_to_quaternion(self.rotation())

    @classmethod
    def from_ros(cls, position: Any, quaternion: Any) -> "ControllerPose":
        return cls.from_matrix(ros_to_matrix(position, quaternion))

    def distance_to(self, other: "ControllerPose") -> Tuple[float, float]:
        """(position distance in mm, rotation angle in degrees) between two poses."""
        dp = math.sqrt((self.x - other.x) ** 2 + (self.y - other.y) ** 2 + (self.z - other.z) ** 2)
        r = self.rotation().T @ other.rotation()
        angle = math.acos(max(-1.0, min(1.0, (float(np.trace(r)) - 1.0) / 2.0)))
        return dp, math.degrees(angle)


#: the controller's home pose (vr_driver/doc/ros_api.md; SRDF group_state ``home``)
HOME_POSE = ControllerPose(1120.0, 0.0, 725.0, 0.0, 45.0, 0.0)


def controller_to_matrix(values: Any) -> np.ndarray:
    """(X, Y, Z mm, Rx, Ry, Rz deg) or a ControllerPose -> 4x4 transform in metres."""
    pose = values if isinstance(values, ControllerPose) else ControllerPose.from_sequence(values)
    return pose.to_matrix()


def matrix_to_controller(transform: Any) -> ControllerPose:
    return ControllerPose.from_matrix(transform)


def controller_to_ros(values: Any) -> Tuple[Tuple[float, float, float], Tuple[float, float, float, float]]:
    pose = values if isinstance(values, ControllerPose) else ControllerPose.from_sequence(values)
    return pose.to_ros()


def ros_to_controller(position: Any, quaternion: Any) -> ControllerPose:
    return ControllerPose.from_ros(position, quaternion)


def matrix_to_ros(transform: Any) -> Tuple[Tuple[float, float, float], Tuple[float, float, float, float]]:
    t = np.asarray(transform, dtype=float)
    return (float(t[0, 3]), float(t[1, 3]), float(t[2, 3])), matrix_to_quaternion(t[:3, :3])


def ros_to_matrix(position: Any, quaternion: Any) -> np.ndarray:
    return make_transform(quaternion_to_matrix(quaternion), _vector(position, 3, "position [m]"))


def matrix_to_kdl_frame(transform: Any):
    """A ``PyKDL.Frame`` from a 4x4 transform."""
    import PyKDL as kdl

    t = np.asarray(transform, dtype=float)
    r = t[:3, :3].tolist()
    return kdl.Frame(kdl.Rotation(r[0][0], r[0][1], r[0][2], r[1][0], r[1][1], r[1][2],
                                  r[2][0], r[2][1], r[2][2]),
                     kdl.Vector(float(t[0, 3]), float(t[1, 3]), float(t[2, 3])))


def kdl_frame_to_matrix(frame: Any) -> np.ndarray:
    """A 4x4 transform from a ``PyKDL.Frame``."""
    m, p = frame.M, frame.p
    return np.array([
        [m[0, 0], m[0, 1], m[0, 2], p[0]],
        [m[1, 0], m[1, 1], m[1, 2], p[1]],
        [m[2, 0], m[2, 1], m[2, 2], p[2]],
        [0.0, 0.0, 0.0, 1.0],
    ])


# ------------------------------------------------------------------------------------------ workspace

@dataclass(frozen=True)
class Workspace:
    """The allowed box of controller poses (``workspace`` in config/vr_driver.yaml): mm and degrees, bounds inclusive."""

    x: Tuple[float, float] = (100.0, 1400.0)
    y: Tuple[float, float] = (-900.0, 900.0)
    z: Tuple[float, float] = (0.0, 1400.0)
    angle: Tuple[float, float] = (-180.0, 180.0)

    def __post_init__(self) -> None:
        for name in ("x", "y", "z", "angle"):
            lo, hi = _vector(getattr(self, name), 2, "workspace %s" % name)
            if lo > hi:
                raise PoseError("workspace %s: lower bound %g above upper bound %g" % (name, lo, hi))
            object.__setattr__(self, name, (lo, hi))

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "Workspace":
        """From ``{x: [lo, hi], y: [...], z: [...], angle: [...]}`` (missing keys keep the default)."""
        unknown = set(data) - {"x", "y", "z", "angle"}
        if unknown:
            raise PoseError("workspace: unknown keys %s (allowed: x, y, z, angle)" % sorted(unknown))
        return cls(**{k: tuple(v) for k, v in data.items()})

    def check(self, pose: ControllerPose) -> ControllerPose:
        """Return ``pose`` unchanged, or raise PoseError naming the first field out of range."""
        if not isinstance(pose, ControllerPose):
            pose = ControllerPose.from_sequence(pose)
        for name, unit in zip(CONTROLLER_FIELDS, _UNITS):
            lo, hi = getattr(self, name) if len(name) == 1 else self.angle
            value = getattr(pose, name)
            if not lo <= value <= hi:
                raise PoseError("%s = %g %s is outside the workspace [%g, %g] %s"
                                % (_label(name), value, unit, lo, hi, unit))
        return pose

    def excess(self, pose: ControllerPose) -> float:
        """How far ``pose`` lies outside the box: the largest excess of a field over its range,
        in that field's unit (mm, deg); 0 inside."""
        worst = 0.0
        for name in CONTROLLER_FIELDS:
            lo, hi = getattr(self, name) if len(name) == 1 else self.angle
            value = getattr(pose, name)
            worst = max(worst, lo - value, value - hi)
        return worst

    def contains(self, pose: ControllerPose) -> bool:
        try:
            self.check(pose)
        except PoseError:
            return False
        return True


# ---------------------------------------------------------------------------------- frame conventions

def _identity() -> np.ndarray:
    return np.eye(4)


@dataclass(frozen=True, eq=False)
class FrameConventions:
    """Maps controller poses (TCP in ``base``) to the kinematic chain's tip (``tool0`` in
    ``base_link``) and back.

    ``base_in_root``: pose of the controller frame ``base`` in the chain root (``base_link``).
    ``flange_in_tip``: pose of ``flange`` in the chain tip (``tool0``).
    ``tcp_in_flange``: the TCP offset (flange -> TCP), identity by default.
    All 4x4 in metres.
    """

    base_in_root: np.ndarray = field(default_factory=_identity)
    flange_in_tip: np.ndarray = field(default_factory=_identity)
    tcp_in_flange: np.ndarray = field(default_factory=_identity)

    def __post_init__(self) -> None:
        for name in ("base_in_root", "flange_in_tip", "tcp_in_flange"):
            t = check_transform(getattr(self, name), name)
            t.setflags(write=False)
            object.__setattr__(self, name, t)
        tcp_in_tip = self.flange_in_tip @ self.tcp_in_flange
        object.__setattr__(self, "_tip_in_tcp", invert_transform(tcp_in_tip))
        object.__setattr__(self, "_tcp_in_tip", tcp_in_tip)
        object.__setattr__(self, "_root_in_base", invert_transform(self.base_in_root))

    @staticmethod
    def tcp_offset(values: Any) -> np.ndarray:
        """A TCP offset transform from (X, Y, Z mm, Rx, Ry, Rz deg) in the flange frame."""
        return controller_to_matrix(values)

    def with_tcp(self, tcp_in_flange: Any) -> "FrameConventions":
        """The same frames with another TCP offset (a 4x4 transform or a 6-tuple in mm/deg)."""
        arr = np.asarray(tcp_in_flange, dtype=float) if not isinstance(tcp_in_flange, ControllerPose) \
            else tcp_in_flange.to_matrix()
        if arr.shape == (6,):
            arr = self.tcp_offset(arr)
        return FrameConventions(self.base_in_root, self.flange_in_tip, arr)

    # base <-> base_link
    def base_to_root(self, transform_in_base: Any) -> np.ndarray:
        """A transform expressed in ``base`` -> the same frame expressed in ``base_link``."""
        return self.base_in_root @ np.asarray(transform_in_base, dtype=float)

    def root_to_base(self, transform_in_root: Any) -> np.ndarray:
        return self._root_in_base @ np.asarray(transform_in_root, dtype=float)

    # controller pose <-> chain tip
    def tcp_to_tip(self, tcp_in_base: Any) -> np.ndarray:
        """TCP pose in ``base`` (4x4) -> chain tip pose in the chain root (4x4)."""
        return self.base_in_root @ np.asarray(tcp_in_base, dtype=float) @ self._tip_in_tcp

    def tip_to_tcp(self, tip_in_root: Any) -> np.ndarray:
        return self._root_in_base @ np.asarray(tip_in_root, dtype=float) @ self._tcp_in_tip

    def controller_to_tip(self, pose: Any) -> np.ndarray:
        return self.tcp_to_tip(controller_to_matrix(pose))

    def tip_to_controller(self, tip_in_root: Any) -> ControllerPose:
        return ControllerPose.from_matrix(self.tip_to_tcp(tip_in_root))
