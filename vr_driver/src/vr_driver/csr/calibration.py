"""The ``.csr`` route of the kinematic calibration: calibration pairs from a program with the taught
points in joint form and the poses the controller reported while the arm stood at them. ROS-free:
``rosrun vr_driver calibrate record`` (:mod:`vr_driver.ros.calibration_recorder`) feeds it the
driver's ``tool_pose``; tests feed it a stepped driver world.

The pair is what the fit (``panasonic_vr006l_support.kinematic_calibration``) needs: the joint
angles as the controller counts them (the taught point's AJ columns RT..TW, turned into the model's
joints by the program's :class:`~.conventions.JointConvention`, in degrees) and the TCP pose the
controller itself reports there (its own kinematics: X Y Z mm, Rx Ry Rz deg). Our model is used
only to tell which taught point a rest belongs to.

- :func:`taught_points`: the AJ points the program's MOVEs visit, in order (every AJ pose if the
  program has no MOVE); CsrError for a Cartesian (AU) point, duplicates or none.
- :class:`RestDetector`: a rest is a run of reported poses that stays within ``still_mm`` /
  ``still_deg`` of its first sample for ``hold`` seconds; reported once, with the mean pose.
- :class:`PairRecorder`: each rest to the nearest taught point by our model's FK within the gate
  (the fit's own "unreachable pair" limits, 100 mm / 10 deg); the later rest at a point replaces an
  earlier one; :meth:`PairRecorder.write` writes the YAML the fit reads, only when every point has
  its pose (unless ``partial``).
"""
from __future__ import annotations

import datetime as _dt
import math
import os
from dataclasses import dataclass, field
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from ..errors import CsrError
from .conventions import JointConvention
from .model import CsrProgram

#: a taught point this near another (every joint, deg) is the same point twice
DUPLICATE_DEG = 0.05
#: defaults of the rest detector: [s], [mm], [deg]
REST_HOLD = 1.0
REST_STILL_MM = 0.3
REST_STILL_DEG = 0.05
#: reported poses further apart than this [s] (a link loss) start a new rest
REST_MAX_GAP = 0.5


@dataclass(frozen=True)
class TaughtPoint:
    """A taught point: its name in the program, the model's joints in degrees (chain order), and the
    line it was read from."""

    name: str
    joints_deg: Tuple[float, ...]
    line: int = 0


def taught_points(program: CsrProgram, convention: JointConvention = JointConvention(),
                  source: str = "") -> List[TaughtPoint]:
    """The taught points of ``program``: the poses its MOVE commands visit, in order of first visit
    (all poses in [Pose] order when it has no MOVE). Each must be an AJ pose (the joint form): the
    calibration needs the joints the controller counts, which an AU (Cartesian) point does not give."""
    names: List[str] = []
    for move in program.moves():
        if move.point not in names:
            names.append(move.point)
    if not names:
        names = [p.name for p in program.poses]
    if not names:
        raise CsrError("the program has no poses: nothing to calibrate with", source=source)
    points: List[TaughtPoint] = []
    for name in names:
        try:
            pose = program.pose(name)
        except KeyError:
            raise CsrError("a MOVE visits %s, which is not in [Pose]" % name, field="pose " + name,
                           source=source) from None
        if pose.kind != "AJ":
            raise CsrError("pose %s is %s, not AJ: the calibration needs the taught points in joint form "
                           "(axis coordinates RT..TW); re-teach or re-save the point as joint angles"
                           % (name, pose.kind), pose.line, "pose " + name, source)
        q = convention.from_aj(pose.values[:6])
        points.append(TaughtPoint(name, tuple(math.degrees(v) for v in q), pose.line))
    for i, a in enumerate(points):
        for b in points[:i]:
            if max(abs(x - y) for x, y in zip(a.joints_deg, b.joints_deg)) < DUPLICATE_DEG:
                raise CsrError("pose %s repeats pose %s (the same joints): each calibration pose must be distinct"
                               % (a.name, b.name), a.line, "pose " + a.name, source)
    return points


@dataclass(frozen=True)
class Rest:
    """The arm stood still from ``start`` to ``end`` [s]: ``pose`` is the mean reported pose (mm, deg),
    ``samples`` how many poses it averages, ``spread_mm`` / ``spread_deg`` the largest departure of a
    sample from the first."""

    start: float
    end: float
    pose: Tuple[float, ...]
    samples: int
    spread_mm: float = 0.0
    spread_deg: float = 0.0


