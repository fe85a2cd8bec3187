"""The MoveIt configuration a ROS Noetic user launches (issue 16 item 5), checked without MoveIt.

MoveIt is not packaged by Debian, so move_group cannot run here. What can be checked is checked:
the controller list agrees with the SRDF, the URDF and the driver; every launch file (.launch and
.launch.xml) refers only to files that exist, uses only arguments it declares, and passes an include
only arguments the included file declares; roslaunch's own loader resolves the entry points with
their argument variants and yields the parameters move_group reads; and the only nodes whose packages
are missing here are MoveIt's and RViz's (listed below, with the reason).
"""
import copy
import os
import re
import subprocess
import sys
import unittest
import xml.etree.ElementTree as ET

import yaml

try:
    from panasonic_vr006l_support.description import render_urdf
    from panasonic_vr006l_support.model import RobotModel
except ImportError:  # plain pytest from the source tree
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..",
                                    "panasonic_vr006l_support", "src"))
    from panasonic_vr006l_support.description import render_urdf
    from panasonic_vr006l_support.model import RobotModel

PKG = "panasonic_vr006l_moveit_config"
PKG_DIR = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
REPO = os.path.dirname(PKG_DIR)
LAUNCH_DIR = os.path.join(PKG_DIR, "launch")
JOINTS = ["joint_%d" % i for i in range(1, 7)]
# Node packages these launch files start that a Debian machine does not have: MoveIt itself
# (moveit_ros_move_group: not in Debian) and RViz (optional here: scripts/setup --rviz installs it).
NEEDS_MOVEIT_OR_GUI = {"moveit_ros_move_group", "rviz"}
SUBST = re.compile(r"\$\((\w+)\s*([^)]*)\)")


def launch_files():
    return sorted(os.path.join(LAUNCH_DIR, f) for f in os.listdir(LAUNCH_DIR)
                  if f.endswith(".launch") or f.endswith(".launch.xml"))


def package_dir(name):
    """Our packages from the source tree; others through rospack (None when not installed)."""
    if os.path.isfile(os.path.join(REPO, name, "package.xml")):
        return os.path.join(REPO, name)
    res = subprocess.run(["rospack", "find", name], capture_output=True, text=True)
    return res.stdout.strip() if res.returncode == 0 else None


def load_yaml(path):
    with open(path) as f:
        return yaml.safe_load(f)


def declared_args(root):
    """name -> default or value ('' when neither) of every <arg> a launch file declares (at any
    depth, groups included; an <arg> inside <include> passes a value on and declares nothing)."""
    found = {}

    def walk(elem):
        for child in elem:
            if child.tag == "arg":
                found[child.get("name")] = child.get("default", child.get("value", ""))
            elif child.tag != "include":
                walk(child)
    walk(root)
    return found


def resolve(text, args):
    """$(find pkg) and $(arg name) (the declared default) substituted; None if something else remains."""
    def sub(m):
        kind, rest = m.group(1), m.group(2).strip()
        if kind == "find":
            return package_dir(rest) or "<missing package %s>" % rest
        if kind == "arg" and rest in args:
            return args[rest]
        raise KeyError(m.group(0))
    try:
        for _ in range(5):                       # an arg's default may itself hold $(find ...)
            new = SUBST.sub(sub, text)
            if new == text:
                break
            text = new
        return text
    except KeyError:
        return None


_COMMANDS = {}


def roslaunch_load(path, *args):
    """roslaunch's XML loader on one file, as `roslaunch --dump-params` does: includes, args,
    params, node declarations; nothing started, node executables not looked up. A ``command=``
    parameter runs once per command line in this process (xacro, vr_driver's moveit_config: the
    same lines for most loads); one that fails raises and is not kept."""
    import roslaunch.config
    import roslaunch.xmlloader

    class RememberingLoader(roslaunch.xmlloader.XmlLoader):
        def param_value(self, verbose, name, ptype, value, textfile, binfile, command):
            if command is None:
                return super().param_value(verbose, name, ptype, value, textfile, binfile, command)
            key = (ptype, command)
            if key not in _COMMANDS:
                _COMMANDS[key] = super().param_value(verbose, name, ptype, value, textfile, binfile, command)
            return copy.deepcopy(_COMMANDS[key])

    config = roslaunch.config.ROSLaunchConfig()
    RememberingLoader().load(path, config, argv=["roslaunch"] + list(args), verbose=False)
    return config


