"""Kinematics of the arm on PyKDL: our own URDF -> KDL chain builder, FK, IK, Jacobian. ROS-free.

The chain runs from the SRDF group's ``base_link`` to its ``tip_link`` (``base_link`` -> ``tool0``);
the IK time budget comes from MoveIt's ``kinematics.yaml`` (``kinematics_solver_timeout``).

The jobs around the class, one module each: :mod:`.limits` (the joint limits and the joint-space
operations on them), :mod:`.ik` (the IK search: its strategy, settings and errors), :mod:`.analytic`
(the closed-form IK of a six-axis arm with a spherical wrist). Their names are importable from here.

Errors (vr_driver.errors): ``UnreachableError``, ``IkTimeoutError``, ``JointLimitError`` (the IK,
:mod:`.ik`; ``JointLimitError`` also from :meth:`Kinematics.check_limits`), ``NearSingularError``
(when the caller sets ``min_manipulability``), ``PoseError`` (NaN, inf, wrong lengths, unknown joint
names), ``ModelError`` (unusable description).

Command line (controller units: mm and degrees; joints in radians)::

    python3 -m vr_driver.kinematics.solver fk J1 J2 J3 J4 J5 J6
    python3 -m vr_driver.kinematics.solver ik X Y Z RX RY RZ [--seed J1 ... J6]

prints JSON ``{"joints", "pose", "reachable", "error"}``; exit 0 solved, 3 unreachable, 2 usage.
"""
from __future__ import annotations

import argparse
import contextlib
import enum
import json
import math
import os
import random
import sys
import time
import xml.etree.ElementTree as ET
from typing import Any, Dict, Iterator, List, Mapping, Optional, Sequence, Tuple

import numpy as np
import PyKDL as kdl
from panasonic_vr006l_support import model as _support_model

from .. import validate
from ..errors import JointLimitError, KinematicsError, ModelError, NearSingularError, PoseError
from ..poses import ControllerPose, FrameConventions, finite_number, matrix_to_kdl_frame, rpy_to_matrix
from .ik import IkSettings, IkSolver, jnt_array, rotation_and_position
from .limits import JointLimits, model_accelerations

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

