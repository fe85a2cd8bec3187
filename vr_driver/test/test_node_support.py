"""The virtual devices' nodes open their device through one helper (ros/support.py): a port that
cannot be opened ends the node with 3 and a wrong setting with 2, each said in words; ``~pty_link``
``auto`` is this launch's own link, its folder made."""
import logging
import os

import pytest

from vr_driver.controller.simulator import EXIT_DEVICE, EXIT_OK, EXIT_USAGE, SimDeviceError, SimError
from vr_driver.ros.support import open_device, own_link


def _raise(exc):
    def make():
        raise exc
    return make


def test_a_device_that_opens_is_returned_with_exit_ok():
    device = object()
    assert open_device("virtual_x", lambda: device) == (device, EXIT_OK)


@pytest.mark.parametrize("exc, status, words", [
    (SimDeviceError("cannot open /dev/ttyX: no such file"), EXIT_DEVICE, "virtual_x: device error: cannot open"),
    (SimError("baud must be one of ..."), EXIT_USAGE, "virtual_x: baud must be one of"),
    (ValueError("invalid literal for int()"), EXIT_USAGE, "virtual_x: invalid literal"),
])
def test_a_device_that_fails_ends_the_node_in_words(exc, status, words, caplog):
    with caplog.at_level(logging.DEBUG):
        assert open_device("virtual_x", _raise(exc)) == (None, status)
    assert words in caplog.text


def test_an_internal_error_is_not_taken_for_a_setting():
    with pytest.raises(KeyError):
        open_device("virtual_x", _raise(KeyError("bug")))


def test_own_link(tmp_path, monkeypatch):
    monkeypatch.setenv("ROS_LOG_DIR", str(tmp_path / "log"))
    monkeypatch.setenv("ROS_MASTER_URI", "http://localhost:11399")
    monkeypatch.delenv("ROS_NAMESPACE", raising=False)
    assert own_link("", "line") is None and own_link(None, "line") is None
    assert own_link("/tmp/some/link", "line") == "/tmp/some/link"
    path = own_link("auto", "line")
    assert path == str(tmp_path / "log" / "vr006l_virtual_line_11399") and os.path.isdir(tmp_path / "log")
    assert own_link("auto:io_island", "line") == str(tmp_path / "log" / "vr006l_virtual_io_island_11399")
    with pytest.raises(SimError, match="~pty_link must be a path"):
        own_link(5, "line")


RAISE_ALL = r'''
import os, sys, threading
from vr_driver.bus.worker import set_process_priority
started = threading.Event(); release = threading.Event()
def idle():
    started.set(); release.wait()
before = threading.Thread(target=idle, daemon=True)        # as rospy's threads, started first
before.start(); started.wait()
words = set_process_priority(int(sys.argv[1]))
tids = [int(t) for t in os.listdir("/proc/self/task")]
policies = sorted({(os.sched_getscheduler(t), os.sched_getparam(t).sched_priority) for t in tids})
print(words); print(len(tids), policies)
release.set()
'''


def test_virtual_hardware_threads_started_before_are_raised_too():
    """A virtual device's node asks for SCHED_FIFO after rospy started its threads: every thread of
    the process gets it (one left at normal scheduling, holding the interpreter's lock under a CPU
    hog, held the device's real-time threads back); 0 changes nothing. In a process of its own."""
    import subprocess
    import sys

    def run(priority):
        res = subprocess.run([sys.executable, "-c", RAISE_ALL, str(priority)], capture_output=True, text=True,
                             timeout=60, env=dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p)))
        assert res.returncode == 0, res.stderr
        return res.stdout.splitlines()
    words, threads = run(0)
    assert words == "normal scheduling (rt_priority 0)" and threads.endswith("[(%d, 0)]" % os.SCHED_OTHER), threads
    words, threads = run(3)
    if not words.startswith("SCHED_FIFO"):
        pytest.skip("real-time priority not granted here: " + words)
    assert words == "SCHED_FIFO 3", words
    assert threads.startswith("2 ") and threads.endswith("[(%d, 3)]" % os.SCHED_FIFO), threads


