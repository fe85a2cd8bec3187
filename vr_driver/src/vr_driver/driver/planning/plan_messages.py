"""The messages between the driver and its planning process (vr_driver.driver.planning.plan_process), one
class each -- the same pattern as the bus process's (:mod:`vr_driver.bus.messages`): a frozen
dataclass per message with :meth:`~vr_driver.bus.messages.Message.encode` and :func:`decode`
(every field checked: a malformed message raises :class:`PlanMessageError` naming what is wrong,
and changes nothing), a plain tagged tuple on the wire, and a :class:`Channel` per end.

The driver sends (:data:`TO_WORKER`)::

    Configure     ("start", params: DriverParams)          the first message: build the planning parts
    Plan          ("plan", goal: PlanGoal, start, seed, cycle_rate, scene: SceneSnapshot or None)
                                                           one plan: the arm's joints to plan from, the
                                                           planner's seed (None: random), the node's
                                                           bus cycle rate [Hz], the scene change:
                                                           the driver's scene when it differs from the one
                                                           sent last (None: unchanged)
    Stop          ("stop",)                                end the process

Each message but Stop gets exactly one answer, a malformed one too (PlanFailed: it changes
nothing). A plan is cancelled by stopping the process: the worker is busy in C++ while it plans.

The planning process sends (:data:`FROM_WORKER`)::

    Ready         ("ready",)                               the parts are built: it plans
    Missing       ("missing", package, module, feature, text)   a library is missing (MissingDependency)
    StartFailed   ("error", text)                          it cannot plan for these parameters
    Outcome       ("outcome", outcome: PlanOutcome)        a plan's result, its profile included, and on
                                                           success what the driver sends for it as the
                                                           stream check made it (the node's announcement)
    PlanFailed    ("exception", text)                      the plan failed inside (a planner bug), or the
                                                           request was malformed: it goes on
    Log           ("log", level, text)                     one of its warnings, for the node's log
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from multiprocessing.connection import Connection
from typing import TYPE_CHECKING, Dict, Optional, Tuple, Type

from ...bus.messages import Channel, Message, message
from ...errors import VrDriverError
from ...kinematics.scene import Scene, SceneObject
from ...params import DriverParams
from .planning import PlanGoal, PlanOutcome

if TYPE_CHECKING:
    from ..core import DriverCore

__all__ = ["PlanMessageError", "Configure", "SceneSnapshot", "Plan", "Stop", "Ready", "Missing", "StartFailed",
           "Outcome", "PlanFailed", "Log", "TO_WORKER", "FROM_WORKER", "driver_end", "worker_end"]

#: a scene object as the socket carries it: (name, shape, size, position, quaternion)
ObjectTuple = Tuple[str, str, Tuple[float, ...], Tuple[float, ...], Tuple[float, ...]]


class PlanMessageError(VrDriverError):
    """A planning message that is not one of the protocol's, or whose fields are not what it says."""


class PlanMessage(Message):
    NOUN = "planning message"
    ERROR = PlanMessageError


def _numbers(value: tuple, what: str) -> Tuple[float, ...]:
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value):
        raise PlanMessageError("planning message: %s %.80r, expected finite numbers" % (what, value))
    return tuple(float(v) for v in value)


# ---------------------------------------------------------------------------- the driver's
@message("start")
class Configure(PlanMessage):
    """("start", params): the first message; the worker builds its planning parts for ``params``."""

    params: DriverParams


