"""The package layout of vr_driver (doc/README.md, "Layout") and its import direction, checked by
parsing every module under src/vr_driver with ``ast`` (nothing is imported). Every import statement
counts, module-level or inside a function.

Layers (the first name below ``vr_driver``):

- the vocabulary: the top-level modules errors, poses, params, validate, io_signals (and the
  package's ``__init__``). They import no subpackage.
- ``protocol`` (v1, v2): imports only the vocabulary. ``kinematics`` (solver, preview): imports only
  the vocabulary. The code has no import between the two in either direction, and the test keeps it
  so (the wire codec needs no PyKDL, the kinematics no wire format).
- ``driver``: imports the vocabulary, protocol and kinematics; never controller, terminal, csr or ros.
- ``controller`` (the virtual G2 and the simulated devices): never imports driver, terminal or ros.
- ``csr`` and ``terminal``: never import ros.
- ``ros``: may import everything. Only ros imports rospy, actionlib, the other ROS client packages
  or message packages (``*_msgs``, ``*_srvs``, the generated ``vr_driver.msg`` / ``vr_driver.srv``).

Known exceptions (KNOWN, each a lazy import inside one function; one that is no longer needed
fails the test, so the list only shrinks): ``params`` resolves ``port: auto`` with
``controller.program.resolve_link``, takes the protocol object from ``protocol.registry`` and the
controller's own I/O length from ``driver.stations``; ``csr.cli`` imports rospy, rosgraph and
trajectory_msgs for ``--from-topic``.

``test_each_rule_can_fail`` breaks a copy of the package once per rule and checks that the checker
reports it."""
from __future__ import annotations

import ast
import os
import shutil

import pytest

SRC = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "src")
PACKAGE = os.path.join(SRC, "vr_driver")

VOCABULARY = ("errors", "poses", "params", "validate", "io_signals")
SUBPACKAGES = ("protocol", "kinematics", "bus", "driver", "controller", "terminal", "csr", "ros")
#: per layer: the layers it may import (whitelist) ...
MAY_IMPORT = {
    "vocabulary": {"vocabulary"},
    "protocol": {"vocabulary", "protocol"},
    "kinematics": {"vocabulary", "kinematics"},
    "bus": {"bus"},
    "driver": {"vocabulary", "protocol", "kinematics", "bus", "driver"},
}
#: ... or the layers it must not import (blacklist)
MUST_NOT_IMPORT = {
    "controller": {"driver", "terminal", "ros"},
    "csr": {"ros"},
    "terminal": {"ros"},
    "ros": set(),
}
ROS_PACKAGES = {"rospy", "rosgraph", "rospkg", "roslib", "rosparam", "rosservice", "rostopic", "rosnode",
                "roslaunch", "rosbag", "actionlib", "diagnostic_updater", "dynamic_reconfigure", "tf",
                "tf2_ros", "message_filters", "genpy"}
#: (importing module, imported module): allowed only inside a function
KNOWN = {
    ("vr_driver.params", "vr_driver.controller.program"): "port: auto resolves like the virtual controller's link",
    ("vr_driver.params", "vr_driver.protocol"): "the protocol object (names, GSD modules, record length, I/O)",
    ("vr_driver.params", "vr_driver.driver.stations"): "the controller's own I/O length in the v2 records",
    ("vr_driver.params", "vr_driver.kinematics.planner"): "planner_id: the OMPL planners the planner knows",
    ("vr_driver.csr.cli", "rosgraph"): "csr_export --from-topic",
    ("vr_driver.csr.cli", "rospy"): "csr_export --from-topic",
    ("vr_driver.csr.cli", "trajectory_msgs.msg"): "csr_export --from-topic",
}


def module_name(root, path):
    rel = os.path.relpath(path, os.path.dirname(root))[:-3].split(os.sep)
    return ".".join(rel[:-1] if rel[-1] == "__init__" else rel)


def layer(name):
    """The layer of an absolute module name inside vr_driver ('ros' for the generated messages)."""
    parts = name.split(".")
    if len(parts) == 1 or parts[1] in VOCABULARY:
        return "vocabulary"
    if parts[1] in ("msg", "srv"):
        return "ros"
    return parts[1] if parts[1] in SUBPACKAGES else "unknown:" + parts[1]


def is_ros(name):
    top = name.split(".")[0]
    return (top in ROS_PACKAGES or top.endswith(("_msgs", "_srvs"))
            or name.split(".")[:2] in (["vr_driver", "msg"], ["vr_driver", "srv"]))


def imports(path, name):
    """(imported absolute module, line, lazy) of every import statement of the module ``name``."""
    with open(path) as f:
        tree = ast.parse(f.read(), path)
    top_level = {id(node) for node in tree.body}
    is_package = path.endswith("__init__.py")
    found = []
    for node in ast.walk(tree):
        lazy = id(node) not in top_level
        if isinstance(node, ast.Import):
            found += [(alias.name, node.lineno, lazy) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".")
                base = base[:len(base) - node.level + (1 if is_package else 0)]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module
            if module == "vr_driver":       # from vr_driver import validate / from .. import validate
                found += [(module + "." + alias.name, node.lineno, lazy) for alias in node.names]
            else:
                found.append((module, node.lineno, lazy))
    return found


def modules(root):
    for top, dirs, names in os.walk(root):
        dirs[:] = sorted(d for d in dirs if d != "__pycache__")
        for n in sorted(names):
            if n.endswith(".py"):
                yield os.path.join(top, n)


