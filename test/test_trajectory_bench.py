"""bench/trajectory.py's generator makes what the bench claims: valid planner-like trajectories.

Checked with the driver's own code, not the generator's: the driver's validate() and
segment_speeds() accept each one (joint limits, increasing times, within the speed limits); every
point's TCP and every sample of the joint-space chords between points lie in the workspace box of
vr_driver.yaml (check_envelope); 10-100 points; each segment's limiting joint at 50-100 % of its
speed limit; chained (each starts where the previous ended); the same for the same seed. The
"wrist" set's goals cross joint_5 = 0 and end near or on it, inside the limits and the box, with the
accelerations matched to the arm's ramp; its judging follows the driver's wrist band (joint_4 /
joint_6 by their sum where joint_5 is near 0).
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


def set_up_stack(cls):
    """The bench module, the driver's parameter file, the kinematics and the motion planner, as
    class attributes of a test class."""
    cls.bench = load_bench()
    from vr_driver.kinematics.solver import Kinematics
    from vr_driver.kinematics.preview import MovePreviewer
    from vr_driver.params import DriverParams
    with open(os.path.join(REPO, "vr_driver", "config", "vr_driver.yaml")) as fh:
        cls.params = DriverParams.from_dict(yaml.safe_load(fh))
    cls.kin = Kinematics.default()
    cls.planner = MovePreviewer(cls.kin)


class TrajectoryGeneratorTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        set_up_stack(cls)
        cls.trajs = cls.bench.generate(7, 12)

    def test_same_seed_same_trajectories(self):
        again = self.bench.generate(7, 12)
        self.assertEqual([t.to_json() for t in again], [t.to_json() for t in self.trajs])
        other = self.bench.generate(8, 2)
        self.assertNotEqual(other[0].to_json(), self.trajs[0].to_json())

    def test_the_driver_accepts_them_and_speeds_are_50_to_100_percent(self):
        from vr_driver.driver.motion.trajectories import TrajectoryGoal, segment_speeds, validate
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
                    self.assertLessEqual(s, 1.0)
                # cruise at 50..100 %, from rest and to rest: the first and last segments slower
                self.assertGreaterEqual(max(speeds), 0.5 - 1e-6)
                self.assertLess(speeds[0], max(speeds))
                self.assertEqual(len(t.fractions), len(speeds))
                for a, b in zip(t.fractions, speeds):
                    self.assertAlmostEqual(a, b, places=6)

    def test_points_and_chords_inside_the_limits_and_the_workspace(self):
        from vr_driver.kinematics.preview import check_envelope
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


def joint_limits_yaml():
    """(velocity, acceleration) limits per joint, read here from MoveIt's joint_limits.yaml."""
    with open(os.path.join(REPO, "panasonic_vr006l_moveit_config", "config", "joint_limits.yaml")) as fh:
        d = yaml.safe_load(fh)["joint_limits"]
    names = ["joint_%d" % i for i in range(1, 7)]
    return [d[n]["max_velocity"] for n in names], [d[n]["max_acceleration"] for n in names]


