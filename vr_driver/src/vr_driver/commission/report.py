"""The end of a commissioning: the table (assumption, expected, measured, consequence) and the files
(ROS-free).

:func:`write_yaml` writes ONE file for ``driver.launch commissioning:=FILE``: the driver's parameters
that follow from the measurements, by their DriverParams names (``protocol``, ``byte_order``,
``stream_smooth``), the measured behaviours of the G2 under keys of their own (the virtual G2's
names: ``interpreter_lookahead``, ``speed_scale``, ``loop_blocks_during_move``, ...; the driver does
not read them yet), the planner's joint limits (``joint_limits``, MoveIt's shape) and, under
``commissioning``, the date, the controller's identity, the robot time and the table.
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

__all__ = ["DRIVER_KEYS", "NEW_KEYS", "table", "driver_values", "joint_limits", "write_yaml",
           "write_joint_limits"]

#: a speed scale this close to 1 is the assumed unit (the measurement's own precision)
SPEED_TOLERANCE = 0.02
#: DriverParams names the commissioning sets
DRIVER_KEYS = ("protocol", "byte_order", "stream_smooth")
#: keys of measured G2 behaviours the driver does not read yet (the virtual G2's parameter names)
NEW_KEYS = ("interpreter_lookahead", "loop_period", "loop_period_spread", "loop_blocks_during_move",
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


def driver_values(measured: Mapping[str, Any]) -> Dict[str, Any]:
    """The driver's parameters (DriverParams names) and the new keys, from what was measured."""
    out: Dict[str, Any] = {"protocol": "v3"}
    if "byte_order" in measured:
        out["byte_order"] = measured["byte_order"]
    if measured.get("interpreter_lookahead") == 0 or measured.get("loop_blocks_during_move"):
        out["stream_smooth"] = 0
    for key in NEW_KEYS:
        value = measured.get(key)
        if value is None:
            continue
        if key == "accelerations":
            value = {"joint_%d" % axis: float(a) for axis, a in sorted(value.items())}
        elif isinstance(value, float):
            value = round(value, 6)
        out[key] = value
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
               results: Sequence[StepResult], limits: Mapping[str, Any], robot_time: float,
               date: Optional[datetime.datetime] = None) -> None:
    """The commissioning file (module docstring)."""
    date = date or datetime.datetime.now(datetime.timezone.utc).astimezone()
    findings = [f for r in results for f in r.findings]
    doc: Dict[str, Any] = dict(driver_values(measured))
    doc["joint_limits"] = dict(limits)
    doc["commissioning"] = {
        "date": date.isoformat(timespec="seconds"),
        "controller": dict(identity),
        "robot_time": round(robot_time, 1),
        "steps": {r.name: {"status": r.status, "seconds": round(r.seconds, 2),
                           **({"error": r.error} if r.error else {})} for r in results},
        "findings": [f.as_dict() for f in findings],
    }
    text = ("Written by `rosrun vr_driver commission` on %s (vr_driver/doc/commissioning.md). Controller: %s. "
            "driver.launch commissioning:=THIS_FILE sets the driver's parameters below (DriverParams names: %s); "
            "%s are the G2's measured behaviours (the virtual G2's parameter names); joint_limits are the "
            "planner's (also in joint_limits.yaml beside this file)."
            % (date.strftime("%Y-%m-%d %H:%M:%S %Z"), _identity_lines(identity), ", ".join(DRIVER_KEYS),
               ", ".join(NEW_KEYS)))
    header = "".join("# %s\n" % line for line in textwrap.wrap(text, 98))
    _write(path, header + yaml.safe_dump(doc, sort_keys=False, default_flow_style=False, width=110))


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
