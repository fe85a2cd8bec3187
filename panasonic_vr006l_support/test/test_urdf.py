"""The VR-006L model: the xacro renders, check_urdf accepts it, and it matches its YAML source."""
import math
import os
import shutil
import subprocess
import sys
import tempfile
import unittest

import numpy as np
import yaml

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "src"))

from panasonic_vr006l_support.description import (  # noqa: E402
    DescriptionError, default_kinematics_yaml, main as xacro_compat_main, render_urdf)
from panasonic_vr006l_support import calibration  # noqa: E402
from panasonic_vr006l_support.model import ModelError, RobotModel, rpy_matrix  # noqa: E402

PKG_DIR = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
JOINTS = ["joint_%d" % i for i in range(1, 7)]
LINKS = ["base_link"] + ["link_%d" % i for i in range(1, 7)] + ["flange", "tool0", "base"]


def load_yaml(name):
    with open(os.path.join(PKG_DIR, "config", name)) as f:
        return yaml.safe_load(f)


class ModelTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.urdf = render_urdf()
        cls.model = RobotModel.from_urdf_string(cls.urdf)
        cls.cfg = load_yaml("kinematics_vr006l.yaml")
        cls.geo = {k: v["value"] for k, v in cls.cfg["geometry"].items()}

    def test_check_urdf_accepts_the_rendered_model(self):
        with tempfile.NamedTemporaryFile("w", suffix=".urdf", delete=False) as f:
            f.write(self.urdf)
        try:
            out = subprocess.run(["check_urdf", f.name], capture_output=True, text=True, timeout=30)
        finally:
            os.unlink(f.name)
        self.assertEqual(out.returncode, 0, out.stderr + out.stdout)
        self.assertIn("Successfully Parsed XML", out.stdout)
        self.assertIn("root Link: base_link", out.stdout)

    def test_links_and_joints_are_the_ros_industrial_set(self):
        self.assertEqual(sorted(self.model.links), sorted(LINKS))
        self.assertEqual(self.model.root, "base_link")
        movable = [j.name for j in self.model.joints.values() if j.movable]
        self.assertEqual(sorted(movable), JOINTS)
        for name in JOINTS:
            self.assertEqual(self.model.joints[name].type, "revolute")

    def test_chain_base_link_to_tool0_has_six_revolute_joints_in_order(self):
        movable = self.model.movable_joints("base_link", "tool0")
        self.assertEqual([j.name for j in movable], JOINTS)
        self.assertTrue(all(j.type == "revolute" for j in movable))
        self.assertEqual(self.model.joints["flange-tool0"].type, "fixed")
        self.assertEqual(self.model.joints["base_link-base"].type, "fixed")

    def test_limits_and_velocities_match_the_yaml(self):
        for name, lim in self.cfg["joints"].items():
            j = self.model.joints[name]
            self.assertAlmostEqual(j.lower, lim["lower"], places=9, msg=name)
            self.assertAlmostEqual(j.upper, lim["upper"], places=9, msg=name)
            self.assertAlmostEqual(j.velocity, lim["velocity"], places=9, msg=name)
            self.assertAlmostEqual(j.effort, lim["effort"], places=9, msg=name)
            self.assertLess(j.lower, j.upper, name)

    def test_limits_are_the_thesis_values(self):
        thesis = {"joint_1": (-2.705, 2.705, 2.09), "joint_2": (-1.745, 2.618, 2.09),
                  "joint_3": (-3.0, 1.3, 2.09), "joint_4": (-3.316, 4.712, 2.09),
                  "joint_5": (-4.712, 4.712, 5.23), "joint_6": (-6.28, 6.28, 5.23)}
        for name, (lo, hi, vel) in thesis.items():
            j = self.model.joints[name]
            self.assertEqual((j.lower, j.upper, j.velocity), (lo, hi, vel), name)

    def test_joint_names_yaml_lists_the_movable_joints_in_order(self):
        names = load_yaml("joint_names_vr006l.yaml")["controller_joint_names"]
        self.assertEqual(names, [j.name for j in self.model.movable_joints("base_link", "tool0")])

    def test_every_yaml_dimension_is_labelled_with_a_source(self):
        for key, entry in self.cfg["geometry"].items():
            self.assertIn("source", entry, key)
            self.assertIn("calibrate", entry, key)
        for key, entry in self.cfg["joints"].items():
            self.assertIn("source", entry, key)
            self.assertIn("acceleration_source", entry, key)
            self.assertIn("assumption", entry["acceleration_source"], key)

    def test_zero_pose_fk_matches_hand_computed_dimensions(self):
        g = self.geo
        flange = self.model.chain_fk("base_link", "flange", np.zeros((1, 6)))[0]
        expected = [g["shoulder_offset"] + g["forearm"] + g["j5_to_flange"], 0.0,
                    g["j2_height"] + g["upper_arm"] + g["elbow_offset"]]
        np.testing.assert_allclose(flange[:3, 3], expected, atol=1e-9)
        np.testing.assert_allclose(flange[:3, :3], np.eye(3), atol=1e-9)

    def test_tool0_points_out_of_the_flange_with_x_up_at_zero(self):
        tool0 = self.model.chain_fk("base_link", "tool0", np.zeros((1, 6)))[0]
        np.testing.assert_allclose(tool0[:3, 2], [1, 0, 0], atol=1e-9)  # z forward
        np.testing.assert_allclose(tool0[:3, 0], [0, 0, 1], atol=1e-9)  # x up

    def test_joint_axes_and_positive_directions(self):
        g = self.geo
        wrist = lambda q: self.model.chain_fk("base_link", "link_5", np.array([q]))[0][:3, 3]  # noqa: E731
        # joint_1 positive turns the arm towards +y
        self.assertGreater(wrist([0.3, 0, 0, 0, 0])[1], 0.1)
        # joint_2 positive leans the upper arm forward: the elbow moves to +x
        elbow = self.model.chain_fk("base_link", "link_3", np.array([[0, 0.3, 0]]))[0][:3, 3]
        self.assertAlmostEqual(elbow[0], g["shoulder_offset"] + g["upper_arm"] * math.sin(0.3), places=9)
        # joint_3 positive turns the forearm down
        self.assertLess(wrist([0, 0, 0.3, 0, 0])[2], wrist([0, 0, 0, 0, 0])[2] - 0.1)

    def test_reach_within_one_percent_of_nominal(self):
        reach = self.model.horizontal_reach("base_link", "flange")
        nominal = self.cfg["nominal_reach"]["value"]
        self.assertLess(abs(reach - nominal) / nominal, 0.01, "reach %.4f m vs nominal %.4f m" % (reach, nominal))

    def test_every_moving_link_has_visual_collision_and_plausible_inertia(self):
        from urdf_parser_py.urdf import URDF

        robot = URDF.from_xml_string(self.urdf)
        total = 0.0
        for link in robot.links:
            if link.name in ("flange", "tool0", "base", "base_link"):
                # frames, and the fixed root (KDL warns about a root link with inertia)
                self.assertIsNone(link.inertial, link.name)
                if link.name == "base_link":
                    self.assertTrue(link.visuals and link.collisions)
                continue
            self.assertTrue(link.visuals, link.name)
            self.assertTrue(link.collisions, link.name)
            self.assertIsNotNone(link.inertial, link.name)
            m = link.inertial.mass
            i = link.inertial.inertia
            self.assertGreater(m, 0.0, link.name)
            moments = sorted([i.ixx, i.iyy, i.izz])
            self.assertGreater(moments[0], 0.0, link.name)
            self.assertGreaterEqual(moments[0] + moments[1], moments[2] - 1e-12, link.name)  # triangle rule
            total += m
        self.assertTrue(60.0 < total < 200.0, "moving mass %.1f kg" % total)

    def test_dimensions_really_come_from_the_yaml(self):
        cfg = load_yaml("kinematics_vr006l.yaml")
        cfg["geometry"]["upper_arm"]["value"] = 0.700
        cfg["joints"]["joint_3"]["upper"] = 1.0
        with tempfile.NamedTemporaryFile("w", suffix=".yaml", delete=False) as f:
            yaml.safe_dump(cfg, f)
        try:
            model = RobotModel.from_urdf_string(render_urdf(mappings={"kinematics_config": f.name}))
        finally:
            os.unlink(f.name)
        flange = model.chain_fk("base_link", "flange", np.zeros((1, 6)))[0]
        self.assertAlmostEqual(flange[2, 3], self.geo["j2_height"] + 0.700 + self.geo["elbow_offset"], places=9)
        self.assertEqual(model.joints["joint_3"].upper, 1.0)

    def test_prefix_renames_every_link_and_joint(self):
        model = RobotModel.from_urdf_string(render_urdf(mappings={"prefix": "r1_"}))
        self.assertEqual(sorted(model.links), sorted("r1_" + n for n in LINKS))
        self.assertEqual(sorted(j.name for j in model.joints.values() if j.movable), ["r1_" + j for j in JOINTS])

    def test_default_yaml_path_is_the_package_file(self):
        self.assertEqual(os.path.realpath(default_kinematics_yaml()),
                         os.path.realpath(os.path.join(PKG_DIR, "config", "kinematics_vr006l.yaml")))