class TimeOptimalSetTest(unittest.TestCase):
    """The "topp" set (the bench's default): resampled every 0.1 s, within MoveIt's velocity AND
    acceleration limits as the samples show them (divided differences: a trajectory within the
    limits gives samples within them, whatever it is between), from rest to rest, accepted by the
    driver, and time-optimal on a plain move."""

    @classmethod
    def setUpClass(cls):
        set_up_stack(cls)
        cls.vmax, cls.amax = joint_limits_yaml()
        cls.trajs = cls.bench.generate(5, 4, timing="topp") + cls.bench.generate(9, 4, timing="topp")

    def test_within_the_velocity_and_acceleration_limits(self):
        eps = 1e-9
        seen_acc = seen_vel = 0.0
        for k, t in enumerate(self.trajs):
            with self.subTest(trajectory=k):
                times, pts = t.times, t.points
                h = [b - a for a, b in zip(times, times[1:])]
                v = [[(q1[j] - q0[j]) / hh for j in range(6)] for q0, q1, hh in zip(pts, pts[1:], h)]
                for vv in v:
                    for j in range(6):
                        self.assertLessEqual(abs(vv[j]), self.vmax[j] + eps)
                        seen_vel = max(seen_vel, abs(vv[j]) / self.vmax[j])
                for i in range(len(v) - 1):
                    for j in range(6):
                        acc = 2.0 * (v[i + 1][j] - v[i][j]) / (h[i] + h[i + 1])
                        self.assertLessEqual(abs(acc), self.amax[j] + eps)
                        seen_acc = max(seen_acc, abs(acc) / self.amax[j])
                # from rest and to rest: the first and last segments as if accelerating from rest
                for j in range(6):
                    self.assertLessEqual(abs(v[0][j]), self.amax[j] * h[0] / 2.0 + eps)
                    self.assertLessEqual(abs(v[-1][j]), self.amax[j] * h[-1] / 2.0 + eps)
        # time-optimal: some joint near one of its limits. The model's accelerations bring a joint to
        # full speed in 0.1 s (one resampling step), so the samples' divided differences average the
        # ramps out (about 0.6 of the limit at most): the velocity shows it; the trapezoid test below
        # checks the acceleration
        self.assertGreater(max(seen_acc, seen_vel), 0.8, "time-optimal: some joint near its velocity or "
                           "acceleration limit")

    def test_resampled_every_tenth_of_a_second_and_the_driver_accepts_them(self):
        from vr_driver.driver.motion.trajectories import TrajectoryGoal, segment_speeds, validate
        from vr_driver.kinematics.preview import check_envelope
        names = self.params.controller_joint_names
        lim = self.kin.limits
        for k, t in enumerate(self.trajs):
            with self.subTest(trajectory=k):
                steps = [b - a for a, b in zip(t.times_ns, t.times_ns[1:])]
                self.assertTrue(all(s == 100_000_000 for s in steps[:-1]), steps)
                self.assertTrue(50_000_000 <= steps[-1] <= 150_000_000, steps[-1])
                traj = validate(TrajectoryGoal(names, t.points, t.times), names, t.points[0], lim.lower, lim.upper, 0.0)
                self.assertTrue(all(s <= 1.0 for s in segment_speeds(traj, lim.velocity, names)))
                for a, b in zip(t.points, t.points[1:]):
                    self.assertTrue(self.params.workspace.contains(self.kin.fk_pose(b)))
                    check_envelope(self.planner.ptp_joints(a, b), self.params.workspace)
        for a, b in zip(self.trajs[:3], self.trajs[1:4]):
            self.assertEqual(a.points[-1], b.points[0])                  # chained

    def test_a_straight_move_of_one_joint_takes_the_trapezoid_time(self):
        b = self.bench
        vmax, amax = [1.0] * 6, [2.0] * 6
        for dist, optimal in ((2.0, 2.0 / 1.0 + 1.0 / 2.0),              # cruises: D / v + v / a
                              (0.2, 2.0 * math.sqrt(0.2 / 2.0))):        # never at full speed: 2 sqrt(D / a)
            leg = b.Leg((0.0,) * 6, (dist,) + (0.0,) * 5, (0.0,) * 6)
            timed = b.time_leg(leg, vmax, amax)
            self.assertAlmostEqual(timed.duration, optimal, delta=0.01 * optimal)
            self.assertAlmostEqual(timed.leg.q(timed.s_at(timed.duration / 2.0))[0], dist / 2.0, delta=1e-3)

    def test_a_straight_move_at_the_model_s_limits_takes_their_trapezoid_time(self):
        """MoveIt's limits are the model's one set (accelerations velocity / 0.1 s): full speed in 0.1 s."""
        b = self.bench
        self.assertEqual(self.amax, [20.9] * 4 + [52.3] * 2)
        for joint in (0, 4):
            v, a = self.vmax[joint], self.amax[joint]
            self.assertAlmostEqual(v / a, 0.1, places=9)
            for dist, optimal in ((1.0, 1.0 / v + v / a), (0.05, 2.0 * math.sqrt(0.05 / a))):
                goal = [0.0] * 6
                goal[joint] = dist
                timed = b.time_leg(b.Leg((0.0,) * 6, tuple(goal), (0.0,) * 6), self.vmax, self.amax)
                self.assertAlmostEqual(timed.duration, optimal, delta=0.01 * optimal)

    def test_a_bent_leg_keeps_both_limits_between_the_grid_points(self):
        b = self.bench
        vmax, amax = self.vmax, self.amax
        leg = b.Leg((0.0, 0.2, -0.3, 0.0, 0.5, 0.0), (1.2, -0.4, 0.3, 1.5, 1.0, -2.0),
                    (0.0, 0.3, 0.0, -0.35, 0.0, 0.2))
        timed = b.time_leg(leg, [v * b.TOPP_MARGIN for v in vmax], [a * b.TOPP_MARGIN for a in amax])
        pts, tns = b.resample([timed], dt=0.004)                          # finely: between the grid points too
        times = [x * 1e-9 for x in tns]
        v = [[(q1[j] - q0[j]) / (t1 - t0) for j in range(6)] for q0, q1, t0, t1 in zip(pts, pts[1:], times, times[1:])]
        for i in range(len(v) - 1):
            h = times[i + 2] - times[i]
            for j in range(6):
                self.assertLessEqual(abs(v[i][j]), vmax[j])
                self.assertLessEqual(abs(2.0 * (v[i + 1][j] - v[i][j]) / h), amax[j])


