"""A "true" robot: the URDF of a VR-006L whose dimensions and joint zeros come from a file of its own.

Why: the driver computes with the model (``config/kinematics_vr006l.yaml``), whose dimensions are
placeholders; a real arm differs from it, and its controller computes with its *own* numbers. The
virtual G2 (``python3 -m vr_driver.controller``, option ``true_model``) uses this module to simulate such
an arm, so that the effect of a wrong model shows in a simulation as it would on the robot (issue 25).

The file has the layout of ``config/kinematics_vr006l.yaml``: a ``geometry`` section (``j2_height``,
``shoulder_offset``, ``upper_arm``, ``elbow_offset``, ``forearm``, ``j5_to_flange``, ``base_frame_z``;
each a mapping with ``value``, or a plain number) and a ``joints`` section (``joint_1`` ..
``joint_6``, each with ``lower``, ``upper``, ``velocity``, ``effort`` and optionally ``acceleration``
and ``zero_offset``). The zero offsets may instead sit in a top-level ``zero_offsets`` section
(``joint_N: {value: RAD}`` or ``joint_N: RAD``, as ``kinematic_calibration`` writes it; one joint in
both places is refused). ``masses`` is optional (default: the model's; it does not change the
kinematics); text entries (``source`` notes) and other top-level entries are ignored. A copy of the
model's YAML with some numbers changed is a valid file.

Joint zero offsets, ``zero_offset`` [rad] per joint (default 0): the angle the controller reports
(and takes as a joint target) is the true joint angle minus the offset, ``q_controller = q_true -
zero_offset``, where the true angle is measured from the model's zero pose (upper arm vertical,
forearm along +x, wrist straight). So with ``joint_2: {zero_offset: 0.005}`` the controller reads 0
while the upper arm leans 5 mrad forward. The offset is applied to the rendered model by rotating the
joint's origin by the offset about its axis: the URDF's joint variable is then the controller's angle,
and ``FK(q_controller)`` is where the true arm is. The joint limits of the file are in the
controller's convention (the G2's soft limits are set in its own angles).

Rendering never touches the package's xacro: the validated numbers are written to a temporary YAML
and passed as the xacro argument ``kinematics_config`` (read with ``description``'s PyYAML-6-safe
``load_yaml``); without a file the package's own model is rendered unchanged.

Python::

    from panasonic_vr006l_support import true_model
    model = true_model.load("my_robot.yaml")        # TrueModelError naming the file and the key
    urdf = true_model.render_urdf(model)             # or render_urdf("my_robot.yaml"), render_urdf(None)

Command line::

    python3 -m panasonic_vr006l_support.true_model FILE [-o OUT.urdf] [--prefix P]

ROS-free; needs PyYAML and xacro (as ``description``).
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import os
import sys
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from typing import Any, Dict, Mapping, Optional, Sequence, Union

import numpy as np
import yaml

from . import calibration, description

__all__ = ["GEOMETRY_KEYS", "LENGTH_KEYS", "JOINT_NAMES", "JOINT_KEYS", "TrueModelError", "TrueModel", "load",
           "from_mapping", "render_urdf", "apply_zero_offsets", "main"]

#: the geometry entries of the file, all required [m]
GEOMETRY_KEYS = ("j2_height", "shoulder_offset", "upper_arm", "elbow_offset", "forearm", "j5_to_flange",
                 "base_frame_z")
#: the geometry entries that are lengths (>= 0; base_frame_z is an offset of either sign)
LENGTH_KEYS = GEOMETRY_KEYS[:-1]
#: lengths that must be > 0 (the upper arm and the forearm carry the arm's reach)
POSITIVE_KEYS = ("upper_arm", "forearm")
JOINT_NAMES = tuple("joint_%d" % i for i in range(1, 7))
#: the required limits of each joint (the URDF's <limit>)
JOINT_KEYS = ("lower", "upper", "velocity", "effort")
#: optional per joint
OPTIONAL_JOINT_KEYS = ("acceleration", "zero_offset")
#: |zero_offset| above this is refused (a zero that far off is a wrong file, not a calibration)
MAX_ZERO_OFFSET = math.pi / 2


class TrueModelError(ValueError):
    """The true-model file is unusable; the message names the file and the key."""


@dataclass(frozen=True)
class TrueModel:
    """The validated numbers of a true-model file (``path`` None: the model's own)."""

    path: Optional[str]
    geometry: Mapping[str, float]
    joints: Mapping[str, Mapping[str, float]]          # lower, upper, velocity, effort (+ acceleration)
    zero_offsets: Mapping[str, float] = field(default_factory=dict)
    masses: Mapping[str, float] = field(default_factory=dict)

    @property
    def accelerations(self) -> Optional[Dict[str, float]]:
        """{joint: rad/s^2} when the file gives one for every joint, else None (the model's set)."""
        acc = {name: j["acceleration"] for name, j in self.joints.items() if "acceleration" in j}
        return acc if len(acc) == len(self.joints) else None

    def kinematics_config(self) -> Dict[str, Any]:
        """The tree the xacro macro reads (``kinematics_config``), numbers only."""
        return {
            "geometry": {key: {"value": float(v)} for key, v in self.geometry.items()},
            "joints": {name: {k: float(v) for k, v in limits.items()} for name, limits in self.joints.items()},
            "masses": {name: float(v) for name, v in self.masses.items()},
        }


def _number(value: Any, where: str, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise TrueModelError("%s: %s must be a number, got %r" % (where, what, value))
    value = float(value)
    if not math.isfinite(value):
        raise TrueModelError("%s: %s must be a finite number, got %r" % (where, what, value))
    return value


def _zero_offset(value: float, where: str) -> float:
    if abs(value) > MAX_ZERO_OFFSET:
        raise TrueModelError("%s: %r rad is more than pi/2 off the model's zero" % (where, value))
    return value


def _model_masses() -> Dict[str, float]:
    cfg = _read_yaml(description.default_kinematics_yaml())
    return {k: float(v) for k, v in (cfg.get("masses") or {}).items()}


def _read_yaml(path: str) -> Any:
    return calibration.read_yaml(path, TrueModelError, "the true model ")


def from_mapping(cfg: Any, path: str = "<mapping>") -> TrueModel:
    """Validate a parsed true-model tree (``path`` names it in the messages)."""
    if not isinstance(cfg, dict):
        raise TrueModelError("%s: expected a mapping with geometry and joints, got %s" % (path, type(cfg).__name__))
    for section in ("geometry", "joints"):
        if section not in cfg:
            raise TrueModelError("%s: missing key %r" % (path, section))
        if not isinstance(cfg[section], dict):
            raise TrueModelError("%s: %s must be a mapping" % (path, section))
    geo_in = cfg["geometry"]
    unknown = sorted(str(k) for k in geo_in if k not in GEOMETRY_KEYS)
    if unknown:
        raise TrueModelError("%s: unknown geometry key(s) %s (known: %s)"
                             % (path, ", ".join(unknown), ", ".join(GEOMETRY_KEYS)))
    geometry: Dict[str, float] = {}
    for key in GEOMETRY_KEYS:
        where = "%s: geometry.%s" % (path, key)
        if key not in geo_in:
            raise TrueModelError("%s: missing key geometry.%s" % (path, key))
        entry = geo_in[key]
        if isinstance(entry, dict):
            if "value" not in entry:
                raise TrueModelError("%s: missing key geometry.%s.value" % (path, key))
            entry = entry["value"]
        value = _number(entry, where, "the value")
        if key in LENGTH_KEYS and value < 0.0:
            raise TrueModelError("%s: a length cannot be negative, got %r m" % (where, value))
        if key in POSITIVE_KEYS and value == 0.0:
            raise TrueModelError("%s: must be > 0 m" % where)
        geometry[key] = value
    joints_in = cfg["joints"]
    unknown = sorted(str(k) for k in joints_in if k not in JOINT_NAMES)
    if unknown:
        raise TrueModelError("%s: unknown joint(s) %s under joints (known: %s)"
                             % (path, ", ".join(unknown), ", ".join(JOINT_NAMES)))
    joints: Dict[str, Dict[str, float]] = {}
    offsets: Dict[str, float] = {}
    for name in JOINT_NAMES:
        if name not in joints_in:
            raise TrueModelError("%s: missing key joints.%s" % (path, name))
        entry = joints_in[name]
        if not isinstance(entry, dict):
            raise TrueModelError("%s: joints.%s must be a mapping of its limits" % (path, name))
        limits: Dict[str, float] = {}
        for key in JOINT_KEYS + OPTIONAL_JOINT_KEYS:
            where = "%s: joints.%s.%s" % (path, name, key)
            if key not in entry:
                if key in JOINT_KEYS:
                    raise TrueModelError("%s: missing key joints.%s.%s" % (path, name, key))
                continue
            value = _number(entry[key], where, "the value")
            if key in ("velocity", "acceleration") and value <= 0.0:
                raise TrueModelError("%s: must be > 0, got %r" % (where, value))
            if key == "effort" and value < 0.0:
                raise TrueModelError("%s: cannot be negative, got %r" % (where, value))
            if key == "zero_offset":
                offsets[name] = _zero_offset(value, where)
            else:
                limits[key] = value
        if limits["lower"] > limits["upper"]:
            raise TrueModelError("%s: joints.%s: lower limit %r above upper limit %r"
                                 % (path, name, limits["lower"], limits["upper"]))
        joints[name] = limits
    section = cfg.get("zero_offsets")
    if section is not None:       # the section panasonic_vr006l_support.kinematic_calibration writes
        if not isinstance(section, dict):
            raise TrueModelError("%s: zero_offsets must be a mapping of joints" % path)
        unknown = sorted(str(k) for k in section if k not in JOINT_NAMES)
        if unknown:
            raise TrueModelError("%s: unknown joint(s) %s under zero_offsets (known: %s)"
                                 % (path, ", ".join(unknown), ", ".join(JOINT_NAMES)))
        for name, entry in section.items():
            where = "%s: zero_offsets.%s" % (path, name)
            if isinstance(entry, dict):
                if "value" not in entry:
                    raise TrueModelError("%s: missing key zero_offsets.%s.value" % (path, name))
                entry = entry["value"]
            if name in offsets:
                raise TrueModelError("%s: joint %s has a zero offset both in joints.%s.zero_offset and in "
                                     "zero_offsets.%s: give one" % (path, name, name, name))
            offsets[name] = _zero_offset(_number(entry, where, "the value"), where)
    masses = _model_masses()
    if "masses" in cfg:
        if not isinstance(cfg["masses"], dict):
            raise TrueModelError("%s: masses must be a mapping" % path)
        for key, value in cfg["masses"].items():
            if key not in masses:
                raise TrueModelError("%s: unknown link %r under masses (known: %s)"
                                     % (path, key, ", ".join(sorted(masses))))
            masses[key] = _number(value, "%s: masses.%s" % (path, key), "the mass")
            if masses[key] <= 0.0:
                raise TrueModelError("%s: masses.%s: must be > 0 kg" % (path, key))
    return TrueModel(path, geometry, joints, offsets, masses)


def load(path: Optional[str] = None) -> TrueModel:
    """The validated true model of ``path`` (None or "": the model's own YAML, path None)."""
    if not path:
        own = description.default_kinematics_yaml()
        return dataclasses.replace(from_mapping(_read_yaml(own), own), path=None)
    return from_mapping(_read_yaml(path), path)


def _axis_angle_matrix(axis: Sequence[float], angle: float) -> np.ndarray:
    k = np.asarray(axis, dtype=float)
    k = k / np.linalg.norm(k)
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * kx + (1.0 - math.cos(angle)) * (kx @ kx)


def _rpy_matrix(rpy: Sequence[float]) -> np.ndarray:
    r, p, y = rpy
    rx = np.array([[1, 0, 0], [0, math.cos(r), -math.sin(r)], [0, math.sin(r), math.cos(r)]])
    ry = np.array([[math.cos(p), 0, math.sin(p)], [0, 1, 0], [-math.sin(p), 0, math.cos(p)]])
    rz = np.array([[math.cos(y), -math.sin(y), 0], [math.sin(y), math.cos(y), 0], [0, 0, 1]])
    return rz @ ry @ rx


def _matrix_rpy(m: np.ndarray) -> Sequence[float]:
    # exact zeros stay exact (atan2(0, 1) == 0), so an axis-aligned rotation keeps a clean rpy
    return (math.atan2(m[2, 1], m[2, 2]), math.atan2(-m[2, 0], math.hypot(m[2, 1], m[2, 2])),
            math.atan2(m[1, 0], m[0, 0]))


def apply_zero_offsets(urdf_xml: str, offsets: Mapping[str, float], prefix: str = "") -> str:
    """The URDF with each named joint's origin turned by its offset about the joint's axis: the
    joint variable becomes the controller's angle, ``q_true - offset`` (see the module docstring).
    ``offsets`` names the joints without ``prefix``."""
    if not any(offsets.values()):
        return urdf_xml
    root = ET.fromstring(urdf_xml)
    found = set()
    for joint in root.findall("joint"):
        name = joint.get("name", "")
        if not name.startswith(prefix) or name[len(prefix):] not in offsets:
            continue
        plain = name[len(prefix):]
        found.add(plain)
        offset = float(offsets[plain])
        if offset == 0.0:
            continue
        axis_elem = joint.find("axis")
        axis = [float(v) for v in axis_elem.get("xyz").split()] if axis_elem is not None else [1.0, 0.0, 0.0]
        origin = joint.find("origin")
        if origin is None:
            origin = ET.SubElement(joint, "origin", {"xyz": "0 0 0", "rpy": "0 0 0"})
        rpy = [float(v) for v in (origin.get("rpy") or "0 0 0").split()]
        m = _rpy_matrix(rpy) @ _axis_angle_matrix(axis, offset)
        # the rotation is about a coordinate axis in the package's model: snap the round-off of the
        # other entries so that parallel / perpendicular axes stay exactly so (the analytic IK checks)
        m[np.abs(m) < 1e-15] = 0.0
        origin.set("rpy", " ".join(repr(float(v)) for v in _matrix_rpy(m)))
    missing = sorted(set(offsets) - found)
    if missing:
        raise TrueModelError("zero offsets for joint(s) %s, which the URDF does not have" % ", ".join(missing))
    return ET.tostring(root, encoding="unicode")


def render_urdf(model: Union[None, str, TrueModel] = None, prefix: str = "") -> str:
    """The URDF text of the true robot: ``model`` a TrueModel, a file path, or None / "" (the
    package's model, rendered exactly as ``description.render_urdf``). Raises TrueModelError for a
    bad file, description.DescriptionError when xacro fails."""
    mappings = {"prefix": prefix} if prefix else {}
    if not model:
        return description.render_urdf(None, mappings or None)
    if isinstance(model, str):
        model = load(model)
    with tempfile.TemporaryDirectory(prefix="vr006l_true_model_") as tmp:
        config = os.path.join(tmp, "kinematics.yaml")
        with open(config, "w") as f:
            yaml.safe_dump(model.kinematics_config(), f)
        mappings["kinematics_config"] = config
        xml = description.render_urdf(None, mappings)
    return apply_zero_offsets(xml, model.zero_offsets, prefix)


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog="python3 -m panasonic_vr006l_support.true_model",
                                     description="Render the URDF of a true robot from a kinematics YAML "
                                                 "(the layout of config/kinematics_vr006l.yaml, plus "
                                                 "zero_offset per joint).")
    parser.add_argument("file", nargs="?", default=None, help="the true-model YAML (default: the model's)")
    parser.add_argument("--prefix", default="", help="prefix of every link and joint name")
    parser.add_argument("-o", "--output", help="write the URDF here instead of standard output")
    args = parser.parse_args(argv)
    try:
        text = render_urdf(args.file, args.prefix)
    except (TrueModelError, description.DescriptionError) as exc:
        print("true_model: error: %s" % exc, file=sys.stderr)
        return 1
    description.write_output(text, args.output)
    return 0


if __name__ == "__main__":
    sys.exit(main())
