#!/usr/bin/python3
"""Collision-aware planning in the example cell (printed, never asserted).

    scripts/env python3 bench/planning.py [--n 100] [--seed 1] [--budget 1.0] [--planner RRTConnect]
                                          [--velocity-scaling 1.0] [--ramp-time S]
                                          [--no-execute] [--protocol v2] [--driver] [--quick]
                                          [--cell PATH] [--peer] [--per-query] [--dump PATH]

The VR-006L (support package's xacro, moveit_config's SRDF) in the example cell
(panasonic_vr006l_support/config/cell_example.yaml: table, pillar, shelf), collision padding the
driver's (``collision_padding``, 10 mm; the planner keeps its clearance, 10 mm, on top). N
queries, chained: the first starts at the arm's home, each next one where the previous one ended.
Each goal is a random configuration free with the padding (uniform within the joint limits,
joint_5 within +-100 deg: the wrist folds onto itself between 105 and 255 deg, which cuts the free
space into parts no path joins -- a query between two of them has no answer for any planner);
every other query asks for it as a pose (the controller pose of its TCP, mm / deg: the planner
solves every IK branch and takes the nearest collision-free one), the others as joints.

Each query: kinematics.planner.Planner.plan (OMPL RRTConnect, shortcutting and smoothing, TOPP-RA at
the full speed and acceleration limits (``--velocity-scaling``, default 1: the plan action's
default is 0.1, this bench asks for the full speed explicitly), samples every 0.05 s, every sample and chord re-checked),
the time of the whole call; then, independently of the planner, every sample and every straight
chord between two samples (0.25 deg steps) checked with a CollisionChecker of the true shapes
(padding 0: collisions) and with the padded one (inside the padding).

``--cell PATH``: another cell (default the example cell). In ``bench/cells/hood_post.yaml`` (a hood
on the table, open towards the robot, and a post) every other pair of goals lies inside the hood
(:data:`GOAL_REGIONS`: a random TCP pose there, a free IK solution of it), so that each query goes in
or out of it: a detour around its walls and under its top; still every other goal a pose goal.

``--peer``: an independent compiled planner answers the same queries in the same run
(bench/planning_peer.py: mplib, OMPL's RRTConnect on FCL in C++, its own IK and TOPP-RA; in the venv
``.ws/peers-planning`` that ``scripts/setup --bench-peers`` makes, which this bench runs when the
venv is missing; never used by the driver): from the same start to the same goal, the same budget,
its time measured inside its own process; figures per goal kind, ours / the peer's, printed.

``--per-query``: a line per query -- its call, its path duration against the straight joint move
from its start to the plan's end timed as the planner times one (what no path between the two can
undercut), the holds (the elbow crossing's), the path's vertices, the tries and why they were made
again. ``--dump PATH``: the queries as JSON lines (index, kind, start and goal joints, seed,
duration), to replay one alone from the start it had in this run.

Execution (unless --no-execute): each plan, validated as joint_trajectory_action validates it
(driver.motion.trajectories.validate from the arm's reported joints, segment_speeds), runs on the in-memory
driver rig of the tests (vr_driver/test/driver/_world.py: DriverCore with the cell as its scene --
it checks every sample and chord itself and refuses a path that collides --, our DP master, the
virtual controller's slave, program and simulated arm, one fake clock; ``--protocol v2`` joint
targets streamed on the plan's timing by default; its workspace box widened to the arm's whole
reach, ``REACH_BOX``, as the driver's default box is an envelope of its own); every tick of the
fake clock the driver's reported joints (what joint_states publishes) and the simulated arm's own
joints are checked for collisions (true shapes). The next query starts from the reported joints.

``--ramp-time S``: an arm that reaches full speed in S seconds (the simulated arm's ``ramp_time``, an
older controller's 0.5 s for example) and the planner matched to it, as the commissioning sets it:
each joint's acceleration limit its speed limit / S, written to a ``joint_limits.yaml`` that the
plan action reads (``planning_limits``) and the bare planner plans with.

Figures: success rate (a plan) and success within the budget (the whole call <= --budget),
median / p95 / max planning time (the whole call, its process time, and the OMPL part alone), the
share of queries the straight move solved, path duration (median / p95), collisions of the planned
samples and chords, and in execution: runs that succeeded, samples checked, collisions. --quick:
N = 10.
"""
from __future__ import annotations

