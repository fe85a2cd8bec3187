"""The cell PC's units run as the units say, against the virtual G2, and come back by their own
restart rule (no systemd on these machines: test/_unit_supervisor.py reads each unit file and runs
its ExecStart=, environment, user, rtprio limit, KillSignal= and Restart= / RestartSec= as systemd
would; vr_driver/doc/cell_pc.md says what this does not show).

scripts/install-cell writes a throw-away root; its master unit runs; a virtual G2 stands where udev
puts the adapter (<root>/dev/vr006l_bus); the driver unit runs. A node standing for the workstation
subscribes to robot_status once. Then the node `interface` is SIGKILLed (roslaunch ends with status
0: Restart=always brings it back), then roslaunch itself (the processes it leaves are stopped, as
in a cgroup, before the new start). Each time the same subscription sees the driver serve again
(link up, motion possible), from a new node, while the master stayed up."""
import os
import pwd
import queue
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import unittest
import xmlrpc.client

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, HERE)
from _unit_supervisor import environment_file  # noqa: E402

UNITS = "etc/systemd/system/"


def free_port():
    with socket.socket() as sock:
        sock.bind(("localhost", 0))
        return sock.getsockname()[1]


class Supervised:
    """One unit under test/_unit_supervisor.py; its events (lines) in a queue, with their times."""

    def __init__(self, unit, journal):
        self.journal = journal
        self.proc = subprocess.Popen([sys.executable, os.path.join(HERE, "_unit_supervisor.py"), unit,
                                      "--journal", journal], stdout=subprocess.PIPE, text=True)
        self.events = queue.Queue()
        self.seen = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self):
        for line in self.proc.stdout:
            self.events.put((time.monotonic(), line.split()))

    def expect(self, word, timeout):
        """The next event, which must be ``word``: (its time, its words)."""
        try:
            at, words = self.events.get(timeout=timeout)
        except queue.Empty:
            raise AssertionError("no %r within %g s after %s; the journal ends:\n%s"
                                 % (word, timeout, self.seen, self.tail()))
        self.seen.append(" ".join(words))
        if words[0] != word:
            raise AssertionError("expected %r, the supervisor said %r (before: %s); the journal ends:\n%s"
                                 % (word, " ".join(words), self.seen, self.tail()))
        return at, words

    def tail(self):
        try:
            with open(self.journal, errors="replace") as f:
                return "".join(f.readlines()[-25:])
        except OSError as exc:
            return str(exc)

    def stop(self):
        """systemctl stop: KillSignal=, then SIGKILL after TimeoutStopSec= (the supervisor does it)."""
        if self.proc.poll() is None:
            self.proc.terminate()

    def wait(self):
        try:
            self.proc.wait(45)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


class VirtualG2:
    """The virtual G2 controller on a pty linked at ``link`` (ROS_MASTER_URI from the environment)."""

    def __init__(self, link):
        self.proc = subprocess.Popen([os.path.join(REPO, "scripts", "env"), "rosrun", "vr_driver", "virtual_controller",
                                      "_pty_link:=" + link], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                     start_new_session=True)

    def stop(self):
        os.killpg(self.proc.pid, signal.SIGINT)

    def wait(self):
        try:
            self.proc.wait(20)
        except subprocess.TimeoutExpired:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait()


def alive(pid):
    try:
        with open("/proc/%d/stat" % pid) as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


