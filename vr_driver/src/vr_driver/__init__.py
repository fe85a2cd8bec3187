"""vr_driver: ROS driver stack for the Panasonic VR-006L on a G2 controller over PROFIBUS-DP.

Core modules (protocol, controller_sim, kinematics, motion, pose_input, csr) import no rospy;
node.py, terminal.py, conversions.py and params.py are the ROS edge.
"""

# The generated messages (vr_driver.msg) live in the catkin devel/install space, the code here:
# let one `vr_driver` package span both, whichever of the two is found first on sys.path.
from pkgutil import extend_path as _extend_path

__path__ = _extend_path(__path__, __name__)
del _extend_path
