"""The package layout of vr_driver (doc/layout.md) and its import direction, checked by
parsing every module under src/vr_driver with ``ast`` (nothing is imported). Every import statement
counts, module-level or inside a function.

Layers (the first name below ``vr_driver``):

- the vocabulary: the top-level modules errors, poses, params, validate, io_signals (and the
  package's ``__init__``). They import no subpackage.
- ``protocol`` (v1, v2): imports only the vocabulary. ``kinematics`` (solver, preview): imports only
  the vocabulary. The code has no import between the two in either direction, and the test keeps it
  so (the wire codec needs no PyKDL, the kinematics no wire format).
- ``driver``: imports the vocabulary, protocol, kinematics and bus; never controller, terminal, csr or
  ros. Inside it, one room per job (DRIVER_MAY_IMPORT), each importing only the rooms below it:
  ``link`` (the bus side) < ``motion`` (jobs, sequencers, streams, the status) < ``joints`` (the
  arm's joints, supervision) and ``checks`` (a job's way in: submit, path checks, stream
  preparation) < the top (``core``, ``bus_loop``, ``sequencers``, ``__init__``) < ``planning`` (the
  plan action and its worker process). ``own_thread`` (top level) imports nothing of the driver;
  the top and ``checks`` use it.
- ``controller`` (the virtual G2 and the simulated devices): never imports driver, terminal or ros.
- ``csr`` and ``terminal``: never import ros.
- ``ros``: may import everything. Only ros imports rospy, actionlib, the other ROS client packages
  or message packages (``*_msgs``, ``*_srvs``, the generated ``vr_driver.msg`` / ``vr_driver.srv``).

Known exceptions (KNOWN, each a lazy import inside one function, with its reason; one that is no
longer needed fails the test, so the list only shrinks): ``params`` takes the protocol objects from
``protocol.registry`` (in one function, ``_registry``); ``csr.cli`` imports rospy, rosgraph and
trajectory_msgs for ``--from-topic``.

The shape of the code, checked the same way:

- **No long class**: no class in src/vr_driver is longer than MAX_CLASS_LINES (from its ``class``
  line to its last line, ``ast``'s ``end_lineno``): a class that long has more than one job. There
  are no exceptions: the six classes that were longer when the rule came (Kinematics, Planner,
  LinkSupervisor, Terminal, SequencerBase, InterfaceNode) have been carved.
- **No import circle** among the modules of vr_driver: module-level and function-level imports
  both count (a lazy import hides a circle from the interpreter, not from the reader); ``from
  package import name`` counts as an import of the submodule ``package.name`` when there is one.
  The import of a module's parent package that Python does on the way is not counted (every
  module of a package that re-exports would be in a circle with it). The strongly connected
  components of that graph must be single modules, once the edges of CIRCLE_EDGES (each with its
  reason) are left out; an edge there that no longer closes a circle fails the test, so that list
  only shrinks too.

The protocol's two names (doc/layout.md, "Names"), checked the same way:

- **One name for the object, one for the string**: a function parameter, a dataclass field or an
  annotated attribute whose annotation names the protocol object's class (``Protocol``,
  ``ProtocolV1``, ...) is called ``wire`` (``_wire`` when private), and one called ``wire`` is
  annotated with that class (never ``str`` or another type); an unannotated assignment of the
  object (``x.wire``, ``registry.get(...)``, ``protocols.get(...)``, ``protocol_option(...)``,
  ``with_send_ahead(...)``) binds ``wire`` / ``_wire`` too. ``protocol`` is the user's string: the
  ROS parameter ``~protocol``, ``--protocol``, the launch argument.
- **Protocol-specific modules stay behind the seam**: only ``protocol`` itself and ``controller``
  (the virtual G2's programs implement the protocols) import ``vr_driver.protocol.v1`` / ``v2`` /
  ``v3``, and the modules of PROTOCOL_SPECIFIC, each with its reason (one that no longer imports
  them fails the test); everything else asks the protocol object.

``test_each_rule_can_fail`` breaks a copy of the package once per rule and checks that the checker
reports it."""
from __future__ import annotations

