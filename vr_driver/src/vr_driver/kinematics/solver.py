"""Kinematics of the arm on PyKDL: our own URDF -> KDL chain builder, FK, IK, Jacobian. ROS-free.

The chain runs from the SRDF group's ``base_link`` to its ``tip_link`` (``base_link`` -> ``tool0``);
the IK time budget comes from MoveIt's ``kinematics.yaml`` (``kinematics_solver_timeout``).

IK strategy (``Kinematics.ik``):

1. Validate the target (finite, a rotation) and the seed (finite, right length; clamped into the
   limits, because KDL's NR_JL returns a seed outside the limits unchanged).
2. When the chain has the structure of a six-axis industrial arm with a spherical wrist (6 revolute
   joints; J2 parallel to J3 and perpendicular to J1; the axes of J4, J5, J6 meet in one point),
   an analytic solver built from the chain's zero-pose screw axes (generic, any such URDF) computes
   all 8 branches (shoulder front/back x elbow up/down x wrist flip). The reach check is part of it
   and costs a few microseconds. Each joint is then moved by +-2 pi towards the seed where the limits
   allow it (the wrist joints span more than 2 pi), out-of-limit branches are dropped, and the
   branch nearest the seed wins. The result is checked with KDL's FK (1e-6 m, 1e-6 rad) and, if it
   misses, polished by KDL NR_JL.
3. Otherwise (any other chain), KDL ``ChainIkSolverPos_NR_JL`` and then ``ChainIkSolverPos_LMA``
   (which converges more often but ignores the limits, so its joints are moved by full turns into
   the limits and re-checked) from the seed, then from random seeds (``random.Random``, seedable)
   until the time budget is spent, after a cheap reach check (distance to the target against the
   sum of the chain's link lengths). One solver run may overrun the budget (~1 ms at most).

Errors (vr_driver.errors): ``UnreachableError`` (outside the reach, with the distances),
``IkTimeoutError`` (numeric search exhausted), ``JointLimitError`` (reachable only outside the
limits, naming the joint), ``NearSingularError`` (when the caller sets ``min_manipulability``),
``PoseError`` (NaN, inf, wrong lengths, unknown joint names), ``ModelError`` (unusable description).

Command line (controller units: mm and degrees; joints in radians)::

    python3 -m vr_driver.kinematics.solver fk J1 J2 J3 J4 J5 J6
    python3 -m vr_driver.kinematics.solver ik X Y Z RX RY RZ [--seed J1 ... J6]

prints JSON ``{"joints", "pose", "reachable", "error"}``; exit 0 solved, 3 unreachable, 2 usage.
"""
from __future__ import annotations

import argparse
import contextlib
import enum
import functools
import json
import math
import os
import random
import sys
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from typing import Any, Dict, Iterator, List, Mapping, Optional, Sequence, Tuple

import numpy as np
import PyKDL as kdl
from panasonic_vr006l_support import joint_limits as _support_limits
from panasonic_vr006l_support import model as _support_model

from .. import validate
from ..errors import (IkTimeoutError, JointLimitError, KinematicsError, ModelError, NearSingularError, PoseError,
                     UnreachableError)
from ..poses import (ControllerPose, FrameConventions, check_transform, finite_number, rpy_to_matrix,
                    wrap_angle)

__all__ = [
    "UrdfJoint",
    "UrdfModel",
    "JointLimits",
    "IkSettings",
    "ConfigurationRule",
    "Kinematics",
    "build_kdl_chain",
    "read_srdf",
    "read_ik_settings",
    "model_accelerations",
    "main",
]

TWO_PI = 2.0 * math.pi
_MOVABLE = ("revolute", "continuous", "prismatic")
_GEOM_EPS = 1e-9           # tolerance of the structure detection (m, or unit-vector components)
#: [rad] track_pose: an IK solution this far from the seed in some joint is another configuration
TRACK_JUMP = math.radians(15.0)
#: [mm, deg] track_pose: how near the seed's pose must be to the reported one to stand for it (the
#: report is rounded to whole mm / deg: within 0.5 of the truth; 1 leaves room for Euler noise)
TRACK_NEAR = (1.0, 1.0)
#: [m, rad] track_pose: how near the configuration nearest an unreachable reported pose must put the
#: tip to stand for it (a pose rounded past the reach of the stretched-out arm: v3's 0.1 mm rounding)
TRACK_ROUNDING = (0.2e-3, math.radians(0.02))


# =========================================================================================== the URDF

#: one joint of the URDF (the support package's reader: origin 4x4, xyz, rpy, unit axis, limits)
UrdfJoint = _support_model.Joint


@contextlib.contextmanager
def _model_errors() -> Iterator[None]:
    """The support package's ModelError as ours (a VrDriverError), same message."""
    try:
        yield
    except _support_model.ModelError as exc:
        raise ModelError(str(exc)) from exc


class UrdfModel(_support_model.RobotModel):
    """The URDF as kinematics reads it: the support package's reader (:class:`RobotModel`), with
    vr_driver's ModelError and the joints KDL can chain (revolute, continuous, prismatic, fixed;
    no mimic joints)."""

    @classmethod
    def from_string(cls, xml: str) -> "UrdfModel":
        with _model_errors():
            model = cls.from_urdf_string(xml)
        for j in model.joints.values():
            what = "URDF joint %s" % j.name
            if j.type not in _MOVABLE + ("fixed",):
                raise ModelError("%s: joint type %r is not supported (revolute, continuous, prismatic, fixed)"
                                 % (what, j.type))
            if j.mimic:
                raise ModelError("%s: mimic joints are not supported" % what)
        return model

    def chain(self, base: str, tip: str) -> List[UrdfJoint]:
        with _model_errors():
            return super().chain(base, tip)

    def fixed_transform(self, frm: str, to: str) -> np.ndarray:
        with _model_errors():
            return super().fixed_transform(frm, to)


def build_kdl_chain(joints: Sequence[UrdfJoint]) -> "kdl.Chain":
    """A KDL chain from URDF joints in chain order, with the kdl_parser convention: one segment per
    joint, named after the child link, whose joint sits at the joint origin (axis rotated into the
    parent frame) and whose tip frame is the joint origin."""
    chain = kdl.Chain()
    for j in joints:
        m = rpy_to_matrix(*j.rpy)
        frame = kdl.Frame(kdl.Rotation(*[float(v) for v in m.reshape(-1)]), kdl.Vector(*j.xyz))
        if j.type == "fixed":
            kjoint = kdl.Joint(j.name, kdl.Joint.Fixed)
        else:
            kind = kdl.Joint.TransAxis if j.type == "prismatic" else kdl.Joint.RotAxis
            kjoint = kdl.Joint(j.name, frame.p, frame.M * kdl.Vector(*j.axis), kind)
        chain.addSegment(kdl.Segment(j.child, kjoint, frame))
    return chain


# ========================================================================= the controller's choice

