"""``rosrun vr_driver moveit_config WHAT``: the MoveIt 1 configuration pieces made from the stack's
files, printed for a launch file (``<param type="yaml" command="...">``) or a user (doc/moveit.md):

    scene [CELL]          the cell as MoveIt's .scene text, inflated by the driver's padding
                          (--workspace: and walls beyond the driver's workspace box)
    srdf                  the SRDF (with --prefix: every link and joint name prefixed)
    controllers           the simple controller manager's controller_list (YAML)
    joint-limits          robot_description_planning/joint_limits (YAML; --commissioning: its file's)
    execution             move_group's trajectory_execution parameters for --protocol (YAML)
    kinematics            the planning group's kinematics.yaml entry, --solver kdl | opw (YAML)

Bad input: one line on stderr naming the file and key, exit 2; nothing printed on stdout."""
from __future__ import annotations

import argparse
import os
import sys
from typing import Any, Dict, Optional, Sequence

import yaml

from vr_driver.errors import VrDriverError

from . import config, opw, scene_text

DEFAULT_PADDING = 0.01      # m: vr_driver.yaml's collision_padding when no file says otherwise


def _driver_params(config_file: str) -> Dict[str, Any]:
    params: Dict[str, Any] = {}
    if config_file:
        try:
            with open(config_file, encoding="utf-8") as fh:
                params = yaml.safe_load(fh) or {}
        except (OSError, yaml.YAMLError) as exc:
            raise config.MoveItConfigError("driver parameter file %s: %s" % (config_file, exc)) from None
        if not isinstance(params, dict):
            raise config.MoveItConfigError("driver parameter file %s: expected a mapping of parameters, got %s"
                                           % (config_file, type(params).__name__))
    return params


def driver_scene_and_padding(cell: str, padding: str, config_file: str):
    """(cell path, padding [m]) as the driver takes them: an argument given wins over the driver's
    parameter file (``scene``, ``collision_padding``), which wins over none / 0.01 m."""
    params = _driver_params(config_file)
    cell = cell or str(params.get("scene") or "")
    if padding == "":
        value: Any = params.get("collision_padding", DEFAULT_PADDING)
    else:
        try:
            value = float(padding)
        except ValueError:
            raise config.MoveItConfigError("--padding: expected metres >= 0, got %r" % padding) from None
    return cell, value


def walls_for(config_file: str, model: str = "") -> list:
    """The walls of the driver's workspace box (its parameter file's ``workspace``, else the
    default), the box's z measured from the model's ``base`` frame."""
    from panasonic_vr006l_support import kinematic_calibration as kc

    from vr_driver.poses import Workspace
    ws = _driver_params(config_file).get("workspace") or {}
    try:
        workspace = Workspace.from_dict(ws)
    except (TypeError, ValueError) as exc:
        raise config.MoveItConfigError("driver parameter file %s: workspace: %s" % (config_file, exc)) from None
    base_z = (kc.nominal_parameters(model) if model else kc.nominal_parameters())["base_frame_z"]
    return scene_text.workspace_walls(workspace, base_z)


def scene_for(cell: str, padding: Any, name: str = "", walls: Sequence[Any] = ()) -> str:
    """The .scene text of the cell file ``cell`` ("" : an empty scene) with ``padding`` and ``walls``."""
    from vr_driver.kinematics.scene import Scene, load_scene
    scene = load_scene(cell) if cell else Scene()
    base = os.path.splitext(os.path.basename(cell))[0] if cell else "workspace"
    return scene_text.scene_text(scene, padding, name or base, walls=walls)


def _dump(value: Any) -> str:
    return yaml.safe_dump(value, default_flow_style=False, sort_keys=False)


def build_parser(prog: Optional[str] = None) -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="what", required=True)
    s = sub.add_parser("scene", help="the cell as MoveIt's .scene text")
    s.add_argument("cell", nargs="?", default="", help="cell YAML (default: the driver parameter file's scene)")
    s.add_argument("--padding", default="", help="m (default: the driver parameter file's collision_padding, 0.01)")
    s.add_argument("--config", default="", help="the driver's parameter file (vr_driver.yaml)")
    s.add_argument("--name", default="", help="the scene's name (default: the cell file's)")
    s.add_argument("--workspace", action="store_true",
                   help="add walls beyond the driver's workspace box (x max, y min / max, z max)")
    s.add_argument("--model", default="", help="the kinematics YAML (its base_frame_z places the box)")
    s.add_argument("-o", "--out", default="", help="write here instead of stdout")
    for name in ("srdf", "controllers", "joint-limits"):
        p = sub.add_parser(name)
        p.add_argument("--prefix", default="", help="the URDF's name prefix (driver.launch prefix:=)")
        if name == "joint-limits":
            p.add_argument("--commissioning", default="", help="the commissioning file: its joint_limits.yaml")
            p.add_argument("--model", default="", help="the kinematics YAML: its joints' limits (no commissioning)")
    e = sub.add_parser("execution")
    e.add_argument("--protocol", required=True, choices=sorted(config.EXECUTION))
    e.add_argument("--commissioning", default="")
    e.add_argument("--monitoring", default="true", choices=("true", "false"),
                   help="false: MoveIt never cancels a trajectory for its duration")
    e.add_argument("--start-tolerance", type=float, default=0.01,
                   help="rad between the plan's start and joint_states (MoveIt's allowed_start_tolerance)")
    k = sub.add_parser("kinematics")
    k.add_argument("--solver", default="kdl", choices=("kdl", "opw"))
    k.add_argument("--model", default="", help="the kinematics YAML (driver.launch model:=); default the package's")
    return ap


def render(args: argparse.Namespace) -> str:
    if args.what == "scene":
        cell, padding = driver_scene_and_padding(args.cell, args.padding, args.config)
        walls = walls_for(args.config, args.model) if args.workspace else []
        return scene_for(cell, padding, args.name, walls)
    if args.what == "srdf":
        return config.srdf(args.prefix)
    if args.what == "controllers":
        return _dump(config.controller_list(args.prefix))
    if args.what == "joint-limits":
        return _dump(config.joint_limits(args.commissioning, args.prefix, args.model))
    if args.what == "execution":
        out = config.execution_limits(args.protocol, args.commissioning)
        out["execution_duration_monitoring"] = args.monitoring == "true"
        out["allowed_start_tolerance"] = args.start_tolerance
        return _dump(out)
    if args.solver == "opw":
        return _dump(opw.kinematics_entry(args.model))
    with open(os.path.join(config.moveit_config_dir(), "config", "kinematics.yaml"), encoding="utf-8") as fh:
        return _dump(yaml.safe_load(fh)["manipulator"])


def main(argv: Optional[Sequence[str]] = None, prog: Optional[str] = None) -> int:
    args = build_parser(prog).parse_args(argv)
    try:
        text = render(args)
    except (VrDriverError, ValueError, OSError) as exc:
        print("moveit_config %s: %s" % (args.what, exc), file=sys.stderr)
        return 2
    if getattr(args, "out", ""):
        with open(args.out, "w", encoding="utf-8") as fh:
            fh.write(text)
    else:
        sys.stdout.write(text)
    return 0
