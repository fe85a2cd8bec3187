"""The workstation's side of test_two_machines.py: a ROS client in a network namespace of its own,
talking to the driver in the other through the master at ROS_MASTER_URI.

    python3 _graph_client.py trajectory     a FollowJointTrajectory goal: joint_1 10 deg and back
    python3 _graph_client.py plan           a plan action goal (joint_1 20 deg on), planned and run
    python3 _graph_client.py server SECONDS whether joint_trajectory_action is seen within SECONDS

Prints one line per outcome (``TRAJECTORY <state> <error_code> <error_string>``, ``PLAN <state>
<error_code> <execution_error_code> <error_string>``, ``SERVER SEEN`` / ``SERVER NOT SEEN``), flushed,
and exits 0 when the outcome is the one the mode wants (SUCCEEDED; the server seen).
"""
from __future__ import annotations

import math
import sys
import threading

import actionlib
import rospy
from vr_driver.ros.support import init_node
from actionlib_msgs.msg import GoalStatus
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from vr_driver.msg import (FollowJointTrajectoryAction, FollowJointTrajectoryGoal, PlanAction, PlanGoal,
                           PlanResult, RobotStatus, TriState)

#: [s] for the driver to come up in the other namespace (roscore, the virtual G2, the bus) and answer
START_WAIT = 90.0


def run_goal(client, goal, timeout):
    """(state, result) of one goal through the plain ActionClient (its callbacks carry the handle)."""
    done = threading.Event()

    def transition(handle):
        if handle.get_comm_state() == actionlib.CommState.DONE:
            done.set()
    handle = client.send_goal(goal, transition_cb=transition)
    if not done.wait(timeout):
        return None, None
    return handle.get_goal_status(), handle.get_result()


def wait_ready():
    """The arm's joints once robot_status says motion is possible."""
    status = rospy.wait_for_message("robot_status", RobotStatus, timeout=START_WAIT)
    while status.motion_possible.val != TriState.TRUE:
        status = rospy.wait_for_message("robot_status", RobotStatus, timeout=START_WAIT)
    return rospy.wait_for_message("joint_states", JointState, timeout=10.0)


def trajectory() -> int:
    client = actionlib.ActionClient("joint_trajectory_action", FollowJointTrajectoryAction)
    if not client.wait_for_server(rospy.Duration(START_WAIT)):
        print("TRAJECTORY no server", flush=True)
        return 1
    joints = wait_ready()
    start = list(joints.position)
    there = list(start)
    there[0] += math.radians(10.0)
    traj = JointTrajectory(joint_names=list(joints.name))
    # stamped here, read there: the two namespaces share one clock, as chrony keeps two machines'
    traj.header.stamp = rospy.Time.now() + rospy.Duration(0.2)
    for position, t in ((start, 0.0), (there, 1.5), (start, 3.0)):
        traj.points.append(JointTrajectoryPoint(positions=position, velocities=[0.0] * 6,
                                                time_from_start=rospy.Duration(t)))
    state, result = run_goal(client, FollowJointTrajectoryGoal(trajectory=traj), 60.0)
    if result is None:
        print("TRAJECTORY no result", flush=True)
        return 1
    print("TRAJECTORY %s %d %s" % (GoalStatus.to_string(state), result.error_code, result.error_string), flush=True)
    return 0 if state == GoalStatus.SUCCEEDED and result.error_code == 0 else 1


def plan() -> int:
    client = actionlib.ActionClient("plan", PlanAction)
    if not client.wait_for_server(rospy.Duration(START_WAIT)):
        print("PLAN no server", flush=True)
        return 1
    joints = wait_ready()
    goal = PlanGoal(goal_type=PlanGoal.JOINTS, joint_names=list(joints.name), positions=list(joints.position),
                    allowed_planning_time=5.0, velocity_scaling=1.0)
    goal.positions[0] += math.radians(20.0)
    state, result = run_goal(client, goal, 90.0)
    if result is None:
        print("PLAN no result", flush=True)
        return 1
    print("PLAN %s %d %d %s" % (GoalStatus.to_string(state), result.error_code, result.execution_error_code,
                                result.error_string), flush=True)
    return 0 if state == GoalStatus.SUCCEEDED and result.error_code == PlanResult.SUCCESS else 1


def server(seconds: float) -> int:
    client = actionlib.ActionClient("joint_trajectory_action", FollowJointTrajectoryAction)
    seen = client.wait_for_server(rospy.Duration(seconds))
    print("SERVER SEEN" if seen else "SERVER NOT SEEN", flush=True)
    return 0 if seen else 1


def main(argv) -> int:
    init_node("workstation_client", anonymous=True, disable_signals=True)
    try:
        if argv[0] == "trajectory":
            return trajectory()
        if argv[0] == "plan":
            return plan()
        return server(float(argv[1]))
    finally:
        rospy.signal_shutdown("done")


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
