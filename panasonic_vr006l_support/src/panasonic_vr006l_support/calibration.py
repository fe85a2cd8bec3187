"""The numbers of ``config/kinematics_vr006l.yaml`` as a xacro property, for the stock ``xacro``.

Why: xacro's ``load_yaml`` cannot run on Debian 12 (PyPI's xacro 1.13.3 calls ``yaml.load(f)``
without a Loader, which PyYAML 6 refuses), and xacro has no other way to read a file's data. So
``urdf/vr006l_calibration.xacro`` holds the YAML's numbers and flags (its ``source`` notes stay in the
YAML) as one property, ``vr006l_calibration``, a nested ``dict(...)`` expression that every xacro
evaluates. The YAML stays the single source: this module writes the xacro from it, and the tests fail
when the two differ. After editing the YAML run::

    scripts/env python3 -m panasonic_vr006l_support.calibration          # rewrite the xacro
    scripts/env python3 -m panasonic_vr006l_support.calibration --check  # exit 1 if out of date

ROS-free; needs only PyYAML.
"""
from __future__ import annotations

import argparse
import os
import sys
from typing import Any, List, Optional, Sequence

import yaml

PROPERTY = "vr006l_calibration"
PACKAGE_DIR = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
YAML_PATH = os.path.join(PACKAGE_DIR, "config", "kinematics_vr006l.yaml")
XACRO_PATH = os.path.join(PACKAGE_DIR, "urdf", "vr006l_calibration.xacro")


class CalibrationError(Exception):
    """The YAML holds something the xacro property cannot carry; the message says where."""


def numbers_only(value: Any, where: str = "") -> Any:
    """The YAML tree without its text (notes such as ``source``): dicts, numbers and booleans."""
    if isinstance(value, dict):
        out = {}
        for key, item in value.items():
            if not isinstance(key, str) or not key.isidentifier():
                raise CalibrationError("%s: key %r is not a plain name" % (where or "top level", key))
            if isinstance(item, str):
                continue
            out[key] = numbers_only(item, where + "." + key if where else key)
        return out
    if isinstance(value, bool) or (isinstance(value, (int, float)) and value == value
                                   and value not in (float("inf"), float("-inf"))):
        return value
    raise CalibrationError("%s: %r is neither a number, a flag nor a mapping" % (where, value))


def _expression(value: Any, indent: int) -> str:
    if not isinstance(value, dict):
        return repr(value)
    if not any(isinstance(item, dict) for item in value.values()):      # a leaf: one line
        return "dict(%s)" % ", ".join("%s=%r" % kv for kv in value.items())
    pad = " " * (indent + 2)
    items = ["%s%s=%s" % (pad, key, _expression(item, indent + 2)) for key, item in value.items()]
    return "dict(\n%s)" % ",\n".join(items)


def xacro_text(cfg: Any, yaml_name: str = "config/kinematics_vr006l.yaml") -> str:
    """The xacro file for the YAML tree ``cfg``."""
    tree = numbers_only(cfg)
    lines: List[str] = [
        '<?xml version="1.0"?>',
        "<!-- GENERATED from %s by panasonic_vr006l_support.calibration: do not edit." % yaml_name,
        "     Edit the YAML, then run: scripts/env python3 -m panasonic_vr006l_support.calibration",
        "     (the stock xacro cannot read YAML on Debian 12; the tests check that this file matches). -->",
        '<robot xmlns:xacro="http://wiki.ros.org/xacro">',
        '  <xacro:property name="%s" value="${%s}"/>' % (PROPERTY, _expression(tree, 2)),
        "</robot>",
        "",
    ]
    return "\n".join(lines)


def read_yaml(path: str, error: Any = None, what: str = "") -> Any:
    """The YAML tree of ``path``; ``error`` (an exception class, default CalibrationError) with the
    reason when it cannot be read or parsed, the file named as ``what`` + path."""
    error = error or CalibrationError
    try:
        with open(path) as f:
            return yaml.safe_load(f)
    except OSError as exc:
        raise error("cannot read %s%s: %s" % (what, path, exc.strerror or exc)) from exc
    except yaml.YAMLError as exc:
        raise error("%s%s is not valid YAML: %s" % (what, path, exc)) from exc


def load(path: str = YAML_PATH) -> Any:
    return read_yaml(path)


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog="python3 -m panasonic_vr006l_support.calibration",
                                     description="Write urdf/vr006l_calibration.xacro from the calibration YAML.")
    parser.add_argument("--check", action="store_true", help="only compare; exit 1 if the xacro is out of date")
    parser.add_argument("--yaml", default=YAML_PATH, help="the calibration YAML (default: the package's)")
    parser.add_argument("-o", "--output", default=XACRO_PATH, help="the xacro to write (default: the package's)")
    args = parser.parse_args(argv)
    try:
        text = xacro_text(load(args.yaml))
    except CalibrationError as exc:
        print("calibration: error: %s" % exc, file=sys.stderr)
        return 2
    try:
        with open(args.output) as f:
            current = f.read()
    except OSError:
        current = None
    if args.check:
        if current != text:
            print("calibration: %s is out of date with %s; run python3 -m panasonic_vr006l_support.calibration"
                  % (args.output, args.yaml), file=sys.stderr)
            return 1
        return 0
    if current != text:
        with open(args.output, "w") as f:
            f.write(text)
        print("wrote %s" % args.output)
    return 0


if __name__ == "__main__":
    sys.exit(main())