import argparse
import math
import os
import random
import statistics
import subprocess
import sys
import tempfile
import time

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
for _pkg in ("vr_driver", "panasonic_vr006l_support", "pyprofibus_vendor"):
    _src = os.path.join(REPO, _pkg, "src")
    if _src not in sys.path:
        sys.path.insert(0, _src)

from vr_driver.errors import MissingDependency  # noqa: E402
from vr_driver.params import DriverParams  # noqa: E402

CELL = os.path.join(REPO, "panasonic_vr006l_support", "config", "cell_example.yaml")
#: the cells whose goals alternate in pairs between a region and the rest of the cell: (TCP x, y, z
#: ranges [mm] in ``base``, Ry range [deg]; Rx and Rz within +-30 deg) -- inside the hood
GOAL_REGIONS = {"hood_post.yaml": ((850.0, 1050.0), (250.0, 650.0), (420.0, 700.0), (30.0, 90.0))}
#: the venv of the peer planner (scripts/setup --bench-peers) and its answering script
PEER_VENV = os.path.join(os.environ.get("VR_WS", os.path.join(REPO, ".ws")), "peers-planning")
PEER_SCRIPT = os.path.join(REPO, "bench", "planning_peer.py")
#: joint_5 stays within this (deg): the part of the free space home is in (module text)
WRIST_FOLD = 100.0
#: the rig's workspace box (mm, deg): the arm's whole reach. The driver's default box (vr_driver.yaml,
#: X 100..1400, Y -900..900, Z 0..1400 mm) is a safety envelope of its own that random motions in the
#: cell leave (behind the robot, under the table's height); the bench measures collisions, not that
REACH_BOX = {"x": [-2000.0, 2000.0], "y": [-2000.0, 2000.0], "z": [-1000.0, 2500.0], "angle": [-180.0, 180.0]}
#: [rad] the largest joint step when a chord between two samples is checked
CHORD_STEP = math.radians(0.25)


def percentile(values, p):
    s = sorted(values)
    if not s:
        return float("nan")
    return s[min(len(s) - 1, max(0, int(math.ceil(p / 100.0 * len(s))) - 1))]


def random_free(kin, checker, rng):
    while True:
        q = kin.random_joints(rng)
        if abs(q[4]) <= math.radians(WRIST_FOLD) and not checker.in_collision(q):
            return q


def region_free(kin, checker, rng, region):
    """A free configuration (joint_5 within WRIST_FOLD) whose TCP is a random pose in ``region``
    (GOAL_REGIONS): a free IK solution of it, at random."""
    from vr_driver.errors import KinematicsError
    from vr_driver.poses import ControllerPose
    (x0, x1), (y0, y1), (z0, z1), (r0, r1) = region
    lim = kin.limits
    while True:
        pose = ControllerPose(rng.uniform(x0, x1), rng.uniform(y0, y1), rng.uniform(z0, z1),
                              rng.uniform(-30.0, 30.0), rng.uniform(r0, r1), rng.uniform(-30.0, 30.0))
        try:
            sols = kin.ik_solutions(kin.conventions.controller_to_tip(pose))
        except KinematicsError:
            continue
        sols = [tuple(q) for q in sols if abs(q[4]) <= math.radians(WRIST_FOLD) and not checker.in_collision(q)
                and all(lo <= v <= hi for v, lo, hi in zip(q, lim.lower, lim.upper))]
        if sols:
            return sols[rng.randrange(len(sols))]