def canonical(urdf_text):
    """The URDF without comments and layout whitespace, for comparing two renderings."""
    from lxml import etree

    root = etree.fromstring(urdf_text.encode(), etree.XMLParser(remove_comments=True, remove_blank_text=True))
    return etree.tostring(root, method="c14n")


class StockXacroTest(unittest.TestCase):
    """Plain ``xacro`` (PyPI's 1.13.3 on Debian 12, whose load_yaml fails under PyYAML 6) renders the
    model, identical to the model rendered from the YAML itself."""

    def test_the_xacro_command_renders_the_model(self):
        xacro = shutil.which("xacro")
        self.assertIsNotNone(xacro, "xacro is not on PATH: run scripts/setup")
        res = subprocess.run([xacro, os.path.join(PKG_DIR, "urdf", "vr006l.xacro")],
                             capture_output=True, text=True, timeout=60)
        self.assertEqual(res.returncode, 0, res.stderr)
        self.assertNotIn("Loader", res.stderr)
        from_yaml = render_urdf(mappings={"kinematics_config": default_kinematics_yaml()})
        self.assertEqual(canonical(res.stdout), canonical(from_yaml))
        model = RobotModel.from_urdf_string(res.stdout)
        self.assertEqual(sorted(model.links), sorted(LINKS))

    def test_the_generated_calibration_matches_the_yaml(self):
        with open(calibration.XACRO_PATH) as f:
            self.assertEqual(f.read(), calibration.xacro_text(load_yaml("kinematics_vr006l.yaml")),
                             "urdf/vr006l_calibration.xacro is out of date: "
                             "run scripts/env python3 -m panasonic_vr006l_support.calibration")
        self.assertEqual(calibration.main(["--check"]), 0)

    def test_a_changed_yaml_makes_the_check_fail_and_the_writer_follow(self):
        cfg = load_yaml("kinematics_vr006l.yaml")
        cfg["geometry"]["upper_arm"]["value"] = 0.7
        with tempfile.TemporaryDirectory() as d:
            src, out = os.path.join(d, "k.yaml"), os.path.join(d, "c.xacro")
            with open(src, "w") as f:
                yaml.safe_dump(cfg, f)
            with open(out, "w") as f:
                f.write(calibration.xacro_text(load_yaml("kinematics_vr006l.yaml")))
            self.assertEqual(calibration.main(["--check", "--yaml", src, "-o", out]), 1)
            self.assertEqual(calibration.main(["--yaml", src, "-o", out]), 0)
            self.assertEqual(calibration.main(["--check", "--yaml", src, "-o", out]), 0)
            with open(out) as f:
                self.assertRegex(f.read(), r"upper_arm=dict\([^)]*value=0\.7\b")

    def test_text_notes_are_left_out_and_odd_values_refused(self):
        self.assertEqual(calibration.numbers_only({"a": {"value": 1.5, "source": "x", "calibrate": False}}),
                         {"a": {"value": 1.5, "calibrate": False}})
        for bad in ({"a": [1, 2]}, {"a": float("nan")}, {"a b": 1}, {"a": None}):
            with self.assertRaises(calibration.CalibrationError):
                calibration.numbers_only(bad)


