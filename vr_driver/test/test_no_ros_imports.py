"""The core modules of vr_driver import without ROS (vr_driver/__init__.py): rospy, rospkg and every
*_msgs package are blocked, then each core module that exists is imported afresh in a subprocess."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

SRC = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "src")
REPO = os.path.dirname(os.path.dirname(SRC))
CSR_MODULES = ("fields", "inputs", "model", "writer", "parser", "conventions", "waypoints", "export", "cli")
CORE = ("errors", "validate", "poses", "params", "io_signals",
        "protocol", "protocol.base", "protocol.registry", "protocol.v1", "protocol.v2", "kinematics", "kinematics.solver", "kinematics.preview",
        "kinematics.planner",
        "kinematics.deps", "kinematics.scene", "kinematics.collision",
        "driver", "driver.link", "driver.sequencer", "driver.jobs", "driver.core", "driver.trajectories",
        "driver.stations", "driver.streaming", "driver.record_clock", "driver.supervision", "driver.joint_command",
        "driver.scene_guard",
        "controller", "controller.program", "controller.session", "controller.program_v2", "controller.arm",
        "controller.stream_arm", "controller.io_island", "controller.line",
        "terminal", "terminal.pose_input", "terminal.jog", "csr") + tuple("csr." + m for m in CSR_MODULES)
BLOCKED = ("rospy", "rospkg", "roslib", "std_msgs", "sensor_msgs", "geometry_msgs", "industrial_msgs",
           "trajectory_msgs", "visualization_msgs", "actionlib")

_SCRIPT = """
import importlib, json, sys, traceback
for name in {blocked!r}:
    sys.modules[name] = None          # any import of it raises ImportError
sys.path[:0] = {paths!r}
results = {{}}
for module in {modules!r}:
    before = set(sys.modules)
    try:
        importlib.import_module("vr_driver." + module)
    except Exception:
        results[module] = traceback.format_exc(limit=-3)
        continue
    loaded = sorted(m for m in set(sys.modules) - before if m.endswith("_msgs") and sys.modules[m] is not None)
    results[module] = "loaded %s" % loaded if loaded else "ok"
print(json.dumps(results))
"""


@pytest.fixture(scope="module")
def imported_without_ros():
    """{module: "ok" or what went wrong} for every CORE module, imported one after the other in ONE
    fresh interpreter with ROS blocked (a subprocess each took 16 s for the lot). The verdicts are
    the same: a blocked import raises whichever module comes first, and a *_msgs module that one
    loads is charged to it."""
    paths = [SRC, os.path.join(REPO, "pyprofibus_vendor", "src"), os.path.join(REPO, "panasonic_vr006l_support", "src")]
    script = _SCRIPT.format(blocked=BLOCKED, paths=paths, modules=CORE)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("module", CORE)
def test_core_module_imports_without_ros(module, imported_without_ros):
    assert imported_without_ros[module] == "ok", imported_without_ros[module]


def test_rospy_blocked_in_process_too():
    """The same check in this process (as a user's process would): block rospy, re-import the modules."""
    saved = {k: v for k, v in sys.modules.items() if k == "rospy" or k.startswith("vr_driver")}
    try:
        for k in list(sys.modules):
            if k.startswith("vr_driver"):
                del sys.modules[k]
        sys.modules["rospy"] = None
        import importlib
        for module in CORE:
            path = os.path.join(SRC, "vr_driver", *module.split("."))
            if os.path.exists(path + ".py") or os.path.exists(os.path.join(path, "__init__.py")):
                importlib.import_module("vr_driver." + module)
    finally:
        sys.modules.pop("rospy", None)
        for k in list(sys.modules):
            if k.startswith("vr_driver"):
                del sys.modules[k]
        sys.modules.update(saved)


@pytest.mark.parametrize("module", ["protocol.v1", "protocol.v2", "poses", "params"])
def test_the_wire_codec_and_the_vocabulary_need_no_kinematics(module):
    """The 14-byte codec, the pose vocabulary (MoveType lives there) and the parameters import
    neither PyKDL nor the kinematics or planning modules."""
    paths = [SRC, os.path.join(REPO, "pyprofibus_vendor", "src")]
    script = ("import sys; sys.path[:0] = %r; import vr_driver.%s; "
              "bad = [m for m in ('PyKDL', 'vr_driver.kinematics') if m in sys.modules]; "
              "assert not bad, bad; print('ok')" % (paths, module))
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and proc.stdout.strip() == "ok", proc.stderr


def test_only_the_csr_command_line_mentions_ros():
    """vr_driver.csr: cli.py is the one module that may import ROS (lazily, for --from-topic); every
    other module of the package names no ROS package in any import statement."""
    import ast
    folder = os.path.join(SRC, "vr_driver", "csr")
    names = sorted(n for n in os.listdir(folder) if n.endswith(".py"))
    assert {m + ".py" for m in CSR_MODULES} <= set(names), names
    ros = ("rospy", "rosgraph", "rospkg", "roslib", "actionlib")
    for name in names:
        with open(os.path.join(folder, name)) as f:
            tree = ast.parse(f.read(), name)
        imported = []
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                imported += [(a.name, node) for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
                imported.append((node.module, node))
        found = [(mod, node.lineno) for mod, node in imported
                 if mod.split(".")[0] in ros or mod.split(".")[0].endswith("_msgs")]
        if name != "cli.py":
            assert not found, (name, found)
        else:
            assert found, "cli.py should import rospy for --from-topic"
            top_level = {id(n) for n in tree.body}
            assert not [f for f in found if any(id(n) in top_level and n.lineno == f[1] for n in tree.body)], \
                ("cli.py imports ROS at module level", found)
