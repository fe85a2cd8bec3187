#!/usr/bin/python3
"""Latencies and rates of the driver node against the virtual controller (printed, never asserted).

    scripts/bench driver_latency [-- --goals 20 --estops 20 --window 10 --baud B --cycle-rate R --both | --quick]
    scripts/bench driver_latency -- --protocol v3 --joint-only --paced --both     (d) alone, paced line

Each configuration runs in a worker process of its own that starts a private roscore on a free port
(from 11700 up, or --ros-port) and vr_driver/launch/driver.launch (sim:=true, the pty linked in a
private temporary directory, baud / cycle_rate as given; default the launch file's defaults), waits
until robot_status says motion_possible, then measures, in this order:

  (c) an idle window of --window s: joint_states and robot_status rates and jitter (inter-arrival
      times at this client and between the publisher's header stamps), the ROS transport time
      (header stamp -> arrival), and the CPU of the `interface` and `virtual_controller` processes
      (utime + stime from /proc/PID/stat over the window; the PIDs come from the nodes' XML-RPC
      getPid) -- the bench's own subscriber runs meanwhile, on the same 2 cores;
  (a) --goals move_to_pose goals (LIN, +-50 mm in y about the home pose, 0.5 s of motion each; one
      warm-up goal first, not counted), each after the previous result, 3 bus cycles (the driver
      needs 2 after a result to release the handshake; a goal sent before waits for that) and a
      random pause of 0..100 ms (so sends are not phase-locked to the bus cycle or the publishing
      timers). From send_goal(): the driver handing the target to the bus (the stamp of its rosout
      line "job N: sent target", logged when it sets the outputs that go out with the next bus
      cycle), the controller going BUSY (the start_time of the virtual controller's execution-log
      entry, /virtual_controller/executed), the first action feedback with phase "moving" and the
      first robot_status with in_motion TRUE as this client receives them (and that status's
      header stamp, i.e. when the driver published it);
  (b) --estops e-stop presses and releases via /virtual_controller/set_estop: from the virtual
      controller's own log line ("e-stop pressed" / "released", its rosout stamp, written just
      before the simulated arm takes the e-stop) and from the service call's return to the first
      robot_status with e_stopped TRUE / FALSE received here (and published by the driver).

  (d) with a streaming protocol (--protocol v2 / v3): --joint-commands joint_command messages
      (trajectory_msgs/JointTrajectory of one point: joint_1 +-1 deg from where the arm rests,
      time_from_start 0.05 s), each from rest -- a new stream every time: after the previous
      command's execution-log entry, joint_command_timeout + 0.1 s and a random pause of 0..100 ms.
      From publish(): the controller taking the target (the taken_time of its execution-log entry),
      and joint_states showing motion (joint_1 more than 0.001 deg from the rest value): its header
      stamp (the record's time) and its arrival here. With protocol v1 the topic refuses every
      command and (d) is skipped. --joint-only skips (a) and (b).

--paced puts the virtual line between the driver and the controller (io:=true, line_baud = --baud):
the bytes take their wire time, as on the real bus; without it the pty carries them at once.

Clocks. The virtual controller's start_time is Python's time.monotonic() in its own process; on
Linux that is CLOCK_MONOTONIC, one clock for the whole machine, so it is compared with this
process's time.monotonic() directly (checked per goal: send_goal <= start_time <= feedback
"moving", the count is printed). rosout and header stamps are rospy wall time (time.time() of
the sending process, the same system clock); they are mapped onto time.monotonic() with one
offset measured at start. Arrival times here are time.monotonic() in the subscriber callbacks.

Figures are medians / p95 / max in ms with counts. A pty has no baud timing: --baud only sets the
DP timing parameters of master and slave, the bytes move at pty speed. Exit status 1 when the
stack does not come up or a measurement fails (a goal not succeeding, a status never seen).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import random
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import xml.etree.ElementTree as ET
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
LAUNCH = os.path.join(REPO, "vr_driver", "launch", "driver.launch")
RESULT_TAG = "@@DRIVER_LATENCY_RESULT "
HOME = (1120.0, 0.0, 725.0, 0.0, 45.0, 0.0)
A_POSE = (1120.0, 50.0, 725.0, 0.0, 45.0, 0.0)
B_POSE = (1120.0, -50.0, 725.0, 0.0, 45.0, 0.0)
FAST = (187500, 50.0)
#: deg: the joint_1 step of each joint_command measured in (d)
JOG_STEP_DEG = 1.0
READY_TIMEOUT = 90.0


# ------------------------------------------------------------------------------------ small helpers

def launch_defaults() -> Tuple[int, float]:
    """baud and cycle_rate defaults of driver.launch (19200 / 20.0 if it cannot be read)."""
    baud, rate = 19200, 20.0
    try:
        for arg in ET.parse(LAUNCH).getroot().iter("arg"):
            if arg.get("name") == "baud" and arg.get("default"):
                baud = int(arg.get("default"))
            elif arg.get("name") == "cycle_rate" and arg.get("default"):
                rate = float(arg.get("default"))
    except (OSError, ET.ParseError, ValueError):
        pass
    return baud, rate


def port_free(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        if s.connect_ex(("127.0.0.1", port)) == 0:
            return False
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            s.bind(("", port))
        return True
    except OSError:
        return False


def pick_port(base: int) -> int:
    for port in range(base, base + 400):
        if port_free(port):
            return port
    raise RuntimeError("no free TCP port in %d..%d" % (base, base + 399))


def proc_stat(pid: int) -> Optional[Tuple[int, int]]:
    """(utime + stime in clock ticks, start time) of a process from /proc/PID/stat, None if gone."""
    try:
        with open("/proc/%d/stat" % pid) as fh:
            data = fh.read()
    except OSError:
        return None
    fields = data[data.rindex(")") + 2:].split()        # fields[0] is the state (field 3)
    return int(fields[11]) + int(fields[12]), int(fields[19])


def stats(values: Sequence[float]) -> Dict[str, Any]:
    """n, median, p95, max, min, mean, sd of the values (ms)."""
    v = sorted(values)
    if not v:
        return {"n": 0}
    return {"n": len(v), "median": statistics.median(v), "p95": v[max(0, int(math.ceil(0.95 * len(v))) - 1)],
            "max": v[-1], "min": v[0], "mean": statistics.fmean(v),
            "sd": statistics.pstdev(v) if len(v) > 1 else 0.0}


def fmt(s: Optional[Dict[str, Any]]) -> str:
    if not s or not s.get("n"):
        return "n/a"
    return "%.1f / %.1f / %.1f (%d)" % (s["median"], s["p95"], s["max"], s["n"])


def row(label: str, s: Optional[Dict[str, Any]], width: int = 58) -> str:
    if not s or not s.get("n"):
        return "%-*s %8s %8s %8s %5d" % (width, label, "n/a", "n/a", "n/a", 0)
    return "%-*s %8.1f %8.1f %8.1f %5d" % (width, label, s["median"], s["p95"], s["max"], s["n"])


def header(width: int = 58) -> str:
    return "%-*s %8s %8s %8s %5s" % (width, "  [ms]", "median", "p95", "max", "n")


# ------------------------------------------------------------------------------------- the ROS stack

class Stack:
    """A private roscore and driver.launch, each in a session of its own, and the PIDs of their
    nodes (roslaunch puts every node in a session of its own too), so that :meth:`stop` can end all
    of it even when roslaunch does not."""

    def __init__(self, tmp: str, port: int):
        self.tmp = tmp
        self.port = port
        self.master_uri = "http://localhost:%d" % port
        self.env = dict(os.environ, ROS_MASTER_URI=self.master_uri, ROS_LOG_DIR=os.path.join(tmp, "log"))
        self.roscore: Optional[subprocess.Popen] = None
        self.launch: Optional[subprocess.Popen] = None
        self.node_pids: Dict[str, Tuple[int, int]] = {}      # name -> (pid, start time)
        self.core_pids: Dict[str, Tuple[int, int]] = {}

    def _spawn(self, args: List[str], log_name: str) -> subprocess.Popen:
        log = open(os.path.join(self.tmp, log_name), "wb")
        try:
            return subprocess.Popen(args, env=self.env, stdin=subprocess.DEVNULL, stdout=log,
                                    stderr=subprocess.STDOUT, start_new_session=True, cwd=self.tmp)
        finally:
            log.close()

    def log_tail(self, log_name: str, lines: int = 25) -> str:
        try:
            with open(os.path.join(self.tmp, log_name), errors="replace") as fh:
                return "".join(fh.readlines()[-lines:])
        except OSError:
            return ""

    def start_roscore(self, timeout: float = 30.0) -> None:
        import rosgraph
        self.roscore = self._spawn(["roscore", "-p", str(self.port)], "roscore.log")
        master = rosgraph.Master("/driver_latency_probe", master_uri=self.master_uri)
        end = time.monotonic() + timeout
        while True:
            try:
                pid = master.getPid()
                self._remember(self.core_pids, "rosmaster", pid)
                return
            except Exception:  # noqa: BLE001 - not up yet
                pass
            if self.roscore.poll() is not None:
                raise RuntimeError("roscore exited (%s):\n%s" % (self.roscore.returncode, self.log_tail("roscore.log")))
            if time.monotonic() > end:
                raise RuntimeError("roscore on port %d not up in %.0f s:\n%s"
                                   % (self.port, timeout, self.log_tail("roscore.log")))
            time.sleep(0.2)

    def start_launch(self, args: List[str]) -> None:
        self.launch = self._spawn(["roslaunch", "--sigint-timeout", "5", "vr_driver", "driver.launch"] + args,
                                  "launch.log")

    def launch_alive(self) -> bool:
        return self.launch is not None and self.launch.poll() is None

    @staticmethod
    def _remember(table: Dict[str, Tuple[int, int]], name: str, pid: int) -> None:
        st = proc_stat(pid)
        if st is not None:
            table[name] = (pid, st[1])

    def collect_pids(self, own_name: str) -> None:
        """PIDs of every node on the master (XML-RPC getPid), split into roscore's and the launch's."""
        import xmlrpc.client

        import rosgraph
        master = rosgraph.Master(own_name, master_uri=self.master_uri)
        pubs, subs, srvs = master.getSystemState()
        names = {n for _topic, nodes in list(pubs) + list(subs) + list(srvs) for n in nodes}
        for name in sorted(names):
            if name == own_name:
                continue
            try:
                uri = master.lookupNode(name)
                code, _msg, pid = xmlrpc.client.ServerProxy(uri).getPid(own_name)
            except Exception:  # noqa: BLE001 - a node that went away
                continue
            if code == 1:
                self._remember(self.core_pids if name == "/rosout" else self.node_pids, name, pid)

    def pid(self, name: str) -> Optional[int]:
        entry = self.node_pids.get(name)
        return entry[0] if entry else None

    @staticmethod
    def _stop_group(proc: Optional[subprocess.Popen], sigint_wait: float) -> None:
        if proc is None or proc.poll() is not None:
            return
        for sig, wait in ((signal.SIGINT, sigint_wait), (signal.SIGTERM, 5.0), (signal.SIGKILL, 5.0)):
            try:
                os.killpg(proc.pid, sig)
            except ProcessLookupError:
                return
            try:
                proc.wait(wait)
                return
            except subprocess.TimeoutExpired:
                continue

    @staticmethod
    def _reap(table: Dict[str, Tuple[int, int]]) -> List[str]:
        """End processes of ours still alive (same PID and start time as recorded)."""
        left = []
        for name, (pid, start) in table.items():
            st = proc_stat(pid)
            if st is None or st[1] != start:
                continue
            left.append("%s (pid %d)" % (name, pid))
            for sig in (signal.SIGTERM, signal.SIGKILL):
                try:
                    os.kill(pid, sig)
                except ProcessLookupError:
                    break
                end = time.monotonic() + 3.0
                while time.monotonic() < end:
                    st = proc_stat(pid)
                    if st is None or st[1] != start or _zombie(pid):
                        break
                    time.sleep(0.05)
                else:
                    continue
                break
        return left

    def stop(self) -> List[str]:
        """Stop roslaunch (its nodes), then roscore; end leftovers. Returns what had to be killed."""
        self._stop_group(self.launch, 20.0)
        left = self._reap(self.node_pids)
        self._stop_group(self.roscore, 15.0)
        left += self._reap(self.core_pids)
        return left


def _zombie(pid: int) -> bool:
    try:
        with open("/proc/%d/stat" % pid) as fh:
            data = fh.read()
        return data[data.rindex(")") + 2] == "Z"
    except (OSError, ValueError):
        return True


# ------------------------------------------------------------------------------------------ worker

class Recorder:
    """Every message of a topic with its arrival time (time.monotonic()), waits with deadlines."""

    def __init__(self, rospy: Any, topic: str, kind: Any, keep: Optional[Callable[[Any], bool]] = None):
        self.messages: List[Tuple[float, Any]] = []
        self.cond = threading.Condition()
        self.keep = keep
        self.sub = rospy.Subscriber(topic, kind, self._cb, queue_size=200, tcp_nodelay=True)

    def _cb(self, msg: Any) -> None:
        t = time.monotonic()
        if self.keep is not None and not self.keep(msg):
            return
        with self.cond:
            self.messages.append((t, msg))
            self.cond.notify_all()

    def mark(self) -> int:
        with self.cond:
            return len(self.messages)

    def wait_for(self, predicate: Callable[[Any], bool], timeout: float, start: int = 0
                 ) -> Optional[Tuple[float, Any]]:
        end = time.monotonic() + timeout
        i = start
        with self.cond:
            while True:
                while i < len(self.messages):
                    if predicate(self.messages[i][1]):
                        return self.messages[i]
                    i += 1
                left = end - time.monotonic()
                if left <= 0:
                    return None
                self.cond.wait(min(left, 0.5))

    def between(self, t0: float, t1: float) -> List[Tuple[float, Any]]:
        with self.cond:
            return [(t, m) for t, m in self.messages if t0 <= t <= t1]

    def last(self) -> Optional[Any]:
        with self.cond:
            return self.messages[-1][1] if self.messages else None


class Failure(Exception):
    """A measurement that could not be made (the message says which)."""


def stack_worker(cfg: Dict[str, Any], prefix: str, node: str, header: str, launch_args: Sequence[str],
                 measure: Callable[[Any, "Stack"], int], failed: Callable[[BaseException, "Stack"], bool]) -> int:
    """One configuration in its own ROS graph (also bench/trajectory.py's): a temporary directory
    (``prefix``), a roscore on a free port, this process as ROS node ``node``, driver.launch with
    ``sim:=true``, its pty in the directory, and ``launch_args``; then ``measure(rospy, stack)`` gives
    the exit status. ``header`` is printed first (``{port}`` and ``{tmp}`` filled in). An error is
    reported by ``failed(exc, stack)`` (a traceback first unless it is a :class:`Failure`), which
    says whether to keep the logs; a Ctrl-C gives 130. Everything started is stopped, and the
    directory removed unless kept (or ``cfg["keep_logs"]``)."""
    tmp = tempfile.mkdtemp(prefix=prefix)
    port = cfg["ros_port"] or pick_port(11700 + (os.getpid() % 150) * 2)
    stack = Stack(tmp, port)
    os.environ["ROS_MASTER_URI"] = stack.master_uri           # before rospy reads it
    os.environ["ROS_LOG_DIR"] = stack.env["ROS_LOG_DIR"]

    interrupt_once((signal.SIGINT, signal.SIGTERM, signal.SIGHUP))

    rospy = None
    status = 1
    keep = False
    print(header.format(port=port, tmp=tmp), flush=True)
    try:
        stack.start_roscore()
        import rospy as _rospy
        rospy = _rospy
        rospy.init_node(node, anonymous=True, disable_signals=True)
        stack.start_launch(["sim:=true", "sim_port:=%s/g2" % tmp] + list(launch_args))
        status = measure(rospy, stack)
    except KeyboardInterrupt:
        print("interrupted: stopping what was started", flush=True)
        status = 130
    except Exception as exc:  # noqa: BLE001 - report, clean up, exit 1
        if not isinstance(exc, Failure):
            import traceback
            traceback.print_exc()
        keep = failed(exc, stack)
    finally:
        if rospy is not None:
            rospy.signal_shutdown("benchmark done")
        left = stack.stop()
        if left:
            print("had to kill: %s" % ", ".join(left), flush=True)
        if keep or cfg.get("keep_logs"):
            print("logs kept in %s" % tmp, flush=True)
        else:
            shutil.rmtree(tmp, ignore_errors=True)
    return status


def worker(cfg: Dict[str, Any]) -> int:
    def measure(rospy: Any, stack: "Stack") -> int:
        result = Measure(rospy, stack, cfg).run()
        print(RESULT_TAG + json.dumps(result), flush=True)
        return 0 if not result["failures"] else 1

    def failed(exc: BaseException, stack: "Stack") -> bool:
        print("FAILED: %s" % exc if isinstance(exc, Failure) else
              "FAILED: %s: %s" % (type(exc).__name__, exc), flush=True)
        print("launch log (tail), all logs in %s:\n%s" % (stack.tmp, stack.log_tail("launch.log")), flush=True)
        return True
    return stack_worker(
        cfg, "vr_driver_latency_", "driver_latency_bench",
        "--- %d bit/s, %g Hz bus cycle, protocol %s%s (ROS master port {port}, pty {tmp}/g2, speed_factor %g)"
        % (cfg["baud"], cfg["cycle_rate"], cfg["protocol"], ", paced line" if cfg["paced"] else "",
           cfg["speed_factor"]),
        ["baud:=%d" % cfg["baud"], "cycle_rate:=%g" % cfg["cycle_rate"], "speed_factor:=%g" % cfg["speed_factor"],
         "protocol:=%s" % cfg["protocol"]]
        + (["io:=true", "line_baud:=%d" % cfg["baud"]] if cfg["paced"] else []),
        measure, failed)


def interrupt_once(signals: Sequence[int]) -> None:
    """The first of these signals raises KeyboardInterrupt in the main thread; later ones are
    ignored, so a second Ctrl-C cannot break the clean-up half way."""
    fired = []

    def handler(signum: int, frame: Any) -> None:
        if not fired:
            fired.append(signum)
            raise KeyboardInterrupt("signal %d" % signum)
    for sig in signals:
        signal.signal(sig, handler)


class Measure:
    def __init__(self, rospy: Any, stack: Stack, cfg: Dict[str, Any]):
        import actionlib
        from diagnostic_msgs.msg import DiagnosticArray
        from rosgraph_msgs.msg import Log
        from sensor_msgs.msg import JointState
        from std_msgs.msg import String
        from std_srvs.srv import SetBool

        from vr_driver.msg import MoveToPoseAction, RobotStatus, TriState
        self.rospy, self.stack, self.cfg = rospy, stack, cfg
        self.TRUE, self.FALSE = TriState.TRUE, TriState.FALSE
        self.rng = random.Random(cfg["seed"])
        self.failures: List[str] = []
        self.own = rospy.get_name()
        # wall -> monotonic, one offset (the smallest of a few reads brackets it best)
        pairs = []
        for _ in range(5):
            m0 = time.monotonic()
            w = time.time()
            m1 = time.monotonic()
            pairs.append((m1 - m0, w - (m0 + m1) / 2))
        self.wall_offset = min(pairs)[1]
        self.status = Recorder(rospy, "/robot_status", RobotStatus)
        self.joints = Recorder(rospy, "/joint_states", JointState)
        self.executed = Recorder(rospy, "/virtual_controller/executed", String)
        self.rosout = Recorder(rospy, "/rosout", Log,
                               keep=lambda m: m.name in ("/interface", "/virtual_controller"))
        self.diag = Recorder(rospy, "/diagnostics", DiagnosticArray,
                             keep=lambda m: any(s.name.endswith("link") for s in m.status))
        self.client = actionlib.SimpleActionClient("/move_to_pose", MoveToPoseAction)
        self.set_estop = rospy.ServiceProxy("/virtual_controller/set_estop", SetBool)
        self.set_drives = rospy.ServiceProxy("/virtual_controller/set_drives_powered", SetBool)
        from trajectory_msgs.msg import JointTrajectory
        self.joint_command = rospy.Publisher("/joint_command", JointTrajectory, queue_size=1, tcp_nodelay=True)

    def mono(self, stamp: Any) -> float:
        """A rospy wall-clock stamp on this process's time.monotonic()."""
        return stamp.to_sec() - self.wall_offset

    # -------------------------------------------------------------------------------- set-up
    def wait_ready(self) -> float:
        t0 = time.monotonic()
        end = t0 + READY_TIMEOUT
        rospy = self.rospy

        def alive() -> None:
            if not self.stack.launch_alive():
                raise Failure("driver.launch exited (%s) before it was ready:\n%s"
                              % (self.stack.launch.returncode, self.stack.log_tail("launch.log")))
            if time.monotonic() > end:
                raise Failure("the driver was not ready within %.0f s" % READY_TIMEOUT)
        while not self.client.wait_for_server(rospy.Duration(0.5)):
            alive()
        while self.joint_command.get_num_connections() == 0:    # the node subscribes it last
            alive()
            time.sleep(0.05)
        while True:
            try:
                rospy.wait_for_service("/virtual_controller/set_estop", 0.5)
                break
            except rospy.ROSException:
                alive()
        while self.status.wait_for(lambda m: m.motion_possible.val == self.TRUE, 0.5,
                                   max(0, self.status.mark() - 1)) is None:
            alive()
        ready = time.monotonic() - t0
        self.stack.collect_pids(self.own)
        return ready

    def wait_motion_possible(self, what: str, timeout: float = 10.0) -> None:
        start = max(0, self.status.mark() - 1)
        if self.status.wait_for(lambda m: m.motion_possible.val == self.TRUE and m.in_motion.val == self.FALSE
                                and m.e_stopped.val == self.FALSE, timeout, start) is None:
            raise Failure("motion_possible not TRUE within %.0f s (%s)" % (timeout, what))

    # -------------------------------------------------------------------------------- (c)
    def idle_window(self) -> Dict[str, Any]:
        window = self.cfg["window"]
        pids = {name: self.stack.pid(name) for name in ("/interface", "/virtual_controller")}
        t0 = time.monotonic()
        cpu0 = {n: proc_stat(p) if p else None for n, p in pids.items()}
        own0 = time.process_time()
        time.sleep(window)
        t1 = time.monotonic()
        cpu1 = {n: proc_stat(p) if p else None for n, p in pids.items()}
        own1 = time.process_time()
        tick = os.sysconf("SC_CLK_TCK")
        out: Dict[str, Any] = {"window": t1 - t0, "cpu": {}, "pids": pids}
        for name in pids:
            a, b = cpu0[name], cpu1[name]
            out["cpu"][name] = None if not a or not b else 100.0 * (b[0] - a[0]) / tick / (t1 - t0)
        out["cpu"]["bench client"] = 100.0 * (own1 - own0) / (t1 - t0)
        for key, rec in (("joint_states", self.joints), ("robot_status", self.status)):
            msgs = rec.between(t0, t1)
            arr = [t for t, _m in msgs]
            stamps = [self.mono(m.header.stamp) for _t, m in msgs]
            gaps = [(b - a) * 1e3 for a, b in zip(arr, arr[1:])]
            pgaps = [(b - a) * 1e3 for a, b in zip(stamps, stamps[1:])]
            transport = [(t - s) * 1e3 for t, s in zip(arr, stamps)]
            out[key] = {"n": len(msgs), "rate": len(msgs) / (t1 - t0),
                        "gaps": stats(gaps), "pub_gaps": stats(pgaps), "transport": stats(transport)}
        last = self.diag.last()
        out["bus"] = {}
        if last is not None:
            for s in last.status:
                if s.name.endswith("link"):
                    out["bus"] = {kv.key: kv.value for kv in s.values}
        return out

    # -------------------------------------------------------------------------------- (a)
    def one_goal(self, target: Sequence[float]) -> Dict[str, Any]:
        from actionlib_msgs.msg import GoalStatus

        from vr_driver.msg import CartesianPose, MoveToPoseGoal
        goal = MoveToPoseGoal(target=CartesianPose(*[float(v) for v in target]), move_type=MoveToPoseGoal.LIN)
        feedback: List[Tuple[float, str]] = []

        def on_feedback(fb: Any) -> None:
            feedback.append((time.monotonic(), fb.phase))
        i_status, i_rosout, i_exec = self.status.mark(), self.rosout.mark(), self.executed.mark()
        t_send = time.monotonic()
        self.client.send_goal(goal, feedback_cb=on_feedback)
        if not self.client.wait_for_result(self.rospy.Duration(30.0)):
            self.client.cancel_goal()
            raise Failure("no result for the goal to %s within 30 s" % (target,))
        t_done = time.monotonic()
        state, result = self.client.get_state(), self.client.get_result()
        if state != GoalStatus.SUCCEEDED:
            raise Failure("the goal to %s ended in state %d: %s" % (target, state, result.reason if result else ""))
        rec: Dict[str, Any] = {"send": t_send, "done": t_done}
        moving = [t for t, phase in feedback if phase == "moving"]
        rec["fb_moving"] = moving[0] if moving else None
        hit = self.status.wait_for(lambda m: m.in_motion.val == self.TRUE, 0.0, i_status)
        rec["status_motion"] = hit[0] if hit else None
        rec["status_motion_pub"] = self.mono(hit[1].header.stamp) if hit else None
        entry = self.executed.wait_for(lambda m: json.loads(m.data)["outcome"] == "executed", 3.0, i_exec)
        if entry is not None:
            data = json.loads(entry[1].data)
            rec["busy"] = float(data["start_time"])
            rec["ctrl_end"] = float(data["time"])
        else:
            rec["busy"] = None
        sent = self.rosout.wait_for(lambda m: m.name == "/interface" and "sent target" in m.msg, 1.0, i_rosout)
        rec["sent"] = self.mono(sent[1].header.stamp) if sent else None
        return rec

    def goals(self) -> Dict[str, Any]:
        n = self.cfg["goals"]
        self.wait_motion_possible("before the warm-up goal")
        self.one_goal(A_POSE)                                    # warm-up from home, not counted
        recs = []
        settle = 3.0 / self.cfg["cycle_rate"]
        for i in range(n):
            self.wait_motion_possible("before goal %d" % (i + 1))
            # the driver releases the handshake 2 bus cycles after it reports a goal done (flag 0
            # out, controller READY back): a goal sent earlier waits for that, not for the bus
            time.sleep(settle + self.rng.uniform(0.0, 0.1))
            recs.append(self.one_goal(B_POSE if i % 2 == 0 else A_POSE))

        def since_send(key: str) -> List[float]:
            return [(r[key] - r["send"]) * 1e3 for r in recs if r.get(key) is not None]
        out = {"n": n,
               "sent": stats(since_send("sent")),
               "busy": stats(since_send("busy")),
               "fb_moving": stats(since_send("fb_moving")),
               "status_motion": stats(since_send("status_motion")),
               "status_motion_pub": stats(since_send("status_motion_pub")),
               "busy_to_fb": stats([(r["fb_moving"] - r["busy"]) * 1e3 for r in recs
                                    if r.get("busy") is not None and r.get("fb_moving") is not None]),
               "busy_to_status": stats([(r["status_motion"] - r["busy"]) * 1e3 for r in recs
                                        if r.get("busy") is not None and r.get("status_motion") is not None]),
               "motion": stats([(r["ctrl_end"] - r["busy"]) * 1e3 for r in recs if r.get("busy") is not None]),
               "goal_total": stats([(r["done"] - r["send"]) * 1e3 for r in recs])}
        consistent = [r for r in recs if r.get("busy") is not None and r.get("fb_moving") is not None
                      and r["send"] <= r["busy"] <= r["fb_moving"]]
        out["clock_ok"] = len(consistent)
        out["clock_n"] = sum(1 for r in recs if r.get("busy") is not None and r.get("fb_moving") is not None)
        for key, what in (("busy", "controller BUSY (execution log)"), ("fb_moving", 'feedback "moving"'),
                          ("status_motion", "robot_status in_motion TRUE"), ("sent", 'rosout "sent target"')):
            missing = n - out[key]["n"] if out[key].get("n") else n
            if missing:
                self.failures.append("%s missing for %d of %d goals" % (what, missing, n))
        return out

    # -------------------------------------------------------------------------------- (b)
    def estop_once(self, pressed: bool) -> Dict[str, Optional[float]]:
        want = self.TRUE if pressed else self.FALSE
        words = "e-stop pressed" if pressed else "e-stop released"
        i_status, i_rosout = self.status.mark(), self.rosout.mark()
        t0 = time.monotonic()
        resp = self.set_estop(pressed)
        t1 = time.monotonic()
        if not resp.success:
            raise Failure("set_estop(%s) failed: %s" % (pressed, resp.message))
        hit = self.status.wait_for(lambda m: m.e_stopped.val == want, 5.0, i_status)
        if hit is None:
            raise Failure("robot_status never showed e_stopped %s within 5 s" % ("TRUE" if pressed else "FALSE"))
        log = self.rosout.wait_for(lambda m: m.name == "/virtual_controller" and words in m.msg, 2.0, i_rosout)
        t_log = self.mono(log[1].header.stamp) if log else None
        t_pub = self.mono(hit[1].header.stamp)
        return {"call": (t1 - t0) * 1e3, "from_ret": (hit[0] - t1) * 1e3, "from_call": (hit[0] - t0) * 1e3,
                "from_log": None if t_log is None else (hit[0] - t_log) * 1e3,
                "pub_from_log": None if t_log is None else (t_pub - t_log) * 1e3,
                "log_in_call": None if t_log is None else float(t0 <= t_log <= t1)}

    def estops(self) -> Dict[str, Any]:
        recs: Dict[bool, List[Dict[str, Optional[float]]]] = {True: [], False: []}
        for i in range(self.cfg["estops"]):
            self.wait_motion_possible("before e-stop %d" % (i + 1))
            time.sleep(self.rng.uniform(0.0, 0.1))
            recs[True].append(self.estop_once(True))
            time.sleep(self.rng.uniform(0.05, 0.15))
            recs[False].append(self.estop_once(False))
            resp = self.set_drives(True)          # released, the drives stay off (as on a G2)
            if not resp.success:
                raise Failure("set_drives_powered(True) failed: %s" % resp.message)
        out: Dict[str, Any] = {"n": self.cfg["estops"]}
        for pressed, key in ((True, "set"), (False, "clear")):
            for field in ("call", "from_ret", "from_call", "from_log", "pub_from_log"):
                out["%s_%s" % (key, field)] = stats([r[field] for r in recs[pressed] if r[field] is not None])
            out["%s_log_in_call" % key] = sum(1 for r in recs[pressed] if r["log_in_call"])
        missing = sum(1 for p in (True, False) for r in recs[p] if r["from_log"] is None)
        if missing:
            self.failures.append("the virtual controller's e-stop log line missing %d times" % missing)
        self.wait_motion_possible("after the e-stops")
        return out

    # -------------------------------------------------------------------------------- (d)
    def joint_command_once(self, sign: float) -> Dict[str, Optional[float]]:
        from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
        rest = self.joints.last()
        if rest is None:
            raise Failure("no joint_states")
        q0 = list(rest.position)
        target = list(q0)
        target[0] += sign * math.radians(JOG_STEP_DEG)
        msg = JointTrajectory()
        msg.joint_names = list(rest.name)
        msg.points = [JointTrajectoryPoint(positions=target, time_from_start=self.rospy.Duration(0.05))]
        i_js, i_exec = self.joints.mark(), self.executed.mark()
        msg.header.stamp = self.rospy.Time.now()
        t_pub = time.monotonic()
        self.joint_command.publish(msg)
        moved = self.joints.wait_for(lambda m: abs(m.position[0] - q0[0]) > math.radians(0.001), 3.0, i_js)
        entry = self.executed.wait_for(lambda m: True, 3.0, i_exec)
        if moved is None or entry is None:
            raise Failure("joint_command to joint_1 %+g deg: %s" % (
                sign * JOG_STEP_DEG, "joint_states never showed motion" if moved is None
                else "no execution-log entry (the controller never took it)"))
        data = json.loads(entry[1].data)
        return {"taken": (float(data["taken_time"]) - t_pub) * 1e3,
                "js_stamp": (self.mono(moved[1].header.stamp) - t_pub) * 1e3,
                "js_arrival": (moved[0] - t_pub) * 1e3,
                "taken_to_js": (self.mono(moved[1].header.stamp) - float(data["taken_time"])) * 1e3,
                "outcome": data["outcome"]}

    def joint_commands(self) -> Dict[str, Any]:
        timeout = float(self.rospy.get_param("/interface/joint_command_timeout", 0.2))
        recs = []
        for i in range(self.cfg["joint_commands"]):
            self.wait_motion_possible("before joint command %d" % (i + 1))
            time.sleep(timeout + 0.1 + self.rng.uniform(0.0, 0.1))      # the previous stream ended
            recs.append(self.joint_command_once(1.0 if i % 2 == 0 else -1.0))
        out: Dict[str, Any] = {"n": len(recs), "timeout": timeout}
        for key in ("taken", "js_stamp", "js_arrival", "taken_to_js"):
            out[key] = stats([r[key] for r in recs])
        out["outcomes"] = sorted({r["outcome"] for r in recs})
        return out

    # -------------------------------------------------------------------------------- report
    def run(self) -> Dict[str, Any]:
        started = time.monotonic()
        ready = self.wait_ready()
        print("ready %.1f s after roslaunch (action server, set_estop service, motion_possible TRUE); "
              "interface pid %s, virtual_controller pid %s"
              % (ready, self.stack.pid("/interface"), self.stack.pid("/virtual_controller")), flush=True)
        time.sleep(1.0)                                          # let the start-up settle
        idle = self.idle_window()
        self.print_idle(idle)
        goals = estops = None
        if not self.cfg["joint_only"]:
            goals = self.goals()
            self.print_goals(goals)
            estops = self.estops()
            self.print_estops(estops)
        joint = None
        if self.cfg["protocol"] != "v1" and self.cfg["joint_commands"] > 0:
            joint = self.joint_commands()
            self.print_joint_commands(joint)
        else:
            print("(d) joint_command: skipped (protocol %s cannot stream: the topic refuses every "
                  "command)\n" % self.cfg["protocol"], flush=True)
        for failure in self.failures:
            print("FAILED: %s" % failure)
        print("this configuration: %.1f s" % (time.monotonic() - started), flush=True)
        return {"baud": self.cfg["baud"], "cycle_rate": self.cfg["cycle_rate"], "idle": idle, "goals": goals,
                "estops": estops, "joint": joint, "protocol": self.cfg["protocol"], "paced": self.cfg["paced"],
                "failures": self.failures}

    @staticmethod
    def print_joint_commands(j: Dict[str, Any]) -> None:
        print("(d) joint_command -> controller -> joint_states: %d commands, joint_1 +-%g deg from rest, "
              "a new stream each (joint_command_timeout %g s)" % (j["n"], JOG_STEP_DEG, j["timeout"]))
        print(header())
        print(row("publish -> controller takes it (execution-log taken_time)", j["taken"]))
        print(row("publish -> joint_states shows motion (its stamp)", j["js_stamp"]))
        print(row("publish -> joint_states shows motion (arrival here)", j["js_arrival"]))
        print(row("controller takes it -> joint_states shows motion (stamp)", j["taken_to_js"]))
        print("outcomes in the execution log: %s" % ", ".join(j["outcomes"]))
        print(flush=True)

    @staticmethod
    def print_idle(idle: Dict[str, Any]) -> None:
        print("(c) idle window %.1f s: topic rates and inter-arrival jitter" % idle["window"])
        print("%-13s %5s %8s %9s %9s %9s %9s   %s" % ("topic", "msgs", "rate Hz", "mean ms", "sd ms",
                                                     "min ms", "max gap", "publisher stamps: sd / max gap ms"))
        for key in ("joint_states", "robot_status"):
            t = idle[key]
            g, p = t["gaps"], t["pub_gaps"]
            if not g.get("n"):
                print("%-13s %5d %8.2f   (too few messages)" % (key, t["n"], t["rate"]))
                continue
            print("%-13s %5d %8.2f %9.2f %9.2f %9.2f %9.2f   %.2f / %.2f"
                  % (key, t["n"], t["rate"], g["mean"], g["sd"], g["min"], g["max"],
                     p.get("sd", float("nan")), p.get("max", float("nan"))))
        for key in ("joint_states", "robot_status"):
            print("transport %-13s header stamp -> arrival here: %s ms (median / p95 / max (n))"
                  % (key, fmt(idle[key]["transport"])))
        for name in ("/interface", "/virtual_controller", "bench client"):
            value = idle["cpu"].get(name)
            pid = idle["pids"].get(name)
            print("CPU %-20s %s %% of one core%s" % (name, "n/a" if value is None else "%5.1f" % value,
                                                     " (pid %d, /proc/%d/stat utime+stime)" % (pid, pid) if pid
                                                     else " (time.process_time)"))
        bus = idle["bus"]
        if bus:
            print("driver bus (/diagnostics): %s cycles/s, cycles %s, retries %s, timeouts %s, slave %s"
                  % (bus.get("cycle rate [1/s]", "?"), bus.get("bus cycles", "?"), bus.get("bus retries", "?"),
                     bus.get("bus timeouts", "?"), bus.get("slave state", "?")))
        print(flush=True)

    @staticmethod
    def print_goals(g: Dict[str, Any]) -> None:
        print("(a) move_to_pose goal -> BUSY: %d LIN goals (+-50 mm in y, 1 warm-up goal not counted)" % g["n"])
        print(header())
        print(row("send_goal -> driver hands target to the bus (rosout stamp)", g["sent"]))
        print(row("send_goal -> controller BUSY (execution-log start_time)", g["busy"]))
        print(row('send_goal -> client: first feedback phase "moving"', g["fb_moving"]))
        print(row("send_goal -> driver publishes in_motion TRUE (stamp)", g["status_motion_pub"]))
        print(row("send_goal -> client: first robot_status in_motion TRUE", g["status_motion"]))
        print(row('controller BUSY -> client: feedback "moving"', g["busy_to_fb"]))
        print(row("controller BUSY -> client: robot_status in_motion TRUE", g["busy_to_status"]))
        print(row("controller motion (start_time -> end time)", g["motion"]))
        print(row("send_goal -> result (whole goal)", g["goal_total"]))
        print("clock check: send_goal <= controller start_time <= feedback \"moving\" for %d of %d goals "
              "(CLOCK_MONOTONIC is shared between processes)" % (g["clock_ok"], g["clock_n"]))
        print(flush=True)

    @staticmethod
    def print_estops(e: Dict[str, Any]) -> None:
        print("(b) e-stop -> robot_status: %d presses and %d releases via /virtual_controller/set_estop"
              % (e["n"], e["n"]))
        print(header())
        for key, words, flag in (("set", "press", "TRUE"), ("clear", "release", "FALSE")):
            print(row("%s: set_estop service call (call -> return)" % words, e["%s_call" % key]))
            print(row("%s: controller log -> driver publishes e_stopped %s" % (words, flag),
                      e["%s_pub_from_log" % key]))
            print(row("%s: controller log -> client: e_stopped %s" % (words, flag), e["%s_from_log" % key]))
            print(row("%s: service return -> client: e_stopped %s" % (words, flag), e["%s_from_ret" % key]))
        print("controller log stamp inside the service call for %d + %d of %d + %d"
              % (e["set_log_in_call"], e["clear_log_in_call"], e["n"], e["n"]))
        print(flush=True)


# ------------------------------------------------------------------------------------------ parent

def summary(results: List[Dict[str, Any]]) -> None:
    cols = ["%d Bd, %g Hz, %s%s" % (r["baud"], r["cycle_rate"], r["protocol"], " paced" if r["paced"] else "")
            for r in results]
    width = max(32, *(len(c) for c in cols))
    print("=== summary: median / p95 / max ms (n); rates over the idle window")
    print(("%-44s" % "metric" + "".join(" %-*s" % (width, c) for c in cols)).rstrip())

    def line(label: str, cells: List[str]) -> None:
        print(("%-44s" % label + "".join(" %-*s" % (width, c) for c in cells)).rstrip())
    def part(key: str, field: str) -> List[str]:
        return [fmt(r[key][field]) if r.get(key) else "-" for r in results]
    if any(r.get("goals") for r in results):
        line("goal -> driver hands target to the bus", part("goals", "sent"))
        line("goal -> controller BUSY", part("goals", "busy"))
        line("goal -> feedback moving", part("goals", "fb_moving"))
        line("goal -> robot_status in_motion", part("goals", "status_motion"))
        line("e-stop press (ctrl log) -> robot_status", part("estops", "set_from_log"))
        line("e-stop press (svc return) -> robot_status", part("estops", "set_from_ret"))
        line("e-stop release (ctrl log) -> robot_status", part("estops", "clear_from_log"))
    if any(r.get("joint") for r in results):
        line("joint_command -> controller takes it", part("joint", "taken"))
        line("joint_command -> joint_states motion (stamp)", part("joint", "js_stamp"))
        line("joint_command -> joint_states motion (here)", part("joint", "js_arrival"))

    def rate(r: Dict[str, Any], key: str) -> str:
        t = r["idle"][key]
        g = t["gaps"]
        if not g.get("n"):
            return "%.2f Hz" % t["rate"]
        return "%.2f Hz, sd %.1f, max gap %.1f" % (t["rate"], g["sd"], g["max"])
    line("joint_states rate, jitter sd, max gap (ms)", [rate(r, "joint_states") for r in results])
    line("robot_status rate, jitter sd, max gap (ms)", [rate(r, "robot_status") for r in results])

    def cpu(r: Dict[str, Any], name: str) -> str:
        v = r["idle"]["cpu"].get(name)
        return "n/a" if v is None else "%.1f %%" % v
    line("interface CPU idle (% of one core)", [cpu(r, "/interface") for r in results])
    line("virtual_controller CPU idle", [cpu(r, "/virtual_controller") for r in results])


def run_worker(cfg: Dict[str, Any], script: str = __file__, tag: str = RESULT_TAG
               ) -> Tuple[int, Optional[Dict[str, Any]]]:
    """Run one configuration in a worker process (``script --worker CFG``, its own session and process
    group: a Ctrl-C reaches this process only, which passes it on once) and relay its output; (exit
    status, the result the worker printed after ``tag``). Also bench/trajectory.py's runner.
    start_new_session, not process_group= (Python 3.11+): the benchmark runs on 3.8."""
    proc = subprocess.Popen([sys.executable, os.path.abspath(script), "--worker", json.dumps(cfg)],
                            stdout=subprocess.PIPE, text=True, bufsize=1, start_new_session=True)
    result = None
    forwarded = False
    while True:
        try:
            for text in proc.stdout:
                if text.startswith(tag):
                    result = json.loads(text[len(tag):])
                else:
                    sys.stdout.write(text)
                    sys.stdout.flush()
            return proc.wait(), result
        except KeyboardInterrupt:
            if not forwarded and proc.poll() is None:
                forwarded = True
                try:
                    proc.send_signal(signal.SIGINT)
                except ProcessLookupError:
                    pass
            continue


def main(argv: Optional[List[str]] = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--worker"]:
        return worker(json.loads(argv[1]))
    sigs = [signal.SIGTERM, signal.SIGHUP]
    if signal.getsignal(signal.SIGINT) is not signal.SIG_IGN:   # respect a shell that ignores it
        sigs.append(signal.SIGINT)
    interrupt_once(sigs)
    baud0, rate0 = launch_defaults()
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--goals", type=int, default=20, help="move_to_pose goals measured (default 20)")
    p.add_argument("--estops", type=int, default=20, help="e-stop press/release pairs (default 20)")
    p.add_argument("--window", type=float, default=10.0, help="idle window for rates and CPU [s] (default 10)")
    p.add_argument("--baud", type=int, default=baud0, help="PROFIBUS bit rate (default the launch's, %d)" % baud0)
    p.add_argument("--cycle-rate", type=float, default=rate0,
                   help="bus cycles per second (default the launch's, %g)" % rate0)
    p.add_argument("--both", action="store_true", help="then also a run at %d bit/s, %g Hz" % FAST)
    p.add_argument("--speed-factor", type=float, default=1.0, help="virtual controller speed factor (default 1)")
    p.add_argument("--ros-port", type=int, default=0, help="ROS master port (default: a free one from 11700)")
    p.add_argument("--seed", type=int, default=1, help="random pauses' seed (default 1)")
    p.add_argument("--keep-logs", action="store_true", help="keep the ROS logs (roslaunch, nodes) and print where")
    p.add_argument("--quick", action="store_true", help="smoke run: 3 goals, 2 e-stops, a 2 s window")
    p.add_argument("--protocol", default="v1", choices=("v1", "v2", "v3"),
                   help="controller protocol (default v1; (d) joint_command needs v2 or v3)")
    p.add_argument("--joint-commands", type=int, default=20,
                   help="(d) joint_command messages measured with v2 / v3 (default 20; 0: none)")
    p.add_argument("--joint-only", action="store_true", help="skip (a) goals and (b) e-stops")
    p.add_argument("--paced", action="store_true",
                   help="the virtual line carries the bytes at --baud (io:=true line_baud:=BAUD)")
    args = p.parse_args(argv)
    if args.quick:
        args.goals, args.estops, args.window = 3, 2, 2.0
        args.joint_commands = min(args.joint_commands, 3)
    if args.goals < 1 or args.estops < 1 or args.window <= 0:
        p.error("--goals and --estops must be >= 1, --window > 0")
    configs = [(args.baud, args.cycle_rate)]
    if args.both and configs[0] != FAST:
        configs.append(FAST)
    started = time.perf_counter()
    print("driver latency benchmark: driver.launch sim:=true, %d goals, %d e-stops, %.1f s idle window; "
          "%d configuration(s), each with its own roscore + launch"
          % (args.goals, args.estops, args.window, len(configs)),
          flush=True)
    print("clocks: arrivals here and the controller's start_time on CLOCK_MONOTONIC (time.monotonic(), one "
          "clock for all processes); rosout and header stamps on the wall clock (rospy time), mapped onto "
          "it with one offset", flush=True)
    results, status = [], 0
    for i, (baud, rate) in enumerate(configs):
        cfg = {"baud": baud, "cycle_rate": rate, "goals": args.goals, "estops": args.estops, "window": args.window,
               "speed_factor": args.speed_factor, "ros_port": args.ros_port, "seed": args.seed + i,
               "keep_logs": args.keep_logs, "protocol": args.protocol, "joint_commands": args.joint_commands,
               "joint_only": args.joint_only, "paced": args.paced}
        code, result = run_worker(cfg)
        if code == 130:
            print("interrupted")
            return 130
        if code != 0 or result is None:
            status = 1
        if result is not None:
            results.append(result)
    if results:
        summary(results)
    print("python %s, %d CPUs, load %.2f, wall time %.1f s%s"
          % (sys.version.split()[0], os.cpu_count() or 0, os.getloadavg()[0], time.perf_counter() - started,
             "; FAILED (see above)" if status else ""))
    return status


if __name__ == "__main__":
    sys.exit(main())
