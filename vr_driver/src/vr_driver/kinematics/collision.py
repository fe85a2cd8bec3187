"""Collision checking of the arm against itself and the cell (kinematics.scene), on pinocchio and
coal (PyPI ``pin``, ``coal``; pinned in scripts/setup; Python >= 3.10). Without them, building a
checker raises MissingDependency naming the package and scripts/setup; importing this module does
not need them.

    checker = CollisionChecker.default(scene=load_scene(path), padding=0.02)
    checker.in_collision(q)        # q: joint_1..joint_6 [rad], the controller's angles
    checker.contacts(q)            # [Contact(link_a, other, distance, world)], nearest first
    checker.check_path(qs)         # None, or (index of the first colliding sample, its contacts)
    checker.min_distance(q)        # smallest distance over the checked pairs [m] (< 0: penetration)
    checker.first_collision(qs)    # index of the first row of qs (n x 6) in collision, or None

What is checked (the pairs, fixed when the checker or its scene is built):

- self: every two links' collision geometry of the URDF, except the pairs the SRDF disables
  (``disable_collisions``: adjacent links and pairs that can never meet); without an SRDF the links
  joined by one joint are left out instead (their housings overlap at the joint by design);
- world: every moving link against every scene object. The fixed root link (base_link) is not
  checked against the scene: it cannot move, and the surface the robot stands on touches it.

Padding inflates every shape by ``padding`` [m] for the verdict (coal's security margin: a pair
counts as colliding when its distance is below ``padding``); distances reported are those of the
true shapes. The URDF's collision geometry is made of primitives (vr006l_macro.xacro), as the scene.

The verdicts (``in_collision``, ``first_collision``, ``check_path``) go
through a broad phase (pinocchio's tree broad-phase pool over coal's dynamic AABB tree, one
configuration or a batch of them in one C++ call, stopping at the first collision): the same
verdict as every pair's narrow phase (``contacts``, and the tests' brute-force comparison), about
a third of its CPU (``bench/README.md``, "Planning", Round 3). It is built for the scene and the
padding it has and dropped with either.

Joint angles: ``q`` is given in the order of ``joint_names`` (default: the URDF's six revolute
joints joint_1..joint_6, prefixed); the URDF already holds the zero offsets, so these are the
controller's angles, the same vectors as kinematics.solver's.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from typing import Any, Iterable, List, NamedTuple, Optional, Sequence, Set, Tuple

import numpy as np

from vr_driver.errors import ModelError, PoseError
from vr_driver.kinematics.deps import require
from vr_driver.kinematics.scene import Scene, SceneObject

__all__ = ["Contact", "CollisionChecker", "fresh_geometry_data", "read_disabled_pairs"]


class Contact(NamedTuple):
    """One colliding pair: ``link_a`` a link of the robot, ``other`` another link (``world`` False)
    or a scene object's name (``world`` True), ``distance`` [m] between their true shapes (< 0:
    penetration depth; >= 0 but < padding: inside the padding)."""
    link_a: str
    other: str
    distance: float
    world: bool

    def __str__(self) -> str:
        return "%s with %s %s (%s)" % (self.link_a, "object" if self.world else "link", self.other,
                                       "%.1f mm apart" % (self.distance * 1e3) if self.distance >= 0
                                       else "%.1f mm deep" % (-self.distance * 1e3))


def read_disabled_pairs(srdf_xml: str, prefix: str = "") -> Set[frozenset]:
    """The SRDF's ``disable_collisions`` pairs as frozensets of link names (with ``prefix``)."""
    try:
        root = ET.fromstring(srdf_xml)
    except ET.ParseError as exc:
        raise ModelError("SRDF is not valid XML: %s" % exc) from exc
    pairs = set()
    for el in root.iter("disable_collisions"):
        a, b = el.get("link1"), el.get("link2")
        if not a or not b:
            raise ModelError("SRDF: disable_collisions needs link1 and link2, got %r" % (el.attrib,))
        pairs.add(frozenset((prefix + a, prefix + b)))
    return pairs


def fresh_geometry_data(geom_model: Any, padding: float) -> Any:
    """A geometry data of its own for one query of ``geom_model`` (``padding`` as every pair's
    security margin, signed distances): coal's narrow phase on a data that queried other
    configurations before keeps what it found there -- a collision verdict missed link_4 inside
    link_6, and a penetration depth came out 1 to 3 um apart from the same configuration's on a
    fresh data (CollisionChecker.min_distance, whose depths the scene guard compares to 1 um).
    About 0.25 ms."""
    data = geom_model.createData()
    for req in data.collisionRequests:
        req.security_margin = padding
    for req in data.distanceRequests:
        req.enable_signed_distance = True
    return data


