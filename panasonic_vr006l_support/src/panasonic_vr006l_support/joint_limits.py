"""The model's joint limits as numbers, read from ``config/kinematics_vr006l.yaml`` (the one source).

The URDF carries position, velocity and effort limits; the joint *accelerations* have no place in a
URDF ``<limit>``, so they are read here, from the same YAML entries (``joints.<name>.acceleration``).
They are an ASSUMPTION (velocity / 0.1 s, the ramp the virtual arm has always used) until measured on
the real arm: see the YAML's comment and the package's README.md, "The robot model". MoveIt's ``joint_limits.yaml``
carries the same accelerations (its test compares them), and the virtual arm's default ramp time is
:func:`ramp_time` of this set.

ROS-free; needs only PyYAML.
"""
from __future__ import annotations

import math
from typing import Any, Dict, Mapping, Optional, Sequence

import yaml

from .calibration import YAML_PATH

__all__ = ["LimitsError", "YAML_PATH", "load", "velocities", "accelerations", "ramp_time", "model_ramp_time",
           "RAMP_DIGITS"]

#: :func:`ramp_time` is rounded to this many decimals of a second (1 ns): 5.23 / 52.3 is
#: 0.10000000000000002 in floating point, the ramp is 0.1 s
RAMP_DIGITS = 9

_KEYS = ("lower", "upper", "velocity", "acceleration", "effort")


class LimitsError(Exception):
    """The YAML's joint limits are missing or unusable; the message names the file and the joint."""


def _number(value: Any, where: str, positive: bool) -> float:
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    if not ok or (positive and value <= 0.0):
        raise LimitsError("%s must be a finite number%s, got %r" % (where, " > 0" if positive else "", value))
    return float(value)


def load(path: Optional[str] = None) -> Dict[str, Dict[str, float]]:
    """{joint name: {lower, upper, velocity, acceleration, effort}} of the YAML (default: the
    package's), in the file's order; every value checked (velocity, acceleration, effort > 0)."""
    path = path or YAML_PATH
    try:
        with open(path) as f:
            data = yaml.safe_load(f) or {}
    except OSError as exc:
        raise LimitsError("cannot read %s: %s" % (path, exc.strerror or exc)) from exc
    except yaml.YAMLError as exc:
        raise LimitsError("%s is not valid YAML: %s" % (path, exc)) from exc
    joints = data.get("joints") if isinstance(data, dict) else None
    if not isinstance(joints, dict) or not joints:
        raise LimitsError("%s has no 'joints' mapping" % path)
    out: Dict[str, Dict[str, float]] = {}
    for name, entry in joints.items():
        if not isinstance(entry, dict):
            raise LimitsError("%s: joints.%s is not a mapping" % (path, name))
        lim = {}
        for key in _KEYS:
            where = "%s: joints.%s.%s" % (path, name, key)
            if key not in entry:
                raise LimitsError("%s is missing" % where)
            lim[key] = _number(entry[key], where, key in ("velocity", "acceleration", "effort"))
        out[str(name)] = lim
    return out


def velocities(path: Optional[str] = None) -> Dict[str, float]:
    """{joint name: velocity limit [rad/s]} of the model."""
    return {name: lim["velocity"] for name, lim in load(path).items()}


def accelerations(path: Optional[str] = None) -> Dict[str, float]:
    """{joint name: acceleration limit [rad/s^2]} of the model (an assumption, see the module)."""
    return {name: lim["acceleration"] for name, lim in load(path).items()}


def ramp_time(velocity: Sequence[float], acceleration: Sequence[float]) -> float:
    """Time [s] from rest to full speed of the slowest-ramping joint: max over the joints of
    velocity / acceleration (joints with an infinite velocity or acceleration left out), rounded to
    ``RAMP_DIGITS`` decimals. LimitsError when no joint has both finite."""
    if len(velocity) != len(acceleration):
        raise LimitsError("%d velocities but %d accelerations" % (len(velocity), len(acceleration)))
    ratios = [float(v) / float(a) for v, a in zip(velocity, acceleration)
              if math.isfinite(v) and math.isfinite(a) and a > 0.0]
    if not ratios:
        raise LimitsError("no joint has both a finite velocity and a finite acceleration limit")
    return round(max(ratios), RAMP_DIGITS)


def model_ramp_time(limits: Optional[Mapping[str, Mapping[str, float]]] = None) -> float:
    """:func:`ramp_time` of the model's set (default: the package's YAML): 0.1 s."""
    lims = load() if limits is None else limits
    return ramp_time([lim["velocity"] for lim in lims.values()], [lim["acceleration"] for lim in lims.values()])
