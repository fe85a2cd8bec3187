"""The model's one set of joint limits: accelerations next to the velocities, the ramp time they give."""
import math
import os
import sys
import tempfile
import unittest

import yaml

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "src"))

from panasonic_vr006l_support import joint_limits  # noqa: E402

JOINTS = ["joint_%d" % i for i in range(1, 7)]


class JointLimitsTest(unittest.TestCase):
    def test_every_joint_has_an_acceleration_of_velocity_over_a_tenth_of_a_second(self):
        lims = joint_limits.load()
        self.assertEqual(list(lims), JOINTS)
        for name, lim in lims.items():
            # the assumption the YAML documents: full speed from rest in 0.1 s
            self.assertAlmostEqual(lim["acceleration"], lim["velocity"] / 0.1, places=9, msg=name)
        self.assertEqual(joint_limits.accelerations(),
                         {"joint_1": 20.9, "joint_2": 20.9, "joint_3": 20.9, "joint_4": 20.9,
                          "joint_5": 52.3, "joint_6": 52.3})
        self.assertEqual(joint_limits.velocities()["joint_5"], 5.23)

    def test_the_model_ramp_time_is_exactly_a_tenth_of_a_second(self):
        self.assertEqual(joint_limits.model_ramp_time(), 0.1)

    def test_ramp_time_is_the_slowest_joint_and_skips_unknown_ones(self):
        self.assertEqual(joint_limits.ramp_time([2.0, 1.0], [4.0, 1.0]), 1.0)
        self.assertEqual(joint_limits.ramp_time([2.0, 1.0], [4.0, math.inf]), 0.5)
        with self.assertRaises(joint_limits.LimitsError):
            joint_limits.ramp_time([1.0], [math.inf])
        with self.assertRaises(joint_limits.LimitsError):
            joint_limits.ramp_time([1.0, 2.0], [1.0])

    def test_a_missing_or_bad_acceleration_names_the_file_and_the_joint(self):
        with open(joint_limits.YAML_PATH) as f:
            cfg = yaml.safe_load(f)
        for bad, words in ((None, "missing"), (0.0, "> 0"), ("fast", "> 0"), (float("nan"), "finite")):
            data = yaml.safe_load(yaml.safe_dump(cfg))
            if bad is None:
                del data["joints"]["joint_4"]["acceleration"]
            else:
                data["joints"]["joint_4"]["acceleration"] = bad
            with tempfile.NamedTemporaryFile("w", suffix=".yaml", delete=False) as f:
                yaml.safe_dump(data, f)
            try:
                with self.assertRaises(joint_limits.LimitsError) as ctx:
                    joint_limits.load(f.name)
            finally:
                os.unlink(f.name)
            self.assertIn(f.name, str(ctx.exception))
            self.assertIn("joints.joint_4.acceleration", str(ctx.exception))
            self.assertIn(words, str(ctx.exception))
        with self.assertRaises(joint_limits.LimitsError) as ctx:
            joint_limits.load("/nonexistent/kin.yaml")
        self.assertIn("/nonexistent/kin.yaml", str(ctx.exception))


if __name__ == "__main__":
    unittest.main()
