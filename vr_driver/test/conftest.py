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
    from vr_driver.kinematics.preview import MovePreviewer
    return MovePreviewer(kin)


# ---------------------------------------------------------------------------------------- lanes
# scripts/test runs the modules that compute beside each other, and the ones that run in real time
# (real ptys, real threads, deadlines on the wall clock) in a phase of their own, beside other
# real-time tests only (see scripts/test). `pytest --lane NAME` selects one group of modules; without
# --lane every module runs. The computing modules are three groups so that two cores finish them
# together: the top-level modules ("computation"), the stepped driver tests in driver/ ("stepped")
# and the planning worker's ("planning", processes of OMPL). A new module that opens a pty or waits
# on the wall clock belongs in "realtime".
LANE_OF = {
    "test_driver.py": "realtime",                  # DriverCore and the virtual G2 over a real pty
    "test_port_faults.py": "realtime",
    "test_controller_sim_pty.py": "pty",           # the v1 program on a real pty, at SCHED_FIFO: a lane of its own
                                                   # beside the computing groups, as the soak (71 s; scripts/test)
    "test_controller_v2_pty.py": "realtime",
    "test_sim_line_pty.py": "realtime",
    "test_scan_line.py": "realtime",               # `scan` on the virtual line at a drawn rate
    "test_adapter_line_pty.py": "realtime",        # the USB adapter model on the virtual line (~10 s)
    "test_bus_process.py": "realtime",             # the bus process over a real pty, killed mid-move
    "test_two_machines.py": "realtime",            # driver PC and workstation in two network namespaces
    "test_commission.py": "solo",                  # `commission` measures the virtual G2 to the ms: alone
    "test_soak.py": "soak",                        # the longest: a lane of its own
    "test_plan_process.py": "planning",
}
LANES = ("computation", "stepped", "planning", "realtime", "pty", "soak", "solo")


def lane_of(path) -> str:
    """The group of the test module at ``path`` (a pathlib.Path)."""
    default = "stepped" if path.parent.name == "driver" else "computation"
    return LANE_OF.get(path.name, default)


def pytest_addoption(parser):
    parser.addoption("--lane", choices=LANES, default=None,
                     help="run only this group of test modules (scripts/test runs them apart)")


def pytest_ignore_collect(collection_path, config):
    lane = config.getoption("--lane")
    if lane is None or collection_path.suffix != ".py" or not collection_path.name.startswith("test_"):
        return None
    return True if lane_of(collection_path) != lane else None
