"""The goal's walk to the wire, measured (bench/goal_walk.py, issue 47): a v3 FollowJointTrajectory
goal through the node's TrajectoryServer (no ROS master) and the stepped DriverCore, every repository
file that runs recorded -- on the goal's side (its callback and its thread, to the supervisor) and on
the bus's side (the bus iterations to the DP cycle that carried its first target). The goal's side
reaches the bus side only through the inbox (posts, its Wake, the MotionSnapshot it reads): no bus
loop, link, DP master or bus process code runs in a goal's threads. Needs rospy and the built
messages (``scripts/env``); skipped with the reason otherwise."""
from __future__ import annotations

import os
import sys

import pytest

pytest.importorskip("vr_driver.msg", reason="vr_driver messages not built (run scripts/test)")
pytest.importorskip("actionlib", reason="actionlib not importable")

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
sys.path.insert(0, os.path.join(REPO, "bench"))
import goal_walk  # noqa: E402

DRIVER = "vr_driver/src/vr_driver/driver/"


@pytest.fixture(scope="module")
def walked():
    res = goal_walk.walk("v3", goals=2)
    assert res["ok"], res["words"]
    return res["last"]


def test_the_goal_side_runs_nothing_of_the_bus_side(walked):
    goal = list(walked[goal_walk.GOAL])
    # the walk was recorded: the goal's way in, its checks and its post
    for f in ("vr_driver/src/vr_driver/ros/trajectory_server.py", DRIVER + "checks/job_control.py",
              DRIVER + "checks/stream_prep.py", DRIVER + "motion/trajectories.py", DRIVER + "motion/inbox.py"):
        assert f in goal, goal
    assert [f for f in goal if goal_walk.bus_side(f)] == []
    # nor the bus side's status internals, nor the sequencer: the inbox is the one meeting point
    assert DRIVER + "motion/status.py" not in goal and DRIVER + "motion/sequencer.py" not in goal
    assert set(walked[goal_walk.THREAD]) | set(walked[goal_walk.CALLBACK]) == set(goal)


def test_the_bus_side_takes_the_inbox_to_the_telegram_without_the_virtual_controller(walked):
    bus = list(walked[goal_walk.BUS])
    for f in (DRIVER + "bus_loop.py", DRIVER + "link/link.py", DRIVER + "motion/inbox.py",
              DRIVER + "motion/streaming.py", "vr_driver/src/vr_driver/protocol/v3.py",
              "pyprofibus_vendor/src/pyprofibus_vendor/dp_master.py"):
        assert f in bus, bus
    assert not [f for f in bus if f.startswith("vr_driver/src/vr_driver/controller/") or "dp_slave" in f], bus