class CellServiceTest(unittest.TestCase):
    def test_the_driver_unit_serves_and_comes_back_after_kills_by_its_own_restart_rule(self):
        import rosgraph
        import rospy
        from vr_driver.msg import RobotStatus, TriState

        root = tempfile.mkdtemp(prefix="vr006l_cell_service_")
        self.addCleanup(shutil.rmtree, root, True)
        port = free_port()
        res = subprocess.run([os.path.join(REPO, "scripts", "install-cell"), "--root", root, "--yes",
                              "--adapter-serial", "FT1TEST9", "--user", pwd.getpwuid(os.getuid()).pw_name,
                              "--ros-port", str(port), "--ros-ip", "127.0.0.1",
                              "--scene", os.path.join(REPO, "panasonic_vr006l_support/config/cell_example.yaml")],
                             capture_output=True, text=True, timeout=60)
        self.assertEqual(res.returncode, 0, res.stdout + res.stderr)
        env = environment_file(os.path.join(root, "etc/vr006l/cell.env"))
        saved = {k: os.environ.get(k) for k in ("ROS_MASTER_URI", "ROS_IP")}
        self.addCleanup(lambda: [os.environ.pop(k, None) if v is None else os.environ.__setitem__(k, v)
                                 for k, v in saved.items()])
        os.environ.update(ROS_MASTER_URI=env["ROS_MASTER_URI"], ROS_IP=env["ROS_IP"])   # the workstation's

        running = []                   # stopped at the end: the driver first, then the others at once

        def stop_all():
            for group in (running[2:], running[:2]):
                for proc in group:
                    proc.stop()
                for proc in group:
                    proc.wait()
        self.addCleanup(stop_all)
        master = Supervised(os.path.join(root, UNITS, "vr006l-master.service"), os.path.join(root, "master.journal"))
        running.append(master)
        master.expect("started", 10)
        end = time.monotonic() + 60          # the master answers (nothing to wait on but asking it)
        while not rosgraph.is_master_online() and time.monotonic() < end:
            time.sleep(0.1)
        self.assertTrue(rosgraph.is_master_online(), master.tail())
        # the adapter: a virtual G2 on a pty linked where the udev rule names it
        os.makedirs(os.path.join(root, "dev"))
        running.append(VirtualG2(os.path.join(root, "dev/vr006l_bus")))
        driver = Supervised(os.path.join(root, UNITS, "vr006l-driver.service"), os.path.join(root, "driver.journal"))
        running.append(driver)
        _, (_, first_main) = driver.expect("started", 10)

        # the workstation's node: one subscription for the whole test
        rospy.init_node("cell_workstation", anonymous=True, disable_signals=True)
        self.addCleanup(rospy.signal_shutdown, "test over")
        serving = threading.Condition()
        statuses = []

        def on_status(msg):
            with serving:
                statuses.append((time.monotonic(), msg.in_error.val == TriState.FALSE
                                 and msg.motion_possible.val == TriState.TRUE))
                serving.notify_all()
        rospy.Subscriber("robot_status", RobotStatus, on_status, queue_size=50)

        def serves_after(since, timeout=60.0):
            with serving:
                ok = serving.wait_for(lambda: any(at > since and good for at, good in statuses), timeout)
            self.assertTrue(ok, "no robot_status with the link up and motion possible within %g s; the journal "
                                "ends:\n%s" % (timeout, driver.tail()))

        def interface_pid():
            api = rosgraph.Master("/cell_workstation").lookupNode("/interface")
            return xmlrpc.client.ServerProxy(api).getPid("/cell_workstation")[2]

        t0 = time.monotonic()
        serves_after(t0, timeout=90.0)
        print("\nthe driver unit served %.1f s after its start" % (time.monotonic() - t0))

        # 1. the driver node dies: roslaunch ends with status 0 (the node was required), Restart=always
        node = interface_pid()
        os.kill(node, signal.SIGKILL)
        killed = time.monotonic()
        driver.expect("ended", 30)
        self.assertEqual(driver.seen[-1], "ended %s status 0" % first_main)
        driver.expect("cleaned", 45)
        self.assertEqual(driver.expect("restart", 5)[1], ["restart", "1"])
        restarted, (_, second_main) = driver.expect("started", 5)
        serves_after(restarted)
        self.assertNotEqual(interface_pid(), node)
        print("served again %.1f s after the node was killed" % (time.monotonic() - killed))

        # 2. roslaunch itself is killed: what it leaves is stopped before the new start
        node = interface_pid()
        left = [int(c) for c in open("/proc/%s/task/%s/children" % (second_main, second_main)).read().split()]
        self.assertTrue(left)
        os.kill(int(second_main), signal.SIGKILL)
        killed = time.monotonic()
        driver.expect("ended", 30)
        self.assertEqual(driver.seen[-1], "ended %s signal SIGKILL" % second_main)
        _, (_, count) = driver.expect("cleaned", 45)
        self.assertGreaterEqual(int(count), len(left))
        self.assertEqual([pid for pid in left if alive(pid)], [])
        driver.expect("restart", 5)
        restarted, _ = driver.expect("started", 5)
        serves_after(restarted)
        self.assertNotEqual(interface_pid(), node)
        print("served again %.1f s after roslaunch was killed" % (time.monotonic() - killed))

        # the master stayed up all along: the workstation's subscription was never lost
        self.assertTrue(master.events.empty(), list(master.events.queue))
        with open(driver.journal, errors="replace") as f:
            journal = f.read()
        # what a user reads in the journal: each of the three starts of the node
        self.assertEqual(journal.count("process[interface-2]: started with pid"), 3, journal[-3000:])


if __name__ == "__main__":
    unittest.main()
