"""The planning semantics agree with the robot model: SRDF names, named states, limits, solver settings."""
import math
import os
import sys
import unittest
import xml.etree.ElementTree as ET

import numpy as np
import yaml

try:  # the support package's helpers: from the devel space, else from the source tree
    from panasonic_vr006l_support import joint_limits as model_limits
    from panasonic_vr006l_support.description import render_urdf
    from panasonic_vr006l_support.model import RobotModel, rpy_matrix
except ImportError:  # plain pytest from the source tree
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..",
                                    "panasonic_vr006l_support", "src"))
    from panasonic_vr006l_support import joint_limits as model_limits
    from panasonic_vr006l_support.description import render_urdf
    from panasonic_vr006l_support.model import RobotModel, rpy_matrix

PKG_DIR = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SUPPORT_DIR = os.path.join(os.path.dirname(PKG_DIR), "panasonic_vr006l_support")
JOINTS = ["joint_%d" % i for i in range(1, 7)]


def config(name):
    return os.path.join(PKG_DIR, "config", name)


class SrdfTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.model = RobotModel.from_urdf_string(render_urdf())
        cls.srdf = ET.parse(config("panasonic_vr006l.srdf")).getroot()

    def test_robot_name_matches_urdf(self):
        self.assertEqual(self.srdf.get("name"), self.model.name)

    def test_manipulator_is_the_chain_base_link_to_tool0(self):
        groups = {g.get("name"): g for g in self.srdf.findall("group")}
        chains = groups["manipulator"].findall("chain")
        self.assertEqual(len(chains), 1)
        self.assertEqual((chains[0].get("base_link"), chains[0].get("tip_link")), ("base_link", "tool0"))
        self.assertEqual([j.name for j in self.model.movable_joints("base_link", "tool0")], JOINTS)

    def test_every_name_in_the_srdf_exists_in_the_urdf(self):
        links = set(self.model.links)
        joints = set(self.model.joints)
        groups = {g.get("name") for g in self.srdf.findall("group")}
        for elem in self.srdf.iter():
            for attr in ("base_link", "tip_link", "parent_link", "link1", "link2"):
                if elem.get(attr) is not None:
                    self.assertIn(elem.get(attr), links, "%s %s=%s" % (elem.tag, attr, elem.get(attr)))
            if elem.tag == "link":
                self.assertIn(elem.get("name"), links)
            if elem.tag == "joint":
                self.assertIn(elem.get("name"), joints)
            for attr in ("group", "parent_group"):
                if elem.get(attr) is not None:
                    self.assertIn(elem.get(attr), groups, "%s %s=%s" % (elem.tag, attr, elem.get(attr)))

    def test_named_states_home_and_zero_are_complete_and_within_limits(self):
        states = {s.get("name"): {j.get("name"): float(j.get("value")) for j in s.findall("joint")}
                  for s in self.srdf.findall("group_state")}
        self.assertEqual(sorted(states), ["home", "zero"])
        for name, values in states.items():
            self.assertEqual(sorted(values), JOINTS, name)
            for joint, value in values.items():
                j = self.model.joints[joint]
                self.assertTrue(j.lower <= value <= j.upper, "%s %s=%f" % (name, joint, value))
        self.assertTrue(all(v == 0.0 for v in states["zero"].values()))

    def test_home_state_is_the_controller_home_pose(self):
        """home = X 1120, Y 0, Z 725 mm, Rx 0, Ry 45, Rz 0 deg (R = Rz Ry Rx) of the flange in `base`."""
        home = {j.get("name"): float(j.get("value"))
                for s in self.srdf.findall("group_state") if s.get("name") == "home" for j in s.findall("joint")}
        poses = self.model.link_transforms(home)
        flange_in_base = np.linalg.inv(poses["base"]) @ poses["flange"]
        np.testing.assert_allclose(flange_in_base[:3, 3] * 1000.0, [1120.0, 0.0, 725.0], atol=0.5)
        np.testing.assert_allclose(flange_in_base[:3, :3], rpy_matrix((0.0, math.radians(45.0), 0.0)), atol=1e-5)

    def test_adjacent_links_are_disabled(self):
        disabled = {frozenset((d.get("link1"), d.get("link2"))): d.get("reason")
                    for d in self.srdf.findall("disable_collisions")}
        for joint in self.model.joints.values():
            if self.model.collisions.get(joint.parent) and self.model.collisions.get(joint.child):
                self.assertEqual(disabled.get(frozenset((joint.parent, joint.child))), "Adjacent", joint.name)

    def test_never_pairs_cannot_touch_over_the_joint_range(self):
        """Each 'Never' pair is checked by sampling: the upper arm's collision box never enters the
        base cylinder (plus 1 cm) anywhere in joint_2's range (joint_1 cannot matter: the base is
        radially symmetric about its axis)."""
        never = [(d.get("link1"), d.get("link2")) for d in self.srdf.findall("disable_collisions")
                 if d.get("reason") == "Never"]
        self.assertEqual(never, [("base_link", "link_2")])
        (cyl,) = self.model.collisions["base_link"]
        (box,) = self.model.collisions["link_2"]
        self.assertEqual((cyl.kind, box.kind), ("cylinder", "box"))
        radius, length = cyl.size
        top = cyl.origin[2, 3] + length / 2.0
        grid = np.stack(np.meshgrid(*[np.linspace(-s / 2.0, s / 2.0, n) for s, n in zip(box.size, (7, 9, 60))],
                                    indexing="ij"), -1).reshape(-1, 3)
        j2 = self.model.joints["joint_2"]
        closest = np.inf
        for q in np.linspace(j2.lower, j2.upper, 200):
            t = self.model.link_transforms({"joint_2": q})["link_2"] @ box.origin
            pts = grid @ t[:3, :3].T + t[:3, 3]
            inside_height = pts[:, 2] <= top + 0.01
            if inside_height.any():
                closest = min(closest, float(np.hypot(pts[inside_height, 0], pts[inside_height, 1]).min()))
        self.assertGreater(closest, radius + 0.01)


