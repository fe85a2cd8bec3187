"""RViz as driver.launch rviz:=true shows it: scripts/screenshot_rviz under Xvfb sees the robot, the
goal arrow, the previewed path and the robot_status text in the picture (skipped without Xvfb and
rviz: scripts/setup --rviz installs them)."""
import os
import re
import shutil
import subprocess
import tempfile
import unittest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCRIPT = os.path.join(REPO, "scripts", "screenshot_rviz")


class RvizScreenshotTest(unittest.TestCase):
    def test_driver_launch_points_rviz_at_the_driver_config(self):
        with open(os.path.join(REPO, "vr_driver", "launch", "driver.launch")) as f:
            launch = f.read()
        self.assertIn('args="-d $(find vr_driver)/rviz/driver.rviz"', launch)
        self.assertIn('type="status_display"', launch)
        with open(os.path.join(REPO, "vr_driver", "rviz", "driver.rviz")) as f:
            config = f.read()
        for needle in ("rviz/RobotModel", "Marker Topic: /interface/markers", "goal: true", "path: true",
                       "Marker Topic: /status_display/marker"):
            self.assertIn(needle, config)

    @unittest.skipUnless(shutil.which("Xvfb") and shutil.which("rviz"),
                         "Xvfb or rviz not installed (scripts/setup --rviz installs them)")
    def test_the_screenshot_shows_robot_goal_path_and_status(self):
        from PIL import Image

        with tempfile.TemporaryDirectory() as d:
            out = os.path.join(d, "rviz.png")
            res = subprocess.run([SCRIPT, "-o", out, "--timeout", "90"], capture_output=True, text=True, timeout=400)
            self.assertEqual(res.returncode, 0, res.stdout + res.stderr[-3000:])
            for name in ("robot", "goal arrow", "path", "robot_status text"):
                self.assertRegex(res.stdout, r"\] %s .* +[0-9]+ pixels" % re.escape(name))
            with Image.open(out) as image:
                self.assertEqual(image.size, (1200, 800))

    def test_missing_tools_are_named(self):
        env = dict(os.environ, PATH="/nonexistent")
        res = subprocess.run(["/usr/bin/python3", SCRIPT, "-o", "/tmp/never.png"], capture_output=True, text=True,
                             env=env, timeout=60)
        self.assertEqual(res.returncode, 4)
        self.assertIn("scripts/setup --rviz", res.stderr)


if __name__ == "__main__":
    unittest.main()
