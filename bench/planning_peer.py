"""The planning bench's peer: an independent compiled planner answering the bench's queries in the
same run (bench/planning.py --peer). Run by the bench in its own venv (``.ws/peers-planning``,
``mplib`` from PyPI: ``scripts/setup --bench-peers``), never by the driver, and never imported by
it: it reads one JSON object a line on stdin and answers one a line on stdout.

    {"urdf": PATH, "srdf": PATH, "objects": [{"name", "shape", "size", "position", "quaternion"}],
     "padding": M, "velocity": [...], "acceleration": [...], "budget": S}     -> {"ready": true, ...}
    {"start": [rad x 6], "joints": [rad x 6]}                               -> {"ok", "time", "duration", ...}
    {"start": [rad x 6], "pose": [[4 x 4] tool0 in base_link, m]}          -> the same

mplib (SAPIEN's motion planning library, MIT licence): OMPL's RRTConnect on FCL's collision checks
in C++, its own numerical IK (random restarts) for a pose goal, TOPP-RA for the timing -- the same
family of tools as the plan action's, with its collision loop compiled. The cell's objects are
grown by ``padding`` (boxes and cylinders by that much on every side): the peer keeps the driver's
padding from the cell as the plan action does (the robot's own shapes are not grown). ``time``:
the whole call (IK, search, simplification, timing), measured here, so that the pipe is not in it.
"""
import json
import os
import sys
import time

import numpy as np


def _quat_wxyz(q):
    x, y, z, w = q
    return np.array([w, x, y, z], dtype=float)


def _objects(fcl, Pose, objects, padding):
    out = []
    for obj in objects:
        size = [float(v) for v in obj["size"]]
        if obj["shape"] == "box":
            geom = fcl.Box(*(s + 2.0 * padding for s in size))
        elif obj["shape"] == "cylinder":
            geom = fcl.Cylinder(size[0] + padding, size[1] + 2.0 * padding)
        else:
            geom = fcl.Sphere(size[0] + padding)
        pose = Pose(np.array(obj["position"], dtype=float), _quat_wxyz(obj["quaternion"]))
        out.append(fcl.FCLObject(obj["name"], pose, [fcl.CollisionObject(geom)], [Pose()]))
    return out


def main():
    # the answers on a stdout of their own: whatever mplib prints (Python or C++: "IK failed", ...)
    # goes to stderr
    answers = os.fdopen(os.dup(1), "w")
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    import mplib
    from mplib import Pose
    from mplib.collision_detection import fcl
    setup = json.loads(sys.stdin.readline())
    t = time.perf_counter()
    planner = mplib.Planner(setup["urdf"], "tool0", srdf=setup["srdf"],
                            joint_vel_limits=np.array(setup["velocity"], dtype=float),
                            joint_acc_limits=np.array(setup["acceleration"], dtype=float),
                            objects=_objects(fcl, Pose, setup["objects"], float(setup["padding"])))
    budget = float(setup.get("budget", 1.0))
    dt = float(setup.get("dt", 0.05))
    print(json.dumps({"ready": True, "version": getattr(mplib, "__version__", "?"),
                      "setup_s": time.perf_counter() - t}), file=answers, flush=True)
    for line in sys.stdin:
        query = json.loads(line)
        start = np.array(query["start"], dtype=float)
        t = time.perf_counter()
        try:
            if "pose" in query:
                result = planner.plan_pose(Pose(np.array(query["pose"], dtype=float)), start, time_step=dt,
                                           planning_time=budget, wrt_world=True)
            else:
                result = planner.plan_qpos([np.array(query["joints"], dtype=float)], start, time_step=dt,
                                           planning_time=budget)
        except Exception as exc:  # an answer the bench counts as a failure, the peer goes on
            result = {"status": "%s: %s" % (type(exc).__name__, exc)}
        elapsed = time.perf_counter() - t
        ok = result.get("status") == "Success"
        answer = {"ok": ok, "time": elapsed, "status": str(result.get("status"))}
        if ok:
            answer["duration"] = float(result["duration"])
            answer["positions"] = np.asarray(result["position"], dtype=float).tolist()
        print(json.dumps(answer), file=answers, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
