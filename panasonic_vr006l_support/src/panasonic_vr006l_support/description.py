"""Render the VR-006L xacro to URDF text, from Python or the command line.

Why this exists: on Debian 12 the only ROS 1 xacro is PyPI's ``xacro==1.13.3``, whose ``load_yaml``
calls ``yaml.load(f)`` without a Loader, which PyYAML 6 (Debian 12) rejects with
``load() missing 1 required positional argument: 'Loader'``. The package's own calibration reaches the
macro without ``load_yaml`` (``urdf/vr006l_calibration.xacro``, see ``calibration``), so the stock
``xacro`` renders the model; another YAML (``kinematics_config:=FILE``) is read with ``load_yaml``, and
this module swaps in a safe YAML loader inside xacro's expression namespace for it (nothing else in
the process changes). On a ROS distribution whose xacro already works with PyYAML 6 the swap changes
nothing.

It also resolves the two substitutions the model uses, ``$(find PKG)`` and ``$(arg NAME)``, itself
(rospkg and xacro's own argument table): xacro 1.13 imports the whole of ``roslaunch`` for any
``$(...)``, about 0.3 s of CPU (0.06 s for rospkg alone) in every process that renders the model
through this module (the tests, the tools, the planning bench). Any other substitution still goes to roslaunch, as before.

Command line (what the launch files call)::

    xacro_compat FILE.xacro [name:=value ...] [-o OUT.urdf]
"""
from __future__ import annotations

import argparse
import inspect
import os
import sys
from typing import Dict, Optional, Sequence

PACKAGE = "panasonic_vr006l_support"


class DescriptionError(Exception):
    """The robot description could not be rendered; the message says why."""


def package_dir() -> str:
    """The support package's directory: from rospkg when available, else the source tree."""
    try:
        import rospkg  # optional: present in any ROS environment

        return rospkg.RosPack().get_path(PACKAGE)
    except Exception:  # rospkg missing, or the package is not on ROS_PACKAGE_PATH
        return os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def default_xacro_path() -> str:
    return os.path.join(package_dir(), "urdf", "vr006l.xacro")


def default_kinematics_yaml() -> str:
    return os.path.join(package_dir(), "config", "kinematics_vr006l.yaml")


def _yaml_load_needs_loader() -> bool:
    import yaml

    param = inspect.signature(yaml.load).parameters.get("Loader")
    return param is not None and param.default is inspect.Parameter.empty


def _install_safe_load_yaml(xacro_module) -> None:
    """Make xacro's ``load_yaml`` work with PyYAML >= 6 (see the module docstring)."""
    if not _yaml_load_needs_loader():
        return
    import yaml

    def load_yaml(filename):
        filename = xacro_module.abs_filename_spec(filename)
        oldstack = xacro_module.push_file(filename)
        try:
            with open(filename) as stream:
                return yaml.safe_load(stream)
        except OSError as exc:
            raise xacro_module.XacroException("cannot read YAML file %s: %s" % (filename, exc))
        finally:
            xacro_module.restore_filestack(oldstack)
            xacro_module.all_includes.append(filename)

    xacro_module.global_symbols["load_yaml"] = load_yaml


def _install_light_substitutions(xacro_module) -> None:
    """Resolve ``$(find PKG)``, ``$(arg NAME)`` and ``$(cwd)`` without importing roslaunch (see the
    module docstring); anything else goes to xacro's own ``eval_extension``. Idempotent."""
    original = getattr(xacro_module, "_vr006l_original_eval_extension", None)
    if original is None:
        original = xacro_module.eval_extension
        xacro_module._vr006l_original_eval_extension = original
    packages = {}

    def eval_extension(text):
        words = text[2:-1].split() if text.startswith("$(") and text.endswith(")") else []
        if len(words) == 2 and words[0] == "arg":
            args = xacro_module.substitution_args_context.get("arg", {})
            if words[1] not in args:
                raise xacro_module.XacroException(
                    "Undefined substitution argument", exc=KeyError("arg '%s' is not defined" % words[1]))
            return args[words[1]]
        if len(words) == 2 and words[0] == "find":
            if words[1] not in packages:
                import rospkg

                try:
                    packages[words[1]] = rospkg.RosPack().get_path(words[1])
                except rospkg.ResourceNotFound as exc:
                    raise xacro_module.XacroException("resource not found:", exc=exc) from exc
            return packages[words[1]]
        return original(text)

    xacro_module.eval_extension = eval_extension


def _ensure_package_path() -> None:
    """Let ``$(find panasonic_vr006l_support)`` resolve outside a sourced workspace (plain pytest on
    the source tree): append the folder holding this package to ROS_PACKAGE_PATH when it is missing."""
    root = os.path.dirname(package_dir())
    current = os.environ.get("ROS_PACKAGE_PATH", "")
    entries = [os.path.realpath(p) for p in current.split(os.pathsep) if p]
    if os.path.realpath(root) not in entries:
        os.environ["ROS_PACKAGE_PATH"] = os.pathsep.join([p for p in (current, root) if p])


def render_urdf(xacro_path: Optional[str] = None, mappings: Optional[Dict[str, str]] = None) -> str:
    """Process a xacro file (default: the VR-006L top level) and return the URDF as text.

    ``mappings`` are xacro args (``{"prefix": "r1_"}``). Raises DescriptionError on any failure.
    """
    try:
        import xacro
    except ImportError as exc:
        raise DescriptionError(
            "xacro is not installed: run scripts/setup (it installs xacro==1.13.3 from PyPI)") from exc
    path = xacro_path or default_xacro_path()
    if not os.path.isfile(path):
        raise DescriptionError("xacro file not found: %s" % path)
    _install_safe_load_yaml(xacro)
    _install_light_substitutions(xacro)
    _ensure_package_path()
    try:
        doc = xacro.process_file(path, mappings=dict(mappings or {}))
    except Exception as exc:  # xacro raises many types (XacroException, NameError, KeyError...)
        raise DescriptionError("xacro failed on %s: %s" % (path, exc)) from exc
    return doc.toprettyxml(indent="  ")


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(
        prog="xacro_compat",
        description="Render a xacro file to URDF (xacro 1.13 with a PyYAML-6-safe load_yaml).")
    parser.add_argument("input", nargs="?", default=None,
                        help="xacro file (default: the VR-006L top-level xacro)")
    parser.add_argument("mappings", nargs="*", metavar="name:=value", help="xacro arguments")
    parser.add_argument("-o", "--output", help="write the URDF here instead of standard output")
    args = parser.parse_args(argv)
    mappings = {}
    for item in args.mappings:
        if ":=" not in item:
            parser.error("argument %r is not of the form name:=value" % item)
        key, value = item.split(":=", 1)
        mappings[key] = value
    try:
        text = render_urdf(args.input, mappings)
    except DescriptionError as exc:
        print("xacro_compat: error: %s" % exc, file=sys.stderr)
        return 1
    write_output(text, args.output)
    return 0


def write_output(text: str, path: Optional[str]) -> None:
    """A command line's result: to the file ``path``, or to standard output without one."""
    if path:
        with open(path, "w") as out:
            out.write(text)
    else:
        sys.stdout.write(text)
