"""What a ROS user expects of a released package (issue 26 item 8): the license text at the
repository root, a CHANGELOG.rst per package in catkin's format whose newest section is this
release, and one version in every package.xml and setup.py."""
import os
import re
import subprocess
import sys
import unittest
import xml.etree.ElementTree as ET

from catkin_pkg.changelog import get_changelog_from_path

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PACKAGES = ["panasonic_vr006l_moveit_config", "panasonic_vr006l_support", "pyprofibus_vendor", "vr_driver"]


def manifest_version(pkg):
    return ET.parse(os.path.join(REPO, pkg, "package.xml")).getroot().findtext("version").strip()


def setup_py_version(pkg):
    """The version setup.py gives setuptools, computed as catkin does (generate_distutils_setup in
    the package directory), in a child process: setup() is replaced to print it."""
    code = ("import sys, setuptools\n"
            "setuptools.setup = lambda **kw: print(kw.get('version'))\n"
            "sys.argv = ['setup.py']\n"
            "exec(open('setup.py').read())\n")
    res = subprocess.run([sys.executable, "-c", code], cwd=os.path.join(REPO, pkg),
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    return res.stdout.strip().splitlines()[-1]


def changelog(pkg):
    return get_changelog_from_path(os.path.join(REPO, pkg, "CHANGELOG.rst"), pkg)


class ReleaseTest(unittest.TestCase):
    def test_the_license_text_is_at_the_root_and_matches_the_manifests(self):
        with open(os.path.join(REPO, "LICENSE")) as f:
            text = f.read()
        self.assertTrue(text.startswith("BSD 3-Clause License"))
        self.assertRegex(text, r"Copyright \(c\) 2026, ")
        for clause in ("Redistributions of source code must retain",
                       "Redistributions in binary form must reproduce",
                       "Neither the name of the copyright holder",
                       'IS PROVIDED BY THE COPYRIGHT HOLDERS AND CONTRIBUTORS "AS IS"'):
            self.assertIn(clause, text)
        for pkg in PACKAGES:
            self.assertEqual(ET.parse(os.path.join(REPO, pkg, "package.xml")).getroot().findtext("license"),
                             "BSD-3-Clause", pkg)

    def test_every_package_has_one_version(self):
        versions = {pkg: manifest_version(pkg) for pkg in PACKAGES}
        for pkg, version in versions.items():
            self.assertRegex(version, r"^\d+\.\d+\.\d+$", pkg)
        self.assertEqual(len(set(versions.values())), 1, versions)

    def test_setup_py_gives_the_manifests_version(self):
        found = 0
        for pkg in PACKAGES:
            if not os.path.exists(os.path.join(REPO, pkg, "setup.py")):
                continue
            found += 1
            with self.subTest(package=pkg):
                self.assertEqual(setup_py_version(pkg), manifest_version(pkg))
        self.assertEqual(found, 3)            # all but the MoveIt config (no Python)

    def test_each_changelog_is_catkins_format_with_this_release_on_top(self):
        for pkg in PACKAGES:
            with self.subTest(package=pkg):
                path = os.path.join(REPO, pkg, "CHANGELOG.rst")
                with open(path) as f:
                    lines = f.read().splitlines()
                title = "Changelog for package %s" % pkg
                self.assertEqual(lines[:3], ["^" * len(title), title, "^" * len(title)])
                log = changelog(pkg)
                sections = list(log.foreach_version())
                self.assertTrue(sections, "no version section")
                version, date, _ = sections[0]
                self.assertEqual(version, manifest_version(pkg))
                self.assertIsNotNone(date, "the newest section has no date")
                heading = "%s (%s)" % (version, date.strftime("%Y-%m-%d"))
                index = lines.index(heading)
                self.assertEqual(lines[index + 1], "-" * len(heading))
                entries = [str(item) for item in log.get_content_of_version(version)]
                self.assertTrue(entries and all(e.startswith("* ") for e in entries), entries)
                bullets = [line for line in lines[index + 2:] if line.startswith("* ")]
                self.assertGreaterEqual(len(bullets), 1)

    def test_the_checks_fail_on_a_broken_changelog(self):
        """The format check can fail: catkin's parser finds no version in a file without the
        underlined heading."""
        import tempfile
        with tempfile.TemporaryDirectory() as tmp:
            path = os.path.join(tmp, "CHANGELOG.rst")
            with open(path, "w") as f:
                f.write("Changelog for package x\n\n0.2.0 2026-11-25\n* an entry\n")
            self.assertEqual(list(get_changelog_from_path(path, "x").foreach_version()), [])
        self.assertIsNone(re.match(r"^\d+\.\d+\.\d+$", "0.2"))


if __name__ == "__main__":
    unittest.main()