import ast
import os
import re

import pytest

SRC = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "src")
PACKAGE = os.path.join(SRC, "vr_driver")

VOCABULARY = ("errors", "poses", "params", "validate", "io_signals")
SUBPACKAGES = ("protocol", "kinematics", "bus", "driver", "commission", "controller", "terminal", "csr", "moveit",
               "ros")
#: per layer: the layers it may import (whitelist) ...
MAY_IMPORT = {
    "vocabulary": {"vocabulary"},
    "protocol": {"vocabulary", "protocol"},
    "kinematics": {"vocabulary", "kinematics"},
    "bus": {"bus"},
    "driver": {"vocabulary", "protocol", "kinematics", "bus", "driver"},
    # the commissioning tool: the driver's link and the protocols against a real (or virtual) G2,
    # never the virtual G2 itself, the terminal or ROS
    "commission": {"vocabulary", "protocol", "kinematics", "bus", "driver", "commission"},
    # what MoveIt 1 is given (the cell as .scene text, the prefixed config, OPW): the cell and the errors
    "moveit": {"vocabulary", "kinematics", "moveit"},
}
#: inside ``driver``: per room (its subpackage; ``core`` for the top-level modules but own_thread) the
#: rooms it may import (one way: no two rooms import each other)
DRIVER_MAY_IMPORT = {
    "own_thread": {"own_thread"},
    "link": {"link"},
    "motion": {"link", "motion"},
    "joints": {"link", "motion", "joints"},
    "checks": {"own_thread", "link", "motion", "checks"},
    "core": {"own_thread", "link", "motion", "joints", "checks", "core"},
    "planning": {"own_thread", "link", "motion", "joints", "checks", "core", "planning"},
}
DRIVER_ROOMS = ("link", "motion", "joints", "checks", "planning")
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
#: (importing module, imported module): allowed only inside a function, each with why it is needed.
#: (What params once took from above and no longer does: ``port: auto``'s link name lives in params
#: (controller.pty_link uses it), the OMPL planners' names too (kinematics.planner uses them), the
#: controller's own I/O length in io_signals (driver.link.stations uses it).)
KNOWN = {
    # the protocol parameter is checked against the registered protocol objects and resolved to one
    # (DriverParams.wire: streams? controller I/O? GSD modules and record lengths for the bus config);
    # the registry holds the protocols' code, so it cannot move down, and every builder of
    # DriverParams (the node, commission, csr, benches, tests) would otherwise have to pass it in
    ("vr_driver.params", "vr_driver.protocol"): "the protocol objects by name (params._registry)",
    # ROS only where it is asked for: csr_export works on files without a ROS installation
    ("vr_driver.csr.cli", "rosgraph"): "csr_export --from-topic",
    ("vr_driver.csr.cli", "rospy"): "csr_export --from-topic",
    ("vr_driver.csr.cli", "trajectory_msgs.msg"): "csr_export --from-topic",
}
#: modules outside ``protocol`` and ``controller`` that import a protocol's own module
#: (vr_driver.protocol.v1 / v2 / v3), and why: each is that protocol's registered implementation
PROTOCOL_SPECIFIC = {
    "vr_driver.driver.sequencers": "registers the driver's sequencer and stream family with each built-in "
                                   "protocol object (Protocol.implement)",
    "vr_driver.driver.motion.handshake": "v1's sequencer (HandshakeSequencer, registered for v1) runs v1's "
                                         "request / done handshake (MasterHandshake, Command, Feedback)",
    "vr_driver.commission.bus": "the commissioning tool measures v3's assumptions about the G2 on v3's records",
    "vr_driver.commission.steps": "the commissioning tool measures v3's assumptions about the G2 on v3's records",
}
#: the protocol object's names: a parameter, field or attribute holding it (doc/layout.md, "Names")
WIRE_NAMES = ("wire", "_wire")
#: the annotations that name the protocol object's class (the seam's and each protocol's subclass)
PROTOCOL_CLASS = re.compile(r"\AProtocol(V[0-9]+)?\Z")
#: a protocol's own module
PROTOCOL_MODULE = re.compile(r"\Avr_driver\.protocol\.v[0-9]+\Z")
#: the longest a class may be [lines]
MAX_CLASS_LINES = 350
#: import edges (importer, imported) left out of the circle check, and why; each closes a circle today
CIRCLE_EDGES: dict = {}


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