class DescriptionErrorsTest(unittest.TestCase):
    def test_missing_xacro_file_is_a_clear_error(self):
        with self.assertRaises(DescriptionError) as ctx:
            render_urdf("/nonexistent/robot.xacro")
        self.assertIn("not found", str(ctx.exception))

    def test_missing_yaml_is_a_clear_error(self):
        with self.assertRaises(DescriptionError) as ctx:
            render_urdf(mappings={"kinematics_config": "/nonexistent/kin.yaml"})
        self.assertIn("/nonexistent/kin.yaml", str(ctx.exception))

    def test_yaml_missing_a_dimension_is_an_error(self):
        cfg = load_yaml("kinematics_vr006l.yaml")
        del cfg["geometry"]["forearm"]
        with tempfile.NamedTemporaryFile("w", suffix=".yaml", delete=False) as f:
            yaml.safe_dump(cfg, f)
        try:
            with self.assertRaises(DescriptionError) as ctx:
                render_urdf(mappings={"kinematics_config": f.name})
        finally:
            os.unlink(f.name)
        self.assertIn("forearm", str(ctx.exception))

    def test_cli_writes_urdf_and_reports_errors_with_exit_codes(self):
        with tempfile.TemporaryDirectory() as d:
            out = os.path.join(d, "vr.urdf")
            self.assertEqual(xacro_compat_main(["-o", out]), 0)
            with open(out) as f:
                self.assertIn('<joint name="joint_6" type="revolute">', f.read())
        self.assertEqual(xacro_compat_main(["/nonexistent.xacro"]), 1)

    def test_model_rejects_unknown_links_and_bad_dof(self):
        model = RobotModel.from_urdf_string(render_urdf())
        with self.assertRaises(ModelError):
            model.chain("base_link", "no_such_link")
        with self.assertRaises(ModelError):
            model.chain("tool0", "base_link")
        with self.assertRaises(ModelError):
            model.chain_fk("base_link", "tool0", np.zeros((1, 5)))
        with self.assertRaises(ModelError):
            RobotModel.from_urdf_string("<robot name='x'><link name='a'/>")