class ConfigurationRule(enum.Enum):
    """Which of a Cartesian target's joint solutions (J1 front / back, elbow, wrist flip, J4..J6
    turns; near joint_5 = 0 the split of joint_4 / joint_6) a controller that solves the pose with
    its own IK takes -- the G2's rule is an assumption to check on a real G2
    (doc/controller_program.md §7, §10.9):

    - ``PREVIOUS_TARGET`` (the documented assumption): the solution nearest the joints of the
      previous target it took (the arm's joints when it has none: the first target, or none
      pending where the program keeps none);
    - ``CURRENT_JOINTS``: the solution nearest the arm's joints at the moment it takes the target.

    The two differ only where the arm is not at the previous target then: a target taken ahead
    while the arm is still on its way (v3's ring), or after a stop short of the previous one. The
    virtual G2 has it as a parameter (``configuration``); the driver applies the same rule to what
    it sent to know which joints the arm is at (:mod:`vr_driver.driver.tracking`)."""

    PREVIOUS_TARGET = "previous_target"
    CURRENT_JOINTS = "current_joints"

    #: a rule from itself or its name (``previous_target`` / ``current_joints``); PoseError naming
    #: both otherwise
    parse = validate.choice_parser(PoseError, "unknown configuration rule {value!r} ({words})")

    def seed(self, previous: Optional[Sequence[float]], current: Sequence[float]) -> Tuple[float, ...]:
        """The joints the IK solution is taken nearest to: ``previous`` (the previous target's, None
        when there is none) under PREVIOUS_TARGET, else ``current`` (the arm's)."""
        chosen = previous if self is ConfigurationRule.PREVIOUS_TARGET and previous is not None else current
        return tuple(float(v) for v in chosen)


# ===================================================================================== SRDF and YAML

def read_srdf(srdf_xml: str, group: str = "manipulator") -> Tuple[str, str, Dict[str, Dict[str, float]]]:
    """(base_link, tip_link, {state name: {joint: value}}) of a chain group of an SRDF."""
    try:
        root = ET.fromstring(srdf_xml)
    except ET.ParseError as exc:
        raise ModelError("the SRDF is not valid XML: %s" % exc) from exc
    base = tip = None
    for elem in root.findall("group"):
        if elem.get("name") == group:
            chain = elem.find("chain")
            if chain is None:
                raise ModelError("SRDF group %r has no <chain base_link tip_link>" % group)
            base, tip = chain.get("base_link"), chain.get("tip_link")
    if base is None or tip is None:
        raise ModelError("SRDF has no chain group %r" % group)
    states: Dict[str, Dict[str, float]] = {}
    for elem in root.findall("group_state"):
        if elem.get("group") == group:
            states[elem.get("name")] = {j.get("name"): float(j.get("value")) for j in elem.findall("joint")}
    return base, tip, states


@dataclass(frozen=True)
class IkSettings:
    """IK settings. ``timeout`` [s] is the whole budget of one IK call (MoveIt's
    ``kinematics_solver_timeout``). ``attempts`` (``kinematics_solver_attempts``) is read and kept:
    MoveIt repeats a failed search that many times; our numeric path instead restarts from random
    seeds until the one budget is spent, which covers the same need without multiplying the time.
    Tolerances: FK(IK(p)) must match p within ``position_tolerance`` [m] and
    ``orientation_tolerance`` [rad]."""

    timeout: float = 0.005
    attempts: int = 3
    position_tolerance: float = 1e-6
    orientation_tolerance: float = 1e-6
    nr_max_iterations: int = 100
    nr_eps: float = 1e-9

    def __post_init__(self) -> None:
        validate.number(self.timeout, lambda _: ModelError("IK timeout must be a positive number of seconds, got %r"
                                                           % (self.timeout,)), 0.0, lo_open=True, text=False)
        if int(self.attempts) < 1:
            raise ModelError("IK attempts must be >= 1, got %r" % self.attempts)


def read_ik_settings(yaml_text: str, group: str = "manipulator") -> IkSettings:
    """IkSettings from MoveIt's kinematics.yaml text (the given group's entry)."""
    import yaml

    try:
        data = yaml.safe_load(yaml_text) or {}
    except yaml.YAMLError as exc:
        raise ModelError("kinematics.yaml does not parse: %s" % exc) from exc
    entry = data.get(group)
    if not isinstance(entry, dict):
        raise ModelError("kinematics.yaml has no entry for group %r" % group)
    try:
        return IkSettings(timeout=float(entry.get("kinematics_solver_timeout", 0.005)),
                          attempts=int(entry.get("kinematics_solver_attempts", 3)))
    except (TypeError, ValueError) as exc:
        raise ModelError("kinematics.yaml group %r: bad solver setting: %s" % (group, exc)) from exc


@dataclass(frozen=True)
class JointLimits:
    """Per joint, in chain order: position limits and velocity [rad/s] from the URDF; acceleration
    [rad/s^2] from the model's one set (panasonic_vr006l_support's kinematics_vr006l.yaml: an
    assumption, velocity / 0.1 s, to measure on the real arm), inf for a joint the set does not name."""

    names: Tuple[str, ...]
    lower: Tuple[float, ...]
    upper: Tuple[float, ...]
    velocity: Tuple[float, ...]
    revolute: Tuple[bool, ...]
    acceleration: Tuple[float, ...] = ()

    @property
    def ramp_time(self) -> Optional[float]:
        """[s] from rest to full speed of the slowest-ramping joint (max velocity / acceleration over
        the joints with both finite, rounded to 1 ns); None when no joint has an acceleration."""
        try:
            return _support_limits.ramp_time(self.velocity, self.acceleration)
        except _support_limits.LimitsError:
            return None


@functools.lru_cache(maxsize=None)
def model_accelerations() -> Dict[str, float]:
    """{joint name: acceleration [rad/s^2]} of the model's set (the support package's YAML, read once)."""
    try:
        return dict(_support_limits.accelerations())
    except _support_limits.LimitsError as exc:
        raise ModelError(str(exc)) from exc


# ====================================================================== small pure-Python 3-D helpers
# The analytic solver runs in tens of microseconds only with plain floats (numpy calls cost ~1 us each).

def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _norm(a):
    return math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


def _rotate(axis, angle, v):
    """Rodrigues: v rotated about the unit ``axis`` by ``angle``."""
    c, s = math.cos(angle), math.sin(angle)
    kx, ky, kz = axis
    cx, cy, cz = ky * v[2] - kz * v[1], kz * v[0] - kx * v[2], kx * v[1] - ky * v[0]
    d = (kx * v[0] + ky * v[1] + kz * v[2]) * (1.0 - c)
    return (v[0] * c + cx * s + kx * d, v[1] * c + cy * s + ky * d, v[2] * c + cz * s + kz * d)


def _mv(a, v):
    return (a[0] * v[0] + a[1] * v[1] + a[2] * v[2], a[3] * v[0] + a[4] * v[1] + a[5] * v[2],
            a[6] * v[0] + a[7] * v[1] + a[8] * v[2])


def _angle_about(axis, frm, to):
    """The angle that rotates ``frm`` onto ``to`` about ``axis`` (both projected onto the plane
    normal to the axis); None when ``frm`` is (nearly) parallel to the axis."""
    fp = _sub(frm, tuple(axis[i] * _dot(axis, frm) for i in range(3)))
    if _norm(fp) < 1e-9:
        return None
    return math.atan2(_dot(axis, _cross(fp, to)), _dot(fp, to))


def stretched_elbow(kin: "Kinematics") -> Optional[float]:
    """[rad] joint_3 where the arm is stretched out (the shoulder, the elbow and the wrist centre in
    a line, the two elbow branches of a pose meet: near it a pose hardly fixes joint_2 / joint_3 and
    the nearest-solution IK of a controller may take the other branch); None without the analytic
    solver (an arm of another shape)."""
    solver = getattr(kin, "_analytic", None)
    if solver is None:
        return None
    return math.remainder(solver.phi2 - solver.phiw + math.pi, 2.0 * math.pi)


