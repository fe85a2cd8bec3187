"""The ROS graph across two machines (doc/network.md), end to end: two network namespaces the test
makes and always removes -- "the driver PC" (A) and "the workstation" (B) -- joined by a veth pair
with one private /30 of their own (no route anywhere else). In A: `roslaunch vr_driver
driver_pc.launch` (roscore, the driver against the virtual G2 over a real pty), ROS_IP set to A's
address. In B, with ROS_MASTER_URI at A and ROS_IP B's address: a FollowJointTrajectory goal
SUCCEEDED and a plan action goal planned and run; `check_network` all ok. Then B without ROS_IP:
the driver cannot connect back to B's action client (the classic pitfall: not seen, no error), and
check_network and the pose terminal say so, naming the ROS_IP to set; a node in A without ROS_IP is
named unreachable from B; a master port with nothing on it is named.

Needs root (CAP_NET_ADMIN) for `ip netns`: skipped, saying so, only when the kernel refuses to make a
namespace (CI machines run the suite as root)."""
from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
CLIENT = os.path.join(HERE, "_graph_client.py")
#: the test's own hosts: one private /30, only between its two namespaces
ADDR_A, ADDR_B, PREFIX = "10.199.44.1", "10.199.44.2", 30
#: the namespaces are the test's alone: the master's usual port is free there
PORT = 11311
MASTER = "http://%s:%d" % (ADDR_A, PORT)
#: names with this process's id, so two runs at once never meet (veth names: 15 characters at most)
NS_A, NS_B = "vrnet_a%d" % os.getpid(), "vrnet_b%d" % os.getpid()
VETH_A, VETH_B = "vrna%d" % os.getpid(), "vrnb%d" % os.getpid()


def ip(*args, check=True):
    return subprocess.run(["ip"] + list(args), capture_output=True, text=True, timeout=20, check=check)


def remove_namespaces(names=((NS_A, VETH_A), (NS_B, VETH_B))):
    """The namespaces (and so the veth pair) gone, whatever exists of them."""
    for ns, veth in names:
        ip("-n", ns, "link", "del", veth, check=False)
        ip("netns", "del", ns, check=False)


def remove_left_behind():
    """The namespaces of an earlier run of this test that was killed before it could remove them
    (their process is gone)."""
    listed = ip("netns", "list", check=False).stdout if shutil.which("ip") else ""
    for pid in sorted({int(m) for m in re.findall(r"^vrnet_[ab](\d+)\b", listed, re.M)}):
        if pid != os.getpid() and not os.path.exists("/proc/%d" % pid):
            remove_namespaces((("vrnet_a%d" % pid, "vrna%d" % pid), ("vrnet_b%d" % pid, "vrnb%d" % pid)))


def make_namespaces():
    """A and B joined by the veth pair; skip when the kernel refuses a namespace (not root)."""
    assert shutil.which("ip") is not None, "iproute2's `ip` is not installed (scripts/setup installs it)"
    made = ip("netns", "add", NS_A, check=False)
    if made.returncode != 0:
        pytest.skip("the kernel refused a network namespace (`ip netns add`: %s): this test needs root "
                    "(CAP_NET_ADMIN)" % made.stderr.strip())
    ip("netns", "add", NS_B)
    ip("link", "add", VETH_A, "type", "veth", "peer", "name", VETH_B)
    for ns, veth, address in ((NS_A, VETH_A, ADDR_A), (NS_B, VETH_B, ADDR_B)):
        ip("link", "set", veth, "netns", ns)
        ip("-n", ns, "addr", "add", "%s/%d" % (address, PREFIX), "dev", veth)
        ip("-n", ns, "link", "set", veth, "up")
        ip("-n", ns, "link", "set", "lo", "up")


def ns_env(logdir, ros_ip):
    """This process's environment with the master at A and ROS_IP as given (None: unset); never a
    ROS_HOSTNAME (it would win over ROS_IP; scripts/env sets one where the host name does not resolve)."""
    env = dict(os.environ)
    env.pop("ROS_HOSTNAME", None)
    env.pop("ROS_IP", None)
    if ros_ip is not None:
        env["ROS_IP"] = ros_ip
    env.update(ROS_MASTER_URI=MASTER, ROS_LOG_DIR=logdir)
    return env