class WristSetTest(unittest.TestCase):
    """The "wrist" set (``--set wrist``): deterministic, its goals cross joint_5 = 0, end within 2 deg
    of it or on it, with joint_4 / joint_6 away from 0 and apart and the arm's other joints moving a
    little; every point and chord inside the limits and the box, within MoveIt's velocity limits and
    the accelerations matched to the arm's ramp (0.5 s: velocity / 0.5 s), the same paths at both."""

    @classmethod
    def setUpClass(cls):
        set_up_stack(cls)
        cls.vmax, cls.amax = joint_limits_yaml()
        cls.n = 2 * len(cls.bench.WRIST_KINDS)
        cls.chk = cls.bench.Checker()
        cls.trajs = cls.bench.generate(3, cls.n, cls.chk, timing="wrist")
        cls.slow = cls.bench.generate(3, cls.n, cls.chk, timing="wrist", ramp_time=0.5)

    def test_same_seed_same_goals(self):
        again = self.bench.generate(3, 3, self.chk, timing="wrist")
        self.assertEqual([t.to_json() for t in again], [t.to_json() for t in self.trajs[:3]])
        other = self.bench.generate(4, 1, self.chk, timing="wrist")
        self.assertNotEqual(other[0].to_json(), self.trajs[0].to_json())

    def test_goals_cross_and_end_near_or_on_the_singularity(self):
        b = self.bench
        deg = math.radians
        crossed = near = on = 0
        for k, t in enumerate(self.trajs):
            kind = b.WRIST_KINDS[k % len(b.WRIST_KINDS)]
            j5 = [q[4] for q in t.points]
            end = t.points[-1]
            with self.subTest(goal=k, kind=kind, j5=[round(math.degrees(v), 2) for v in j5]):
                self.assertEqual(t.legs[-1].split()[0], kind)
                if kind == "cross":
                    # from one side to the other: a sign change between two points of the last leg
                    self.assertTrue(deg(15.0) - 1e-9 <= abs(end[4]) <= deg(35.0) + 1e-9)
                    self.assertTrue(any(a * b_ < 0.0 for a, b_ in zip(j5, j5[1:])))
                    if abs(j5[0]) >= deg(15.0):
                        self.assertLess(j5[0] * end[4], 0.0)
                    crossed += 1
                elif kind == "near":
                    self.assertTrue(0.0 < abs(end[4]) <= deg(2.0))
                    near += 1
                else:
                    self.assertEqual(end[4], 0.0)                 # exactly on it
                    on += 1
                # the wrist's other joints away from 0 and apart at the end (and at every waypoint)
                self.assertGreaterEqual(abs(end[3]), deg(10.0) - 1e-9)
                self.assertGreaterEqual(abs(end[5]), deg(10.0) - 1e-9)
                self.assertGreaterEqual(abs(end[3] - end[5]), deg(15.0) - 1e-9)
                # the arm's other joints move a little: at most 10 deg per leg (and a bend of 10 deg)
                moved = [max(abs(q[i] - t.points[0][i]) for q in t.points) for i in range(3)]
                self.assertLessEqual(max(moved), deg(10.0) * len(t.legs) + deg(10.0) + 1e-9)
                self.assertGreater(max(moved), deg(0.5))
        self.assertEqual((crossed, near, on), (8, 2, 2))
        # a goal that starts inside the band leaves it first (near -> a side -> across)
        after_near = self.trajs[3]
        self.assertLess(abs(after_near.points[0][4]), math.radians(2.0))
        self.assertEqual([leg.split()[0] for leg in after_near.legs], ["side", "cross"])

    def test_points_and_chords_inside_the_limits_and_the_box_and_the_driver_accepts_them(self):
        from vr_driver.driver.motion.trajectories import TrajectoryGoal, segment_speeds, validate
        from vr_driver.kinematics.preview import check_envelope
        names = self.params.controller_joint_names
        lim = self.kin.limits
        ws = self.params.workspace
        for k, t in enumerate(self.trajs + self.slow):
            with self.subTest(goal=k):
                steps = [b - a for a, b in zip(t.times_ns, t.times_ns[1:])]
                self.assertTrue(all(s == 100_000_000 for s in steps[:-1]), steps)
                traj = validate(TrajectoryGoal(names, t.points, t.times), names, t.points[0], lim.lower, lim.upper, 0.0)
                self.assertTrue(all(s <= 1.0 for s in segment_speeds(traj, lim.velocity, names)))
                for i, q in enumerate(t.points):
                    self.assertEqual(self.kin.limit_violations(q), [])
                    self.assertTrue(ws.contains(self.kin.fk_pose(q)), self.kin.fk_pose(q))
                    if i:
                        check_envelope(self.planner.ptp_joints(t.points[i - 1], q), ws)   # raises if not
        self.assertEqual(self.trajs[0].points[0], tuple(self.kin.ik_pose(self.bench.HOME_POSE)))
        for a, b in zip(self.trajs, self.trajs[1:]):
            self.assertEqual(a.points[-1], b.points[0])                  # chained

    def accelerations(self, t):
        """Per joint the largest |acceleration| the samples show (divided differences; at the ends from
        rest and to rest), and the largest speed as a share of MoveIt's limit."""
        times, pts = t.times, t.points
        h = [b - a for a, b in zip(times, times[1:])]
        v = [[(q1[j] - q0[j]) / hh for j in range(6)] for q0, q1, hh in zip(pts, pts[1:], h)]
        acc = [0.0] * 6
        for i in range(len(v) - 1):
            for j in range(6):
                acc[j] = max(acc[j], abs(2.0 * (v[i + 1][j] - v[i][j]) / (h[i] + h[i + 1])))
        for j in range(6):                      # from rest and to rest
            acc[j] = max(acc[j], 2.0 * abs(v[0][j]) / h[0], 2.0 * abs(v[-1][j]) / h[-1])
        return acc, max(abs(x) / vm for vv in v for x, vm in zip(vv, self.vmax))

    def test_accelerations_matched_to_the_ramp_and_the_same_paths(self):
        b = self.bench
        self.assertEqual(self.chk.accelerations(), tuple(self.amax))
        matched = self.chk.accelerations(0.5)
        for m, v in zip(matched, self.vmax):
            self.assertAlmostEqual(m, v / 0.5, places=12)
        with self.assertRaises(ValueError):
            self.chk.accelerations(0.0)
        over = 0
        for k, (fast, slow) in enumerate(zip(self.trajs, self.slow)):
            with self.subTest(goal=k):
                # the same path (the same waypoints), only timed for the slower arm
                self.assertEqual(fast.legs, slow.legs)
                self.assertEqual(fast.points[0], slow.points[0])
                self.assertEqual(fast.points[-1], slow.points[-1])
                self.assertGreater(slow.duration, fast.duration)
                acc, speed = self.accelerations(slow)
                self.assertLessEqual(speed, 1.0 + 1e-9)
                for j in range(6):
                    self.assertLessEqual(acc[j], matched[j] + 1e-9)
                acc_fast, _speed = self.accelerations(fast)
                for j in range(6):
                    self.assertLessEqual(acc_fast[j], self.amax[j] + 1e-9)
                over += any(a > m for a, m in zip(acc_fast, matched))
        # the model-ramp plans ask for more than a 0.5 s arm has: matching matters
        self.assertGreater(over, 0)
        self.assertEqual(b.WRIST_CONFIGS, ("v3-paced", "v3-paced-ramp05", "v1-paced", "v2-paced"))
        for name in b.WRIST_CONFIGS:
            self.assertIn(name, b.CONFIGS)
        self.assertEqual(b.CONFIGS["v3-paced-ramp05"][3], {"paced": True, "lookahead": 1, "ramp_time": 0.5})


