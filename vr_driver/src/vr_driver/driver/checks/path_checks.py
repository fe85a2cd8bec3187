"""The checks every path passes before anything of it is sent (ROS-free, no I/O; callers' threads,
never the bus thread): :class:`PathChecks` previews a move as the controller will run it, keeps a
straight joint move inside the workspace box, and asks the cell (:mod:`vr_driver.driver.checks.scene_guard`)
whether samples of a path or the chords between them collide.

All planning and checking is done under the driver's *planning gate* (one at a time: twenty goals
planning at once starved the bus thread of the interpreter lock, README "Reliability"). The previewer
and the scene guard may be replaced as a whole (a test's recording previewer, the plan process's scene
per request); the checks always use the current ones.
"""
from __future__ import annotations

import math
import threading
from typing import Any, Optional, Sequence

import numpy as np

from ...kinematics.preview import ENVELOPE_EPS, MovePreviewer, check_envelope
from ...kinematics.solver import Kinematics
from ...poses import Workspace
from ...protocol.base import Protocol
from ..motion.jobs import MoveRequest, Preview
from .scene_guard import SceneGuard

__all__ = ["PathChecks", "load_cell"]


def load_cell(path: str):
    """The Scene of the cell file ``path`` (None for ""); ParamError naming ``scene`` with the
    SceneError's words (the file, the entry and the key) when it is bad."""
    if not path:
        return None
    from ...errors import SceneError
    from ...kinematics.scene import load_scene
    from ...params import ParamError
    try:
        return load_scene(path)
    except SceneError as exc:
        raise ParamError("scene", path, str(exc)) from None


class PathChecks:
    """The previews and path checks of one driver (module docstring): ``previewer`` previews,
    ``scene_guard`` checks collisions, ``gate`` is the planning gate both run under; ``wire`` (the
    protocol object) says what a move's wire targets are (:meth:`~vr_driver.protocol.base.Protocol.move_commands`)."""

    def __init__(self, kinematics: Kinematics, previewer: MovePreviewer, workspace: Workspace,
                 gate: threading.Lock, scene_guard: SceneGuard, wire: Protocol) -> None:
        self.kin = kinematics
        self.wire = wire
        self.previewer = previewer
        self.workspace = workspace
        self.gate = gate
        self.scene_guard = scene_guard

    def preview(self, request: MoveRequest, start_joints: Sequence[float]) -> Preview:
        """Validate and plan ``request`` from ``start_joints``; sends nothing. The whole previewed
        path must stay inside the joint limits and the workspace box and collide with nothing.
        Raises VrDriverError (PoseError, KinematicsError, MotionError, EnvelopeError,
        ProtocolError, CollisionError) with the reason."""
        commands = self.wire.move_commands(request.move_type, request.target, request.via, self.workspace)
        # plan to exactly what will be sent (whole mm / deg)
        target = commands[-1].pose
        via = commands[0].pose if len(commands) == 2 else None
        with self.gate:
            trajectory = self.previewer.plan(request.move_type, start_joints, target, via)
        check_envelope(trajectory, self.workspace)
        self.check_collision_path(trajectory.positions, "%s path" % request.move_type.name, trajectory.times)
        return Preview(request, commands, trajectory, tuple(trajectory.goal))

    def check_joint_move(self, start: Sequence[float], end: Sequence[float]) -> None:
        """The straight joint move ``start`` -> ``end`` inside the joint limits and the workspace
        box, sampled as a PTP preview; raises (EnvelopeError, KinematicsError...) with the reason.
        (A move whose samples lie clearly inside the box is passed without building its preview:
        :meth:`_clearly_inside`.)"""
        with self.gate:
            if self._clearly_inside(start, end):
                return
            check_envelope(self.previewer.ptp_joints(start, end), self.workspace)

    def _clearly_inside(self, start: Sequence[float], end: Sequence[float]) -> bool:
        """True when the PTP preview of ``start`` -> ``end`` would pass :func:`check_envelope` --
        each of the preview's samples (the same joints: ``MovePreviewer._ptp``'s spacing and
        interpolation) and both ends within the joint limits (``Kinematics.check_limits``' rule and
        tolerance, one vector check: the ends are not checked apart first), and the TCP of each
        sample within the position box widened by half of ENVELOPE_EPS (the envelope allows all of
        it) -- without building the timed preview: the TCP's position from KDL's
        frames (``Kinematics.tcp_position``, the planner's box check; 3 x faster than the 4x4 of a
        preview sample, the same kinematics in another order of float operations: they differ by
        ~1e-13 mm, a millionth of the half left over). False whenever that is not sure -- a sample
        in that other half or beyond, a box narrower in its angles than +-180 deg, a
        previewer other than :class:`MovePreviewer`'s PTP -- and the full preview decides and words
        the error: what passes and what is refused (and how) is that of the preview alone. (A
        stream's segments: a fifth of its check was building their previews.)"""
        prev, ws = self.previewer, self.workspace
        kind = type(prev)
        if kind.ptp_joints is not MovePreviewer.ptp_joints or kind._ptp is not MovePreviewer._ptp \
                or ws.angle[0] > -180.0 or ws.angle[1] < 180.0:
            return False
        kin = prev.kin
        q0, q1 = np.array(kin.joint_vector(start)), np.array(kin.joint_vector(end))
        n = max(1, int(math.ceil(float(np.max(np.abs(q1 - q0))) / prev.settings.ptp_step)))
        s = np.linspace(0.0, 1.0, n + 1)
        positions = q0[None, :] + s[:, None] * (q1 - q0)[None, :]
        # the samples and the end itself (the last sample, q0 + (q1 - q0), may miss it by a rounding;
        # the first is q0): outside, the preview raises JointLimitError as check_limits words it
        lower, upper = np.array(kin.limits.lower) - 1e-9, np.array(kin.limits.upper) + 1e-9
        if np.any((positions < lower) | (positions > upper)) or np.any((q1 < lower) | (q1 > upper)):
            return False
        margin = ENVELOPE_EPS / 2.0
        x0, x1 = ws.x[0] - margin, ws.x[1] + margin
        y0, y1 = ws.y[0] - margin, ws.y[1] + margin
        z0, z1 = ws.z[0] - margin, ws.z[1] + margin
        for q in positions.tolist():
            x, y, z = kin.tcp_position(q)
            if not (x0 <= x <= x1 and y0 <= y <= y1 and z0 <= z <= z1):
                return False
        return True

    def check_collision_path(self, samples: Sequence[Sequence[float]], what: str,
                             times: Optional[Sequence[float]] = None) -> None:
        """Raise CollisionError when ``samples`` (joint vectors, controller order) or a straight
        chord between two of them would collide (scene_guard: the chords checked at most the
        planner's max_sweep of arm motion apart); ``what`` names the path in the message."""
        self.scene_guard.check_path(samples, what, times)

    @property
    def collision(self) -> Any:
        """The scene guard's CollisionChecker (None: nothing is checked)."""
        return self.scene_guard.checker
