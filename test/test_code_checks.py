"""Static checks over every Python file of the repository (extensionless scripts included):
ruff (pyflakes rules, ../ruff.toml) and vermin (nothing newer than Python 3.8, the Python of Noetic on
Ubuntu 20.04). Both come from PyPI, pinned in scripts/setup."""
import os
import shutil
import subprocess
import tempfile
import unittest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SKIP_DIRS = {".git", ".ws", "__pycache__", ".pytest_cache", ".hypothesis"}
VERMIN_ARGS = ["-t=3.8-", "--no-tips", "--violations", "--no-make-paths-absolute"]


def python_files(root=REPO):
    """Every *.py file, and every file whose first line is a python shebang, below ``root``."""
    found = []
    for top, dirs, files in os.walk(root):
        dirs[:] = sorted(d for d in dirs if d not in SKIP_DIRS)
        for name in sorted(files):
            path = os.path.join(top, name)
            if name.endswith(".py"):
                found.append(path)
                continue
            if os.path.islink(path) or not os.path.isfile(path):
                continue
            with open(path, "rb") as f:
                first = f.readline(200)
            if first.startswith(b"#!") and b"python" in first:
                found.append(path)
    return [os.path.relpath(p, root) for p in found]


def tool(name):
    path = shutil.which(name)
    if path is None:
        raise AssertionError("%s is not installed: run scripts/setup (it installs it from PyPI)" % name)
    return path


def run(cmd, cwd=REPO):
    return subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=300)


class CodeChecksTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.files = python_files()

    def test_the_file_list_has_the_packages_and_the_scripts(self):
        for path in ("vr_driver/src/vr_driver/driver/core.py", "vr_driver/nodes/interface", "scripts/junit_summary",
                     "bench/driver_latency.py", "test/test_code_checks.py",
                     "pyprofibus_vendor/src/pyprofibus_vendor/dp_slave.py"):
            self.assertIn(path, self.files)
        self.assertFalse([p for p in self.files if p.startswith(".ws")])

    def test_ruff_finds_nothing(self):
        res = run([tool("ruff"), "check", "--config", os.path.join(REPO, "ruff.toml"), "--output-format", "concise",
                   "--no-cache"] + self.files)
        self.assertEqual(res.returncode, 0, "ruff check:\n" + res.stdout + res.stderr)

    def test_vermin_finds_nothing_newer_than_python_3_8(self):
        res = run([tool("vermin")] + VERMIN_ARGS + self.files)
        self.assertEqual(res.returncode, 0, "vermin %s:\n%s%s" % (" ".join(VERMIN_ARGS), res.stdout, res.stderr))


class ChecksCatchTest(unittest.TestCase):
    """The two checks, configured as above, do fail on what they are there for."""

    def setUp(self):
        self.tmp = tempfile.mkdtemp(prefix="vr_checks_")
        self.addCleanup(shutil.rmtree, self.tmp)

    def write(self, name, text):
        path = os.path.join(self.tmp, name)
        with open(path, "w") as f:
            f.write(text)
        return path

    def test_ruff_reports_unused_redefined_and_undefined_names(self):
        path = self.write("bad", "#!/usr/bin/env python3\nimport math\nimport os\nimport os\nprint(nowhere)\n")
        self.assertIn("bad", python_files(self.tmp))
        res = run([tool("ruff"), "check", "--config", os.path.join(REPO, "ruff.toml"), "--output-format", "concise",
                   "--no-cache", path], cwd=self.tmp)
        self.assertNotEqual(res.returncode, 0)
        for code in ("F401", "F811", "F821"):
            self.assertIn(code, res.stdout)

    def test_vermin_reports_3_9_and_3_11_only_calls(self):
        path = self.write("new.py", "import random, subprocess\nrandom.Random(1).randbytes(4)\n"
                                    "subprocess.Popen(['true'], process_group=0)\n")
        res = run([tool("vermin")] + VERMIN_ARGS + [path], cwd=self.tmp)
        self.assertNotEqual(res.returncode, 0)
        self.assertIn("randbytes", res.stdout)
        self.assertIn("process_group", res.stdout)


if __name__ == "__main__":
    unittest.main()
