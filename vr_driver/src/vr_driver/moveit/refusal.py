"""The driver's refusal of a trajectory, said for a MoveIt user: one line (the FollowJointTrajectory
result's ``error_string``, which MoveIt's controller manager logs and RViz's MotionPlanning panel
reports) saying why and what to change. MoveIt plans against what it was given; the driver checks
more (its cell with its padding, its workspace box, the G2's configuration rule on v1 / v3), so each
kind of refusal names the setting that makes MoveIt plan what the driver takes (doc/moveit.md)."""
from __future__ import annotations

from typing import Optional

from vr_driver.errors import CollisionError

LAUNCH = "roslaunch panasonic_vr006l_moveit_config moveit_planning_execution.launch"


def _hint(exc: BaseException, text: str, padding: Optional[float]) -> str:
    pad = "" if padding is None else " (padding %.0f mm)" % (padding * 1e3)
    if isinstance(exc, CollisionError) and exc.contacts:
        objects = sorted({c.other for c in exc.contacts if c.world})
        if objects:
            return ("MoveIt's planning scene lacks %s or the driver's padding%s: start MoveIt with the driver's "
                    "cell (%s scene:=CELL.yaml) or add it to MoveIt's scene grown by the padding"
                    % (", ".join(objects), pad, LAUNCH))
        return ("MoveIt checks the arm against itself without the driver's padding%s: plan with more room "
                "between the links, or lower collision_padding" % pad)
    if "workspace" in text:
        return ("MoveIt knows the driver's workspace box (parameter workspace) only as walls at x max, y min / "
                "max and z max (%s workspace_walls:=true, the default) and not a TCP offset: keep the goal and "
                "the path inside the box, or widen it in the driver's parameter file" % LAUNCH)
    if "configuration" in text or "cannot solve its pose" in text:
        return ("the G2 takes Cartesian targets (v1 / v3) and keeps its configuration: plan a goal in the "
                "start's configuration (kinematics_solver:=opw gives the branch nearest the start), or run "
                "protocol:=v2 (joint targets)")
    if "limit" in text or "speed" in text or "velocity" in text:
        return ("plan with the driver's limits: commissioning:=FILE gives MoveIt the commissioned "
                "joint_limits.yaml; lower MoveIt's velocity scaling")
    return "see the driver's log (node interface) for the details"


def for_moveit(exc: BaseException, padding: Optional[float] = None) -> str:
    """``refused by the driver: <its reason, on one line> -- <what to change>``."""
    text = " ".join(str(exc).split())
    return "refused by the driver: %s -- %s" % (text, _hint(exc, text, padding))
