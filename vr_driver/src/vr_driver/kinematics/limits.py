"""The joint limits of a chain (:class:`JointLimits`): read from its URDF joints and the model's
acceleration set, and the joint-space operations that need nothing but them (clamp into the
limits, name the joints outside, draw joints within). ROS-free; no PyKDL."""
from __future__ import annotations

import functools
import math
import random
from dataclasses import dataclass
from typing import Dict, List, Mapping, Optional, Sequence, Tuple

from panasonic_vr006l_support import joint_limits as _support_limits
from panasonic_vr006l_support.model import Joint

from ..errors import ModelError


@functools.lru_cache(maxsize=None)
def model_accelerations() -> Dict[str, float]:
    """{joint name: acceleration [rad/s^2]} of the model's set (the support package's YAML, read once)."""
    try:
        return dict(_support_limits.accelerations())
    except _support_limits.LimitsError as exc:
        raise ModelError(str(exc)) from exc


@dataclass(frozen=True)
class JointLimits:
    """Per joint, in chain order: position limits and velocity [rad/s] from the URDF; acceleration
    [rad/s^2] from the model's one set (panasonic_vr006l_support's kinematics_vr006l.yaml: an
    assumption, velocity / 0.1 s, to measure on the real arm), inf for a joint the set does not name."""

    names: Tuple[str, ...]
    lower: Tuple[float, ...]
    upper: Tuple[float, ...]
    velocity: Tuple[float, ...]
    revolute: Tuple[bool, ...]
    acceleration: Tuple[float, ...] = ()

    @classmethod
    def of_joints(cls, movable: Sequence[Joint], prefix: str = "",
                  accelerations: Optional[Mapping[str, float]] = None) -> "JointLimits":
        """The limits of the movable URDF joints ``movable`` (in chain order): a missing position or velocity limit is inf (continuous joints). Each joint's
        acceleration comes from ``accelerations`` ({joint name: rad/s^2}, the URDF's names) when
        given, else from the model's set by the joint's name without ``prefix``; inf where none is
        known. ModelError for an acceleration that is not a number > 0."""
        return cls(names=tuple(j.name for j in movable),
                   lower=tuple(-math.inf if j.lower is None else j.lower for j in movable),
                   upper=tuple(math.inf if j.upper is None else j.upper for j in movable),
                   velocity=tuple(math.inf if j.velocity is None else j.velocity for j in movable),
                   revolute=tuple(j.type != "prismatic" for j in movable),
                   acceleration=_accelerations(movable, prefix, accelerations))

    @property
    def ramp_time(self) -> Optional[float]:
        """[s] from rest to full speed of the slowest-ramping joint (max velocity / acceleration over
        the joints with both finite, rounded to 1 ns); None when no joint has an acceleration."""
        try:
            return _support_limits.ramp_time(self.velocity, self.acceleration)
        except _support_limits.LimitsError:
            return None

    def violations(self, q: Sequence[float], tol: float = 1e-9) -> List[str]:
        """One line per joint of ``q`` outside its position limits (by more than ``tol``)."""
        return ["%s = %.6g outside [%.6g, %.6g]" % (n, v, lo, hi)
                for n, v, lo, hi in zip(self.names, q, self.lower, self.upper) if not lo - tol <= v <= hi + tol]

    def clamp(self, q: Sequence[float]) -> Tuple[float, ...]:
        """``q`` with each joint moved to its nearest position limit where it lies outside."""
        return tuple(min(max(v, lo), hi) for v, lo, hi in zip(q, self.lower, self.upper))

    def random_joints(self, rng: random.Random) -> Tuple[float, ...]:
        """Joints drawn uniformly within the limits (continuous joints: within +-pi)."""
        return tuple(rng.uniform(max(lo, -math.pi) if not math.isfinite(lo) else lo,
                                 min(hi, math.pi) if not math.isfinite(hi) else hi)
                     for lo, hi in zip(self.lower, self.upper))


def _accelerations(movable: Sequence[Joint], prefix: str,
                   given: Optional[Mapping[str, float]]) -> Tuple[float, ...]:
    """Each joint's acceleration limit (:meth:`JointLimits.of_joints`)."""
    out = []
    for j in movable:
        if given is not None:
            value = given.get(j.name, math.inf)
        else:
            plain = j.name[len(prefix):] if prefix and j.name.startswith(prefix) else j.name
            value = model_accelerations().get(plain, math.inf)
        if not (isinstance(value, (int, float)) and not isinstance(value, bool) and value > 0.0
                and not math.isnan(value)):
            raise ModelError("joint %s: acceleration limit must be a number > 0, got %r" % (j.name, value))
        out.append(float(value))
    return tuple(out)