class _AnalyticSolver:
    """Closed-form IK of a 6R arm with J2 || J3 _|_ J1 and a spherical wrist, from the zero-pose screw
    axes of the chain (product of exponentials: T(q) = e^[a1]q1 ... e^[a6]q6 M)."""

    def __init__(self, axes, points, tip_zero: np.ndarray):
        a = [tuple(float(c) for c in ax) for ax in axes]
        p = [tuple(float(c) for c in pt) for pt in points]
        self.a = a
        # the wrist centre: where the axes of J4 and J5 meet
        self.w0 = _closest_point(p[3], a[3], p[4], a[4])
        self.s23 = 1.0 if _dot(a[1], a[2]) > 0 else -1.0
        self.p1 = p[0]
        self.a1xa2 = _cross(a[0], a[1])
        self.d1 = _dot(a[1], _sub(self.w0, p[0]))
        # plane of the arm (normal a2): basis e1, e2 with e1 x e2 = a2
        e1 = a[0]
        e2 = _cross(a[1], e1)
        self.e1, self.e2 = e1, e2
        c2 = (_dot(e1, p[1]), _dot(e2, p[1]))
        c3 = (_dot(e1, p[2]), _dot(e2, p[2]))
        w0 = (_dot(e1, self.w0), _dot(e2, self.w0))
        self.c2, self.c3, self.w0p = c2, c3, w0
        self.l2 = math.hypot(c3[0] - c2[0], c3[1] - c2[1])
        self.r3 = math.hypot(w0[0] - c3[0], w0[1] - c3[1])
        self.phi2 = math.atan2(c2[1] - c3[1], c2[0] - c3[0])
        self.phiw = math.atan2(w0[1] - c3[1], w0[0] - c3[0])
        # tip (M) at zero: rotation and the wrist centre seen from the tip
        mr = tip_zero[:3, :3]
        self.w_in_tip = tuple(float(v) for v in (mr.T @ (np.array(self.w0) - tip_zero[:3, 3])))
        # wrist: subproblem-2 constants (rotate a6 by J4 then J5)
        a4, a5, a6 = a[3], a[4], a[5]
        self.c45 = _dot(a4, a5)
        self.n45 = _norm(_cross(a4, a5)) ** 2
        self.a4xa5 = _cross(a4, a5)
        self.beta_num = _dot(a5, a6)
        # a unit vector normal to a6 (for q6)
        helper = (1.0, 0.0, 0.0) if abs(a6[0]) < 0.9 else (0.0, 1.0, 0.0)
        v = _cross(a6, helper)
        n = _norm(v)
        self.v6 = (v[0] / n, v[1] / n, v[2] / n)
        self.m_a6 = tuple(float(c) for c in mr.T @ np.array(a6))
        self.m_v6 = tuple(float(c) for c in mr.T @ np.array(self.v6))
        self.reach_min = abs(self.l2 - self.r3)
        self.reach_max = self.l2 + self.r3

    def solve(self, r, p, seed, lower, upper):
        """All branches for the tip rotation ``r`` (row-major 9-tuple) and position ``p``, each joint
        moved by +-2 pi towards ``seed`` within [lower, upper].

        Returns (candidates sorted by squared distance to the seed as (distance, q), number of
        geometric branches, [(joint index, value) that broke a limit], reason when none exists).
        """
        a = self.a
        a1, a2, a4, a5, a6 = a[0], a[1], a[3], a[4], a[5]
        wt = self.w_in_tip
        w = (p[0] + r[0] * wt[0] + r[1] * wt[1] + r[2] * wt[2],
             p[1] + r[3] * wt[0] + r[4] * wt[1] + r[5] * wt[2],
             p[2] + r[6] * wt[0] + r[7] * wt[1] + r[8] * wt[2])
        ta = _mv(r, self.m_a6)               # R_target M_R^T a6: where the J6 axis must point
        tv = _mv(r, self.m_v6)               # ... and a vector normal to it (for q6)
        p1 = self.p1
        u = (w[0] - p1[0], w[1] - p1[1], w[2] - p1[2])
        aa = _dot(a2, u)
        bb = _dot(self.a1xa2, u)
        rr = math.hypot(aa, bb)
        d = self.d1
        if rr < 1e-9:
            if abs(d) > 1e-9:
                return [], 0, [], "the wrist centre is on the joint_1 axis but the arm is offset sideways"
            q1s = (seed[0], seed[0] + math.pi)                  # shoulder singularity: keep the seed's q1
        else:
            if abs(d) > rr:
                return [], 0, [], ("the wrist centre is %.4f m from the joint_1 axis, closer than the "
                                   "arm's lateral offset %.4f m" % (rr, abs(d)))
            phi = math.atan2(bb, aa)
            delta = math.acos(d / rr)
            q1s = (phi + delta, phi - delta) if delta > 1e-12 else (phi,)
        e1, e2, c2, c3 = self.e1, self.e2, self.c2, self.c3
        l2, r3, phiw, s23 = self.l2, self.r3, self.phiw, self.s23
        q3_base = self.phi2 - phiw
        c45, n45, a4xa5, bnum = self.c45, self.n45, self.a4xa5, self.beta_num
        den = c45 * c45 - 1.0
        v6 = self.v6
        cands = []
        rejected = []
        n_raw = 0
        reason = ""
        miss = math.inf
        s0, s1, s2, s3, s4, s5 = seed
        for q1 in q1s:
            x = _rotate(a1, -q1, u)
            xp0 = e1[0] * x[0] + e1[1] * x[1] + e1[2] * x[2] + _dot(e1, p1) - c2[0]
            xp1 = e2[0] * x[0] + e2[1] * x[1] + e2[2] * x[2] + _dot(e2, p1) - c2[1]
            dist2 = xp0 * xp0 + xp1 * xp1
            cos_psi = (l2 * l2 + r3 * r3 - dist2) / (2.0 * l2 * r3)
            if cos_psi > 1.0 + 1e-12 or cos_psi < -1.0 - 1e-12:
                # the branch that misses by least says why (J1 turned back is often far off)
                if abs(cos_psi) - 1.0 < miss:
                    miss = abs(cos_psi) - 1.0
                    dist = math.sqrt(dist2)
                    off = dist - self.reach_max if cos_psi < 0.0 else self.reach_min - dist
                    reason = ("the wrist centre is %.4f m from the shoulder (joint_2 axis), %.2f mm %s; the arm "
                              "reaches %.4f ... %.4f m" % (dist, off * 1000.0, "beyond its reach" if cos_psi < 0.0
                                                           else "too close", self.reach_min, self.reach_max))
                continue
            psi = math.acos(max(-1.0, min(1.0, cos_psi)))
            j1 = _turn(q1, s0, lower[0], upper[0])
            ta1 = _rotate(a1, -q1, ta)
            tv1 = _rotate(a1, -q1, tv)
            ang_x = math.atan2(xp1, xp0)
            for q3 in ((q3_base + psi, q3_base - psi) if psi > 1e-12 else (q3_base,)):
                ang = phiw + q3
                q2 = ang_x - math.atan2(c3[1] + r3 * math.sin(ang) - c2[1], c3[0] + r3 * math.cos(ang) - c2[0])
                n_raw += 2
                if j1 is None:
                    rejected.append((0, q1))
                    continue
                j2 = _turn(q2, s1, lower[1], upper[1])
                if j2 is None:
                    rejected.append((1, q2))
                    continue
                j3 = _turn(q3, s2, lower[2], upper[2])
                if j3 is None:
                    rejected.append((2, q3))
                    continue
                arm_d = (j1 - s0) ** 2 + (j2 - s1) ** 2 + (j3 - s2) ** 2
                # wrist: R4 R5 R6 = rw; first put a6 onto t (Paden-Kahan subproblem 2), then q6
                q23 = -(q2 + s23 * q3)
                t = _rotate(a2, q23, ta1)
                vt = _rotate(a2, q23, tv1)
                a4t = _dot(a4, t)
                alpha = (c45 * bnum - a4t) / den
                beta = (c45 * a4t - bnum) / den
                g2 = (1.0 - alpha * alpha - beta * beta - 2.0 * alpha * beta * c45) / n45
                if g2 < -1e-9:
                    n_raw -= 2
                    reason = reason or "the wrist cannot reach the orientation"
                    continue
                g = math.sqrt(g2) if g2 > 0.0 else 0.0
                for gamma in ((g, -g) if g > 1e-9 else (0.0,)):
                    z = (alpha * a4[0] + beta * a5[0] + gamma * a4xa5[0],
                         alpha * a4[1] + beta * a5[1] + gamma * a4xa5[1],
                         alpha * a4[2] + beta * a5[2] + gamma * a4xa5[2])
                    q4 = _angle_about(a4, z, t)
                    singular = q4 is None
                    if singular:                                 # wrist singularity: keep the seed's q4
                        q4 = s3
                        z = _rotate(a4, -q4, t)
                    q5 = _angle_about(a5, a6, z)
                    if q5 is None:
                        continue
                    v = _rotate(a5, -q5, _rotate(a4, -q4, vt))
                    q6 = _angle_about(a6, v6, v)
                    j4 = _turn(q4, s3, lower[3], upper[3])
                    j5 = _turn(q5, s4, lower[4], upper[4])
                    j6 = _turn(q6, s5, lower[5], upper[5])
                    if j4 is None or j5 is None or j6 is None:
                        bad = 3 if j4 is None else 4 if j5 is None else 5
                        rejected.append((bad, (q4, q5, q6)[bad - 3]))
                    else:
                        cands.append((arm_d + (j4 - s3) ** 2 + (j5 - s4) ** 2 + (j6 - s5) ** 2,
                                      (j1, j2, j3, j4, j5, j6)))
                    if singular:
                        break
        cands.sort()
        return cands, n_raw, rejected, reason


