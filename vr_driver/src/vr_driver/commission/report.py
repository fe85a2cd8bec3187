"""The end of a commissioning: the table (assumption, expected, measured, consequence) and the files
(ROS-free).

:func:`write_yaml` writes ONE file for ``driver.launch commissioning:=FILE``, in the shape
:class:`vr_driver.params.DriverParams` validates: the driver's parameters that follow from the
measurements by their names (``protocol``, ``byte_order``, ``stream_smooth`` where the arm cannot
blend), ``planning_limits`` (the ``joint_limits.yaml`` written beside it: the plan action's limits),
the measured behaviours of the G2 under ``controller`` (:class:`~vr_driver.params.ControllerFacts`:
``interpreter_lookahead``, ``speed_scale``, ``loop_blocks_during_move``, ...; only what was measured,
and ``not_measured``: the keys the bus hid, their reasons under ``commissioning/not_measured``)
and, under ``commissioning`` (information), the date, the controller's identity, the robot time and
the table.
:func:`write_joint_limits` writes the same limits as a MoveIt ``joint_limits.yaml`` beside it.
"""
from __future__ import annotations

import datetime
import math
import os
import textwrap
from typing import Any, Dict, List, Mapping, Optional, Sequence

import yaml

from .steps import Finding, StepResult

__all__ = ["DRIVER_KEYS", "CONTROLLER_KEYS", "table", "driver_values", "joint_limits", "write_yaml",
           "write_joint_limits"]

#: a speed scale this close to 1 is the assumed unit (the measurement's own precision)
SPEED_TOLERANCE = 0.02
#: DriverParams names the commissioning sets
DRIVER_KEYS = ("protocol", "byte_order", "stream_smooth", "planning_limits", "controller", "commissioning")
#: the measured G2 behaviours, the keys of ``controller`` (ControllerFacts; the virtual G2's parameter names)
CONTROLLER_KEYS = ("interpreter_lookahead", "loop_period", "loop_period_spread", "loop_blocks_during_move",
            "speed_scale", "configuration", "send_ahead", "unreachable", "ring_size", "ramp_shape",
            "ramp_time", "accelerations", "check_word")


def _wrap(text: str, width: int) -> List[str]:
    return textwrap.wrap(text, width) or [""]


def table(findings: Sequence[Finding], width: int = 100) -> str:
    """The findings as a text table, one block per row: a verdict mark (ok / DIFFERS / not measured),
    the assumption, then expected / measured / consequence indented."""
    lines = []
    for f in findings:
        mark = {True: "ok", False: "DIFFERS", None: "--"}[f.ok]
        lines.append("%-8s %s" % (mark, f.assumption))
        for label, text in (("expected", f.expected), ("measured", f.measured), ("consequence", f.consequence)):
            wrapped = _wrap(text, width - 22)
            lines.append("         %-12s %s" % (label + ":", wrapped[0]))
            lines.extend("         %-12s %s" % ("", w) for w in wrapped[1:])
    return "\n".join(lines)


def driver_values(measured: Mapping[str, Any], not_measured: Optional[Mapping[str, str]] = None) -> Dict[str, Any]:
    """The driver's parameters (DriverParams names; the measured behaviours under ``controller``) from
    what was measured; the keys a step could not measure (``not_measured``: {key: why}) listed under
    ``controller/not_measured``, never written as a value (the driver keeps their assumptions, and
    takes an unmeasured look-ahead as a stop at every point). ``protocol`` v3, or v1 where the program loop blocks during a MOVE (v3 cannot
    stream with it: the driver refuses it at start); ``stream_smooth`` 0 where the arm cannot blend."""
    blocks = bool(measured.get("loop_blocks_during_move"))
    out: Dict[str, Any] = {"protocol": "v1" if blocks else "v3"}
    if "byte_order" in measured:
        out["byte_order"] = measured["byte_order"]
    if measured.get("interpreter_lookahead") == 0 or blocks:
        out["stream_smooth"] = 0
    controller: Dict[str, Any] = {}
    for key in CONTROLLER_KEYS:
        value = measured.get(key)
        if value is None:
            continue
        if key == "accelerations":
            value = {"joint_%d" % axis: float(a) for axis, a in sorted(value.items())}
        elif isinstance(value, float):
            value = round(value, 6)
        controller[key] = value
    hidden = sorted(k for k in (not_measured or {}) if k in CONTROLLER_KEYS and k not in controller)
    if hidden:
        controller["not_measured"] = hidden
    out["controller"] = controller
    return out


