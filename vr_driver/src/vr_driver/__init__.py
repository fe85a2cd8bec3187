"""vr_driver: ROS driver stack for the Panasonic VR-006L on a G2 controller over PROFIBUS-DP.

Core modules (protocol, controller_sim, kinematics, motion, pose_input, csr) import no rospy;
node.py, terminal.py, conversions.py and params.py are the ROS edge.
"""
