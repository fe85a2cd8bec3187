"""bench/trajectory.py's generator makes what the bench claims: valid planner-like trajectories.

Checked with the driver's own code, not the generator's: the driver's validate() and
segment_speeds() accept each one (joint limits, increasing times, within the speed limits); every
point's TCP and every sample of the joint-space chords between points lie in the workspace box of
vr_driver.yaml (check_envelope); 10-100 points; each segment's limiting joint at 50-100 % of its
speed limit; chained (each starts where the previous ended); the same for the same seed.
"""
import importlib.util
import math
import os
import sys
import unittest

import yaml

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def load_bench():
    spec = importlib.util.spec_from_file_location("bench_trajectory", os.path.join(REPO, "bench", "trajectory.py"))
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module            # dataclasses look the module up while it loads
    spec.loader.exec_module(module)
    return module


class TrajectoryGeneratorTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.bench = load_bench()
        from vr_driver.kinematics import Kinematics
        from vr_driver.motion import MotionPlanner
        from vr_driver.params import DriverParams
        with open(os.path.join(REPO, "vr_driver", "config", "vr_driver.yaml")) as fh:
            cls.params = DriverParams.from_dict(yaml.safe_load(fh))
        cls.kin = Kinematics.default()
        cls.planner = MotionPlanner(cls.kin)
        cls.trajs = cls.bench.generate(7, 12)

    def test_same_seed_same_trajectories(self):
        again = self.bench.generate(7, 12)
        self.assertEqual([t.to_json() for t in again], [t.to_json() for t in self.trajs])
        other = self.bench.generate(8, 2)
        self.assertNotEqual(other[0].to_json(), self.trajs[0].to_json())

    def test_the_driver_accepts_them_and_speeds_are_50_to_100_percent(self):
        from vr_driver.driver.trajectories import TrajectoryGoal, segment_speeds, validate
        names = self.params.controller_joint_names
        lim = self.kin.limits
        for k, t in enumerate(self.trajs):
            with self.subTest(trajectory=k):
                self.assertGreaterEqual(len(t.points), 10)
                self.assertLessEqual(len(t.points), 100)
                self.assertEqual(t.times_ns[0], 0)
                goal = TrajectoryGoal(names, t.points, t.times)
                traj = validate(goal, names, t.points[0], lim.lower, lim.upper, 0.0)
                speeds = segment_speeds(traj, lim.velocity, names)
                self.assertEqual(len(speeds), len(t.points) - 1)
                for s in speeds:
                    self.assertGreaterEqual(s, 0.5 - 1e-6)
                    self.assertLessEqual(s, 1.0)
                self.assertEqual(len(t.fractions), len(speeds))
                for a, b in zip(t.fractions, speeds):
                    self.assertAlmostEqual(a, b, places=6)

    def test_points_and_chords_inside_the_limits_and_the_workspace(self):
        from vr_driver.motion import check_envelope
        ws = self.params.workspace
        lim = self.kin.limits
        for k, t in enumerate(self.trajs):
            for i, q in enumerate(t.points):
                with self.subTest(trajectory=k, point=i):
                    self.assertEqual(self.kin.limit_violations(q), [])
                    self.assertTrue(ws.contains(self.kin.fk_pose(q)), self.kin.fk_pose(q))
                    self.assertTrue(all(lo < v < hi for v, lo, hi in zip(q, lim.lower, lim.upper)))
                    if i:
                        check_envelope(self.planner.ptp_joints(t.points[i - 1], q), ws)   # raises if not

    def test_chained_from_home_and_planner_like(self):
        home = self.kin.ik_pose(self.bench.HOME_POSE)
        self.assertEqual(self.trajs[0].points[0], tuple(home))
        for a, b in zip(self.trajs, self.trajs[1:]):
            self.assertEqual(a.points[-1], b.points[0])
        for t in self.trajs:
            self.assertGreater(max(abs(x - y) for x, y in zip(t.points[0], t.points[-1]))
                               + max(abs(x - y) for p in t.points for x, y in zip(p, t.points[0])),
                               math.radians(20.0))              # it goes somewhere
            mid = t.times_ns[-1] // 2
            self.assertEqual(len(t.sample(mid * 1e-9)), 6)
            self.assertEqual(t.sample(t.duration + 1.0), t.points[-1])
        sizes = {len(t.points) for t in self.trajs}
        self.assertGreater(len(sizes), 3, "the number of points varies")


if __name__ == "__main__":
    unittest.main()
