"""scripts/install-cell into a throw-away root: every file it writes, checked (the udev rule and the
limits line parsed, the units parsed and, where the machine has it, `systemd-analyze verify`; the
YAMLs byte for byte), the list it shows before changing, bad input refused with nothing written,
a second install that changes nothing, and the uninstall. The units run against the virtual G2:
test_cell_service.py."""
import os
import pwd
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
import unittest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _unit_supervisor import parse_unit  # noqa: E402

INSTALL = os.path.join(REPO, "scripts", "install-cell")
USER = pwd.getpwuid(os.getuid()).pw_name
CONFIG = os.path.join(REPO, "vr_driver/config/vr_driver.yaml")
MODEL = os.path.join(REPO, "panasonic_vr006l_support/config/kinematics_vr006l.yaml")
SCENE = os.path.join(REPO, "panasonic_vr006l_support/config/cell_example.yaml")
LIMITS_SRC = os.path.join(REPO, "panasonic_vr006l_moveit_config/config/joint_limits.yaml")
WRITTEN = ["etc/udev/rules.d/70-vr006l-bus.rules", "etc/security/limits.d/vr006l.conf",
           "etc/vr006l/vr_driver.yaml", "etc/vr006l/commissioning.yaml", "etc/vr006l/model.yaml",
           "etc/vr006l/scene.yaml", "etc/vr006l/joint_limits.yaml", "etc/vr006l/cell.env",
           "etc/systemd/system/vr006l-master.service", "etc/systemd/system/vr006l-driver.service",
           "etc/vr006l/installed"]
# a udev rule line: comma-separated KEY{attr}OP"value"; the keys and operators udev(7) knows that we use
UDEV_KEY = re.compile(r'\s*(ACTION|SUBSYSTEM|DRIVER|ATTRS\{[a-zA-Z_]+\}|ATTR\{[a-zA-Z_/]+\}|ENV\{[A-Z_]+\}|SYMLINK|'
                      r'GROUP|MODE|TAG|RUN)(==|!=|\+=|=)"([^"]*)"\s*$')
MATCH_ONLY = ("ACTION", "SUBSYSTEM", "DRIVER", "ATTRS")


def install(*args, root, stdin=None):
    return subprocess.run([INSTALL, "--root", root] + list(args), capture_output=True, text=True,
                          input=stdin, timeout=60)


def files_under(root):
    return sorted(os.path.relpath(os.path.join(d, f), root) for d, _, fs in os.walk(root) for f in fs)


def udev_rules(text):
    """Each rule (not a comment) as a list of (key, operator, value); AssertionError on a bad line."""
    rules = []
    for line in text.splitlines():
        if not line.strip() or line.startswith("#"):
            continue
        pairs = []
        for part in line.split('", '):
            part = part if part.endswith('"') else part + '"'
            m = UDEV_KEY.match(part)
            assert m, "not a udev key we know: %r in %r" % (part, line)
            key, op, value = m.groups()
            if key.startswith(MATCH_ONLY):
                assert op in ("==", "!="), "operator %s on %s" % (op, key)
            elif not key.startswith("ENV{"):                    # ENV: a match or an assignment
                assert op in ("=", "+="), "operator %s on %s" % (op, key)
            pairs.append((key, op, value))
        rules.append(pairs)
    return rules


