"""The PROFIBUS core never imports ROS: every module imports with rospy blocked."""
from __future__ import annotations

import importlib
import subprocess
import sys
import unittest

CORE = ["errors", "phy", "phy_serial", "fdl", "dp", "dp_master", "dp_slave"]


class NoRosImports(unittest.TestCase):
    def test_core_imports_without_ros(self):
        code = (
            "import sys\n"
            "for name in ('rospy', 'rospkg', 'roslib', 'std_msgs'):\n"
            "    sys.modules[name] = None\n"
            "import pyprofibus_vendor\n"
            + "".join(f"import pyprofibus_vendor.{m}\n" for m in CORE)
            + "assert not any(k.split('.')[0] in ('rospy', 'rospkg', 'roslib') and v is not None"
              " for k, v in sys.modules.items())\n"
        )
        src = importlib.import_module("pyprofibus_vendor").__file__.rsplit("/", 2)[0]
        result = subprocess.run([sys.executable, "-c", code], cwd=src, capture_output=True,
                                text=True, timeout=60)
        self.assertEqual(result.returncode, 0, result.stderr)

    def test_public_api_is_exported(self):
        pkg = importlib.import_module("pyprofibus_vendor")
        for name in pkg.__all__:
            self.assertTrue(hasattr(pkg, name), name)
        self.assertTrue(pkg.__doc__.startswith("pyprofibus_vendor: a ROS-free PROFIBUS-DP stack"))


if __name__ == "__main__":
    unittest.main()
