#!/usr/bin/python3
"""rostest of the collision scene's ROS interface (test/scene.test: driver.launch with
scene:=the example cell, against the virtual controller): ~scene/list gives the cell, the latched
~scene_markers show it, ~scene/add / remove / load change it and the verdict of move_to_pose, bad
input changes nothing, /diagnostics reports it; a PTP into the pillar is refused naming the link
and the object, and the controller executes only the motions that were accepted; a trajectory sent
as MoveIt sends one, through the pillar, ends with one line saying why and what to change."""
from __future__ import annotations

import json

import rospy
import rostest
from actionlib_msgs.msg import GoalStatus
from geometry_msgs.msg import Pose
from visualization_msgs.msg import Marker, MarkerArray

from driver_check import DriverTestBase, Recorder
from vr_driver.msg import FollowJointTrajectoryResult, MoveToPoseGoal, SceneObject
from vr_driver.srv import AddSceneObject, ListSceneObjects, LoadScene, RemoveSceneObject

PKG = "vr_driver"
CELL_NAMES = ["table", "pillar", "shelf"]
HOME_Q = (0.0, 0.645469, -0.280043, 0.0, 0.419972, 0.0)


def pose(x, y, z, q=(0.0, 0.0, 0.0, 1.0)) -> Pose:
    p = Pose()
    p.position.x, p.position.y, p.position.z = x, y, z
    p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w = q
    return p


def target(kin, q):
    """The controller pose of the joints ``q``, rounded as the wire carries it."""
    return tuple(round(v) for v in kin.fk_pose(q).as_tuple())


