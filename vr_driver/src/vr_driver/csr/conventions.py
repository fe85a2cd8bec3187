"""Joint-angle conventions: URDF joint angles (radians) <-> the AJ columns RT UA FA RW BW TW."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence, Tuple, Union

from ..errors import CsrError
from .fields import JOINT_COLUMNS, _number, show


@dataclass(frozen=True)
class JointConvention:
    """URDF joints (radians, joint_1..joint_6) <-> AJ columns RT UA FA RW BW TW (degrees)::

        x_i   = degrees(q_i)                    for every axis, except
        x_FA  = degrees(q_3 + coupling * q_2)   when fa_reference == "horizontal"
        AJ_i  = sign_i * x_i + offset_i

    ``fa_reference`` "ua": FA is the forearm angle relative to the upper arm (the URDF's joint_3);
    "horizontal": the forearm angle relative to the horizontal (as ABB / Fanuc J3 count it).
    ``coupling`` is +1 when joint_2 and joint_3 turn about the same direction (our URDF), -1 when
    opposite (:meth:`coupling_of` reads it from a Kinematics). ``signs`` are +1 / -1,
    ``offsets`` degrees. The default (ua, +1, 0) is the identity: both conventions agree at the
    zero pose (upper arm vertical, forearm horizontal), and the thesis gives no other evidence."""

    fa_reference: str = "ua"
    signs: Tuple[int, ...] = (1, 1, 1, 1, 1, 1)
    offsets: Tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    coupling: int = 1

    def __post_init__(self) -> None:
        if self.fa_reference not in ("ua", "horizontal"):
            raise CsrError("%s is not 'ua' or 'horizontal'" % show(self.fa_reference), field="FA reference")
        signs = tuple(self.signs)
        if len(signs) != 6 or any(s not in (1, -1) or isinstance(s, bool) for s in signs):
            raise CsrError("signs must be six values +1 / -1, got %s" % show(self.signs), field="signs")
        object.__setattr__(self, "signs", signs)
        if len(tuple(self.offsets)) != 6:
            raise CsrError("offsets must be six numbers (degrees), got %s" % show(self.offsets), field="offsets")
        object.__setattr__(self, "offsets", tuple(_number(v, "offset %s" % axis)
                                                  for axis, v in zip(JOINT_COLUMNS, self.offsets)))
        if self.coupling not in (1, -1):
            raise CsrError("coupling must be +1 or -1, got %s" % show(self.coupling), field="coupling")

    @classmethod
    def from_options(cls, fa_reference: str = "ua", flip: Union[str, Sequence[str]] = (),
                     offsets: Union[Mapping[str, float], Sequence[str]] = (), coupling: int = 1
                     ) -> "JointConvention":
        """From option values: ``flip`` "UA,BW" or ["UA", "BW"]; ``offsets`` {"BW": -90} or
        ["BW=-90"]. Axis names are RT UA FA RW BW TW (case-insensitive)."""
        names = flip.split(",") if isinstance(flip, str) else list(flip)
        signs = [1] * 6
        for name in names:
            if not name.strip():
                continue
            signs[_axis_index(name, "flip")] = -1
        values = [0.0] * 6
        items = offsets.items() if isinstance(offsets, Mapping) else [_split_offset(s) for s in offsets]
        for axis, value in items:
            values[_axis_index(axis, "offset")] = _number(value, "offset %s" % axis)
        return cls(fa_reference, tuple(signs), tuple(values), coupling)

    @staticmethod
    def coupling_of(kinematics: Any) -> int:
        """+1 if the chain's 2nd and 3rd joints turn about the same direction at the zero pose,
        -1 if opposite; CsrError if they are not parallel (no 'horizontal' FA then)."""
        import numpy as np
        t = np.eye(4)
        axes = []
        for j in kinematics.chain_joints:
            t = t @ j.origin
            if j.movable:
                axes.append(t[:3, :3] @ np.array(j.axis))
        if len(axes) < 3:
            raise CsrError("the chain has fewer than 3 joints", field="FA reference")
        dot = float(axes[1] @ axes[2])
        if abs(abs(dot) - 1.0) > 1e-6:
            raise CsrError("joint 2 and joint 3 are not parallel: the FA reference is undefined", field="FA reference")
        return 1 if dot > 0 else -1

    def to_aj(self, q: Sequence[float]) -> Tuple[float, ...]:
        x = [math.degrees(v) for v in q[:6]]
        if self.fa_reference == "horizontal":
            x[2] = math.degrees(q[2] + self.coupling * q[1])
        return tuple(s * v + o for s, v, o in zip(self.signs, x, self.offsets))

    def from_aj(self, aj: Sequence[float]) -> Tuple[float, ...]:
        x = [(v - o) * s for v, s, o in zip(aj[:6], self.signs, self.offsets)]
        q = [math.radians(v) for v in x]
        if self.fa_reference == "horizontal":
            q[2] = math.radians(x[2]) - self.coupling * q[1]
        return tuple(q)

    def describe(self) -> str:
        flips = [a for a, s in zip(JOINT_COLUMNS, self.signs) if s < 0]
        offs = ["%s%+g" % (a, o) for a, o in zip(JOINT_COLUMNS, self.offsets) if o]
        return "FA relative to %s, flipped: %s, offsets: %s" % (
            "UA" if self.fa_reference == "ua" else "the horizontal", ",".join(flips) or "none",
            ",".join(offs) or "none")


def _axis_index(name: str, what: str) -> int:
    key = name.strip().upper()
    if key not in JOINT_COLUMNS:
        raise CsrError("%s is not an axis (%s)" % (show(name), ", ".join(JOINT_COLUMNS)), field=what)
    return JOINT_COLUMNS.index(key)


def _split_offset(text: str) -> Tuple[str, str]:
    if "=" not in text:
        raise CsrError("%s is not AXIS=DEGREES (e.g. BW=-90)" % show(text), field="offset")
    axis, value = text.split("=", 1)
    return axis, value
