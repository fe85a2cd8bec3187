"""The repository is a catkin source space of four format-3 packages whose dependencies all resolve."""
import ast
import glob
import os
import subprocess
import unittest
import xml.etree.ElementTree as ET

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PACKAGES = ["panasonic_vr006l_moveit_config", "panasonic_vr006l_support", "pyprofibus_vendor", "vr_driver"]
DEP_TAGS = ("depend", "build_depend", "buildtool_depend", "exec_depend", "test_depend", "build_export_depend")
# rosdep keys that Debian does not package but scripts/setup installs from PyPI
PYPI_KEYS = {"xacro": "xacro", "urdfdom_py": "urdf_parser_py"}


def manifest(pkg):
    return ET.parse(os.path.join(REPO, pkg, "package.xml")).getroot()


def debian_installed(name):
    res = subprocess.run(["dpkg-query", "-W", "-f=${Status}", name], capture_output=True, text=True)
    return res.returncode == 0 and res.stdout.endswith("installed")


def ros_package(name):
    """A ROS package with a manifest (rospack), or one Debian ships as Python only (python3-*-msgs)."""
    if subprocess.run(["rospack", "find", name], capture_output=True, text=True).returncode == 0:
        return True
    return debian_installed("python3-" + name.replace("_", "-"))


class PackagesTest(unittest.TestCase):
    def test_top_level_cmakelists_is_catkins_toplevel(self):
        path = os.path.join(REPO, "CMakeLists.txt")
        self.assertTrue(os.path.islink(path))
        self.assertTrue(os.readlink(path).endswith("catkin/cmake/toplevel.cmake"))

    def test_the_four_packages_are_format_3_with_matching_names(self):
        found = sorted(os.path.basename(os.path.dirname(p)) for p in glob.glob(os.path.join(REPO, "*", "package.xml")))
        self.assertEqual(found, PACKAGES)
        for pkg in PACKAGES:
            root = manifest(pkg)
            self.assertEqual(root.get("format"), "3", pkg)
            self.assertEqual(root.findtext("name"), pkg)
            self.assertTrue(root.findtext("description").strip(), pkg)
            self.assertIsNotNone(root.find("export/architecture_independent"), pkg)
            self.assertIsNotNone(root.find("buildtool_depend"), pkg)

    def test_every_dependency_resolves_here(self):
        """Every dependency whose condition holds here (catkin_pkg evaluates it as rosdep does: MoveIt's
        packages are dependencies on ROS Noetic only, and Debian's ROS_DISTRO is "Debian")."""
        from catkin_pkg.package import parse_package

        for pkg in PACKAGES:
            package = parse_package(os.path.join(REPO, pkg, "package.xml"))
            package.evaluate_conditions(os.environ)
            wanted = {dep.name for attr in ("build_depends", "buildtool_depends", "exec_depends", "test_depends",
                                            "build_export_depends", "buildtool_export_depends")
                      for dep in getattr(package, attr) if dep.evaluated_condition is not False}
            for tag in DEP_TAGS:
                for dep in manifest(pkg).findall(tag):
                    name = dep.text.strip()
                    if name not in wanted:
                        self.assertIn("condition", dep.attrib, (pkg, name))
                        continue
                    with self.subTest(package=pkg, depend=name):
                        if name in PYPI_KEYS:
                            __import__(PYPI_KEYS[name])
                        elif name == "rviz":  # optional GUI: scripts/setup --rviz installs it
                            continue
                        else:
                            self.assertTrue(ros_package(name) or debian_installed(name),
                                            "%s: dependency %s is neither a ROS package nor an installed Debian package" % (pkg, name))

    def test_python_packages_are_declared_in_setup_py(self):
        for pkg in PACKAGES:
            src = os.path.join(REPO, pkg, "src")
            if not os.path.isdir(src):
                continue
            modules = sorted(d for d in os.listdir(src) if os.path.isfile(os.path.join(src, d, "__init__.py")))
            with open(os.path.join(REPO, pkg, "setup.py")) as f:
                tree = ast.parse(f.read())
            declared = [ast.literal_eval(kw.value) for node in ast.walk(tree) if isinstance(node, ast.Call)
                        for kw in node.keywords if kw.arg == "packages"]
            self.assertEqual(len(declared), 1, pkg)
            subpackages = sorted(os.path.relpath(root, src).replace(os.sep, ".")
                                 for root, _, files in os.walk(src) if "__init__.py" in files)
            self.assertEqual(sorted(declared[0]), subpackages, "%s: setup.py must list every sub-package" % pkg)
            self.assertTrue(modules, pkg)

    def test_executables_use_debians_python(self):
        """pyenv's python3 first on PATH cannot import rospy: every script names /usr/bin/python3."""
        for path in glob.glob(os.path.join(REPO, "*", "scripts", "*")) + glob.glob(os.path.join(REPO, "*", "nodes", "*")) \
                + glob.glob(os.path.join(REPO, "*", "test", "*_check.py")):
            with open(path, "rb") as f:
                first = f.readline()
            if first.startswith(b"#!") and b"python" in first:
                self.assertEqual(first.strip(), b"#!/usr/bin/python3", path)
                self.assertTrue(os.access(path, os.X_OK), "%s is not executable" % path)


if __name__ == "__main__":
    unittest.main()
