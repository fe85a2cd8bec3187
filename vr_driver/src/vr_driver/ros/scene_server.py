"""The collision scene's ROS interface of the node `interface` (issue 27). ROS adapter only: the
scene, its checks and every decision are the core's (:mod:`vr_driver.driver.checks.scene_guard`).

- ``~scene/add`` (vr_driver/AddSceneObject): a vr_driver/SceneObject (name, shape box | cylinder |
  sphere, dimensions, pose in base_link) and ``replace``;
- ``~scene/remove`` (vr_driver/RemoveSceneObject): by name;
- ``~scene/list`` (vr_driver/ListSceneObjects): every object, in the order added;
- ``~scene/load`` (vr_driver/LoadScene): a cell YAML replaces the whole scene ("" clears it);
- ``~scene_markers`` (visualization_msgs/MarkerArray, latched): the objects (namespace ``scene``)
  and their names (``scene_names``) in <prefix>base_link, republished whole on every change;
- /diagnostics task ``collision``: whether checking is on, the padding, the objects, the refusals.

Bad input (an unknown shape, a wrong number of dimensions, NaN, a size <= 0, a zero quaternion, a
duplicate name without ``replace``, an unknown name, a bad file): success false, the message says
why, nothing changes. The names are private (``~``) like ``~markers``: the scene is this driver's.
"""
from __future__ import annotations

from typing import Any, List, Tuple

import rospy
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import Pose
from visualization_msgs.msg import Marker, MarkerArray

from vr_driver.msg import SceneObject as SceneObjectMsg
from vr_driver.srv import (AddSceneObject, AddSceneObjectResponse, ListSceneObjects, ListSceneObjectsResponse,
                           LoadScene, LoadSceneResponse, RemoveSceneObject, RemoveSceneObjectResponse)

from ..errors import VrDriverError
from ..kinematics.scene import SHAPES, FRAME, Scene, SceneObject

#: RGBA of the objects (a translucent orange: the arm stays visible through them)
OBJECT_COLOR = (1.0, 0.55, 0.1, 0.6)


def object_from_msg(msg: Any) -> SceneObject:
    """A SceneObject from a vr_driver/SceneObject message; SceneError naming the field."""
    from ..errors import SceneError
    if msg.shape not in SHAPES:
        raise SceneError("scene object %r: shape must be one of %s, got %r" % (msg.name, ", ".join(SHAPES), msg.shape))
    p, o = msg.pose.position, msg.pose.orientation
    return SceneObject(msg.name, msg.shape, tuple(msg.dimensions), (p.x, p.y, p.z),
                       quaternion=(o.x, o.y, o.z, o.w))


def object_to_msg(obj: SceneObject) -> Any:
    msg = SceneObjectMsg(name=obj.name, shape=obj.shape, dimensions=list(obj.size))
    msg.pose = _pose(obj)
    return msg


def _pose(obj: SceneObject) -> Pose:
    pose = Pose()
    pose.position.x, pose.position.y, pose.position.z = obj.position
    pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = obj.quaternion
    return pose


def scene_markers(scene: Scene, frame: str, stamp: Any) -> MarkerArray:
    """The whole scene as markers: a DELETEALL first (removed objects disappear), then per object
    its solid (ns ``scene``) and its name above it (ns ``scene_names``)."""
    markers: List[Marker] = [Marker(action=Marker.DELETEALL)]
    for i, obj in enumerate(scene.objects()):
        solid = Marker()
        solid.header.frame_id, solid.header.stamp = frame, stamp
        solid.ns, solid.id, solid.action = "scene", i, Marker.ADD
        solid.pose = _pose(obj)
        if obj.shape == "box":
            solid.type = Marker.CUBE
            solid.scale.x, solid.scale.y, solid.scale.z = obj.size
        elif obj.shape == "cylinder":
            solid.type = Marker.CYLINDER
            solid.scale.x = solid.scale.y = 2.0 * obj.size[0]
            solid.scale.z = obj.size[1]
        else:
            solid.type = Marker.SPHERE
            solid.scale.x = solid.scale.y = solid.scale.z = 2.0 * obj.size[0]
        solid.color.r, solid.color.g, solid.color.b, solid.color.a = OBJECT_COLOR
        label = Marker()
        label.header.frame_id, label.header.stamp = frame, stamp
        label.ns, label.id, label.action, label.type = "scene_names", i, Marker.ADD, Marker.TEXT_VIEW_FACING
        label.pose.position.x, label.pose.position.y = obj.position[0], obj.position[1]
        label.pose.position.z = obj.position[2] + obj.bounding_radius() + 0.05
        label.pose.orientation.w = 1.0
        label.scale.z = 0.06
        label.color.r = label.color.g = label.color.b = label.color.a = 1.0
        label.text = obj.name
        markers += [solid, label]
    return MarkerArray(markers=markers)


