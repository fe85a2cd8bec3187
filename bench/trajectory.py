#!/usr/bin/python3
"""Planner-like trajectories through joint_trajectory_action on the virtual controller (printed, never asserted).

    scripts/bench trajectory [-- --n 3 --seed 1 --configs v1-paced,v2-paced,v3-paced,v3-paced-la0 --plot DIR]
    scripts/bench trajectory -- --set wrist [--n 6]      (v3-paced, v3-paced-ramp05, v1-paced, v2-paced)
    scripts/bench trajectory -- --set wrist --configs v3-paced-ramp05 --commissioning FILE   (before / after)

Trajectories (:func:`generate`, deterministic for a seed; the same set for every configuration):
random joint paths as a sampling planner returns them -- 1 to 3 legs between random waypoints, each
leg straight or bent (a sine bump in one or two joints) in joint space.

The "topp" set (default, ``--set topp``), as MoveIt's time parameterisation and resampling give
them: each leg's curve timed from rest to rest (the legs meet at corners, where a path followed
exactly must stop) time-optimally under MoveIt's joint velocity limits (times one velocity scaling
in [0.5, 1.0] per trajectory) AND acceleration limits (panasonic_vr006l_moveit_config's
joint_limits.yaml, full), by the classic forward-backward pass on the path parameter
(:func:`time_leg`, at ``TOPP_MARGIN`` of each limit for its grid), then resampled every 0.1 s plus
the end (:func:`resample`). Each leg's curve, every resampled point and every chord between two lie
in the limits and the box below. Goals carry empty tolerances (the driver's per-protocol defaults),
as MoveIt sends them.

The "wrist" set (``--set wrist``, :func:`wrist_plan`): goals across and onto the wrist singularity
(joint_5 = 0), where a pose fixes joint_4 + joint_6 but hardly their split. Goal i does
``WRIST_KINDS[i]`` (cycled): "cross" from one side (|joint_5| 15-35 deg) to the other, "near" ends
within 0.2-2 deg of 0, "on" ends on it exactly; from home: + -> -, - -> +, + -> near, near -> a side
-> across, -> 0, 0 -> a side -> across. 1-2 legs, straight or bent (never in joint_5), joint_4 and
joint_6 away from 0 and apart at every waypoint (10-40 / 10-60 deg, at least 15 deg apart), joint_1..3
moving up to 10 deg per leg; timed as the "topp" set (velocity scaling 0.2-1: a slow crossing spends
a few bus cycles in the band) with the planner's accelerations MATCHED to the configuration's arm
(``ramp_time``: velocity / ramp_time, :meth:`Checker.accelerations`; the same paths, only the timing
differs); every point and chord inside the limits and the box (the other singularities checked with
joint_5 at 30 deg). Judged as the driver judges (:class:`WristRule`, vr_driver.driver.joints.resolution's
band): where joint_5 is within 5 deg of 0 in the sample or the plan, joint_4 / joint_6 by their sum,
elsewhere each joint; the deviation, the distance to the path and the final error so. The targets
(``WRIST_TARGETS``, per goal and per configuration): every goal SUCCESSFUL with empty tolerances, time
<= 1.10 x plan + 0.3 s, deviation <= 0.5 deg, final error <= 0.05 deg; v1: SUCCESSFUL only (its time
and deviation reported). Default configurations ``WRIST_CONFIGS``.

The "dense" set (``--set dense``, the first bench's): 10 to 100 points in all
(point 0 = the start, at time 0), the points spread over the legs by length. Every point lies inside
the joint limits and its TCP inside the driver's workspace box (vr_driver.yaml, shrunk by a margin
for the controller's whole-mm rounding), and so does every sample of the straight joint-space chord
between two consecutive points (the driver's own PTP preview and ``check_envelope``). The waypoints
keep one arm configuration (elbow, wrist) and the joints off their limits (``SAMPLE_BOX``); every
point keeps off singularities (``MIN_MANIPULABILITY``), where the v1 program's rounded Cartesian
targets would solve to joints far from the plan.
Each leg is timed at one random fraction in [0.5, 1.0] of the joint speed limits at cruise: every
segment's limiting joint moves at that fraction; as a planner's time parameterisation, the whole
trajectory speeds up from rest and slows down to rest with a constant acceleration over
``ACCEL_TIME`` (:func:`time_law`; times are whole nanoseconds, rounded up, so no fraction is ever
exceeded). The trajectories chain: each starts where the previous one ends, the first at the
virtual controller's home pose. The bench makes trajectory i from where the arm really is, with the
same random source (:func:`rng_for`): an arm that ended where planned runs exactly the set printed in
the header; one that ended a little off (v1) a nearly identical one.

Configurations (``CONFIGS``): protocol v1 / v2 / v3 (``driver.launch protocol:=``, both ends) at
19 200 bit/s, 20 Hz bus cycle ("slow", "paced") and 187 500 bit/s, 50 Hz ("fast"); "paced": the
virtual line carries its bytes at the bit rate (``line_baud:=``) with the I/O island on it
(``io:=true``); v3 with the G2 program's interpreter look-ahead 1 or 0 ("-la0",
``interpreter_lookahead:=``); "-ramp05" (not run by default): the paced ones with the virtual arm
reaching full speed in 0.5 s (``ramp_time:=0.5``, as an older controller may) instead of the 0.1 s
of the model's joint limits (velocity / acceleration; v1's arm does not model it); each in a worker process with its own roscore and driver.launch
(sim:=true). A goal is a FollowJointTrajectory (vr_driver's md5-identical copy of control_msgs)
sent by an actionlib client with header.stamp 0 (start now) and the path / goal tolerances of
--path-tolerance / --goal-tolerance; by default none (the driver's per-protocol defaults), except
v1 goals of the dense set: 5 deg (``V1_TOLERANCE``).

Figures per goal and, in the summary, median / max per configuration over the goals run to the end
(succeeded, or missed only the goal tolerance). t = 0 is send_goal at this client; joint_states by
their header stamps (the driver's wall clock, the same as this process's):
  time ratio     (result received - send_goal) / planned duration;
  still          the share of that time the arm stood still: runs of joint_states samples in which no
                 joint moved more than 0.01 deg, spanning at least two bus cycles and two joint_states
                 periods (so one feedback record published twice is not a stop; ``min_still``), from
                 the run's first to its last sample (a lower bound: 50 ms more per stop at most);
  stops          standing-still episodes between the first and the last motion of the arm;
  start          send_goal -> the first joint_states sample that moved (part of "still");
  path dev       the largest |joint_states - plan(t - d)| of any joint, the plan interpolated
                 (linearly, as the driver does) at the sample's time since send_goal less the start
                 delay d (0 .. 0.5 s in 5 ms steps refined to 0.25 ms, the one that gives the smallest deviation: the
                 goal's way to the driver and the bus's to the controller, "plan delay"); each sample
                 at its header stamp (the time the controller took its record); also the
                 same with d = 0 ("dev at send") and the distance to the planned path at any time
                 ("path-only");
  final error    the largest joint error of the first joint_states after the result vs the last point;
  succeeded      goals with state SUCCEEDED and error_code SUCCESSFUL;
  time margin    time - (1.10 x plan + 0.3 s);
  per joint      the path dev of each joint (at the goal's start delay), median / max over the goals;
  driver's own   the driver's "at most X deg from the plan at the same time" of the result;
  goal start     send_goal -> the virtual G2 took the goal's first target (the taken_time of its entry
                 on /virtual_controller/executed, on the same monotonic clock; v1: the request
                 accepted), per goal and as median / p95 / max against START_MEDIAN / START_P95, beside
                 the driver's own words (all from the goal's arrival: "prepared in P s; first target
                 left F s after the goal arrived; ran R x ...") and how far the bench's time and
                 start delay are from the driver's.
``--kinds K,...`` (the wrist set): its goals' kinds, cycled (cross, near, on, and "end": across
joint_5 = 0 to within WRIST_END = 1 deg of it on the other side, where the driver's wire-target
search is longest; bench/README.md, "How soon a goal moves").
joint_states are stamped with the time the controller took their record (no age window: ``age`` 0).
The summary is Markdown tables, then per configuration each target (``TARGETS``: v3 on the paced
19.2 kbit/s line at look-ahead >= 1; every configuration is judged against them) met or NOT met.
``--true-model FILE``: the virtual G2 is the robot of FILE (driver.launch ``true_model:=``; the
driver keeps its model) and every goal's deviation, distance to the path and final error are of the arm's TRUE joints (the
virtual controller's ``~true_joints``, at their header stamps, the same start-delay fit; the timing
figures stay joint_states'), not of joint_states: with v1 and
v3 those are the driver's IK of the reported pose and would hide the error. To compare with the plan,
whose joints are the driver model's, the true joints are taken less the driver model's joint zero
offsets (0 for the package's model): both then count from the same zero pose. ``--calibrate``
(with ``--true-model``): then the pendant session is simulated (:func:`simulate_calibration`: the
proposed poses, the joints the pendant shows and the TCP pose the controller reports on the true
robot, rounded to 0.01; the fit from the package's model, written to a temporary YAML) and every
configuration runs again with the driver's ``model:=`` that file; the before / after table follows.
``--commissioning FILE`` (what ``rosrun vr_driver commission`` wrote, with the ``joint_limits.yaml``
beside it): every configuration runs twice, as before the commissioning -- the driver without it,
the planner at the model's limits (joint_limits.yaml of the MoveIt config; the "wrist" set's
accelerations too, NOT matched to the configuration's arm: what a user plans with before measuring
it) -- and after it: ``driver.launch commissioning:=FILE`` (the driver's parameters from the file;
the configuration's ``protocol:=`` and bus still win) and the planner at the file's limits (its
``planning_limits``, :func:`planner_limits`, velocity and acceleration); the before / after table
follows (:func:`compare_commissioning`).
``--plot DIR``: per goal DIR/<config>_<goal>.png, the planned and the executed joints over time
(:func:`plot_goal`, matplotlib Agg). A configuration the stack does not support
(no ready driver, every goal refused) is reported with the reason; the bench then goes on with the
next one. Exit status 1 when a configuration failed.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import random
import re
import signal
import sys
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
for _pkg in ("vr_driver", "pyprofibus_vendor", "panasonic_vr006l_support"):
    _src = os.path.join(REPO, _pkg, "src")
    if _src not in sys.path:
        sys.path.insert(0, _src)
if os.path.dirname(os.path.abspath(__file__)) not in sys.path:
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import driver_latency  # noqa: E402 (ROS-free: its Failure, Recorder, runner and stack worker serve here too)
from driver_latency import Failure, Recorder, interrupt_once, stack_worker  # noqa: E402

RESULT_TAG = "@@TRAJECTORY_RESULT "
CONFIG_FILE = os.path.join(REPO, "vr_driver", "config", "vr_driver.yaml")
#: the virtual controller's initial pose (controller.options' default, mm / deg)
HOME_POSE = (1120.0, 0.0, 725.0, 0.0, 45.0, 0.0)
#: name -> (protocol, baud, bus cycles per second, options): "paced" the virtual line carries its
#: bytes at the bit rate (driver.launch line_baud:=, io:=true: the I/O island on the line too),
#: "lookahead" the v3 G2 program's interpreter look-ahead (driver.launch interpreter_lookahead:=),
#: "ramp_time" the virtual arm's time from rest to full speed [s] (driver.launch ramp_time:=; unset: the
#: model's joint limits, velocity / acceleration = 0.1 s; 0.5: an older controller may ramp so slowly;
#: v1's arm ramps over a share of each move and ignores it)
CONFIGS: Dict[str, Tuple[str, int, float, Dict[str, Any]]] = {
    "v1-slow": ("v1", 19200, 20.0, {}),
    "v1-fast": ("v1", 187500, 50.0, {}),
    "v1-paced": ("v1", 19200, 20.0, {"paced": True}),
    "v2-slow": ("v2", 19200, 20.0, {}),
    "v2-fast": ("v2", 187500, 50.0, {}),
    "v2-paced": ("v2", 19200, 20.0, {"paced": True}),
    "v3-fast": ("v3", 187500, 50.0, {"lookahead": 1}),
    "v3-paced": ("v3", 19200, 20.0, {"paced": True, "lookahead": 1}),
    "v3-paced-la0": ("v3", 19200, 20.0, {"paced": True, "lookahead": 0}),
    "v1-paced-ramp05": ("v1", 19200, 20.0, {"paced": True, "ramp_time": 0.5}),
    "v2-paced-ramp05": ("v2", 19200, 20.0, {"paced": True, "ramp_time": 0.5}),
    "v3-paced-ramp05": ("v3", 19200, 20.0, {"paced": True, "lookahead": 1, "ramp_time": 0.5}),
}
DEFAULT_CONFIGS = ("v1-paced", "v2-paced", "v3-paced", "v3-paced-la0", "v3-fast")
#: the targets (v3 at 19.2 kbit/s on the paced line with the I/O island, look-ahead >= 1; shown for
#: every configuration): (label, key, limit)
TARGETS = (("time - 1.10 x plan - 0.3 s", "margin_s", 0.0), ("still [%]", "still_pct", 5.0),
           ("dev per joint [deg]", "dev_deg", 0.5), ("final error [deg]", "final_deg", 0.05))
TIME_FACTOR, TIME_SLACK = 1.10, 0.3   # s: the time target, time <= 1.10 x plan + 0.3 s
#: the "wrist" set's targets (every configuration, every goal; shown with the band rule of
#: :class:`WristRule`): (label, key, limit); on v1 only "every goal SUCCESSFUL" is judged, its time
#: and deviation (stops at kept points, whole-mm / whole-degree targets) are reported
WRIST_TARGETS = (("time - 1.10 x plan - 0.3 s", "margin_s", 0.0),
                 ("deviation at the same time, band rule [deg]", "dev_deg", 0.5),
                 ("final error, band rule [deg]", "final_deg", 0.05))

# --------------------------------------------------------------------------------- the generator
#: where waypoints are drawn [deg]: inside the limits with room to spare, one arm configuration as a
#: collision-checked plan keeps it: J3 on one side of the elbow singularity (J3 ~ -80), J5 on one
#: side of the wrist singularity (J5 = 0) -- the v1 program solves each (rounded, Cartesian) target
#: nearest to the previous one and would switch configuration near them
SAMPLE_BOX = ((-120.0, 120.0), (-40.0, 90.0), (-50.0, 40.0), (-150.0, 150.0), (15.0, 120.0), (-180.0, 180.0))
#: the largest change of each joint from one waypoint to the next [deg]
LEG_SPAN = (90.0, 60.0, 60.0, 90.0, 60.0, 120.0)
MIN_LEG = math.radians(20.0)          # a leg moves some joint at least this much
MIN_STEP = 0.02                       # s: points at most every 20 ms at full speed (as a planner spaces them)
BUMP = (5.0, 20.0)                    # bent legs: sine bump amplitude [deg]
POINTS = (10, 100)
SPEED = (0.5, 1.0)                    # fraction of the joint speed limits per leg (at cruise)
#: s: the trajectory speeds up from rest and slows down to rest over this long (constant
#: acceleration of the time law), as a planner's time parameterisation does -- no arm jumps to speed
ACCEL_TIME = 0.3
#: every point this far from a singularity (Yoshikawa's measure; the median of random joints is ~0.06):
#: near one, the v1 program's whole mm / degree poses solve to joints degrees away from the plan
MIN_MANIPULABILITY = 0.03
WORKSPACE_MARGIN = 5.0                # mm: the box shrunk by this (the v1 program rounds to whole mm)
#: v1's default path and goal tolerance [deg]: its whole mm / degree Cartesian targets, solved again by
#: the controller's IK, land the wrist up to ~1.5 deg off (trajectories.V1_WIRE_ERROR); with the
#: driver's default 1 deg every goal would end early, with no figures of a whole run
V1_TOLERANCE = 5.0
#: the trajectory sets: "topp" time-optimal (velocity and acceleration limited) and resampled, as
#: MoveIt's time parameterisation gives; "dense" 10-100 points at cruise fractions (the first bench);
#: "wrist" the topp timing on goals across and onto the wrist singularity (joint_5 = 0)
TIMINGS = ("topp", "dense", "wrist")


@dataclass(frozen=True)
class Planned:
    """One trajectory: ``points[0]`` is the start (time 0); ``times_ns`` time_from_start in whole
    nanoseconds (exact in a ROS Duration); ``fractions`` the planned speed of each segment as a
    fraction of the joint speed limits (its limiting joint's); ``legs`` how it was made."""

    points: Tuple[Tuple[float, ...], ...]
    times_ns: Tuple[int, ...]
    fractions: Tuple[float, ...]
    legs: Tuple[str, ...]

    @property
    def times(self) -> Tuple[float, ...]:
        return tuple(t * 1e-9 for t in self.times_ns)

    @property
    def duration(self) -> float:
        return self.times_ns[-1] * 1e-9

    def sample(self, t: float) -> Tuple[float, ...]:
        """The planned joints at ``t`` s (linear between points, held before / after)."""
        times = self.times
        if t <= 0.0:
            return self.points[0]
        if t >= times[-1]:
            return self.points[-1]
        k = 1
        while times[k] < t:
            k += 1
        f = (t - times[k - 1]) / (times[k] - times[k - 1])
        return tuple(a + f * (b - a) for a, b in zip(self.points[k - 1], self.points[k]))

    def to_json(self) -> Dict[str, Any]:
        return {"points": [list(p) for p in self.points], "times_ns": list(self.times_ns),
                "fractions": list(self.fractions), "legs": list(self.legs)}

    @classmethod
    def from_json(cls, d: Dict[str, Any]) -> "Planned":
        return cls(tuple(tuple(p) for p in d["points"]), tuple(d["times_ns"]), tuple(d["fractions"]),
                   tuple(d["legs"]))


class Checker:
    """The driver's kinematics (Kinematics.default(), the config's TCP offset) and its workspace
    box (vr_driver.yaml), shrunk by ``margin`` mm: is a joint point, a chord, inside?"""

    def __init__(self, margin: float = WORKSPACE_MARGIN, config: str = CONFIG_FILE):
        import yaml

        from vr_driver.kinematics.solver import Kinematics
        from vr_driver.kinematics.preview import MovePreviewer
        from vr_driver.params import DriverParams
        from vr_driver.poses import Workspace
        with open(config) as fh:
            self.params = DriverParams.from_dict(yaml.safe_load(fh) or {})
        self.kin = Kinematics.default()
        if any(self.params.tcp_offset):
            self.kin.conventions = self.kin.conventions.with_tcp(self.params.tcp_offset)
        self.planner = MovePreviewer(self.kin)
        ws = self.params.workspace
        self.workspace = Workspace(x=(ws.x[0] + margin, ws.x[1] - margin), y=(ws.y[0] + margin, ws.y[1] - margin),
                                   z=(ws.z[0] + margin, ws.z[1] - margin), angle=ws.angle)
        self.lower, self.upper = self.kin.limits.lower, self.kin.limits.upper
        self.vmax = self.kin.limits.velocity
        #: MoveIt's limits (joint_limits.yaml), the "topp" set's time parameterisation's
        self.vmax_planner, self.amax = joint_limits(self.params.controller_joint_names)

    def home(self) -> Tuple[float, ...]:
        return self.kin.ik_pose(HOME_POSE)

    def point_ok(self, q: Sequence[float], wrist: bool = False) -> bool:
        """``q`` inside the joint limits, its TCP inside the box, off singularities (``wrist``: the
        "wrist" set's points sit on joint_5 = 0 by design: the rest of the arm off its own, the
        measure taken with joint_5 at ``WRIST_PROBE``)."""
        if any(not lo <= v <= hi for v, lo, hi in zip(q, self.lower, self.upper)):
            return False
        if not self.workspace.contains(self.kin.fk_pose(q)):
            return False
        if wrist:
            q = tuple(q[:4]) + (WRIST_PROBE,) + tuple(q[5:])
        return self.kin.manipulability(q) >= MIN_MANIPULABILITY

    def accelerations(self, ramp_time: Optional[float] = None) -> Tuple[float, ...]:
        """The planner's acceleration limits matched to an arm that reaches full speed in
        ``ramp_time`` s (MoveIt's velocity / ramp_time; None: joint_limits.yaml's, the model's 0.1 s)."""
        if ramp_time is None:
            return tuple(self.amax)
        if not ramp_time > 0.0:
            raise ValueError("ramp_time %r: a positive time in seconds" % (ramp_time,))
        return tuple(v / ramp_time for v in self.vmax_planner)

    def chord_ok(self, a: Sequence[float], b: Sequence[float]) -> bool:
        """Every sample (0.02 rad apart) of the straight joint-space move a -> b in the box."""
        from vr_driver.errors import VrDriverError
        from vr_driver.kinematics.preview import check_envelope
        try:
            check_envelope(self.planner.ptp_joints(a, b), self.workspace)
        except VrDriverError:
            return False
        return True


def _leg_points(a: Sequence[float], b: Sequence[float], bump: Sequence[float], n: int) -> List[Tuple[float, ...]]:
    """``n`` points after ``a`` on the leg a -> b (the last one is b), bent by ``bump`` * sin(pi s)."""
    out = []
    for j in range(1, n + 1):
        s = j / n
        w = math.sin(math.pi * s)
        out.append(tuple(x + s * (y - x) + w * d for x, y, d in zip(a, b, bump)))
    return out


def _waypoint(rng: random.Random, prev: Sequence[float], chk: Checker) -> Optional[Tuple[float, ...]]:
    for _ in range(200):
        q = []
        for v, (lo, hi), span in zip(prev, SAMPLE_BOX, LEG_SPAN):
            lo, hi = math.radians(lo), math.radians(hi)
            lo2, hi2 = max(lo, v - math.radians(span)), min(hi, v + math.radians(span))
            q.append(rng.uniform(lo2, hi2) if lo2 < hi2 else min(max(v, lo), hi))
        if max(abs(x - y) for x, y in zip(q, prev)) < MIN_LEG:
            continue
        if chk.point_ok(q):
            return tuple(q)
    return None


def generate_one(rng: random.Random, start: Sequence[float], chk: Checker, n_points: Optional[int] = None,
                 speed: Tuple[float, float] = SPEED, timing: str = "topp", index: int = 0,
                 amax: Optional[Sequence[float]] = None, kinds: Sequence[str] = ()) -> Planned:
    """One planner-like trajectory from ``start`` (see the module doc): ``timing`` "topp" (time-optimal
    under the velocity and acceleration limits, resampled every RESAMPLE_DT), "dense" (10-100
    points, each leg at its cruise fraction, :func:`time_law`) or "wrist" (:func:`wrist_plan`: the
    goal ``kinds[index]`` of the set, cycled -- default WRIST_KINDS --, timed as "topp" under the
    accelerations ``amax``, default joint_limits.yaml's). Raises RuntimeError when no valid one is found in many attempts (cannot
    happen from a valid start in practice)."""
    if timing not in TIMINGS:
        raise ValueError("timing %r: one of %s" % (timing, ", ".join(TIMINGS)))
    start = tuple(float(v) for v in start)
    if timing == "wrist":
        kinds = tuple(kinds) or WRIST_KINDS
        return wrist_plan(rng, start, chk, kinds[index % len(kinds)], amax)
    for _attempt in range(200):
        n_legs = rng.randint(1, 3)
        ways, prev = [], start
        for _ in range(n_legs):
            w = _waypoint(rng, prev, chk)
            if w is None:
                break
            ways.append(w)
            prev = w
        if len(ways) != n_legs:
            continue
        # bends and segment counts: by length (the largest joint change in units of its speed limit)
        bumps, kinds = [], []
        for _ in ways:
            bump = [0.0] * 6
            if rng.random() < 0.5:
                for i in rng.sample(range(6), rng.randint(1, 2)):
                    bump[i] = math.radians(rng.uniform(*BUMP)) * rng.choice((-1.0, 1.0))
                kinds.append("bent")
            else:
                kinds.append("straight")
            bumps.append(bump)
        starts = [start] + ways[:-1]
        if timing == "topp":
            planned = _topp_plan(rng, starts, ways, bumps, kinds, chk, speed)
            if planned is not None:
                return planned
            continue
        lengths = [max(abs(y - x) / v for x, y, v in zip(a, b, chk.vmax)) for a, b in zip(starts, ways)]
        if n_points is not None:
            n = n_points
        else:
            n = rng.randint(POINTS[0], min(POINTS[1], max(POINTS[0], int(sum(lengths) / MIN_STEP) + 1)))
        segments = n - 1
        counts = [max(3 if k == "bent" else 1, int(round(segments * ln / sum(lengths))))
                  for ln, k in zip(lengths, kinds)]
        while sum(counts) > segments:                 # take back from the longest allocation
            i = max(range(len(counts)), key=lambda j: counts[j])
            if counts[i] <= (3 if kinds[i] == "bent" else 1):
                break
            counts[i] -= 1
        while sum(counts) < segments:
            counts[max(range(len(counts)), key=lambda j: lengths[j] / counts[j])] += 1
        if sum(counts) != segments:
            continue
        points: List[Tuple[float, ...]] = [start]
        nominal = [0.0]                               # times at the legs' cruise speeds
        ok = True
        for a, b, bump, count in zip(starts, ways, bumps, counts):
            f = rng.uniform(*speed)
            for q in _leg_points(a, b, bump, count):
                if not (chk.point_ok(q) and chk.chord_ok(points[-1], q)):
                    ok = False
                    break
                need = max(abs(y - x) / v for x, y, v in zip(points[-1], q, chk.vmax))
                if need <= 0.0:
                    ok = False
                    break
                nominal.append(nominal[-1] + need / f)
                points.append(q)
            if not ok:
                break
        if ok:
            times_ns = [int(math.ceil(time_law(u, nominal[-1]) * 1e9)) for u in nominal]
            fractions = [max(abs(y - x) / v for x, y, v in zip(p0, p1, chk.vmax)) / ((t1 - t0) * 1e-9)
                         for p0, p1, t0, t1 in zip(points, points[1:], times_ns, times_ns[1:])]
            return Planned(tuple(points), tuple(times_ns), tuple(fractions), tuple(kinds))
    raise RuntimeError("no valid trajectory found from %s" % (start,))


def _topp_plan(rng: random.Random, starts: Sequence[Tuple[float, ...]], ways: Sequence[Tuple[float, ...]],
               bumps: Sequence[Sequence[float]], kinds: Sequence[str], chk: Checker,
               speed: Tuple[float, float], accel: Optional[Sequence[float]] = None,
               wrist: bool = False) -> Optional[Planned]:
    """The "topp" set: the legs' curves checked against the limits and the box, timed at one velocity
    scaling in ``speed`` (as MoveIt's) with the full acceleration limits (``accel``, default
    joint_limits.yaml's), resampled; None if a curve or a resampled point or chord leaves the box.
    ``wrist``: the points may sit on joint_5 = 0 (:meth:`Checker.point_ok`)."""
    legs = [Leg(tuple(a), tuple(b), tuple(bump)) for a, b, bump in zip(starts, ways, bumps)]
    for leg in legs:
        prev = leg.a
        for k in range(1, LEG_CHECKS + 1):
            q = leg.q(k / LEG_CHECKS)
            if not (chk.point_ok(q, wrist) and chk.chord_ok(prev, q)):
                return None
            prev = q
    f = rng.uniform(*speed)
    vmax = [f * v * TOPP_MARGIN for v in chk.vmax_planner]
    amax = [a * TOPP_MARGIN for a in (chk.amax if accel is None else accel)]
    try:
        timed = [time_leg(leg, vmax, amax) for leg in legs]
    except ValueError:
        return None
    points, times_ns = resample(timed)
    for p0, p1 in zip(points, points[1:]):
        if not (chk.point_ok(p1, wrist) and chk.chord_ok(p0, p1)):
            return None
    fractions = [max(abs(y - x) / v for x, y, v in zip(p0, p1, chk.vmax)) / ((t1 - t0) * 1e-9)
                 for p0, p1, t0, t1 in zip(points, points[1:], times_ns, times_ns[1:])]
    return Planned(tuple(points), tuple(times_ns), tuple(fractions), tuple(kinds))


def time_law(u: float, total: float, accel: float = ACCEL_TIME) -> float:
    """The time at which a path run at its cruise speeds in ``total`` s reaches its nominal time
    ``u``, when the speed ramps up linearly from rest over ``accel`` s and down to rest over the
    last ``accel`` s (both shortened to ``total`` for a short path): the run lasts ``total + accel``."""
    a = min(accel, total)
    if a <= 0.0:
        return u
    if u <= a / 2.0:
        return math.sqrt(2.0 * a * u)
    if u >= total - a / 2.0:
        return total + a - math.sqrt(2.0 * a * max(0.0, total - u))
    return u + a / 2.0


def rng_for(seed: int, index: int) -> random.Random:
    """The random source of trajectory ``index`` (0-based) of a set."""
    return random.Random(seed * 1000003 + index)


def generate(seed: int, n: int, chk: Optional[Checker] = None, start: Optional[Sequence[float]] = None,
             timing: str = "dense", ramp_time: Optional[float] = None, kinds: Sequence[str] = ()) -> List[Planned]:
    """``n`` chained trajectories (each from the previous one's end), from ``start`` (default home).
    The bench makes trajectory ``i`` the same way from where the arm really is (:func:`rng_for`):
    from the planned end, it is this one. ``ramp_time`` (the "wrist" set only): the planner's
    accelerations matched to an arm reaching full speed in that time (:meth:`Checker.accelerations`);
    ``kinds``: its goals' kinds (cycled; default WRIST_KINDS)."""
    chk = chk or Checker()
    q = tuple(start) if start is not None else chk.home()
    amax = chk.accelerations(ramp_time) if timing == "wrist" else None
    out = []
    for i in range(n):
        traj = generate_one(rng_for(seed, i), q, chk, timing=timing, index=i, amax=amax, kinds=kinds)
        out.append(traj)
        q = traj.points[-1]
    return out


# ------------------------------------------------------------------ time-optimal timing ("topp" set)
#: MoveIt's joint limits (velocity and acceleration), as a planner's time parameterisation reads them
JOINT_LIMITS_FILE = os.path.join(REPO, "panasonic_vr006l_moveit_config", "config", "joint_limits.yaml")
RESAMPLE_DT = 0.1                     # s: the timed path resampled this often (MoveIt's resample_dt)
#: the forward-backward pass aims at this share of every limit: it checks the limits at its grid
#: points only, the margin covers the path's curvature between them (the test checks the result)
TOPP_MARGIN = 0.97
TOPP_GRID = 240                       # path parameter steps per leg
LEG_CHECKS = 24                       # points of each leg's curve checked against the box


def joint_limits(names: Sequence[str], path: str = JOINT_LIMITS_FILE) -> Tuple[Tuple[float, ...], Tuple[float, ...]]:
    """(max velocity, max acceleration) per joint of ``names`` [rad/s, rad/s^2] from MoveIt's
    joint_limits.yaml (every joint must have both)."""
    import yaml
    with open(path) as fh:
        limits = (yaml.safe_load(fh) or {})["joint_limits"]
    vel, acc = [], []
    for n in names:
        d = limits[n]
        if not (d.get("has_velocity_limits") and d.get("has_acceleration_limits")):
            raise ValueError("%s: %s has no velocity or no acceleration limit" % (path, n))
        vel.append(float(d["max_velocity"]))
        acc.append(float(d["max_acceleration"]))
    return tuple(vel), tuple(acc)


@dataclass(frozen=True)
class Leg:
    """One leg of a path: q(s) = a + s (b - a) + sin(pi s) bump, s in [0, 1]."""

    a: Tuple[float, ...]
    b: Tuple[float, ...]
    bump: Tuple[float, ...]

    def q(self, s: float) -> Tuple[float, ...]:
        w = math.sin(math.pi * s)
        return tuple(x + s * (y - x) + w * d for x, y, d in zip(self.a, self.b, self.bump))

    def dq(self, s: float) -> Tuple[float, ...]:
        c = math.pi * math.cos(math.pi * s)
        return tuple((y - x) + c * d for x, y, d in zip(self.a, self.b, self.bump))

    def ddq(self, s: float) -> Tuple[float, ...]:
        c = -math.pi * math.pi * math.sin(math.pi * s)
        return tuple(c * d for d in self.bump)


def _accel_range(d1: Sequence[float], d2: Sequence[float], x: float, amax: Sequence[float]
                 ) -> Optional[Tuple[float, float]]:
    """The path accelerations u allowed at path speed^2 ``x``: every joint's q' u + q'' x within
    +-amax; None if there is none."""
    lo, hi = -math.inf, math.inf
    for a1, a2, am in zip(d1, d2, amax):
        if abs(a1) > 1e-12:
            c1, c2 = (-am - a2 * x) / a1, (am - a2 * x) / a1
            lo, hi = max(lo, min(c1, c2)), min(hi, max(c1, c2))
        elif abs(a2 * x) > am:
            return None
    return (lo, hi) if lo <= hi else None


@dataclass(frozen=True)
class TimedLeg:
    """A leg timed from rest to rest: path speed^2 ``x`` at the grid points s = i / n, their times ``t``."""

    leg: Leg
    x: Tuple[float, ...]
    t: Tuple[float, ...]

    @property
    def duration(self) -> float:
        return self.t[-1]

    def s_at(self, t: float) -> float:
        """The path parameter at ``t`` s after the leg's start (constant path acceleration per step)."""
        n = len(self.x) - 1
        if t <= 0.0:
            return 0.0
        if t >= self.t[-1]:
            return 1.0
        lo, hi = 0, n
        while hi - lo > 1:                        # t[lo] <= t < t[hi]
            mid = (lo + hi) // 2
            if self.t[mid] <= t:
                lo = mid
            else:
                hi = mid
        ds = 1.0 / n
        u = (self.x[lo + 1] - self.x[lo]) / (2.0 * ds)
        tau = t - self.t[lo]
        s = lo * ds + math.sqrt(self.x[lo]) * tau + 0.5 * u * tau * tau
        return min(max(s, lo * ds), (lo + 1) * ds)


def time_leg(leg: Leg, vmax: Sequence[float], amax: Sequence[float], n: int = TOPP_GRID) -> TimedLeg:
    """Time-optimal timing of ``leg`` from rest to rest with joint speeds <= ``vmax`` and joint
    accelerations <= ``amax``: the classic forward-backward pass on the path parameter s (the
    phase plane s, x = ds/dt^2, constant path acceleration u between grid points; Bobrow / Shin &
    McKay, as TOPP-RA's reachability sets reduce to on a path like this): the speed limit curve from
    both limits, then the forward pass at the largest u allowed, the backward pass at the smallest
    u allowed, the smaller of the two at each point."""
    ds = 1.0 / n
    d1 = [leg.dq(i * ds) for i in range(n + 1)]
    d2 = [leg.ddq(i * ds) for i in range(n + 1)]
    mvc = []
    for a1, a2 in zip(d1, d2):
        top = min(((vm / abs(v)) ** 2 for v, vm in zip(a1, vmax) if abs(v) > 1e-12), default=1e12)
        if _accel_range(a1, a2, top, amax) is None:          # the acceleration limit bounds the speed
            lo, hi = 0.0, top
            for _ in range(50):
                mid = 0.5 * (lo + hi)
                if _accel_range(a1, a2, mid, amax) is None:
                    hi = mid
                else:
                    lo = mid
            top = lo
        mvc.append(top)
    x = [0.0] * (n + 1)
    for i in range(n):                                        # forward: accelerate as hard as allowed
        r = _accel_range(d1[i], d2[i], x[i], amax)
        up = r[1] if r is not None else 0.0
        x[i + 1] = max(0.0, min(mvc[i + 1], x[i] + 2.0 * up * ds))
    x[n] = 0.0
    for i in range(n - 1, -1, -1):                            # backward: brake as hard as allowed
        r = _accel_range(d1[i + 1], d2[i + 1], x[i + 1], amax)
        down = r[0] if r is not None else 0.0
        x[i] = min(x[i], max(0.0, x[i + 1] - 2.0 * down * ds))
    x[0] = 0.0
    t = [0.0]
    for i in range(n):
        v = math.sqrt(x[i]) + math.sqrt(x[i + 1])
        if v <= 0.0:
            raise ValueError("leg cannot be timed (stuck at s = %.3f)" % (i * ds))
        t.append(t[-1] + 2.0 * ds / v)
    return TimedLeg(leg, tuple(x), tuple(t))


def resample(timed: Sequence[TimedLeg], dt: float = RESAMPLE_DT) -> Tuple[List[Tuple[float, ...]], List[int]]:
    """The legs one after the other (each from rest to rest: they meet at corners), sampled every
    ``dt`` s and at the end (a last sample closer than dt / 2 to the end is left out, so the last
    segment is 0.5 .. 1.5 dt long); (points, times in whole ns). The first point is the first leg's
    start and the last the last leg's end, exactly."""
    starts, total = [], 0.0
    for tl in timed:
        starts.append(total)
        total += tl.duration
    step_ns = int(round(dt * 1e9))
    end_ns = int(math.ceil(total * 1e9))
    times_ns = list(range(0, end_ns, step_ns))
    if len(times_ns) > 1 and end_ns - times_ns[-1] < step_ns // 2:
        times_ns.pop()
    points = []
    for tn in times_ns:
        t = tn * 1e-9
        k = len(starts) - 1
        while k > 0 and starts[k] > t:
            k -= 1
        points.append(timed[k].leg.q(timed[k].s_at(t - starts[k])))
    points[0] = tuple(timed[0].leg.a)
    points.append(tuple(timed[-1].leg.b))
    times_ns.append(end_ns)
    return points, times_ns


# ------------------------------------------------------------------------ the "wrist" set
#: what goal ``i`` of the "wrist" set does (cycled): "cross" ends on the other side of joint_5 = 0
#: than it starts, "near" ends within ``WRIST_NEAR`` of it, "on" ends on it; each starting inside
#: the band first leaves it to a side. From home (joint_5 +24 deg): + -> -, - -> +, + -> near,
#: near -> side -> the other side, side -> 0, 0 -> side -> the other side, then again
WRIST_KINDS = ("cross", "cross", "near", "cross", "on", "cross")
WRIST_SIDE = (15.0, 35.0)             # deg: |joint_5| of a goal's end or via point off the singularity
WRIST_NEAR = (0.2, 2.0)               # deg: |joint_5| of a "near" goal's end
#: deg: |joint_5| of an "end" goal's end: across joint_5 = 0 to within this of it on the other side (the
#: driver's longest wire-target search: bench/README.md, "How soon a goal moves")
WRIST_END = 1.0
#: the kinds of wrist goal (``--kinds``)
WRIST_KIND_NAMES = ("cross", "near", "on", "end")
WRIST_J4 = (10.0, 40.0)               # deg: |joint_4| at every waypoint (away from 0) ...
WRIST_J6 = (10.0, 60.0)               # deg: ... |joint_6| ...
WRIST_SPLIT = 15.0                    # deg: ... and |joint_4 - joint_6| (the split a pose leaves open near 0)
WRIST_ARM = 10.0                      # deg: joint_1..3 move up to this per leg ("a little")
WRIST_BUMP = (3.0, 10.0)              # deg: bent legs, in one of joint_1..4, joint_6 (never joint_5)
#: velocity scaling per trajectory (MoveIt's): fast crossings and slow ones, which spend a few bus cycles in the band
WRIST_SPEED = (0.2, 1.0)
#: joint_5 [rad] at which the "wrist" set's points are checked for the arm's other singularities
WRIST_PROBE = math.radians(30.0)
#: the configurations the "wrist" set runs by default: v3 at 19.2 kbit/s paced with the island,
#: look-ahead 1, at the model's ramp and at 0.5 s (the planner's accelerations matched), v1, v2
WRIST_CONFIGS = ("v3-paced", "v3-paced-ramp05", "v1-paced", "v2-paced")


def _wrist_waypoint(rng: random.Random, prev: Sequence[float], j5: float, chk: Checker
                    ) -> Optional[Tuple[float, ...]]:
    """A waypoint with joint_5 = ``j5``: joint_1..3 up to ``WRIST_ARM`` from ``prev`` (inside
    ``SAMPLE_BOX``), joint_4 / joint_6 drawn anew away from 0 and apart (``WRIST_J4``, ``WRIST_J6``,
    ``WRIST_SPLIT``); None if none passes the checks."""
    for _ in range(200):
        q = list(prev)
        for i in range(3):
            lo, hi = (math.radians(v) for v in SAMPLE_BOX[i])
            q[i] = min(max(prev[i] + math.radians(rng.uniform(-WRIST_ARM, WRIST_ARM)), lo), hi)
        q[3] = rng.choice((-1.0, 1.0)) * math.radians(rng.uniform(*WRIST_J4))
        q[5] = rng.choice((-1.0, 1.0)) * math.radians(rng.uniform(*WRIST_J6))
        q[4] = j5
        if abs(q[3] - q[5]) >= math.radians(WRIST_SPLIT) and chk.point_ok(q, wrist=True):
            return tuple(q)
    return None


def wrist_joint5(rng: random.Random, start_j5: float, kind: str) -> List[Tuple[str, float]]:
    """joint_5 [rad] of each waypoint of a "wrist" goal of ``kind`` from ``start_j5``, with what its
    leg does ("side": to one side, "cross": across joint_5 = 0, "near", "on"). A start on a side
    (``|joint_5| >= WRIST_SIDE[0]``) may go via another point on that side (one trajectory in two);
    a start nearer the singularity first leaves it to a side drawn at random."""
    def side() -> float:
        return math.radians(rng.uniform(*WRIST_SIDE))
    if kind not in WRIST_KIND_NAMES:
        raise ValueError("wrist goal kind %r: one of %s" % (kind, ", ".join(WRIST_KIND_NAMES)))
    on_side = abs(start_j5) >= math.radians(WRIST_SIDE[0]) - 1e-9
    if on_side:
        s = math.copysign(1.0, start_j5)
        out = [("side", s * side())] if rng.random() < 0.5 else []
    else:
        s = rng.choice((-1.0, 1.0))
        out = [("side", s * side())]
    if kind == "cross":
        out.append(("cross", -s * side()))
    elif kind == "near":
        out.append(("near", rng.choice((-1.0, 1.0)) * math.radians(rng.uniform(*WRIST_NEAR))))
    elif kind == "end":
        out.append(("end", -s * math.radians(rng.uniform(0.0, WRIST_END))))
    else:
        out.append(("on", 0.0))
    return out


def wrist_plan(rng: random.Random, start: Sequence[float], chk: Checker, kind: str,
               amax: Optional[Sequence[float]] = None) -> Planned:
    """One goal of the "wrist" set from ``start``: its joint_5 waypoints (:func:`wrist_joint5`), the
    other joints by :func:`_wrist_waypoint`, each leg straight or bent (never in joint_5: a "cross"
    leg crosses 0 once), timed as the "topp" set (:func:`_topp_plan`, velocity scaling in
    ``WRIST_SPEED``, accelerations ``amax``: the planner's, matched to the arm's ramp). The random
    draws do not depend on ``amax``: the same paths at every ramp, only their timing differs.
    ``legs``: "<what the leg does to joint_5> <straight|bent>". Raises RuntimeError when no valid
    one is found."""
    start = tuple(float(v) for v in start)
    for _attempt in range(200):
        plan = wrist_joint5(rng, start[4], kind)
        ways, prev = [], start
        for _what, j5 in plan:
            w = _wrist_waypoint(rng, prev, j5, chk)
            if w is None:
                break
            ways.append(w)
            prev = w
        if len(ways) != len(plan):
            continue
        bumps, kinds = [], []
        for what, _j5 in plan:
            bump = [0.0] * 6
            if rng.random() < 0.5:
                bump[rng.choice((0, 1, 2, 3, 5))] = math.radians(rng.uniform(*WRIST_BUMP)) * rng.choice((-1.0, 1.0))
                kinds.append(what + " bent")
            else:
                kinds.append(what + " straight")
            bumps.append(bump)
        planned = _topp_plan(rng, [start] + ways[:-1], ways, bumps, kinds, chk, WRIST_SPEED, accel=amax, wrist=True)
        if planned is not None:
            return planned
    raise RuntimeError("no valid wrist goal (%s) found from %s" % (kind, start))


@dataclass(frozen=True)
class WristRule:
    """How the "wrist" set is judged: the driver's wrist band (vr_driver.driver.joints.resolution:
    ``WRIST_BAND``, ``WireResolution.in_band`` / ``sum_of``). Where joint_5 is within ``band`` of 0
    in the sample or in the plan it is compared with (the driver's rule, supervision's
    ``_judged``), joint_4 and joint_6 count by ``joint_4 + sign * joint_6`` -- the pose fixes only
    that there, on every protocol that carries poses -- elsewhere every joint by itself."""

    band: float
    sign: float

    @classmethod
    def of(cls, kin: Any) -> "WristRule":
        """The driver's band and sign for the arm ``kin`` (the sign: its joint_4 / joint_6 axes)."""
        from types import SimpleNamespace

        from vr_driver.driver.joints.resolution import WRIST_BAND, WireResolution
        wire = WireResolution(kin, SimpleNamespace(pose_resolution=(1.0, 1.0)), band=WRIST_BAND)
        return cls(wire.band, wire.sign)

    def in_band(self, actual: Sequence[float], desired: Sequence[float]) -> bool:
        return abs(actual[4]) < self.band or abs(desired[4]) < self.band

    def errors(self, actual: Sequence[float], desired: Sequence[float]) -> List[float]:
        """7 errors [rad]: the six joints' (joint_4's and joint_6's 0 inside the band) and the
        sum's (0 outside it)."""
        errs = [abs(a - b) for a, b in zip(actual, desired)] + [0.0]
        if self.in_band(actual, desired):
            errs[6] = abs((actual[3] - desired[3]) + self.sign * (actual[5] - desired[5]))
            errs[3] = errs[5] = 0.0
        return errs

    def words(self) -> str:
        return "joint_4 %s joint_6 by their sum where |joint_5| < %.1f deg (the sample's or the plan's)" % (
            "+" if self.sign > 0 else "-", math.degrees(self.band))


# ------------------------------------------------------------------------------------ the figures
STILL_EPS = math.radians(0.01)        # a joint that moved less than this did not move
MAX_LAG, LAG_STEP = 0.5, 0.005        # s: start delays tried when comparing with the plan
FINE_STEP = 0.00025                   # s: ... then around the best of them
AGE_STEPS = 8                         # instants tried within a sample's age window


def still_runs(samples: Sequence[Tuple[float, Sequence[float]]], min_still: float) -> List[Tuple[float, float]]:
    """(start, end) of every run of samples (time, joints) in which no joint moved more than
    STILL_EPS from the run's first sample, lasting at least ``min_still`` s."""
    runs = []
    i = 0
    while i < len(samples):
        t0, q0 = samples[i]
        j = i
        while j + 1 < len(samples) and max(abs(a - b) for a, b in zip(samples[j + 1][1], q0)) <= STILL_EPS:
            j += 1
        if samples[j][0] - t0 >= min_still:
            runs.append((t0, samples[j][0]))
        i = j + 1
    return runs


def min_still(cycle_rate: float, joint_states_rate: float) -> float:
    """The shortest standing still counted [s]: unchanged over two bus cycles and two joint_states
    periods (less 10 ms of stamp jitter): at 20 Hz / 20 Hz three equal samples in a row, at 50 Hz
    / 20 Hz two."""
    return max(2.0 / cycle_rate, 1.0 / joint_states_rate) - 0.01


def analyse(plan: Planned, samples: Sequence[Tuple[float, Sequence[float]]], t_result: float,
            final: Optional[Sequence[float]], shortest_still: float, age: float = 0.0,
            judged: Optional[Sequence[Tuple[float, Sequence[float]]]] = None,
            wrist: Optional[WristRule] = None) -> Dict[str, Any]:
    """The figures of one goal from joint_states ``samples`` (time since send_goal, joints in the
    controller's order), the result's time, the first joints after it and :func:`min_still`.
    ``judged`` (--true-model: the true joints, same form): the deviation, the distance to the path
    and (``final`` being then the first true joints after the result) the final error are of these;
    the timing figures (still, stops, start) stay those of ``samples``. ``wrist`` (the "wrist" set):
    the deviation, the distance to the path and the final error by its band rule (joint_4 / joint_6
    by their sum where joint_5 is near 0): ``dev_joints_deg`` then has joint_4's and joint_6's
    outside the band only, ``dev_sum_deg`` the sum's inside it (None: no sample there), ``dev_joint``
    7 when the sum is the worst; ``band_samples`` how many samples were judged so."""
    from vr_driver.driver.motion.trajectories import ValidTrajectory, path_deviation
    inside = [(t, q) for t, q in samples if 0.0 <= t <= t_result]
    out: Dict[str, Any] = {"planned": plan.duration, "elapsed": t_result, "ratio": t_result / plan.duration,
                           "margin_s": t_result - (TIME_FACTOR * plan.duration + TIME_SLACK),
                           "samples": len(inside)}
    runs = still_runs(inside, shortest_still)
    still = sum(b - a for a, b in runs)
    out["still_pct"] = 100.0 * still / t_result if t_result > 0 else 0.0
    moving = [t for (t, q), (_t0, q0) in zip(inside[1:], inside) if max(abs(a - b) for a, b in zip(q, q0)) > STILL_EPS]
    if moving:
        first, last = moving[0], moving[-1]
        out["stops"] = sum(1 for a, b in runs if a > first and b < last)
        out["start_s"] = first
    else:
        out["stops"] = 0
        out["start_s"] = None
    # ``age`` > 0: a sample stamped when its record reached the driver (the arm was there up to ``age``
    # earlier) is compared with the plan over that window, the nearest instant counting; the bench
    # passes 0, its stamps being the time the controller took the record
    steps = [age * k / AGE_STEPS for k in range(AGE_STEPS + 1)] if age > 0.0 else [0.0]
    if judged is not None:
        inside = [(t, q) for t, q in judged if 0.0 <= t <= t_result]

    def errors(q: Sequence[float], want: Sequence[float]) -> List[float]:
        if wrist is None:
            return [abs(a - b) for a, b in zip(q, want)]
        return wrist.errors(q, want)

    def deviation(lag: float) -> Tuple[float, int, List[float]]:
        worst, joint = 0.0, 0
        per_joint = [0.0] * (len(plan.points[0]) + (1 if wrist is not None else 0))
        for t, q in inside:
            best, best_errs = math.inf, per_joint
            for back in steps:
                want = plan.sample(t - lag - back)
                errs = errors(q, want)
                if max(errs) < best:
                    best, best_errs = max(errs), errs
            per_joint = [max(a, b) for a, b in zip(per_joint, best_errs)]
            if best > worst:
                worst, joint = best, best_errs.index(best)
        return worst, joint, per_joint
    raw, _j, raw_joints = deviation(0.0)
    # the plan run late by the start delay the stack cannot avoid (the goal travels to the driver,
    # the bus to the controller): the smallest deviation over delays 0 .. MAX_LAG in LAG_STEP steps
    # (then refined in FINE_STEP steps around the best: at 150 deg/s a 2.5 ms step is 0.4 deg)
    lag, (worst, joint, joints) = 0.0, (raw, _j, raw_joints)
    for k in range(1, int(round(MAX_LAG / LAG_STEP)) + 1):
        d = deviation(k * LAG_STEP)
        if d[0] < worst:
            lag, (worst, joint, joints) = k * LAG_STEP, d
    coarse = lag
    for k in range(-int(round(LAG_STEP / FINE_STEP)), int(round(LAG_STEP / FINE_STEP)) + 1):
        t = coarse + k * FINE_STEP
        if 0.0 <= t <= MAX_LAG and k:
            d = deviation(t)
            if d[0] < worst:
                lag, (worst, joint, joints) = t, d
    out["dev_deg"], out["dev_joint"] = math.degrees(worst), joint + 1
    out["dev_joints_deg"] = [math.degrees(v) for v in joints[:6]]
    out["dev_send_deg"], out["lag_s"] = math.degrees(raw), lag
    path = ValidTrajectory(positions=plan.points, times=plan.times, path_tolerance=(1.0,) * 6,
                           goal_tolerance=(1.0,) * 6, goal_time_tolerance=0.0, delay=0.0,
                           per_configuration=unit_band(plan, wrist) if wrist is not None else None)
    out["path_deg"] = math.degrees(max((path_deviation(path, q)[0] for _t, q in inside), default=0.0))
    out["final_deg"] = (math.degrees(max(errors(final, plan.points[-1]))) if final is not None else None)
    if wrist is not None:
        band = [wrist.in_band(q, plan.sample(t - lag)) for t, q in inside]
        out["band_samples"] = sum(band)
        out["sum_name"] = "J4+J6" if wrist.sign > 0 else "J4-J6"
        out["dev_sum_deg"] = math.degrees(joints[6]) if any(band) else None
        out["final_by_sum"] = final is not None and wrist.in_band(final, plan.points[-1])
        out["j5_deg"] = [math.degrees(plan.points[0][4]), min((math.degrees(q[4]) for q in plan.points), key=abs),
                         math.degrees(plan.points[-1][4])]
    return out


def unit_band(plan: Planned, wrist: WristRule) -> Any:
    """The driver's per-configuration tolerances (``ConfigurationTolerances``) with every tolerance
    1 rad and ``wrist``'s band: the driver's distance to the path (``path_deviation``) in rad, with
    joint_4 / joint_6 by their sum within the band."""
    from vr_driver.driver.motion.trajectories import ConfigurationTolerances
    n = len(plan.points)
    return ConfigurationTolerances(path=((1.0,) * 6,) * n, path_sum=(1.0,) * n, goal_sum=1.0,
                                   errors=((0.0,) * 6,) * n, sum_errors=(0.0,) * n, band=wrist.band,
                                   sign=wrist.sign)


#: the driver's own figure in the result's error_string (driver.joints.supervision's note)
DRIVER_DEV = re.compile(r"at most ([0-9.]+) deg from the plan at the same time")
#: the driver's own timing figures in the result's error_string (driver.joints.supervision's note, timed from
#: the goal's arrival): key -> pattern of its value [s or x]
DRIVER_TIMING = {
    "driver_prep_s": re.compile(r"prepared in ([0-9.]+) s"),
    "driver_first_s": re.compile(r"first target left ([0-9.]+) s after"),
    "driver_ratio": re.compile(r"ran ([0-9.]+) x the planned"),
    "driver_delay_s": re.compile(r"after a start delay of ([0-9.]+) s"),
}
#: the start targets (issue 46: a goal moves within 0.1 s of its arrival), over the goals of a
#: configuration: goal sent -> the controller took its first target, median and p95 [s]
START_MEDIAN, START_P95 = 0.10, 0.15


def driver_timing(text: str) -> Dict[str, Optional[float]]:
    """The driver's timing figures of a result's error_string (:data:`DRIVER_TIMING`; None: not said)."""
    out: Dict[str, Optional[float]] = {}
    for key, pattern in DRIVER_TIMING.items():
        found = pattern.search(text or "")
        out[key] = float(found.group(1)) if found else None
    return out


def first_taken(entries: Sequence[Dict[str, Any]], since: float) -> Optional[float]:
    """[s] from ``since`` (time.monotonic() at send_goal) to the first target the controller took
    after it: the earliest ``taken_time`` (v2 / v3) or ``start_time`` (v1: the request accepted) of
    its execution-log entries (/virtual_controller/executed, on the same monotonic clock) at or after
    ``since``; None when none."""
    times = [float(e.get("taken_time", e.get("start_time"))) for e in entries
             if e.get("taken_time", e.get("start_time")) is not None]
    times = [t for t in times if t >= since]
    return min(times) - since if times else None


def percentile(values: Sequence[float], q: float) -> float:
    """The ``q`` quantile (0..1) of ``values``, linear between order statistics (nan: none)."""
    v = sorted(values)
    if not v:
        return math.nan
    x = q * (len(v) - 1)
    lo = int(math.floor(x))
    hi = min(lo + 1, len(v) - 1)
    return v[lo] + (v[hi] - v[lo]) * (x - lo)


def plot_goal(directory: str, config: str, index: int, plan: Planned, samples: Sequence[Tuple[float, Sequence[float]]],
              lag: float, t_result: float, heading: str) -> str:
    """One PNG per goal, ``directory/<config>_<index>.png``: per joint (six panels) the plan over time
    since send_goal, run late by the fitted start delay ``lag`` (line), the joint_states samples by
    their header stamps (dots) and the result's arrival (dotted line); its path."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    os.makedirs(directory, exist_ok=True)
    fig, axes = plt.subplots(3, 2, figsize=(8.0, 6.4), sharex=True)
    t_plan = [lag + t for t in plan.times]
    t_dense, k = [], 0.0
    end = max(t_result, (samples[-1][0] if samples else 0.0), t_plan[-1]) + 0.1
    while k <= end:
        t_dense.append(k)
        k += 0.01
    shown = [(t, q) for t, q in samples if -0.2 <= t <= end]
    for j, ax in enumerate(axes.flat):
        ax.plot(t_dense, [math.degrees(plan.sample(t - lag)[j]) for t in t_dense], "-", color="tab:blue", lw=1.2,
                label="plan (+%.2f s start delay)" % lag)
        ax.plot(t_plan, [math.degrees(q[j]) for q in plan.points], ".", color="tab:blue", ms=3)
        ax.plot([t for t, _q in shown], [math.degrees(q[j]) for _t, q in shown], ".", color="tab:red", ms=3,
                label="joint_states (header stamps)")
        ax.axvline(t_result, color="0.4", ls=":", lw=1.0, label="result")
        ax.set_ylabel("J%d [deg]" % (j + 1))
        ax.grid(True, lw=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("time since send_goal [s]")
    axes[0][0].legend(fontsize=6, loc="best")
    fig.suptitle(heading, fontsize=9)
    fig.tight_layout()
    path = os.path.join(directory, "%s_%02d.png" % (config, index))
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


# ------------------------------------------------------------------------------------------ worker
# (Failure, from driver_latency: a configuration that cannot be measured, the message says why)

def model_zero_offsets(path: str = "") -> Tuple[float, ...]:
    """The joint zero offsets [rad] of a kinematics YAML (``path`` "": the package's model)."""
    from panasonic_vr006l_support import kinematic_calibration as kc
    params = kc.nominal_parameters(path) if path else kc.nominal_parameters()
    return tuple(params[name] for name in kc.OFFSETS)


def simulate_calibration(true_file: str, out_path: str, n_poses: Optional[int] = None, seed: int = 0
                         ) -> Dict[str, Any]:
    """The commissioning session on the robot of ``true_file``, ROS-free: at each of
    ``propose_poses()`` (whole degrees, the controller's angles the operator jogs to) the joints the
    pendant shows (rounded to 0.01 deg) and the TCP pose the controller reports (the true robot's FK,
    ``kinematic_calibration.fk_controller`` with ``nominal_parameters(true_file)``, rounded to 0.01 mm
    / 0.01 deg); ``fit`` from the package's model; ``write_yaml`` to ``out_path``. Returns the fit's
    summary and how far the fitted parameters are from the true file's: the largest length error [mm]
    and zero offset error [deg] (``j2_height`` as ``j2_height - base_frame_z``, the combination the
    data determines; ``base_frame_z`` is held)."""
    from panasonic_vr006l_support import kinematic_calibration as kc
    truth = kc.nominal_parameters(true_file)
    poses = kc.propose_poses(kc.DEFAULT_POSES if n_poses is None else n_poses, seed=seed)
    pairs = []
    for q in poses:
        shown = [round(float(v), 2) for v in q]
        pose = kc.fk_controller(truth, list(q))
        pairs.append((shown, [round(float(v), 2) for v in pose]))
    result = kc.fit(pairs)
    kc.write_yaml(result, out_path)
    fitted = result.parameters
    length_err: Dict[str, float] = {}
    for name in kc.GEOMETRY:
        if name == "base_frame_z":
            continue
        if name == "j2_height":
            err = (fitted[name] - fitted["base_frame_z"]) - (truth[name] - truth["base_frame_z"])
        else:
            err = fitted[name] - truth[name]
        length_err[name] = abs(err) * 1000.0
    angle_err = {name: abs(math.degrees(fitted[name] - truth[name])) for name in kc.OFFSETS}
    worst_l = max(length_err, key=length_err.get)
    worst_a = max(angle_err, key=angle_err.get)
    before_l = max(abs(result.nominal[n] - truth[n]) * 1000.0 for n in kc.GEOMETRY if n != "base_frame_z")
    before_a = max(abs(math.degrees(result.nominal[n] - truth[n])) for n in kc.OFFSETS)
    return {"path": out_path, "poses": len(pairs), "summary": result.summary(),
            "rms_mm": result.rms_mm, "max_mm": length_err[worst_l], "max_mm_name": worst_l,
            "max_deg": angle_err[worst_a], "max_deg_name": worst_a,
            "model_max_mm": before_l, "model_max_deg": before_a}


class Run:
    """One configuration: the stack is up; send the goals, collect joint_states, compute figures."""

    def __init__(self, rospy: Any, stack: Any, cfg: Dict[str, Any]):
        import actionlib
        from sensor_msgs.msg import JointState

        from vr_driver.msg import FollowJointTrajectoryAction, RobotStatus, TriState
        self.rospy, self.stack, self.cfg = rospy, stack, cfg
        self.TRUE, self.FALSE = TriState.TRUE, TriState.FALSE
        self.chk = Checker()
        self.names = list(self.chk.params.controller_joint_names)
        from std_msgs.msg import String
        self.status = Recorder(rospy, "/robot_status", RobotStatus)
        # the virtual G2's execution log: when it took each target (the goal's start, from send_goal)
        self.executed = Recorder(rospy, "/virtual_controller/executed", String)
        self.joints = Recorder(rospy, "/joint_states", JointState)
        # --true-model: the goals are judged on the arm's true joints, counted from the driver model's
        # zero pose (the true angles less the driver model's zero offsets)
        self.true = (Recorder(rospy, "/virtual_controller/true_joints", JointState)
                     if cfg.get("true_model") else None)
        self.zero = tuple(cfg.get("model_zero") or (0.0,) * 6)
        self.client = actionlib.ActionClient("/joint_trajectory_action", FollowJointTrajectoryAction)
        # the "wrist" set: judged by the driver's band rule, planned with accelerations matched to the
        # arm's ramp -- or, with --commissioning, the model's (before) or the commissioning's (after)
        wrist = cfg.get("set") == "wrist"
        self.wrist = WristRule.of(self.chk.kin) if wrist else None
        self.amax = planner_setup(self.chk, cfg)
        # the virtual arm's accelerations (its ramp_time, else the model's): what bounds how closely
        # any arm could follow a plan (vr_driver.driver.joints.following)
        self.arm_acc = (self.chk.accelerations(cfg["ramp_time"]) if cfg.get("ramp_time")
                        else tuple(self.chk.kin.limits.acceleration))

    def q_of(self, msg: Any) -> Optional[Tuple[float, ...]]:
        try:
            return tuple(msg.position[list(msg.name).index(n)] for n in self.names)
        except (ValueError, IndexError):
            return None

    def true_q(self, msg: Any) -> Optional[Tuple[float, ...]]:
        """The true joints of a ~true_joints message in the driver model's convention."""
        try:
            q = [msg.position[list(msg.name).index("joint_%d" % (i + 1))] for i in range(6)]
        except (ValueError, IndexError):
            return None
        return tuple(a - z for a, z in zip(q, self.zero))

    def crash(self) -> Optional[str]:
        """The exception line of the first traceback in the launch log (a node's thread died: the
        driver will not become ready), else None."""
        lines = self.stack.log_tail("launch.log", 400).splitlines()
        seen = False
        for line in lines:
            if line.startswith("Traceback"):
                seen = True
            elif seen and re.match(r"^[A-Za-z_][\w.]*(Error|Exception|Exit)\b.*", line):
                return line.strip()
        return None

    def alive(self, end: float, what: str) -> None:
        if not self.stack.launch_alive():
            raise Failure("driver.launch exited (%s) %s: %s\n%s" % (
                self.stack.launch.returncode, what, self.crash() or "", self.stack.log_tail("launch.log")))
        crash = self.crash()
        if crash is not None:
            raise Failure("%s: a node failed: %s\n%s" % (what, crash, self.stack.log_tail("launch.log", 12)))
        if time.monotonic() > end:
            raise Failure("%s: timed out\n%s" % (what, self.stack.log_tail("launch.log", 12)))

    def wait_ready(self, timeout: float) -> float:
        t0 = time.monotonic()
        end = t0 + timeout
        while not self.client.wait_for_server(self.rospy.Duration(0.5)):
            self.alive(end, "no joint_trajectory_action server")
        self.wait_idle(end, "motion_possible never TRUE")
        return time.monotonic() - t0

    def wait_idle(self, end: float, what: str) -> None:
        while self.status.wait_for(lambda m: m.motion_possible.val == self.TRUE and m.in_motion.val == self.FALSE,
                                   0.5, max(0, self.status.mark() - 1)) is None:
            self.alive(end, what)

    def current(self) -> Tuple[float, ...]:
        hit = self.joints.wait_for(lambda m: self.q_of(m) is not None, 5.0, max(0, self.joints.mark() - 1))
        if hit is None:
            raise Failure("no joint_states")
        return self.q_of(hit[1])

    def goal(self, plan: Planned, path_tol: float, goal_tol: float) -> Any:
        from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

        from vr_driver.msg import FollowJointTrajectoryGoal, JointTolerance
        traj = JointTrajectory(joint_names=self.names)           # header.stamp 0: start now
        for q, t in zip(plan.points, plan.times_ns):
            traj.points.append(JointTrajectoryPoint(positions=list(q),
                                                    time_from_start=self.rospy.Duration(0, t)))
        goal = FollowJointTrajectoryGoal(trajectory=traj)
        if path_tol:
            goal.path_tolerance = [JointTolerance(name=n, position=path_tol) for n in self.names]
        if goal_tol:
            goal.goal_tolerance = [JointTolerance(name=n, position=goal_tol) for n in self.names]
        return goal

    def send(self, goal: Any, timeout: float) -> Tuple[Optional[int], Any, float, float]:
        """(status or None on timeout, result, send wall time, result wall time). A plain
        ActionClient: SimpleActionClient can miss a fast refusal (ros/actionlib#206)."""
        import actionlib
        done = threading.Event()
        stamp: List[float] = []

        def transition(handle: Any) -> None:
            if handle.get_comm_state() == actionlib.CommState.DONE and not done.is_set():
                stamp.append(time.time())
                done.set()
        t_send = time.time()
        handle = self.client.send_goal(goal, transition_cb=transition)
        if not done.wait(timeout):
            handle.cancel()
            done.wait(15.0)
            return None, None, t_send, time.time()
        return handle.get_goal_status(), handle.get_result(), t_send, stamp[0]

    def reposition(self, target: Sequence[float]) -> str:
        """Take the arm to ``target`` with a slow two-point goal (not measured)."""
        q = self.current()
        need = max(abs(a - b) / v for a, b, v in zip(q, target, self.chk.vmax))
        plan = Planned((tuple(q), tuple(target)), (0, int(math.ceil(need / 0.3 * 1e9)) + 1), (0.3,), ("reposition",))
        status, result, _t0, _t1 = self.send(self.goal(plan, -1.0, math.radians(1.0)), 60.0 + 3 * plan.duration)
        return "reposition: state %s %s" % (status, result.error_string if result is not None else "no result")

    @staticmethod
    def stamped(recorder: Any, mark: int, joints_of: Callable[[Any], Any], t_send: float, t_done: float
                ) -> Tuple[Optional[Tuple[float, ...]], List[Tuple[float, Any]]]:
        """From ``recorder``'s messages since ``mark``: the joints of the first stamped at or after the
        result (``t_done``; None if none came within 2 s) and every (stamp - ``t_send``, joints)."""
        final = None
        hit = recorder.wait_for(lambda m: m.header.stamp.to_sec() >= t_done and joints_of(m) is not None, 2.0, mark)
        if hit is not None:
            final = joints_of(hit[1])
        with recorder.cond:
            msgs = [m for _t, m in recorder.messages[mark:]]
        return final, [(m.header.stamp.to_sec() - t_send, joints_of(m)) for m in msgs if joints_of(m) is not None]

    def one(self, index: int) -> Dict[str, Any]:
        """Trajectory ``index`` (1-based) of the set, made from where the arm is (an arm that
        ended exactly at the previous planned end gets the very trajectory :func:`generate` makes)."""
        from actionlib_msgs.msg import GoalStatus
        rospy = self.rospy
        cfg = self.cfg
        self.wait_idle(time.monotonic() + 30.0, "the arm not idle before trajectory %d" % index)
        q = self.current()
        note = ""
        try:
            plan = generate_one(rng_for(cfg["seed"], index - 1), q, self.chk, timing=cfg["set"], index=index - 1,
                                amax=self.amax, kinds=cfg.get("kinds", ()))
        except RuntimeError:                  # the arm stopped somewhere odd: from home
            note = self.reposition(self.chk.home())
            self.wait_idle(time.monotonic() + 30.0, "the arm not idle after going home")
            plan = generate_one(rng_for(cfg["seed"], index - 1), self.current(), self.chk, timing=cfg["set"],
                                index=index - 1, amax=self.amax, kinds=cfg.get("kinds", ()))
        mark = self.joints.mark()
        true_mark = self.true.mark() if self.true is not None else 0
        exec_mark = self.executed.mark()
        timeout = 30.0 + 4.0 * plan.duration + 1.5 * len(plan.points)
        goal = self.goal(plan, cfg["path_tol"], cfg["goal_tol"])
        mono_send = time.monotonic()
        status, result, t_send, t_done = self.send(goal, timeout)
        final, samples = self.stamped(self.joints, mark, self.q_of, t_send, t_done)
        judged = None
        if self.true is not None:             # judged on the true joints (at their stamps)
            final, judged = self.stamped(self.true, true_mark, self.true_q, t_send, t_done)
        # joint_states are stamped with the time the controller took their record: no age window
        rec = analyse(plan, samples, t_done - t_send, final,
                      min_still(cfg["cycle_rate"], self.chk.params.joint_states_rate), age=0.0, judged=judged,
                      wrist=self.wrist)
        if cfg.get("plot"):
            rec["plot"] = plot_goal(cfg["plot"], cfg["name"], index, plan, samples, rec["lag_s"],
                                    t_done - t_send, "%s goal %d: %s" % (cfg["name"], index, cfg["title"]))
        if cfg.get("dump"):
            with open(cfg["dump"], "a") as fh:
                fh.write(json.dumps({"config": cfg["name"], "index": index, "plan": plan.to_json(),
                                     "samples": samples, "t_result": t_done - t_send, "final": final,
                                     "true_samples": judged}) + "\n")
        rec.update(index=index, points=len(plan.points), legs=list(plan.legs),
                   state=status, state_name=GoalStatus.to_string(status) if status is not None else "NO RESULT",
                   code=result.error_code if result is not None else None,
                   error_string=result.error_string if result is not None else "no result within %.0f s" % timeout,
                   note=note)
        if self.wrist is not None:
            from vr_driver.driver.joints.following import following_floor
            # the least deviation any arm with the virtual arm's accelerations could have from this plan
            floor, where = following_floor(plan.times, plan.points, self.arm_acc, band=self.wrist.band,
                                           sign=self.wrist.sign)
            rec["floor_deg"], rec["floor_where"] = math.degrees(floor), where
        found = DRIVER_DEV.search(rec["error_string"])
        rec["driver_dev_deg"] = float(found.group(1)) if found else None
        rec.update(driver_timing(rec["error_string"]))
        # the goal's start: the controller's log entry of its first target (published at its outcome)
        self.executed.wait_for(lambda m: first_taken([json.loads(m.data)], mono_send) is not None, 2.0, exec_mark)
        with self.executed.cond:
            entries = [json.loads(m.data) for _t, m in self.executed.messages[exec_mark:]]
        rec["first_s"] = first_taken(entries, mono_send)
        rec["ok"] = status == GoalStatus.SUCCEEDED and result is not None and result.error_code == 0
        rec["ran"] = status not in (None, GoalStatus.REJECTED)
        # to the end: succeeded, or only the goal tolerance missed (the figures are of a whole run)
        rec["completed"] = rec["ok"] or (status == GoalStatus.ABORTED and rec["code"] == -5)
        rospy.sleep(3.0 / cfg["cycle_rate"])
        return rec

    def run(self) -> Dict[str, Any]:
        cfg = self.cfg
        ready = self.wait_ready(cfg["ready_timeout"])
        print("ready %.1f s after roslaunch (joint_trajectory_action up, motion_possible TRUE)" % ready, flush=True)
        recs = []
        if self.wrist is not None:
            print("wrist goals: %s; planner's accelerations %s rad/s^2 (%s)"
                  % (self.wrist.words(), "/".join("%.3g" % a for a in self.amax), planner_words(cfg)), flush=True)
        elif cfg.get("planner_limits"):
            print("planner's limits: %s" % planner_words(cfg), flush=True)
        print("%3s %4s %7s %-10s %6s %7s %7s %7s %5s %10s %7s %8s %9s  %s" % (
            "#", "pts", "plan s", "state", "ratio", "margin", "still%", "start s", "stops", "dev deg(J)", "delay",
            "path deg", "final deg", "result"), flush=True)
        refused_in_a_row = 0
        for i in range(cfg["n"]):
            rec = self.one(i + 1)
            recs.append(rec)
            print("%3d %4d %7.2f %-10s %6.2f %+7.2f %7.1f %7s %5d %7.2f(%s) %7.3f %8.2f %9s  %s%s"
                  % (rec["index"], rec["points"], rec["planned"], rec["state_name"], rec["ratio"], rec["margin_s"],
                     rec["still_pct"], "n/a" if rec["start_s"] is None else "%.2f" % rec["start_s"],
                     rec["stops"], rec["dev_deg"], rec.get("sum_name", "") if rec["dev_joint"] == 7 else rec["dev_joint"],
                     rec["lag_s"], rec["path_deg"], "n/a" if rec["final_deg"] is None else "%.3f" % rec["final_deg"],
                     rec["error_string"][:110], " [%s]" % rec["note"] if rec["note"] else ""), flush=True)
            if self.wrist is not None:
                print("    %s [%s]" % (wrist_words(rec, cfg["protocol"]), " / ".join(rec["legs"])), flush=True)
            print("    %s" % start_words(rec), flush=True)
            refused_in_a_row = 0 if rec["ran"] else refused_in_a_row + 1
            if refused_in_a_row >= 2 and not any(r["ran"] for r in recs):
                raise Failure("unsupported: the first goals were refused (%s)" % rec["error_string"])
            if rec["state"] is None and not any(r["ok"] for r in recs):
                raise Failure("unsupported: no result for trajectory %d within the timeout" % rec["index"])
        return {"name": cfg["name"], "protocol": cfg["protocol"], "baud": cfg["baud"], "cycle_rate": cfg["cycle_rate"],
                "goals": recs, "tolerances": cfg["tolerances"], "title": cfg["title"], "set": cfg["set"],
                "true_model": cfg.get("true_model", ""), "model": cfg.get("model", ""),
                "wrist_rule": self.wrist.words() if self.wrist is not None else ""}


def worker(cfg: Dict[str, Any]) -> int:
    def measure(rospy: Any, stack: Any) -> int:
        result = Run(rospy, stack, cfg).run()
        print(RESULT_TAG + json.dumps(result), flush=True)
        return 0

    def failed(exc: BaseException, stack: Any) -> bool:
        what = str(exc) if isinstance(exc, Failure) else "%s: %s" % (type(exc).__name__, exc)
        print("FAILED %s: %s" % (cfg["name"], what), flush=True)
        print(RESULT_TAG + json.dumps({"name": cfg["name"], "failed": what.split("\n")[0] if isinstance(exc, Failure)
                                       else what}), flush=True)
        return cfg.get("keep_logs", False) if isinstance(exc, Failure) else True
    return stack_worker(
        cfg, "vr_traj_bench_", "trajectory_bench",
        "--- %s: %s (ROS master port {port}, speed_factor %g; %s set; tolerances %s; virtual hardware %s)"
        % (cfg["name"], cfg["title"], cfg["speed_factor"], cfg["set"], cfg["tolerances"],
           "at SCHED_FIFO %d where allowed" % cfg["sim_rt_priority"] if cfg.get("sim_rt_priority")
           else "at normal scheduling"),
        launch_args(cfg), measure, failed)


#: SCHED_FIFO priority of the virtual hardware's nodes (driver.launch sim_rt_priority) where allowed:
#: above the driver's bus process (20), as bench/bus_health.py's rig -- the bench runs alone
SIM_RT_PRIORITY = 30


def launch_args(cfg: Dict[str, Any]) -> List[str]:
    """driver.launch's arguments for a configuration (besides sim:=true and sim_port)."""
    args = ["baud:=%d" % cfg["baud"], "cycle_rate:=%g" % cfg["cycle_rate"], "speed_factor:=%g" % cfg["speed_factor"],
            "protocol:=%s" % cfg["protocol"]]
    if cfg.get("paced"):
        args += ["io:=true", "line_baud:=%d" % cfg["baud"]]
    if cfg.get("lookahead") is not None:
        args.append("interpreter_lookahead:=%d" % cfg["lookahead"])
    if cfg.get("ramp_time") is not None:
        args.append("ramp_time:=%g" % cfg["ramp_time"])
    if cfg.get("true_model"):
        args.append("true_model:=%s" % cfg["true_model"])
    if cfg.get("model"):
        args.append("model:=%s" % cfg["model"])
    if cfg.get("commissioning"):
        args.append("commissioning:=%s" % cfg["commissioning"])
    if cfg.get("sim_rt_priority"):
        args.append("sim_rt_priority:=%d" % cfg["sim_rt_priority"])
    return args


def planner_limits(commissioning: str, config: str = CONFIG_FILE) -> Tuple[str, Tuple[float, ...], Tuple[float, ...]]:
    """(the file, max velocity, max acceleration per joint, the controller's order) the planner
    plans with after the commissioning ``commissioning`` (its ``planning_limits``: the
    joint_limits.yaml ``commission`` wrote beside it -- driver.launch's rule -- read as the driver
    reads it, vr_driver.params.read_planning_limits, for the joints of the driver's ``config``).
    ValueError naming the file when it is not a commissioning's."""
    import yaml

    from vr_driver.driver.checks.commissioned import plain_names
    from vr_driver.errors import VrDriverError
    from vr_driver.params import DriverParams, read_planning_limits
    with open(config) as fh:
        params = DriverParams.from_dict(yaml.safe_load(fh) or {})
    with open(commissioning) as fh:
        doc = yaml.safe_load(fh) or {}
    if not isinstance(doc, dict) or "commissioning" not in doc:
        raise ValueError("%s: not a commissioning file (no commissioning: mapping; rosrun vr_driver commission "
                         "--out FILE writes one)" % commissioning)
    beside = os.path.join(os.path.dirname(os.path.abspath(commissioning)), "joint_limits.yaml")
    try:
        velocity, acceleration = read_planning_limits(beside, plain_names(params))
    except VrDriverError as exc:
        raise ValueError("%s: its planner's limits: %s" % (commissioning, exc)) from None
    return beside, tuple(velocity), tuple(acceleration)


def planner_setup(chk: Checker, cfg: Dict[str, Any]) -> Optional[Tuple[float, ...]]:
    """The planner's limits of a configuration, set on ``chk`` (its ``vmax_planner`` and ``amax``:
    every set's timing reads them): the commissioning's (``cfg["planner_limits"]``, --commissioning
    after) or the model's; returns the "wrist" set's accelerations -- the commissioning's, the
    model's (``cfg["unmatched"]``: --commissioning before) or matched to the arm's ``ramp_time`` --
    and None for the other sets (they plan at ``chk.amax``)."""
    if cfg.get("planner_limits"):
        _file, velocity, acceleration = planner_limits(cfg["commissioning"])
        chk.vmax_planner, chk.amax = velocity, acceleration
    if cfg.get("set") != "wrist":
        return None
    if cfg.get("planner_limits") or cfg.get("unmatched"):
        return tuple(chk.amax)
    return chk.accelerations(cfg.get("ramp_time"))


def planner_words(cfg: Dict[str, Any]) -> str:
    """Where a configuration's planner limits come from, in words."""
    if cfg.get("planner_limits"):
        return "the commissioning's, %s" % cfg["planner_limits"]
    if cfg.get("unmatched") or cfg.get("set") != "wrist":
        return "the model's 0.1 s ramp, joint_limits.yaml%s" % (
            " (before the commissioning: not matched to the arm)" if cfg.get("unmatched") else "")
    if cfg.get("ramp_time"):
        return "matched to the arm's %g s ramp" % cfg["ramp_time"]
    return "matched to the model's 0.1 s ramp, joint_limits.yaml"


def title(protocol: str, baud: int, rate: float, paced: bool, lookahead: Optional[int],
          ramp_time: Optional[float] = None) -> str:
    """A configuration in words, e.g. 'v3, 19.2 kbit/s, 20 Hz, paced line + I/O island, look-ahead 1'
    (', ramp 0.5 s' when the virtual arm's ramp is not the model's)."""
    text = "%s, %g kbit/s, %g Hz" % (protocol, baud / 1000.0, rate)
    text += ", paced line + I/O island" if paced else ", pty"
    if lookahead is not None:
        text += ", look-ahead %d" % lookahead
    if ramp_time is not None:
        text += ", ramp %g s%s" % (ramp_time, " (v1's arm: not modelled)" if protocol == "v1" else "")
    return text


# ------------------------------------------------------------------------------------------ parent
def _median(values: Sequence[float]) -> float:
    v = sorted(values)
    n = len(v)
    return v[n // 2] if n % 2 else 0.5 * (v[n // 2 - 1] + v[n // 2])


def _mm(values: Sequence[float], fmt: str = "%.3g") -> str:
    """median / max, or n/a."""
    return (fmt + " / " + fmt) % (_median(values), max(values)) if values else "n/a"


def verdicts(result: Dict[str, Any]) -> List[Tuple[str, Optional[bool]]]:
    """(target, met) of one configuration: every goal SUCCESSFUL, then each of TARGETS on every goal
    run to the end (a deviation per joint: the largest joint of the goal); the "wrist" set: each of
    WRIST_TARGETS, met None (reported, not judged) on v1."""
    goals = result["goals"]
    ran = [g for g in goals if g["completed"]]
    out: List[Tuple[str, Optional[bool]]] = [("all goals SUCCESSFUL", bool(goals) and all(g["ok"] for g in goals))]
    wrist = result.get("set") == "wrist"
    for label, key, limit in (WRIST_TARGETS if wrist else TARGETS):
        if wrist and result.get("protocol") == "v1":
            out.append((label, None))
            continue
        vals = [g[key] for g in ran if g.get(key) is not None]
        out.append((label, bool(vals) and len(vals) == len(goals) and max(vals) <= limit))
    return out


def goal_verdicts(rec: Dict[str, Any], protocol: str) -> List[Tuple[str, Optional[bool]]]:
    """The "wrist" set's judging of one goal: SUCCESSFUL, then each of WRIST_TARGETS (False when the
    goal did not run to the end; None on v1: reported, not judged)."""
    out: List[Tuple[str, Optional[bool]]] = [("SUCCESSFUL", bool(rec["ok"]))]
    for label, key, limit in WRIST_TARGETS:
        value = rec.get(key)
        out.append((label, None if protocol == "v1" else
                    bool(rec["completed"]) and value is not None and value <= limit))
    return out


def beyond_any_arm(rec: Dict[str, Any]) -> bool:
    """Whether the goal's plan asks more than any arm with the virtual arm's accelerations can do for
    the deviation target (its floor, vr_driver.driver.joints.following, above the target)."""
    return rec.get("floor_deg") is not None and rec["floor_deg"] > dict(
        (key, limit) for _label, key, limit in WRIST_TARGETS)["dev_deg"]


def _met(met: Optional[bool]) -> str:
    return "reported (not judged)" if met is None else "met" if met else "NOT met"


def wrist_words(rec: Dict[str, Any], protocol: str) -> str:
    """One goal of the "wrist" set in a line: joint_5 from / nearest 0 / to, the samples judged by
    the sum, the deviation outside the band and the sum's inside it, the final error, the verdicts."""
    j5 = rec.get("j5_deg") or [math.nan] * 3
    return ("wrist: joint_5 %+.1f -> %+.1f deg (nearest 0: %+.2f), %d of %d samples in the band; deviation outside "
            "it %s deg, %s in it %s deg; final %s deg%s; %s%s" % (
                j5[0], j5[2], j5[1], rec.get("band_samples", 0), rec["samples"],
                "%.2f" % max(rec["dev_joints_deg"], default=0.0), rec.get("sum_name", "J4+J6"),
                "n/a" if rec.get("dev_sum_deg") is None else "%.3f" % rec["dev_sum_deg"],
                "n/a" if rec["final_deg"] is None else "%.3f" % rec["final_deg"],
                " (J4 / J6 by their sum)" if rec.get("final_by_sum") else "",
                ", ".join("%s %s" % (label.split(" [")[0], _met(met)) for label, met in goal_verdicts(rec, protocol)),
                "" if rec.get("floor_deg") is None else "; no arm that keeps these accelerations comes closer than %.2f deg "
                "to this plan (%s)%s" % (rec["floor_deg"], rec["floor_where"],
                                         ": the deviation target is beyond any such arm" if beyond_any_arm(rec) else "")))


def _s(value: Optional[float], fmt: str = "%.3f") -> str:
    return "n/a" if value is None else fmt % value


def start_differences(rec: Dict[str, Any]) -> Tuple[Optional[float], Optional[float]]:
    """[s] the bench's figures less the driver's of one goal: the run's time (the time ratios x the
    plan) and the start delay; None where either is missing."""
    ratio = rec.get("driver_ratio")
    time_diff = (rec["ratio"] - ratio) * rec["planned"] if ratio is not None and rec.get("ratio") is not None else None
    delay = rec.get("driver_delay_s")
    delay_diff = rec["lag_s"] - delay if delay is not None and rec.get("lag_s") is not None else None
    return time_diff, delay_diff


def start_words(rec: Dict[str, Any]) -> str:
    """One goal's start in a line: goal sent -> the controller took its first target (the bench's),
    the driver's preparation and first target (from the goal's arrival), and the time and start delay
    as the bench and the driver measured them."""
    time_diff, delay_diff = start_differences(rec)
    return ("start: sent -> the G2 took the first target %s s; the driver: prepared in %s s, first target left %s s "
            "after the goal arrived; time %.3f x plan (driver %s, %s ms apart), start delay %.3f s (driver %s, %s ms "
            "apart)" % (_s(rec.get("first_s")), _s(rec.get("driver_prep_s")), _s(rec.get("driver_first_s")),
                        rec["ratio"], _s(rec.get("driver_ratio"), "%.2f"),
                        _s(None if time_diff is None else 1e3 * time_diff, "%+.0f"), rec["lag_s"],
                        _s(rec.get("driver_delay_s")), _s(None if delay_diff is None else 1e3 * delay_diff, "%+.0f")))


def start_summary(results: List[Dict[str, Any]]) -> None:
    """How soon the goals moved (Markdown): per configuration, goal sent -> the controller took the
    first target (median / p95 / max over the goals), the driver's preparation and first target
    (median / max), and how far the bench's time and start delay are from the driver's (largest)."""
    print("\ngoal start (issue 46: median <= %.2f s, p95 <= %.2f s from the goal to its first target; the driver's "
          "figures within one bus cycle of the bench's):" % (START_MEDIAN, START_P95))
    head = ("configuration", "sent -> G2 took the first target, median / p95 / max [s]",
            "driver: prepared in [s]", "driver: first target left [s]", "time, bench - driver, largest [ms]",
            "start delay, bench - driver, largest [ms]", "bus cycle [ms]", "target")
    print("| " + " | ".join(head) + " |")
    print("|" + " --- |" * len(head))
    for r in results:
        if "failed" in r:
            continue
        goals = r["goals"]
        first = [g["first_s"] for g in goals if g.get("first_s") is not None]
        diffs = [start_differences(g) for g in goals if g["completed"]]
        tdiff = [abs(d[0]) for d in diffs if d[0] is not None]
        ddiff = [abs(d[1]) for d in diffs if d[1] is not None]
        met = bool(first) and len(first) == len(goals) and _median(first) <= START_MEDIAN \
            and percentile(first, 0.95) <= START_P95
        print("| %s | %s / %s / %s | %s | %s | %s | %s | %.0f | %s |" % (
            r["title"], _s(_median(first) if first else None), _s(percentile(first, 0.95) if first else None),
            _s(max(first) if first else None),
            _mm([g["driver_prep_s"] for g in goals if g.get("driver_prep_s") is not None], "%.3f"),
            _mm([g["driver_first_s"] for g in goals if g.get("driver_first_s") is not None], "%.3f"),
            _s(1e3 * max(tdiff) if tdiff else None, "%.0f"), _s(1e3 * max(ddiff) if ddiff else None, "%.0f"),
            1e3 / r["cycle_rate"], "met" if met else "NOT met"))


def summary(results: List[Dict[str, Any]]) -> None:
    """The figures per configuration as Markdown tables (median / max over the goals run to the end,
    that is succeeded or missed only the goal tolerance), then the targets met or not."""
    print("=== summary: median / max over the goals run to the end (succeeded, or missed only the goal "
          "tolerance); time margin = time - (%.2f x plan + %.1f s); deviation from the plan at the same time "
          "(joint_states header stamps%s) less the fitted start delay"
          % (TIME_FACTOR, TIME_SLACK, "; deviation, distance to the path and final error: the TRUE joints, "
             "/virtual_controller/true_joints" if any(r.get("true_model") for r in results) else ""))
    head = ("configuration", "goals SUCCESSFUL", "time / plan", "time margin [s]", "standing still [%]", "stops",
            "deviation [deg]", "start delay [s]", "driver's own [deg]", "deviation at send [deg]",
            "distance to the path [deg]", "final error [deg]")
    print("| " + " | ".join(head) + " |")
    print("|" + " --- |" * len(head))
    rows_j = []
    for r in results:
        if "failed" in r:
            print("| %s | FAILED: %s |" % (r["name"], r["failed"][:160]) + " |" * (len(head) - 2))
            continue
        goals = r["goals"]
        ran = [g for g in goals if g["completed"]]

        def vals(key: str) -> List[float]:
            return [g[key] for g in ran if g.get(key) is not None]
        print("| %s | %d / %d | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s |" % (
            r["title"], sum(1 for g in goals if g["ok"]), len(goals), _mm(vals("ratio"), "%.2f"),
            _mm(vals("margin_s"), "%+.2f"), _mm(vals("still_pct"), "%.1f"), _mm(vals("stops"), "%g"),
            _mm(vals("dev_deg"), "%.2f"), _mm(vals("lag_s"), "%.3f"), _mm(vals("driver_dev_deg"), "%.2f"),
            _mm(vals("dev_send_deg"), "%.2f"), _mm(vals("path_deg"), "%.2f"), _mm(vals("final_deg"), "%.3f")))
        per_joint = [[g["dev_joints_deg"][j] for g in ran if g.get("dev_joints_deg")] for j in range(6)]
        rows_j.append("| %s | %s |" % (r["title"], " | ".join(_mm(v, "%.2f") for v in per_joint)))
    wrist = any(r.get("set") == "wrist" for r in results)
    if not wrist:
        print("| **target** (v3, 19.2 kbit/s paced, I/O island, look-ahead >= 1) | all | | <= 0 | <= 5 | | <= 0.5 "
              "per joint | | | | | <= 0.05 |")
    if rows_j:
        print("\ndeviation from the plan at the same time per joint [deg], median / max over the goals (target <= 0.5%s):"
              % ("; J4 and J6 outside the wrist band" if wrist else ""))
        print("| configuration | J1 | J2 | J3 | J4 | J5 | J6 |")
        print("|" + " --- |" * 7)
        for row in rows_j:
            print(row)
    if wrist:
        wrist_summary(results)
    start_summary(results)
    print()
    for r in results:
        if "failed" in r:
            print("%s: FAILED / unsupported: %s" % (r["name"], r["failed"]))
            continue
        print("%s against the targets (every goal): %s" % (
            r["name"], ", ".join("%s %s" % (label, _met(met)) for label, met in verdicts(r))))
        beyond = [g for g in r["goals"] if beyond_any_arm(g)]
        if beyond:
            print("  beyond any arm that keeps the virtual arm's accelerations (vr_driver.driver.joints.following; the "
                  "virtual arm itself exceeds them in blends and moves shorter than its ramp): %s" % "; ".join(
                "goal %d no closer than %.2f deg (%s), measured %.2f by joint_states' samples (which may miss the "
                "moment)" % (g["index"], g["floor_deg"], g["floor_where"], g["dev_deg"]) for g in beyond))


def wrist_summary(results: List[Dict[str, Any]]) -> None:
    """The "wrist" set's table (Markdown): per configuration, median / max over the goals run to the
    end, the figures the targets judge by the band rule, and the targets' row."""
    rule = next((r.get("wrist_rule") for r in results if r.get("wrist_rule")), "")
    print("\nwrist goals (across and onto joint_5 = 0), judged with %s; v1: every goal SUCCESSFUL judged, the rest "
          "reported:" % (rule or "the driver's wrist band"))
    head = ("configuration", "goals SUCCESSFUL", "time margin [s]", "deviation, band rule [deg]",
            "outside the band, largest joint [deg]", "sum in the band [deg]", "samples in the band",
            "final error, band rule [deg]", "driver's own [deg]")
    print("| " + " | ".join(head) + " |")
    print("|" + " --- |" * len(head))
    for r in results:
        if "failed" in r:
            print("| %s | FAILED: %s |" % (r["name"], r["failed"][:160]) + " |" * (len(head) - 2))
            continue
        goals = r["goals"]
        ran = [g for g in goals if g["completed"]]

        def vals(key: str) -> List[float]:
            return [g[key] for g in ran if g.get(key) is not None]
        print("| %s | %d / %d | %s | %s | %s | %s | %d of %d | %s | %s |" % (
            r["title"], sum(1 for g in goals if g["ok"]), len(goals), _mm(vals("margin_s"), "%+.2f"),
            _mm(vals("dev_deg"), "%.2f"), _mm([max(g["dev_joints_deg"]) for g in ran if g.get("dev_joints_deg")], "%.2f"),
            _mm(vals("dev_sum_deg"), "%.3f"), sum(g.get("band_samples", 0) for g in ran), sum(g["samples"] for g in ran),
            _mm(vals("final_deg"), "%.3f"), _mm(vals("driver_dev_deg"), "%.2f")))
    print("| **target** (v3 19.2 kbit/s paced + island, look-ahead 1, ramp 0.1 and 0.5 s; v2; v1 SUCCESSFUL only) "
          "| all | <= 0 | <= 0.5 | | | | <= 0.05 | |")


def run_worker(cfg: Dict[str, Any]) -> Tuple[int, Optional[Dict[str, Any]]]:
    """One configuration in a worker process (driver_latency's runner: own session, Ctrl-C passed on
    once, output relayed); (exit status, result)."""
    return driver_latency.run_worker(cfg, __file__, RESULT_TAG)


def main(argv: Optional[List[str]] = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--worker"]:
        return worker(json.loads(argv[1]))
    sigs = [signal.SIGTERM, signal.SIGHUP]
    if signal.getsignal(signal.SIGINT) is not signal.SIG_IGN:
        sigs.append(signal.SIGINT)
    interrupt_once(sigs)
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--n", type=int, default=3, help="trajectories per configuration (default 3)")
    p.add_argument("--seed", type=int, default=1, help="the trajectories' seed (default 1)")
    p.add_argument("--configs", default="",
                   help="comma-separated subset of %s (default: %s; --set wrist: %s)"
                        % (", ".join(CONFIGS), ",".join(DEFAULT_CONFIGS), ",".join(WRIST_CONFIGS)))
    p.add_argument("--set", choices=TIMINGS, default="topp",
                   help="trajectories: topp = time-optimal under MoveIt's velocity and acceleration limits, "
                        "resampled every %g s, goals with empty tolerances (default); dense = 10-100 points at "
                        "cruise fractions, v1 goals with %g deg tolerances; wrist = goals across and onto "
                        "joint_5 = 0, timed as topp with the accelerations matched to the arm's ramp, judged "
                        "with joint_4 / joint_6 by their sum near joint_5 = 0" % (RESAMPLE_DT, V1_TOLERANCE))
    p.add_argument("--kinds", default="", metavar="K,K,...",
                   help="the wrist set's goals, cycled: cross, near, on, end (across joint_5 = 0 to within %g deg "
                        "of it); default %s" % (WRIST_END, ",".join(WRIST_KINDS)))
    p.add_argument("--plot", default="", metavar="DIR",
                   help="draw each goal's planned and executed joints over time into DIR/<config>_<goal>.png")
    p.add_argument("--speed-factor", type=float, default=1.0,
                   help="virtual controller motion time divisor (default 1: real time)")
    p.add_argument("--path-tolerance", type=float, default=None,
                   help="path tolerance per joint in the goals [deg]; 0: none given (the driver's default, "
                        "as MoveIt sends them), negative: no limit (default: none given; --set dense: v1 %g)"
                        % V1_TOLERANCE)
    p.add_argument("--goal-tolerance", type=float, default=None,
                   help="goal tolerance per joint [deg]; 0: none given (default: none given; --set dense: v1 %g)"
                        % V1_TOLERANCE)
    p.add_argument("--ready-timeout", type=float, default=60.0, help="driver ready within [s] (default 60)")
    p.add_argument("--sim-rt-priority", type=int, default=SIM_RT_PRIORITY, metavar="N",
                   help="SCHED_FIFO priority of the virtual G2, line and island where the system allows it "
                        "(driver.launch sim_rt_priority:=; default %(default)s, above the driver's bus process: a "
                        "real G2 is never late, and the bench measures the driver, not the simulator starved "
                        "by its neighbours; 0: normal scheduling)")
    p.add_argument("--ros-port", type=int, default=0, help="ROS master port (default: a free one from 11700)")
    p.add_argument("--keep-logs", action="store_true", help="keep the ROS logs and print where")
    p.add_argument("--dump", default="", help="append each goal's plan and joint_states samples to this file "
                                               "(JSON lines: config, index, plan, samples [t, joints], t_result)")
    p.add_argument("--quick", action="store_true", help="smoke run: 1 trajectory per configuration")
    p.add_argument("--paced", action="store_true",
                   help="every configuration on the paced line (the *-paced ones always are): the virtual line "
                        "carries its bytes at the configuration's bit rate (driver.launch line_baud:=), so a "
                        "record takes its real wire time (a 72-byte v2 exchange ~95 ms at 19.2 kbit/s)")
    p.add_argument("--true-model", default="", metavar="FILE",
                   help="the virtual G2 is the robot of FILE (driver.launch true_model:=; e.g. "
                        "vr_driver/test/data/true_model_example.yaml); the goals are judged on its true joints "
                        "(/virtual_controller/true_joints) instead of joint_states")
    p.add_argument("--calibrate", action="store_true",
                   help="with --true-model: then simulate the pendant calibration session, fit, and run every "
                        "configuration again with the driver's model:= the fitted YAML; print before / after")
    p.add_argument("--commissioning", default="", metavar="FILE",
                   help="the file `rosrun vr_driver commission --out FILE` wrote (the joint_limits.yaml beside it): "
                        "every configuration before the commissioning (the driver without it, the planner at the "
                        "model's limits, the wrist set's accelerations not matched to the arm) and after "
                        "(driver.launch commissioning:=FILE, the planner at its limits); print before / after")
    args = p.parse_args(argv)
    if args.calibrate and not args.true_model:
        p.error("--calibrate needs --true-model")
    if args.commissioning:
        if args.calibrate:
            p.error("--commissioning and --calibrate: one before / after at a time")
        if not os.path.isfile(args.commissioning):
            p.error("--commissioning: no such file %s" % args.commissioning)
        args.commissioning = os.path.abspath(args.commissioning)
        try:
            planner_limits(args.commissioning)
        except (ValueError, OSError) as exc:
            p.error("--commissioning: %s" % exc)
    if args.true_model:
        if not os.path.isfile(args.true_model):
            p.error("--true-model: no such file %s" % args.true_model)
        args.true_model = os.path.abspath(args.true_model)
    if args.quick:
        args.n = 1
    names = [c.strip() for c in (args.configs or ",".join(WRIST_CONFIGS if args.set == "wrist" else DEFAULT_CONFIGS)
                                 ).split(",") if c.strip()]
    bad = [c for c in names if c not in CONFIGS]
    if bad or not names:
        p.error("unknown configuration(s) %s (known: %s)" % (", ".join(bad), ", ".join(CONFIGS)))
    if args.n < 1:
        p.error("--n must be >= 1")
    kinds = tuple(k.strip() for k in args.kinds.split(",") if k.strip())
    if kinds and args.set != "wrist":
        p.error("--kinds: the wrist set's (--set wrist)")
    if any(k not in WRIST_KIND_NAMES for k in kinds):
        p.error("--kinds: each one of %s" % ", ".join(WRIST_KIND_NAMES))
    args.kinds = kinds or WRIST_KINDS
    if not 0 <= args.sim_rt_priority <= 99:
        p.error("--sim-rt-priority: 0 (normal scheduling) or 1..99")
    started = time.perf_counter()
    plans = generate(args.seed, args.n, timing=args.set, kinds=args.kinds)
    print("trajectory benchmark: %d trajectories per configuration (%s set, seed %d: %s points, %s s planned%s), "
          "configurations %s; each with its own roscore + driver.launch sim:=true"
          % (args.n, args.set, args.seed, "/".join(str(len(t.points)) for t in plans),
             "/".join("%.2f" % t.duration for t in plans),
             "; goals %s at the model's ramp (a ramp_time configuration: the same paths, timed with the planner's "
             "accelerations matched to it)" % "/".join(args.kinds[i % len(args.kinds)] for i in range(args.n))
             if args.set == "wrist" else "", ", ".join(names)), flush=True)
    status, results = run_all(args, names, title_note="", model="",
                              stage="before" if args.commissioning else "")
    if status == 130:
        return 130
    summary(results)
    if args.commissioning:
        print("=== after the commissioning: driver.launch commissioning:=%s, the planner at %s"
              % (args.commissioning, planner_limits(args.commissioning)[0]),
              flush=True)
        code, after = run_all(args, names, title_note="", model="", stage="after")
        if code == 130:
            return 130
        status = status or code
        summary(after)
        compare_commissioning(results, after)
    if args.calibrate:
        import tempfile
        out = os.path.join(tempfile.mkdtemp(prefix="vr_traj_calib_"), "kinematics_fitted.yaml")
        calib = simulate_calibration(args.true_model, out)
        print("=== simulated calibration: %d poses read at the pendant of the true robot %s, fitted from the "
              "package's model, written to %s" % (calib["poses"], args.true_model, out))
        print(calib["summary"])
        print("the package's model vs the true file: up to %.3f mm / %.4f deg; fitted: up to %.4f mm (%s) / "
              "%.5f deg (%s)" % (calib["model_max_mm"], calib["model_max_deg"], calib["max_mm"],
                                 calib["max_mm_name"], calib["max_deg"], calib["max_deg_name"]), flush=True)
        code, after = run_all(args, names, title_note=" (driver model: the fitted YAML)", model=out)
        if code == 130:
            return 130
        status = status or code
        summary(after)
        compare(results, after, calib)
    print("python %s, %d CPUs, load %.2f, wall time %.1f s%s"
          % (sys.version.split()[0], os.cpu_count() or 0, os.getloadavg()[0], time.perf_counter() - started,
             "; a configuration FAILED (see above)" if status else ""))
    return status


def run_all(args: Any, names: Sequence[str], title_note: str, model: str, stage: str = ""
            ) -> Tuple[int, List[Dict[str, Any]]]:
    """Every configuration of ``names`` in its worker, the driver's ``model`` "" (the package's) or a
    YAML; ``stage`` (--commissioning) "before" or "after" the commissioning of
    ``args.commissioning`` (:func:`planner_setup`); (exit status: 0, 1 a configuration failed, 130
    interrupted; the results)."""
    def tol(deg: Optional[float], protocol: str) -> float:
        if deg is None:
            deg = V1_TOLERANCE if protocol == "v1" and args.set == "dense" else 0.0
        return -1.0 if deg < 0 else math.radians(deg)

    def shown(value: float) -> str:
        return "none" if value < 0 else "default" if value == 0 else "%g" % math.degrees(value)
    results, status = [], 0
    zero = list(model_zero_offsets(model)) if args.true_model else None
    for name in names:
        protocol, baud, rate, opts = CONFIGS[name]
        paced = bool(args.paced or opts.get("paced"))
        cfg = {"name": name, "protocol": protocol, "baud": baud, "cycle_rate": rate, "n": args.n, "seed": args.seed,
               "speed_factor": args.speed_factor, "path_tol": tol(args.path_tolerance, protocol),
               "goal_tol": tol(args.goal_tolerance, protocol), "ready_timeout": args.ready_timeout,
               "ros_port": args.ros_port, "keep_logs": args.keep_logs, "paced": paced,
               "lookahead": opts.get("lookahead"), "ramp_time": opts.get("ramp_time"), "set": args.set,
               "title": title(protocol, baud, rate, paced, opts.get("lookahead"), opts.get("ramp_time")),
               "plot": os.path.abspath(args.plot) if args.plot else "",
               "dump": os.path.abspath(args.dump) if args.dump else "",
               "true_model": args.true_model, "model": model, "model_zero": zero,
               "sim_rt_priority": args.sim_rt_priority, "kinds": list(args.kinds)}
        if args.true_model:
            cfg["title"] += ", true robot %s%s" % (os.path.basename(args.true_model), title_note)
        if stage == "before":
            cfg["unmatched"] = True
            cfg["title"] += ", before commissioning (planner at the model's limits)"
        elif stage == "after":
            cfg["commissioning"] = args.commissioning
            cfg["planner_limits"] = planner_limits(args.commissioning)[0]
            cfg["title"] += ", commissioned (driver and planner from %s)" % os.path.basename(args.commissioning)
        cfg["tolerances"] = "path %s, goal %s" % (shown(cfg["path_tol"]), shown(cfg["goal_tol"]))
        code, result = run_worker(cfg)
        if code == 130:
            print("interrupted")
            return 130, results
        if result is None:
            result = {"name": name, "failed": "the worker exited with status %d and no result" % code}
        if code != 0 or "failed" in result:
            status = 1
        results.append(result)
    return status, results


def _completed(r: Dict[str, Any], key: str) -> List[float]:
    """``key`` of every goal of configuration result ``r`` run to the end (that has it)."""
    return [g[key] for g in r.get("goals", []) if g["completed"] and g.get(key) is not None]


def _successful(r: Dict[str, Any]) -> str:
    """"k / n" goals SUCCESSFUL of configuration result ``r``, or FAILED when it did not run."""
    if "failed" in r:
        return "FAILED"
    return "%d / %d" % (sum(1 for g in r["goals"] if g["ok"]), len(r["goals"]))


def compare_commissioning(before: List[Dict[str, Any]], after: List[Dict[str, Any]]) -> None:
    """The before / after commissioning table (Markdown), per configuration: goals SUCCESSFUL, the
    time margin, the deviation from the plan at the same time, the driver's own figure and the
    final error (median / max over the goals run to the end; the "wrist" set by its band rule)."""
    print("=== before / after the commissioning (median / max over the goals run to the end; time margin = time - "
          "(%.2f x plan + %.1f s))" % (TIME_FACTOR, TIME_SLACK))
    head = ("configuration", "goals SUCCESSFUL before → after", "plan [s] before", "plan [s] after",
            "time margin before [s]", "time margin after [s]", "deviation before [deg]", "deviation after [deg]",
            "driver's own before [deg]", "driver's own after [deg]", "final error before [deg]",
            "final error after [deg]")
    print("| " + " | ".join(head) + " |")
    print("|" + " --- |" * len(head))
    by_name = {r["name"]: r for r in after}
    for b in before:
        a = by_name.get(b["name"], {"failed": "not run"})
        vals, ok = _completed, _successful
        print("| %s | %s → %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s |" % (
            b["name"], ok(b), ok(a), _mm(vals(b, "planned"), "%.2f"), _mm(vals(a, "planned"), "%.2f"),
            _mm(vals(b, "margin_s"), "%+.2f"), _mm(vals(a, "margin_s"), "%+.2f"),
            _mm(vals(b, "dev_deg"), "%.2f"), _mm(vals(a, "dev_deg"), "%.2f"),
            _mm(vals(b, "driver_dev_deg"), "%.2f"), _mm(vals(a, "driver_dev_deg"), "%.2f"),
            _mm(vals(b, "final_deg"), "%.3f"), _mm(vals(a, "final_deg"), "%.3f")))


def compare(before: List[Dict[str, Any]], after: List[Dict[str, Any]], calib: Dict[str, Any]) -> None:
    """The before / after calibration table (Markdown), per configuration: the deviation from the
    plan of the TRUE joints (median / max over the goals run to the end) and their final error, with
    the package's model and with the fitted one."""
    print("=== before / after calibration: the true joints vs the plan (median / max over the goals run to the end); "
          "parameters: the package's model up to %.2f mm / %.3f deg from the true file, the fitted one up to "
          "%.4f mm / %.5f deg" % (calib["model_max_mm"], calib["model_max_deg"], calib["max_mm"], calib["max_deg"]))
    head = ("configuration", "goals SUCCESSFUL before → after", "deviation before [deg]", "deviation after [deg]",
            "distance to the path before [deg]", "distance to the path after [deg]",
            "final error before [deg]", "final error after [deg]", "fitted parameters' largest error")
    print("| " + " | ".join(head) + " |")
    print("|" + " --- |" * len(head))
    by_name = {r["name"]: r for r in after}
    for b in before:
        a = by_name.get(b["name"], {"failed": "not run"})
        vals, ok = _completed, _successful
        print("| %s | %s → %s | %s | %s | %s | %s | %s | %s | %.4f mm / %.5f deg |" % (
            b["name"], ok(b), ok(a), _mm(vals(b, "dev_deg"), "%.3f"), _mm(vals(a, "dev_deg"), "%.3f"),
            _mm(vals(b, "path_deg"), "%.3f"), _mm(vals(a, "path_deg"), "%.3f"),
            _mm(vals(b, "final_deg"), "%.3f"), _mm(vals(a, "final_deg"), "%.3f"), calib["max_mm"], calib["max_deg"]))


if __name__ == "__main__":
    sys.exit(main())