class InstallCellTest(unittest.TestCase):
    def setUp(self):
        self.root = tempfile.mkdtemp(prefix="vr006l_cell_root_")
        self.addCleanup(shutil.rmtree, self.root, True)
        src = tempfile.mkdtemp(prefix="vr006l_cell_src_")
        self.addCleanup(shutil.rmtree, src, True)
        self.commissioning = os.path.join(src, "g2.yaml")
        with open(self.commissioning, "w") as f:
            f.write("protocol: v3\nstream_smooth: 2\n")
        shutil.copy(LIMITS_SRC, os.path.join(src, "joint_limits.yaml"))
        self.full = ["--adapter-serial", "FT1TEST9", "--product", "6001", "--user", USER,
                     "--config", CONFIG, "--commissioning", self.commissioning, "--model", MODEL,
                     "--scene", SCENE, "--ros-port", "11411", "--ros-ip", "192.168.7.2",
                     "--arg", "baud:=187500"]

    def path(self, rel):
        return os.path.join(self.root, rel)

    def read(self, rel):
        with open(self.path(rel)) as f:
            return f.read()

    def test_every_file_it_writes(self):
        res = install(*self.full, "--yes", root=self.root)
        self.assertEqual(res.returncode, 0, res.stdout + res.stderr)
        self.assertEqual(files_under(self.root), sorted(WRITTEN))
        for rel in WRITTEN:                                        # each one listed before it was written
            self.assertIn("write %s " % self.path(rel), res.stdout.split("done:")[0], rel)
        self.assertEqual(sorted(self.read("etc/vr006l/installed").split("\n")[1:-1]), sorted("/" + w for w in WRITTEN))
        for src, rel in ((CONFIG, "vr_driver.yaml"), (self.commissioning, "commissioning.yaml"), (MODEL, "model.yaml"),
                         (SCENE, "scene.yaml"), (LIMITS_SRC, "joint_limits.yaml")):
            with open(src) as f:
                self.assertEqual(self.read("etc/vr006l/" + rel), f.read(), rel)
        for d in ("var/lib/vr006l", "var/log/vr006l"):             # ROS_HOME and the logs, the user's
            self.assertEqual(os.stat(self.path(d)).st_uid, os.getuid())

        # the udev rule: the adapter by its serial number, the name, the group, low latency
        rules = udev_rules(self.read("etc/udev/rules.d/70-vr006l-bus.rules"))
        self.assertEqual(len(rules), 2)
        tty, latency = (dict((k, (op, v)) for k, op, v in rule) for rule in rules)
        for rule in (tty, latency):
            self.assertEqual(rule["ATTRS{serial}"], ("==", "FT1TEST9"))
            self.assertEqual(rule["ATTRS{idVendor}"], ("==", "0403"))
            self.assertEqual(rule["ATTRS{idProduct}"], ("==", "6001"))
        self.assertEqual(tty["SUBSYSTEM"], ("==", "tty"))
        self.assertEqual(tty["SYMLINK"], ("+=", "vr006l_bus"))
        self.assertEqual((tty["GROUP"], tty["MODE"]), (("=", "dialout"), ("=", "0660")))
        self.assertEqual(tty["ENV{ID_MM_DEVICE_IGNORE}"], ("=", "1"))
        self.assertEqual((latency["SUBSYSTEM"], latency["DRIVER"]), (("==", "usb-serial"), ("==", "ftdi_sio")))
        self.assertEqual(latency["ATTR{latency_timer}"], ("=", "1"))
        if shutil.which("udevadm") and "verify" in subprocess.run(["udevadm", "--help"], capture_output=True,
                                                                  text=True).stdout:
            res = subprocess.run(["udevadm", "verify", self.path("etc/udev/rules.d/70-vr006l-bus.rules")],
                                 capture_output=True, text=True)
            self.assertEqual(res.returncode, 0, res.stdout + res.stderr)

        # limits.d: <user> - rtprio 20, the only rule
        lines = [l.split() for l in self.read("etc/security/limits.d/vr006l.conf").splitlines()
                 if l.strip() and not l.startswith("#")]
        self.assertEqual(lines, [[USER, "-", "rtprio", "20"]])

        env = dict(l.split("=", 1) for l in self.read("etc/vr006l/cell.env").splitlines() if l and l[0] != "#")
        self.assertEqual(env, {"ROS_MASTER_URI": "http://localhost:11411", "ROS_IP": "192.168.7.2",
                               "ROS_HOME": self.path("var/lib/vr006l"), "ROS_LOG_DIR": self.path("var/log/vr006l")})

        # the units: the driver's command line, its user, its restart rule, real-time, the master first
        master = parse_unit(self.path("etc/systemd/system/vr006l-master.service"))
        driver = parse_unit(self.path("etc/systemd/system/vr006l-driver.service"))
        scripts_env = os.path.join(REPO, "scripts", "env")
        self.assertEqual(shlex.split(master["Service"]["ExecStart"][0]), [scripts_env, "roscore", "-p", "11411"])
        etc = self.path("etc/vr006l/")
        self.assertEqual(shlex.split(driver["Service"]["ExecStart"][0]),
                         [scripts_env, "roslaunch", "--wait", "vr_driver", "driver.launch", "sim:=false",
                          "port:=" + self.path("dev/vr006l_bus"), "config:=%svr_driver.yaml" % etc,
                          "commissioning:=%scommissioning.yaml" % etc, "model:=%smodel.yaml" % etc,
                          "scene:=%sscene.yaml" % etc, "baud:=187500"])
        for unit in (master, driver):
            s = unit["Service"]
            self.assertEqual((s["User"], s["Restart"], s["RestartSec"], s["KillSignal"]),
                             ([USER], ["always"], ["1"], ["SIGINT"]))
            self.assertEqual(s["EnvironmentFile"], [self.path("etc/vr006l/cell.env")])
            self.assertEqual(s["Environment"], ["PYTHONUNBUFFERED=1"])
            self.assertEqual(unit["Install"]["WantedBy"], ["multi-user.target"])
            self.assertEqual(unit["Unit"]["StartLimitIntervalSec"], ["0"])
        self.assertEqual(driver["Service"]["LimitRTPRIO"], ["20"])
        self.assertEqual(driver["Service"]["SupplementaryGroups"], ["dialout"])
        self.assertEqual(driver["Unit"]["Requires"], ["vr006l-master.service"])
        self.assertIn("vr006l-master.service", driver["Unit"]["After"][0].split())
        if shutil.which("systemd-analyze"):
            res = subprocess.run(["systemd-analyze", "verify", self.path("etc/systemd/system/vr006l-master.service"),
                                  self.path("etc/systemd/system/vr006l-driver.service")],
                                 capture_output=True, text=True, timeout=60)
            self.assertEqual(res.returncode, 0, res.stderr)
            self.assertNotIn("vr006l-", res.stdout + res.stderr)     # no warning about our units

        # the same install again changes nothing; uninstall removes exactly what it wrote
        again = install(*self.full, "--yes", root=self.root)
        self.assertEqual((again.returncode, again.stdout.strip()), (0, "install-cell: nothing to change"))
        gone = install("--uninstall", "--yes", root=self.root)
        self.assertEqual(gone.returncode, 0, gone.stderr)
        self.assertEqual(files_under(self.root), [])
        self.assertFalse(os.path.exists(self.path("etc/vr006l")))

    def test_help_names_every_file_it_writes(self):
        res = subprocess.run([INSTALL, "--help"], capture_output=True, text=True, timeout=30)
        self.assertEqual(res.returncode, 0, res.stderr)
        self.assertIn("scripts/install-cell", res.stdout)
        for rel in WRITTEN[:2] + WRITTEN[-3:-1]:
            self.assertIn("/" + rel, res.stdout)

    def test_dry_run_and_a_no_at_the_prompt_change_nothing(self):
        dry = install(*self.full, "--dry-run", root=self.root)
        self.assertEqual(dry.returncode, 0, dry.stderr)
        self.assertEqual(files_under(self.root), [])
        for rel in WRITTEN:
            self.assertIn("write " + self.path(rel), dry.stdout)
        in_dialout = "dialout" in subprocess.run(["id", "-nG", USER], capture_output=True, text=True).stdout.split()
        self.assertEqual("usermod -aG dialout " + USER in dry.stdout, not in_dialout)
        self.assertIn("systemctl enable vr006l-master.service vr006l-driver.service", dry.stdout)
        self.assertIn("systemctl restart vr006l-driver.service", dry.stdout)
        no = install(*self.full, root=self.root, stdin="n\n")
        self.assertEqual(no.returncode, 1)
        self.assertIn("Change these? [y/N]", no.stdout)
        self.assertEqual(files_under(self.root), [])

    def test_bad_input_is_refused_and_nothing_is_written(self):
        bad_yaml = os.path.join(self.root, "..", os.path.basename(self.root) + "_bad.yaml")
        with open(bad_yaml, "w") as f:
            f.write("a: [1, 2\n")
        self.addCleanup(os.remove, bad_yaml)
        greedy = os.path.join(self.root, "..", os.path.basename(self.root) + "_rt30.yaml")
        with open(greedy, "w") as f:
            f.write("bus_rt_priority: 30\n")
        self.addCleanup(os.remove, greedy)
        cases = [(["--adapter-serial", 'FT1"; RUN+="/bin/sh'], "--adapter-serial"),
                 (["--adapter-serial", "FT1", "--config", greedy], "below the config's bus_rt_priority 30"),
                 ([], "--adapter-serial is needed"),
                 (["--adapter-serial", "FT1", "--vendor", "04030"], "--vendor"),
                 (["--adapter-serial", "FT1", "--user", "no_such_user_vr006l"], "no such user"),
                 (["--adapter-serial", "FT1", "--scene", "/nonexistent/scene.yaml"], "no such file"),
                 (["--adapter-serial", "FT1", "--config", bad_yaml], "not readable YAML"),
                 (["--adapter-serial", "FT1", "--model", LIMITS_SRC + "x"], "no such file"),
                 (["--adapter-serial", "FT1", "--commissioning", SCENE], "joint_limits.yaml beside it"),
                 (["--adapter-serial", "FT1", "--arg", "port:=/dev/ttyS0"], "set by install-cell"),
                 (["--adapter-serial", "FT1", "--rt-priority", "0"], "--rt-priority"),
                 (["--adapter-serial", "FT1", "--latency", "fast"], "--latency"),
                 (["--adapter-serial", "FT1", "--bogus"], "--bogus"),
                 (["--adapter-path", "pci-0000:00:14.0-usb-0:2:1.0"], "--latency ftdi"),
                 (["--adapter-path", "usb 0:2", "--latency", "none"], "--adapter-path"),
                 (["--adapter-path", "p1", "--adapter-serial", "FT1", "--latency", "none"], "not both")]
        for args, words in cases:
            res = install(*args, "--yes", root=self.root)
            self.assertEqual(res.returncode, 2, (args, res.stdout, res.stderr))
            self.assertIn(words, res.stderr, args)
            self.assertEqual(files_under(self.root), [], args)

    def test_an_adapter_without_a_serial_number_by_its_socket(self):
        """A CH340 (vendor 1a86) has no serial number: the rule names the socket's ID_PATH, and the
        low-latency flag through setserial."""
        path = "pci-0000:00:14.0-usb-0:2:1.0"
        res = install("--adapter-path", path, "--vendor", "1A86", "--latency", "setserial", "--user", USER, "--yes",
                      root=self.root)
        self.assertEqual(res.returncode, 0, res.stderr)
        rules = [dict((k, (op, v)) for k, op, v in rule)
                 for rule in udev_rules(self.read("etc/udev/rules.d/70-vr006l-bus.rules"))]
        self.assertEqual(len(rules), 2)
        for rule in rules:
            self.assertEqual((rule["SUBSYSTEM"], rule["ENV{ID_PATH}"], rule["ATTRS{idVendor}"]),
                             (("==", "tty"), ("==", path), ("==", "1a86")))
            self.assertNotIn("ATTRS{serial}", rule)
        self.assertEqual(rules[0]["SYMLINK"], ("+=", "vr006l_bus"))
        self.assertEqual(rules[1]["RUN"], ("+=", "/bin/setserial /dev/%k low_latency"))

    def test_a_workspace_the_user_cannot_enter_is_found(self):
        """The service runs from this clone as --user: a directory on the way that the user may not
        enter (a home directory of mode 0700) would stop it at every boot; install-cell names it."""
        import importlib.machinery
        import importlib.util
        loader = importlib.machinery.SourceFileLoader("install_cell", INSTALL)
        spec = importlib.util.spec_from_loader("install_cell", loader)
        module = importlib.util.module_from_spec(spec)
        loader.exec_module(module)
        other = next((p.pw_name for p in pwd.getpwall() if p.pw_uid not in (0, os.getuid())), None)
        self.assertIsNotNone(other)
        inner = os.path.join(self.root, "home", "ws")
        os.makedirs(inner)
        os.chmod(self.root, 0o755)
        os.chmod(os.path.join(self.root, "home"), 0o700)
        self.assertEqual(module.unreachable(inner, other), os.path.join(self.root, "home"))
        os.chmod(os.path.join(self.root, "home"), 0o711)
        self.assertIsNone(module.unreachable(inner, other))
        self.assertIsNone(module.unreachable(inner, "root"))

    def test_a_file_it_did_not_write_is_not_overwritten_and_a_dropped_yaml_is_removed(self):
        os.makedirs(self.path("etc/udev/rules.d"))
        with open(self.path("etc/udev/rules.d/70-vr006l-bus.rules"), "w") as f:
            f.write("# someone else's\n")
        res = install(*self.full, "--yes", root=self.root)
        self.assertEqual(res.returncode, 2)
        self.assertIn("was not written by install-cell", res.stderr)
        self.assertEqual(files_under(self.root), ["etc/udev/rules.d/70-vr006l-bus.rules"])
        os.remove(self.path("etc/udev/rules.d/70-vr006l-bus.rules"))
        self.assertEqual(install(*self.full, "--yes", root=self.root).returncode, 0)
        without_scene = [a for a in self.full if a not in ("--scene", SCENE)]
        res = install(*without_scene, "--yes", root=self.root)
        self.assertEqual(res.returncode, 0, res.stderr)
        self.assertIn("remove %s (an earlier install's" % self.path("etc/vr006l/scene.yaml"), res.stdout)
        self.assertNotIn("scene:=", self.read("etc/systemd/system/vr006l-driver.service"))
        self.assertEqual(files_under(self.root), sorted(w for w in WRITTEN if w != "etc/vr006l/scene.yaml"))


if __name__ == "__main__":
    unittest.main()