class WristJudgingTest(unittest.TestCase):
    """The "wrist" set's judging on made-up runs: inside the band (|joint_5| < 5 deg, the sample's or
    the plan's) joint_4 / joint_6 by their sum, outside it each joint; the targets per goal and per
    configuration, v1 on SUCCESSFUL only."""

    @classmethod
    def setUpClass(cls):
        cls.bench = load_bench()
        cls.rule = cls.bench.WristRule(band=math.radians(5.0), sign=1.0)
        d = math.radians
        # joint_5 from +20 to -20 deg in 1 s, joint_4 +20, joint_6 -30 (the sweep)
        cls.plan = cls.bench.Planned(((0.1, 0.5, -0.2, d(20.0), d(20.0), d(-30.0)),
                                      (0.1, 0.5, -0.2, d(20.0), d(-20.0), d(-30.0))),
                                     (0, 1_000_000_000), (0.1,), ("cross straight",))
        cls.times = [0.05 * k for k in range(21)]

    def run_of(self, change):
        """Samples of the plan at 20 Hz, ``change(t, q)`` applied."""
        return [(t, change(t, list(self.plan.sample(t)))) for t in self.times]

    def test_the_driver_s_band_and_sign(self):
        from vr_driver.driver.joints.resolution import WRIST_BAND, WireResolution
        from vr_driver.kinematics.solver import Kinematics
        from types import SimpleNamespace
        kin = Kinematics.default()
        rule = self.bench.WristRule.of(kin)
        self.assertEqual(rule.band, WRIST_BAND)
        self.assertEqual(rule.sign, WireResolution(kin, SimpleNamespace(pose_resolution=(0.1, 0.01))).sign)
        self.assertIn("by their sum where |joint_5| < 5.0 deg", rule.words())

    def test_inside_the_band_a_split_that_keeps_the_sum_is_on_the_plan(self):
        b = self.bench
        d = math.radians

        def split(t, q):
            if abs(q[4]) < d(5.0):                   # the controller's own split: +10 / -10 deg
                q[3] += d(10.0)
                q[5] -= d(10.0)
            return tuple(q)
        samples = self.run_of(split)
        judged = b.analyse(self.plan, samples, 1.0, self.plan.points[-1], 0.1, wrist=self.rule)
        plain = b.analyse(self.plan, samples, 1.0, self.plan.points[-1], 0.1)
        self.assertLess(judged["dev_deg"], 1e-6)
        self.assertLess(judged["path_deg"], 1e-6)          # the driver's path check with the same band
        self.assertAlmostEqual(judged["dev_sum_deg"], 0.0, places=6)
        self.assertEqual(judged["band_samples"], 5)        # joint_5 at +4, +2, 0, -2, -4 deg
        self.assertEqual(judged["sum_name"], "J4+J6")
        self.assertAlmostEqual(plain["dev_deg"], 10.0, places=6)
        self.assertGreater(plain["path_deg"], 5.0)
        self.assertNotIn("dev_sum_deg", plain)

    def test_inside_the_band_the_sum_counts(self):
        b = self.bench
        d = math.radians

        def turned(t, q):
            if abs(q[4]) < d(5.0):                    # both the same way: the sum off by 0.6 deg
                q[3] += d(0.3)
                q[5] += d(0.3)
            return tuple(q)
        r = b.analyse(self.plan, self.run_of(turned), 1.0, self.plan.points[-1], 0.1, wrist=self.rule)
        self.assertAlmostEqual(r["dev_deg"], 0.6, places=6)
        self.assertEqual(r["dev_joint"], 7)                # the sum is the worst
        self.assertAlmostEqual(r["dev_sum_deg"], 0.6, places=6)
        self.assertEqual(r["dev_joints_deg"][3], 0.0)      # joint_4 and joint_6 outside the band: on the plan
        self.assertEqual(r["dev_joints_deg"][5], 0.0)
        verdict = dict(b.goal_verdicts(dict(r, ok=True, completed=True), "v3"))
        self.assertFalse(verdict["deviation at the same time, band rule [deg]"])

    def test_outside_the_band_each_joint_counts(self):
        b = self.bench
        d = math.radians

        def off(t, q):
            if q[4] > d(10.0):                          # a split off the plan where the wrist is well-conditioned
                q[3] += d(0.4)
                q[5] -= d(0.4)
            return tuple(q)
        r = b.analyse(self.plan, self.run_of(off), 1.0, self.plan.points[-1], 0.1, wrist=self.rule)
        self.assertAlmostEqual(r["dev_deg"], 0.4, places=6)
        self.assertIn(r["dev_joint"], (4, 6))
        self.assertAlmostEqual(r["dev_joints_deg"][3], 0.4, places=6)
        self.assertAlmostEqual(r["dev_sum_deg"], 0.0, places=6)
        verdict = dict(b.goal_verdicts(dict(r, ok=True, completed=True, margin_s=-0.1), "v3"))
        self.assertEqual(set(verdict.values()), {True})     # 0.4 deg: within 0.5

    def test_the_final_error_by_the_same_rule(self):
        b = self.bench
        d = math.radians
        plan = b.Planned((self.plan.points[0], (0.1, 0.5, -0.2, d(20.0), 0.0, d(-30.0))), (0, 1_000_000_000),
                         (0.1,), ("on straight",))
        samples = [(t, plan.sample(t)) for t in self.times]
        end = list(plan.points[-1])
        split = tuple(end[:3] + [end[3] + d(5.0), end[4], end[5] - d(5.0)])
        turned = tuple(end[:3] + [end[3] + d(0.03), end[4], end[5] + d(0.03)])
        r = b.analyse(plan, samples, 1.0, split, 0.1, wrist=self.rule)
        self.assertAlmostEqual(r["final_deg"], 0.0, places=9)
        self.assertTrue(r["final_by_sum"])
        self.assertAlmostEqual(b.analyse(plan, samples, 1.0, turned, 0.1, wrist=self.rule)["final_deg"], 0.06, places=6)
        self.assertAlmostEqual(b.analyse(plan, samples, 1.0, split, 0.1)["final_deg"], 5.0, places=6)
        # an end off the band: each joint
        far = b.analyse(self.plan, self.run_of(lambda t, q: tuple(q)), 1.0,
                        tuple(v + (d(0.04) if j == 3 else 0.0) for j, v in enumerate(self.plan.points[-1])),
                        0.1, wrist=self.rule)
        self.assertAlmostEqual(far["final_deg"], 0.04, places=6)
        self.assertFalse(far["final_by_sum"])

    def test_the_targets_per_configuration_v1_on_successful_only(self):
        b = self.bench
        good = {"ok": True, "completed": True, "margin_s": -0.2, "dev_deg": 0.3, "final_deg": 0.01}
        late = dict(good, margin_s=0.4)
        for protocol in ("v3", "v2"):
            met = dict(b.verdicts({"set": "wrist", "protocol": protocol, "goals": [good, good]}))
            self.assertEqual(set(met.values()), {True}, protocol)
            met = dict(b.verdicts({"set": "wrist", "protocol": protocol, "goals": [good, late]}))
            self.assertFalse(met["time - 1.10 x plan - 0.3 s"])
            self.assertTrue(met["all goals SUCCESSFUL"])
        met = dict(b.verdicts({"set": "wrist", "protocol": "v1", "goals": [good, late]}))
        self.assertEqual(met, {"all goals SUCCESSFUL": True, "time - 1.10 x plan - 0.3 s": None,
                               "deviation at the same time, band rule [deg]": None,
                               "final error, band rule [deg]": None})
        failed = dict(good, ok=False, completed=False)
        self.assertFalse(dict(b.verdicts({"set": "wrist", "protocol": "v1", "goals": [good, failed]}))[
            "all goals SUCCESSFUL"])
        self.assertEqual([m for _l, m in b.goal_verdicts(failed, "v3")], [False] * 4)
        # a goal whose plan no arm follows within the target says so in its line (the floor: vr_driver.driver.joints.following)
        words = dict(good, samples=10, dev_joints_deg=[0.6] * 6, j5_deg=[20.0, 1.0, -20.0], floor_deg=0.75,
                     floor_where="joint_6 at point 3 of 3 (stops from 162 deg/s)")
        self.assertTrue(b.beyond_any_arm(words))
        self.assertIn("comes closer than 0.75 deg to this plan (joint_6 at point 3 of 3 (stops from 162 deg/s)): the "
                      "deviation target is beyond any such arm", b.wrist_words(words, "v3"))
        self.assertFalse(b.beyond_any_arm(dict(words, floor_deg=0.4)))
        self.assertNotIn("beyond any arm", b.wrist_words(dict(words, floor_deg=0.4), "v3"))
        self.assertFalse(b.beyond_any_arm(good))
        # the topp set's verdicts are unchanged: TARGETS, still included
        self.assertEqual([label for label, _m in b.verdicts({"set": "topp", "protocol": "v1", "goals": [good]})],
                         ["all goals SUCCESSFUL"] + [label for label, _k, _l in b.TARGETS])