class ControllersTest(unittest.TestCase):
    def setUp(self):
        self.controllers = load_yaml(os.path.join(PKG_DIR, "config", "controllers.yaml"))["controller_list"]

    def test_one_follow_joint_trajectory_controller_at_joint_trajectory_action(self):
        self.assertEqual(len(self.controllers), 1)
        (c,) = self.controllers
        # MoveIt 1.1 names the action `name` when action_ns is empty: relative, so move_group reaches
        # the driver's joint_trajectory_action in its own namespace (ROS-Industrial's name "" would
        # make it /joint_trajectory_action, absolute)
        self.assertEqual((c["name"], c["action_ns"]), ("joint_trajectory_action", ""))
        self.assertEqual(c["type"], "FollowJointTrajectory")
        self.assertIs(c["default"], True)

    def test_joints_are_the_srdf_group_the_urdf_chain_and_the_drivers(self):
        joints = self.controllers[0]["joints"]
        srdf = ET.parse(os.path.join(PKG_DIR, "config", "panasonic_vr006l.srdf")).getroot()
        (group,) = [g for g in srdf.findall("group") if g.get("name") == "manipulator"]
        (chain,) = group.findall("chain")
        model = RobotModel.from_urdf_string(render_urdf())
        chain_joints = [j.name for j in model.movable_joints(chain.get("base_link"), chain.get("tip_link"))]
        driver = load_yaml(os.path.join(REPO, "vr_driver", "config", "vr_driver.yaml"))
        self.assertEqual(joints, JOINTS)
        self.assertEqual(chain_joints, joints)
        self.assertEqual(sorted(n for n, j in model.joints.items() if j.type != "fixed"), sorted(joints))
        self.assertEqual(driver["controller_joint_names"], joints)

    def test_ompl_config_names_the_srdf_group_and_defined_planners(self):
        ompl = load_yaml(os.path.join(PKG_DIR, "config", "ompl_planning.yaml"))
        groups = {g.get("name") for g in ET.parse(os.path.join(PKG_DIR, "config", "panasonic_vr006l.srdf"))
                  .getroot().findall("group")}
        self.assertIn("manipulator", ompl)
        for group in set(ompl) - {"planner_configs"}:
            self.assertIn(group, groups)
            self.assertIn(ompl[group]["default_planner_config"], ompl[group]["planner_configs"])
            for name in ompl[group]["planner_configs"]:
                self.assertTrue(ompl["planner_configs"][name]["type"].startswith("geometric::"), name)
        for name in re.findall(r"\w+", ompl["manipulator"]["projection_evaluator"].partition("(")[2]):
            self.assertIn(name, JOINTS)


class LaunchFilesStaticTest(unittest.TestCase):
    """Each file on its own, parsed as XML (the .launch.xml files included only through others too)."""

    def test_the_moveit_launch_files_are_there(self):
        names = {os.path.basename(p) for p in launch_files()}
        for name in ("move_group.launch", "moveit_planning_execution.launch", "moveit_rviz.launch", "demo.launch",
                     "planning_context.launch", "planning_pipeline.launch.xml", "ompl_planning_pipeline.launch.xml",
                     "trajectory_execution.launch.xml", "panasonic_vr006l_moveit_controller_manager.launch.xml"):
            self.assertIn(name, names)

    def test_every_referenced_file_exists_and_every_yaml_parses(self):
        checked = 0
        for path in launch_files():
            root = ET.parse(path).getroot()
            args = declared_args(root)
            for elem in root.iter():
                for attr in ("file", "textfile", "args"):
                    value = elem.get(attr)
                    if value is None or "$(find" not in value:
                        continue
                    with self.subTest(launch=os.path.basename(path), tag=elem.tag, value=value):
                        resolved = resolve(value, args)
                        self.assertIsNotNone(resolved, "cannot resolve %s" % value)
                        target = resolved.split()[-1] if attr == "args" else resolved
                        self.assertTrue(os.path.isfile(target), "%s -> %s does not exist" % (value, target))
                        if elem.tag == "rosparam" or target.endswith(".yaml"):
                            self.assertIsInstance(load_yaml(target), dict)
                        checked += 1
        self.assertGreaterEqual(checked, 10)

    def test_every_arg_used_is_declared(self):
        for path in launch_files():
            root = ET.parse(path).getroot()
            args = declared_args(root)
            used = set()
            for elem in root.iter():
                for value in elem.attrib.values():
                    used |= set(re.findall(r"\$\(arg\s+(\w+)\)", value))
                    if value.startswith("$(eval"):
                        used |= set(re.findall(r"arg\('(\w+)'\)", value))
            with self.subTest(launch=os.path.basename(path)):
                self.assertEqual(sorted(used - set(args)), [])

    def test_includes_pass_only_args_the_included_file_declares(self):
        for path in launch_files():
            root = ET.parse(path).getroot()
            args = declared_args(root)
            for inc in root.iter("include"):
                target = resolve(inc.get("file"), args)
                passed = {a.get("name") for a in inc.findall("arg")}
                with self.subTest(launch=os.path.basename(path), include=inc.get("file")):
                    self.assertIsNotNone(target)
                    self.assertTrue(os.path.isfile(target), target)
                    self.assertEqual(sorted(passed - set(declared_args(ET.parse(target).getroot()))), [])

    def test_planning_execution_includes_move_group_and_the_driver_passing_sim_and_port(self):
        root = ET.parse(os.path.join(LAUNCH_DIR, "moveit_planning_execution.launch")).getroot()
        includes = {inc.get("file"): {a.get("name"): a.get("value") for a in inc.findall("arg")}
                    for inc in root.iter("include")}
        driver = includes["$(find vr_driver)/launch/driver.launch"]
        for name in ("sim", "port", "sim_port", "baud", "cycle_rate", "config", "commissioning", "protocol",
                     "prefix", "model", "scene", "collision_padding"):
            self.assertEqual(driver[name], "$(arg %s)" % name)
        self.assertEqual(driver["rviz"], "false")
        self.assertIn("$(find panasonic_vr006l_moveit_config)/launch/move_group.launch", includes)
        # the same defaults as driver.launch, so a bare launch behaves as the driver alone does
        mine = declared_args(root)
        theirs = declared_args(ET.parse(os.path.join(REPO, "vr_driver", "launch", "driver.launch")).getroot())
        for name in ("sim", "port", "sim_port", "baud", "cycle_rate", "config", "commissioning", "protocol",
                     "prefix", "model", "scene", "collision_padding"):
            self.assertEqual(mine[name], theirs[name], name)

    def test_a_broken_reference_is_caught(self):
        """The static checks can fail: a missing file and an undeclared arg."""
        args = {"x": "ompl"}
        self.assertFalse(os.path.isfile(resolve("$(find %s)/launch/$(arg x)_nope.launch.xml" % PKG, args)))
        self.assertIsNone(resolve("$(arg y)", args))