class Process:
    """A process in a namespace, its output read by a thread (a full pipe would stall it)."""

    def __init__(self, ns, argv, env):
        self.lines = []
        self.proc = subprocess.Popen(["ip", "netns", "exec", ns] + argv, stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True, env=env, start_new_session=True)
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()

        self.changed = threading.Condition()

    def _read(self):
        for line in self.proc.stdout:
            with self.changed:
                self.lines.append(line)
                self.changed.notify_all()

    def wait_line(self, pattern, timeout):
        """The first output line matching ``pattern`` (a regular expression), or None by the deadline."""
        found = []

        def seen():
            found[:] = [line for line in self.lines if re.search(pattern, line)]
            return bool(found) or self.proc.poll() is not None
        with self.changed:
            self.changed.wait_for(seen, timeout)
        return found[0] if found else None

    def stop(self):
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGINT)
            try:
                self.proc.wait(30)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait(10)
        self.reader.join(5)
        return "".join(self.lines)


@pytest.fixture(scope="module")
def cell():
    """The driver PC (A) running driver_pc.launch; yields (the log folder, its launch). Removes
    everything after."""
    logdir = tempfile.mkdtemp(prefix="vr_two_machines_")
    remove_left_behind()
    driver = None
    try:
        make_namespaces()
        # roslaunch starts the master itself: ROS_MASTER_URI names an address of A
        driver = Process(NS_A, ["roslaunch", "vr_driver", "driver_pc.launch"], ns_env(logdir, ADDR_A))
        yield logdir, driver
    finally:
        if driver is not None:
            driver.stop()
        remove_namespaces()
        shutil.rmtree(logdir, ignore_errors=True)


#: waits (30 s at most) until the master knows the node argv[1]
WAIT_FOR_NODE = """
import sys, time, rosgraph
master, end = rosgraph.Master("/wait"), time.monotonic() + 30
while True:
    try:
        master.lookupNode(sys.argv[1]); break
    except Exception:
        if time.monotonic() > end: sys.exit("not registered")
        time.sleep(0.1)
"""


def in_b(cell, argv, ros_ip=ADDR_B, timeout=150, master=None):
    env = ns_env(cell[0], ros_ip)
    if master is not None:
        env["ROS_MASTER_URI"] = master
    return subprocess.run(["ip", "netns", "exec", NS_B] + argv, capture_output=True, text=True, env=env,
                          timeout=timeout)


def client(cell, *args, ros_ip=ADDR_B):
    return in_b(cell, [sys.executable, CLIENT] + list(args), ros_ip=ros_ip)


def driver_pc_said(cell, lines=40):
    """The end of driver_pc.launch's output (for a failure's message)."""
    return "\n--- driver_pc.launch in A, the last lines:\n" + "".join(cell[1].lines[-lines:])


def test_trajectory_goal_from_the_workstation_succeeds(cell):
    res = client(cell, "trajectory")
    assert res.returncode == 0, res.stdout + res.stderr + driver_pc_said(cell)
    assert re.search(r"^TRAJECTORY SUCCEEDED 0 ", res.stdout, re.M), res.stdout


def test_plan_goal_from_the_workstation_is_planned_and_run(cell):
    from vr_driver.kinematics.deps import missing_dependencies
    missing = missing_dependencies()
    if missing:
        pytest.skip("; ".join(reason for _, reason in missing))
    res = client(cell, "plan")
    assert res.returncode == 0, res.stdout + res.stderr + driver_pc_said(cell)
    assert re.search(r"^PLAN SUCCEEDED 1 0 ", res.stdout, re.M), res.stdout