def joint_limits(names: Sequence[str], velocity: Sequence[float], acceleration: Sequence[float],
                 measured: Mapping[str, Any]) -> Dict[str, Dict[str, Any]]:
    """MoveIt's joint limits: the velocity limits times the measured speed scale where it is below 1
    (speed 1000 then never reaches the joint limit), the measured accelerations where measured,
    the model's elsewhere."""
    scale = measured.get("speed_scale")
    factor = 1.0
    if isinstance(scale, (int, float)) and math.isfinite(scale) and 0.0 < scale < 1.0 - SPEED_TOLERANCE:
        factor = scale               # within the measurement's 2 %: the unit as assumed
    acc = measured.get("accelerations") or {}
    out = {}
    for i, name in enumerate(names):
        a = acc.get(i + 1, acceleration[i])
        out[name] = {"has_velocity_limits": True, "max_velocity": round(float(velocity[i]) * factor, 4),
                     "has_acceleration_limits": True, "max_acceleration": round(float(a), 3)}
    return out


def _identity_lines(identity: Mapping[str, Any]) -> str:
    return ", ".join("%s %s" % (k, identity[k]) for k in ("protocol", "ident", "station_address", "chk_cfg")
                     if k in identity)


def write_yaml(path: str, measured: Mapping[str, Any], identity: Mapping[str, Any],
               results: Sequence[StepResult], limits_path: str, robot_time: float,
               date: Optional[datetime.datetime] = None, not_measured: Optional[Mapping[str, str]] = None) -> None:
    """The commissioning file (module docstring); ``limits_path``: the joint_limits.yaml written
    beside it (stored absolute as ``planning_limits``; driver.launch sets it from the file's place)."""
    date = date or datetime.datetime.now(datetime.timezone.utc).astimezone()
    findings = [f for r in results for f in r.findings]
    values = driver_values(measured, not_measured)
    doc: Dict[str, Any] = {k: v for k, v in values.items() if k != "controller"}
    doc["planning_limits"] = os.path.abspath(limits_path)
    doc["controller"] = values["controller"]
    doc["commissioning"] = {
        "date": date.isoformat(timespec="seconds"),
        "controller": dict(identity),
        "robot_time": round(robot_time, 1),
        "steps": {r.name: {"status": r.status, "seconds": round(r.seconds, 2),
                           **({"error": r.error} if r.error else {})} for r in results},
        "findings": [f.as_dict() for f in findings],
    }
    if values["controller"].get("not_measured"):
        doc["commissioning"]["not_measured"] = {k: (not_measured or {})[k] for k in values["controller"]["not_measured"]}
    doc = _no_none(doc)
    text = ("Written by `rosrun vr_driver commission` on %s (vr_driver/doc/commissioning.md). Controller: %s. "
            "driver.launch commissioning:=THIS_FILE loads it into the driver's parameters (DriverParams: %s); "
            "controller holds the G2's measured behaviours (what the driver does with each is logged at connect); "
            "planning_limits names the planner's limits (joint_limits.yaml beside this file)."
            % (date.strftime("%Y-%m-%d %H:%M:%S %Z"), _identity_lines(identity), ", ".join(DRIVER_KEYS)))
    header = "".join("# %s\n" % line for line in textwrap.wrap(text, 98))
    _write(path, header + yaml.safe_dump(doc, sort_keys=False, default_flow_style=False, width=110))


def _no_none(value: Any) -> Any:
    """``value`` without None anywhere (the ROS parameter server cannot hold it: roslaunch would fail
    loading the file): a mapping's key whose value is None is left out (a finding not measured has
    no ``ok``), a None in a list becomes "none"."""
    if isinstance(value, Mapping):
        return {k: _no_none(v) for k, v in value.items() if v is not None}
    if isinstance(value, (list, tuple)):
        return ["none" if v is None else _no_none(v) for v in value]
    return value


def write_joint_limits(path: str, limits: Mapping[str, Mapping[str, Any]], source: str,
                       measured_axes: Sequence[int]) -> None:
    """``joint_limits.yaml`` in the shape of panasonic_vr006l_moveit_config/config/joint_limits.yaml."""
    lines = ["# Joint limits for planners (MoveIt's format), from the commissioning in %s." % os.path.basename(source),
             "# Velocities: the model's times the measured MOVEP speed scale where below 1; accelerations: measured",
             "# for joints %s, the model's for the others (vr_driver/doc/commissioning.md)."
             % (", ".join(str(a) for a in measured_axes) or "none"),
             "joint_limits:"]
    for name, lim in limits.items():
        lines.append("  %s: {has_velocity_limits: true, max_velocity: %g, has_acceleration_limits: true, "
                     "max_acceleration: %g}" % (name, lim["max_velocity"], lim["max_acceleration"]))
    _write(path, "\n".join(lines) + "\n")


def _write(path: str, text: str) -> None:
    tmp = path + ".tmp"
    with open(tmp, "w", encoding="utf-8") as fh:
        fh.write(text)
    os.replace(tmp, path)