def driver_room(name):
    """The room inside ``driver`` of an absolute module name of that layer."""
    parts = name.split(".")
    if len(parts) > 3 and parts[2] in DRIVER_ROOMS:
        return parts[2]
    return "own_thread" if parts[2:3] == ["own_thread"] else "core"


def is_ros(name):
    top = name.split(".")[0]
    return (top in ROS_PACKAGES or top.endswith(("_msgs", "_srvs"))
            or name.split(".")[:2] in (["vr_driver", "msg"], ["vr_driver", "srv"]))


_PARSED = {}
#: {path: text} read instead of the file (test_each_rule_can_fail: the package with one file broken,
#: without copying it)
_OVERRIDE = {}


def parsed(path):
    """The module's ast, parsed once per version of the file (every check walks the same files)."""
    key = _key(path)
    if key not in _PARSED:
        if path in _OVERRIDE:
            _PARSED[key] = ast.parse(_OVERRIDE[path], path)
        else:
            with open(path) as f:
                _PARSED[key] = ast.parse(f.read(), path)
    return _PARSED[key]


_IMPORTS = {}


def _source(path):
    """The module's text (as :func:`parsed` reads it)."""
    if path in _OVERRIDE:
        return _OVERRIDE[path]
    with open(path) as f:
        return f.read()


def _key(path):
    """What a file's derived facts are cached under: its path and version (or its text in memory)."""
    if path in _OVERRIDE:
        return (path, _OVERRIDE[path])
    st = os.stat(path)
    return (path, st.st_mtime_ns, st.st_size)


def imports(path, name):
    """(imported absolute module, line, lazy) of every import statement of the module ``name``."""
    key = (_key(path), name)
    if key not in _IMPORTS:
        _IMPORTS[key] = _imports(path, name)
    return _IMPORTS[key]


def _imports(path, name):
    tree = parsed(path)
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
    for path in sorted(_OVERRIDE):          # a module only in memory (a test's new file)
        if path.startswith(root + os.sep) and not os.path.exists(path):
            yield path


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
                elif mine == theirs == "driver" and driver_room(target) not in DRIVER_MAY_IMPORT[driver_room(name)]:
                    reason = "driver.%s may import only driver.%s" % (
                        driver_room(name), ", driver.".join(sorted(DRIVER_MAY_IMPORT[driver_room(name)])))
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


def long_classes(root=PACKAGE):
    """Every class longer than MAX_CLASS_LINES, as readable lines."""
    bad = []
    for path in modules(root):
        name = module_name(root, path)
        tree = parsed(path)
        for node in ast.walk(tree):
            if isinstance(node, ast.ClassDef):
                lines = node.end_lineno - node.lineno + 1
                if lines > MAX_CLASS_LINES:
                    bad.append("%s:%d: class %s is %d lines (at most %d: give its jobs classes of "
                               "their own)" % (name, node.lineno, node.name, lines, MAX_CLASS_LINES))
    return bad


_FROMS = {}


def _import_froms(path, tree):
    key = _key(path)
    if key not in _FROMS:
        _FROMS[key] = [node for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)]
    return _FROMS[key]


_GRAPHS = {}


def import_graph(root=PACKAGE):
    """{module: {the vr_driver modules it imports}}, every import statement counted (module
    docstring); an import of a module outside the package is left out. Made once per version of
    the package's files (several checks walk it)."""
    key = (root, tuple(_key(path) for path in modules(root)))
    if key not in _GRAPHS:
        _GRAPHS[key] = _import_graph(root)
    return _GRAPHS[key]


