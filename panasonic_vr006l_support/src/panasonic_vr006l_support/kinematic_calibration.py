"""Kinematic calibration of the VR-006L model against the G2 controller (issue 25, item 2): the
ROS-free core.

From N pairs (the joint angles the teach pendant shows, the TCP pose the controller reports at the
same moment) it fits, by least squares, the seven dimensions of ``config/kinematics_vr006l.yaml``
(``geometry``) and six joint zero offsets, says which parameters the data cannot determine (and holds
them), reports residuals and each fitted parameter's standard uncertainty, refuses unusable data with
the reason, proposes the poses to measure, and writes a copy of the YAML with the fitted values.

The model (the same chain as ``urdf/vr006l_macro.xacro``; frames and zero pose as there: upper arm
vertical, forearm along +x, wrist straight)::

    flange in base = Tz(-base_frame_z) Rz(t1) T(shoulder_offset, 0, j2_height) Ry(t2) T(0, 0, upper_arm)
                     Ry(t3) T(0, 0, elbow_offset) Rx(t4) T(forearm, 0, 0) Ry(t5) Rx(t6) T(j5_to_flange, 0, 0)

with ``t_i = shown_i + zero_i``: the angle the pendant shows is the true joint angle minus the zero
offset. The pose is the controller's: X, Y, Z in mm, Rx, Ry, Rz in degrees, R = Rz Ry Rx
(``vr_driver.poses``); the TCP must be the flange (no tool offset active on the controller while the
pairs are read). This module does not import vr_driver (its tests compare the FK with it).

Units inside: metres and radians (``Parameters`` values). Pairs come in the pendant's units: degrees
for the joints, mm and degrees for the pose.

**Weighting.** The residual of a pair is its position error in mm and its rotation error (the angle
vector of R_reported R_model^T) in radians times ``lever_mm`` (default 1000 mm): a rotation error of
1 deg counts like 17.45 mm. Reason: the dominant noise is the pendant's joint readout (0.01 deg), which
moves the TCP by about (lever to the joint) x (angle error) and turns it by the angle error; the
levers of the VR-006L are 0.1 to 1.4 m, about 1 m on average, so this weighting makes the residuals
roughly equally noisy (the condition for least squares to be the best estimate). ``sigma`` (the RMS
of the weighted residuals, corrected for the degrees of freedom) is in mm.

**Identifiability.** ``j2_height`` and ``base_frame_z`` move the TCP identically (both only shift it
along z): the data determines ``j2_height - base_frame_z`` only, so ``base_frame_z`` is held (at its
value in ``nominal``) and the fitted ``j2_height`` carries the difference. This structural null space is
found from the SVD of the Jacobian over a generic set of poses, not assumed; every other parameter is
determinable. A data set whose Jacobian has a further (near) null direction is refused as degenerate,
with the combination it cannot determine.

API: :func:`nominal_parameters`, :func:`fk`, :func:`fk_controller`, :func:`fit` (-> :class:`FitResult`),
:func:`propose_poses`, :func:`write_yaml`, :class:`CalibrationError`; ``python3 -m
panasonic_vr006l_support.kinematic_calibration --help`` (propose, fit, write).
"""
from __future__ import annotations

import argparse
import datetime
import math
import os
import sys
import tempfile
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np
import yaml

from .calibration import YAML_PATH, read_yaml

__all__ = ["CalibrationError", "GEOMETRY", "OFFSETS", "PARAMETERS", "DEFAULT_POSES", "LEVER_MM",
           "nominal_parameters", "joint_limits", "fk", "fk_controller", "fit", "FitResult", "propose_poses",
           "predicted_uncertainty", "write_yaml", "load_pairs", "main"]

#: the seven dimensions of the YAML's ``geometry`` (metres), in the model's order
GEOMETRY = ("j2_height", "shoulder_offset", "upper_arm", "elbow_offset", "forearm", "j5_to_flange",
            "base_frame_z")
#: the joint zero offsets (radians): true joint angle = shown angle + offset
OFFSETS = tuple("zero_joint_%d" % i for i in range(1, 7))
PARAMETERS = GEOMETRY + OFFSETS
_N = len(PARAMETERS)
_IS_LENGTH = np.array([name in GEOMETRY for name in PARAMETERS])

#: rotation errors are weighted as the arc they make at this lever [mm] (1 deg ~ 17.45 mm)
LEVER_MM = 1000.0
#: the parameters' scale in the fit: 1 mm for lengths, 1 mrad for offsets (1 mm at 1 m)
_SCALE = np.full(len(PARAMETERS), 1e-3)
#: when a structural null direction must be held, the first of these it involves is held
_HOLD_PREFERENCE = ("base_frame_z",) + tuple(reversed(PARAMETERS))

#: the number of poses :func:`propose_poses` proposes by default (see its docstring)
DEFAULT_POSES = 12

#: refusal thresholds
METRES_LIMIT_MM = 5.0            # a pose with every |X|, |Y|, |Z| below this looks like metres
UNREACHABLE_MM = 100.0           # a pair this far from the nominal model is a typo
UNREACHABLE_DEG = 10.0
DUPLICATE_DEG = 0.005            # joints equal to within half the display resolution
DEGENERATE_RCOND = 1e-4          # column-normalised singular value ratio below this: degenerate
STRUCTURAL_RCOND = 1e-9


class CalibrationError(ValueError):
    """The pairs (or the model) cannot give a calibration; the message names the problem and, where
    one pair is at fault, its index (0-based)."""


Parameters = Dict[str, float]


# ============================================================================================ model

def _load_yaml(path: str) -> Any:
    return read_yaml(path, CalibrationError)


def _entry_value(entry: Any, where: str) -> float:
    value = entry.get("value") if isinstance(entry, dict) else entry
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise CalibrationError("%s: %r is not a finite number" % (where, value))
    return float(value)