def _turn(v, s, lo, hi):
    """``v`` plus the multiple of 2 pi nearest ``s`` that lies within [lo, hi] (None if none)."""
    k = round((s - v) / TWO_PI)
    c = v + k * TWO_PI
    if lo - 1e-9 <= c <= hi + 1e-9:
        return hi if c > hi else lo if c < lo else c
    best = None
    for c2 in (c - TWO_PI, c + TWO_PI):
        if lo - 1e-9 <= c2 <= hi + 1e-9 and (best is None or abs(c2 - s) < abs(best - s)):
            best = hi if c2 > hi else lo if c2 < lo else c2
    return best


def _product(choices: Sequence[Sequence[float]]) -> Iterator[Tuple[float, ...]]:
    """Every combination of one value per entry of ``choices`` (itertools.product, as tuples)."""
    import itertools
    return (tuple(c) for c in itertools.product(*choices))


def _closest_point(p1, a1, p2, a2):
    """The midpoint of the common normal of two lines (point, unit direction)."""
    w = _sub(p1, p2)
    b = _dot(a1, a2)
    den = 1.0 - b * b
    if den < 1e-12:
        return p1
    d, e = _dot(a1, w), _dot(a2, w)
    s = (b * e - d) / den
    t = (e - b * d) / den
    x1 = (p1[0] + s * a1[0], p1[1] + s * a1[1], p1[2] + s * a1[2])
    x2 = (p2[0] + t * a2[0], p2[1] + t * a2[1], p2[2] + t * a2[2])
    return ((x1[0] + x2[0]) / 2, (x1[1] + x2[1]) / 2, (x1[2] + x2[2]) / 2)


def _line_distance(point, p, a):
    v = _sub(point, p)
    return _norm(_cross(v, a))


def _detect_analytic(axes, points, types) -> Tuple[bool, str]:
    """Whether the analytic solver applies, and why not."""
    if len(axes) != 6 or any(t not in ("revolute", "continuous") for t in types):
        return False, "the chain is not six revolute joints"
    a, p = axes, points
    if abs(_dot(a[0], a[1])) > _GEOM_EPS:
        return False, "joint 2 is not perpendicular to joint 1"
    if _norm(_cross(a[1], a[2])) > _GEOM_EPS:
        return False, "joint 3 is not parallel to joint 2"
    if _norm(_cross(a[3], a[4])) < 1e-6 or _norm(_cross(a[4], a[5])) < 1e-6:
        return False, "wrist axes 4/5 or 5/6 are parallel"
    w0 = _closest_point(p[3], a[3], p[4], a[4])
    if _line_distance(w0, p[3], a[3]) > _GEOM_EPS or _line_distance(w0, p[4], a[4]) > _GEOM_EPS:
        return False, "wrist axes 4 and 5 do not intersect"
    if _line_distance(w0, p[5], a[5]) > _GEOM_EPS:
        return False, "wrist axis 6 does not pass through the wrist centre"
    if _line_distance(p[2], p[1], a[1]) < 1e-6:
        return False, "joint 2 and joint 3 axes coincide"
    return True, ""


# ======================================================================================== Kinematics