SHUTDOWN = r'''
import sys, threading, time
import rospy
from rosgraph.xmlrpc import XmlRpcNode
from vr_driver.ros.support import end_rpc_loop
node = XmlRpcNode(0)                                     # rospy's own XML-RPC node, no master needed
node.start()
while node.uri is None:
    time.sleep(0.01)
rospy.core.add_shutdown_hook(node.shutdown)              # as init_node keeps it
waiter = end_rpc_loop() if sys.argv[1] == "quiet" else None
node.shutdown("test")                                    # rospy's hook: the socket closed
if waiter is not None:
    waiter.join(5.0)                                     # server.shutdown() returns: serve_forever has ended
ended = waiter is not None and not waiter.is_alive()
c0 = time.process_time(); time.sleep(0.3); cpu = time.process_time() - c0   # the process idle, or not
import traceback
serving = sum(any(fs.name == "serve_forever" for fs in traceback.extract_stack(f))
              for f in sys._current_frames().values())
print(ended, serving, round(cpu, 3))
'''


def test_a_node_ends_without_spinning():
    """rospy closes its XML-RPC server's socket while the server's thread loops in serve_forever: the
    thread then spins at a full core until the process ends (py-spy: a virtual line at SCHED_FIFO in
    serve_forever during shutdown, a bus process beside it without a cycle for 7 s). end_rpc_loop, the
    first shutdown hook of our nodes (support.init_node), ends the loop first: after the socket is
    closed no thread serves, and the process is idle. Without it the loop still runs (the check can
    fail). rospy's own XmlRpcNode, in a process of its own."""
    import subprocess
    import sys

    def run(mode):
        res = subprocess.run([sys.executable, "-c", SHUTDOWN, mode], capture_output=True, text=True, timeout=60,
                             env=dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p)))
        assert res.returncode == 0, res.stderr
        ended, serving, cpu = res.stdout.split()
        return ended, int(serving), float(cpu)
    ended, serving, cpu = run("quiet")
    assert ended == "True" and serving == 0, (ended, serving)
    assert cpu < 0.06, cpu                  # idle: a spinning thread takes the whole 0.3 s, or its share of it
    _, serving, _ = run("plain")
    assert serving == 1


#: the one node that keeps rospy's own init_node: csr_export --from-topic waits for one message and
#: ends, and csr never imports ros (test_layout)
OWN_INIT = {"src/vr_driver/csr/cli.py"}


def test_every_node_starts_through_support_init_node():
    """Each of our nodes, and the rostests' clients, start with support.init_node: its first shutdown
    hook keeps their shutdown from spinning (above). A new node that calls rospy.init_node fails here."""
    import pathlib
    root = pathlib.Path(__file__).resolve().parents[1]
    call = "rospy." + "init_node("                     # not this file's own text
    calls = sorted(str(p.relative_to(root)) for d in ("src", "test", "scripts", "nodes") if (root / d).is_dir()
                   for p in (root / d).rglob("*.py") if call in p.read_text(errors="replace"))
    assert set(calls) - {"src/vr_driver/ros/support.py"} == OWN_INIT, calls


BACK_AT_SHUTDOWN = r'''
import os, sys, threading
import rospy
from vr_driver.ros import support
rospy.get_param = lambda name, default=None: int(sys.argv[1])      # ~rt_priority, without a master
started = threading.Event(); release = threading.Event()
def idle():
    started.set(); release.wait()
before = threading.Thread(target=idle, daemon=True)                 # as rospy's threads, started first
before.start(); started.wait()
def policies():
    tids = [int(t) for t in os.listdir("/proc/self/task")]
    return sorted({(os.sched_getscheduler(t), os.sched_getparam(t).sched_priority) for t in tids})
rospy.on_shutdown(support.quiet_shutdown)                          # as support.init_node does
print(support.virtual_hardware_priority("virtual_x"))
print(policies())
rospy.signal_shutdown("test")
print(policies())
release.set()
'''


def test_virtual_hardware_goes_back_to_normal_scheduling_as_ros_shuts_down():
    """A virtual device's node raised to SCHED_FIFO has every thread back at normal scheduling once
    its ROS shutdown has begun (init_node's hook runs before rospy closes its XML-RPC socket, after which
    that thread busy-loops until the process ends: at SCHED_FIFO three devices ending at once sat
    out roslaunch's SIGINT and SIGTERM, 17 s of both cores each time). In a process of its own."""
    import subprocess
    import sys

    res = subprocess.run([sys.executable, "-c", BACK_AT_SHUTDOWN, "3"], capture_output=True, text=True,
                         timeout=60, env=dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p)))
    assert res.returncode == 0, res.stderr
    words, raised, after = res.stdout.splitlines()[-3:]
    if not words.startswith("SCHED_FIFO"):
        pytest.skip("real-time priority not granted here: " + words)
    assert raised == "[(%d, 3)]" % os.SCHED_FIFO, raised
    assert after == "[(%d, 0)]" % os.SCHED_OTHER, after
