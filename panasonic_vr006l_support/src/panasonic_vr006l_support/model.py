"""The stack's one URDF reader and a small read-only view of the model: the joint tree, the shapes,
forward kinematics of every link (batched, numpy) and the reach. ROS-free, our own small parser on
ElementTree (urdf_parser_py is not needed). Used by the model tests, the picture renderer and
``vr_driver.kinematics.solver`` (which builds its KDL chain from :meth:`RobotModel.chain`).

Kinematics for control (IK, Jacobians) lives in ``vr_driver.kinematics.solver`` on PyKDL; this module
only answers questions about the model's geometry.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np


class ModelError(Exception):
    """The URDF is not what the question needs (unknown link, no chain, unsupported joint...)."""


MOVABLE_TYPES = ("revolute", "continuous", "prismatic")
_ZERO3 = (0.0, 0.0, 0.0)


def _floats(text: Optional[str], count: int, default: Tuple[float, ...], what: str) -> Tuple[float, ...]:
    if text is None:
        return default
    try:
        values = tuple(float(v) for v in text.split())
    except ValueError as exc:
        raise ModelError("%s: %r is not %d numbers" % (what, text, count)) from exc
    if len(values) != count or not all(math.isfinite(v) for v in values):
        raise ModelError("%s: %r is not %d finite numbers" % (what, text, count))
    return values


def _origin(elem: Optional[Any], what: str) -> Tuple[Tuple[float, ...], Tuple[float, ...]]:
    """(xyz, rpy) of the ``<origin>`` child of ``elem`` (zeros where absent)."""
    origin = elem.find("origin") if elem is not None else None
    if origin is None:
        return _ZERO3, _ZERO3
    return (_floats(origin.get("xyz"), 3, _ZERO3, what + " origin xyz"),
            _floats(origin.get("rpy"), 3, _ZERO3, what + " origin rpy"))


def _limit(elem: Any, jtype: str, what: str) -> Tuple[Optional[float], ...]:
    """(lower, upper, velocity, effort) of a joint's ``<limit>``; lower and upper None for a
    continuous joint, all None without a limit (where the joint type allows that)."""
    limit = elem.find("limit")
    if limit is None:
        if jtype in ("revolute", "prismatic"):
            raise ModelError("%s: a %s joint needs a <limit>" % (what, jtype))
        return None, None, None, None
    try:
        velocity = float(limit.get("velocity", "inf"))
        effort = float(limit.get("effort", "0"))
        lower = upper = None
        if jtype != "continuous":
            lower, upper = float(limit.get("lower", "0")), float(limit.get("upper", "0"))
    except ValueError as exc:
        raise ModelError("%s: bad <limit>: %s" % (what, exc)) from exc
    if lower is not None and upper is not None and lower > upper:
        raise ModelError("%s: lower limit %g above upper limit %g" % (what, lower, upper))
    return lower, upper, velocity, effort


def rpy_matrix(rpy: Sequence[float]) -> np.ndarray:
    """Rotation of URDF ``rpy`` (fixed axes X, then Y, then Z): R = Rz(yaw) Ry(pitch) Rx(roll)."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array([
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ])


def transform(xyz: Sequence[float] = (0.0, 0.0, 0.0), rpy: Sequence[float] = (0.0, 0.0, 0.0)) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3] = rpy_matrix(rpy)
    t[:3, 3] = xyz
    return t