def _import_graph(root):
    paths = {module_name(root, path): path for path in modules(root)}
    graph = {}
    for name, path in paths.items():
        edges = set()
        tree = parsed(path)
        found = imports(path, name)
        for target, _line, _lazy in found:
            edges.add(target)
        for node in _import_froms(path, tree):           # from package import submodule
            for module in [t for t, line, _ in found if line == node.lineno]:
                edges.update(module + "." + alias.name for alias in node.names
                             if module + "." + alias.name in paths)
        resolved = set()
        for target in edges:
            while target and target not in paths:        # a name inside a module: the module
                target = target.rpartition(".")[0]
            if target and target != name:
                resolved.add(target)
        graph[name] = resolved
    return graph


def strongly_connected(graph):
    """The strongly connected components of ``graph`` (Tarjan's algorithm, iterative), each sorted."""
    index, low, on_stack, stack, found = {}, {}, set(), [], []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph.get(child, ())))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                found.append(sorted(component))
    return found


def import_circles(root=PACKAGE):
    """Every import circle among vr_driver's modules once CIRCLE_EDGES are left out, and every edge
    of CIRCLE_EDGES that no longer closes a circle, as readable lines."""
    graph = import_graph(root)
    cut = {name: {t for t in targets if (name, t) not in CIRCLE_EDGES} for name, targets in graph.items()}
    bad = ["import circle: %s (a module of it must stop importing another: move what both need into a "
           "module of its own)" % " <-> ".join(component)
           for component in strongly_connected(cut) if len(component) > 1]
    if root == PACKAGE:
        whole = [set(c) for c in strongly_connected(graph) if len(c) > 1]
        bad += ["%s -> %s no longer closes a circle: remove it from CIRCLE_EDGES" % edge
                for edge in sorted(CIRCLE_EDGES)
                if edge[1] not in graph.get(edge[0], ()) or not any(set(edge) <= c for c in whole)]
    return bad


def _names_protocol_class(annotation) -> bool:
    """The annotation is the protocol object's class (``Protocol``, ``Optional[Protocol]``,
    ``"ProtocolV3"``, ``Protocol | None``, ...; a container of them -- ``Dict[str, Protocol]`` -- is
    another thing, and so is ``typing.Protocol``)."""
    node = annotation
    if isinstance(node, ast.Name):
        return bool(PROTOCOL_CLASS.match(node.id))
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        try:
            return _names_protocol_class(ast.parse(node.value, mode="eval").body)
        except SyntaxError:
            return False
    if isinstance(node, ast.BinOp) and isinstance(node.op, ast.BitOr):
        return _names_protocol_class(node.left) or _names_protocol_class(node.right)
    if isinstance(node, ast.Subscript):
        outer = node.value.id if isinstance(node.value, ast.Name) else getattr(node.value, "attr", "")
        inner = node.slice
        if type(inner).__name__ == "Index":                      # Python 3.8: an ast.Index around it
            inner = inner.value
        if outer == "Optional":
            return _names_protocol_class(inner)
        if outer == "Union":
            return any(_names_protocol_class(e) for e in getattr(inner, "elts", [inner]))
    return False


def _gives_protocol_object(value) -> bool:
    """``value`` is an expression that evaluates to the protocol object: ``x.wire``, the registry's
    ``get`` (``registry.get`` / ``protocols.get`` / ``_registry().get``), ``protocol_option(...)``,
    ``x.with_send_ahead(...)``."""
    if isinstance(value, ast.Attribute):
        return value.attr in WIRE_NAMES
    if not isinstance(value, ast.Call):
        return False
    func = value.func
    if isinstance(func, ast.Name):
        return func.id == "protocol_option"
    if isinstance(func, ast.Attribute):
        if func.attr == "with_send_ahead":
            return True
        owner = func.value
        return func.attr == "get" and ((isinstance(owner, ast.Name) and owner.id in ("registry", "protocols"))
                                       or (isinstance(owner, ast.Call) and isinstance(owner.func, ast.Name)
                                           and owner.func.id == "_registry"))
    return False


