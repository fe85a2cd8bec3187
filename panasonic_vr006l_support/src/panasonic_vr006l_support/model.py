"""A small read-only view of a URDF robot model: the joint tree, forward kinematics of every link
(batched, numpy) and the reach. ROS-free. Used by the model tests and the picture renderer.

Kinematics for control (IK, Jacobians) lives in ``vr_driver.kinematics`` on PyKDL; this module
only answers questions about the model's geometry.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np


class ModelError(Exception):
    """The URDF is not what the question needs (unknown link, no chain, unsupported joint...)."""


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

    @property
    def movable(self) -> bool:
        return self.type in ("revolute", "continuous", "prismatic")


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
                 collisions: Mapping[str, List[Shape]]):
        self.name = name
        self.root = root
        self.joints: Dict[str, Joint] = {j.name: j for j in joints}
        self.visuals = dict(visuals)
        self.collisions = dict(collisions)
        self.links = [root] + [j.child for j in joints]
        self._parent_joint = {j.child: j for j in joints}

    @classmethod
    def from_urdf_string(cls, xml: str) -> "RobotModel":
        try:
            from urdf_parser_py.urdf import URDF
        except ImportError as exc:  # pragma: no cover - environment problem
            raise ModelError("urdf_parser_py is missing: run scripts/setup (urdfdom-py from PyPI)") from exc
        try:
            robot = URDF.from_xml_string(xml)
        except Exception as exc:
            raise ModelError("URDF does not parse: %s" % exc) from exc
        materials = {m.name: m for m in (robot.materials or [])}
        joints = []
        for j in robot.joints:
            o = j.origin
            origin = transform(o.xyz if o is not None and o.xyz else (0, 0, 0),
                               o.rpy if o is not None and o.rpy else (0, 0, 0))
            axis = np.array(j.axis if j.axis is not None else (1.0, 0.0, 0.0), dtype=float)
            norm = np.linalg.norm(axis)
            if norm == 0.0:
                raise ModelError("joint %s has a zero axis" % j.name)
            lim = j.limit
            joints.append(Joint(
                name=j.name, type=j.type, parent=j.parent, child=j.child, origin=origin, axis=axis / norm,
                lower=getattr(lim, "lower", None), upper=getattr(lim, "upper", None),
                velocity=getattr(lim, "velocity", None), effort=getattr(lim, "effort", None)))
        visuals, collisions = {}, {}
        for link in robot.links:
            visuals[link.name] = [cls._shape(v, materials) for v in link.visuals]
            collisions[link.name] = [cls._shape(c, materials) for c in link.collisions]
        return cls(robot.name, robot.get_root(), joints, visuals, collisions)

    @staticmethod
    def _shape(elem, materials) -> Shape:
        o = elem.origin
        origin = transform(o.xyz if o is not None and o.xyz else (0, 0, 0),
                           o.rpy if o is not None and o.rpy else (0, 0, 0))
        g = elem.geometry
        kind = type(g).__name__.lower()
        if kind == "box":
            size = tuple(g.size)
        elif kind == "cylinder":
            size = (g.radius, g.length)
        elif kind == "sphere":
            size = (g.radius,)
        else:
            size = ()
        rgba = None
        mat = getattr(elem, "material", None)
        if mat is not None:
            color = mat.color if mat.color is not None else getattr(materials.get(mat.name), "color", None)
            if color is not None:
                rgba = tuple(color.rgba)
        return Shape(kind=kind, size=size, origin=origin, rgba=rgba)

    # --- structure -------------------------------------------------------------------------------
    def chain(self, base: str, tip: str) -> List[Joint]:
        """Joints from ``base`` down to ``tip`` (tip must be a descendant of base)."""
        for name in (base, tip):
            if name not in self.links:
                raise ModelError("no link named %r in model %s" % (name, self.name))
        joints = []
        link = tip
        while link != base:
            joint = self._parent_joint.get(link)
            if joint is None:
                raise ModelError("%s is not below %s" % (tip, base))
            joints.append(joint)
            link = joint.parent
        return list(reversed(joints))

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
