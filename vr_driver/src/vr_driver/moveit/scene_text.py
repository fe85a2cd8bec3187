"""The cell (:class:`vr_driver.kinematics.scene.Scene`) as the text MoveIt 1 reads into its planning
scene (``PlanningScene::loadGeometryFromStream``, MoveIt 1.1's format, which
``moveit_ros_planning``'s ``publish_scene_from_text`` publishes):

    <scene name>
    * <object id>
    <x y z of the object>            the object's pose in the planning frame (the robot's root link)
    <qx qy qz qw>
    <number of shapes>               then per shape:
    box | cylinder | sphere          geometric_shapes' name
    <dimensions>                     box: x y z; cylinder: radius length; sphere: radius
    <x y z>  <qx qy qz qw>           the shape's pose in the object (here: none)
    <r g b a>                        its colour (0 0 0 0: MoveIt's default)
    <number of subframes>            0
    .                                the end

Each shape is inflated by the driver's ``collision_padding`` (box edges by 2 p, cylinder radius by p
and length by 2 p, sphere radius by p): every point within p of the true shape is inside the
exported one, so a configuration MoveIt finds free keeps every link at least p from the object, as
the driver's check demands (its padding is a margin on each link / object pair)."""
from __future__ import annotations

import math
from typing import List, Sequence, Tuple

from vr_driver.errors import SceneError
from vr_driver.kinematics.scene import Scene, SceneObject
from vr_driver.poses import Workspace

#: the colour of exported objects (RGBA; MoveIt shows objects without one in its scene colour)
COLOUR = (0.55, 0.55, 0.6, 1.0)


def _num(v: float) -> str:
    """A number as the text stream reads it back exactly enough (0.1 um, 1e-9 of a unit quaternion)."""
    text = "%.10g" % v
    return "0" if text in ("-0", "0") else text


def padded_size(obj: SceneObject, padding: float) -> Tuple[float, ...]:
    """The object's dimensions grown by ``padding`` [m] on every side (see the module text)."""
    if obj.shape == "box":
        return tuple(s + 2.0 * padding for s in obj.size)
    if obj.shape == "cylinder":
        return (obj.size[0] + padding, obj.size[1] + 2.0 * padding)
    return (obj.size[0] + padding,)


#: the faces of the driver's workspace box that become walls in MoveIt's scene: those beyond the
#: robot's own column. x_min (100 mm before the joint_1 axis) and z_min (the mounting surface) would
#: cut the base and the shoulder, which MoveIt checks against every object: they stay the driver's.
WALL_FACES = ("x_max", "y_min", "y_max", "z_max")
WALL_THICKNESS = 0.1            # m
#: walls faint (where the colours are read: RViz's Scene Objects import; publish_scene_from_text
#: sends the objects without them, RViz then draws its scene colour)
WALL_COLOUR = (0.9, 0.6, 0.2, 0.12)


def workspace_walls(workspace: Workspace, base_frame_z: float = 0.0,
                    faces: Sequence[str] = WALL_FACES) -> List[SceneObject]:
    """Slabs (``workspace_<face>``) just outside the given faces of the driver's workspace box (mm, in
    the controller's frame ``base``, ``base_frame_z`` [m] above base_link), each covering its face
    and the slabs beside it: an arm MoveIt keeps clear of them keeps its flange inside those faces
    (a TCP offset beyond the flange is not in the URDF: the driver still checks it)."""
    lo = [v / 1000.0 for v in (workspace.x[0], workspace.y[0], workspace.z[0])]
    hi = [v / 1000.0 for v in (workspace.x[1], workspace.y[1], workspace.z[1])]
    lo[2] += base_frame_z
    hi[2] += base_frame_z
    t = WALL_THICKNESS
    walls = []
    for face in faces:
        axis = "xyz".index(face[0])
        upper = face.endswith("max")
        size, centre = [], []
        for i in range(3):
            if i == axis:
                size.append(t)
                centre.append(hi[i] + t / 2.0 if upper else lo[i] - t / 2.0)
            else:
                size.append(hi[i] - lo[i] + 2.0 * t)
                centre.append((hi[i] + lo[i]) / 2.0)
        walls.append(SceneObject("workspace_" + face, "box", size, centre))
    return walls


def scene_text(scene: Scene, padding: float = 0.0, name: str = "vr006l_cell",
               colour: Sequence[float] = COLOUR, walls: Sequence[SceneObject] = ()) -> str:
    """The ``.scene`` text of ``scene``, every shape inflated by ``padding`` [m] (>= 0), then
    ``walls`` (:func:`workspace_walls`; not inflated: the box bounds the TCP, not a clearance)."""
    if isinstance(padding, bool) or not isinstance(padding, (int, float)) or not math.isfinite(padding) \
            or padding < 0.0:
        raise SceneError("padding must be a number >= 0 [m], got %r" % (padding,))
    if not name.strip() or "\n" in name:
        raise SceneError("the scene name must be one non-empty line, got %r" % name)
    lines: List[str] = [name]
    items = [(obj, float(padding), colour) for obj in scene.objects()] + [(w, 0.0, WALL_COLOUR) for w in walls]
    for obj, pad, rgba in items:
        if any(c.isspace() for c in obj.name):
            # MoveIt reads an object id to the end of its line but a subframe name up to a blank:
            # keep ids one word so every reader agrees
            raise SceneError("scene object %r: MoveIt's scene text needs a name without blanks" % obj.name)
        lines.append("* " + obj.name)
        lines.append(" ".join(_num(v) for v in obj.position))
        lines.append(" ".join(_num(v) for v in obj.quaternion))
        lines.append("1")
        lines.append(obj.shape)
        lines.append(" ".join(_num(v) for v in padded_size(obj, pad)))
        lines.append("0 0 0")
        lines.append("0 0 0 1")
        lines.append(" ".join(_num(v) for v in rgba))
        lines.append("0")
    lines.append(".")
    return "\n".join(lines) + "\n"