def _axis_rotations(axis: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Rotation matrices (N, 3, 3) about a unit ``axis`` by each of ``angles`` (Rodrigues)."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    s = np.sin(angles)[:, None, None]
    c = np.cos(angles)[:, None, None]
    return np.eye(3)[None] + s * k[None] + (1.0 - c) * (k @ k)[None]


@dataclass(frozen=True)
class Joint:
    name: str
    type: str
    parent: str
    child: str
    origin: np.ndarray = field(repr=False)  # 4x4 parent -> joint frame at q = 0
    axis: np.ndarray = field(repr=False)
    lower: Optional[float] = None
    upper: Optional[float] = None
    velocity: Optional[float] = None
    effort: Optional[float] = None
    xyz: Tuple[float, float, float] = (0.0, 0.0, 0.0)   # the origin as written in the URDF
    rpy: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    mimic: bool = False                                  # has a <mimic> element

    @property
    def movable(self) -> bool:
        return self.type in MOVABLE_TYPES


@dataclass(frozen=True)
class Shape:
    """One visual or collision primitive, in its link's frame."""
    kind: str                   # 'box' | 'cylinder' | 'sphere' | 'mesh'
    size: Tuple[float, ...]     # box (x, y, z); cylinder (radius, length); sphere (radius,); mesh ()
    origin: np.ndarray = field(repr=False)
    rgba: Optional[Tuple[float, float, float, float]] = None


class RobotModel:
    """The joint tree of a URDF, with forward kinematics."""

    def __init__(self, name: str, root: str, joints: Sequence[Joint], visuals: Mapping[str, List[Shape]],
                 collisions: Mapping[str, List[Shape]], links: Optional[Sequence[str]] = None):
        self.name = name
        self.root = root
        self.joints: Dict[str, Joint] = {j.name: j for j in joints}
        self.visuals = dict(visuals)
        self.collisions = dict(collisions)
        self.links = list(links) if links is not None else [root] + [j.child for j in joints]
        self._parent_joint: Dict[str, Joint] = {}
        for j in joints:
            if j.child in self._parent_joint:
                raise ModelError("link %s has two parent joints (%s, %s)" % (j.child, self._parent_joint[j.child].name,
                                                                            j.name))
            self._parent_joint[j.child] = j

    @classmethod
    def from_urdf_string(cls, xml: str) -> "RobotModel":
        """Read a URDF (ModelError says what is wrong: not XML, a joint without parent / child /
        limit, numbers that are not finite, a zero axis, not one root link)."""
        try:
            root = ET.fromstring(xml)
        except ET.ParseError as exc:
            raise ModelError("the URDF is not valid XML: %s" % exc) from exc
        if root.tag != "robot":
            raise ModelError("the URDF's root element is <%s>, not <robot>" % root.tag)
        materials = {m.get("name"): m for m in root.findall("material")}
        joints = [cls._joint(elem) for elem in root.findall("joint")]
        links = [link.get("name") for link in root.findall("link")]
        children = {j.child for j in joints}
        roots = [name for name in links if name not in children]
        if len(roots) != 1:
            raise ModelError("the URDF needs exactly one root link, it has %s" % (", ".join(roots) or "none"))
        visuals = {link.get("name"): [cls._shape(v, materials, "link %s visual" % link.get("name"))
                                      for v in link.findall("visual")] for link in root.findall("link")}
        collisions = {link.get("name"): [cls._shape(c, materials, "link %s collision" % link.get("name"))
                                         for c in link.findall("collision")] for link in root.findall("link")}
        return cls(root.get("name", ""), roots[0], joints, visuals, collisions, links=links)

    @staticmethod
    def _joint(elem: Any) -> Joint:
        name, jtype = elem.get("name"), elem.get("type")
        what = "URDF joint %s" % name
        parent, child = elem.find("parent"), elem.find("child")
        if parent is None or child is None:
            raise ModelError("%s: missing <parent> or <child>" % what)
        xyz, rpy = _origin(elem, what)
        axis_elem = elem.find("axis")
        axis = np.array(_floats(axis_elem.get("xyz") if axis_elem is not None else None, 3, (1.0, 0.0, 0.0),
                                what + " axis"), dtype=float)
        norm = float(np.linalg.norm(axis))
        if jtype != "fixed" and norm < 1e-12:
            raise ModelError("%s: zero axis" % what)
        lower, upper, velocity, effort = _limit(elem, jtype, what)
        return Joint(name=name, type=jtype, parent=parent.get("link"), child=child.get("link"),
                     origin=transform(xyz, rpy), axis=axis / norm if norm > 0 else axis, lower=lower, upper=upper,
                     velocity=velocity, effort=effort, xyz=xyz, rpy=rpy, mimic=elem.find("mimic") is not None)

    @staticmethod
    def _shape(elem: Any, materials: Mapping[str, Any], what: str) -> Shape:
        origin = transform(*_origin(elem, what))
        geometry = elem.find("geometry")
        g = geometry[0] if geometry is not None and len(geometry) else None
        kind = g.tag if g is not None else ""
        if kind == "box":
            size = _floats(g.get("size"), 3, _ZERO3, what + " box size")
        elif kind == "cylinder":
            size = _floats(g.get("radius"), 1, (0.0,), what + " radius") + _floats(g.get("length"), 1, (0.0,),
                                                                                   what + " length")
        elif kind == "sphere":
            size = _floats(g.get("radius"), 1, (0.0,), what + " radius")
        else:
            size = ()
        rgba = None
        mat = elem.find("material")
        if mat is not None:
            color = mat.find("color")
            if color is None and mat.get("name") in materials:
                color = materials[mat.get("name")].find("color")
            if color is not None:
                rgba = _floats(color.get("rgba"), 4, (0.0, 0.0, 0.0, 0.0), what + " colour")
        return Shape(kind=kind, size=size, origin=origin, rgba=rgba)

    # --- structure -------------------------------------------------------------------------------
    def chain(self, base: str, tip: str) -> List[Joint]:
        """The joints from ``base`` down to ``tip`` (fixed ones included), in order; ModelError if
        ``tip`` is not below ``base``."""
        return self._chain(base, tip)

    def _chain(self, base: str, tip: str) -> List[Joint]:
        for link in (base, tip):
            if link not in self.links:
                raise ModelError("link %r is not in the URDF (links: %s)" % (link, ", ".join(self.links)))
        joints = []
        link = tip
        while link != base:
            joint = self._parent_joint.get(link)
            if joint is None:
                raise ModelError("no kinematic chain from %s to %s (%s is not below %s)" % (base, tip, tip, base))
            joints.append(joint)
            link = joint.parent
        return list(reversed(joints))

    def fixed_transform(self, frm: str, to: str) -> np.ndarray:
        """Pose of link ``to`` in link ``frm`` when they are joined by fixed joints only (either way)."""
        try:
            joints = self._chain(frm, to)
            inverse = False
        except ModelError:
            joints = self._chain(to, frm)
            inverse = True
        t = np.eye(4)
        for j in joints:
            if j.movable:
                raise ModelError("%s and %s are not rigidly connected (joint %s moves)" % (frm, to, j.name))
            t = t @ j.origin
        return np.linalg.inv(t) if inverse else t

    def movable_joints(self, base: str, tip: str) -> List[Joint]:
        return [j for j in self.chain(base, tip) if j.movable]

    # --- kinematics ------------------------------------------------------------------------------
    def link_transforms(self, positions: Mapping[str, float]) -> Dict[str, np.ndarray]:
        """4x4 pose of every link in the root frame; joints missing from ``positions`` are at 0."""
        poses = {self.root: np.eye(4)}
        pending = list(self.joints.values())
        while pending:
            rest = []
            for j in pending:
                if j.parent not in poses:
                    rest.append(j)
                    continue
                poses[j.child] = poses[j.parent] @ self._joint_motion(j, np.array([positions.get(j.name, 0.0)]))[0]
            if len(rest) == len(pending):
                raise ModelError("joints not connected to the root: %s" % [j.name for j in rest])
            pending = rest
        return poses

    @staticmethod
    def _joint_motion(joint: Joint, q: np.ndarray) -> np.ndarray:
        """(N, 4, 4): origin * motion(q) for each of the N joint values."""
        n = q.shape[0]
        motion = np.tile(np.eye(4), (n, 1, 1))
        if joint.type in ("revolute", "continuous"):
            motion[:, :3, :3] = _axis_rotations(joint.axis, q)
        elif joint.type == "prismatic":
            motion[:, :3, 3] = q[:, None] * joint.axis[None]
        elif joint.type != "fixed":
            raise ModelError("joint type %s of %s is not supported" % (joint.type, joint.name))
        return joint.origin[None] @ motion

    def chain_fk(self, base: str, tip: str, q: np.ndarray) -> np.ndarray:
        """Batched FK: ``q`` (N, dof) in movable-joint order of the chain -> (N, 4, 4) tip poses in base."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        chain = self.chain(base, tip)
        dof = sum(1 for j in chain if j.movable)
        if q.shape[1] != dof:
            raise ModelError("chain %s->%s has %d movable joints, got %d values" % (base, tip, dof, q.shape[1]))
        result = np.tile(np.eye(4), (q.shape[0], 1, 1))
        i = 0
        for j in chain:
            if j.movable:
                result = result @ self._joint_motion(j, q[:, i])
                i += 1
            else:
                result = result @ j.origin[None]
        return result

    def horizontal_reach(self, base: str = "base_link", tip: str = "flange", samples: int = 9) -> float:
        """Largest distance of ``tip`` from the first joint's axis, over the joint limits.

        A coarse grid over every joint but the first (whose rotation cannot change the distance to its
        own axis), then a shrinking pattern search around the best point.
        """
        movable = self.movable_joints(base, tip)
        if not movable:
            raise ModelError("no movable joint between %s and %s" % (base, tip))
        first = movable[0]
        axis_origin = first.origin[:3, 3]
        axis_dir = first.origin[:3, :3] @ first.axis
        lows = np.array([j.lower if j.lower is not None else -math.pi for j in movable])
        highs = np.array([j.upper if j.upper is not None else math.pi for j in movable])

        def distances(qs: np.ndarray) -> np.ndarray:
            p = self.chain_fk(base, tip, qs)[:, :3, 3] - axis_origin
            along = p @ axis_dir
            return np.linalg.norm(p - along[:, None] * axis_dir[None], axis=1)

        grids = [np.array([0.0])] + [np.linspace(lo, hi, samples) for lo, hi in zip(lows[1:], highs[1:])]
        mesh = np.stack(np.meshgrid(*grids, indexing="ij"), axis=-1).reshape(-1, len(movable))
        d = distances(mesh)
        best = mesh[int(np.argmax(d))]
        best_d = float(d.max())
        step = (highs - lows) / samples
        step[0] = 0.0
        for _ in range(60):
            offsets = np.array([np.zeros(len(movable))] + [s * e for i, s in enumerate(step) if s > 0
                                                           for e in (np.eye(len(movable))[i], -np.eye(len(movable))[i])])
            cand = np.clip(best[None] + offsets, lows, highs)
            dc = distances(cand)
            k = int(np.argmax(dc))
            if dc[k] > best_d + 1e-12:
                best, best_d = cand[k], float(dc[k])
            else:
                step = step / 2.0
        return best_d