def violations(root=PACKAGE):
    """Every import against the rules, as readable lines; empty when the layout holds."""
    bad, used = [], set()
    for path in modules(root):
        name = module_name(root, path)
        mine = layer(name)
        if mine.startswith("unknown"):
            bad.append("%s: not in any layer (add it to the vocabulary or move it into a subpackage)" % name)
            continue
        for target, line, lazy in imports(path, name):
            where = "%s:%d imports %s" % (name, line, target)
            reason = None
            if target.split(".")[0] == "vr_driver" and not is_ros(target):
                theirs = layer(target)
                if theirs.startswith("unknown"):
                    reason = "a module that is in no layer"
                elif mine in MAY_IMPORT and theirs not in MAY_IMPORT[mine]:
                    reason = "%s may import only %s" % (mine, ", ".join(sorted(MAY_IMPORT[mine])))
                elif theirs in MUST_NOT_IMPORT.get(mine, ()):
                    reason = "%s must not import %s" % (mine, theirs)
            elif is_ros(target) and mine != "ros":
                reason = "only vr_driver.ros imports ROS"
            if reason is None:
                continue
            key = (name, target)
            if key in KNOWN and lazy:
                used.add(key)
                continue
            bad.append("%s: %s%s" % (where, reason, " (a known exception, but at module level)"
                                     if key in KNOWN else ""))
    if root == PACKAGE:
        bad += ["known exception no longer needed, remove it from KNOWN: %s -> %s" % key
                for key in sorted(set(KNOWN) - used)]
    return bad


def test_the_import_direction_holds():
    assert violations() == []


def test_the_layout_is_as_documented():
    """The subpackages exist; the top level holds the vocabulary only; the new subpackages'
    ``__init__`` are a docstring and nothing else (no re-exports: one import path per name)."""
    top = sorted(n[:-3] for n in os.listdir(PACKAGE) if n.endswith(".py"))
    assert top == sorted(VOCABULARY + ("__init__",))
    for sub in SUBPACKAGES:
        assert os.path.isfile(os.path.join(PACKAGE, sub, "__init__.py")), sub
    for sub in ("protocol", "kinematics", "controller", "terminal", "ros"):
        with open(os.path.join(PACKAGE, sub, "__init__.py")) as f:
            body = ast.parse(f.read()).body
        assert len(body) == 1 and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant), sub


def test_setup_py_installs_every_subpackage():
    with open(os.path.join(os.path.dirname(SRC), "setup.py")) as f:
        setup = f.read()
    packages = ast.literal_eval(setup.split("packages=", 1)[1].split("]", 1)[0] + "]")
    assert sorted(packages) == sorted(["vr_driver"] + ["vr_driver." + s for s in SUBPACKAGES])


# (module file to break, the import statement added at module level, what the checker must say)
BREAKS = [
    ("errors.py", "from .protocol.v1 import Command", "vocabulary may import only"),
    ("poses.py", "from .kinematics.solver import Kinematics", "vocabulary may import only"),
    ("protocol/v1.py", "from ..kinematics.solver import Kinematics", "protocol may import only"),
    ("protocol/v2.py", "from ..driver import DriverCore", "protocol may import only"),
    ("kinematics/solver.py", "from ..protocol.v1 import Command", "kinematics may import only"),
    ("kinematics/preview.py", "from ..controller.arm import SimArm", "kinematics may import only"),
    ("driver/core.py", "from ..controller.program import VirtualController", "driver may import only"),
    ("driver/link.py", "from ..terminal.pose_input import Backend", "driver may import only"),
    ("driver/jobs.py", "from ..ros.support import route_to_rosout", "driver may import only"),
    ("controller/program.py", "from ..driver.core import DriverCore", "controller must not import driver"),
    ("controller/arm.py", "from ..terminal import pose_input", "controller must not import terminal"),
    ("controller/line.py", "import vr_driver.ros.support", "controller must not import ros"),
    ("csr/export.py", "from ..ros.interface import main", "csr must not import ros"),
    ("terminal/pose_input.py", "from ..ros import pose_terminal", "terminal must not import ros"),
    ("controller/session.py", "import rospy", "only vr_driver.ros imports ROS"),
    ("driver/core.py", "from std_msgs.msg import String", "only vr_driver.ros imports ROS"),
    ("terminal/pose_input.py", "import actionlib", "only vr_driver.ros imports ROS"),
    ("kinematics/solver.py", "from vr_driver.msg import RobotStatus", "only vr_driver.ros imports ROS"),
    ("csr/cli.py", "import rospy", "known exception, but at module level"),
    ("params.py", "from .controller.program import resolve_link", "known exception, but at module level"),
    ("stray.py", '"""A module beside the vocabulary that is not part of it."""', "not in any layer"),
]


@pytest.mark.parametrize("path, statement, expected", BREAKS, ids=["%s: %s" % b[:2] for b in BREAKS])
def test_each_rule_can_fail(tmp_path, path, statement, expected):
    """A copy of the package with one forbidden import added (or, for the last case, a module in no
    layer) is reported, naming the rule; the unbroken copy is not."""
    root = str(tmp_path / "vr_driver")
    shutil.copytree(PACKAGE, root, ignore=shutil.ignore_patterns("__pycache__"))
    assert [v for v in violations(root) if "known exception no longer" not in v] == []
    with open(os.path.join(root, path), "a") as f:
        f.write("\n" + statement + "\n")
    found = violations(root)
    assert any(expected in v for v in found), found