_MOVABLE = ("revolute", "continuous", "prismatic")
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
    it sent to know which joints the arm is at (:mod:`vr_driver.driver.joints.tracking`)."""

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


def stretched_elbow(kin: "Kinematics") -> Optional[float]:
    """[rad] joint_3 where the arm is stretched out (the shoulder, the elbow and the wrist centre in
    a line, the two elbow branches of a pose meet: near it a pose hardly fixes joint_2 / joint_3 and
    the nearest-solution IK of a controller may take the other branch); None without the analytic
    solver (an arm of another shape)."""
    solver = getattr(getattr(kin, "ik_solver", None), "analytic", None)
    if solver is None:
        return None
    return math.remainder(solver.phi2 - solver.phiw + math.pi, 2.0 * math.pi)


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
        self.limits = JointLimits.of_joints(movable, prefix, accelerations)
        self.joint_names = self.limits.names
        self.dof = len(movable)
        self.chain = build_kdl_chain(self.chain_joints)
        self._fk = kdl.ChainFkSolverPos_recursive(self.chain)
        self._jac = kdl.ChainJntToJacSolver(self.chain)
        #: the IK search (:meth:`ik` and :meth:`ik_solutions` delegate to it)
        self.ik_solver = IkSolver(self.chain_joints, self.chain, self.limits, self.settings, analytic)
        self.reach_bound = self.ik_solver.reach_bound
        self.analytic_reason = self.ik_solver.analytic_reason
        self.named_states = {name: self.joint_vector(values) for name, values in (named_states or {}).items()}
        self.conventions = conventions or self._default_conventions()
        self._tcp_frames: Optional[Tuple[FrameConventions, Any, Any]] = None   # (tcp_position's)

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
        return self.ik_solver.analytic is not None

    # ------------------------------------------------------------------------------- joint vectors
    def joint_vector(self, values: Any) -> Tuple[float, ...]:
        """A validated joint vector (tuple of floats) from a sequence in chain order or a mapping
        ``{joint name: value}`` naming every joint; PoseError otherwise."""
        if type(values) is tuple and len(values) == self.dof and \
                all(type(v) is float and math.isfinite(v) for v in values):
            return values           # already what the checks below make of it (every IK and FK comes here)
        if isinstance(values, np.ndarray) and values.dtype == np.float64 and values.shape == (self.dof,) \
                and bool(np.all(np.isfinite(values))):
            return tuple(values.tolist())       # (a path's samples: the same floats the checks make)
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
        """One line per joint of ``q`` outside its limits (:meth:`JointLimits.violations`)."""
        return self.limits.violations(q, tol)

    def check_limits(self, q: Sequence[float], tol: float = 1e-9) -> Tuple[float, ...]:
        """``q`` validated; JointLimitError naming every joint outside its limits."""
        q = self.joint_vector(q)
        bad = self.limit_violations(q, tol)
        if bad:
            raise JointLimitError("joints outside their limits: " + "; ".join(bad))
        return q

    def clamp(self, q: Sequence[float]) -> Tuple[float, ...]:
        return self.limits.clamp(q)

    def random_joints(self, rng: random.Random) -> Tuple[float, ...]:
        """Uniform within the limits (continuous joints: within +-pi)."""
        return self.limits.random_joints(rng)

    # ------------------------------------------------------------------------------------------ FK
    def fk_frame(self, q: Sequence[float]) -> "kdl.Frame":
        """Tip frame in the chain root as a ``PyKDL.Frame`` (no validation: the fast path)."""
        f = kdl.Frame()
        if self._fk.JntToCart(jnt_array(self.dof, q), f) < 0:
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

    def tcp_in_tip(self) -> Tuple[np.ndarray, np.ndarray]:
        """(``base`` in the chain root's terms: the 4x4 that takes a point in the root to ``base``
        [m], the TCP's position in the tip's frame [m]) -- the two fixed parts of :meth:`tcp_position`."""
        conv = self.conventions
        root_to_base = conv.root_to_base(np.eye(4))
        # tip_to_tcp(I) = root_in_base @ tcp_in_tip: less the base part, the TCP in the tip's frame
        return root_to_base, np.linalg.solve(root_to_base, conv.tip_to_tcp(np.eye(4)))[:3, 3]

    def tcp_position(self, q: Sequence[float]) -> Tuple[float, float, float]:
        """The TCP's position in ``base`` [mm] at joints ``q`` (the X, Y, Z of :meth:`fk_pose`),
        without validating ``q`` and without the orientation: the fast path of a check that runs
        per configuration (the plan action's workspace box, ``driver.planning.planning.CellValidity``),
        all in KDL's C++ (one ``fk_pose`` builds and checks a ControllerPose: 5 x as long)."""
        conv = self.conventions
        cached = self._tcp_frames
        if cached is None or cached[0] is not conv:
            base, offset = self.tcp_in_tip()
            cached = self._tcp_frames = (conv, matrix_to_kdl_frame(base), kdl.Vector(*(float(v) for v in offset)))
        p = cached[1] * (self.fk_frame(q) * cached[2])
        return p[0] * 1000.0, p[1] * 1000.0, p[2] * 1000.0

    # -------------------------------------------------------------------------------- Jacobian
    def jacobian(self, q: Sequence[float]) -> np.ndarray:
        """6 x dof Jacobian (linear rows first) of the tip origin, in the root frame."""
        q = self.joint_vector(q)
        jac = kdl.Jacobian(self.dof)
        self._jac.JntToJac(jnt_array(self.dof, q), jac)
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
        r, p = rotation_and_position(target)
        q = self.ik_solver.nearest(r, p, self._seed(seed), start + budget, budget, rng, numeric)
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
        r, p = rotation_and_position(target)
        seed_t = self._seed(seed)
        if not self.has_analytic_solver:
            return [self.ik(target, seed_t)]
        return self.ik_solver.solutions(r, p, seed_t)

    def _seed(self, seed: Optional[Sequence[float]]) -> Tuple[float, ...]:
        """The IK seed validated; None: zero clamped into the limits."""
        return self.joint_vector(seed) if seed is not None else self.clamp((0.0,) * self.dof)


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