class LimitsAndKinematicsTest(unittest.TestCase):
    def test_joint_limits_yaml_matches_the_urdf_velocities(self):
        model = RobotModel.from_urdf_string(render_urdf())
        with open(config("joint_limits.yaml")) as f:
            limits = yaml.safe_load(f)["joint_limits"]
        self.assertEqual(sorted(limits), JOINTS)
        for name, lim in limits.items():
            self.assertTrue(lim["has_velocity_limits"], name)
            self.assertAlmostEqual(lim["max_velocity"], model.joints[name].velocity, places=9, msg=name)
            if lim["has_acceleration_limits"]:
                self.assertGreater(lim["max_acceleration"], 0.0, name)

    def test_joint_limits_yaml_has_the_models_accelerations(self):
        # the one set: panasonic_vr006l_support/config/kinematics_vr006l.yaml, joints.<name>.acceleration
        path = config("joint_limits.yaml")
        with open(path) as f:
            limits = yaml.safe_load(f)["joint_limits"]
        model = model_limits.accelerations()
        self.assertEqual(sorted(model), JOINTS)
        for name in JOINTS:
            lim = limits[name]
            self.assertIs(lim.get("has_acceleration_limits"), True,
                          "%s: %s has no acceleration limit (has_acceleration_limits: true)" % (path, name))
            self.assertAlmostEqual(lim.get("max_acceleration"), model[name], places=9,
                                   msg="%s: %s max_acceleration %r differs from the model's %r (%s)"
                                   % (path, name, lim.get("max_acceleration"), model[name],
                                      model_limits.YAML_PATH))

    def test_kinematics_yaml_has_only_the_keys_moveit_1_reads(self):
        """MoveIt 1.1's kinematics plugin loader looks up kinematics_solver, _search_resolution and
        _timeout under each group; _attempts (deprecated since Melodic) only makes it warn at every
        start, so it must not be there (our IK reads the same file and defaults it)."""
        with open(config("kinematics.yaml")) as f:
            kin = yaml.safe_load(f)
        group = kin["manipulator"]
        self.assertEqual(set(group), {"kinematics_solver", "kinematics_solver_search_resolution",
                                      "kinematics_solver_timeout"})
        self.assertEqual(group["kinematics_solver"], "kdl_kinematics_plugin/KDLKinematicsPlugin")
        self.assertGreater(group["kinematics_solver_timeout"], 0.0)
        self.assertGreater(group["kinematics_solver_search_resolution"], 0.0)


if __name__ == "__main__":
    unittest.main()