class Kinematics:
    """FK, IK, Jacobian of one chain of a URDF, on PyKDL. Build with :meth:`from_urdf_string`,
    :meth:`from_files` or :meth:`default`. Joint vectors are sequences of floats in chain order."""

    def __init__(self, model: UrdfModel, base: str, tip: str, settings: Optional[IkSettings] = None,
                 named_states: Optional[Mapping[str, Mapping[str, float]]] = None,
                 conventions: Optional[FrameConventions] = None, analytic: bool = True,
                 prefix: str = "", accelerations: Optional[Mapping[str, float]] = None):
        self.model = model
        self.prefix = prefix          # of every link and joint name (the URDF's xacro prefix)
        self.base, self.tip = base, tip
        self.settings = settings or IkSettings()
        self.chain_joints = model.chain(base, tip)
        movable = [j for j in self.chain_joints if j.movable]
        if not movable:
            raise ModelError("the chain %s -> %s has no movable joint" % (base, tip))
        self.limits = JointLimits(
            names=tuple(j.name for j in movable),
            lower=tuple(-math.inf if j.lower is None else j.lower for j in movable),
            upper=tuple(math.inf if j.upper is None else j.upper for j in movable),
            velocity=tuple(math.inf if j.velocity is None else j.velocity for j in movable),
            revolute=tuple(j.type != "prismatic" for j in movable),
            acceleration=self._accelerations(movable, prefix, accelerations))
        self.joint_names = self.limits.names
        self.dof = len(movable)
        self.chain = build_kdl_chain(self.chain_joints)
        self._fk = kdl.ChainFkSolverPos_recursive(self.chain)
        self._jac = kdl.ChainJntToJacSolver(self.chain)
        self._q_min = self._jnt(self.limits.lower, clip=True)
        self._q_max = self._jnt(self.limits.upper, clip=True)
        self._vel = kdl.ChainIkSolverVel_pinv(self.chain)
        self._nr_jl = kdl.ChainIkSolverPos_NR_JL(self.chain, self._q_min, self._q_max, self._fk, self._vel,
                                                 self.settings.nr_max_iterations, self.settings.nr_eps)
        self._lma = kdl.ChainIkSolverPos_LMA(self.chain, 1e-10, 500, 1e-15)
        self.named_states = {name: self.joint_vector(values) for name, values in (named_states or {}).items()}
        self.conventions = conventions or self._default_conventions()
        # zero-pose screw axes (root frame) and reach bound
        axes, points, t = [], [], np.eye(4)
        reach = 0.0
        for j in self.chain_joints:
            o = j.origin
            reach += float(np.linalg.norm(o[:3, 3]))
            t = t @ o
            if j.movable:
                axes.append(tuple(t[:3, :3] @ np.array(j.axis)))
                points.append(tuple(t[:3, 3]))
        self._zero_tip = t
        self.reach_bound = reach
        self._first_point = points[0]
        ok, why = _detect_analytic(axes, points, [j.type for j in movable])
        self.analytic_reason = why
        self._analytic = _AnalyticSolver(axes, points, t) if (ok and analytic) else None

    @staticmethod
    def _accelerations(movable: Sequence[UrdfJoint], prefix: str,
                       given: Optional[Mapping[str, float]]) -> Tuple[float, ...]:
        """Each joint's acceleration limit: from ``given`` ({joint name: rad/s^2}, the URDF's names),
        else from the model's set by the joint's name without ``prefix``; inf where none is known."""
        out = []
        for j in movable:
            if given is not None:
                value = given.get(j.name, math.inf)
            else:
                plain = j.name[len(prefix):] if prefix and j.name.startswith(prefix) else j.name
                value = model_accelerations().get(plain, math.inf)
            if not (isinstance(value, (int, float)) and not isinstance(value, bool) and value > 0.0
                    and not math.isnan(value)):
                raise ModelError("joint %s: acceleration limit must be a number > 0, got %r" % (j.name, value))
            out.append(float(value))
        return tuple(out)

    # ------------------------------------------------------------------------------------ factories
    @classmethod
    def from_urdf_string(cls, xml: str, srdf_xml: Optional[str] = None, kinematics_yaml: Optional[str] = None,
                         group: str = "manipulator", base: Optional[str] = None, tip: Optional[str] = None,
                         prefix: str = "", **kwargs: Any) -> "Kinematics":
        """From URDF text; base/tip from the SRDF group (else ``base``/``tip``, else base_link/tool0);
        IK settings from kinematics.yaml text (else defaults).

        ``prefix``: the URDF's names carry this prefix (several robots in one cell) while the SRDF
        names the plain ones: the chain runs ``<prefix>base_link`` -> ``<prefix>tool0``, the SRDF's
        named states and the ``base`` / ``flange`` frames are looked up with the prefix too.
        ``base`` / ``tip`` given explicitly are used as they are."""
        model = UrdfModel.from_string(xml)
        states: Dict[str, Dict[str, float]] = {}
        if srdf_xml is not None:
            s_base, s_tip, s_states = read_srdf(srdf_xml, group)
            base, tip = base or prefix + s_base, tip or prefix + s_tip
            states = {name: {prefix + joint: value for joint, value in values.items()}
                      for name, values in s_states.items()}
        settings = kwargs.pop("settings", None)
        if settings is None and kinematics_yaml is not None:
            settings = read_ik_settings(kinematics_yaml, group)
        return cls(model, base or prefix + "base_link", tip or prefix + "tool0", settings, states,
                   prefix=prefix, **kwargs)

    @classmethod
    def from_files(cls, urdf_path: str, srdf_path: Optional[str] = None, kinematics_yaml_path: Optional[str] = None,
                   **kwargs: Any) -> "Kinematics":
        """From files; a ``.xacro`` URDF is rendered with panasonic_vr006l_support's xacro wrapper
        (with the xacro argument ``prefix`` when ``prefix=`` is given: see :meth:`from_urdf_string`)."""
        def read(path: Optional[str]) -> Optional[str]:
            if path is None:
                return None
            try:
                with open(path) as f:
                    return f.read()
            except OSError as exc:
                raise ModelError("cannot read %s: %s" % (path, exc)) from exc

        if urdf_path.endswith(".xacro"):
            from panasonic_vr006l_support.description import DescriptionError, render_urdf
            try:
                xml = render_urdf(urdf_path, {"prefix": kwargs["prefix"]} if kwargs.get("prefix") else None)
            except DescriptionError as exc:
                raise ModelError(str(exc)) from exc
        else:
            xml = read(urdf_path)
        return cls.from_urdf_string(xml, read(srdf_path), read(kinematics_yaml_path), **kwargs)

    @classmethod
    def default(cls, **kwargs: Any) -> "Kinematics":
        """The VR-006L: the support package's xacro, the moveit_config's SRDF and kinematics.yaml
        (``prefix="left_"``: the xacro rendered with that prefix, the chain and limits read from
        ``left_base_link`` -> ``left_tool0``)."""
        from panasonic_vr006l_support.description import default_xacro_path, package_dir
        moveit = os.path.join(os.path.dirname(package_dir()), "panasonic_vr006l_moveit_config", "config")
        return cls.from_files(default_xacro_path(), os.path.join(moveit, "panasonic_vr006l.srdf"),
                              os.path.join(moveit, "kinematics.yaml"), **kwargs)

    @classmethod
    def from_true_model(cls, path: Optional[str] = None, **kwargs: Any) -> "Kinematics":
        """The kinematics of a "true" VR-006L whose dimensions, joint limits and joint zero offsets
        come from ``path`` (panasonic_vr006l_support.true_model: the layout of kinematics_vr006l.yaml,
        plus ``zero_offset`` per joint; the joint variables are the controller's angles, ``q_true -
        zero_offset``); None or "": exactly :meth:`default`. The SRDF, kinematics.yaml and (unless
        the file gives every joint's ``acceleration``) the accelerations are the model's. Raises
        ModelError naming the file and the key."""
        if not path:
            return cls.default(**kwargs)
        from panasonic_vr006l_support import true_model
        from panasonic_vr006l_support.description import DescriptionError, package_dir
        try:
            model = true_model.load(path)
            xml = true_model.render_urdf(model, kwargs.get("prefix", ""))
        except (true_model.TrueModelError, DescriptionError) as exc:
            raise ModelError(str(exc)) from exc
        moveit = os.path.join(os.path.dirname(package_dir()), "panasonic_vr006l_moveit_config", "config")

        def read(name: str) -> str:
            try:
                with open(os.path.join(moveit, name)) as f:
                    return f.read()
            except OSError as exc:
                raise ModelError("cannot read %s: %s" % (os.path.join(moveit, name), exc)) from exc

        acc = model.accelerations
        if acc is not None and "accelerations" not in kwargs:
            kwargs["accelerations"] = {kwargs.get("prefix", "") + name: v for name, v in acc.items()}
        return cls.from_urdf_string(xml, read("panasonic_vr006l.srdf"), read("kinematics.yaml"), **kwargs)

    def _default_conventions(self) -> FrameConventions:
        """``base`` in the chain root and ``flange`` in the chain tip, from the URDF when present."""
        links = self.model.links
        base, flange = self.prefix + "base", self.prefix + "flange"
        base_in_root = self.model.fixed_transform(self.base, base) if base in links else np.eye(4)
        flange_in_tip = self.model.fixed_transform(self.tip, flange) if flange in links else np.eye(4)
        return FrameConventions(base_in_root, flange_in_tip)

    @property
    def has_analytic_solver(self) -> bool:
        return self._analytic is not None

    # ------------------------------------------------------------------------------- joint vectors
    def _jnt(self, values: Sequence[float], clip: bool = False) -> "kdl.JntArray":
        q = kdl.JntArray(self.dof)
        if clip:                                   # infinite limits (continuous joints) -> large finite
            for i, v in enumerate(values):
                q[i] = max(-1e10, min(1e10, v))
        else:
            for i, v in enumerate(values):
                q[i] = v
        return q

    def joint_vector(self, values: Any) -> Tuple[float, ...]:
        """A validated joint vector (tuple of floats) from a sequence in chain order or a mapping
        ``{joint name: value}`` naming every joint; PoseError otherwise."""
        if isinstance(values, Mapping):
            unknown = set(values) - set(self.joint_names)
            if unknown:
                raise PoseError("unknown joint names %s (the chain's joints: %s)"
                                % (sorted(unknown), ", ".join(self.joint_names)))
            missing = [n for n in self.joint_names if n not in values]
            if missing:
                raise PoseError("missing joints %s" % missing)
            values = [values[n] for n in self.joint_names]
        try:
            items = list(values)
        except TypeError as exc:
            raise PoseError("joints must be a sequence of %d numbers, got %r" % (self.dof, values)) from exc
        if len(items) != self.dof:
            raise PoseError("joints must have %d values (%s), got %d"
                            % (self.dof, ", ".join(self.joint_names), len(items)))
        return tuple(finite_number(v, name) for name, v in zip(self.joint_names, items))

    def limit_violations(self, q: Sequence[float], tol: float = 1e-9) -> List[str]:
        lim = self.limits
        return ["%s = %.6g outside [%.6g, %.6g]" % (n, v, lo, hi)
                for n, v, lo, hi in zip(lim.names, q, lim.lower, lim.upper) if not lo - tol <= v <= hi + tol]

    def check_limits(self, q: Sequence[float], tol: float = 1e-9) -> Tuple[float, ...]:
        """``q`` validated; JointLimitError naming every joint outside its limits."""
        q = self.joint_vector(q)
        bad = self.limit_violations(q, tol)
        if bad:
            raise JointLimitError("joints outside their limits: " + "; ".join(bad))
        return q

    def clamp(self, q: Sequence[float]) -> Tuple[float, ...]:
        return tuple(min(max(v, lo), hi) for v, lo, hi in zip(q, self.limits.lower, self.limits.upper))

    def random_joints(self, rng: random.Random) -> Tuple[float, ...]:
        """Uniform within the limits (continuous joints: within +-pi)."""
        return tuple(rng.uniform(max(lo, -math.pi) if not math.isfinite(lo) else lo,
                                 min(hi, math.pi) if not math.isfinite(hi) else hi)
                     for lo, hi in zip(self.limits.lower, self.limits.upper))

    # ------------------------------------------------------------------------------------------ FK
    def fk_frame(self, q: Sequence[float]) -> "kdl.Frame":
        """Tip frame in the chain root as a ``PyKDL.Frame`` (no validation: the fast path)."""
        f = kdl.Frame()
        if self._fk.JntToCart(self._jnt(q), f) < 0:
            raise KinematicsError("KDL forward kinematics failed for %r" % (tuple(q),))
        return f

    def fk(self, q: Sequence[float]) -> np.ndarray:
        """Tip (``tool0``) pose in the chain root (``base_link``), 4x4 in metres."""
        q = self.joint_vector(q)
        f = self.fk_frame(q)
        m, p = f.M, f.p
        return np.array([[m[0, 0], m[0, 1], m[0, 2], p[0]], [m[1, 0], m[1, 1], m[1, 2], p[1]],
                         [m[2, 0], m[2, 1], m[2, 2], p[2]], [0.0, 0.0, 0.0, 1.0]])

    def fk_pose(self, q: Sequence[float]) -> ControllerPose:
        """The controller pose (TCP in ``base``, mm / deg) at joints ``q``."""
        return self.conventions.tip_to_controller(self.fk(q))

    # -------------------------------------------------------------------------------- Jacobian
    def jacobian(self, q: Sequence[float]) -> np.ndarray:
        """6 x dof Jacobian (linear rows first) of the tip origin, in the root frame."""
        q = self.joint_vector(q)
        jac = kdl.Jacobian(self.dof)
        self._jac.JntToJac(self._jnt(q), jac)
        return np.array([[jac[r, c] for c in range(self.dof)] for r in range(6)])

    def manipulability(self, q: Sequence[float]) -> float:
        """Yoshikawa's measure sqrt(det(J J^T)) (0 at a singularity)."""
        j = self.jacobian(q)
        return float(math.sqrt(max(0.0, np.linalg.det(j @ j.T))))

    def check_singularity(self, q: Sequence[float], min_manipulability: float) -> float:
        w = self.manipulability(q)
        if w < min_manipulability:
            raise NearSingularError("near a singularity at joints (%s): manipulability %.3g below %.3g"
                                    % (", ".join("%.4f" % v for v in q), w, min_manipulability))
        return w

    # ------------------------------------------------------------------------------------------ IK
    def ik_pose(self, pose: Any, seed: Optional[Sequence[float]] = None, **kwargs: Any) -> Tuple[float, ...]:
        """IK of a controller pose (ControllerPose or (X, Y, Z, Rx, Ry, Rz) in mm / deg)."""
        if not isinstance(pose, ControllerPose):
            pose = ControllerPose.from_sequence(pose)
        return self.ik(self.conventions.controller_to_tip(pose), seed, **kwargs)

    def track_pose(self, pose: Any, seed: Sequence[float],
                   near: Tuple[float, float] = TRACK_NEAR) -> Tuple[float, ...]:
        """The joints of a *reported* pose (v1: whole mm / deg) of an arm known, or predicted, to
        be at ``seed``: the IK solution nearest the seed -- unless that is another configuration (a
        joint over TRACK_JUMP away) while the seed itself lies within ``near`` (mm, deg) of the
        pose: the rounding pushed the pose past a reach or joint limit of the seed's branch (the
        arm is stretched out, at a limit), and the arm is at the seed. Raises as :meth:`ik_pose`
        when the pose is unreachable and the seed is not near it."""
        if not isinstance(pose, ControllerPose):
            pose = ControllerPose.from_sequence(pose)
        seed = self.joint_vector(seed)
        try:
            q = self.ik_pose(pose, seed=seed)
        except KinematicsError:
            if self._near_pose(seed, pose, near):
                return seed
            nearest = self._nearest_configuration(pose, seed)
            if nearest is None:
                raise
            return nearest
        if max(abs(a - b) for a, b in zip(q, seed)) > TRACK_JUMP and self._near_pose(seed, pose, near):
            return seed
        return q

    def _nearest_configuration(self, pose: ControllerPose, seed: Sequence[float],
                               steps: int = 60) -> Optional[Tuple[float, ...]]:
        """Joints whose tip is within TRACK_ROUNDING of ``pose`` though no joints reach it exactly (a
        pose rounded just past the reach), found by damped least squares from ``seed``; None when
        the nearest configuration is farther (a pose really out of reach) or outside the limits."""
        target = self.conventions.controller_to_tip(pose)
        q = np.array(seed, dtype=float)
        damping = 0.03                  # near the wrist singularity J4 / J6 drift along J4 + J6 = const: stay near the seed
        for _ in range(steps):
            t = self.fk(q)
            dp = target[:3, 3] - t[:3, 3]
            r = target[:3, :3] @ t[:3, :3].T
            dr = 0.5 * np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
            if np.linalg.norm(dp) <= TRACK_ROUNDING[0] and np.linalg.norm(dr) <= TRACK_ROUNDING[1]:
                out = tuple(float(v) for v in q)
                return out if not self.limit_violations(out) else None
            jac = self.jacobian(q)
            err = np.concatenate([dp, dr])
            q = q + jac.T @ np.linalg.solve(jac @ jac.T + damping ** 2 * np.eye(6), err)
        return None

    def _near_pose(self, q: Sequence[float], pose: ControllerPose, near: Tuple[float, float]) -> bool:
        at = self.fk_pose(q)
        d_xyz = max(abs(a - b) for a, b in zip(at.as_tuple()[:3], pose.as_tuple()[:3]))
        d_ang = max(abs((a - b + 180.0) % 360.0 - 180.0)
                    for a, b in zip(at.as_tuple()[3:], pose.as_tuple()[3:]))
        return d_xyz <= near[0] and d_ang <= near[1]

    def ik(self, target: Any, seed: Optional[Sequence[float]] = None, timeout: Optional[float] = None,
           rng: Optional[random.Random] = None, min_manipulability: Optional[float] = None,
           numeric: bool = False) -> Tuple[float, ...]:
        """Joints that put the tip at ``target`` (4x4 array or ``PyKDL.Frame``, tip in the chain root),
        nearest to ``seed`` (default: zero clamped into the limits; the numeric path starts from the
        seed clamped into the limits). ``timeout`` overrides the budget,
        ``rng`` drives the random restarts, ``numeric`` forces the KDL path. Raises UnreachableError,
        IkTimeoutError, JointLimitError, NearSingularError, PoseError."""
        start = time.perf_counter()
        budget = self.settings.timeout if timeout is None else timeout
        r, p = self._target(target)
        seed_t = self.joint_vector(seed) if seed is not None else self.clamp((0.0,) * self.dof)
        if self._analytic is not None and not numeric:
            q = self._ik_analytic(r, p, seed_t)
        else:
            q = self._ik_numeric(r, p, seed_t, start + budget, rng or random.Random(), budget * 1e3)
        if min_manipulability is not None:
            self.check_singularity(q, min_manipulability)
        return q

    def ik_solutions(self, target: Any, seed: Optional[Sequence[float]] = None) -> List[Tuple[float, ...]]:
        """Every joint solution within the limits that puts the tip at ``target`` (as :meth:`ik`),
        nearest to ``seed`` first (squared joint distance): with the analytic solver each geometric
        branch (shoulder x elbow x wrist, up to 8) and, for each revolute joint whose range spans
        more than 2 pi (the wrist), each full turn of it that fits the limits; a planner picks the
        nearest one that is also collision-free. Without the analytic solver: the one solution of
        :meth:`ik`. Raises as :meth:`ik` when there is none."""
        r, p = self._target(target)
        seed_t = self.joint_vector(seed) if seed is not None else self.clamp((0.0,) * self.dof)
        if self._analytic is None:
            return [self.ik(target, seed_t)]
        lower, upper = self.limits.lower, self.limits.upper
        candidates, _, _, _ = self._analytic.solve(r, p, seed_t, lower, upper)
        found = []
        for _, q in candidates:
            if not self._ok(q, r, p):
                q = self._nr_polish(q, r, p)
                if q is None:
                    continue
            found.append(q)
        if not found:                          # the errors (and the polish) of the one-solution path
            found.append(self._ik_analytic(r, p, seed_t))
        out: List[Tuple[float, ...]] = []
        for q in found:
            turns = []
            for v, lo, hi, rev in zip(q, lower, upper, self.limits.revolute):
                if not rev:
                    turns.append((v,))
                    continue
                k_lo, k_hi = math.ceil((lo - 1e-9 - v) / TWO_PI), math.floor((hi + 1e-9 - v) / TWO_PI)
                turns.append(tuple(min(max(v + k * TWO_PI, lo), hi) for k in range(k_lo, k_hi + 1)) or (v,))
            for variant in _product(turns):
                if all(max(abs(a - b) for a, b in zip(variant, other)) > 1e-9 for other in out):
                    out.append(variant)
        out.sort(key=lambda q: sum((a - b) ** 2 for a, b in zip(q, seed_t)))
        return out

    def _target(self, target: Any):
        if isinstance(target, kdl.Frame):
            m, v = target.M, target.p
            r = (m[0, 0], m[0, 1], m[0, 2], m[1, 0], m[1, 1], m[1, 2], m[2, 0], m[2, 1], m[2, 2])
            p = (v[0], v[1], v[2])
            if not all(math.isfinite(x) for x in r + p):
                raise PoseError("target frame contains NaN or inf")
            return r, p
        if isinstance(target, np.ndarray) and target.shape == (4, 4) and target.dtype == float:
            rows = target.tolist()
            flat = rows[0] + rows[1] + rows[2]
            if all(math.isfinite(x) for x in flat) and rows[3] == [0.0, 0.0, 0.0, 1.0]:
                r = (flat[0], flat[1], flat[2], flat[4], flat[5], flat[6], flat[8], flat[9], flat[10])
                det_ok = abs(_dot(_cross(r[0:3], r[3:6]), r[6:9]) - 1.0) < 1e-6
                if det_ok and abs(_dot(r[0:3], r[3:6])) < 1e-6 and abs(_dot(r[0:3], r[0:3]) - 1.0) < 1e-6 \
                        and abs(_dot(r[3:6], r[3:6]) - 1.0) < 1e-6:
                    return r, (flat[3], flat[7], flat[11])
        t = check_transform(target, "IK target")
        flat = t[:3, :3].reshape(-1).tolist()
        return tuple(flat), tuple(t[:3, 3].tolist())

    def _verify(self, q, r, p) -> Tuple[float, float]:
        """(position error [m], rotation error [rad]) of FK(q) against (r, p), with KDL's FK."""
        f = kdl.Frame()
        self._fk.JntToCart(self._jnt(q), f)
        m, v = f.M, f.p
        dp = math.sqrt((v[0] - p[0]) ** 2 + (v[1] - p[1]) ** 2 + (v[2] - p[2]) ** 2)
        # rotation angle of R_fk^T R_target from its trace
        tr = (m[0, 0] * r[0] + m[1, 0] * r[3] + m[2, 0] * r[6] + m[0, 1] * r[1] + m[1, 1] * r[4]
              + m[2, 1] * r[7] + m[0, 2] * r[2] + m[1, 2] * r[5] + m[2, 2] * r[8])
        c = (tr - 1.0) / 2.0
        if c > 1.0 - 1e-10:
            # acos loses precision near 0: use the skew part instead
            s = [m[0, 0], m[0, 1], m[0, 2], m[1, 0], m[1, 1], m[1, 2], m[2, 0], m[2, 1], m[2, 2]]
            # R_fk^T R_target, skew part
            def e(i, j):
                return s[i] * r[j] + s[i + 3] * r[j + 3] + s[i + 6] * r[j + 6]
            da = 0.5 * math.sqrt((e(2, 1) - e(1, 2)) ** 2 + (e(0, 2) - e(2, 0)) ** 2 + (e(1, 0) - e(0, 1)) ** 2)
        else:
            da = math.acos(max(-1.0, c))
        return dp, da

    def _ok(self, q, r, p) -> bool:
        dp, da = self._verify(q, r, p)
        return dp <= self.settings.position_tolerance and da <= self.settings.orientation_tolerance

    def _ik_analytic(self, r, p, seed) -> Tuple[float, ...]:
        lower, upper = self.limits.lower, self.limits.upper
        candidates, n_raw, rejected, reason = self._analytic.solve(r, p, seed, lower, upper)
        if not n_raw:
            raise UnreachableError("pose unreachable: " + (reason or "no arm configuration reaches it"))
        if not candidates:
            i, v = rejected[0]
            v = wrap_angle(v) if self.limits.revolute[i] else v
            names = sorted({self.joint_names[j] for j, _ in rejected})
            raise JointLimitError(
                "pose reachable only outside the joint limits: all %d arm/wrist configurations violate "
                "%s (e.g. %s = %.4f rad, limits [%.4f, %.4f])"
                % (n_raw, ", ".join(names), self.joint_names[i], v, lower[i], upper[i]))
        for _, q in candidates:
            if self._ok(q, r, p):
                return q
        # numerical trouble (e.g. at a singular boundary): polish the nearest with KDL
        q = self._nr_polish(candidates[0][1], r, p)
        if q is not None:
            return q
        raise UnreachableError("pose unreachable: the analytic solution misses the pose by more than the "
                               "tolerance and KDL could not polish it")

    def _nr_polish(self, q0, r, p) -> Optional[Tuple[float, ...]]:
        target = kdl.Frame(kdl.Rotation(*r), kdl.Vector(*p))
        out = kdl.JntArray(self.dof)
        if self._nr_jl.CartToJnt(self._jnt(q0), target, out) < 0:
            return None
        q = tuple(out[i] for i in range(self.dof))
        if self.limit_violations(q) or not self._ok(q, r, p):
            return None
        return q

    def _nearest_turns(self, q, seed) -> Tuple[float, ...]:
        """Each revolute joint moved by multiples of 2 pi towards the seed, staying within limits."""
        out = []
        for v, s, lo, hi, rev in zip(q, seed, self.limits.lower, self.limits.upper, self.limits.revolute):
            if rev:
                k = round((s - v) / TWO_PI)
                for kk in (k, k - 1, k + 1):
                    c = v + kk * TWO_PI
                    if lo <= c <= hi and abs(c - s) < abs(v - s):
                        v = c
            out.append(v)
        return tuple(out)

    def _into_limits(self, q, seed) -> Optional[Tuple[float, ...]]:
        out = []
        for v, s, lo, hi, rev in zip(q, seed, self.limits.lower, self.limits.upper, self.limits.revolute):
            if rev:
                v = _turn(v, s, lo, hi)
                if v is None:
                    return None
            elif not lo <= v <= hi:
                return None
            out.append(v)
        return tuple(out)

    def _ik_numeric(self, r, p, seed, deadline, rng, budget_ms) -> Tuple[float, ...]:
        dist = math.sqrt(sum((p[i] - self._first_point[i]) ** 2 for i in range(3)))
        if dist > self.reach_bound:
            raise UnreachableError("pose unreachable: %.4f m from the first joint, beyond the chain's "
                                   "total length %.4f m" % (dist, self.reach_bound))
        target = kdl.Frame(kdl.Rotation(*r), kdl.Vector(*p))
        out = kdl.JntArray(self.dof)
        q_init = self.clamp(seed)          # NR_JL would return an out-of-limit seed unchanged
        tries = 0
        while True:
            tries += 1
            if self._nr_jl.CartToJnt(self._jnt(q_init), target, out) >= 0:
                q = tuple(out[i] for i in range(self.dof))
                if not self.limit_violations(q) and self._ok(q, r, p):
                    return self._nearest_turns(q, seed)
            # LMA converges far more often but ignores the limits: take each joint's full turn
            # nearest the seed that fits (prismatic joints must fit as they are)
            if self._lma.CartToJnt(self._jnt(q_init), target, out) >= 0:
                q = self._into_limits(tuple(out[i] for i in range(self.dof)), seed)
                if q is not None and self._ok(q, r, p):
                    return q
            if time.perf_counter() >= deadline:
                raise IkTimeoutError("pose unreachable: no IK solution in %d tries within the %.2f ms budget"
                                     % (tries, budget_ms))
            q_init = self.random_joints(rng)