class SceneTest(DriverTestBase):
    @classmethod
    def setUpClass(cls):
        super().setUpClass()
        for name in ("add", "remove", "list", "load"):
            rospy.wait_for_service("/interface/scene/" + name, 20.0)
        cls.add = rospy.ServiceProxy("/interface/scene/add", AddSceneObject)
        cls.remove = rospy.ServiceProxy("/interface/scene/remove", RemoveSceneObject)
        cls.list = rospy.ServiceProxy("/interface/scene/list", ListSceneObjects)
        cls.load = rospy.ServiceProxy("/interface/scene/load", LoadScene)
        cls.scene_markers = Recorder("/interface/scene_markers", MarkerArray)
        cls.cell = rospy.get_param("/interface/scene")

    def setUp(self):
        self.loaded_at = rospy.Time.now()         # the markers of this load are stamped at or after it
        response = self.load(self.cell)
        self.assertTrue(response.success, response.message)

    def names(self):
        return [o.name for o in self.list().objects]

    def markers_with(self, names, timeout=5.0):
        """The latest scene markers once they show exactly ``names`` (ns scene)."""
        def shows(msg):
            return [m.text for m in msg.markers if m.ns == "scene_names"] == list(names)
        msg = self.scene_markers.wait_for(shows, timeout, start=max(0, len(self.scene_markers.messages) - 1))
        self.assertIsNotNone(msg, "no scene markers showing %s" % (names,))
        return msg

    def test_1_list_markers_and_diagnostics_show_the_cell(self):
        objects = self.list().objects
        self.assertEqual([o.name for o in objects], CELL_NAMES)
        pillar = objects[1]
        self.assertEqual((pillar.shape, tuple(pillar.dimensions)), ("cylinder", (0.1, 2.2)))
        self.assertAlmostEqual(pillar.pose.position.x, 0.62)
        self.assertIn("collision checking on", self.list().message)
        # latched: a subscriber that comes late still gets the scene
        late = rospy.wait_for_message("/interface/scene_markers", MarkerArray, 5.0)
        solids = [m for m in late.markers if m.ns == "scene"]
        self.assertEqual(late.markers[0].action, Marker.DELETEALL)
        self.assertEqual([m.type for m in solids], [Marker.CUBE, Marker.CYLINDER, Marker.CUBE])
        self.assertEqual({m.header.frame_id for m in solids}, {"base_link"})
        self.assertAlmostEqual(solids[1].scale.x, 0.2)
        # (diagnostic_updater's first message says "Node starting up" with no values: wait for the task's)
        def filled(m):
            return any(s.name.endswith("collision") and any(kv.key == "collision checking" for kv in s.values)
                       for s in m.status)
        diag = self.diag.wait_for(filled, 10.0)
        self.assertIsNotNone(diag, "no collision diagnostics")
        status = [s for s in diag.status if s.name.endswith("collision")][0]
        values = {kv.key: kv.value for kv in status.values}
        self.assertEqual((values["collision checking"], values["scene objects"]), ("on", "3"))

    def test_2_a_ptp_into_the_pillar_is_refused_naming_the_link_and_the_object(self):
        self.at_home()
        q = list(HOME_Q)
        q[0] = 0.8                                    # the stretched arm turned 46 deg left: in the pillar
        refused = target(self.kin, q)
        state, result = self.move(MoveToPoseGoal.PTP, refused)
        self.assertEqual(state, GoalStatus.ABORTED, result.reason)
        self.assertRegex(result.reason, r"^refused: PTP path collides (at sample|between samples) \d+")
        self.assertIn("with pillar (penetration", result.reason)
        self.assertRegex(result.reason, r"link_\d with pillar")
        # the next motion reaches the controller; the refused one, sent before it, never did
        q[0] = -0.3
        accepted = target(self.kin, q)
        state, result = self.move(MoveToPoseGoal.PTP, accepted)
        self.assertEqual(state, GoalStatus.SUCCEEDED, result.reason)
        self.assertIsNotNone(self.executed.wait_for(lambda m: json.loads(m.data)["target"] == list(accepted), 10.0))
        self.assertNotIn(list(refused), [e["target"] for e in self.entries()])

    def test_2b_a_moveit_trajectory_through_the_pillar_says_why_and_what_to_change(self):
        """MoveIt without the cell plans through the pillar; the driver refuses, and the result's
        error_string (logged by MoveIt's controller manager) is one line naming the object, the
        padding and the launch argument that gives MoveIt the cell."""
        start = self.at_home()
        q = list(HOME_Q)
        q[0] = 0.8
        state, result = self.follow(self.trajectory_goal([start, q], [0.0, 2.0]))
        self.assertEqual(state, GoalStatus.ABORTED, result.error_string)
        self.assertEqual(result.error_code, FollowJointTrajectoryResult.INVALID_GOAL)
        text = result.error_string
        self.assertNotIn("\n", text)
        self.assertRegex(text, r"^refused by the driver: trajectory collides .*with pillar.*nothing was sent -- ")
        self.assertIn("MoveIt's planning scene lacks pillar or the driver's padding (padding 10 mm)", text)
        self.assertIn("moveit_planning_execution.launch scene:=", text)
        self.assertNotIn(list(target(self.kin, q)), [e["target"] for e in self.entries()])

    def test_3_add_remove_change_the_verdict(self):
        self.at_home()
        q = list(HOME_Q)
        q[0] = -0.6
        goal = target(self.kin, q)
        state, result = self.move(MoveToPoseGoal.PTP, goal, preview_only=True)
        self.assertEqual(state, GoalStatus.SUCCEEDED, result.reason)
        crate = SceneObject(name="crate", shape=SceneObject.BOX, dimensions=[0.3, 0.3, 0.6],
                            pose=pose(0.85, -0.55, 0.75))
        response = self.add(crate, False)
        self.assertTrue(response.success, response.message)
        self.assertIn("added box crate", response.message)
        self.assertEqual(self.names(), CELL_NAMES + ["crate"])
        self.markers_with(CELL_NAMES + ["crate"])
        state, result = self.move(MoveToPoseGoal.PTP, goal, preview_only=True)
        self.assertEqual(state, GoalStatus.ABORTED)
        self.assertIn("with crate", result.reason)
        response = self.remove("crate")
        self.assertTrue(response.success, response.message)
        self.markers_with(CELL_NAMES)
        state, result = self.move(MoveToPoseGoal.PTP, goal, preview_only=True)
        self.assertEqual(state, GoalStatus.SUCCEEDED, result.reason)

    def marker_index(self, predicate, timeout=5.0):
        """The index among the scene markers received of the first that satisfies ``predicate``."""
        msg = self.scene_markers.wait_for(predicate, timeout)
        self.assertIsNotNone(msg, "no such scene markers within %.0f s" % timeout)
        with self.scene_markers.cond:
            return next(i for i, m in enumerate(self.scene_markers.messages) if m is msg)

    def test_4_bad_input_changes_nothing(self):
        # the markers of setUp's load first: they may arrive after the load's reply (they did under
        # load, and were counted as a republication); the next markers are those of the probe below
        loaded = self.marker_index(lambda m: any(k.ns == "scene_names" and k.header.stamp >= self.loaded_at
                                                 for k in m.markers))
        nan = float("nan")
        bad = [
            (SceneObject(name="cone", shape="cone", dimensions=[0.1], pose=pose(1, 0, 1)), "shape must be one of"),
            (SceneObject(name="b", shape="box", dimensions=[0.1, nan, 0.1], pose=pose(1, 0, 1)), "finite"),
            (SceneObject(name="b", shape="box", dimensions=[0.1, -0.2, 0.1], pose=pose(1, 0, 1)), "> 0"),
            (SceneObject(name="b", shape="sphere", dimensions=[0.1, 0.2], pose=pose(1, 0, 1)), "size"),
            (SceneObject(name="b", shape="sphere", dimensions=[0.1], pose=pose(nan, 0, 1)), "position"),
            (SceneObject(name="b", shape="sphere", dimensions=[0.1], pose=pose(1, 0, 1, (0, 0, 0, 0))), "quaternion"),
            (SceneObject(name="", shape="sphere", dimensions=[0.1], pose=pose(1, 0, 1)), "name"),
            (SceneObject(name="pillar", shape="sphere", dimensions=[0.1], pose=pose(1, 0, 1)), "already in the scene"),
        ]
        for obj, why in bad:
            response = self.add(obj, False)
            self.assertFalse(response.success, obj)
            self.assertIn(why, response.message)
            self.assertTrue(response.message.startswith("refused: ") and "nothing changed" in response.message)
        response = self.remove("nothing")
        self.assertFalse(response.success)
        self.assertIn("no object named 'nothing'", response.message)
        response = self.load("/nonexistent/cell.yaml")
        self.assertFalse(response.success)
        self.assertIn("/nonexistent/cell.yaml", response.message)
        objects = self.list().objects
        self.assertEqual([o.name for o in objects], CELL_NAMES)
        self.assertEqual(objects[1].shape, "cylinder")
        # a real change after them: its markers come next, in order on the one connection, unless a
        # refused input republished the scene before it
        probe = SceneObject(name="probe", shape="sphere", dimensions=[0.05], pose=pose(1.0, 0.0, 1.6))
        self.assertTrue(self.add(probe, False).success)
        shown = self.marker_index(lambda m: "probe" in [k.text for k in m.markers if k.ns == "scene_names"])
        with self.scene_markers.cond:
            between = self.scene_markers.messages[loaded + 1:shown]
        self.assertEqual(len(between), 0, "markers republished without a change: %d message(s)" % len(between))
        self.assertTrue(self.remove("probe").success)

    def test_5_replace_load_and_clear(self):
        moved = SceneObject(name="pillar", shape=SceneObject.SPHERE, dimensions=[0.05], pose=pose(0.3, 0.9, 1.5))
        response = self.add(moved, True)
        self.assertTrue(response.success, response.message)
        objects = self.list().objects
        self.assertEqual([o.name for o in objects], CELL_NAMES)
        self.assertEqual((objects[1].shape, objects[1].pose.position.z), ("sphere", 1.5))
        response = self.load("")
        self.assertTrue(response.success, response.message)
        self.assertEqual(self.names(), [])
        self.markers_with([])
        response = self.load(self.cell)
        self.assertTrue(response.success, response.message)
        self.assertEqual(self.names(), CELL_NAMES)
        self.markers_with(CELL_NAMES)


if __name__ == "__main__":
    rostest.rosrun(PKG, "scene", SceneTest)
