#!/usr/bin/python3
"""Time of one collision check of vr_driver.kinematics.collision (issue 27; printed, never asserted).

    scripts/env python3 bench/collision.py [--n 5000] [--seed 1] [--quick]

The VR-006L (support package's xacro, moveit_config's SRDF) in the example cell
(panasonic_vr006l_support/config/cell_example.yaml: table, pillar, shelf), padding 0. N joint vectors
uniform within the joint limits, the same ones for every query; each query's time per call
(perf_counter around N calls, divided by N), in microseconds:

  pin FK        pinocchio.forwardKinematics alone (the floor of any check: the joint placements)
  KDL FK        kinematics.solver's Kinematics.fk (tool0 pose, PyKDL): what the planner pays per
                sample today for the pose alone
  in_collision  CollisionChecker.in_collision: FK, geometry placements, every pair until the first hit
  in_collision  the same restricted to the free samples and to the colliding ones (a hit stops early)
  min_distance  every pair's distance (GJK)
  contacts      every colliding pair, with its distance

Ratios: in_collision / pin FK and in_collision / KDL FK. --quick: N = 300 (smoke run).
"""
from __future__ import annotations

import argparse
import os
import sys
import time

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
for _pkg in ("vr_driver", "panasonic_vr006l_support"):
    _src = os.path.join(REPO, _pkg, "src")
    if _src not in sys.path:
        sys.path.insert(0, _src)

import numpy as np  # noqa: E402

from vr_driver.errors import MissingDependency  # noqa: E402
from vr_driver.kinematics.scene import load_scene  # noqa: E402

CELL = os.path.join(REPO, "panasonic_vr006l_support", "config", "cell_example.yaml")


def per_call_us(fn, samples) -> float:
    start = time.perf_counter()
    for q in samples:
        fn(q)
    return (time.perf_counter() - start) / max(1, len(samples)) * 1e6


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=5000, help="number of random joint vectors (default 5000)")
    parser.add_argument("--seed", type=int, default=1, help="random generator seed (default 1)")
    parser.add_argument("--quick", action="store_true", help="N = 300: a smoke run")
    args = parser.parse_args()
    n = 300 if args.quick else args.n
    started = time.perf_counter()
    try:
        from vr_driver.kinematics.collision import CollisionChecker
        checker = CollisionChecker.default(scene=load_scene(CELL))
        import pinocchio as pin
    except MissingDependency as exc:
        print("collision benchmark skipped: %s" % exc)
        return 0
    from vr_driver.kinematics.solver import Kinematics
    kin = Kinematics.default()
    rng = np.random.default_rng(args.seed)
    lo, hi = np.array(kin.limits.lower), np.array(kin.limits.upper)
    samples = [lo + rng.random(6) * (hi - lo) for _ in range(n)]
    verdict = [checker.in_collision(q) for q in samples]
    free = [q for q, hit in zip(samples, verdict) if not hit]
    hits = [q for q, hit in zip(samples, verdict) if hit]
    model, data = checker.model, checker.data
    full = [checker._config(q) for q in samples]

    print("collision benchmark: %d joint vectors within the limits, seed %d, cell %s (%s), %d pairs checked"
          % (n, args.seed, os.path.relpath(CELL, REPO), ", ".join(checker.scene.names()), len(checker.checked_pairs())))
    print("free %d, colliding %d (%.1f %% free)" % (len(free), len(hits), 100.0 * len(free) / max(1, n)))
    times = {
        "pin FK": per_call_us(lambda q: pin.forwardKinematics(model, data, q), full),
        "KDL FK": per_call_us(kin.fk, samples),
        "in_collision": per_call_us(checker.in_collision, samples),
        "in_collision free": per_call_us(checker.in_collision, free),
        "in_collision hit": per_call_us(checker.in_collision, hits),
        "min_distance": per_call_us(checker.min_distance, samples),
        "contacts": per_call_us(checker.contacts, samples),
    }
    print("%-18s %10s" % ("query", "us/call"))
    for name, us in times.items():
        print("%-18s %10.1f" % (name, us))
    print("ratio in_collision / pin FK: %.1f" % (times["in_collision"] / times["pin FK"]))
    print("ratio in_collision / KDL FK: %.1f" % (times["in_collision"] / times["KDL FK"]))
    print("python %s, pinocchio %s, coal %s, numpy %s, wall time %.1f s"
          % (sys.version.split()[0], pin.__version__, __import__("coal").__version__, np.__version__,
             time.perf_counter() - started))
    return 0


if __name__ == "__main__":
    sys.exit(main())
