"""Python helpers of the VR-006L support package: render the xacro, read the model, draw it (ROS-free)."""

import os as _os

# One BLAS thread per process (see vr_driver/__init__.py: OpenBLAS's spinning threads on two cores
# slowed a 2 s calibration fit past 500 s beside two busy loops). Before numpy loads; a user's value
# is kept.
for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS"):
    _os.environ.setdefault(_name, "1")
del _name, _os