# ============================================================================================== CLI

def _json_pose(pose: ControllerPose) -> List[float]:
    return [round(v, 6) for v in pose.as_tuple()]


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python3 -m vr_driver.kinematics.solver",
        description="Forward / inverse kinematics of the VR-006L (controller units: mm, degrees; joints: rad). "
                    "Prints JSON {joints, pose, reachable, error}; exit 0 solved, 3 unreachable, 2 usage.")
    sub = parser.add_subparsers(dest="command")
    p_fk = sub.add_parser("fk", help="joints -> controller pose")
    p_fk.add_argument("joints", nargs="+", metavar="J", help="joint values in rad")
    p_ik = sub.add_parser("ik", help="controller pose -> joints")
    p_ik.add_argument("pose", nargs="+", metavar="V", help="X Y Z (mm) RX RY RZ (deg)")
    p_ik.add_argument("--seed", nargs="+", metavar="J", help="seed joints in rad (default: home)")
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return 2 if exc.code else 0
    if args.command is None:
        parser.print_usage(sys.stderr)
        return 2

    def emit(joints, pose, reachable, error, code):
        print(json.dumps({"joints": joints, "pose": pose, "reachable": reachable, "error": error}))
        return code

    try:
        kin = Kinematics.default()
    except ModelError as exc:
        print("error: cannot load the robot model: %s" % exc, file=sys.stderr)
        return 1
    try:
        if args.command == "fk":
            q = kin.joint_vector(_parse_numbers(args.joints, "joints"))
        else:
            pose = ControllerPose.from_sequence(_parse_numbers(args.pose, "pose"))
            seed = kin.joint_vector(_parse_numbers(args.seed, "seed")) if args.seed \
                else kin.named_states.get("home")
    except PoseError as exc:
        print("usage error: %s" % exc, file=sys.stderr)
        return emit(None, None, False, str(exc), 2)
    if args.command == "fk":
        pose = _json_pose(kin.fk_pose(q))
        bad = kin.limit_violations(q)
        if bad:
            return emit(list(q), pose, False, "joints outside their limits: " + "; ".join(bad), 3)
        return emit(list(q), pose, True, None, 0)
    try:
        q = kin.ik_pose(pose, seed)
    except KinematicsError as exc:
        return emit(None, _json_pose(pose), False, "%s: %s" % (type(exc).__name__, exc), 3)
    return emit([round(v, 9) for v in q], _json_pose(pose), True, None, 0)


def _parse_numbers(items: Sequence[str], what: str) -> List[float]:
    out = []
    for s in items:
        try:
            out.append(float(s))
        except ValueError as exc:
            raise PoseError("%s: %r is not a number" % (what, s)) from exc
    return out


if __name__ == "__main__":
    sys.exit(main())
