"""The MoveIt configuration of panasonic_vr006l_moveit_config as a launch needs it for one robot:
with the URDF's name prefix (several arms in one ROS graph: ``left_joint_1``...), with the
commissioned joint limits, and with the driver's padding (doc/moveit.md).

- :func:`srdf` -- the SRDF with every link and joint name prefixed (group and state names stay);
- :func:`controller_list` -- the simple controller manager's list: one FollowJointTrajectory
  controller whose action name is relative, ``joint_trajectory_action``, so ``move_group`` in the
  robot's namespace reaches the driver's action in that namespace;
- :func:`joint_limits` -- MoveIt's ``joint_limits`` mapping, the commissioned file's when a
  commissioning file is given (the ``joint_limits.yaml`` beside it, as ``driver.launch
  commissioning:=`` gives the driver's planner), else a model YAML's, else the package's, the
  names prefixed;
- :func:`execution_limits` -- MoveIt's execution-duration parameters for a protocol."""
from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from typing import Any, Dict, List, Optional

from vr_driver.errors import VrDriverError
from vr_driver.params import read_planning_limits

JOINTS = tuple("joint_%d" % i for i in range(1, 7))
#: the driver's FollowJointTrajectory action, relative to its node's namespace
ACTION = "joint_trajectory_action"
#: SRDF attributes that name a link or a joint of the URDF
_NAME_ATTRS = {"chain": ("base_link", "tip_link"), "link": ("name",), "joint": ("name",),
               "end_effector": ("parent_link",), "disable_collisions": ("link1", "link2"),
               "virtual_joint": ("child_link",), "passive_joint": ("name",)}


class MoveItConfigError(VrDriverError, ValueError):
    """A file the MoveIt configuration is made from is missing or wrong; the message names it."""


def moveit_config_dir() -> str:
    """panasonic_vr006l_moveit_config in the source tree (or beside the installed support package)."""
    from panasonic_vr006l_support.description import package_dir
    return os.path.join(os.path.dirname(package_dir()), "panasonic_vr006l_moveit_config")


def _read(path: str) -> str:
    try:
        with open(path, encoding="utf-8") as fh:
            return fh.read()
    except OSError as exc:
        raise MoveItConfigError("cannot read %s: %s" % (path, exc)) from None


def srdf(prefix: str = "", path: Optional[str] = None) -> str:
    """The package's SRDF (or ``path``) with ``prefix`` before every link and joint name."""
    path = path or os.path.join(moveit_config_dir(), "config", "panasonic_vr006l.srdf")
    text = _read(path)
    if not prefix:
        return text
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise MoveItConfigError("%s: not XML: %s" % (path, exc)) from None
    for elem in root.iter():
        for attr in _NAME_ATTRS.get(elem.tag, ()):
            if elem.get(attr) is not None:
                elem.set(attr, prefix + elem.get(attr))
    return '<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def controller_list(prefix: str = "") -> List[Dict[str, Any]]:
    """MoveIt's ``controller_list`` for the simple controller manager (see the module text). MoveIt
    1.1's handle names its action ``name`` when ``action_ns`` is empty, else ``name/action_ns``:
    the ROS-Industrial ``name: ""`` makes it ``/joint_trajectory_action``, absolute, which misses a
    driver in a namespace."""
    return [{"name": ACTION, "action_ns": "", "type": "FollowJointTrajectory", "default": True,
             "joints": [prefix + j for j in JOINTS]}]


def limits_file(commissioning: str = "") -> str:
    """The joint_limits.yaml to plan with: beside the commissioning file, else the package's."""
    if commissioning:
        return os.path.join(os.path.dirname(os.path.abspath(commissioning)), "joint_limits.yaml")
    return os.path.join(moveit_config_dir(), "config", "joint_limits.yaml")


def joint_limits(commissioning: str = "", prefix: str = "", model: str = "") -> Dict[str, Dict[str, Any]]:
    """MoveIt's ``joint_limits`` mapping (``robot_description_planning/joint_limits``), names
    prefixed, the limits the driver's planner uses: with a commissioning file the joint_limits.yaml
    beside it (checked as the driver checks ``planning_limits``), else with a ``model`` YAML its
    joints' velocity and acceleration, else the package's joint_limits.yaml (the model's set)."""
    if model and not commissioning:
        from panasonic_vr006l_support import joint_limits as model_limits
        try:
            limits = model_limits.load(model)
        except model_limits.LimitsError as exc:
            raise MoveItConfigError("model %s: %s" % (model, exc)) from None
        missing = [j for j in JOINTS if j not in limits]
        if missing:
            raise MoveItConfigError("model %s: joints.%s missing" % (model, missing[0]))
        velocity = tuple(limits[j]["velocity"] for j in JOINTS)
        acceleration = tuple(limits[j]["acceleration"] for j in JOINTS)
    else:
        path = limits_file(commissioning)
        try:
            velocity, acceleration = read_planning_limits(path, JOINTS)
        except VrDriverError as exc:
            raise MoveItConfigError(str(exc)) from None
    return {prefix + j: {"has_velocity_limits": True, "max_velocity": v,
                         "has_acceleration_limits": True, "max_acceleration": a}
            for j, v, a in zip(JOINTS, velocity, acceleration)}


#: MoveIt's trajectory_execution parameters per protocol: (allowed_execution_duration_scaling,
#: allowed_goal_duration_margin [s]); MoveIt cancels a trajectory still running after scaling x the
#: plan's duration + margin. Measured (bench/README.md, "How planned trajectories run": time / plan,
#: max over the goals): v3 1.10 (1.13 with a 0.5 s ramp), v2 1.18 (1.26), v1 1.59 -- v1 stops at
#: every kept point, so its ratio grows with the points; v3 on an interpreter without look-ahead
#: stops too (1.57). MoveIt's default (1.2, 0.5 s) cancels long v2 and v1 plans.
EXECUTION = {"v1": (2.5, 2.0), "v2": (1.4, 0.5), "v3": (1.2, 0.5)}
#: v3 on a G2 whose interpreter reads no MOVE ahead (commissioned interpreter_lookahead 0): v1's
STOPPING = EXECUTION["v1"]


def execution_limits(protocol_name: str, commissioning: str = "") -> Dict[str, Any]:
    """``trajectory_execution/*`` of move_group for ``protocol_name`` (v1 | v2 | v3) and the
    commissioning file (its ``controller/interpreter_lookahead`` 0, or listed under
    ``controller/not_measured``, makes every streamed point a stop: the driver then streams with
    ``stream_smooth`` 0)."""
    if protocol_name not in EXECUTION:
        raise MoveItConfigError("protocol must be one of %s, got %r" % (", ".join(sorted(EXECUTION)), protocol_name))
    scaling, margin = EXECUTION[protocol_name]
    if commissioning and (scaling, margin) != STOPPING:     # (v1 stops at every point anyway)
        import yaml
        try:
            doc = yaml.safe_load(_read(commissioning)) or {}
        except yaml.YAMLError as exc:
            raise MoveItConfigError("%s: not YAML: %s" % (commissioning, exc)) from None
        controller = doc.get("controller") if isinstance(doc, dict) else None
        if isinstance(controller, dict) and (controller.get("interpreter_lookahead") == 0
                                             or "interpreter_lookahead" in (controller.get("not_measured") or ())):
            scaling, margin = STOPPING
    return {"execution_duration_monitoring": True, "allowed_execution_duration_scaling": scaling,
            "allowed_goal_duration_margin": margin}
