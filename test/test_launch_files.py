"""Every launch file of every package parses and resolves (args, $(find), xacro commands, YAML loads).

roslaunch's own loader (what `roslaunch --dump-params` runs) loads the whole configuration the way a
launch would, including running the `command=` of robot_description, without starting a master or
any node -- here in this process (a `roslaunch` process per file cost about 0.9 s of CPU for its
imports, some 30 times: a quarter of this module's time), each file and set of args loaded once.
"""
import copy
import glob
import io
import os
import re
import unittest
from contextlib import redirect_stderr, redirect_stdout

import yaml

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# extra args for launch files whose defaults are not enough to load them
ARGS = {
    "planning_context.launch": [["load_robot_description:=true"], ["load_robot_description:=false"]],
    # MoveIt's launch files load here too: the loader never looks up node executables, so the
    # missing moveit_ros_move_group does not matter (its nodes are checked in the package's tests)
    "move_group.launch": [[], ["allow_trajectory_execution:=false", "load_robot_description:=true"]],
    "moveit_planning_execution.launch": [["sim:=true"], ["sim:=false", "port:=/dev/ttyUSB0", "baud:=187500"]],
}


def launch_files():
    return sorted(glob.glob(os.path.join(REPO, "*", "launch", "*.launch")))


class Loaded:
    """A launch file loaded as `roslaunch --dump-params` loads it: ``ok`` (it loaded and set
    parameters), ``params`` (name -> value, as the YAML that command prints reads back: a copy of
    its own for each caller) and ``stderr`` (why it did not load, and the loader's warnings)."""

    def __init__(self, ok: bool, params: dict, stderr: str, nodes: int = 0) -> None:
        self.params = copy.deepcopy(params)
        self.stderr = stderr
        self.ok = ok and (bool(params) or nodes > 0)      # a file may only start nodes (moveit_rviz.launch)


_LOADED = {}
_COMMANDS = {}
_LOADER_CLASS = []


def _loader():
    """roslaunch's XmlLoader with its ``command=`` parameters run once per command line in this
    process (robot_description's xacro: about 0.5 s of CPU each, the same command line for most of
    the launch files and arguments here); a command that fails raises, is not kept and runs again."""
    if not _LOADER_CLASS:
        import roslaunch.xmlloader

        class RememberingLoader(roslaunch.xmlloader.XmlLoader):
            def param_value(self, verbose, name, ptype, value, textfile, binfile, command):
                if command is None:
                    return super().param_value(verbose, name, ptype, value, textfile, binfile, command)
                key = (ptype, command)
                if key not in _COMMANDS:
                    _COMMANDS[key] = super().param_value(verbose, name, ptype, value, textfile, binfile, command)
                return _COMMANDS[key]
        _LOADER_CLASS.append(RememberingLoader)
    return _LOADER_CLASS[0]()


def dump_params(path, args=()):
    """``path`` loaded with the launch arguments ``args`` (name:=value) by roslaunch's XmlLoader, as
    `roslaunch --dump-params path args` does (roslaunch.param_dump), once per file content and args."""
    import roslaunch.config
    with open(path, "rb") as fh:
        # the environment a launch file reads ($(optenv ...)) is part of what it loads as
        key = (os.path.abspath(path), fh.read(), tuple(args), os.environ.get("VR006L_SIM_RT_PRIORITY"))
    if key not in _LOADED:
        config = roslaunch.config.ROSLaunchConfig()
        err, out = io.StringIO(), io.StringIO()
        ok = True
        with redirect_stderr(err), redirect_stdout(out):
            try:
                _loader().load(path, config, argv=["roslaunch"] + list(args), verbose=False)
            except Exception as exc:            # what --dump-params reports as "Unable to load file"
                ok = False
                err.write("Unable to load file %s: %s" % (path, exc))
        params = {str(k): v.value for k, v in config.params.items()} if ok else {}
        # through YAML, as the command's output: the values a reader of it gets
        _LOADED[key] = (ok, yaml.safe_load(yaml.safe_dump(params)) or {}, err.getvalue(), len(config.nodes))
    return Loaded(*_LOADED[key])


