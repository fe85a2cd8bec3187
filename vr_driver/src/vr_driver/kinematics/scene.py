"""The robot's cell as simple solids: boxes, cylinders and spheres placed in ``base_link`` (the
robot's mounting frame), which the collision checker (kinematics.collision) tests the arm against.
ROS-free and dependency-free (numpy, PyYAML): loading and validating a cell needs neither pinocchio
nor coal.

A cell file (doc/collision_scene.md; example: panasonic_vr006l_support/config/cell_example.yaml)::

    frame: base_link              # optional; the only frame objects may be given in
    objects:
      - name: table               # unique, non-empty
        type: box                 # box | cylinder | sphere
        size: [0.8, 1.2, 0.05]    # box: full edge lengths x, y, z [m], each > 0
        position: [0.9, 0.0, 0.3] # centre of the solid [m]
        rpy: [0.0, 0.0, 0.0]      # optional [rad], URDF convention (fixed axes x, then y, then z)
      - name: pillar
        type: cylinder
        radius: 0.1               # > 0 [m]
        length: 1.8               # > 0 [m], along the object's z axis, centred on position
        position: [0.2, 0.75, 0.9]
        quaternion: [0, 0, 0, 1]  # instead of rpy: x, y, z, w (normalised here; not all zero)
      - name: ball
        type: sphere
        radius: 0.05
        position: [0.5, -0.5, 0.2]

Every entry is checked whole before the scene changes: an unknown key, a missing key, a value that
is not a finite number (NaN, inf, a bool, text), a size <= 0, both ``rpy`` and ``quaternion``, a
duplicate name: a SceneError naming the file, the entry (its index and name) and the key.
"""
from __future__ import annotations

import math
from typing import Any, Dict, Iterator, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from vr_driver.errors import SceneError
from vr_driver.validate import as_finite

__all__ = ["SHAPES", "FRAME", "SceneObject", "Scene", "SceneError", "load_scene", "parse_scene", "scene_from_dict"]

#: the frame every object is placed in
FRAME = "base_link"

#: shape type -> its size keys (in the order of SceneObject.size)
SHAPES: Dict[str, Tuple[str, ...]] = {
    "box": ("size",),
    "cylinder": ("radius", "length"),
    "sphere": ("radius",),
}
_POSE_KEYS = ("position", "rpy", "quaternion")
_TOP_KEYS = ("frame", "objects")