class FiguresTest(unittest.TestCase):
    """analyse(): the figures of one goal from joint_states samples, on a made-up run."""

    @classmethod
    def setUpClass(cls):
        cls.bench = load_bench()

    def test_a_run_that_stops_once_on_the_way(self):
        b = self.bench
        plan = b.Planned(((0.0,) * 6, (1.0,) + (0.0,) * 5), (0, 1_000_000_000), (0.5,), ("straight",))
        samples = []
        t = 0.0
        while t <= 2.0 + 1e-9:            # 20 Hz: still 0-0.3 s, moving, still 0.8-1.2 s, moving, at the end
            if t < 0.3:
                x = 0.0
            elif t < 0.8:
                x = (t - 0.3)
            elif t < 1.2:
                x = 0.5
            elif t < 1.7:
                x = 0.5 + (t - 1.2)
            else:
                x = 1.0
            samples.append((t, (x,) + (0.0,) * 5))
            t += 0.05
        r = b.analyse(plan, samples, 2.0, (1.0001,) + (0.0,) * 5, b.min_still(20.0, 20.0))
        self.assertAlmostEqual(r["ratio"], 2.0)
        self.assertEqual(r["stops"], 1)                      # the one on the way, not start and end
        self.assertAlmostEqual(r["still_pct"], 100.0 * (0.25 + 0.35 + 0.3) / 2.0, delta=3.0)
        self.assertAlmostEqual(r["dev_send_deg"], math.degrees(0.5), delta=0.01)  # t = 1.0-1.2: at 0.5, plan 1.0
        # the plan run 0.3 s late (the start delay) fits the first part exactly; the stop of 0.4 s
        # on the way still leaves 0.2 .. 0.3 of a joint unit at its worst
        self.assertLess(r["dev_deg"], r["dev_send_deg"])
        self.assertGreater(r["dev_deg"], math.degrees(0.19))
        self.assertLessEqual(r["lag_s"], 0.5)
        self.assertEqual(r["dev_joint"], 1)
        self.assertAlmostEqual(r["path_deg"], 0.0, places=6)  # always on the planned line
        self.assertAlmostEqual(r["final_deg"], math.degrees(0.0001), places=6)
        self.assertAlmostEqual(r["start_s"], 0.3, delta=0.06)
        self.assertAlmostEqual(r["margin_s"], 2.0 - (1.10 * 1.0 + 0.3))   # time <= 1.10 x plan + 0.3 s missed by 0.6 s
        self.assertEqual(len(r["dev_joints_deg"]), 6)
        self.assertAlmostEqual(r["dev_joints_deg"][0], r["dev_deg"])
        self.assertEqual(r["dev_joints_deg"][1:], [0.0] * 5)

    def test_the_plot_of_a_goal(self):
        import tempfile
        b = self.bench
        plan = b.Planned(((0.0,) * 6, (1.0,) * 6), (0, 1_000_000_000), (0.5,), ("straight",))
        samples = [(0.05 * k, (min(1.0, 0.05 * k),) * 6) for k in range(30)]
        with tempfile.TemporaryDirectory() as tmp:
            path = b.plot_goal(tmp, "v3-paced", 2, plan, samples, 0.1, 1.4, "test")
            self.assertEqual(os.path.basename(path), "v3-paced_02.png")
            with open(path, "rb") as fh:
                self.assertEqual(fh.read(8), b"\x89PNG\r\n\x1a\n")
            self.assertLess(os.path.getsize(path), 150_000)

    def test_configurations_launch_what_they_say(self):
        b = self.bench
        for name, (protocol, baud, rate, opts) in b.CONFIGS.items():
            cfg = {"baud": baud, "cycle_rate": rate, "speed_factor": 1.0, "protocol": protocol,
                   "paced": bool(opts.get("paced")), "lookahead": opts.get("lookahead"),
                   "ramp_time": opts.get("ramp_time")}
            args = b.launch_args(cfg)
            text = b.title(protocol, baud, rate, cfg["paced"], cfg["lookahead"], cfg["ramp_time"])
            with self.subTest(config=name):
                self.assertIn("protocol:=%s" % protocol, args)
                self.assertEqual("line_baud:=%d" % baud in args, "-paced" in name)
                self.assertEqual("io:=true" in args, cfg["paced"])
                if protocol == "v3":
                    self.assertIn("interpreter_lookahead:=%d" % (0 if name.endswith("-la0") else 1), args)
                # the slower ramp of an older controller: ramp_time:=0.5, shown in the title
                ramp = [a for a in args if a.startswith("ramp_time:=")]
                self.assertEqual(ramp, ["ramp_time:=0.5"] if name.endswith("-ramp05") else [])
                self.assertEqual(", ramp 0.5 s" in text, name.endswith("-ramp05"))
        for protocol in ("v1", "v2", "v3"):
            self.assertEqual(b.CONFIGS[protocol + "-paced-ramp05"][:3], b.CONFIGS[protocol + "-paced"][:3])
            self.assertEqual(dict(b.CONFIGS[protocol + "-paced-ramp05"][3], ramp_time=None),
                             dict(b.CONFIGS[protocol + "-paced"][3], ramp_time=None))
            self.assertNotIn(protocol + "-paced-ramp05", b.DEFAULT_CONFIGS)
        self.assertEqual(b.CONFIGS["v3-paced-ramp05"][3]["lookahead"], 1)
        self.assertEqual(b.CONFIGS["v3-paced"][:2], ("v3", 19200))

    def test_the_simulated_pendant_session_recovers_the_true_robot(self):
        """--calibrate's pendant session (ROS-free): the readings of the proposed poses on the true
        robot, rounded as the pendant shows them, fit from the package's model to the true file's
        parameters (the issue's 0.2 mm / 0.02 deg); the written YAML is a valid driver ``model`` and
        carries the true zero offsets; the true model and the driver's model reach driver.launch."""
        import tempfile
        from vr_driver.params import DriverParams
        b = self.bench
        true_file = os.path.join(REPO, "vr_driver", "test", "data", "true_model_example.yaml")
        with tempfile.TemporaryDirectory() as tmp:
            out = os.path.join(tmp, "fitted.yaml")
            calib = b.simulate_calibration(true_file, out)
            self.assertEqual(calib["poses"], 12)
            self.assertLess(calib["max_mm"], 0.2, calib)
            self.assertLess(calib["max_deg"], 0.02, calib)
            self.assertGreater(calib["model_max_mm"], 5.0, calib)          # the package's model is off
            self.assertEqual(DriverParams.from_dict({"model": out}).model, out)
            zero = b.model_zero_offsets(out)
            self.assertAlmostEqual(zero[1], math.radians(0.3), delta=math.radians(0.02))
        self.assertEqual(b.model_zero_offsets(), (0.0,) * 6)
        args = b.launch_args({"baud": 19200, "cycle_rate": 20.0, "speed_factor": 1.0, "protocol": "v2",
                              "true_model": true_file, "model": "/x/fitted.yaml"})
        self.assertIn("true_model:=%s" % true_file, args)
        self.assertIn("model:=/x/fitted.yaml", args)

    def test_judged_on_the_true_joints(self):
        """--true-model: the deviation, the distance to the path and the final error are of the
        judged (true) samples; the timing figures of joint_states."""
        b = self.bench
        plan = b.Planned(((0.0,) * 6, (1.0, 0.5) + (0.0,) * 4), (0, 1_000_000_000), (0.5,), ("straight",))
        ts = [k * 0.05 for k in range(int(plan.duration / 0.05) + 1)]
        samples = [(t, plan.sample(t)) for t in ts]
        off = [(t, tuple(v + (0.01 if j == 1 else 0.0) for j, v in enumerate(q))) for t, q in samples]
        plain = b.analyse(plan, samples, plan.duration, plan.points[-1], 0.1)
        judged = b.analyse(plan, samples, plan.duration, off[-1][1], 0.1, judged=off)
        self.assertLess(plain["dev_deg"], 1e-6)
        self.assertAlmostEqual(judged["dev_deg"], math.degrees(0.01), places=3)
        self.assertEqual(judged["dev_joint"], 2)
        self.assertAlmostEqual(judged["final_deg"], math.degrees(0.01), places=6)
        for key in ("still_pct", "stops", "start_s", "samples"):
            self.assertEqual(plain[key], judged[key], key)

    def test_a_moving_arm_whose_feedback_repeats_once_is_not_standing_still(self):
        b = self.bench
        moving = [(0.0, (0.0,) * 6), (0.05, (0.1,) + (0.0,) * 5), (0.1, (0.1,) + (0.0,) * 5),
                  (0.15, (0.2,) + (0.0,) * 5)]
        self.assertEqual(b.still_runs(moving, b.min_still(20.0, 20.0)), [])     # 20 Hz bus: one repeat
        self.assertEqual(len(b.still_runs(moving, b.min_still(50.0, 20.0))), 1)  # 50 Hz: 2.5 cycles still