class LaunchFilesTest(unittest.TestCase):
    def test_there_are_launch_files(self):
        names = [os.path.basename(p) for p in launch_files()]
        for expected in ("load_vr006l.launch", "test_vr006l.launch", "planning_context.launch", "move_group.launch",
                         "moveit_planning_execution.launch"):
            self.assertIn(expected, names)

    def test_every_launch_file_loads(self):
        for path in launch_files():
            for args in ARGS.get(os.path.basename(path), [[]]):
                with self.subTest(launch=os.path.relpath(path, REPO), args=args):
                    res = dump_params(path, args)
                    self.assertTrue(res.ok, res.stderr[-2000:])
                    params = res.params
                    self.assertIsInstance(params, dict)

    def test_load_vr006l_puts_a_urdf_on_the_parameter_server(self):
        res = dump_params(os.path.join(REPO, "panasonic_vr006l_support", "launch", "load_vr006l.launch"),
                          ["prefix:=left_"])
        self.assertTrue(res.ok, res.stderr)
        urdf = res.params["/robot_description"]
        self.assertIn('<link name="left_tool0"/>', urdf)

    def test_planning_context_loads_srdf_limits_and_kinematics(self):
        res = dump_params(os.path.join(REPO, "panasonic_vr006l_moveit_config", "launch", "planning_context.launch"))
        self.assertTrue(res.ok, res.stderr)
        params = res.params
        self.assertIn('<group name="manipulator">', params["/robot_description_semantic"])
        self.assertEqual(params["/robot_description_planning/joint_limits/joint_5/max_velocity"], 5.23)
        self.assertIn("/robot_description_kinematics/manipulator/kinematics_solver_timeout", params)
        self.assertNotIn("/robot_description", params)

    def test_a_broken_launch_file_is_reported(self):
        """The check above can fail: a missing YAML, a missing include, a failing command, an unset arg."""
        import tempfile

        broken = [
            '<rosparam command="load" file="$(find panasonic_vr006l_support)/config/nope.yaml"/>',
            '<include file="$(find panasonic_vr006l_support)/launch/nope.launch"/>',
            '<param name="x" command="$(find panasonic_vr006l_support)/scripts/xacro_compat /nope.xacro"/>',
            '<arg name="a"/><param name="x" value="$(arg a)"/>',
        ]
        for body in broken:
            with self.subTest(body=body):
                with tempfile.NamedTemporaryFile("w", suffix=".launch", delete=False) as f:
                    f.write("<launch>%s<param name='y' value='1'/></launch>" % body)
                try:
                    self.assertFalse(dump_params(f.name).ok)
                finally:
                    os.unlink(f.name)



def sim_options(params):
    """The virtual controller's options among a launch's parameters, as the node takes them
    (vr_driver.ros.virtual_controller.split_params: its own parameters, e.g. rt_priority, are not
    options of the virtual G2); an unknown one fails the test."""
    from vr_driver.ros.virtual_controller import split_params
    own = {k[len("/virtual_controller/"):]: v for k, v in params.items() if k.startswith("/virtual_controller/")}
    options, unknown = split_params(own)
    assert not unknown, unknown
    return options


