"""Make vr_driver (and its sibling packages' Python code) importable from the source tree under plain
pytest; inside the catkin workspace the devel space provides the same modules."""
import os
import sys

_REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
for _pkg in ("vr_driver", "pyprofibus_vendor", "panasonic_vr006l_support"):
    _src = os.path.join(_REPO, _pkg, "src")
    if _src not in sys.path:
        sys.path.insert(0, _src)


import pytest  # noqa: E402  (after the path set-up above)


@pytest.fixture(scope="session")
def kin():
    """The default VR-006L kinematics (built once: parsing the URDF and SRDF takes a while).
    Shared: tests must not modify it."""
    from vr_driver.kinematics.solver import Kinematics
    return Kinematics.default()


@pytest.fixture(scope="session")
def planner(kin):
    from vr_driver.kinematics.preview import MotionPlanner
    return MotionPlanner(kin)