class Peer:
    """The peer planner in its own process (bench/planning_peer.py in PEER_VENV): :meth:`plan` sends
    one query, returns its answer (ok, time [s] of its whole call, duration [s])."""

    def __init__(self, kin, scene, padding, budget, dt, vs):
        import json
        python = os.path.join(PEER_VENV, "bin", "python3")
        if subprocess.run([python, "-c", "import mplib"], capture_output=True).returncode if os.path.exists(python) \
                else True:
            subprocess.run([os.path.join(REPO, "scripts", "setup"), "--quiet", "--no-build", "--bench-peers"],
                           check=True)
        from panasonic_vr006l_support.description import default_xacro_path, render_urdf
        self._tmp = tempfile.TemporaryDirectory(prefix="planning_peer_")
        urdf = os.path.join(self._tmp.name, "vr006l.urdf")
        with open(urdf, "w") as f:
            f.write(render_urdf(default_xacro_path()))
        self._json = json
        self.proc = subprocess.Popen([python, PEER_SCRIPT], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        objects = [{"name": o.name, "shape": o.shape, "size": list(o.size), "position": list(o.position),
                    "quaternion": list(o.quaternion)} for o in scene.objects()]
        ready = self._ask({"urdf": urdf, "objects": objects, "padding": padding, "budget": budget, "dt": dt,
                           "srdf": os.path.join(REPO, "panasonic_vr006l_moveit_config", "config",
                                                "panasonic_vr006l.srdf"),
                           "velocity": [v * vs for v in kin.limits.velocity],
                           "acceleration": [a * vs for a in kin.limits.acceleration]})
        self.version = ready.get("version", "?")

    def _ask(self, message):
        self.proc.stdin.write(self._json.dumps(message) + "\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError("the peer planner ended (exit %s)" % self.proc.wait())
        return self._json.loads(line)

    def plan(self, start, goal_joints, goal_tip=None):
        message = {"start": list(start)}
        if goal_tip is not None:
            message["pose"] = [list(map(float, row)) for row in goal_tip]
        else:
            message["joints"] = list(goal_joints)
        return self._ask(message)

    def close(self):
        self.proc.stdin.close()
        self.proc.wait(timeout=10)
        self._tmp.cleanup()


def chord_collisions(checker, positions):
    """(samples or chord points in collision, the first one's contacts as text)."""
    hits, first = 0, ""
    for k, q in enumerate(positions):
        pts = [q]
        if k:
            a = positions[k - 1]
            n = max(1, int(math.ceil(max(abs(x - y) for x, y in zip(a, q)) / CHORD_STEP)))
            pts = [tuple(x + (y - x) * j / n for x, y in zip(a, q)) for j in range(1, n + 1)]
        for p in pts:
            if checker.in_collision(p):
                hits += 1
                if not first:
                    first = "; ".join(str(c) for c in checker.contacts(p))
    return hits, first


class Executor:
    """The in-memory driver rig; :meth:`run` executes one plan and checks every tick's joints."""

    def __init__(self, kin, checker, protocol, ramp_time=None, planning_limits="", cell=CELL):
        sys.path.insert(0, os.path.join(REPO, "vr_driver", "test", "driver"))
        from _world import World
        params = {"workspace": REACH_BOX, "scene": cell}
        if planning_limits:
            params["planning_limits"] = planning_limits
        self.world = World(kin, params, protocol=protocol, ramp_time=ramp_time)
        self.world.ready()
        self.kin, self.checker = kin, checker
        self.samples = self.collisions = 0
        self.first = ""

    @property
    def joints(self):
        return tuple(self.world.status().joints)

    def check(self, q, what):
        self.samples += 1
        if self.checker.in_collision(q):
            self.collisions += 1
            if not self.first:
                self.first = "%s: %s" % (what, "; ".join(str(c) for c in self.checker.contacts(q)))

    def run(self, plan):
        """(succeeded, reason) of one plan on the rig."""
        from vr_driver.driver.motion.trajectories import TrajectoryError, TrajectoryGoal, segment_speeds, validate
        from vr_driver.driver import DriverError
        w, lim = self.world, self.kin.limits
        try:
            traj = validate(TrajectoryGoal.of(plan), w.core.joint_names, self.joints, lim.lower, lim.upper, w.now)
            segment_speeds(traj, lim.velocity, w.core.joint_names)
            run = w.core.submit_trajectory(traj)
        except (TrajectoryError, DriverError) as exc:
            return False, "refused: %s" % exc

        def done():
            self.check(self.joints, "joint_states")
            self.check(tuple(w.arm.joints), "arm")
            return run.done
        try:
            w.run_until(done, 3.0 * plan.duration + 10.0, "trajectory done")
        except Exception as exc:  # the rig's timeout: reported, the bench goes on
            return False, "did not finish: %s" % exc
        if not run.success:
            job = run.failure()
            return False, "failed: %s" % (job.result.reason if job is not None and job.result else "?")
        return True, ""


def print_profile(profiles):
    """Where the plan action's whole call went, per goal kind: the shares of its parts (the plan
    action's PlanOutcome.profile), the validity checks, the tries and why they were made again, the
    last tries that went back along the last plan's path."""
    for kind in ("joints", "pose", "all"):
        rows = [(t, p) for k, t, p in profiles if kind in ("all", k)]
        if not rows:
            continue
        whole = sum(t for t, _ in rows)
        part = {key: sum(p.get(key, 0.0) for _, p in rows)
                for key in ("crossing", "snapshot", "planner", "goal", "plan", "simplify", "time", "check",
                            "stream_check")}
        checks = sum(p.get("checks", 0) for _, p in rows)
        causes = [c.split(":")[0] for _, p in rows for c in p.get("replans", ())]
        given_up = sum(p.get("nearest_given_up", 0.0) for _, p in rows)
        print("profile, %s goals (%d calls, %.2f s in all): planner %.0f %% (IK and goal checks %.0f %%, search %.0f %%, "
              "simplification %.0f %%, timing %.0f %%, the result's check %.0f %%), the driver's stream check %.0f %%, "
              "the elbow crossing %.0f %%, the checker's copy %.0f %%; %d validity checks (%.0f a call, %.1f us each "
              "with the planner's part around them); %d tries, re-planned: %s; a pose's nearest IK solution given up "
              "after its share of the budget: %d; last tries back along the last plan's path: %d; paths that are a "
              "route of earlier plans (the roadmap): %d"
              % (kind, len(rows), whole, *(100.0 * part[k] / whole for k in ("planner", "goal", "plan", "simplify",
                                                                             "time", "check", "stream_check",
                                                                             "crossing", "snapshot")),
                 checks, checks / len(rows), 1e6 * (part["plan"] + part["simplify"] + part["check"]) / max(1, checks),
                 sum(p.get("tries", 0) for _, p in rows),
                 ", ".join("%s %d" % (c, causes.count(c)) for c in sorted(set(causes))) or "none", given_up,
                 sum(p.get("retreat", 0) for _, p in rows), sum(p.get("roadmap", 0) for _, p in rows)))


def straight_duration(planner, a, b):
    """[s] the straight joint move from ``a`` to ``b`` from rest to rest, timed as the planner times one
    (its limits and scaling): what no path between the two can undercut."""
    times = planner._timing.time([tuple(a), tuple(b)], planner.velocity_scaling, planner.acceleration_scaling,
                                 0.05, planner.dt)[0]
    return times[-1]


def holds(plan):
    """The plan's pauses at rest (a sample repeated later: the elbow crossing's hold)."""
    return sum(1 for p, q in zip(plan.positions, plan.positions[1:]) if p == q)


def profile_words(profile):
    """A call's tries and re-plans in a few words (PlanOutcome.profile)."""
    if not profile:
        return ""
    return "tries %d%s%s" % (profile.get("tries", 0), "".join("; %s" % r[:60] for r in profile.get("replans", ())),
                             "; back along the last path" if profile.get("retreat") else "") \
        + ("; a route of earlier plans" if profile.get("roadmap") else "")


def print_peer(by_kind, total, answers, version):
    """Ours and the peer's whole call per goal kind and in all (median, p95), the ratios, the
    peer's successes and path durations."""
    rows = [(kind, [t for t, _ in pairs], [a for _, a in pairs]) for kind, pairs in by_kind.items()]
    rows.append(("all", list(total), answers))
    for kind, ours, theirs in rows:
        times = [a["time"] for a in theirs]
        ok = sum(1 for a in theirs if a["ok"])
        if not ours or not times:
            continue
        m, p = statistics.median(ours), percentile(ours, 95)
        pm, pp = statistics.median(times), percentile(times, 95)
        print("vs the peer (mplib %s), %s goals: whole call median %.0f ms vs %.0f ms (ratio %.2f), p95 %.0f ms vs "
              "%.0f ms (ratio %.2f); the peer planned %d / %d%s"
              % (version, kind, 1e3 * m, 1e3 * pm, m / pm, 1e3 * p, 1e3 * pp, p / pp, ok, len(theirs),
                 ", its path duration median %.2f s" % statistics.median(a["duration"] for a in theirs if a["ok"])
                 if ok else ""))


def matched_limits(kin, ramp_time, directory):
    """(the path of a joint_limits.yaml in ``directory`` whose accelerations are each joint's speed
    limit / ``ramp_time``, the planning model with those limits): an arm with that ramp and the
    planner matched to it, written by the commissioning's own writer."""
    from vr_driver.commission.report import write_joint_limits
    from vr_driver.driver.checks.commissioned import planning_kinematics
    from vr_driver.params import DriverParams
    path = os.path.join(directory, "joint_limits.yaml")
    names = [n.split("/")[-1] for n in kin.joint_names]
    write_joint_limits(path, {n: {"max_velocity": v, "max_acceleration": v / ramp_time}
                              for n, v in zip(names, kin.limits.velocity)},
                       "bench/planning.py --ramp-time %g" % ramp_time, ())
    return path, planning_kinematics(DriverParams.from_dict({"port": "/dev/null", "planning_limits": path}), kin)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=100, help="number of queries (default 100)")
    parser.add_argument("--seed", type=int, default=1, help="random seed of the queries and the planner (default 1)")
    parser.add_argument("--budget", type=float, default=1.0, help="planner time budget [s] (default 1.0)")
    parser.add_argument("--planner", default="RRTConnect", help="OMPL planner (default RRTConnect)")
    parser.add_argument("--velocity-scaling", type=float, default=1.0,
                        help="fraction of the joint speed and acceleration limits, (0, 1] (default 1: the full "
                             "speed; the plan action's default is 0.1)")
    parser.add_argument("--ramp-time", type=float, default=None, metavar="S",
                        help="the simulated arm reaches full speed in S s (its ramp_time; default: the model's "
                             "accelerations) and the planner's accelerations are matched to it (speed / S)")
    parser.add_argument("--no-execute", action="store_true", help="plan and check only, no driver rig")
    parser.add_argument("--protocol", default="v2", help="the rig's protocol (default v2: joint targets)")
    parser.add_argument("--driver", action="store_true",
                        help="plan as the plan action does (driver.planning.planning.PlanActionCore on the rig's driver: "
                             "its checker, the workspace box, with v1 / v3 the wrist margin, the driver's own "
                             "stream check and re-plans) instead of the bare planner")
    parser.add_argument("--quick", action="store_true", help="N = 10: a smoke run")
    parser.add_argument("--cell", default=CELL, help="the cell (a scene YAML; default the example cell; "
                        "bench/cells/hood_post.yaml: goals in and out of a hood)")
    parser.add_argument("--per-query", action="store_true",
                        help="a line per query: its kind, call, path duration against the straight joint move's "
                             "from the start to the plan's end (the same limits), holds, path vertices, tries")
    parser.add_argument("--dump", metavar="PATH", default="",
                        help="write each query as a JSON line (its index, kind, start and goal joints [rad], seed, "
                             "the path duration when planned): a query replayed alone starts where this run's did")
    parser.add_argument("--peer", action="store_true",
                        help="an independent compiled planner (mplib, in its own venv) on the same queries: "
                             "its times and ours / its per goal kind")
    args = parser.parse_args()
    n = 10 if args.quick else args.n
    if args.ramp_time is not None and not (math.isfinite(args.ramp_time) and 0.0 < args.ramp_time <= 5.0):
        parser.error("--ramp-time must be in (0, 5] s, got %r" % args.ramp_time)
    started = time.perf_counter()
    try:
        from vr_driver.kinematics.collision import CollisionChecker
        from vr_driver.kinematics.planner import Planner, PlanningError
        from vr_driver.kinematics.scene import load_scene
        padding = getattr(DriverParams(), "collision_padding", 0.01)
        checker = CollisionChecker.default(scene=load_scene(args.cell), padding=padding)
        exact = CollisionChecker.default(scene=load_scene(args.cell), padding=0.0)
        from vr_driver.kinematics.solver import Kinematics
        kin = Kinematics.default()
        limits_file, planning_kin = "", kin
        if args.ramp_time is not None:
            tmp = tempfile.TemporaryDirectory(prefix="planning_bench_")
            limits_file, planning_kin = matched_limits(kin, args.ramp_time, tmp.name)
        planner = Planner(planning_kin, checker, planner=args.planner, time_budget=args.budget, seed=args.seed,
                          velocity_scaling=args.velocity_scaling, acceleration_scaling=args.velocity_scaling)
    except MissingDependency as exc:
        print("planning benchmark skipped: %s" % exc)
        return 0
    if args.driver and args.no_execute:
        parser.error("--driver plans on the rig's driver: it cannot go with --no-execute")
    executor = None if args.no_execute else Executor(kin, exact, args.protocol, args.ramp_time, limits_file,
                                                     args.cell)
    peer = None
    if args.peer:
        try:
            peer = Peer(kin, checker.scene, padding, args.budget, planner.dt, args.velocity_scaling)
        except (OSError, RuntimeError, ValueError, subprocess.CalledProcessError) as exc:
            print("the peer planner is not there (%s: %s): the bench runs without it" % (type(exc).__name__, exc))
    region = GOAL_REGIONS.get(os.path.basename(args.cell))
    driver_planning = None
    if args.driver:
        from vr_driver.driver.planning.planning import PlanActionCore, PlanGoal
        driver_planning = PlanActionCore(executor.world.core)
    rng = random.Random(args.seed)
    print("planning benchmark: %d queries, seed %d, cell %s (%s), padding %.0f mm (the driver's), planner %s, "
          "budget %.2f s, velocity scaling %g, clearance %.0f mm, max sweep %.0f mm, dt %.2f s%s"
          % (n, args.seed, os.path.relpath(args.cell, REPO), ", ".join(checker.scene.names()), padding * 1e3, args.planner,
             args.budget, args.velocity_scaling, planner.clearance * 1e3, planner.max_sweep * 1e3, planner.dt,
             "" if executor is None else ", executed on the driver rig (protocol %s)" % args.protocol)
          + ("" if args.ramp_time is None else ", the arm's ramp %g s and the planner's accelerations matched "
             "(speed / %g s)" % (args.ramp_time, args.ramp_time))
          + ("; planned by the plan action's core (driver.planning.planning)" if driver_planning is not None else "")
          + ("" if region is None else "; every other pair of goals inside %s" % (region,))
          + ("" if peer is None else "; the peer: mplib %s" % peer.version))
    start = executor.joints if executor is not None else tuple(kin.named_states["home"])
    total, solved, ompl_times, durations, failures, direct = [], [], [], [], [], 0
    cpu = []                                       # [s] the process time of each whole call
    plan_hits = padding_hits = executed = crossing = 0
    first_hit = first_pad = ""
    exec_fail = []
    kinds = {"joints": [0, 0], "pose": [0, 0]}
    by_kind = {"joints": [], "pose": []}           # (our whole call [s], the peer's answer or None)
    profiles = []                                  # (kind, whole call [s], PlanOutcome.profile)
    rows = []                                      # --per-query: a line per query
    dumped = []                                    # --dump: the queries
    for i in range(n):
        target = region_free(kin, checker, rng, region) if region is not None and (i // 2) % 2 == 0 \
            else random_free(kin, checker, rng)
        kind = "pose" if i % 2 else "joints"
        goal = kin.fk_pose(target) if kind == "pose" else target
        kinds[kind][1] += 1
        answer = None
        if args.dump:
            dumped.append({"query": i, "kind": kind, "start": list(start), "goal": list(target), "seed": args.seed + i})
        if peer is not None:
            answer = peer.plan(start, target, kin.fk(target) if kind == "pose" else None)
        t, cpu0 = time.perf_counter(), time.process_time()
        try:
            if driver_planning is not None:
                outcome = driver_planning.plan(
                    PlanGoal(pose=goal, velocity_scaling=args.velocity_scaling) if kind == "pose"
                    else PlanGoal(joints=(kin.joint_names, tuple(goal)), velocity_scaling=args.velocity_scaling),
                    start=start, seed=args.seed + i)
                profiles.append((kind, time.perf_counter() - t, getattr(outcome, "profile", None) or {}))
                if not outcome.ok:
                    raise PlanningError("plan", outcome.text)
                plan = outcome.trajectory
            else:
                plan = planner.plan(start, goal)
        except PlanningError as exc:
            total.append(time.perf_counter() - t)
            cpu.append(time.process_time() - cpu0)
            by_kind[kind].append((total[-1], answer))
            solved.append(False)
            failures.append("query %d (%s): %s" % (i, kind, exc))
            if args.per_query:
                rows.append("query %3d %-6s FAILED  call %5.0f ms  %s"
                            % (i, kind, 1e3 * total[-1], profile_words(profiles[-1][2] if driver_planning else {})))
            crossing += start[4] * target[4] < 0.0
            continue
        total.append(time.perf_counter() - t)
        cpu.append(time.process_time() - cpu0)
        by_kind[kind].append((total[-1], answer))
        solved.append(True)
        kinds[kind][0] += 1
        ompl_times.append(plan.timings["plan"] + plan.timings["simplify"])
        direct += len(plan.path) == 2
        durations.append(plan.duration)
        if args.dump:
            dumped[-1]["duration"] = plan.duration
        if args.per_query:
            rows.append("query %3d %-6s ok      call %5.0f ms  duration %5.2f s, the straight move %5.2f s (x %.2f), "
                        "holds %d, path vertices %d%s  %s"
                        % (i, kind, 1e3 * total[-1], plan.duration, straight_duration(planner, start, plan.goal),
                           plan.duration / max(1e-9, straight_duration(planner, start, plan.goal)), holds(plan),
                           len(plan.path), "" if peer is None or not answer.get("ok") else
                           ", the peer's %.2f s" % answer["duration"],
                           profile_words(profiles[-1][2] if driver_planning else {})))
        hits, text = chord_collisions(exact, plan.positions)
        plan_hits += hits
        first_hit = first_hit or (text and "query %d: %s" % (i, text))
        hits, text = chord_collisions(checker, plan.positions)
        padding_hits += hits
        first_pad = first_pad or (text and "query %d: %s" % (i, text))
        if executor is not None:
            ok, why = executor.run(plan)
            executed += ok
            if not ok:
                exec_fail.append("query %d: %s" % (i, why))
            start = executor.joints
        else:
            start = plan.goal
    ok = len(durations)
    within = sum(1 for t, good in zip(total, solved) if good and t <= args.budget)
    print("success: %d / %d (%.1f %%); joint goals %d / %d, pose goals %d / %d"
          % (ok, n, 100.0 * ok / max(1, n), kinds["joints"][0], kinds["joints"][1], kinds["pose"][0], kinds["pose"][1]))
    print("success within the %.2f s budget (the whole call): %d / %d (%.1f %%)"
          % (args.budget, within, n, 100.0 * within / max(1, n)))
    print("planning time [ms]: median %.1f  p95 %.1f  max %.1f (the whole call: goal, plan, simplify, time, check)"
          % (1e3 * statistics.median(total), 1e3 * percentile(total, 95), 1e3 * max(total)))
    print("process time of the whole call [ms] (this process's CPU: less moved by other load than the wall "
          "time): median %.1f  p95 %.1f  total %.0f" % (1e3 * statistics.median(cpu), 1e3 * percentile(cpu, 95),
                                                        1e3 * sum(cpu)))
    if ompl_times:
        print("OMPL part [ms] (plan + simplify): median %.1f  p95 %.1f  max %.1f; straight move free: %d / %d"
              % (1e3 * statistics.median(ompl_times), 1e3 * percentile(ompl_times, 95), 1e3 * max(ompl_times),
                 direct, ok))
        print("path duration [s]: median %.2f  p95 %.2f  max %.2f"
              % (statistics.median(durations), percentile(durations, 95), max(durations)))
    print("planned samples and chord points in collision: %d%s; inside the padding: %d%s"
          % (plan_hits, " (first: %s)" % first_hit if first_hit else "", padding_hits,
             " (first: %s)" % first_pad if first_pad else ""))
    if executor is not None:
        print("execution: %d / %d plans succeeded on the rig; %d joint samples checked (joint_states and the arm), "
              "%d in collision%s" % (executed, ok, executor.samples, executor.collisions,
                                     " (first: %s)" % executor.first if executor.first else ""))
        for line in exec_fail[:5]:
            print("  not executed: %s" % line)
    if failures:
        print("failed: %d, of which %d ask joint_5 to change sign (the goal's joints; a pose goal may have "
              "other solutions): with a Cartesian protocol a plan must cross the wrist singularity, where the "
              "controller's nearest-solution IK may take another wrist" % (len(failures), crossing))
    for line in failures[:10]:
        print("  failed: %s" % line)
    for line in rows:
        print(line)
    if args.dump:
        import json
        with open(args.dump, "w") as f:
            f.writelines(json.dumps(d) + "\n" for d in dumped)
    if any(p for _, _, p in profiles):
        print_profile(profiles)
    if peer is not None:
        peer.close()
        print_peer(by_kind, total, [a for k in by_kind.values() for _, a in k], peer.version)
    median_ms = 1e3 * statistics.median(total)
    print("%s success >= 99 %%: %.1f %%" % ("PASS" if ok >= 0.99 * n else "MISS", 100.0 * ok / max(1, n)))
    print("%s median <= 100 ms: %.1f ms" % ("PASS" if median_ms <= 100.0 else "MISS", median_ms))
    if executor is not None:
        print("%s 0 collisions in execution: %d" % ("PASS" if executor.collisions == 0 else "MISS", executor.collisions))
    print("python %s, wall time %.1f s" % (sys.version.split()[0], time.perf_counter() - started))
    return 0


if __name__ == "__main__":
    sys.exit(main())