class CollisionChecker:
    """Collision queries for one robot model and one scene. Not thread-safe (one pinocchio Data):
    give each thread its own checker (:meth:`copy`)."""

    def __init__(self, model: Any, geom_model: Any, joint_names: Optional[Sequence[str]] = None,
                 disabled: Iterable[frozenset] = (), padding: float = 0.0, scene: Optional[Scene] = None,
                 adjacent_free: bool = False):
        self._pin = require("pinocchio")
        self._coal = require("coal")
        self.model = model
        self._robot_geom = geom_model
        self.data = model.createData()
        names = list(joint_names) if joint_names is not None else [model.names[i] for i in range(1, model.njoints)]
        idx = []
        for name in names:
            if not model.existJointName(name):
                raise ModelError("collision model: no joint %r (joints: %s)"
                                 % (name, ", ".join(model.names[i] for i in range(1, model.njoints))))
            joint = model.joints[model.getJointId(name)]
            if joint.nq != 1:
                raise ModelError("collision model: joint %s is not a 1-DOF joint (nq=%d)" % (name, joint.nq))
            idx.append(joint.idx_q)
        self.joint_names = tuple(names)
        self._q_index = np.array(idx, dtype=int)
        self._q = self._pin.neutral(model)
        #: whether the checked joints are the model's whole configuration, in its order
        self._q_whole = bool(np.array_equal(self._q_index, np.arange(len(self._q))))
        self._frames: dict = {}          # frame name -> id (frame_point)
        self.disabled = set(disabled)
        self.adjacent_free = adjacent_free
        # the link each robot geometry belongs to, and whether it moves
        self._geom_link = [model.frames[g.parentFrame].name for g in geom_model.geometryObjects]
        self._geom_moves = [g.parentJoint != 0 for g in geom_model.geometryObjects]
        self._adjacent = set()
        for jid in range(1, model.njoints):
            parent = model.parents[jid]
            a = [self._geom_link[k] for k, g in enumerate(geom_model.geometryObjects) if g.parentJoint == parent]
            b = [self._geom_link[k] for k, g in enumerate(geom_model.geometryObjects) if g.parentJoint == jid]
            self._adjacent.update(frozenset((x, y)) for x in a for y in b if x != y)
        self.padding = self._check_padding(padding)
        self._pool: Any = None           # the broad phase of the verdicts (_broad_phase), per scene and padding
        self._pool_data: Any = None      # its kinematics (point_here)
        self.scene = Scene()
        self.set_scene(scene if scene is not None else Scene())

    # ------------------------------------------------------------------------------------ factories
    @classmethod
    def from_urdf(cls, urdf_xml: str, srdf_xml: Optional[str] = None, padding: float = 0.0,
                  scene: Optional[Scene] = None, joint_names: Optional[Sequence[str]] = None,
                  prefix: str = "") -> "CollisionChecker":
        """From URDF text (rendered, no xacro) and SRDF text (its ``disable_collisions``; link names
        there without ``prefix``). Without an SRDF, links joined by one joint are not checked."""
        pin = require("pinocchio")
        try:
            model = pin.buildModelFromXML(urdf_xml)
            geom = pin.buildGeomFromUrdfString(model, urdf_xml, pin.GeometryType.COLLISION)
        except (RuntimeError, ValueError) as exc:
            raise ModelError("pinocchio cannot build the collision model from the URDF: %s" % exc) from exc
        disabled = read_disabled_pairs(srdf_xml, prefix) if srdf_xml is not None else set()
        if joint_names is None and prefix:
            joint_names = ["%sjoint_%d" % (prefix, i) for i in range(1, 7)]
        return cls(model, geom, joint_names, disabled, padding, scene, adjacent_free=srdf_xml is None)

    @classmethod
    def default(cls, padding: float = 0.0, scene: Optional[Scene] = None, prefix: str = "",
                model: str = "") -> "CollisionChecker":
        """The VR-006L: the support package's xacro (rendered; with ``model``, a kinematics YAML such as
        ``calibrate fit --write`` gives, the links at its dimensions and joint zero offsets, as the
        driver's kinematics then are), the moveit_config's SRDF."""
        import os

        from panasonic_vr006l_support import true_model
        from panasonic_vr006l_support.description import DescriptionError, default_xacro_path, package_dir, render_urdf
        try:
            if model:
                xml = true_model.render_urdf(model, prefix)
            else:
                xml = render_urdf(default_xacro_path(), {"prefix": prefix} if prefix else None)
        except (DescriptionError, true_model.TrueModelError) as exc:
            raise ModelError(str(exc)) from exc
        srdf = os.path.join(os.path.dirname(package_dir()), "panasonic_vr006l_moveit_config", "config",
                            "panasonic_vr006l.srdf")
        try:
            with open(srdf) as f:
                srdf_xml = f.read()
        except OSError as exc:
            raise ModelError("cannot read %s: %s" % (srdf, exc)) from exc
        return cls.from_urdf(xml, srdf_xml, padding, scene, prefix=prefix)

    def copy(self) -> "CollisionChecker":
        """An independent checker (own pinocchio data) on the same model, pairs, padding and scene:
        the models built for the scene are shared (nothing changes them once built: a new scene or
        padding of either checker builds or sets its own), the data are its own -- a tenth of
        building the checker anew, which a plan did three or four times."""
        new = object.__new__(type(self))
        new.__dict__.update(self.__dict__)
        new.data = self.model.createData()
        new.geom_data = self.geom_model.createData()
        for req in new.geom_data.distanceRequests:
            req.enable_signed_distance = True
        new._apply_padding()                 # (drops the broad phase: each checker builds its own)
        new._pool_data = None
        new._frames = dict(self._frames)
        new.disabled = set(self.disabled)
        new._adjacent = set(self._adjacent)
        new.scene = self.scene.copy()
        return new

    # ------------------------------------------------------------------------------------ scene
    @staticmethod
    def _check_padding(padding: Any) -> float:
        if isinstance(padding, bool) or not isinstance(padding, (int, float)) or not math.isfinite(padding) \
                or padding < 0.0:
            raise ValueError("padding must be a finite number >= 0 [m], got %r" % (padding,))
        return float(padding)

    def set_padding(self, padding: float) -> None:
        self.padding = self._check_padding(padding)
        self._apply_padding()

    def _apply_padding(self) -> None:
        # coal reports a collision below the security margin (GeometryData.setSecurityMargins wants a
        # matrix over all geometries: setting each pair's request is simpler)
        for req in self.geom_data.collisionRequests:
            req.security_margin = self.padding
        self._pool = None                # built again with the new margins

    def _shape(self, obj: SceneObject) -> Any:
        c = self._coal
        if obj.shape == "box":
            return c.Box(*obj.size)
        if obj.shape == "cylinder":
            return c.Cylinder(obj.size[0], obj.size[1])
        return c.Sphere(obj.size[0])

    def set_scene(self, scene: Scene) -> None:
        """Replace the world objects by those of ``scene`` (a snapshot: later changes to ``scene``
        need another set_scene) and rebuild the pairs."""
        if not isinstance(scene, Scene):
            raise TypeError("set_scene takes a Scene, got %r" % (scene,))
        pin = self._pin
        gm = self._robot_geom.clone()
        n_robot = gm.ngeoms
        names = set(g.name for g in gm.geometryObjects)
        objects = scene.objects()
        for obj in objects:
            if obj.name in names:
                raise ModelError("scene object %r has the name of a robot geometry" % obj.name)
            placement = pin.SE3(obj.rotation, np.array(obj.position, dtype=float))
            gm.addGeometryObject(pin.GeometryObject(obj.name, 0, 0, placement, self._shape(obj)))
        pairs: List[Tuple[int, int]] = []
        for i in range(n_robot):
            for j in range(i + 1, n_robot):
                a, b = self._geom_link[i], self._geom_link[j]
                if a == b or gm.geometryObjects[i].parentJoint == gm.geometryObjects[j].parentJoint:
                    continue   # rigidly attached: never move relative to each other
                if frozenset((a, b)) in self.disabled:
                    continue
                if self.adjacent_free and frozenset((a, b)) in self._adjacent:
                    continue
                pairs.append((i, j))
        for i in range(n_robot):
            if not self._geom_moves[i]:
                continue
            for k in range(len(objects)):
                pairs.append((i, n_robot + k))
        for i, j in pairs:
            gm.addCollisionPair(pin.CollisionPair(i, j))
        self.geom_model = gm
        self.geom_data = gm.createData()
        self._apply_padding()
        for req in self.geom_data.distanceRequests:
            req.enable_signed_distance = True
        self._pool = None                # the old scene's: built again for this one
        self._n_robot = n_robot
        self._pairs = pairs
        self._pair_names = [(self._geom_link[i], self._geom_link[j] if j < n_robot else gm.geometryObjects[j].name,
                             j >= n_robot) for i, j in pairs]
        self.scene = scene.copy()

    def checked_pairs(self) -> List[Tuple[str, str, bool]]:
        """(link, other link or object, world) of every checked pair, one per geometry pair."""
        return list(self._pair_names)

    # ------------------------------------------------------------------------------------ queries
    def _config(self, q: Sequence[float]) -> np.ndarray:
        try:
            # the common case in one step (a planner checks hundreds of thousands of configurations
            # a plan): the right length, every value finite; anything else is looked at below
            if len(q) == len(self._q_index):          # (not broadcast from one value)
                if self._q_whole:                     # the joints are the whole configuration
                    full = np.array(q, dtype=float)
                else:
                    full = self._q.copy()
                    full[self._q_index] = q
                # (a sum is finite only when every value is: one overflowing is looked at below)
                if full.shape == self._q.shape and math.isfinite(sum(q)):
                    return full
        except (TypeError, ValueError):
            pass
        try:
            arr = np.asarray(q, dtype=float).reshape(-1)
        except (TypeError, ValueError) as exc:
            raise PoseError("joint vector must be %d numbers, got %r" % (len(self.joint_names), q)) from exc
        if arr.shape[0] != len(self.joint_names):
            raise PoseError("joint vector must have %d values (%s), got %d"
                            % (len(self.joint_names), ", ".join(self.joint_names), arr.shape[0]))
        if not np.all(np.isfinite(arr)):
            bad = int(np.flatnonzero(~np.isfinite(arr))[0])
            raise PoseError("joint vector: %s is not finite (%r)" % (self.joint_names[bad], arr[bad]))
        full = self._q.copy()
        full[self._q_index] = arr
        return full

    def _broad_phase(self) -> Any:
        """The broad-phase pool of this checker's scene and padding (one geometry model and data;
        its pairs are the checked pairs, each with the padding as its security margin)."""
        pool = self._pool
        if pool is None:
            pool = self._pin.TreeBroadPhaseManagerPool_DynamicAABBTreeCollisionManager(self.model, self.geom_model, 1)
            for data in pool.getGeometryDatas():
                for req in data.collisionRequests:
                    req.security_margin = self.padding
            self._pool, self._pool_data = pool, pool.getData(0)
        return pool

    def _colliding(self, configs: np.ndarray) -> np.ndarray:
        """The broad phase's verdict per column of ``configs`` (model.nq x n, validated), in order,
        stopping at the first collision: True up to and at the first colliding column; the
        columns after it were not checked (False)."""
        return self._pin.computeCollisionsInParallel(1, self._broad_phase(), configs, True, True)

    def in_collision(self, q: Sequence[float]) -> bool:
        """True when any checked pair is closer than the padding (or overlaps) at ``q``."""
        return bool(self._colliding(self._config(q).reshape(-1, 1))[0])

    def first_collision(self, qs: Sequence[Sequence[float]]) -> Optional[int]:
        """The index of the first row of ``qs`` (n x the joints, [rad]) in collision -- as
        :meth:`in_collision` of each row in turn, in one call that stops there --, or None when
        every row is free. Every row is validated before any is checked (PoseError)."""
        arr = np.asarray(qs, dtype=float)
        if arr.ndim != 2 or arr.shape[1] != len(self._q_index) or not np.isfinite(arr).all():
            arr = np.array([self._config(q)[self._q_index] for q in qs], dtype=float).reshape(-1, len(self._q_index))
        if not len(arr):
            return None
        configs = np.repeat(self._q.reshape(-1, 1), len(arr), axis=1)
        configs[self._q_index, :] = arr.T
        hits = np.flatnonzero(self._colliding(np.asfortranarray(configs)))
        return int(hits[0]) if len(hits) else None

    def frame_point(self, q: Sequence[float], frame: str, point: Sequence[float] = (0.0, 0.0, 0.0)) -> np.ndarray:
        """The point ``point`` [m] of the model's frame ``frame`` in the root frame at ``q``.
        ModelError for a frame the model has not. (Pinocchio's forward kinematics: a twentieth of KDL's through its Python wrapper.)"""
        pin = self._pin
        fid = self._frames.get(frame)
        if fid is None:
            if not self.model.existFrame(frame):
                raise ModelError("collision model: no frame %r" % frame)
            fid = self._frames[frame] = self.model.getFrameId(frame)
        pin.forwardKinematics(self.model, self.data, self._config(q))
        return pin.updateFramePlacement(self.model, self.data, fid).act(np.asarray(point, dtype=float))

    def point_probe(self, frame: str, point: Sequence[float] = (0.0, 0.0, 0.0), outer: Any = None) -> Tuple[int, np.ndarray, Any]:
        """What :meth:`point_here` takes for the point ``point`` [m] of the model's frame ``frame``,
        seen through ``outer`` (a 4x4 from the model's root to another frame; None: the root).
        ModelError for a frame the model has not."""
        if not self.model.existFrame(frame):
            raise ModelError("collision model: no frame %r" % frame)
        f = self.model.frames[self.model.getFrameId(frame)]
        o = self._pin.SE3(np.eye(4) if outer is None else np.asarray(outer, dtype=float))
        return f.parentJoint, f.placement.act(np.asarray(point, dtype=float)), o

    def point_here(self, probe: Tuple[int, np.ndarray, Any]) -> np.ndarray:
        """The point of ``probe`` (:meth:`point_probe`) at the configuration of the last
        :meth:`in_collision`, from the kinematics that verdict computed (no forward kinematics
        again): that configuration checked against something else (the plan action's workspace
        box) at next to no cost. ModelError before any verdict."""
        if self._pool_data is None:
            raise ModelError("point_here: no in_collision was asked for before")
        joint, local, outer = probe
        return (outer * self._pool_data.oMi[joint]).act(local)

    def point_at(self, q: Sequence[float], probe: Tuple[int, np.ndarray, Any]) -> np.ndarray:
        """The point of ``probe`` (:meth:`point_probe`) at ``q``: a forward kinematics of its own
        (the configurations of a batch after its verdict, :meth:`first_collision`)."""
        joint, local, outer = probe
        self._pin.forwardKinematics(self.model, self.data, self._config(q))
        return (outer * self.data.oMi[joint]).act(local)

    def contacts(self, q: Sequence[float]) -> List[Contact]:
        """Every colliding pair at ``q`` (one per link / object pair: the deepest geometry pair),
        nearest first; [] when free. Each pair's narrow phase on a geometry data of its own (a
        fresh one: coal's narrow phase on a data that checked other configurations before missed
        a pair the verdicts find, module text)."""
        pin = self._pin
        data = fresh_geometry_data(self.geom_model, self.padding)
        pin.computeCollisions(self.model, self.data, self.geom_model, data, self._config(q), False)
        best = {}
        for k, res in enumerate(data.collisionResults):
            if not res.isCollision():
                continue
            pin.computeDistance(self.geom_model, data, k)
            d = float(data.distanceResults[k].min_distance)
            a, b, world = self._pair_names[k]
            key = (a, b, world)
            if key not in best or d < best[key].distance:
                best[key] = Contact(a, b, d, world)
        return sorted(best.values(), key=lambda c: (c.distance, c.link_a, c.other))

    def _distances(self, q: Sequence[float]) -> List[float]:
        """Every checked pair's distance [m] at ``q`` (true shapes; < 0: the depth), on a fresh
        geometry data: the same answer whatever was asked before."""
        data = fresh_geometry_data(self.geom_model, self.padding)
        self._pin.computeDistances(self.model, self.data, self.geom_model, data, self._config(q))
        return [float(r.min_distance) for r in data.distanceResults]

    def min_distance(self, q: Sequence[float]) -> float:
        """Smallest distance [m] over the checked pairs at ``q`` between the true (unpadded)
        shapes; < 0 when two overlap; inf when nothing is checked."""
        if not self._pairs:
            return math.inf
        return min(self._distances(q))

    def nearest(self, q: Sequence[float]) -> Contact:
        """The pair closest at ``q`` (colliding or not), as a Contact."""
        if not self._pairs:
            raise ModelError("no pair is checked")
        d = self._distances(q)
        k = int(np.argmin(d))
        a, b, world = self._pair_names[k]
        return Contact(a, b, d[k], world)

    def check_path(self, qs: Iterable[Sequence[float]]) -> Optional[Tuple[int, List[Contact]]]:
        """The first sample of ``qs`` in collision, as (its index, its contacts); None when every
        sample is free. Every sample is validated before any is checked."""
        configs = [self._config(q) for q in qs]
        if not configs:
            return None
        hits = np.flatnonzero(self._colliding(np.asfortranarray(np.stack(configs, axis=1))))
        if not len(hits):
            return None
        i = int(hits[0])
        return i, self.contacts(configs[i][self._q_index])