def _quat_from_rpy(roll: float, pitch: float, yaw: float) -> Tuple[float, float, float, float]:
    """(x, y, z, w) of R = Rz(yaw) Ry(pitch) Rx(roll), the URDF's rpy."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
            cr * cp * cy + sr * sp * sy)


def _rotation(q: Sequence[float]) -> np.ndarray:
    x, y, z, w = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


class SceneObject:
    """One solid of the cell, immutable. ``shape``: "box" | "cylinder" | "sphere"; ``size``: box
    (x, y, z) full edge lengths, cylinder (radius, length) along its z axis, sphere (radius,) [m];
    ``position`` of its centre and ``quaternion`` (x, y, z, w, unit) of its orientation in
    base_link. Build with keyword arguments (``rpy=`` or ``quaternion=``), or :meth:`from_dict`;
    a bad value raises SceneError naming the object and the key."""

    __slots__ = ("name", "shape", "size", "position", "quaternion")

    def __init__(self, name: str, shape: str, size: Sequence[float], position: Sequence[float] = (0.0, 0.0, 0.0),
                 rpy: Optional[Sequence[float]] = None, quaternion: Optional[Sequence[float]] = None,
                 *, where: Optional[str] = None):
        # where: what each message starts with (default "scene object 'NAME'"; a file's entry from from_dict)
        if not isinstance(name, str) or not name.strip():
            raise SceneError("%s: name must be a non-empty string, got %r" % (where or "scene object", name))
        where = where or "scene object %r" % name
        if shape not in SHAPES:
            raise SceneError("%s: type must be one of %s, got %r" % (where, ", ".join(SHAPES), shape))
        keys = SHAPES[shape] if shape != "box" else ("x", "y", "z")
        if not _seq(size) or len(size) != len(keys):
            raise SceneError("%s: a %s's size must be a list of %d numbers (%s), got %r"
                             % (where, shape, len(keys), ", ".join(keys), size))
        size_t = tuple(_positive(v, where, "size[%d]" % i if shape == "box" else k)
                       for i, (k, v) in enumerate(zip(keys, size)))
        pos = _vector(position, 3, where, "position")
        if rpy is not None and quaternion is not None:
            raise SceneError("%s: give rpy or quaternion, not both" % where)
        if quaternion is not None:
            qv = _vector(quaternion, 4, where, "quaternion")
            norm = math.sqrt(sum(v * v for v in qv))
            if norm < 1e-9:
                raise SceneError("%s: quaternion must not be all zero" % where)
            quat = tuple(v / norm for v in qv)
        else:
            quat = _quat_from_rpy(*_vector(rpy if rpy is not None else (0.0, 0.0, 0.0), 3, where, "rpy"))
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "shape", shape)
        object.__setattr__(self, "size", tuple(size_t))
        object.__setattr__(self, "position", pos)
        object.__setattr__(self, "quaternion", tuple(float(v) for v in quat))

    def __setattr__(self, key: str, value: Any) -> None:
        raise AttributeError("SceneObject is immutable")

    def __eq__(self, other: object) -> bool:
        return isinstance(other, SceneObject) and all(getattr(self, k) == getattr(other, k) for k in self.__slots__)

    def __hash__(self) -> int:
        return hash(tuple(getattr(self, k) for k in self.__slots__))

    def __repr__(self) -> str:
        return "SceneObject(%r, %r, size=%r, position=%r, quaternion=%r)" % (
            self.name, self.shape, self.size, self.position, self.quaternion)

    @property
    def rotation(self) -> np.ndarray:
        """3x3 rotation matrix of the object in base_link."""
        return _rotation(self.quaternion)

    @property
    def transform(self) -> np.ndarray:
        """4x4 homogeneous transform base_link <- object."""
        t = np.eye(4)
        t[:3, :3] = self.rotation
        t[:3, 3] = self.position
        return t

    def bounding_radius(self) -> float:
        """Radius of a sphere about ``position`` that holds the whole solid."""
        if self.shape == "box":
            return 0.5 * math.sqrt(sum(v * v for v in self.size))
        if self.shape == "cylinder":
            return math.hypot(self.size[0], self.size[1] / 2)
        return self.size[0]

    @classmethod
    def from_dict(cls, entry: Any, where: str = "scene object") -> "SceneObject":
        """One entry of a cell file's ``objects`` (see the module docstring); ``where`` prefixes
        each message (the file and index)."""
        if not isinstance(entry, Mapping):
            raise SceneError("%s: must be a mapping with name, type, size and position, got %r" % (where, entry))
        name = entry.get("name")
        if not isinstance(name, str) or not name.strip():
            raise SceneError("%s: name must be a non-empty string, got %r" % (where, name))
        where = "%s (%s)" % (where, name)
        shape = entry.get("type")
        if shape not in SHAPES:
            raise SceneError("%s: type must be one of %s, got %r" % (where, ", ".join(SHAPES), shape))
        allowed = ("name", "type") + SHAPES[shape] + _POSE_KEYS
        unknown = sorted(str(k) for k in entry if k not in allowed)
        if unknown:
            raise SceneError("%s: unknown key %s (a %s takes %s)" % (where, ", ".join(unknown), shape,
                                                                     ", ".join(allowed)))
        for key in SHAPES[shape] + ("position",):
            if key not in entry:
                raise SceneError("%s: missing key %s" % (where, key))
        size = entry["size"] if shape == "box" else [entry[k] for k in SHAPES[shape]]
        return cls(name, shape, size, entry["position"], entry.get("rpy"), entry.get("quaternion"), where=where)

    def to_dict(self) -> Dict[str, Any]:
        """The entry of a cell file that gives this object back (orientation as a quaternion)."""
        out: Dict[str, Any] = {"name": self.name, "type": self.shape}
        if self.shape == "box":
            out["size"] = list(self.size)
        else:
            out.update(zip(SHAPES[self.shape], self.size))
        out["position"] = list(self.position)
        out["quaternion"] = list(self.quaternion)
        return out


def _seq(value: Any) -> bool:
    return isinstance(value, (list, tuple, np.ndarray))


def _number(value: Any, where: str, key: str) -> float:
    got = as_finite(value, text=False) if not isinstance(value, np.floating) else as_finite(float(value))
    if got is None:
        raise SceneError("%s: %s must be a finite number, got %r" % (where, key, value))
    return got


def _positive(value: Any, where: str, key: str) -> float:
    got = _number(value, where, key)
    if got <= 0.0:
        raise SceneError("%s: %s must be > 0 [m], got %r" % (where, key, value))
    return got


def _vector(value: Any, n: int, where: str, key: str, positive: bool = False) -> Tuple[float, ...]:
    if not _seq(value) or len(value) != n:
        raise SceneError("%s: %s must be a list of %d numbers, got %r" % (where, key, n, value))
    check = _positive if positive else _number
    return tuple(check(v, where, "%s[%d]" % (key, i)) for i, v in enumerate(value))


class Scene:
    """The cell's objects by name, in insertion order. ``add`` / ``remove`` / ``replace`` check
    before they change anything; ``version`` counts the changes (a checker built on a scene can tell
    it is stale)."""

    def __init__(self, objects: Sequence[SceneObject] = ()):
        self._objects: Dict[str, SceneObject] = {}
        self.version = 0
        self.add_all(objects)

    def add(self, obj: SceneObject) -> None:
        """Add ``obj``; SceneError when its name is taken (nothing changes)."""
        if not isinstance(obj, SceneObject):
            raise SceneError("scene: can only add a SceneObject, got %r" % (obj,))
        if obj.name in self._objects:
            raise SceneError("scene: an object named %r is already in the scene" % obj.name)
        self._objects[obj.name] = obj
        self.version += 1

    def add_all(self, objects: Sequence[SceneObject]) -> None:
        """Add every object, or none (a duplicate among them or with the scene: SceneError)."""
        objects = list(objects)
        names = [o.name for o in objects if isinstance(o, SceneObject)]
        for obj in objects:
            if not isinstance(obj, SceneObject):
                raise SceneError("scene: can only add a SceneObject, got %r" % (obj,))
        for i, name in enumerate(names):
            if name in self._objects or name in names[:i]:
                raise SceneError("scene: an object named %r is already in the scene" % name)
        for obj in objects:
            self.add(obj)

    def remove(self, name: str) -> SceneObject:
        """Remove and return the object ``name``; SceneError naming the known ones when absent."""
        if name not in self._objects:
            raise SceneError("scene: no object named %r (objects: %s)" % (name, ", ".join(self._objects) or "none"))
        self.version += 1
        return self._objects.pop(name)

    def replace(self, obj: SceneObject) -> None:
        """Put ``obj`` in place of the object of the same name (moved or resized)."""
        if obj.name not in self._objects:
            raise SceneError("scene: no object named %r to replace" % obj.name)
        self._objects[obj.name] = obj
        self.version += 1

    def clear(self) -> None:
        self._objects.clear()
        self.version += 1

    def get(self, name: str) -> SceneObject:
        if name not in self._objects:
            raise SceneError("scene: no object named %r (objects: %s)" % (name, ", ".join(self._objects) or "none"))
        return self._objects[name]

    def names(self) -> List[str]:
        return list(self._objects)

    def objects(self) -> List[SceneObject]:
        return list(self._objects.values())

    def copy(self) -> "Scene":
        return Scene(self.objects())

    def __contains__(self, name: object) -> bool:
        return name in self._objects

    def __iter__(self) -> Iterator[SceneObject]:
        return iter(list(self._objects.values()))

    def __len__(self) -> int:
        return len(self._objects)

    def __repr__(self) -> str:
        return "Scene(%s)" % ", ".join("%s %s" % (o.shape, o.name) for o in self._objects.values())

    def to_dict(self) -> Dict[str, Any]:
        """The cell file's content (``yaml.safe_dump`` it to save the scene)."""
        return {"frame": FRAME, "objects": [o.to_dict() for o in self._objects.values()]}


