"""How the pose terminal names and writes a pose: its six fields as the controller calls them (X Y Z
in mm, Rx Ry Rz in deg), numbers without trailing zeros, a pose and the joints on one line.

The bottom of the terminal package: :mod:`vr_driver.terminal.pose_input` (reading what is typed)
and :mod:`vr_driver.terminal.sent_move` (reporting a move) both write with it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

from ..poses import ControllerPose

__all__ = ["Field", "FIELDS", "fmt_number", "fmt_pose", "fmt_joints_deg"]


@dataclass(frozen=True)
class Field:
    name: str          # attribute of ControllerPose
    label: str         # what the controller calls it
    unit: str

    @property
    def quantity(self) -> str:
        """What a value of this field is, with its article: 'a position' (mm) or 'an angle' (deg)."""
        return "an angle" if self.unit == "deg" else "a position"


FIELDS = (Field("x", "X", "mm"), Field("y", "Y", "mm"), Field("z", "Z", "mm"),
          Field("rx", "Rx", "deg"), Field("ry", "Ry", "deg"), Field("rz", "Rz", "deg"))


def fmt_number(value: float, decimals: int = 3) -> str:
    """1120.0 -> '1120', 12.5 -> '12.5', -0.0 -> '0'."""
    text = ("%.*f" % (decimals, value)).rstrip("0").rstrip(".") if decimals else "%.0f" % value
    return "0" if text in ("-0", "") else text


def fmt_pose(pose: ControllerPose) -> str:
    return "  ".join("%s %s" % (f.label, fmt_number(getattr(pose, f.name), 1)) for f in FIELDS)


def fmt_joints_deg(joints_rad: Sequence[float]) -> str:
    return "  ".join("J%d %.1f" % (i + 1, math.degrees(q)) for i, q in enumerate(joints_rad))