def test_the_driver_pc_checked_itself_for_remote_clients(cell):
    # driver_pc.launch runs check_network --remote-clients at its start: A's ROS_IP is one of A's
    line = cell[1].wait_line(r"(ok|warning|error): this machine's nodes advertise", 60.0)
    assert line is not None and line.startswith("ok: this machine's nodes advertise '%s' (ROS_IP)" % ADDR_A), \
        "".join(cell[1].lines)


def test_workstation_launch_checks_the_network_all_ok(cell):
    # workstation.launch without RViz: check_network alone, and roslaunch ends when it has
    res = in_b(cell, ["roslaunch", "vr_driver", "workstation.launch", "rviz:=false"], timeout=90)
    assert re.search(r"\[check_network-\d+\] process has finished cleanly", res.stdout), res.stdout + res.stderr
    assert "ok: the ROS master at %s answers" % MASTER in res.stdout
    assert "ok: this machine's nodes advertise '%s' (ROS_IP)" % ADDR_B in res.stdout
    assert "ok: /use_sim_time is false" in res.stdout
    # the namespaces share one clock: well within chrony's reach
    assert re.search(r"^ok: this clock is [+-]0\.0\d\d s from the driver's", res.stdout, re.M), res.stdout


def test_without_ros_ip_the_workstation_is_told_what_to_set(cell):
    # the pitfall is real: the driver cannot connect back to this client's goal topic, and the client
    # is told nothing; the driver says so in its log (its sender watch), naming what to set
    waiting = subprocess.Popen(["ip", "netns", "exec", NS_B, sys.executable, CLIENT, "server", "6"],
                               env=ns_env(cell[0], None), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                               text=True)
    said = cell[1].wait_line(r"nothing /workstation_client\S* publishes to it", 30.0)
    out = waiting.communicate(timeout=60)[0]
    assert "SERVER NOT SEEN" in out, out
    assert said is not None, driver_pc_said(cell)
    assert re.search(r"\(/joint_trajectory_action/cancel, /joint_trajectory_action/goal\) arrives: node "
                     r"/workstation_client\S* advertises http://[^ ]+, which this machine cannot reach \(.*\): "
                     r"set ROS_IP to its machine's address", said), said
    fix = "set ROS_IP=%s (this machine's address toward the master)" % ADDR_B
    res = in_b(cell, ["rosrun", "vr_driver", "check_network"], ros_ip=None)
    assert res.returncode == 1, res.stdout + res.stderr
    assert fix in res.stdout, res.stdout
    assert "ROS_IP and ROS_HOSTNAME are unset" in res.stdout
    res = in_b(cell, ["rosrun", "vr_driver", "pose_terminal", "--plan", "home", "--preview"], ros_ip=None)
    assert res.returncode == 3, res.stdout + res.stderr         # EXIT_NO_DRIVER, at once
    assert fix in res.stderr, res.stdout + res.stderr


def test_a_node_unreachable_by_its_name_and_a_master_not_there_are_named(cell):
    # a node in A without ROS_IP advertises the host name, which does not lead to A from B
    probe = Process(NS_A, ["rostopic", "pub", "-r", "2", "/graph_probe", "std_msgs/Empty", "__name:=graph_probe"],
                    ns_env(cell[0], None))
    try:
        known = in_b(cell, ["python3", "-c", WAIT_FOR_NODE, "/graph_probe"], timeout=60)
        assert known.returncode == 0, known.stdout + known.stderr + probe.stop()
        res = in_b(cell, ["rosrun", "vr_driver", "check_network"])
    finally:
        probe.stop()
    assert res.returncode == 1, res.stdout + res.stderr
    assert re.search(r"^error: node /graph_probe advertises http://[^ ]+, which this machine cannot reach \(.*\): "
                     r"set ROS_IP to its machine's address", res.stdout, re.M), res.stdout
    res = in_b(cell, ["rosrun", "vr_driver", "check_network"], master="http://%s:1" % ADDR_A)
    assert res.returncode == 1
    assert "error: cannot reach the ROS master at http://%s:1 (ROS_MASTER_URI; %s): connection refused: " \
           "nothing listens on port 1 there; is roscore" % (ADDR_A, ADDR_A) in res.stdout, res.stdout
