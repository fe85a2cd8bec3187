"""The node `interface` as a process: a bad parameter stops it at once with a message that names
the parameter (exit 2); a missing serial port keeps it running, reporting the reason and retrying."""
import os
import socket
import subprocess
import threading
import time
import unittest

import yaml

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _free_port():
    """A TCP port nobody listens on now (a fixed one collided with another checkout's run)."""
    with socket.socket() as sock:
        sock.bind(("localhost", 0))
        return sock.getsockname()[1]


PORT = _free_port()


def env():
    e = dict(os.environ)
    e["ROS_MASTER_URI"] = "http://localhost:%d" % PORT
    return e


class InterfaceNodeTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.core = subprocess.Popen(["roscore", "-p", str(PORT)], stdout=subprocess.PIPE,
                                    stderr=subprocess.STDOUT, text=True, env=env(),
                                    start_new_session=True)
        # roscore prints "started core service [/rosout]" once the master and rosout are up. One
        # thread reads its output for the whole run (a full pipe would block the master and every
        # node with it) and signals that line. (select() on the pipe beside readline() missed lines
        # already in the reader's buffer and waited the whole 30 s: the old flake.)
        started = threading.Event()

        def read():
            for line in cls.core.stdout:
                if "started core service" in line:
                    started.set()
        cls.drain = threading.Thread(target=read, daemon=True)
        cls.drain.start()
        if not started.wait(30.0):
            os.killpg(cls.core.pid, 2)
            cls.core.wait(20)
            raise AssertionError("roscore did not start within 30 s")

    @classmethod
    def tearDownClass(cls):
        os.killpg(cls.core.pid, 2)
        cls.core.wait(20)

    def node(self, *args, timeout=60):
        return subprocess.run(["rosrun", "vr_driver", "interface", "__name:=interface_%d" % time.monotonic_ns()]
                              + list(args), capture_output=True, text=True, timeout=timeout, env=env())

    def test_bad_parameters_stop_the_node_naming_the_parameter(self):
        # a bad value and an unknown name through the node itself (every rule of every parameter:
        # vr_driver/test/test_params.py, in-process; a node start here costs some 4 s)
        for arg, words in [("_cycle_rate:=-5.0", "~cycle_rate = -5.0"),
                           ("_speed:=3", "~speed = 3: unknown parameter")]:
            res = self.node(arg)
            self.assertEqual(res.returncode, 2, arg + res.stdout + res.stderr)
            self.assertIn(words, res.stderr, arg)

    def test_other_controller_joint_names_in_its_namespace_stop_the_node(self):
        """ROS-Industrial nodes read controller_joint_names in the driver's namespace: the driver
        sets it there, and refuses to start beside a different list (the arm would be driven by the
        wrong names). The same list is fine: rostest ros_industrial starts the driver after its
        launch loaded joint_names_vr006l.yaml there, as ROS-Industrial launch files do."""
        ns = "/ri_names_%d" % time.monotonic_ns()
        subprocess.run(["rosparam", "set", ns + "/controller_joint_names", "[a, b, c, d, e, f]"],
                       check=True, env=env(), capture_output=True, timeout=30)
        res = self.node("__ns:=" + ns, "_port:=/dev/vr006l_no_such_port")
        self.assertEqual(res.returncode, 2, res.stdout + res.stderr)
        self.assertIn(ns + "/controller_joint_names is already set", res.stderr)
        self.assertIn("rosparam delete", res.stderr)
        got = subprocess.run(["rosparam", "get", ns + "/controller_joint_names"], env=env(),
                             capture_output=True, text=True, timeout=30).stdout
        self.assertEqual(yaml.safe_load(got), list("abcdef"))    # left as it was: nothing changed

    def test_missing_port_is_reported_and_retried_without_exiting(self):
        proc = subprocess.Popen(["rosrun", "vr_driver", "interface", "__name:=interface_noport",
                                 "_port:=/dev/vr006l_no_such_port", "_reconnect_period:=0.2"],
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env(),
                                start_new_session=True)
        seen = []
        reported = threading.Event()

        def read():
            for line in proc.stdout:
                seen.append(line)
                if "cannot open /dev/vr006l_no_such_port" in line:
                    reported.set()
        threading.Thread(target=read, daemon=True).start()
        try:
            self.assertTrue(reported.wait(30.0), "".join(seen))
            self.assertIsNone(proc.poll(), "the node exited instead of retrying")
        finally:
            os.killpg(proc.pid, 2)
            try:
                proc.wait(20)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, 9)
                raise


if __name__ == "__main__":
    unittest.main()
