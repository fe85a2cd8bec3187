#!/usr/bin/python3
"""The standard IK benchmark of vr_driver.kinematics.solver (issue 6; like every benchmark: printed, never asserted).

    scripts/env python3 bench/ik.py [--n 10000] [--seed 1] [--budget 0.005] [--noise 0.05] [--no-numeric]

N random joint vectors uniform within the limits -> FK (tool0 in base_link) -> IK, twice per target:
from a random seed (uniform within the limits) and from a neighbouring seed (the true joints plus
uniform noise of +-noise rad on every joint). Solvers, in one run on the same targets and seeds:

  ours      Kinematics.ik: analytic (8 branches, nearest valid to the seed, KDL-FK-verified to 1e-6 m
            and 1e-6 rad), the default path.
  numeric   Kinematics.ik(numeric=True): KDL NR_JL from the seed (clamped into the limits), then random
            restarts until the time budget is spent (the path used for chains without the analytic
            structure).
  NR_JL     plain KDL ChainIkSolverPos_NR_JL(chain, qmin, qmax, fk, pinv, maxiter=100, eps=1e-6),
            one call from the seed as given.

Success: a joint vector within the limits whose FK matches the target within 1e-6 m and 1e-6 rad
(checked here again, independently of the solver). Times are per call (perf_counter around the call
only), in microseconds, over all calls (successful or not).
"""
from __future__ import annotations

import argparse
import math
import os
import random
import statistics
import sys
import time

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
for _pkg in ("vr_driver", "panasonic_vr006l_support"):
    _src = os.path.join(REPO, _pkg, "src")
    if _src not in sys.path:
        sys.path.insert(0, _src)

import numpy as np  # noqa: E402
import PyKDL as kdl  # noqa: E402

from vr_driver.errors import KinematicsError  # noqa: E402
from vr_driver.kinematics.solver import Kinematics  # noqa: E402
from vr_driver.poses import matrix_to_kdl_frame  # noqa: E402

POS_TOL = 1e-6
ROT_TOL = 1e-6
TARGETS = {"random": (99.95, "mean", 250.0), "neighbour": (99.99, "median", 60.0)}


def pose_ok(kin, q, target) -> bool:
    if q is None or kin.limit_violations(q):
        return False
    t = kin.fk(q)
    dp = float(np.linalg.norm(t[:3, 3] - target[:3, 3]))
    r = t[:3, :3].T @ target[:3, :3]
    skew = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    angle = math.atan2(0.5 * float(np.linalg.norm(skew)), (float(np.trace(r)) - 1.0) / 2.0)
    return dp <= POS_TOL and angle <= ROT_TOL


def summarize(name, seeds, times, ok):
    us = sorted(t * 1e6 for t in times)
    p95 = us[min(len(us) - 1, int(math.ceil(0.95 * len(us))) - 1)]
    return {"solver": name, "seeds": seeds, "n": len(us), "success": 100.0 * sum(ok) / len(ok),
            "mean": statistics.fmean(us), "median": statistics.median(us), "p95": p95, "max": us[-1]}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=10000, help="number of random targets (default 10000)")
    parser.add_argument("--seed", type=int, default=1, help="random generator seed (default 1)")
    parser.add_argument("--budget", type=float, default=0.005, help="IK time budget [s] (default 0.005)")
    parser.add_argument("--noise", type=float, default=0.05, help="neighbouring-seed noise [rad] (default 0.05)")
    parser.add_argument("--no-numeric", action="store_true", help="skip the numeric (NR_JL + restarts) path")
    args = parser.parse_args(argv)
    if args.n < 1:
        parser.error("--n must be >= 1")

    kin = Kinematics.default()
    rng = random.Random(args.seed)
    cases = []
    for _ in range(args.n):
        q = kin.random_joints(rng)
        target = kin.fk(q)
        cases.append((q, target, matrix_to_kdl_frame(target), kin.random_joints(rng),
                      tuple(v + rng.uniform(-args.noise, args.noise) for v in q)))

    lim = kin.limits
    qmin, qmax = kdl.JntArray(6), kdl.JntArray(6)
    for i in range(6):
        qmin[i], qmax[i] = lim.lower[i], lim.upper[i]
    fk = kdl.ChainFkSolverPos_recursive(kin.chain)
    vel = kdl.ChainIkSolverVel_pinv(kin.chain)
    nr_jl = kdl.ChainIkSolverPos_NR_JL(kin.chain, qmin, qmax, fk, vel, 100, 1e-6)

    def run_ours(target, frame, seed, numeric):
        t0 = time.perf_counter()
        try:
            q = kin.ik(target, seed, timeout=args.budget, rng=rng, numeric=numeric)
        except KinematicsError:
            q = None
        return time.perf_counter() - t0, q

    def run_nr(target, frame, seed, numeric):
        q_init = kdl.JntArray(6)
        for i in range(6):
            q_init[i] = seed[i]
        out = kdl.JntArray(6)
        t0 = time.perf_counter()
        ret = nr_jl.CartToJnt(q_init, frame, out)
        dt = time.perf_counter() - t0
        return dt, (tuple(out[i] for i in range(6)) if ret >= 0 else None)

    solvers = [("ours", run_ours, False)]
    if not args.no_numeric:
        solvers.append(("numeric", run_ours, True))
    solvers.append(("NR_JL", run_nr, False))

    print("IK benchmark: %d targets, budget %.1f ms, neighbour noise +-%.3f rad, seed %d, analytic solver: %s"
          % (args.n, args.budget * 1e3, args.noise, args.seed, "yes" if kin.has_analytic_solver else "no"))
    for case in cases[:200]:          # warm-up (caches, branch predictors, lazy imports), not recorded
        for name, fn, numeric in solvers:
            fn(case[1], case[2], case[3], numeric)
    rows = []
    started = time.perf_counter()
    for seeds, index in (("random", 3), ("neighbour", 4)):
        for name, fn, numeric in solvers:
            times, ok = [], []
            for case in cases:
                dt, q = fn(case[1], case[2], case[index], numeric)
                times.append(dt)
                ok.append(pose_ok(kin, q, case[1]))
            rows.append(summarize(name, seeds, times, ok))
    print("%-8s %-10s %7s %10s %10s %10s %10s %10s" % ("solver", "seeds", "n", "success %", "mean us",
                                                      "median us", "p95 us", "max us"))
    for r in rows:
        print("%-8s %-10s %7d %10.3f %10.1f %10.1f %10.1f %10.1f" % (r["solver"], r["seeds"], r["n"], r["success"],
                                                                   r["mean"], r["median"], r["p95"], r["max"]))
    for r in rows:
        if r["solver"] == "ours":
            need_ok, stat, limit = TARGETS[r["seeds"]]
            met = r["success"] >= need_ok and r[stat] <= limit
            print("target %-9s success >= %.2f %% and %s <= %.0f us: %s (%.3f %%, %.1f us)"
                  % (r["seeds"], need_ok, stat, limit, "met" if met else "NOT met", r["success"], r[stat]))
    print("python %s, PyKDL, wall time %.1f s" % (sys.version.split()[0], time.perf_counter() - started))
    return 0


if __name__ == "__main__":
    sys.exit(main())