def nominal_parameters(path: str = YAML_PATH) -> Parameters:
    """The model's parameters from the YAML (metres; the zero offsets [rad] from its ``zero_offsets``
    section or ``joints.joint_N.zero_offset`` -- the layouts ``true_model`` reads -- 0 when absent)."""
    cfg = _load_yaml(path)
    geometry = (cfg or {}).get("geometry") or {}
    out: Parameters = {}
    for name in GEOMETRY:
        if name not in geometry:
            raise CalibrationError("%s: geometry.%s is missing" % (path, name))
        out[name] = _entry_value(geometry[name], "%s: geometry.%s" % (path, name))
    offsets = (cfg or {}).get("zero_offsets") or {}
    joints = (cfg or {}).get("joints") or {}
    for i, name in enumerate(OFFSETS):
        joint = "joint_%d" % (i + 1)
        entry = offsets.get(joint)
        inline = (joints.get(joint) or {}).get("zero_offset") if isinstance(joints.get(joint), dict) else None
        if entry is not None and inline is not None:
            raise CalibrationError("%s: %s has a zero offset both in joints.%s.zero_offset and in zero_offsets.%s"
                                   % (path, joint, joint, joint))
        if inline is not None:
            out[name] = _entry_value(inline, "%s: joints.%s.zero_offset" % (path, joint))
        else:
            out[name] = 0.0 if entry is None else _entry_value(entry, "%s: zero_offsets.%s" % (path, joint))
    return out


def joint_limits(path: str = YAML_PATH) -> Tuple[np.ndarray, np.ndarray]:
    """(lower, upper) of the six joints in radians, from the YAML."""
    joints = (_load_yaml(path) or {}).get("joints") or {}
    lower, upper = [], []
    for i in range(1, 7):
        j = joints.get("joint_%d" % i)
        if not isinstance(j, dict):
            raise CalibrationError("%s: joints.joint_%d is missing" % (path, i))
        lower.append(_entry_value(j.get("lower"), "joints.joint_%d.lower" % i))
        upper.append(_entry_value(j.get("upper"), "joints.joint_%d.upper" % i))
    return np.array(lower), np.array(upper)


def _vector(params: Mapping[str, float]) -> np.ndarray:
    missing = [n for n in PARAMETERS if n not in params]
    if missing:
        raise CalibrationError("parameters missing: %s" % ", ".join(missing))
    v = np.array([float(params[n]) for n in PARAMETERS])
    if not np.all(np.isfinite(v)):
        raise CalibrationError("parameters contain NaN or inf: %s"
                               % ", ".join(n for n, x in zip(PARAMETERS, v) if not math.isfinite(x)))
    return v