@dataclass(frozen=True)
class SceneSnapshot:
    """The driver's scene as a plan uses it (a :class:`Plan` carries it when it changed): the objects
    of its checker as (name, shape, size, position, quaternion) tuples, its padding [m], and whether
    the driver checks collisions (it has a checker); without checking the objects are left out
    (nothing checks them)."""

    objects: Tuple[ObjectTuple, ...]
    padding: float
    checked: bool

    @classmethod
    def of(cls, core: "DriverCore") -> "SceneSnapshot":
        """The scene of ``core``'s checker now, read under the core's planning gate (the checker,
        its scene and padding are replaced as a whole under it, never changed in place)."""
        with core.planning_gate:
            checker = core.collision
            if checker is None or not core.params.collision_check:
                return cls((), float(core.params.collision_padding), False)
            objects = tuple((o.name, o.shape, tuple(o.size), tuple(o.position), tuple(o.quaternion))
                            for o in checker.scene.objects())
            return cls(objects, float(checker.padding), True)

    def check(self) -> "SceneSnapshot":
        """Itself when its fields are what they say; PlanMessageError naming the one that is not."""
        if not (isinstance(self.objects, tuple) and isinstance(self.padding, (int, float))
                and isinstance(self.checked, bool)):
            raise PlanMessageError("planning message 'plan': a scene %.80r, expected (objects, padding, checked)"
                                   % (self,))
        for obj in self.objects:
            if not (isinstance(obj, tuple) and len(obj) == 5 and isinstance(obj[0], str) and isinstance(obj[1], str)
                    and all(isinstance(v, tuple) for v in obj[2:])):
                raise PlanMessageError("planning message 'plan': a scene object %.80r, expected (name, shape, "
                                       "size, position, quaternion)" % (obj,))
        return self

    def scene(self) -> Scene:
        """The objects as a Scene (each rebuilt by SceneObject's own checks)."""
        return Scene([SceneObject(name, shape, size, position, quaternion=quaternion)
                      for name, shape, size, position, quaternion in self.objects])


@message("plan")
class Plan(PlanMessage):
    """("plan", goal, start, seed, cycle_rate, scene): plan ``goal`` from the joints ``start`` with
    the planner's ``seed`` (None: random); ``cycle_rate`` [Hz] the bus cycle rate the node's streams
    are fed at (DriverCore.stream_cycle_rate: its measured bus cycle where slower), so that the
    worker's stream check is the node's; ``scene`` the driver's scene when it differs from the one
    this worker got last (None: unchanged)."""

    goal: PlanGoal
    start: tuple
    seed: Optional[int]
    cycle_rate: float
    scene: Optional[SceneSnapshot]

    @classmethod
    def from_fields(cls, values: tuple) -> "Plan":
        plan = super().from_fields(values)
        _numbers(plan.start, "start joints")   # type: ignore[attr-defined]
        if not (math.isfinite(plan.cycle_rate) and plan.cycle_rate > 0.0):   # type: ignore[attr-defined]
            raise PlanMessageError("planning message 'plan': cycle_rate %r, expected a positive number"
                                   % (plan.cycle_rate,))   # type: ignore[attr-defined]
        if plan.scene is not None:   # type: ignore[attr-defined]
            plan.scene.check()   # type: ignore[attr-defined]
        return plan  # type: ignore[return-value]


@message("stop")
class Stop(PlanMessage):
    """("stop",): end the planning process."""


# ---------------------------------------------------------------------------- the planning process's
@message("ready")
class Ready(PlanMessage):
    """("ready",): the worker has built its parts; it plans."""


@message("missing")
class Missing(PlanMessage):
    """("missing", package, module, feature, text): a library the planning needs is missing (the
    worker's MissingDependency, ``text`` its words)."""

    package: str
    module: str
    feature: str
    text: str


@message("error")
class StartFailed(PlanMessage):
    """("error", text): the worker cannot plan for these parameters (a model, its limits)."""

    text: str


@message("outcome")
class Outcome(PlanMessage):
    """("outcome", outcome): a plan's :class:`~vr_driver.driver.planning.planning.PlanOutcome` (its
    trajectory, words and profile; its stream or PTP previews, which the node announces the run with)."""

    outcome: PlanOutcome


@message("exception")
class PlanFailed(PlanMessage):
    """("exception", text): the plan failed inside the worker, or its request was malformed; the
    worker goes on."""

    text: str


@message("log")
class Log(PlanMessage):
    """("log", level, text): one of the worker's log records (logging's level), for the node's log."""

    level: int
    text: str


TO_WORKER: Dict[str, Type[Message]] = {m.TAG: m for m in (Configure, Plan, Stop)}
FROM_WORKER: Dict[str, Type[Message]] = {m.TAG: m for m in (Ready, Missing, StartFailed, Outcome, PlanFailed, Log)}


def driver_end(conn: Connection) -> Channel:
    """The driver's end (the client): receives what the planning process sends."""
    return Channel(conn, FROM_WORKER)


def worker_end(conn: Connection) -> Channel:
    """The planning process's end (the server): receives what the driver sends."""
    return Channel(conn, TO_WORKER)