def _angle_delta(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return (a - b + 180.0) % 360.0 - 180.0


class RestDetector:
    """Finds where the reported pose stands still. :meth:`feed` each reported pose (stamp [s], six
    values); it returns a :class:`Rest` once per rest, when the pose has stayed within ``still_mm`` /
    ``still_deg`` of the rest's first sample for ``hold`` seconds; the rest then goes on (and is not
    reported again) until the pose leaves it. A sample that is not six finite numbers is ignored
    (counted in ``ignored``); a gap longer than ``max_gap`` or a stamp going back starts afresh."""

    def __init__(self, hold: float = REST_HOLD, still_mm: float = REST_STILL_MM,
                 still_deg: float = REST_STILL_DEG, max_gap: float = REST_MAX_GAP) -> None:
        for name, value in (("hold", hold), ("still_mm", still_mm), ("still_deg", still_deg),
                            ("max_gap", max_gap)):
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0.0):
                raise ValueError("RestDetector: %s must be a positive number, got %r" % (name, value))
        self.hold = float(hold)
        self.still_mm = float(still_mm)
        self.still_deg = float(still_deg)
        self.max_gap = float(max_gap)
        self.ignored = 0
        self._start: Optional[float] = None
        self._last: Optional[float] = None
        self._first = np.zeros(6)
        self._sum = np.zeros(6)
        self._n = 0
        self._spread = (0.0, 0.0)
        self._reported = False

    def _begin(self, t: float, pose: np.ndarray) -> None:
        self._start = self._last = t
        self._first = pose
        self._sum = np.zeros(6)
        self._n = 1
        self._spread = (0.0, 0.0)
        self._reported = False

    def feed(self, t: float, pose: Sequence[float]) -> Optional[Rest]:
        try:
            values = np.asarray([float(v) for v in pose], dtype=float)
            t = float(t)
        except (TypeError, ValueError):
            self.ignored += 1
            return None
        if values.shape != (6,) or not np.all(np.isfinite(values)) or not math.isfinite(t):
            self.ignored += 1
            return None
        if self._start is None or self._last is None or t < self._last or t - self._last > self.max_gap:
            self._begin(t, values)
            return None
        d = values - self._first
        d[3:] = _angle_delta(values[3:], self._first[3:])
        dist_mm, dist_deg = float(np.linalg.norm(d[:3])), float(np.max(np.abs(d[3:])))
        if dist_mm > self.still_mm or dist_deg > self.still_deg:
            self._begin(t, values)
            return None
        self._last = t
        self._sum += d
        self._n += 1
        self._spread = (max(self._spread[0], dist_mm), max(self._spread[1], dist_deg))
        if self._reported or t - self._start < self.hold:
            return None
        self._reported = True
        mean = self._first + self._sum / self._n
        mean[3:] = _angle_delta(mean[3:], np.zeros(3))
        return Rest(self._start, t, tuple(float(v) for v in mean), self._n, *self._spread)


@dataclass
class Recorded:
    """The pose recorded at a taught point (and how near our model put it: ``model_mm``, ``model_deg``)."""

    point: TaughtPoint
    rest: Rest
    model_mm: float
    model_deg: float


#: the model's pose errors at taught joints: (N, 6) joints deg, (N, 6) poses -> (mm, deg) arrays
ModelErrors = Callable[[np.ndarray, np.ndarray], Tuple[np.ndarray, np.ndarray]]


def model_errors(model_path: Optional[str] = None) -> ModelErrors:
    """How far the model (``model_path``: a kinematics YAML; None: the package's) puts the TCP at given
    joints from given poses -- the fit's own measure (panasonic_vr006l_support.kinematic_calibration)."""
    from panasonic_vr006l_support import kinematic_calibration as kc
    params = kc.nominal_parameters(model_path) if model_path else kc.nominal_parameters()
    return lambda joints, poses: kc.pair_errors(params, joints, poses)