class LightSubstitutionsTest(unittest.TestCase):
    """``$(find)`` and ``$(arg)`` resolved without roslaunch give the very URDF roslaunch gives."""

    def _render_both(self, path, mappings):
        """The URDF through render_urdf, and through stock xacro with roslaunch's resolver."""
        import xacro
        from panasonic_vr006l_support import description

        ours = render_urdf(path, mappings)
        light = xacro.eval_extension
        xacro.eval_extension = xacro._vr006l_original_eval_extension
        try:
            theirs = xacro.process_file(path or description.default_xacro_path(),
                                        mappings=dict(mappings or {})).toprettyxml(indent="  ")
        finally:
            xacro.eval_extension = light
        return ours, theirs

    def test_same_urdf_as_roslaunch_substitutions(self):
        two_arms = os.path.join(PKG_DIR, "urdf", "vr006l_two_arms.xacro")
        for path, mappings in ((None, None), (None, {"prefix": "r1_"}),
                               (None, {"kinematics_config": default_kinematics_yaml()}), (two_arms, None)):
            with self.subTest(path=path, mappings=mappings):
                ours, theirs = self._render_both(path, mappings)
                self.assertEqual(ours, theirs)

    def test_model_renders_without_importing_roslaunch(self):
        code = ("import sys; from panasonic_vr006l_support.description import render_urdf; "
                "render_urdf(); render_urdf(None, {'prefix': 'r2_'}); print('roslaunch' in sys.modules)")
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(
            [os.path.join(PKG_DIR, "src")] + os.environ.get("PYTHONPATH", "").split(os.pathsep)))
        out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
        self.assertEqual(out.stdout.strip(), "False")

    def test_undefined_arg_and_unknown_package_are_clear_errors(self):
        with tempfile.TemporaryDirectory() as d:
            for body, words in (("$(arg no_such_arg)", "no_such_arg"),
                                ("$(find no_such_package_xyz)", "no_such_package_xyz")):
                path = os.path.join(d, "bad.xacro")
                with open(path, "w") as f:
                    f.write('<robot name="x" xmlns:xacro="http://www.ros.org/wiki/xacro">'
                            '<link name="%s"/></robot>' % body)
                with self.subTest(body=body):
                    with self.assertRaises(DescriptionError) as ctx:
                        render_urdf(path)
                    self.assertIn(words, str(ctx.exception))


class RpyTest(unittest.TestCase):
    def test_rpy_is_fixed_axes_x_then_y_then_z(self):
        r, p, y = 0.3, -0.7, 1.1
        rx = np.array([[1, 0, 0], [0, math.cos(r), -math.sin(r)], [0, math.sin(r), math.cos(r)]])
        ry = np.array([[math.cos(p), 0, math.sin(p)], [0, 1, 0], [-math.sin(p), 0, math.cos(p)]])
        rz = np.array([[math.cos(y), -math.sin(y), 0], [math.sin(y), math.cos(y), 0], [0, 0, 1]])
        np.testing.assert_allclose(rpy_matrix((r, p, y)), rz @ ry @ rx, atol=1e-12)


if __name__ == "__main__":
    unittest.main()
