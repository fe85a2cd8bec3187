"""The user-facing scripts: help, clear errors, and the workspace environment they provide."""
import os
import select
import signal
import subprocess
import time
import unittest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def script(name, *args, env=None, timeout=120):
    e = dict(os.environ)
    e.update(env or {})
    return subprocess.run([os.path.join(REPO, "scripts", name)] + list(args),
                          capture_output=True, text=True, timeout=timeout, env=e)


class ScriptsTest(unittest.TestCase):
    def test_help_of_every_script(self):
        for name in ("setup", "run", "test", "bench"):
            res = script(name, "--help")
            self.assertEqual(res.returncode, 0, name + res.stderr)
            self.assertIn("scripts/" + name, res.stdout, name)

    def test_unknown_options_are_refused(self):
        for name in ("setup", "run", "test", "bench"):
            res = script(name, "--bogus")
            self.assertEqual(res.returncode, 2, name)
            self.assertIn("--bogus", res.stderr, name)

    def test_env_gives_the_workspace_and_debians_python(self):
        res = script("env", "bash", "-c", 'echo "$ROS_PACKAGE_PATH"; python3 -c "import sys, rospy; print(sys.executable)"; rospack find vr_driver')
        self.assertEqual(res.returncode, 0, res.stderr)
        lines = res.stdout.split()
        self.assertIn(os.path.realpath(REPO), [os.path.realpath(p) for p in lines[0].split(":")])
        self.assertEqual(os.path.realpath(lines[1]), os.path.realpath("/usr/bin/python3"))
        self.assertEqual(os.path.realpath(lines[2]), os.path.realpath(os.path.join(REPO, "vr_driver")))

    def test_env_names_the_independent_profibus_peer(self):
        """scripts/test installs pyprofibus 1.13 into its own venv; our runtime never imports it."""
        res = script("env", "bash", "-c", '"$VR_PEER_PYTHON" -c "import pyprofibus, importlib.metadata as m; print(m.version(\'pyprofibus\'))"; python3 -c "import pyprofibus" 2>/dev/null && echo leaked || echo isolated')
        self.assertEqual(res.returncode, 0, res.stderr)
        self.assertEqual(res.stdout.split(), ["1.13", "isolated"])

    def test_env_without_a_built_workspace_says_so(self):
        res = script("env", "true", env={"VR_WS": "/nonexistent/ws"})
        self.assertEqual(res.returncode, 2)
        self.assertIn("run scripts/setup", res.stderr)

    def test_setup_check_finds_a_missing_debian_package(self):
        """The detection a fresh machine depends on: an absent package is reported, nothing installed."""
        res = script("setup", "--check", env={"VR_SETUP_EXTRA_APT": "no-such-package-vr006l"})
        self.assertEqual(res.returncode, 1, res.stdout + res.stderr)
        self.assertIn("missing Debian packages: no-such-package-vr006l", res.stdout)
        self.assertNotIn("installing", res.stdout)
        ok = script("setup", "--check")
        self.assertEqual(ok.returncode, 0, ok.stdout + ok.stderr)
        self.assertIn("nothing missing", ok.stdout)

    def test_setup_is_idempotent_and_quick_when_everything_is_there(self):
        res = script("setup", "--no-build")
        self.assertEqual(res.returncode, 0, res.stderr)
        self.assertIn("Debian packages: all", res.stdout)
        self.assertNotIn("installing", res.stdout)

    def test_run_drives_the_virtual_controller_and_stops_cleanly(self):
        """The README's first command: one call brings up the driver against the virtual controller."""
        proc = subprocess.Popen([os.path.join(REPO, "scripts", "run"), "--ros-port", "11533",
                                 "sim_port:=/tmp/vr006l_test_run_%d" % os.getpid()],
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                start_new_session=True)
        seen, end = [], time.monotonic() + 90
        try:
            while time.monotonic() < end:
                ready, _, _ = select.select([proc.stdout], [], [], 1.0)
                if not ready:
                    continue
                line = proc.stdout.readline()
                if not line:
                    break
                seen.append(line)
                if "controller connected: READY" in line:
                    break
            self.assertTrue(any("controller connected: READY" in l for l in seen), "".join(seen[-30:]))
        finally:
            os.killpg(proc.pid, signal.SIGINT)
            try:
                proc.wait(30)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
        self.assertFalse(os.path.exists("/tmp/vr006l_test_run_%d" % os.getpid()))   # pty link removed


if __name__ == "__main__":
    unittest.main()