if __name__ == "__main__":
    unittest.main()


class CommissioningTest(unittest.TestCase):
    """--commissioning FILE: before the commissioning the planner plans at the model's limits (the
    "wrist" set's accelerations too, not matched to the arm), after it at the file's
    ``planning_limits`` (the joint_limits.yaml beside it), and the driver gets
    ``commissioning:=FILE``; a file that is not a commissioning's is refused in words."""

    @classmethod
    def setUpClass(cls):
        import tempfile
        cls.bench = load_bench()
        cls.tmp = tempfile.TemporaryDirectory()
        cls.file = os.path.join(cls.tmp.name, "g2_commissioning.yaml")
        # a G2 that ramps in 0.5 s: the accelerations velocity / 0.5, the velocities the model's
        cls.vmax, cls.model_amax = cls.bench.joint_limits(["joint_%d" % i for i in range(1, 7)])
        cls.measured = [round(v / 0.5, 3) for v in cls.vmax]
        with open(cls.file, "w") as fh:
            yaml.safe_dump({"protocol": "v3", "planning_limits": os.path.join(cls.tmp.name, "joint_limits.yaml"),
                            "controller": {"ramp_time": 0.5},
                            "commissioning": {"date": "2026-01-01T00:00:00+00:00"}}, fh)
        with open(os.path.join(cls.tmp.name, "joint_limits.yaml"), "w") as fh:
            yaml.safe_dump({"joint_limits": {"joint_%d" % (i + 1): {
                "has_velocity_limits": True, "max_velocity": v, "has_acceleration_limits": True,
                "max_acceleration": a} for i, (v, a) in enumerate(zip(cls.vmax, cls.measured))}}, fh)
        cls.chk = cls.bench.Checker()

    @classmethod
    def tearDownClass(cls):
        cls.tmp.cleanup()

    def setup(self, **cfg):
        chk = self.bench.Checker.__new__(self.bench.Checker)
        chk.__dict__.update(self.chk.__dict__)              # (the shared model; its own limits)
        return chk, self.bench.planner_setup(chk, cfg)

    def test_the_planner_s_limits_before_and_after(self):
        b = self.bench
        path, velocity, acceleration = b.planner_limits(self.file)
        self.assertEqual(path, os.path.join(self.tmp.name, "joint_limits.yaml"))
        self.assertEqual(velocity, tuple(self.vmax))
        self.assertEqual(acceleration, tuple(self.measured))
        # the wrist set: matched to the arm's ramp without the option, the model's before, the file's after
        _chk, matched = self.setup(set="wrist", ramp_time=0.5)
        self.assertEqual(matched, self.chk.accelerations(0.5))
        chk, before = self.setup(set="wrist", ramp_time=0.5, unmatched=True)
        self.assertEqual(before, tuple(self.model_amax))
        self.assertEqual(chk.amax, self.chk.amax)
        chk, after = self.setup(set="wrist", ramp_time=0.5, commissioning=self.file, planner_limits=path)
        self.assertEqual(after, tuple(self.measured))
        self.assertEqual((tuple(chk.vmax_planner), tuple(chk.amax)), (tuple(self.vmax), tuple(self.measured)))
        # the topp set plans at chk.amax: the file's after, the model's before
        chk, none = self.setup(set="topp", commissioning=self.file, planner_limits=path)
        self.assertIsNone(none)
        self.assertEqual(tuple(chk.amax), tuple(self.measured))
        self.assertNotEqual(tuple(self.model_amax), tuple(self.measured))
        # a goal timed after the commissioning is slower than one timed at the model's limits
        import random
        start = self.chk.home()
        fast = b.generate_one(random.Random(3), start, self.chk, timing="wrist", index=0, amax=before)
        slow = b.generate_one(random.Random(3), start, chk, timing="wrist", index=0, amax=after)
        self.assertEqual(fast.points[-1], slow.points[-1])
        self.assertGreater(slow.duration, fast.duration)
        for words, cfg in (("the commissioning's", {"planner_limits": path}),
                           ("not matched", {"set": "wrist", "unmatched": True}),
                           ("0.5 s ramp", {"set": "wrist", "ramp_time": 0.5})):
            self.assertIn(words, b.planner_words(cfg))

    def test_the_driver_is_launched_with_the_file_and_others_are_refused(self):
        b = self.bench
        args = b.launch_args({"baud": 19200, "cycle_rate": 20.0, "speed_factor": 1.0, "protocol": "v3",
                              "commissioning": self.file})
        self.assertIn("commissioning:=%s" % self.file, args)
        self.assertIn("protocol:=v3", args)
        self.assertFalse(any(a.startswith("commissioning:=") for a in b.launch_args(
            {"baud": 19200, "cycle_rate": 20.0, "speed_factor": 1.0, "protocol": "v3"})))
        other = os.path.join(self.tmp.name, "not_one.yaml")
        with open(other, "w") as fh:
            yaml.safe_dump({"protocol": "v3"}, fh)
        with self.assertRaisesRegex(ValueError, "not a commissioning file"):
            b.planner_limits(other)
        # the option refuses it before anything starts, and --calibrate with it (main sets the
        # bench's signal handlers: this process's are put back)
        import signal
        saved = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
        try:
            for argv in (["--commissioning", other],
                         ["--commissioning", self.file, "--true-model", self.file, "--calibrate"],
                         ["--commissioning", os.path.join(self.tmp.name, "missing.yaml")]):
                with self.subTest(argv=argv), self.assertRaises(SystemExit) as err:
                    b.main(argv)
                self.assertEqual(err.exception.code, 2)
        finally:
            for sig, handler in saved.items():
                signal.signal(sig, handler)
