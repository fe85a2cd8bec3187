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


def scene_text(scene: Scene, padding: float = 0.0, name: str = "vr006l_cell",
               colour: Sequence[float] = COLOUR) -> str:
    """The ``.scene`` text of ``scene``, every shape inflated by ``padding`` [m] (>= 0)."""
    if isinstance(padding, bool) or not isinstance(padding, (int, float)) or not math.isfinite(padding) \
            or padding < 0.0:
        raise SceneError("padding must be a number >= 0 [m], got %r" % (padding,))
    if not name.strip() or "\n" in name:
        raise SceneError("the scene name must be one non-empty line, got %r" % name)
    lines: List[str] = [name]
    for obj in scene.objects():
        if any(c.isspace() for c in obj.name):
            # MoveIt reads an object id to the end of its line but a subframe name up to a blank:
            # keep ids one word so every reader agrees
            raise SceneError("scene object %r: MoveIt's scene text needs a name without blanks" % obj.name)
        lines.append("* " + obj.name)
        lines.append(" ".join(_num(v) for v in obj.position))
        lines.append(" ".join(_num(v) for v in obj.quaternion))
        lines.append("1")
        lines.append(obj.shape)
        lines.append(" ".join(_num(v) for v in padded_size(obj, float(padding))))
        lines.append("0 0 0")
        lines.append("0 0 0 1")
        lines.append(" ".join(_num(v) for v in colour))
        lines.append("0")
    lines.append(".")
    return "\n".join(lines) + "\n"
