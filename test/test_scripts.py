"""The user-facing scripts: help, clear errors, and the workspace environment they provide."""
import io
import os
import re
import select
import signal
import subprocess
import time
import unittest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def signal_state(root_pid):
    """For a failed Ctrl-C: each process below ``root_pid`` with its process group, the foreground
    process group of its terminal (``tpgid``: the group a Ctrl-C signals) and its SIGINT bit in the
    blocked / ignored / caught masks -- what decides whether a Ctrl-C reaches it (/proc)."""
    lines, todo = [], [root_pid]
    while todo:
        pid = todo.pop()
        try:
            with open("/proc/%d/stat" % pid) as f:
                fields = f.read().rsplit(")", 1)[1].split()
            with open("/proc/%d/status" % pid) as f:
                masks = dict(line.split(":\t", 1) for line in f.read().splitlines() if ":\t" in line)
            with open("/proc/%d/cmdline" % pid, "rb") as f:
                cmd = f.read().replace(b"\0", b" ").decode(errors="replace")[:90]
            with open("/proc/%d/task/%d/children" % (pid, pid)) as f:
                todo += [int(c) for c in f.read().split()]
        except OSError as exc:
            lines.append("pid %d: %s" % (pid, exc))
            continue
        sigint = 1 << (signal.SIGINT - 1)
        bits = ", ".join("%s %d" % (k, bool(int(masks.get(k, "0"), 16) & sigint)) for k in ("SigBlk", "SigIgn", "SigCgt"))
        lines.append("pid %d pgrp %s tpgid %s SIGINT: %s  %s" % (pid, fields[2], fields[5], bits, cmd))
    return "\n".join(lines)


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

    def test_env_passes_option_arguments_through(self):
        """devel/setup.bash must not see the command's own options (it used to choke on --help)."""
        res = script("env", "python3", "-c", "import sys; print(sys.argv[1:])", "--help", "-x")
        self.assertEqual(res.returncode, 0, res.stderr)
        self.assertEqual(res.stdout.strip(), "['--help', '-x']")

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
        """--no-terminal: the launch alone in the foreground, as before the pose terminal existed."""
        proc = subprocess.Popen([os.path.join(REPO, "scripts", "run"), "--no-terminal", "--ros-port", "11533",
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

    def test_run_opens_the_pose_terminal_and_stops_everything_when_it_is_left(self):
        """The README's first command, as a person uses it: one call, the driver and the virtual
        controller come up behind the pose terminal; a move; Ctrl-C during a move stops the arm
        (and only the move: the driver stays); Ctrl-C at a prompt abandons the entry, not the session;
        quit leaves and stops everything."""
        import pexpect
        marker = "/tmp/vr006l_test_run_terminal_%d" % os.getpid()
        child = pexpect.spawn(os.path.join(REPO, "scripts", "run"),
                              ["--ros-port", "11536", "sim_port:=" + marker, "baud:=187500", "cycle_rate:=50"],
                              encoding="utf-8", timeout=120, dimensions=(50, 160))
        child.logfile_read = io.StringIO()

        def expect(pattern, timeout=60):
            try:
                return child.expect(pattern, timeout=timeout)
            except (pexpect.TIMEOUT, pexpect.EOF) as exc:
                self.fail("waited for %r (%s); scripts/run showed:\n%s"
                          % (pattern, type(exc).__name__, child.logfile_read.getvalue()[-3000:]))

        prompt = r"X \[mm, 100\.\.1400\] \([-0-9.]+\): "
        try:
            expect(r"\[run\] their output goes to (\S+\.log)", timeout=300)      # after scripts/setup
            log = child.match.group(1)
            # the terminal gives the driver 10 s to report motion possible after it connected; on a
            # loaded machine it may say not yet, and 'status' shows when it is
            ready = expect([r"Controller ready: motion possible; the arm is at X 1120  Y 0  Z 725  Rx 0  Ry 45  Rz 0",
                            r"Motion is not possible now|No robot_status from the driver yet"])
            expect(prompt)
            end = time.monotonic() + 60
            while ready != 0 and time.monotonic() < end:
                child.sendline("status")
                ready = 0 if expect([r"motion possible: yes", r"motion possible: [^y]|No robot_status"]) == 0 else 1
                expect(prompt)
                if ready != 0:
                    time.sleep(1.0)                 # (the terminal has no event to wait on: ask again)
            self.assertEqual(ready, 0, "motion never became possible: " + child.logfile_read.getvalue()[-3000:])
            child.sendline("1000 200 800 0 45 0 lin")
            expect(r"Preview: reachable")
            expect(r"\[y/N\]: ")
            child.sendline("y")
            expect(r"moving +distance to go")
            expect(r"Reached X 1000  Y 200  Z 800  Rx 0  Ry 45  Rz 0")
            expect(prompt)
            # Ctrl-C during a move stops it; a move that ended before the Ctrl-C reached it (a loaded
            # machine can hold this test back for the whole move) says "Reached": then again, the
            # other way (at most 3 moves)
            for target in ("1000 -600 800 0 45 0 lin", "1000 600 800 0 45 0 lin", "1000 -600 800 0 45 0 lin"):
                child.sendline(target)                                     # 3-4.5 s
                expect(r"\[y/N\]: ")
                child.sendline("y")
                expect(r"moving +distance to go")
                child.sendintr()
                stopped = expect([r"Stopped at X ", r"Reached X "]) == 0
                expect(prompt)
                if stopped:
                    break
            if not stopped:
                # the whole dialogue from the first Ctrl-C on (progress lines left out), and who
                # a Ctrl-C signals now: a Ctrl-C that never stops a move is a bug to find
                said = child.logfile_read.getvalue()
                said = "\n".join(line for line in said[said.find("1000 -600 800"):].splitlines()
                                  if "distance to go" not in line)
                self.fail("3 moves ended before the Ctrl-C:\n%s\n%s" % (said[-6000:], signal_state(child.pid)))
            child.sendline("status")                                       # the driver survived the Ctrl-C
            expect(r"motion possible: yes")
            expect(prompt)
            child.sendline("1000")
            expect(r"Y \[mm")
            child.sendintr()                                               # Ctrl-C at a prompt: the entry only
            expect(r"Entry abandoned")
            expect(prompt)
            child.sendline("quit")                                         # leave
            expect(r"Bye\.")
            expect(r"\[run\] stopping the driver and the virtual controller")
            expect(r"\[run\] stopped \(log: ")
            expect(pexpect.EOF)
        finally:
            if child.isalive():
                child.kill(signal.SIGINT)
            child.close()
        self.assertEqual(child.exitstatus, 0, child.logfile_read.getvalue()[-3000:])
        self.assertFalse(os.path.exists(marker))                           # pty link removed
        self.assertEqual(processes_mentioning(marker), [])                 # no orphans
        with open(log) as f:
            self.assertIn("controller connected: READY", f.read())

    def test_run_says_when_the_driver_does_not_come_up(self):
        marker = "/tmp/vr006l_test_run_broken_%d.yaml" % os.getpid()
        res = script("run", "--ros-port", "11537", "--wait", "30", "config:=" + marker, timeout=300)
        self.assertEqual(res.returncode, 3, res.stdout + res.stderr)
        self.assertIn("has ended before", res.stderr)
        self.assertRegex(res.stderr, r"\[run\] ERROR: the driver did not come up .*run-[0-9-]+\.log")
        self.assertIn(marker, res.stderr)                                   # the log's last lines say why
        self.assertEqual(processes_mentioning(marker), [])


class TfToolsTest(unittest.TestCase):
    """The README names the tf tools (rosrun tf tf_echo ...); scripts/setup installs them (Debian tf-tools)."""

    def test_every_tf_tool_the_readme_names_runs(self):
        with open(os.path.join(REPO, "README.md")) as f:
            tools = sorted(set(re.findall(r"rosrun tf (\w+)", f.read())))
        self.assertIn("tf_echo", tools)
        for name in tools:
            res = script("env", "bash", "-c", 'p=$(catkin_find --libexec tf "$1" | head -n 1); '
                         'test -x "$p" && echo "$p" && rospack find tf', "-", name)
            self.assertEqual(res.returncode, 0, "rosrun tf %s: not installed (scripts/setup installs tf-tools)\n%s"
                             % (name, res.stderr))
        res = script("env", "rosrun", "tf", "tf_echo", timeout=60)          # no frames given: its usage
        self.assertIn("Usage: tf_echo source_frame target_frame", res.stdout + res.stderr)

    def test_setup_installs_the_tf_tools(self):
        res = script("setup", "--check", env={"VR_SETUP_EXTRA_APT": ""})
        with open(os.path.join(REPO, "scripts", "setup")) as f:
            text = f.read()
        self.assertRegex(text, r"\btf-tools\b")
        self.assertNotIn("tf-tools", res.stdout)                              # present after setup


def processes_mentioning(text):
    """PIDs of the live processes whose command line contains ``text``."""
    found = []
    for pid in os.listdir("/proc"):
        if not pid.isdigit() or int(pid) == os.getpid():
            continue
        try:
            with open("/proc/%s/cmdline" % pid, "rb") as f:
                cmdline = f.read().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        if text in cmdline:
            found.append(int(pid))
    return found

if __name__ == "__main__":
    unittest.main()