@dataclass
class PairRecorder:
    """Rests -> calibration pairs. ``errors`` measures our model against a reported pose (
    :func:`model_errors`); a rest within ``gate_mm`` / ``gate_deg`` of a taught point's model pose
    belongs to the nearest such point."""

    points: Sequence[TaughtPoint]
    errors: ModelErrors
    gate_mm: float = 100.0
    gate_deg: float = 10.0
    recorded: Dict[str, Recorded] = field(default_factory=dict)

    def add(self, rest: Rest) -> Tuple[Optional[Recorded], str]:
        """Assign ``rest`` to its taught point; returns what was recorded (None if the rest belongs to no
        point) and a line for the log."""
        joints = np.array([p.joints_deg for p in self.points], dtype=float)
        poses = np.repeat(np.array([rest.pose], dtype=float), len(self.points), axis=0)
        mm, deg = self.errors(joints, poses)
        score = mm + deg * (self.gate_mm / self.gate_deg)
        k = int(np.argmin(score))
        pose_text = "(%.2f, %.2f, %.2f mm, %.3f, %.3f, %.3f deg)" % rest.pose
        if mm[k] > self.gate_mm or deg[k] > self.gate_deg:
            return None, ("rest at %s matches no taught point (nearest: %s, %.1f mm / %.2f deg from our model's "
                          "pose there; the gate is %g mm / %g deg): not recorded"
                          % (pose_text, self.points[k].name, mm[k], deg[k], self.gate_mm, self.gate_deg))
        point = self.points[k]
        again = point.name in self.recorded
        rec = Recorded(point, rest, float(mm[k]), float(deg[k]))
        self.recorded[point.name] = rec
        return rec, ("%s %s: %s, %.1f s still, %d samples; our model is %.2f mm / %.3f deg off (%d of %d recorded)"
                     % (point.name, "recorded again" if again else "recorded", pose_text, rest.end - rest.start,
                        rest.samples, mm[k], deg[k], len(self.recorded), len(self.points)))

    def missing(self) -> List[str]:
        return [p.name for p in self.points if p.name not in self.recorded]

    @property
    def complete(self) -> bool:
        return not self.missing()

    def pairs(self) -> List[Tuple[List[float], List[float]]]:
        """(joints deg, pose mm / deg) of every recorded point, in the program's order."""
        return [(list(self.recorded[p.name].point.joints_deg), list(self.recorded[p.name].rest.pose))
                for p in self.points if p.name in self.recorded]

    def text(self, program_path: str = "", date: Optional[str] = None) -> str:
        date = date or _dt.datetime.now().replace(microsecond=0).isoformat()
        lines = ["# calibration pairs recorded %s by rosrun vr_driver calibrate record" % date,
                 "# taught points (joints): %s" % (program_path or "-"),
                 "# pose: the controller's reported TCP pose at rest (X Y Z mm, Rx Ry Rz deg)",
                 "# fit: rosrun vr_driver calibrate fit THIS_FILE --write fitted.yaml --xacro fitted.xacro"]
        missing = self.missing()
        if missing:
            lines.append("# NOT RECORDED: %s" % ", ".join(missing))
        lines.append("pairs:")
        for p in self.points:
            rec = self.recorded.get(p.name)
            if rec is None:
                continue
            lines.append("- {name: %s, joints: [%s], pose: [%s], still_s: %.2f, model_mm: %.3f, model_deg: %.4f}"
                         % (p.name, ", ".join("%.4f" % v for v in p.joints_deg),
                            ", ".join("%.4f" % v for v in rec.rest.pose), rec.rest.end - rec.rest.start,
                            rec.model_mm, rec.model_deg))
        return "\n".join(lines) + "\n"

    def write(self, path: str, program_path: str = "", partial: bool = False) -> str:
        """Write the pairs YAML (atomically). Refuses (CsrError, nothing written) while a point has no
        pose, unless ``partial``, and when nothing is recorded at all."""
        missing = self.missing()
        if not self.recorded:
            raise CsrError("no taught point has a recorded pose yet: nothing written")
        if missing and not partial:
            raise CsrError("%d of %d taught points have no recorded pose (%s): nothing written"
                           % (len(missing), len(self.points), ", ".join(missing)))
        text = self.text(program_path)
        tmp = "%s.tmp%d" % (path, os.getpid())
        try:
            with open(tmp, "w") as f:
                f.write(text)
            os.replace(tmp, path)
        except OSError as exc:
            try:
                os.unlink(tmp)
            except OSError:
                pass
            raise CsrError("cannot write %s: %s" % (path, exc.strerror or exc)) from None
        return text