def _bound_name(target):
    """The name an assignment target binds (a variable or an attribute), None for anything else."""
    if isinstance(target, ast.Name):
        return target.id
    if isinstance(target, ast.Attribute):
        return target.attr
    return None


_WIRE_NAMES = {}


def wire_names(root=PACKAGE):
    """Every parameter, field, attribute or variable that breaks the protocol's two names (module
    docstring), as readable lines."""
    bad = []
    for path in modules(root):
        key = (_key(path), module_name(root, path))
        if key not in _WIRE_NAMES:
            _WIRE_NAMES[key] = _wire_names(path, key[1])
        bad += _WIRE_NAMES[key]
    return bad


def _wire_names(path, name):
    """wire_names of one module."""
    bad = []
    source = _source(path)
    annotated = []                     # (what, its name, its annotation, line)
    assigned = []                      # (its name, its value, line)
    for node in ast.walk(parsed(path)):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            args = node.args
            for arg in args.posonlyargs + args.args + args.kwonlyargs + [args.vararg, args.kwarg]:
                if arg is not None and arg.annotation is not None:
                    annotated.append(("parameter", arg.arg, arg.annotation, arg.lineno))
        elif isinstance(node, ast.AnnAssign) and _bound_name(node.target):
            annotated.append(("field" if isinstance(node.target, ast.Name) else "attribute",
                              _bound_name(node.target), node.annotation, node.lineno))
            if node.value is not None:
                assigned.append((_bound_name(node.target), node.value, node.lineno))
        elif isinstance(node, ast.Assign):
            for target in node.targets:
                if isinstance(target, ast.Tuple) and isinstance(node.value, ast.Tuple) \
                        and len(target.elts) == len(node.value.elts):
                    assigned += [(_bound_name(t), v, node.lineno) for t, v in zip(target.elts, node.value.elts)]
                else:
                    assigned.append((_bound_name(target), node.value, node.lineno))
    for what, bound, annotation, line in annotated:
        if _names_protocol_class(annotation) and bound not in WIRE_NAMES:
            bad.append("%s:%d: %s %s holds the protocol object: call it wire (protocol is the user's "
                       "string)" % (name, line, what, bound))
        elif bound in WIRE_NAMES and not _names_protocol_class(annotation):
            bad.append("%s:%d: %s %s is annotated %s: wire is the protocol object's name (the string is "
                       "protocol)" % (name, line, what, bound, ast.get_source_segment(source, annotation)))
    for bound, value, line in assigned:
        if bound is not None and bound not in WIRE_NAMES and _gives_protocol_object(value):
            bad.append("%s:%d: %s = %s holds the protocol object: call it wire (protocol is the user's "
                       "string)" % (name, line, bound, ast.get_source_segment(source, value)))
    return bad


def protocol_specific_imports(root=PACKAGE):
    """Every import of a protocol's own module (vr_driver.protocol.v1 / v2 / v3) outside ``protocol``,
    ``controller`` and PROTOCOL_SPECIFIC, as readable lines; and each entry of PROTOCOL_SPECIFIC
    that imports none (for the real package)."""
    bad, used = [], set()
    for module, targets in sorted(import_graph(root).items()):
        specific = sorted(t for t in targets if PROTOCOL_MODULE.match(t))
        if not specific or layer(module) in ("protocol", "controller"):
            continue
        if module in PROTOCOL_SPECIFIC:
            used.add(module)
            continue
        bad.append("%s imports %s: protocol-specific code outside the seam (ask the protocol object, or "
                   "register the code with it)" % (module, ", ".join(specific)))
    if root == PACKAGE:
        bad += ["%s imports no protocol's own module any more: remove it from PROTOCOL_SPECIFIC" % module
                for module in sorted(set(PROTOCOL_SPECIFIC) - used)]
    return bad


def test_the_protocol_object_is_called_wire_and_the_string_protocol():
    assert wire_names() == []


