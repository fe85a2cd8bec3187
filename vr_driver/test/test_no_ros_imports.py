"""The core modules of vr_driver import without ROS (vr_driver/__init__.py): rospy, rospkg and every
*_msgs package are blocked, then each core module that exists is imported afresh in a subprocess."""
from __future__ import annotations

import os
import subprocess
import sys

import pytest

SRC = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "src")
REPO = os.path.dirname(os.path.dirname(SRC))
CORE = ("errors", "poses", "kinematics", "motion", "protocol", "params", "driver", "sim_arm",
        "controller_sim", "csr", "pose_input")
BLOCKED = ("rospy", "rospkg", "roslib", "std_msgs", "sensor_msgs", "geometry_msgs", "industrial_msgs",
           "trajectory_msgs", "visualization_msgs", "actionlib")

_SCRIPT = """
import sys
for name in {blocked!r}:
    sys.modules[name] = None          # any import of it raises ImportError
sys.path[:0] = {paths!r}
import importlib
importlib.import_module("vr_driver." + {module!r})
loaded = sorted(m for m in sys.modules if m.endswith("_msgs") and sys.modules[m] is not None)
assert not loaded, loaded
print("ok")
"""


@pytest.mark.parametrize("module", CORE)
def test_core_module_imports_without_ros(module):
    paths = [SRC, os.path.join(REPO, "pyprofibus_vendor", "src"), os.path.join(REPO, "panasonic_vr006l_support", "src")]
    script = _SCRIPT.format(blocked=BLOCKED, paths=paths, module=module)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and proc.stdout.strip() == "ok", proc.stderr


def test_rospy_blocked_in_process_too():
    """The same check in this process (as a user's process would): block rospy, re-import the modules."""
    saved = {k: v for k, v in sys.modules.items() if k == "rospy" or k.startswith("vr_driver")}
    try:
        for k in list(sys.modules):
            if k.startswith("vr_driver"):
                del sys.modules[k]
        sys.modules["rospy"] = None
        import importlib
        for module in CORE:
            if os.path.exists(os.path.join(SRC, "vr_driver", module + ".py")):
                importlib.import_module("vr_driver." + module)
    finally:
        sys.modules.pop("rospy", None)
        for k in list(sys.modules):
            if k.startswith("vr_driver"):
                del sys.modules[k]
        sys.modules.update(saved)
