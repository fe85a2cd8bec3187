"""vr_driver: ROS driver stack for the Panasonic VR-006L on a G2 controller over PROFIBUS-DP.

The core modules import no rospy (test/test_no_ros_imports.py): protocol, driver, controller_sim,
sim_arm, kinematics, motion, poses, validate, params, pose_input, csr and errors. The ROS edge: interface_node
(the driver node), virtual_controller_node, pose_terminal_node and ros_support.
"""

# The generated messages (vr_driver.msg) live in the catkin devel/install space, the code here:
# let one `vr_driver` package span both, whichever of the two is found first on sys.path.
from pkgutil import extend_path as _extend_path

__path__ = _extend_path(__path__, __name__)
del _extend_path
