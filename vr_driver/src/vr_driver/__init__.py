"""vr_driver: ROS driver stack for the Panasonic VR-006L on a G2 controller over PROFIBUS-DP.

The core modules import no rospy (test/test_no_ros_imports.py): errors, poses, params, validate,
io_signals (the vocabulary), protocol, kinematics, driver, controller, terminal and csr.
The ROS edge: ros (the nodes and their helpers). The layout and what each subpackage may import:
doc/layout.md (test/test_layout.py checks it).
"""

# The generated messages (vr_driver.msg) live in the catkin devel/install space, the code here:
# let one `vr_driver` package span both, whichever of the two is found first on sys.path.
import os as _os
from pkgutil import extend_path as _extend_path

# One BLAS thread per process. OpenBLAS (Debian's numpy) otherwise starts a thread per core that
# spins while it waits for work: with the driver's processes side by side on two cores (node, bus
# process, planning worker, virtual G2) the spinning threads took the CPU from the bus and the arm,
# and a 2 s calibration fit took over 500 s beside two busy loops. The matrices here are 6x6 to a few
# hundred rows: a second thread brings nothing. Set before numpy loads (every node imports
# vr_driver first); a value the user set is kept.
for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS"):
    _os.environ.setdefault(_name, "1")

__path__ = _extend_path(__path__, __name__)
del _extend_path, _name, _os
