"""The core modules of vr_driver -- every module outside ros/ -- import without ROS
(vr_driver/__init__.py): rospy, rospkg and every *_msgs package are blocked, then each is imported in
a fresh interpreter."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

SRC = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "src")
REPO = os.path.dirname(os.path.dirname(SRC))
#: every module of the package but the ROS layer (ros/, the generated msg / srv), found on disk: a
#: new module of the core is checked without being listed
CORE = tuple(sorted(
    ".".join(p for p in os.path.relpath(os.path.join(d, f), os.path.join(SRC, "vr_driver"))[:-3].split(os.sep)
             if p != "__init__")
    for d, _dirs, files in os.walk(os.path.join(SRC, "vr_driver"))
    for f in files
    if f.endswith(".py") and f != "__main__.py" and os.path.relpath(d, os.path.join(SRC, "vr_driver")).split(os.sep)[0] not in ("ros", "msg", "srv")
    and not (f == "__init__.py" and d == os.path.join(SRC, "vr_driver"))))
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
    assert "cli.py" in names and {"csr." + n[:-3] for n in names if n not in ("__init__.py", "__main__.py")} <= set(CORE)
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