def test_protocol_specific_modules_are_imported_only_behind_the_seam():
    assert protocol_specific_imports() == []


def test_no_class_is_longer_than_the_limit():
    assert long_classes() == []


def test_no_import_circle():
    assert import_circles() == []


def test_the_import_direction_holds():
    assert violations() == []


def test_the_layout_is_as_documented():
    """The subpackages exist; the top level holds the vocabulary only; the new subpackages'
    ``__init__`` are a docstring and nothing else (no re-exports: one import path per name)."""
    top = sorted(n[:-3] for n in os.listdir(PACKAGE) if n.endswith(".py"))
    assert top == sorted(VOCABULARY + ("__init__",))
    for sub in SUBPACKAGES:
        assert os.path.isfile(os.path.join(PACKAGE, sub, "__init__.py")), sub
    for sub in ("protocol", "kinematics", "controller", "terminal", "ros") + tuple("driver/" + r for r in DRIVER_ROOMS):
        with open(os.path.join(PACKAGE, sub, "__init__.py")) as f:
            body = ast.parse(f.read()).body
        assert len(body) == 1 and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant), sub


def test_setup_py_installs_every_subpackage():
    with open(os.path.join(os.path.dirname(SRC), "setup.py")) as f:
        setup = f.read()
    packages = ast.literal_eval(setup.split("packages=", 1)[1].split("]", 1)[0] + "]")
    assert sorted(packages) == sorted(["vr_driver"] + ["vr_driver." + s for s in SUBPACKAGES]
                                      + ["vr_driver.driver." + r for r in DRIVER_ROOMS])


# (module file to break, the import statement added at module level, what the checker must say)
BREAKS = [
    ("errors.py", "from .protocol.v1 import Command", "vocabulary may import only"),
    ("poses.py", "from .kinematics.solver import Kinematics", "vocabulary may import only"),
    ("protocol/v1.py", "from ..kinematics.solver import Kinematics", "protocol may import only"),
    ("protocol/v2.py", "from ..driver import DriverCore", "protocol may import only"),
    ("kinematics/solver.py", "from ..protocol.v1 import Command", "kinematics may import only"),
    ("kinematics/preview.py", "from ..controller.arm import SimArm", "kinematics may import only"),
    ("driver/core.py", "from ..controller.virtual_controller import VirtualController", "driver may import only"),
    ("driver/link/link.py", "from ...terminal.pose_input import Backend", "driver may import only"),
    ("driver/motion/jobs.py", "from ...ros.support import route_to_rosout", "driver may import only"),
    ("driver/link/link.py", "def later():\n    from ..motion.jobs import MoveJob", "driver.link may import only"),
    ("driver/motion/status.py", "from ..joints.tracking import JointTracker", "driver.motion may import only"),
    ("driver/motion/jobs.py", "from ..checks.path_checks import PathChecks", "driver.motion may import only"),
    ("driver/joints/tracking.py", "from ..checks.scene_guard import SceneGuard", "driver.joints may import only"),
    ("driver/checks/path_checks.py", "from ..joints.resolution import WireResolution", "driver.checks may import only"),
    ("driver/checks/job_control.py", "from ..core import DriverCore", "driver.checks may import only"),
    ("driver/core.py", "def later():\n    from .planning.planning import PlanActionCore", "driver.core may import only"),
    ("driver/own_thread.py", "from .motion.jobs import MoveJob", "driver.own_thread may import only"),
    ("controller/virtual_controller.py", "from ..driver.core import DriverCore", "controller must not import driver"),
    ("controller/arm.py", "from ..terminal import pose_input", "controller must not import terminal"),
    ("controller/line.py", "import vr_driver.ros.support", "controller must not import ros"),
    ("csr/export.py", "from ..ros.interface import main", "csr must not import ros"),
    ("terminal/pose_input.py", "from ..ros import pose_terminal", "terminal must not import ros"),
    ("controller/session.py", "import rospy", "only vr_driver.ros imports ROS"),
    ("driver/core.py", "from std_msgs.msg import String", "only vr_driver.ros imports ROS"),
    ("terminal/pose_input.py", "import actionlib", "only vr_driver.ros imports ROS"),
    ("kinematics/solver.py", "from vr_driver.msg import RobotStatus", "only vr_driver.ros imports ROS"),
    ("csr/cli.py", "import rospy", "known exception, but at module level"),
    ("params.py", "from .protocol import registry", "known exception, but at module level"),
    ("params.py", "def later():\n    from .driver.link.stations import IoLine", "vocabulary may import only"),
    ("params.py", "def later():\n    from .controller.pty_link import SimPort", "vocabulary may import only"),
    ("stray.py", '"""A module beside the vocabulary that is not part of it."""', "not in any layer"),
]