class LaunchFilesLoadTest(unittest.TestCase):
    """The entry points through roslaunch's loader, with their argument variants."""

    @classmethod
    def setUpClass(cls):
        try:
            import roslaunch  # noqa: F401
        except ImportError:
            raise unittest.SkipTest("roslaunch not importable (run through scripts/test)")
        if package_dir("vr_driver") is None:
            raise unittest.SkipTest("packages not found")

    def load(self, name, *args):
        return roslaunch_load(os.path.join(LAUNCH_DIR, name), *args)

    def test_move_group_gets_pipeline_controllers_and_semantics(self):
        c = self.load("move_group.launch")
        p = {k: v.value for k, v in c.params.items()}
        self.assertEqual(p["/move_group/default_planning_pipeline"], "ompl")
        self.assertEqual(p["/move_group/planning_pipelines/ompl/planning_plugin"], "ompl_interface/OMPLPlanner")
        adapters = p["/move_group/planning_pipelines/ompl/request_adapters"].split()
        self.assertEqual(len(adapters), 6)
        self.assertIn("default_planner_request_adapters/AddTimeParameterization", adapters)
        self.assertEqual(p["/move_group/planning_pipelines/ompl/manipulator/default_planner_config"], "RRTConnect")
        self.assertEqual(p["/move_group/moveit_controller_manager"],
                         "moveit_simple_controller_manager/MoveItSimpleControllerManager")
        self.assertEqual(p["/move_group/controller_list"][0]["name"], "joint_trajectory_action")
        self.assertIn('<group name="manipulator">', p["/robot_description_semantic"])
        self.assertIn("/robot_description_kinematics/manipulator/kinematics_solver", p)
        self.assertNotIn("/robot_description", p)
        self.assertEqual([(n.package, n.type) for n in c.nodes], [("moveit_ros_move_group", "move_group")])

    def test_move_group_plan_only_has_no_controllers(self):
        p = self.load("move_group.launch", "allow_trajectory_execution:=false").params
        self.assertFalse(p["/move_group/allow_trajectory_execution"].value)
        self.assertNotIn("/move_group/controller_list", p)

    def test_planning_execution_sim_runs_the_virtual_controller(self):
        c = self.load("moveit_planning_execution.launch", "sim:=true")
        nodes = {n.name: n for n in c.nodes}
        # the virtual controller and the virtual I/O island on the virtual line (driver.launch io:=true)
        self.assertEqual(set(nodes), {"robot_state_publisher", "virtual_controller", "virtual_io_island",
                                      "virtual_line", "interface", "move_group", "moveit_scene"}
                         | {n for n in nodes if n.startswith("rviz")})
        self.assertEqual(c.params["/interface/port"].value, c.params["/virtual_line/pty_link"].value)
        self.assertIn(c.params["/virtual_controller/pty_link"].value, c.params["/virtual_line/stations"].value)
        self.assertIn("/robot_description", c.params)            # from driver.launch, once

    def test_planning_execution_real_port_passes_through(self):
        c = self.load("moveit_planning_execution.launch", "sim:=false", "port:=/dev/ttyUSB7", "baud:=187500",
                      "rviz:=false")
        nodes = {n.name for n in c.nodes}
        self.assertEqual(nodes, {"robot_state_publisher", "interface", "move_group", "moveit_scene"})
        self.assertEqual(c.params["/interface/port"].value, "/dev/ttyUSB7")
        self.assertEqual(c.params["/interface/baud"].value, 187500)

    def test_only_moveit_and_rviz_nodes_are_missing_here(self):
        c = self.load("moveit_planning_execution.launch", "sim:=true", "rviz:=true")
        packages = {n.package for n in c.nodes}
        self.assertTrue({"moveit_ros_move_group", "rviz", "vr_driver"} <= packages)
        missing = {p for p in packages if package_dir(p) is None}
        self.assertEqual(missing - NEEDS_MOVEIT_OR_GUI, set())


if __name__ == "__main__":
    unittest.main()