def _rot(axis: int, angles: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotations about the x (0), y (1) or z (2) axis."""
    c, s = np.cos(angles), np.sin(angles)
    r = np.zeros(angles.shape + (3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    r[..., axis, axis] = 1.0
    r[..., i, i] = c
    r[..., j, j] = c
    r[..., i, j] = -s
    r[..., j, i] = s
    return r


def _chain(p: np.ndarray, q: np.ndarray):
    """FK of the shown joints ``q`` (N, 6, rad) with parameter vector ``p``: flange position (N, 3),
    rotation (N, 3, 3), and for the analytic Jacobian: each joint's axis and origin in ``base``
    (N, 6, 3) and each length's direction (N, 7, 3)."""
    h2, a1, a2, a3, d4, d6, zb = p[:7]
    t = q + p[7:][None]
    n = q.shape[0]
    ex, ey, ez = np.eye(3)
    axes = np.zeros((n, 6, 3))
    origins = np.zeros((n, 6, 3))
    dirs = np.zeros((n, 7, 3))
    pos = np.tile(np.array([0.0, 0.0, -zb]), (n, 1))
    rot = np.tile(np.eye(3), (n, 1, 1))
    axes[:, 0], origins[:, 0] = ez, pos
    rot = rot @ _rot(2, t[:, 0])
    dirs[:, 1] = rot @ ex                                   # shoulder_offset
    dirs[:, 0] = rot @ ez                                   # j2_height
    pos = pos + a1 * dirs[:, 1] + h2 * dirs[:, 0]
    axes[:, 1], origins[:, 1] = rot @ ey, pos
    rot = rot @ _rot(1, t[:, 1])
    dirs[:, 2] = rot @ ez                                   # upper_arm
    pos = pos + a2 * dirs[:, 2]
    axes[:, 2], origins[:, 2] = rot @ ey, pos
    rot = rot @ _rot(1, t[:, 2])
    dirs[:, 3] = rot @ ez                                   # elbow_offset
    pos = pos + a3 * dirs[:, 3]
    axes[:, 3], origins[:, 3] = rot @ ex, pos
    rot = rot @ _rot(0, t[:, 3])
    dirs[:, 4] = rot @ ex                                   # forearm
    pos = pos + d4 * dirs[:, 4]
    axes[:, 4], origins[:, 4] = rot @ ey, pos
    rot = rot @ _rot(1, t[:, 4])
    axes[:, 5], origins[:, 5] = rot @ ex, pos
    rot = rot @ _rot(0, t[:, 5])
    dirs[:, 5] = rot @ ex                                   # j5_to_flange
    pos = pos + d6 * dirs[:, 5]
    dirs[:, 6] = -ez                                        # base_frame_z
    return pos, rot, axes, origins, dirs


def fk(params: Mapping[str, float], joints_rad: Any) -> Tuple[np.ndarray, np.ndarray]:
    """Flange pose in the controller frame ``base`` at the shown joint angles ``joints_rad`` ((6,) or
    (N, 6), radians): (position(s) [m], rotation matrix / matrices)."""
    q = np.asarray(joints_rad, dtype=float)
    single = q.ndim == 1
    pos, rot = _chain(_vector(params), np.atleast_2d(q))[:2]
    return (pos[0], rot[0]) if single else (pos, rot)


def _rpy(rot: np.ndarray) -> np.ndarray:
    """(N, 3) controller angles (rx, ry, rz) [rad], R = Rz Ry Rx (vr_driver.poses.matrix_to_rpy)."""
    cos_ry = np.hypot(rot[:, 0, 0], rot[:, 1, 0])
    ry = np.arctan2(-np.clip(rot[:, 2, 0], -1.0, 1.0), cos_ry)
    rx = np.arctan2(rot[:, 2, 1], rot[:, 2, 2])
    rz = np.arctan2(rot[:, 1, 0], rot[:, 0, 0])
    lock = cos_ry <= 1e-9
    rx = np.where(lock, 0.0, rx)
    rz = np.where(lock, np.arctan2(-rot[:, 0, 1], rot[:, 1, 1]), rz)
    return np.stack([rx, ry, rz], axis=1)


def _matrices(rpy_rad: np.ndarray) -> np.ndarray:
    return _rot(2, rpy_rad[:, 2]) @ _rot(1, rpy_rad[:, 1]) @ _rot(0, rpy_rad[:, 0])


def fk_controller(params: Mapping[str, float], joints_deg: Any) -> np.ndarray:
    """The controller pose(s) (X, Y, Z mm, Rx, Ry, Rz deg) at the shown joints ``joints_deg`` (deg)."""
    q = np.atleast_2d(np.asarray(joints_deg, dtype=float))
    pos, rot = _chain(_vector(params), np.radians(q))[:2]
    out = np.hstack([pos * 1000.0, np.degrees(_rpy(rot))])
    return out[0] if np.ndim(joints_deg) == 1 else out


def _log(rot: np.ndarray) -> np.ndarray:
    """(N, 3) rotation vectors of (N, 3, 3) rotations (angle < pi)."""
    v = 0.5 * np.stack([rot[:, 2, 1] - rot[:, 1, 2], rot[:, 0, 2] - rot[:, 2, 0], rot[:, 1, 0] - rot[:, 0, 1]], 1)
    s = np.linalg.norm(v, axis=1)
    c = np.clip((np.trace(rot, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    angle = np.arctan2(s, c)
    factor = np.where(s > 1e-12, angle / np.where(s > 1e-12, s, 1.0), 1.0)
    return v * factor[:, None]


def _residuals(p: np.ndarray, q: np.ndarray, pos_mm: np.ndarray, rot: np.ndarray, lever_mm: float):
    """Weighted residuals (N, 6): position [mm], rotation vector [rad] x lever_mm; model minus measured."""
    mpos, mrot = _chain(p, q)[:2]
    dp = mpos * 1000.0 - pos_mm
    dr = _log(mrot @ np.transpose(rot, (0, 2, 1)))
    return np.hstack([dp, dr * lever_mm])


def _jacobian(p: np.ndarray, q: np.ndarray, lever_mm: float) -> np.ndarray:
    """(N*6, 13) d residual / d parameter, the parameters in their fit scale (_SCALE: mm, mrad);
    analytic (the rotation residual's derivative to first order in the residual)."""
    pos, _, axes, origins, dirs = _chain(p, q)
    n = q.shape[0]
    jac = np.zeros((n, 6, _N))
    jac[:, :3, :7] = np.transpose(dirs, (0, 2, 1)) * 1000.0
    lever = pos[:, None, :] - origins                       # (N, 6, 3)
    jac[:, :3, 7:] = np.transpose(np.cross(axes, lever), (0, 2, 1)) * 1000.0
    jac[:, 3:, 7:] = np.transpose(axes, (0, 2, 1)) * lever_mm
    return (jac * _SCALE[None, None]).reshape(n * 6, _N)


# =================================================================================== identifiability

def _generic_joints(n: int, seed: int = 12345) -> np.ndarray:
    lower, upper = joint_limits()
    rng = np.random.default_rng(seed)
    return rng.uniform(lower, upper, size=(n, 6))


def _structural_holds(p: np.ndarray, lever_mm: float, free: List[int]) -> List[Tuple[str, str]]:
    """The parameters no data can determine, with the reason: the null space of the Jacobian over a
    generic set of poses, one parameter held per null direction (the first of _HOLD_PREFERENCE that
    the direction involves)."""
    jac = _jacobian(p, _generic_joints(60), lever_mm)
    holds: List[Tuple[str, str]] = []
    free = list(free)
    while free:
        sub = jac[:, free]
        norms = np.linalg.norm(sub, axis=0)
        if np.any(norms == 0.0):
            k = free[int(np.argmin(norms))]
            holds.append((PARAMETERS[k], "%s does not move the TCP at all" % PARAMETERS[k]))
            free.remove(k)
            continue
        _, s, vt = np.linalg.svd(sub / norms, full_matrices=False)
        if s[-1] >= STRUCTURAL_RCOND * s[0]:
            break
        v = vt[-1] / norms
        v = v / np.max(np.abs(v))
        involved = [PARAMETERS[free[i]] for i in range(len(free)) if abs(v[i]) > 0.05]
        k = next(PARAMETERS.index(n) for n in _HOLD_PREFERENCE if n in involved)
        reason = ("%s move the TCP identically (null combination %s): only their combination is "
                  "determinable; %s is held, the fitted %s carries it"
                  % (" and ".join(involved), _combination(v, free), PARAMETERS[k],
                     ", ".join(n for n in involved if n != PARAMETERS[k])))
        holds.append((PARAMETERS[k], reason))
        free.remove(k)
    return holds


def _carriers(held: Mapping[str, str]) -> Dict[str, str]:
    """fitted parameter -> the structurally held one(s) whose difference from nominal it absorbs."""
    out: Dict[str, str] = {}
    for name, reason in held.items():
        marker = "the fitted "
        if marker in reason:
            for fitted in reason.split(marker, 1)[1].split(" carries", 1)[0].split(", "):
                out[fitted] = ", ".join(filter(None, [out.get(fitted), name]))
    return out


def _combination(v: np.ndarray, free: Sequence[int], threshold: float = 0.05) -> str:
    """``v`` (scaled to max |v_i| = 1) as "1.00 a - 0.50 b", largest first, the first term positive."""
    v = v * (1.0 if v[int(np.argmax(np.abs(v)))] > 0 else -1.0)
    terms = ["%s %.2f %s" % ("-" if v[i] < 0 else "+", abs(v[i]), PARAMETERS[free[i]])
             for i in np.argsort(-np.abs(v)) if abs(v[i]) > threshold]
    return " ".join(terms).lstrip("+ ")


# ============================================================================================ input

def load_pairs(path: str) -> List[Tuple[List[float], List[float]]]:
    """Pairs from a YAML file (a list of ``{joints: [6 deg], pose: [X Y Z mm, Rx Ry Rz deg]}``, or under
    a ``pairs`` key) or a CSV file (12 numbers a line: J1..J6 deg, X Y Z mm, Rx Ry Rz deg; lines
    starting with # and a header line are skipped)."""
    try:
        with open(path) as f:
            text = f.read()
    except OSError as exc:
        raise CalibrationError("cannot read %s: %s" % (path, exc.strerror or exc)) from exc
    if path.lower().endswith(".csv"):
        pairs = []
        for lineno, line in enumerate(text.splitlines(), 1):
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            cells = [c.strip() for c in line.replace(";", ",").split(",") if c.strip()]
            try:
                values = [float(c) for c in cells]
            except ValueError:
                if not pairs:
                    continue                                 # a header
                raise CalibrationError("%s:%d: not 12 numbers: %r" % (path, lineno, line))
            if len(values) != 12:
                raise CalibrationError("%s:%d: %d values, need 12 (J1..J6, X Y Z Rx Ry Rz)"
                                       % (path, lineno, len(values)))
            pairs.append((values[:6], values[6:]))
        return pairs
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise CalibrationError("%s is not valid YAML: %s" % (path, exc)) from exc
    if isinstance(data, dict):
        data = data.get("pairs")
    if not isinstance(data, list):
        raise CalibrationError("%s: expected a list of {joints, pose} (or a `pairs:` key)" % path)
    out = []
    for i, item in enumerate(data):
        if not isinstance(item, dict) or "joints" not in item or "pose" not in item:
            raise CalibrationError("%s: pair %d needs `joints` and `pose`" % (path, i))
        out.append((item["joints"], item["pose"]))
    return out


def _as_arrays(pairs: Any) -> Tuple[np.ndarray, np.ndarray]:
    joints, poses = [], []
    for i, pair in enumerate(pairs):
        if isinstance(pair, dict):
            pair = (pair.get("joints"), pair.get("pose"))
        try:
            jq, pose = pair
            jq = [float(v) for v in jq]
            pose = [float(v) for v in (pose.as_tuple() if hasattr(pose, "as_tuple") else pose)]
        except (TypeError, ValueError) as exc:
            raise CalibrationError("pair %d: expected (6 joint angles [deg], 6 pose values [mm, deg]): %s"
                                   % (i, exc)) from exc
        if len(jq) != 6 or len(pose) != 6:
            raise CalibrationError("pair %d: %d joint angles and %d pose values, need 6 and 6 (J1..J6 deg; "
                                   "X Y Z mm, Rx Ry Rz deg)" % (i, len(jq), len(pose)))
        joints.append(jq)
        poses.append(pose)
    return np.array(joints, dtype=float).reshape(-1, 6), np.array(poses, dtype=float).reshape(-1, 6)


def _check_input(joints: np.ndarray, poses: np.ndarray, p: np.ndarray, lever_mm: float) -> None:
    """Refusals that need no fit: NaN / inf, units, duplicates, unreachable pairs."""
    for i in range(len(joints)):
        bad = [("J%d" % (k + 1)) for k in range(6) if not math.isfinite(joints[i, k])] + \
              [f for k, f in enumerate(("X", "Y", "Z", "Rx", "Ry", "Rz")) if not math.isfinite(poses[i, k])]
        if bad:
            raise CalibrationError("pair %d: %s %s NaN or inf" % (i, ", ".join(bad), "is" if len(bad) == 1 else "are"))
    for i in range(len(joints)):
        if np.max(np.abs(poses[i, :3])) < METRES_LIMIT_MM:
            raise CalibrationError(
                "pair %d: the position (%s) looks like metres (every |X|, |Y|, |Z| below %g mm while the arm "
                "reaches about 1.4 m): give the controller's millimetres"
                % (i, ", ".join("%g" % v for v in poses[i, :3]), METRES_LIMIT_MM))
    _check_radians(joints, poses, p, lever_mm)
    for i in range(len(joints)):
        for j in range(i + 1, len(joints)):
            if np.max(np.abs(joints[i] - joints[j])) < DUPLICATE_DEG:
                raise CalibrationError("pairs %d and %d are duplicates: the same joints (%s deg) twice; each pose "
                                       "must be distinct" % (i, j, ", ".join("%.2f" % v for v in joints[i])))
    dp, dr = _pair_errors(p, joints, poses)
    far = [i for i in range(len(joints)) if dp[i] > UNREACHABLE_MM or dr[i] > UNREACHABLE_DEG]
    if far:
        detail = "; ".join("pair %d: %.1f mm, %.2f deg" % (i, dp[i], dr[i]) for i in far[:5])
        raise CalibrationError(
            "unreachable pair%s %s: the reported pose is more than %g mm or %g deg from the nominal model's "
            "pose at the shown joints (%s%s) -- a typo, a swapped field, another TCP or user frame active on "
            "the controller?" % ("s" if len(far) > 1 else "", ", ".join(str(i) for i in far), UNREACHABLE_MM,
                                 UNREACHABLE_DEG, detail, "; ..." if len(far) > 5 else ""))


def _pair_errors(p: np.ndarray, joints_deg: np.ndarray, poses: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Per pair: position error [mm] and rotation error [deg] of the model ``p`` against the poses."""
    r = _residuals(p, np.radians(joints_deg), poses[:, :3], _matrices(np.radians(poses[:, 3:])), 1.0)
    return np.linalg.norm(r[:, :3], axis=1), np.degrees(np.linalg.norm(r[:, 3:], axis=1))


def pair_errors(params: Mapping[str, float], joints_deg: Any, poses: Any) -> Tuple[np.ndarray, np.ndarray]:
    """Per pair: how far the model ``params`` puts the TCP at the shown joints ``joints_deg`` (N, 6 deg)
    from the reported ``poses`` (N, 6: mm, deg): position [mm] and rotation angle [deg]."""
    joints = np.atleast_2d(np.asarray(joints_deg, dtype=float))
    reported = np.atleast_2d(np.asarray(poses, dtype=float))
    return _pair_errors(_vector(params), joints, reported)


def _check_radians(joints: np.ndarray, poses: np.ndarray, p: np.ndarray, lever_mm: float) -> None:
    """Joints or pose angles in radians: every value within +-2 pi (joints) / +-pi (pose angles), and
    the nominal model fits much better when they are read as radians."""
    joints_small = np.max(np.abs(joints)) <= 2.0 * math.pi + 1e-9
    angles_small = np.max(np.abs(poses[:, 3:])) <= math.pi + 1e-9
    if not (joints_small or angles_small):
        return

    def score(jq: np.ndarray, ps: np.ndarray) -> float:
        dp, dr = _pair_errors(p, jq, ps)
        return float(np.median(dp + dr * lever_mm * math.pi / 180.0))

    base = score(joints, poses)
    options = []
    if joints_small:
        options.append(("the joint angles", np.degrees(joints), poses))
    if angles_small:
        options.append(("the pose angles (Rx, Ry, Rz)", joints, np.hstack([poses[:, :3], np.degrees(poses[:, 3:])])))
    if joints_small and angles_small:
        options.append(("the joint angles and the pose angles", np.degrees(joints),
                        np.hstack([poses[:, :3], np.degrees(poses[:, 3:])])))
    best = min(options, key=lambda o: score(o[1], o[2]))
    better = score(best[1], best[2])
    if better < 0.2 * base and base > 20.0:
        raise CalibrationError("%s look like radians (all within +-%s, and the model fits them far better "
                               "read as radians: median error %.1f instead of %.1f mm-equivalent): give degrees, "
                               "as the pendant and the controller show them"
                               % (best[0], "2 pi" if best[0].startswith("the joint") else "pi", better, base))


# ============================================================================================== fit

@dataclass
class FitResult:
    """A calibration. Values in metres / radians; ``uncertainty`` is the standard uncertainty of each
    fitted parameter (same units); ``residuals_mm`` and ``residuals_deg`` are each pair's position and
    rotation error after the fit."""

    parameters: Parameters
    nominal: Parameters
    fitted: Tuple[str, ...]
    held: Dict[str, str]                  # name -> why
    uncertainty: Parameters
    residuals_mm: np.ndarray
    residuals_deg: np.ndarray
    sigma: float                          # RMS weighted residual [mm], corrected for the degrees of freedom
    singular_values: np.ndarray           # of the column-normalised Jacobian of the fitted parameters
    weakest: str                          # the least well determined combination
    n_pairs: int
    iterations: int
    lever_mm: float = LEVER_MM
    warnings: List[str] = field(default_factory=list)

    @property
    def rms_mm(self) -> float:
        return float(np.sqrt(np.mean(self.residuals_mm ** 2)))

    @property
    def max_mm(self) -> float:
        return float(np.max(self.residuals_mm))

    @property
    def rms_deg(self) -> float:
        return float(np.sqrt(np.mean(self.residuals_deg ** 2)))

    @property
    def max_deg(self) -> float:
        return float(np.max(self.residuals_deg))

    def change(self, name: str) -> float:
        return self.parameters[name] - self.nominal[name]

    def summary(self) -> str:
        lines = ["kinematic calibration from %d pairs (%d parameters fitted, %d iterations)"
                 % (self.n_pairs, len(self.fitted), self.iterations),
                 "residuals: position RMS %.3f mm, max %.3f mm; rotation RMS %.4f deg, max %.4f deg; sigma %.3f mm"
                 % (self.rms_mm, self.max_mm, self.rms_deg, self.max_deg, self.sigma)]
        for name in PARAMETERS:
            length = name in GEOMETRY
            k, unit = (1000.0, "mm") if length else (180.0 / math.pi, "deg")
            value = self.parameters[name] * k
            if name in self.held:
                lines.append("  %-16s %11.4f %s  HELD: %s" % (name, value, unit, self.held[name]))
            else:
                lines.append("  %-16s %11.4f %s  +- %.4f  (%+.4f from nominal)"
                             % (name, value, unit, self.uncertainty[name] * k, self.change(name) * k))
        lines.append("least determined: %s" % self.weakest)
        lines.extend("warning: " + w for w in self.warnings)
        return "\n".join(lines)


def fit(pairs: Any, nominal: Optional[Mapping[str, float]] = None, hold: Sequence[str] = (),
        lever_mm: float = LEVER_MM, max_iterations: int = 100) -> FitResult:
    """Fit the model's parameters to ``pairs``: (joints as the pendant shows them [deg], the pose the
    controller reports (X, Y, Z mm, Rx, Ry, Rz deg; a ControllerPose works too)), or dicts with
    ``joints`` and ``pose``. ``nominal``: the start and the value of every held parameter (default: the
    package's YAML); ``hold``: parameters to keep at their nominal value (the structurally
    undeterminable ones are added). Levenberg-Marquardt with the analytic Jacobian.

    Raises CalibrationError (before anything is written) for NaN / inf, values in metres or radians,
    duplicate pairs, unreachable pairs (more than 100 mm / 10 deg from the nominal model: a typo),
    fewer equations than needed (6 N must exceed the free parameters, so that sigma can be estimated),
    a degenerate set (a combination of parameters the poses cannot tell apart beyond the structural
    ones), and a fit that does not converge."""
    nominal = dict(nominal_parameters() if nominal is None else nominal)
    p0 = _vector(nominal)
    unknown = [h for h in hold if h not in PARAMETERS]
    if unknown:
        raise CalibrationError("cannot hold %s: not a parameter (%s)" % (", ".join(unknown), ", ".join(PARAMETERS)))
    if not (lever_mm > 0 and math.isfinite(lever_mm)):
        raise CalibrationError("lever_mm must be a positive number, got %r" % lever_mm)
    joints, poses = _as_arrays(pairs)
    if len(joints) == 0:
        raise CalibrationError("no pairs")
    _check_input(joints, poses, p0, lever_mm)

    held: Dict[str, str] = {h: "held on request" for h in hold}
    free = [i for i, n in enumerate(PARAMETERS) if n not in held]
    for name, reason in _structural_holds(p0, lever_mm, free):
        held[name] = reason
    free = [i for i, n in enumerate(PARAMETERS) if n not in held]
    n_free = len(free)
    if 6 * len(joints) <= n_free:
        raise CalibrationError(
            "too few pairs: %d pair(s) give %d equations for %d free parameters (%s); at least %d pairs are "
            "needed, %d or more (propose_poses) for a useful calibration"
            % (len(joints), 6 * len(joints), n_free, ", ".join(PARAMETERS[i] for i in free),
               n_free // 6 + 1, DEFAULT_POSES))

    q = np.radians(joints)
    pos_mm = poses[:, :3]
    rot = _matrices(np.radians(poses[:, 3:]))
    _check_rank(_jacobian(p0, q, lever_mm)[:, free], free)

    # Levenberg-Marquardt in the fit scale (mm, mrad)
    x = p0.copy()
    r = _residuals(x, q, pos_mm, rot, lever_mm).ravel()
    cost = float(r @ r)
    lam = 1e-3
    iterations = 0
    converged = False
    for iterations in range(1, max_iterations + 1):
        jac = _jacobian(x, q, lever_mm)[:, free]
        g = jac.T @ r
        a = jac.T @ jac
        while True:
            step = np.linalg.solve(a + lam * np.diag(np.diag(a)), -g)
            x_new = x.copy()
            x_new[free] += step * _SCALE[free]
            r_new = _residuals(x_new, q, pos_mm, rot, lever_mm).ravel()
            cost_new = float(r_new @ r_new)
            if cost_new <= cost:
                break
            lam *= 10.0
            if lam > 1e12:
                break
        if cost_new > cost:
            converged = True                                   # no descent left: at the minimum
            break
        small = np.max(np.abs(step)) < 1e-9                    # 1 pm / 1 prad
        x, r, cost = x_new, r_new, cost_new
        lam = max(lam / 10.0, 1e-12)
        if small:
            converged = True
            break
    if not converged:
        raise CalibrationError("the fit did not converge in %d iterations (cost %.3g mm^2)" % (max_iterations, cost))

    jac = _jacobian(x, q, lever_mm)[:, free]
    norms = np.linalg.norm(jac, axis=0)
    _, s, vt = np.linalg.svd(jac / norms, full_matrices=False)
    _check_rank(jac, free)
    dof = len(r) - n_free
    sigma = math.sqrt(cost / dof)
    cov = sigma ** 2 * np.linalg.inv(jac.T @ jac)
    std = np.sqrt(np.diag(cov)) * _SCALE[free]
    weak = vt[-1] / norms
    weak = weak / np.max(np.abs(weak))
    dp, dr = _pair_errors(x, joints, poses)
    result = FitResult(
        parameters={n: float(v) for n, v in zip(PARAMETERS, x)}, nominal={n: float(v) for n, v in zip(PARAMETERS, p0)},
        fitted=tuple(PARAMETERS[i] for i in free), held=held,
        uncertainty={PARAMETERS[i]: float(v) for i, v in zip(free, std)},
        residuals_mm=dp, residuals_deg=dr, sigma=sigma, singular_values=s,
        weakest="%s (singular value ratio %.2g)" % (_combination(weak, free), s[-1] / s[0]),
        n_pairs=len(joints), iterations=iterations, lever_mm=lever_mm)
    if result.max_mm > 1.0 or result.max_deg > 0.1:
        worst = int(np.argmax(dp + dr * lever_mm * math.pi / 180.0))
        result.warnings.append("large residuals after the fit (max %.2f mm, %.3f deg; worst pair %d): a misread "
                               "pair, a tool offset active, or a robot the model's structure does not describe"
                               % (result.max_mm, result.max_deg, worst))
    return result


def _check_rank(jac: np.ndarray, free: Sequence[int]) -> None:
    norms = np.linalg.norm(jac, axis=0)
    if np.any(norms == 0.0):
        names = [PARAMETERS[free[i]] for i in range(len(free)) if norms[i] == 0.0]
        raise CalibrationError("degenerate pose set: %s %s not move the TCP in any pair; measure other poses "
                               "(propose_poses)" % (", ".join(names), "does" if len(names) == 1 else "do"))
    _, s, vt = np.linalg.svd(jac / norms, full_matrices=False)
    weak = [k for k in range(len(s)) if s[k] < DEGENERATE_RCOND * s[0]]
    if weak:
        combos = []
        for k in weak:
            v = vt[k] / norms
            combos.append("%s (singular value ratio %.2g)" % (_combination(v / np.max(np.abs(v)), free), s[k] / s[0]))
        raise CalibrationError("degenerate pose set: the poses cannot tell apart the combination%s %s (below %g); "
                               "vary the joints more (propose_poses)"
                               % ("s" if len(combos) > 1 else "", "; ".join(combos), DEGENERATE_RCOND))


# ========================================================================================== proposal

def _feasible(p: np.ndarray, q: np.ndarray, min_z: float, min_radius: float, min_bend_deg: float) -> np.ndarray:
    """Which of the joint sets ``q`` (N, 6, rad, shown) are away from the singularities and the floor."""
    pos, _, axes, origins, dirs = _chain(p, q)
    t = q + p[7:][None]
    wrist = origins[:, 4]
    zb = p[6]
    ok = (pos[:, 2] + zb >= min_z) & (wrist[:, 2] + zb >= min_z)              # above the mounting surface
    ok &= np.hypot(wrist[:, 0], wrist[:, 1]) >= min_radius                    # shoulder singularity
    ok &= np.abs(np.sin(t[:, 4])) >= math.sin(math.radians(min_bend_deg))      # wrist singularity
    upper = dirs[:, 2]
    to_wrist = wrist - origins[:, 2]
    to_wrist /= np.linalg.norm(to_wrist, axis=1)[:, None]
    sin_elbow = np.linalg.norm(np.cross(upper, to_wrist), axis=1)
    ok &= sin_elbow >= math.sin(math.radians(min_bend_deg))                   # elbow stretched / folded
    return ok


def propose_poses(n: int = DEFAULT_POSES, nominal: Optional[Mapping[str, float]] = None, seed: int = 0,
                  pool: int = 1500, margin_deg: float = 10.0, max_abs_deg: float = 180.0, min_z: float = 0.3, min_radius: float = 0.4,
                  min_bend_deg: float = 15.0, lever_mm: float = LEVER_MM,
                  valid: Optional[Callable[[np.ndarray], bool]] = None) -> List[Tuple[float, ...]]:
    """``n`` joint configurations (degrees, whole degrees: what the operator jogs to, as the pendant
    shows them) that determine every determinable parameter well.

    Candidates: ``pool`` random joint sets within the YAML's limits less ``margin_deg`` and within
    +-``max_abs_deg`` (a wider turn of joints 4 to 6 adds nothing and is awkward to jog), the flange and
    the wrist centre at least ``min_z`` above the mounting surface, the wrist centre ``min_radius`` from
    the joint_1 axis, joint_5 and the elbow bent at least ``min_bend_deg`` (away from the wrist, shoulder
    and elbow singularities), and ``valid(q)`` (radians, when given: e.g. vr_driver's check of the arm
    against itself, which this package cannot import). Selection: greedy, each step the candidate that maximises the smallest
    eigenvalue of the information matrix J^T J of the free parameters (log det until it has full rank),
    then exchange passes. The default 12 poses (72 equations for 12 parameters) predict standard
    uncertainties of about 0.02 mm / 0.002 deg with the pendant's 0.01 display rounding
    (:func:`predicted_uncertainty`); reading 12 poses from the pendant takes about 20 minutes."""
    nominal = dict(nominal_parameters() if nominal is None else nominal)
    p = _vector(nominal)
    if n < 3:
        raise CalibrationError("propose at least 3 poses (12 parameters need more than 12 equations)")
    lower, upper = joint_limits()
    m = math.radians(margin_deg)
    lo = np.maximum(lower + m, -math.radians(max_abs_deg))
    hi = np.minimum(upper - m, math.radians(max_abs_deg))
    rng = np.random.default_rng(seed)
    cand = np.round(np.degrees(rng.uniform(lo, hi, size=(pool * 4, 6))))
    cand = cand[_feasible(p, np.radians(cand), min_z, min_radius, min_bend_deg)]
    if valid is not None:
        keep = []
        for k in range(len(cand)):
            if len(keep) >= pool:
                break
            if valid(np.radians(cand[k])):
                keep.append(k)
        cand = cand[keep]
    cand = cand[:pool]
    if len(cand) < n:
        raise CalibrationError("only %d feasible candidate poses; relax the constraints" % len(cand))
    free = [i for i, name in enumerate(PARAMETERS)
            if name not in dict(_structural_holds(p, lever_mm, list(range(_N))))]
    jac = _jacobian(p, np.radians(cand), lever_mm).reshape(len(cand), 6, _N)[:, :, free]
    info = np.einsum("kai,kaj->kij", jac, jac)                                 # per candidate J^T J
    eps = 1e-6 * float(np.mean(np.trace(info, axis1=1, axis2=2)))

    def score(a: np.ndarray) -> np.ndarray:
        ev = np.linalg.eigvalsh(a)
        full = ev[..., 0] > 1e-9 * ev[..., -1]
        logdet = np.sum(np.log(np.maximum(ev, 0.0) + eps), axis=-1)
        return np.where(full, 1e6 + ev[..., 0], logdet - 1e6)

    chosen: List[int] = []
    total = np.zeros((len(free), len(free)))
    for _ in range(n):
        s = score(total[None] + info)
        s[chosen] = -np.inf
        k = int(np.argmax(s))
        chosen.append(k)
        total = total + info[k]
    for _ in range(3):                                                         # exchange passes
        improved = False
        for slot in range(n):
            rest = total - info[chosen[slot]]
            s = score(rest[None] + info)
            s[chosen] = -np.inf
            k = int(np.argmax(s))
            if s[k] > score(total) + 1e-12:
                total = rest + info[k]
                chosen[slot] = k
                improved = True
        if not improved:
            break
    return [tuple(float(v) for v in cand[k]) for k in chosen]


def predicted_uncertainty(joints_deg: Any, nominal: Optional[Mapping[str, float]] = None,
                          joint_resolution_deg: float = 0.01, pose_resolution: float = 0.01,
                          lever_mm: float = LEVER_MM) -> Parameters:
    """The standard uncertainty of each determinable parameter from poses ``joints_deg`` when the only
    noise is the display rounding (uniform: resolution / sqrt(12)) of the joints and of the pose,
    propagated through the model (m / rad)."""
    nominal = dict(nominal_parameters() if nominal is None else nominal)
    p = _vector(nominal)
    q = np.radians(np.atleast_2d(np.asarray(joints_deg, dtype=float)))
    free = [i for i, name in enumerate(PARAMETERS)
            if name not in dict(_structural_holds(p, lever_mm, list(range(_N))))]
    jac = _jacobian(p, q, lever_mm)
    jp = jac[:, free]
    # a joint reading error moves the residual like the joint's zero offset (per pair, its own rows)
    sj = math.radians(joint_resolution_deg) / math.sqrt(12.0) / 1e-3            # in the offsets' fit scale
    cov_r = np.zeros((len(jac), len(jac)))
    for k in range(len(q)):
        rows = slice(6 * k, 6 * k + 6)
        jo = jac[rows, 7:]
        cov_r[rows, rows] = (sj ** 2) * jo @ jo.T
    sp = pose_resolution / math.sqrt(12.0)
    w = np.r_[np.ones(3), np.full(3, math.radians(1.0) * lever_mm)]
    cov_r += np.diag(np.tile((sp * w) ** 2, len(q)))
    a = np.linalg.pinv(jp)
    cov = a @ cov_r @ a.T
    std = np.sqrt(np.diag(cov)) * _SCALE[free]
    return {PARAMETERS[i]: float(v) for i, v in zip(free, std)}


# ============================================================================================== YAML

def _fmt(value: float, digits: int = 6) -> str:
    """``value`` with ``digits`` decimals (1 um / 1 urad), trailing zeros dropped, at least "0.0"."""
    text = ("%.*f" % (digits, value)).rstrip("0")
    text = text + "0" if text.endswith(".") else text
    return "0.0" if float(text) == 0.0 else text


def write_yaml(result: FitResult, path: str, model_path: str = YAML_PATH, date: Optional[str] = None) -> str:
    """Write a copy of the model YAML ``model_path`` to ``path`` with the fitted values: each fitted
    geometry entry gets its value, ``calibrate: false`` and a ``source`` "fitted from N poses on DATE,
    sigma ..." (its standard uncertainty); held entries stay as they are. The zero offsets go to a
    ``zero_offsets`` section (radians; added at the end, or updated). Every other line and comment is
    kept. Written atomically; returns the text."""
    date = date or datetime.date.today().isoformat()
    try:
        with open(model_path) as f:
            lines = f.read().splitlines()
    except OSError as exc:
        raise CalibrationError("cannot read %s: %s" % (model_path, exc.strerror or exc)) from exc

    carriers = _carriers(result.held)

    def source(name: str) -> str:
        length = name in GEOMETRY
        k, unit, fmt = (1000.0, "mm", "%.3f") if length else (180.0 / math.pi, "deg", "%.4f")
        note = "".join("; only %s - %s is determinable, %s held at %s" % (name, h, h, _fmt(result.parameters[h]))
                       for h in carriers.get(name, "").split(", ") if h)
        return (("fitted from %d poses on %s, sigma " + fmt + " %s (fit RMS %.3f mm / %.4f deg%s; "
                 "panasonic_vr006l_support.kinematic_calibration)")
                % (result.n_pairs, date, result.uncertainty[name] * k, unit, result.rms_mm, result.rms_deg, note))

    def update_entry(section: str, key: str, name: str) -> bool:
        """Rewrite value / source / calibrate of ``section.key`` in ``lines`` in place."""
        try:
            start = next(i for i, l in enumerate(lines) if l.rstrip().split("#")[0].rstrip() == section + ":")
        except StopIteration:
            return False
        entry = None
        for i in range(start + 1, len(lines)):
            l = lines[i]
            if l and not l.startswith(" ") and not l.startswith("#"):
                break                                           # the next top-level section
            if l.strip().split("#")[0].strip() == key + ":" and not l.startswith("    "):
                entry = i
                break
        if entry is None:
            return False
        indent = None
        seen = set()
        i = entry + 1
        while i < len(lines):
            l = lines[i]
            stripped = l.strip()
            if not stripped or stripped.startswith("#"):
                i += 1
                continue
            ind = len(l) - len(l.lstrip())
            if ind <= 2:
                break
            indent = indent if indent is not None else ind
            field_name = stripped.split(":", 1)[0]
            pad = " " * ind
            if field_name == "value":
                lines[i] = pad + "value: " + _fmt(result.parameters[name])
            elif field_name == "source":
                lines[i] = pad + "source: " + '"' + source(name) + '"'
            elif field_name == "calibrate":
                lines[i] = pad + "calibrate: false"
            seen.add(field_name)
            i += 1
        if not {"value", "source", "calibrate"} <= seen:
            return False
        return True

    ok = all(update_entry("geometry", name, name) for name in GEOMETRY if name in result.fitted)
    text = None
    if ok:
        # the zero offsets: drop an existing section, append a fresh one
        try:
            start = next(i for i, l in enumerate(lines) if l.startswith("zero_offsets:"))
            end = next((i for i in range(start + 1, len(lines))
                        if lines[i] and not lines[i].startswith(" ") and not lines[i].startswith("#")), len(lines))
            del lines[start:end]
        except StopIteration:
            pass
        while lines and not lines[-1].strip():
            lines.pop()
        lines += ["", "# Joint zero offsets [rad]: the true joint angle = the angle the pendant shows + the offset",
                  "# (kinematic_calibration); the URDF turns each joint's origin about its axis by it.",
                  "zero_offsets:"]
        for i, name in enumerate(OFFSETS):
            if name in result.fitted:
                lines += ["  joint_%d:" % (i + 1), "    value: " + _fmt(result.parameters[name], 7),
                          '    source: "%s"' % source(name), "    calibrate: false"]
            else:
                lines += ["  joint_%d:" % (i + 1), "    value: " + _fmt(result.parameters[name], 7),
                          '    source: "held: %s"' % result.held.get(name, "").replace('"', "'"),
                          "    calibrate: true"]
        text = "\n".join(lines) + "\n"
        check = yaml.safe_load(text)
        for name in GEOMETRY:
            if abs(float(check["geometry"][name]["value"]) - result.parameters[name]) > 1e-6:
                text = None
                break
    if text is None:
        # the structure was not what the line editor expects: rewrite the tree (the notes in `source`
        # survive, the comments do not)
        cfg = _load_yaml(model_path)
        for name in GEOMETRY:
            if name in result.fitted:
                cfg["geometry"][name].update(value=round(result.parameters[name], 6), source=source(name),
                                             calibrate=False)
        cfg["zero_offsets"] = {"joint_%d" % (i + 1): {"value": round(result.parameters[name], 6),
                                                      "source": source(name) if name in result.fitted else "held",
                                                      "calibrate": name not in result.fitted}
                               for i, name in enumerate(OFFSETS)}
        text = yaml.safe_dump(cfg, sort_keys=False)
    directory = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix=".kinematic_calibration.", dir=directory)
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return text


# =============================================================================================== CLI

def proposal_text(poses: Sequence[Sequence[float]], checked: str = "") -> str:
    """The proposed poses as ``propose`` prints them, with the predicted uncertainty (and ``checked``:
    a note on what the selection checked)."""
    lines = ["# %d poses: J1..J6 [deg] as the pendant shows them%s" % (len(poses), "; " + checked if checked else "")]
    lines += ["%2d: %s" % (i, " ".join("%7.1f" % v for v in q)) for i, q in enumerate(poses)]
    std = predicted_uncertainty(poses)
    lines.append("# predicted standard uncertainty with 0.01 display rounding: max %.3f mm, %.4f deg"
                 % (max(v for k, v in std.items() if k in GEOMETRY) * 1000.0,
                    math.degrees(max(v for k, v in std.items() if k in OFFSETS))))
    return "\n".join(lines)


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python3 -m panasonic_vr006l_support.kinematic_calibration",
        description="Kinematic calibration of the VR-006L model from (pendant joints, controller pose) pairs.")
    sub = parser.add_subparsers(dest="command")
    p_prop = sub.add_parser("propose", help="print the joint configurations to measure (deg)")
    p_prop.add_argument("-n", type=int, default=DEFAULT_POSES, help="number of poses (default %d)" % DEFAULT_POSES)
    p_prop.add_argument("--seed", type=int, default=0)
    p_fit = sub.add_parser("fit", help="fit the model to pairs (YAML or CSV) and print the result")
    p_fit.add_argument("pairs", help="YAML list of {joints: [deg], pose: [mm, deg]} or CSV of 12 numbers a line")
    p_fit.add_argument("--hold", nargs="*", default=[], help="parameters to keep at their nominal value")
    p_fit.add_argument("--model", default=YAML_PATH, help="the model YAML (default: the package's)")
    p_fit.add_argument("--write", metavar="OUT", help="write a copy of the model YAML with the fitted values")
    p_fit.add_argument("--xacro", metavar="OUT", help="with --write: also the generated xacro property of that "
                       "YAML (what urdf/vr006l_calibration.xacro holds for the package's own YAML)")
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_usage(sys.stderr)
        return 2
    try:
        if args.command == "propose":
            print(proposal_text(propose_poses(args.n, seed=args.seed), checked="not checked against the arm's "
                                "collision geometry: `rosrun vr_driver calibrate propose` is"))
            return 0
        if args.xacro and not args.write:
            raise CalibrationError("--xacro needs --write (the xacro is generated from the written YAML)")
        result = fit(load_pairs(args.pairs), nominal_parameters(args.model), hold=args.hold)
        print(result.summary())
        if args.write:
            write_yaml(result, args.write, model_path=args.model)
            print("wrote %s" % args.write)
        if args.xacro:
            from . import calibration
            try:
                text = calibration.xacro_text(calibration.load(args.write), os.path.basename(args.write))
            except calibration.CalibrationError as exc:
                raise CalibrationError("the written YAML gives no xacro property: %s" % exc) from None
            with open(args.xacro, "w") as f:
                f.write(text)
            print("wrote %s" % args.xacro)
        return 0
    except CalibrationError as exc:
        print("kinematic_calibration: error: %s" % exc, file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