#: the shape rules: (module file to break, the text appended to it, what the checker must say)
LONG_CLASS = "class Sprawling:\n" + "    x = 1\n" * MAX_CLASS_LINES
SHAPE_BREAKS = [
    ("driver/motion/jobs.py", LONG_CLASS, "class Sprawling is %d lines" % (MAX_CLASS_LINES + 1)),
    ("driver/motion/jobs.py", "from ..core import DriverCore", "import circle: "),
    ("driver/checks/stream_prep.py", "def later():\n    from .job_control import JobControl",
     "import circle: vr_driver.driver.checks.job_control <-> "),
    ("driver/checks/path_checks.py", "def later():\n    from . import stream_prep", "vr_driver.driver.checks.stream_prep"),
    ("driver/motion/announced.py", "def later(kin, protocol: Protocol):\n    pass",
     "parameter protocol holds the protocol object: call it wire"),
    ("driver/motion/announced.py", "def later(kin, wire: Optional['ProtocolV3'] = None):\n    pass", ""),
    ("driver/motion/announced.py", "def later(wire: str):\n    pass", "parameter wire is annotated str"),
    ("driver/motion/trajectories.py", "@dataclass\nclass Later:\n    wire: Optional[ConfigurationTolerances]",
     "field wire is annotated Optional[ConfigurationTolerances]: wire is the protocol object's name"),
    ("driver/core.py", "class Later:\n    def __init__(self, params):\n        self.protocol = params.wire",
     "protocol = params.wire holds the protocol object"),
    ("ros/industrial.py", "def later(core):\n    lim, proto = core.kin.limits, core.wire",
     "proto = core.wire holds the protocol object"),
    ("commission/scan.py", "def later(name):\n    fit = protocols.get(name)", "fit = protocols.get(name) holds"),
    ("driver/motion/announced.py", "from ...protocol.v1 import program_speed",
     "vr_driver.driver.motion.announced imports vr_driver.protocol.v1: protocol-specific code outside"),
    ("ros/jog.py", "def later():\n    from ..protocol import v3", "vr_driver.ros.jog imports vr_driver.protocol.v3"),
]


def shape_violations(root):
    return long_classes(root) + import_circles(root) + wire_names(root) + protocol_specific_imports(root)


@pytest.mark.parametrize("path, statement, expected", BREAKS + SHAPE_BREAKS,
                         ids=["%s: %s" % (b[0], b[1].splitlines()[-1].strip()) for b in BREAKS + SHAPE_BREAKS])
def test_each_rule_can_fail(path, statement, expected):
    """The package with one forbidden import added to one module (or a module in no layer, a class
    too long, an import that closes a circle -- lazily, too) is reported, naming the rule (the
    module's text replaced in memory: the checkers read the files through ``parsed``); the package
    as it is is not (test_imports_follow_the_layers and the others)."""
    full = os.path.join(PACKAGE, path)
    text = ""
    if os.path.exists(full):
        with open(full) as f:
            text = f.read()
    _OVERRIDE[full] = text + "\n" + statement + "\n"
    try:
        found = violations(PACKAGE) + shape_violations(PACKAGE)
    finally:
        del _OVERRIDE[full]
    if not expected:                        # a statement the rules allow: nothing is reported
        assert found == [], found
        return
    assert any(expected in v for v in found), found
