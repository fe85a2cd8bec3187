"""The protocol seam (vr_driver.protocol, doc/protocols.md): no module outside
``vr_driver/protocol/`` compares protocol names. Code that depends on the protocol asks the
protocol object (``params.wire``, ``protocol.get(name)``) for a fact, a codec or a capability.

The check parses every module of the package and the node scripts with ``ast`` (nothing is
imported) and reports each comparison (``==``, ``!=``, ``in``, ``not in``, ``is``) one of whose
sides is a protocol name (a string ``v<digits>``) or a literal tuple / list / set / dict holding
one; and each ``if`` / conditional expression whose test is such a string. Each rule is shown to
fail on a broken copy (``test_the_check_can_fail``)."""
from __future__ import annotations

import ast
import os
import re

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
PACKAGE = os.path.join(os.path.dirname(HERE), "src", "vr_driver")
NODES = os.path.join(os.path.dirname(HERE), "nodes")
SEAM = os.path.join(PACKAGE, "protocol")
NAME = re.compile(r"\Av[0-9]+\Z")


def _is_name(node) -> bool:
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return bool(NAME.match(node.value))
    if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
        return any(_is_name(e) for e in node.elts)
    if isinstance(node, ast.Dict):
        return any(k is not None and _is_name(k) for k in node.keys)
    return False


def name_comparisons(source: str, path: str = "<source>"):
    """(line, text) of every comparison with a protocol name in ``source``."""
    tree = ast.parse(source, path)
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Compare):
            if any(_is_name(side) for side in [node.left] + list(node.comparators)):
                found.append((node.lineno, ast.get_source_segment(source, node) or ""))
        elif isinstance(node, ast.Subscript) and isinstance(node.value, ast.Dict) and _is_name(node.value):
            found.append((node.lineno, "a dict literal keyed by protocol names"))
    return found


def sources():
    """Every Python module of the package outside the seam, and the node scripts."""
    for top, dirs, names in os.walk(PACKAGE):
        dirs[:] = sorted(d for d in dirs if d != "__pycache__")
        if os.path.abspath(top).startswith(os.path.abspath(SEAM)):
            continue
        for n in sorted(names):
            if n.endswith(".py"):
                yield os.path.join(top, n)
    for n in sorted(os.listdir(NODES)):
        path = os.path.join(NODES, n)
        with open(path, encoding="utf-8") as f:
            if "python" in f.readline():
                yield path


def test_there_are_modules_to_check():
    paths = list(sources())
    assert len(paths) > 40
    assert any(p.endswith(os.path.join("driver", "core.py")) for p in paths)
    assert any(p.endswith(os.path.join("nodes", "interface")) for p in paths)
    assert not any(os.sep + "protocol" + os.sep in p for p in paths)


def test_no_module_outside_the_seam_compares_protocol_names():
    bad = []
    for path in sources():
        with open(path, encoding="utf-8") as f:
            source = f.read()
        bad += ["%s:%d: %s" % (os.path.relpath(path, os.path.dirname(PACKAGE)), line, text)
                for line, text in name_comparisons(source, path)]
    assert not bad, "protocol names compared outside vr_driver.protocol (ask the protocol object):\n" \
        + "\n".join(bad)


@pytest.mark.parametrize("source", [
    'if params.protocol == "v2":\n    pass\n',
    'streaming = "v1" != protocol\n',
    'ok = name in ("v1", "v2")\n',
    'ok = name not in ["v3"]\n',
    'x = {"v1": 14, "v2": 72}[name]\n',
    'ok = proto.name is "v2"\n',
])
def test_the_check_can_fail(source):
    assert name_comparisons(source)


@pytest.mark.parametrize("source", [
    'if params.wire.streams:\n    pass\n',
    'p.add_argument("--protocol", default="v1")\n',
    'label = "v2 stream"\n',
    'ok = version == "2"\n',
])
def test_the_check_lets_the_seam_be_used(source):
    assert not name_comparisons(source)