def scene_from_dict(data: Any, source: str = "") -> Scene:
    """A Scene from a cell file's parsed content; SceneError naming ``source``, the entry and the key."""
    prefix = "%s: " % source if source else ""
    if data is None:
        return Scene()
    if not isinstance(data, Mapping):
        raise SceneError("%scell file must be a mapping with 'objects' (and optionally 'frame'), got %s"
                         % (prefix, type(data).__name__))
    unknown = sorted(str(k) for k in data if k not in _TOP_KEYS)
    if unknown:
        raise SceneError("%sunknown key %s (a cell file takes %s)" % (prefix, ", ".join(unknown), ", ".join(_TOP_KEYS)))
    frame = data.get("frame", FRAME)
    if frame != FRAME:
        raise SceneError("%sframe must be %s (objects are placed in the robot's mounting frame), got %r"
                         % (prefix, FRAME, frame))
    entries = data.get("objects") or []
    if not isinstance(entries, list):
        raise SceneError("%sobjects must be a list, got %s" % (prefix, type(entries).__name__))
    objects: List[SceneObject] = []
    seen: Dict[str, int] = {}
    for i, entry in enumerate(entries):
        obj = SceneObject.from_dict(entry, "%sobjects[%d]" % (prefix, i))
        if obj.name in seen:
            raise SceneError("%sobjects[%d] (%s): duplicate name, already used by objects[%d]"
                             % (prefix, i, obj.name, seen[obj.name]))
        seen[obj.name] = i
        objects.append(obj)
    return Scene(objects)


def parse_scene(text: str, source: str = "") -> Scene:
    """A Scene from a cell file's YAML text."""
    import yaml

    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise SceneError("%snot valid YAML: %s" % ("%s: " % source if source else "", exc)) from exc
    return scene_from_dict(data, source)


def load_scene(path: str) -> Scene:
    """A Scene from a cell file; SceneError naming the file when it cannot be read or is invalid."""
    try:
        with open(path) as f:
            text = f.read()
    except OSError as exc:
        raise SceneError("cannot read cell file %s: %s" % (path, exc)) from exc
    return parse_scene(text, path)