class DriverLaunchParamsTest(unittest.TestCase):
    """The parameters driver.launch gives the node `interface` pass the node's own validation
    (vr_driver.params), for the virtual controller and for a real port."""

    def check(self, *args):
        import sys
        sys.path.insert(0, os.path.join(REPO, "vr_driver", "src"))
        sys.path.insert(0, os.path.join(REPO, "pyprofibus_vendor", "src"))
        from vr_driver.params import DriverParams
        loaded = dump_params(os.path.join(REPO, "vr_driver", "launch", "driver.launch"), args)
        self.assertTrue(loaded.ok, loaded.stderr)
        params = loaded.params
        mine = {k[len("/interface/"):]: v for k, v in params.items() if k.startswith("/interface/")}
        nested = {}
        for key, value in mine.items():          # workspace/x -> {"workspace": {"x": ...}}
            head, _, rest = key.partition("/")
            if rest:
                nested.setdefault(head, {})[rest] = value
            else:
                nested[key] = value
        return DriverParams.from_dict(nested), params

    def test_sim_defaults(self):
        from vr_driver.controller.options import SimOptions
        p, params = self.check("io:=false")
        from vr_driver.controller.pty_link import auto_pty_link
        # one value for both nodes (sim_port, default auto), which both resolve to the same link
        self.assertEqual(params["/virtual_controller/pty_link"], "auto")
        self.assertEqual(params["/interface/port"], "auto")
        self.assertEqual(p.port, auto_pty_link())
        self.assertEqual(p.io_signals, "")
        self.assertFalse(any(k.startswith("/virtual_line/") or k.startswith("/virtual_io_island/") for k in params))
        # no baud argument: the virtual controller's default is the parameter file's baud
        self.assertNotIn("/virtual_controller/baud", params)
        self.assertEqual(p.bus().baud, SimOptions().baud)
        p, params = self.check("baud:=187500")
        self.assertEqual(p.bus().baud, params["/virtual_controller/baud"])

    def test_sim_with_the_io_island_by_default(self):
        """issue 18: sim:=true (io:=true by default) puts the virtual controller and the virtual I/O island
        on one virtual line; the driver opens the line's master end and cycles both stations."""
        from vr_driver.controller.pty_link import auto_pty_link
        island = ["gripper_close", "gripper_closed", "part_present"]
        own = ["g2_gripper_close", "g2_gripper_closed", "g2_part_present"]   # the controller's own I/O (v2)
        for protocol, length, names in (("v1", 14, island), ("v2", 72, island + own)):
            with self.subTest(protocol=protocol):
                p, params = self.check("protocol:=" + protocol)
                self.assertEqual(params["/virtual_line/stations"], ["auto", "auto:io_island"])
                self.assertEqual(params["/virtual_io_island/pty_link"], "auto:io_island")
                self.assertEqual(params["/interface/port"], params["/virtual_line/pty_link"])
                self.assertEqual(p.port, auto_pty_link(station="line"))
                bus = p.bus()
                self.assertEqual([(s.address, s.input_len) for s in bus.slaves], [(4, length), (8, 2)])
                self.assertEqual([s.name for s in p.signal_map(bus).signals], names)
        p, params = self.check("sim:=false", "port:=/dev/ttyUSB7")
        self.assertEqual(p.io_signals, "")
        self.assertFalse(any(k.startswith("/virtual_line/") for k in params))

    def test_ramp_time_reaches_the_virtual_controller_only(self):
        """The virtual arm's ramp: unset by default (the model's joint limits give 0.1 s), ramp_time:=0.5
        (an older controller) a valid option of the virtual controller and of no other node."""
        from vr_driver.controller.options import SimOptions
        _, params = self.check("protocol:=v3")
        self.assertFalse(any(k.endswith("/ramp_time") for k in params))
        _, params = self.check("protocol:=v3", "ramp_time:=0.5")
        self.assertEqual([k for k in params if k.endswith("/ramp_time")], ["/virtual_controller/ramp_time"])
        self.assertEqual(params["/virtual_controller/ramp_time"], 0.5)
        self.assertEqual(SimOptions.from_mapping(sim_options(params)).ramp_time, 0.5)

    def test_sim_rt_priority_reaches_the_virtual_hardware_only(self):
        """The virtual hardware's real-time priority: 0 (normal scheduling) by default on each of
        the virtual G2, the line and the island, or the environment's VR006L_SIM_RT_PRIORITY
        (scripts/test sets 10); sim_rt_priority:=30 (a benchmark run alone, where a real G2 is
        never late) on those three and on no other node, whatever the environment says."""
        from unittest import mock
        hardware = ["/virtual_controller/rt_priority", "/virtual_io_island/rt_priority", "/virtual_line/rt_priority"]
        for env, expected in ((None, 0), ("10", 10)):
            environ = {k: v for k, v in os.environ.items() if k != "VR006L_SIM_RT_PRIORITY"}
            if env is not None:
                environ["VR006L_SIM_RT_PRIORITY"] = env
            with mock.patch.dict(os.environ, environ, clear=True):
                _, params = self.check()
                self.assertEqual(sorted(k for k in params if k.endswith("/rt_priority")), hardware)
                self.assertEqual({params[k] for k in hardware}, {expected}, env)
                _, params = self.check("sim_rt_priority:=30")
                self.assertEqual(sorted(k for k in params if k.endswith("/rt_priority")), hardware)
                self.assertEqual({params[k] for k in hardware}, {30})

    def test_true_model_reaches_the_virtual_controller_only(self):
        """issue 25: true_model:=FILE gives the virtual G2 its own kinematics; the driver (and the
        robot description) keep the model's. Unset by default (the model's)."""
        from vr_driver.controller.options import SimOptions
        example = os.path.join(REPO, "vr_driver", "test", "data", "true_model_example.yaml")
        _, params = self.check("protocol:=v3")
        self.assertFalse(any(k.endswith("/true_model") for k in params))
        _, plain = self.check("protocol:=v3", "true_model:=" + example)
        self.assertEqual([k for k in plain if k.endswith("/true_model")], ["/virtual_controller/true_model"])
        self.assertEqual(SimOptions.from_mapping(sim_options(plain)).true_model, example)
        self.assertEqual(plain["/robot_description"], params["/robot_description"])

    def test_model_reaches_the_driver_and_the_robot_description(self):
        """model:=FILE (a calibrated kinematics YAML) is the driver's model and robot_description's
        (RViz, robot_state_publisher, MoveIt show the arm the driver computes with); the virtual
        controller keeps its own."""
        example = os.path.join(REPO, "vr_driver", "test", "data", "true_model_example.yaml")
        _, params = self.check()
        p, plain = self.check("model:=" + example, "prefix:=left_")
        self.assertEqual(p.model, example)
        self.assertFalse(any(k.endswith("/true_model") for k in plain))

        def joint_3_origin(urdf, prefix=""):
            i = urdf.index('name="%sjoint_3"' % prefix)
            return re.search(r'<origin[^>]*xyz="([^"]*)"', urdf[i:]).group(1).split()
        self.assertAlmostEqual(float(joint_3_origin(params["/robot_description"])[2]), 0.560)
        self.assertAlmostEqual(float(joint_3_origin(plain["/robot_description"], "left_")[2]), 0.570)   # upper arm +10 mm

    def test_real_port(self):
        p, params = self.check("sim:=false", "port:=/dev/ttyUSB7", "baud:=187500")
        self.assertEqual((p.port, p.baud), ("/dev/ttyUSB7", 187500))
        self.assertFalse(any(k.startswith("/virtual_controller/") for k in params))

    def test_driver_launch_keeps_the_parameter_file_unless_an_argument_is_given(self):
        """issue 14: the launch file overrode port, baud and cycle_rate of config:=... silently."""
        import tempfile
        launch = os.path.join(REPO, "vr_driver", "launch", "driver.launch")
        with tempfile.NamedTemporaryFile("w", suffix=".yaml", delete=False) as fh:
            fh.write("port: /dev/ttyS9\nbaud: 187500\ncycle_rate: 50.0\n")
        try:
            cases = [
                ([], {"baud": 187500, "cycle_rate": 50.0}),                      # the file holds
                (["sim:=false"], {"port": "/dev/ttyS9", "baud": 187500}),
                (["sim:=false", "port:=/dev/ttyUSB3", "baud:=500000", "cycle_rate:=25"],
                 {"port": "/dev/ttyUSB3", "baud": 500000, "cycle_rate": 25.0}),  # arguments win
            ]
            for args, expected in cases:
                with self.subTest(args=args):
                    res = dump_params(launch, ["config:=" + fh.name] + args)
                    self.assertTrue(res.ok, res.stderr[-2000:])
                    params = res.params
                    for name, value in expected.items():
                        self.assertEqual(params["/interface/" + name], value, name)
                    if "sim:=false" not in args:    # the virtual line's link, whatever the file says
                        self.assertEqual(params["/interface/port"], params["/virtual_line/pty_link"])
                        self.assertEqual(params["/virtual_line/stations"][0],
                                         params["/virtual_controller/pty_link"])
        finally:
            os.unlink(fh.name)


if __name__ == "__main__":
    unittest.main()
