"""``moveit_scene`` (started by panasonic_vr006l_moveit_config's launch files): the driver's cell,
inflated by its padding, written as MoveIt's .scene text (vr_driver.moveit.scene_text) into the ROS
home and handed to ``moveit_ros_planning``'s ``publish_scene_from_text``, which this process becomes:
it waits for move_group's planning_scene_world subscriber and publishes the objects once. Without a
cell (argument and parameter file empty) it says so and ends. Arguments: those of ``moveit_config
scene``; roslaunch's own (``__name:=`` ...) are handed on."""
from __future__ import annotations

import os
import sys
from typing import List, Optional, Sequence


def main(argv: Optional[Sequence[str]] = None) -> int:
    import rospkg
    from roslib.packages import find_node

    from vr_driver.moveit import cli

    argv = list(sys.argv[1:] if argv is None else argv)
    remaps: List[str] = [a for a in argv if ":=" in a]
    args = cli.build_parser("moveit_scene").parse_args(["scene"] + [a for a in argv if ":=" not in a])
    try:
        cell, padding = cli.driver_scene_and_padding(args.cell, args.padding, args.config)
        walls = cli.walls_for(args.config, args.model) if args.workspace else []
        if not cell and not walls:
            print("moveit_scene: no cell (scene:= and the driver's parameter file's scene are empty) and no "
                  "workspace walls: MoveIt's planning scene stays empty", flush=True)
            return 0
        text = cli.scene_for(cell, padding, args.name, walls)
    except (ValueError, OSError) as exc:
        print("moveit_scene: %s" % exc, file=sys.stderr, flush=True)
        return 2
    out = args.out or os.path.join(rospkg.get_ros_home(), "vr006l_%s.scene" % (
        os.path.splitext(os.path.basename(cell))[0] if cell else "workspace"))
    os.makedirs(os.path.dirname(out), exist_ok=True)
    with open(out, "w", encoding="utf-8") as fh:
        fh.write(text)
    try:
        found = find_node("moveit_ros_planning", "publish_scene_from_text")
    except rospkg.ResourceNotFound:            # the package itself is not there
        found = []
    if not found:
        print("moveit_scene: wrote %s, but moveit_ros_planning's publish_scene_from_text is not installed "
              "(sudo apt install ros-noetic-moveit)" % out, file=sys.stderr, flush=True)
        return 1
    print("moveit_scene: %s (padding %.3f m)%s -> %s, published by publish_scene_from_text"
          % (cell or "no cell", padding, " and the workspace walls" if walls else "", out), flush=True)
    os.execv(found[0], [found[0], out] + remaps)
    return 0  # not reached
