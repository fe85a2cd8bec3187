"""The MoveIt configuration as MoveIt 1 (1.1.16, Noetic) reads it, through roslaunch's own loader
(nothing started; MoveIt is not in Debian): the parameters each of MoveIt's loaders looks up are
there under the names it looks them up by, nothing sits under a name it never reads, and the
launch follows the driver (vr_driver/doc/moveit.md).

Keys, from MoveIt 1.1.16's sources: RobotModelLoader ``robot_description``,
``robot_description_semantic``; KinematicsPluginLoader ``robot_description_kinematics/<group>/``
``kinematics_solver``, ``_search_resolution``, ``_timeout`` (``_attempts`` only warns);
``robot_description_planning/joint_limits/<joint>/`` ``has_velocity_limits``, ``max_velocity``,
``has_acceleration_limits``, ``max_acceleration``; move_group's ``default_planning_pipeline`` and
``planning_pipelines/<p>/planning_plugin``, ``request_adapters``; the TrajectoryExecutionManager's
``moveit_controller_manager`` and its dynamic_reconfigure server ``trajectory_execution/``
``execution_duration_monitoring``, ``allowed_execution_duration_scaling``,
``allowed_goal_duration_margin``, ``allowed_start_tolerance``; PlanWithSensing's
``sense_for_plan/max_safe_path_cost``; the simple controller manager's ``controller_list`` entries
with ``name``, ``action_ns``, ``type``, ``joints`` (its action: ``name`` when ``action_ns`` is empty,
else ``name/action_ns``, resolved in move_group's namespace)."""
import os
import sys
import tempfile
import unittest
import xml.etree.ElementTree as ET

import yaml

from test_moveit_launch import LAUNCH_DIR, PKG_DIR, REPO, package_dir, roslaunch_load

try:
    from panasonic_vr006l_support.model import RobotModel
except ImportError:  # plain pytest from the source tree
    sys.path.insert(0, os.path.join(REPO, "panasonic_vr006l_support", "src"))
    from panasonic_vr006l_support.model import RobotModel

JOINTS = ["joint_%d" % i for i in range(1, 7)]
OPW = "moveit_opw_kinematics_plugin/MoveItOPWKinematicsPlugin"
CELL = os.path.join(REPO, "panasonic_vr006l_support", "config", "cell_example.yaml")


def flat(config):
    """{absolute name: value} of a loaded launch, dict-valued params expanded as the server stores them."""
    out = {}

    def put(name, value):
        if isinstance(value, dict):
            for k, v in value.items():
                put(name.rstrip("/") + "/" + k, v)
        else:
            out[name] = value
    for name, param in config.params.items():
        put(name, param.value)
    return out


def resolve(ns, name):
    return name if name.startswith("/") else ns.rstrip("/") + "/" + name


class MoveItReadsTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        try:
            import roslaunch  # noqa: F401
        except ImportError:
            raise unittest.SkipTest("roslaunch not importable (run through scripts/test)")
        if package_dir("vr_driver") is None:
            raise unittest.SkipTest("packages not found")

    def load(self, *args, name="moveit_planning_execution.launch", path=None):
        config = roslaunch_load(path or os.path.join(LAUNCH_DIR, name), "rviz:=false", *args)
        return config, flat(config)

    def check_as_moveit_reads(self, config, p, ns="/", prefix=""):
        """Every key MoveIt's loaders read, for the robot in namespace ``ns`` with ``prefix``."""
        rd = resolve(ns, "robot_description")
        model = RobotModel.from_urdf_string(p[rd])
        srdf = ET.fromstring(p[rd + "_semantic"])
        for elem in srdf.iter():           # the SRDF names only the URDF's links and joints
            for attr in ("base_link", "tip_link", "parent_link", "link1", "link2", "child_link"):
                if elem.get(attr) is not None:
                    self.assertIn(elem.get(attr), model.links, (attr, elem.get(attr)))
            if elem.tag == "joint":
                self.assertIn(elem.get("name"), model.joints)
        (chain,) = [g for g in srdf.iter("group") if g.get("name") == "manipulator"][0].iter("chain")
        active = [j.name for j in model.movable_joints(chain.get("base_link"), chain.get("tip_link"))]
        self.assertEqual(active, [prefix + j for j in JOINTS])
        for group in ("manipulator",):
            base = rd + "_kinematics/" + group + "/"
            self.assertIn(base + "kinematics_solver", p)
            self.assertGreater(p[base + "kinematics_solver_timeout"], 0.0)
            self.assertGreater(p[base + "kinematics_solver_search_resolution"], 0.0)
            self.assertNotIn(base + "kinematics_solver_attempts", p)
        for joint in active:
            lim = rd + "_planning/joint_limits/" + joint + "/"
            self.assertIs(p[lim + "has_velocity_limits"], True, joint)
            self.assertIs(p[lim + "has_acceleration_limits"], True, joint)
            self.assertGreater(p[lim + "max_velocity"], 0.0)
            self.assertGreater(p[lim + "max_acceleration"], 0.0)
        mg = resolve(ns, "move_group") + "/"
        pipeline = p[mg + "default_planning_pipeline"]
        self.assertIn(mg + "planning_pipelines/%s/planning_plugin" % pipeline, p)
        self.assertIn(mg + "planning_pipelines/%s/request_adapters" % pipeline, p)
        self.assertEqual(p[mg + "moveit_controller_manager"],
                         "moveit_simple_controller_manager/MoveItSimpleControllerManager")
        for key in ("execution_duration_monitoring", "allowed_execution_duration_scaling",
                    "allowed_goal_duration_margin", "allowed_start_tolerance"):
            self.assertIn(mg + "trajectory_execution/" + key, p)
        self.assertIn(mg + "sense_for_plan/max_safe_path_cost", p)
        self.assertNotIn(mg + "max_safe_path_cost", p)        # a key nothing reads
        # the controller list against the driver's action and joints
        (ctrl,) = p[mg + "controller_list"]
        self.assertTrue({"name", "action_ns", "type", "joints"} <= set(ctrl))
        self.assertEqual(ctrl["joints"], active)
        action = ctrl["name"] if ctrl["action_ns"] == "" else ctrl["name"] + "/" + ctrl["action_ns"]
        nodes = {n.name: n for n in config.nodes}
        driver_action = resolve(nodes["interface"].namespace, "joint_trajectory_action")   # TrajectoryServer's name
        self.assertEqual(resolve(nodes["move_group"].namespace, action), driver_action)
        return p

    def test_plain_launch_as_moveit_reads_it(self):
        config, p = self.load("sim:=true")
        self.check_as_moveit_reads(config, p)
        self.assertEqual(p["/interface/protocol"], "v1")
        self.assertEqual(p["/move_group/trajectory_execution/allowed_execution_duration_scaling"], 2.5)
        with open(os.path.join(PKG_DIR, "config", "joint_limits.yaml")) as fh:
            self.assertEqual(p["/robot_description_planning/joint_limits/joint_2/max_velocity"],
                             yaml.safe_load(fh)["joint_limits"]["joint_2"]["max_velocity"])

    def test_prefixed_robot_in_its_namespace(self):
        with tempfile.TemporaryDirectory() as tmp:
            path = os.path.join(tmp, "left.launch")
            with open(path, "w") as fh:
                fh.write('<launch><group ns="left"><include file="%s/moveit_planning_execution.launch">'
                         '<arg name="prefix" value="left_"/><arg name="rviz" value="false"/>'
                         '<arg name="sim" value="false"/><arg name="port" value="/dev/ttyUSB3"/>'
                         '</include></group></launch>' % LAUNCH_DIR)
            config, p = self.load(path=path)
        self.check_as_moveit_reads(config, p, ns="/left", prefix="left_")
        self.assertEqual(p["/left/interface/prefix"], "left_")
        self.assertNotIn("/robot_description_planning/joint_limits/joint_1/max_velocity", p)

    def test_a_commissioning_file_gives_v3_and_its_joint_limits(self):
        with tempfile.TemporaryDirectory() as tmp:
            commissioning = os.path.join(tmp, "g2.yaml")
            with open(commissioning, "w") as fh:
                fh.write("controller: {interpreter_lookahead: 1, speed_scale: 1.0}\n")
            with open(os.path.join(tmp, "joint_limits.yaml"), "w") as fh:
                fh.write("joint_limits:\n" + "".join(
                    "  joint_%d: {has_velocity_limits: true, max_velocity: 1.5, has_acceleration_limits: true, "
                    "max_acceleration: 7.5}\n" % i for i in range(1, 7)))
            config, p = self.load("sim:=true", "commissioning:=" + commissioning)
        self.check_as_moveit_reads(config, p)
        self.assertEqual(p["/interface/protocol"], "v3")
        self.assertEqual(p["/virtual_controller/protocol"], "v3")
        self.assertEqual(p["/interface/planning_limits"], os.path.join(tmp, "joint_limits.yaml"))
        self.assertEqual(p["/robot_description_planning/joint_limits/joint_4/max_acceleration"], 7.5)
        self.assertEqual(p["/move_group/trajectory_execution/allowed_execution_duration_scaling"], 1.2)

    def test_model_scene_padding_and_opw_follow_the_driver(self):
        from vr_driver.moveit import opw
        model = os.path.join(REPO, "vr_driver", "test", "data", "true_model_example.yaml")
        config, p = self.load("sim:=true", "model:=" + model, "scene:=" + CELL, "collision_padding:=0.02",
                              "kinematics_solver:=opw", "protocol:=v2")
        self.check_as_moveit_reads(config, p)
        self.assertEqual((p["/interface/model"], p["/interface/scene"], p["/interface/collision_padding"]),
                         (model, CELL, 0.02))
        kin = "/robot_description_kinematics/manipulator/"
        self.assertEqual(p[kin + "kinematics_solver"], OPW)
        expected = opw.parameters(model)
        self.assertEqual(p[kin + "opw_kinematics_joint_offsets"], expected["opw_kinematics_joint_offsets"])
        self.assertEqual(p[kin + "opw_kinematics_geometric_parameters/c2"], 0.570)
        self.assertEqual(p["/move_group/trajectory_execution/allowed_execution_duration_scaling"], 1.4)
        (scene,) = [n for n in config.nodes if n.name == "moveit_scene"]
        self.assertEqual((scene.package, scene.type), ("vr_driver", "moveit_scene"))
        self.assertIn("--padding=0.02", scene.args)
        self.assertIn("--model=" + model, scene.args)
        self.assertIn("--workspace", scene.args.split())
        self.assertTrue(scene.args.endswith(CELL))
        # the URDF MoveIt plans with is the calibrated model's (upper arm 570 mm)
        model_urdf = RobotModel.from_urdf_string(p["/robot_description"])
        self.assertAlmostEqual(model_urdf.joints["joint_3"].origin[2, 3], 0.570)
        config, p = self.load("sim:=true", "workspace_walls:=false")
        (scene,) = [n for n in config.nodes if n.name == "moveit_scene"]
        self.assertNotIn("--workspace", scene.args.split())

    def test_demo_runs_the_virtual_g2_on_v3_with_the_example_cell(self):
        config, p = self.load(name="demo.launch")
        self.check_as_moveit_reads(config, p)
        self.assertEqual((p["/interface/protocol"], p["/interface/scene"]), ("v3", CELL))
        self.assertIn("virtual_controller", {n.name for n in config.nodes})



class PackageXmlTest(unittest.TestCase):
    def test_moveit_is_a_dependency_on_noetic_only(self):
        """`rosdep install` on Noetic brings move_group and what the launch files start; on Debian
        (no MoveIt) the conditions drop them, so the workspace still resolves and builds."""
        try:
            from catkin_pkg.package import parse_package
        except ImportError:
            raise unittest.SkipTest("catkin_pkg not importable")
        needed = {"moveit_ros_move_group", "moveit_ros_planning", "moveit_planners_ompl", "moveit_kinematics",
                  "moveit_simple_controller_manager", "moveit_ros_visualization", "rviz"}
        for distro, expected in (("noetic", needed), ("Debian", set())):
            pkg = parse_package(os.path.join(PKG_DIR, "package.xml"))
            pkg.evaluate_conditions({"ROS_DISTRO": distro, "ROS_VERSION": "1", "ROS_PYTHON_VERSION": "3"})
            names = {d.name for d in pkg.exec_depends if d.evaluated_condition}
            self.assertEqual(names & (needed | {"moveit_opw_kinematics_plugin"}), expected, distro)
            self.assertIn("vr_driver", names)


if __name__ == "__main__":
    unittest.main()
