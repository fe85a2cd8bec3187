"""vr_driver: ROS driver stack for the Panasonic VR-006L on a G2 controller over PROFIBUS-DP.

The core modules import no rospy (test/test_no_ros_imports.py): errors, poses, params, validate,
io_signals (the vocabulary), protocol, kinematics, driver, controller, terminal and csr.
The ROS edge: ros (the nodes and their helpers). The layout and what each subpackage may import:
doc/layout.md (test/test_layout.py checks it).
"""

# The generated messages (vr_driver.msg) live in the catkin devel/install space, the code here:
# let one `vr_driver` package span both, whichever of the two is found first on sys.path.
from pkgutil import extend_path as _extend_path

__path__ = _extend_path(__path__, __name__)
del _extend_path
