"""bench/planning.py's --ramp-time: the planner matched to a slower arm, as the commissioning sets it.

The joint_limits.yaml the bench writes is read back by the driver's own reader
(params.read_planning_limits, what the plan action's ``planning_limits`` goes through): each joint's
speed the model's, its acceleration the speed / the ramp; the planning model carries them and the
driver's model is left as it was. A ramp outside (0, 5] s is refused with the option's name before
anything is built.
"""
import importlib.util
import math
import os
import subprocess
import sys
import tempfile
import unittest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BENCH = os.path.join(REPO, "bench", "planning.py")


def load_bench():
    spec = importlib.util.spec_from_file_location("bench_planning", BENCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


class MatchedLimitsTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.bench = load_bench()
        from vr_driver.kinematics.solver import Kinematics
        cls.kin = Kinematics.default()

    def test_the_file_reads_back_as_speed_over_the_ramp(self):
        from vr_driver.params import read_planning_limits
        before = tuple(self.kin.limits.acceleration)
        with tempfile.TemporaryDirectory() as tmp:
            path, planning = self.bench.matched_limits(self.kin, 0.5, tmp)
            names = tuple(n.split("/")[-1] for n in self.kin.joint_names)
            velocity, acceleration = read_planning_limits(path, names)
        for v_model, v, a in zip(self.kin.limits.velocity, velocity, acceleration):
            self.assertTrue(math.isclose(v, v_model, rel_tol=1e-5), (v, v_model))
            self.assertTrue(math.isclose(a, v_model / 0.5, rel_tol=1e-5), (a, v_model))
        self.assertEqual(tuple(planning.limits.acceleration), acceleration)
        self.assertEqual(tuple(self.kin.limits.acceleration), before)      # the driver's model untouched
        # the model's own accelerations are faster than a 0.5 s ramp: the match changes something
        self.assertTrue(all(a < m for a, m in zip(acceleration, before)), (acceleration, before))

    def test_goals_in_the_hood_are_free_with_the_tcp_inside_it(self):
        """--cell bench/cells/hood_post.yaml: a goal of the hood's region (GOAL_REGIONS) is a free
        configuration (the driver's padding) whose TCP lies in the region, and the region is under
        the hood's top and between its walls."""
        import random
        from vr_driver.kinematics.collision import CollisionChecker
        from vr_driver.kinematics.scene import load_scene
        cell = os.path.join(REPO, "bench", "cells", "hood_post.yaml")
        checker = CollisionChecker.default(scene=load_scene(cell), padding=0.01)
        region = self.bench.GOAL_REGIONS[os.path.basename(cell)]
        scene = {o.name: o for o in checker.scene.objects()}
        top = scene["hood_top"]
        self.assertLess(region[2][1] / 1000.0, top.position[2] - top.size[2] / 2.0)
        self.assertGreater(region[1][0] / 1000.0, scene["hood_right"].position[1])
        self.assertLess(region[1][1] / 1000.0, scene["hood_left"].position[1])
        rng = random.Random(2)
        for _ in range(3):
            q = self.bench.region_free(self.kin, checker, rng, region)
            self.assertFalse(checker.in_collision(q))
            pose = self.kin.fk_pose(q)
            for value, (lo, hi) in zip((pose.x, pose.y, pose.z), region[:3]):
                self.assertTrue(lo - 1e-6 <= value <= hi + 1e-6, (pose, region))

    def test_a_ramp_out_of_range_is_refused_by_name(self):
        for value in ("0", "-1", "nan", "6"):
            res = subprocess.run([sys.executable, BENCH, "--ramp-time", value], capture_output=True, text=True,
                                 timeout=60)
            self.assertEqual(res.returncode, 2, res.stdout + res.stderr)
            self.assertIn("--ramp-time must be in (0, 5] s", res.stderr)
            self.assertNotIn("planning benchmark:", res.stdout)


if __name__ == "__main__":
    unittest.main()