class SceneServer:
    """The services, the latched markers and the diagnostics task of the core's scene."""

    def __init__(self, core: Any, params: Any, diag: Any) -> None:
        self.core = core
        self.frame = params.prefix + FRAME
        self.marker_pub = rospy.Publisher("~scene_markers", MarkerArray, queue_size=1, latch=True)
        self.services = [
            rospy.Service("~scene/add", AddSceneObject, self._add),
            rospy.Service("~scene/remove", RemoveSceneObject, self._remove),
            rospy.Service("~scene/list", ListSceneObjects, self._list),
            rospy.Service("~scene/load", LoadScene, self._load),
        ]
        diag.add("collision", self._diag)
        core.scene_guard.add_listener(self._publish)
        self._publish(core.scene())

    def _publish(self, scene: Scene) -> None:
        try:
            self.marker_pub.publish(scene_markers(scene, self.frame, rospy.Time.now()))
        except Exception as exc:  # a display aid only
            rospy.logwarn("could not publish the scene markers: %s", exc)

    def _summary(self) -> str:
        scene = self.core.scene()
        guard = self.core.scene_guard
        return "%d object(s)%s; collision checking %s" % (
            len(scene), " (%s)" % ", ".join(scene.names()) if len(scene) else "",
            "on, padding %g m" % guard.padding if guard.active else guard.describe()["collision checking"])

    @staticmethod
    def _refused(what: str, exc: Exception) -> Tuple[bool, str]:
        rospy.logwarn("scene/%s refused: %s", what, exc)
        return False, "refused: %s; nothing changed" % exc

    def _add(self, req) -> AddSceneObjectResponse:
        try:
            obj = object_from_msg(req.object)
            warning = self.core.add_scene_object(obj, replace=req.replace)
        except (VrDriverError, ValueError, TypeError) as exc:
            return AddSceneObjectResponse(*self._refused("add", exc))
        text = "%s %s %s: %s" % ("put" if req.replace else "added", obj.shape, obj.name, self._summary())
        if warning:
            text += "; WARNING: %s" % warning
        return AddSceneObjectResponse(True, text)

    def _remove(self, req) -> RemoveSceneObjectResponse:
        try:
            obj = self.core.remove_scene_object(req.name)
        except (VrDriverError, ValueError, TypeError) as exc:
            return RemoveSceneObjectResponse(*self._refused("remove", exc))
        return RemoveSceneObjectResponse(True, "removed %s %s: %s" % (obj.shape, obj.name, self._summary()))

    def _list(self, _req) -> ListSceneObjectsResponse:
        return ListSceneObjectsResponse([object_to_msg(o) for o in self.core.scene()], self._summary())

    def _load(self, req) -> LoadSceneResponse:
        try:
            if req.path:
                self.core.load_scene(req.path)
            else:
                self.core.clear_scene()
        except (VrDriverError, ValueError, TypeError) as exc:
            return LoadSceneResponse(*self._refused("load", exc))
        return LoadSceneResponse(True, "%s: %s" % ("loaded %s" % req.path if req.path else "cleared", self._summary()))

    def _diag(self, stat):
        guard = self.core.scene_guard
        info = guard.describe()
        if guard.active:
            stat.summary(DiagnosticStatus.OK, "collision checking on: %s object(s)" % info["scene objects"])
        else:
            stat.summary(DiagnosticStatus.WARN, "collision checking %s" % info["collision checking"])
        for key, value in info.items():
            stat.add(key, value)
        return stat
