"""The cell and the collision checks of the driver (issue 27): ROS-free, behind
:class:`~vr_driver.driver.core.DriverCore`'s ``collision``, ``scene()``, ``add_scene_object``,
``remove_scene_object``, ``clear_scene``, ``load_scene`` and ``check_collision_path``.

What is checked: every path before anything of it is queued -- a move's previewed samples (PTP,
LIN, CIRC; so also each PTP of a joint path), a trajectory's samples, the straight joint chords a
stream is sent as, a joint_command step -- against the arm itself (the link pairs the SRDF does
not disable) and every object of the scene, with every shape inflated by ``collision_padding``
(kinematics.collision). Between two samples the straight joint chord is checked at configurations
so close that no point of the arm moves more than ``max_sweep`` (the planner's motion-check
resolution, kinematics.planner.DEFAULT_MAX_SWEEP, 20 mm) from one to the next: the bound is the
planner's, sum_i w_i |dq_i| with w_i the lever arm of joint i (kinematics.planner.joint_weights).
A collision is then missed only where less than ``max_sweep`` / 2 of the arm crosses less than
``max_sweep`` of an obstacle; the padding (10 mm by default) covers that.

A refusal is a :class:`~vr_driver.errors.CollisionError` naming where (the sample, or the chord
between two samples, and its time when the path has times), the link(s) and the other link or the
object, with the depth (or the gap, inside the padding); it changes nothing.

Scene changes (add, replace, remove, clear, load) are checked whole first (SceneError: nothing
changes), then the new checker is built beside the old one and swapped in under the core's
planning gate, so that a check runs either wholly before or wholly after a change. An object may
be added where the arm stands now: it is added, with a warning naming it. A path that starts in
collision is then accepted only if it moves out of it -- until its first free configuration it
touches nothing but what the start touches (the same link / link-or-object pairs) and never goes
deeper, from there on everything is free, and a path that never gets free (a short jog step) ends
farther out than it started -- so the arm can be moved out, never deeper or into something else.
Refusing the object instead would hide a real obstacle from every later check.

Without the optional libraries (pinocchio, coal; kinematics.deps) and with an empty scene the
driver runs with a warning that nothing is checked (``collision`` is None); with a scene it refuses
to start (MissingDependency: a cell given and silently not checked would be worse than none).
"""
from __future__ import annotations

import logging
import math
import threading
import time
from typing import TYPE_CHECKING, Any, Callable, Dict, Iterator, List, Optional, Sequence, Tuple

from ...errors import CollisionError, MissingDependency, ModelError, SceneError
from ...kinematics.planner import DEFAULT_MAX_SWEEP, joint_weights
from ...kinematics.scene import Scene, SceneObject, load_scene

if TYPE_CHECKING:        # (imported where a checker is made: pinocchio is heavy)
    from ...kinematics.collision import CollisionChecker

log = logging.getLogger("vr_driver.driver")

__all__ = ["SceneGuard", "describe_contact"]

# the robot's collision model (rendered xacro, SRDF pairs) per name prefix, built once per process:
# building it takes ~0.3 s, a copy ~1 ms (tests build many cores)
_MODELS: Dict[Tuple[str, str], Any] = {}
_MODELS_LOCK = threading.Lock()
#: a path's check hands the interpreter over every this many configurations (~0.5 ms of checks):
#: the collision library holds the interpreter lock in each call, and the node's bus thread
#: waited behind a 400 000-point goal's check for 100-500 ms at a time
YIELD_EVERY = 64


def _robot_checker(prefix: str, model: str = "") -> Any:
    """A fresh CollisionChecker of the VR-006L with ``prefix`` and no scene (``model``: the driver's
    kinematics YAML, "" the package's); MissingDependency without pinocchio / coal."""
    from ...kinematics.collision import CollisionChecker
    with _MODELS_LOCK:
        base = _MODELS.get((prefix, model))
        if base is None:
            base = _MODELS[(prefix, model)] = CollisionChecker.default(prefix=prefix, model=model)
        return base.copy()


def describe_contact(contact: Any, padding: float) -> str:
    """``link_4 with pillar (penetration 12.0 mm)``; a self pair ``link_4 with link_6 (the arm
    itself, ...)``; inside the padding ``(3.0 mm apart, inside the 10 mm padding)``."""
    if contact.distance < 0.0:
        depth = "penetration %.1f mm" % (-contact.distance * 1e3)
    else:
        depth = "%.1f mm apart, inside the %g mm padding" % (contact.distance * 1e3, padding * 1e3)
    return "%s with %s (%s%s)" % (contact.link_a, contact.other, "" if contact.world else "the arm itself, ", depth)



def hand_over() -> None:
    """Hand the interpreter to another thread (the bus thread must not wait on a long check) --
    when there is one: alone (the plan action's worker process, a bench) a ``sleep(0)`` only gives
    the CPU away to other processes."""
    if threading.active_count() > 1:
        time.sleep(0)


def first_in_collision(checker: CollisionChecker, qs: Sequence[Sequence[float]], every: int, pause: Callable[[], Any]
                       ) -> Optional[int]:
    """The index of the first of ``qs`` in collision (``checker.first_collision``, one call a chunk of
    ``every`` configurations, ``pause()`` between chunks: the bus thread must not wait on a long
    check), or None when all are free."""
    step = max(1, every)
    for start in range(0, len(qs), step):
        if start:
            pause()
        hit = checker.first_collision(qs[start:start + step])
        if hit is not None:
            return start + hit
    return None

class SceneGuard:
    """The scene, the checker built on it and the path checks of one driver core (module text).
    ``gate``: the core's planning gate (held while a check runs, and while a change is swapped in).
    ``prefix``: the robot's name prefix; ``model``: the driver's kinematics YAML (``model``
    parameter: the links at its dimensions; "" the package's); ``checker``: a CollisionChecker to use
    instead (tests)."""

    def __init__(self, kinematics: Any, gate: threading.Lock, scene: Optional[Scene] = None,
                 padding: float = 0.01, enabled: bool = True, prefix: str = "",
                 max_sweep: float = DEFAULT_MAX_SWEEP, checker: Any = None, model: str = "") -> None:
        self._gate = gate
        self._lock = threading.Lock()            # the scene and the listeners (readers never wait on planning)
        self._scene = scene.copy() if scene is not None else Scene()
        self.enabled = bool(enabled)
        self.padding = float(padding)
        self.max_sweep = float(max_sweep)
        self.weights = joint_weights(kinematics)
        self.unavailable = ""                     # why nothing is checked although enabled
        self._missing: Optional[MissingDependency] = None
        self.refusals = 0
        self.last_refusal = ""
        self._listeners: List[Callable[[Scene], None]] = []
        self._checker: Any = None
        if not self.enabled:
            if len(self._scene):
                log.warning("collision_check is false: the scene's %d object(s) are shown but NOT checked; "
                            "paths are not checked against the arm itself either", len(self._scene))
            return
        try:
            base = checker.copy() if checker is not None else _robot_checker(prefix, model)
        except MissingDependency as exc:
            if len(self._scene):
                raise       # a cell given and silently not checked would be worse than none
            self.unavailable, self._missing = str(exc), exc
            log.warning("collision checking is OFF: nothing checks the arm against itself (%s)", exc)
            return
        base.set_padding(self.padding)
        self._checker = self._build(base, self._scene)

    # ------------------------------------------------------------------ queries
    @property
    def checker(self) -> Any:
        """The CollisionChecker of the current scene, or None (checking off). Replaced as a whole
        on every scene change, never changed in place; not thread-safe: use it under the core's
        planning gate, or take a ``copy()``."""
        return self._checker

    @property
    def active(self) -> bool:
        return self._checker is not None

    def scene(self) -> Scene:
        """A copy of the scene."""
        with self._lock:
            return self._scene.copy()

    def add_listener(self, callback: Callable[[Scene], None]) -> None:
        """``callback(scene copy)`` after every change (in the changing thread)."""
        with self._lock:
            self._listeners.append(callback)

    # ------------------------------------------------------------------ changes
    def _build(self, base: Any, scene: Scene) -> Any:
        """A checker of ``scene`` beside ``base`` (an object named as a robot geometry: SceneError)."""
        new = base.copy()
        try:
            new.set_scene(scene)
        except ModelError as exc:
            raise SceneError(str(exc)) from None
        return new

    def _change(self, edit: Callable[[Scene], Any], what: str, current: Optional[Sequence[float]] = None) -> Any:
        """Apply ``edit`` to a copy of the scene; when it passes, build its checker and swap both
        in (under the planning gate). Returns (what ``edit`` returned, a warning: "" or the
        contacts of ``current``, the arm's joints, with the new scene). Without the libraries
        (collision_check true): MissingDependency -- objects that would not be checked are refused."""
        if self._missing is not None:
            raise MissingDependency(self._missing.package, self._missing.module, "the scene's objects",
                                    "collision checking is off without it")
        with self._lock:
            scene = self._scene.copy()
            result = edit(scene)           # SceneError: nothing changed
            old = self._checker
            new = self._build(old, scene) if old is not None else None
            with self._gate:
                self._scene, self._checker = scene, new
            listeners = list(self._listeners)
        log.info("scene: %s (%d object(s): %s)", what, len(scene), ", ".join(scene.names()) or "none")
        warning = ""
        if new is not None and current is not None:
            try:
                with self._gate:
                    hits = new.contacts(current)
            except Exception:  # the warning is an aid; a joint vector the checker cannot take is ignored
                hits = []
            if hits:
                warning = ("the arm's current configuration collides: %s -- only a motion that moves out "
                           "of it is accepted (touching nothing else, never deeper)"
                           % "; ".join(describe_contact(c, new.padding) for c in hits))
                log.warning("scene: %s", warning)
        for callback in listeners:
            try:
                callback(scene.copy())
            except Exception:
                log.exception("scene listener failed")
        return result, warning

    def add(self, obj: SceneObject, replace: bool = False, current: Optional[Sequence[float]] = None) -> str:
        """Add ``obj`` (``replace``: put it in place of the object of its name, or add it when there
        is none); SceneError (nothing changes) for a taken name without ``replace`` or a bad object.
        Returns a warning ("" or: the arm at ``current`` collides with the new scene)."""
        if not isinstance(obj, SceneObject):
            raise SceneError("scene: can only add a SceneObject, got %r" % (obj,))

        def edit(scene: Scene) -> None:
            if replace and obj.name in scene:
                scene.replace(obj)
            else:
                scene.add(obj)
        return self._change(edit, "%s %s %s" % ("replaced" if replace and obj.name in self._scene else "added",
                                                obj.shape, obj.name), current)[1]

    def remove(self, name: str) -> SceneObject:
        """Remove the object ``name`` and return it; SceneError naming the objects when absent."""
        return self._change(lambda scene: scene.remove(name), "removed %s" % name)[0]

    def clear(self) -> None:
        self._change(lambda scene: scene.clear(), "cleared")

    def load(self, path: str, current: Optional[Sequence[float]] = None) -> Scene:
        """Replace the whole scene by the cell file ``path`` (SceneError naming the file, the entry
        and the key: nothing changes). Returns a copy of the new scene."""
        loaded = load_scene(path)

        def edit(scene: Scene) -> None:
            scene.clear()
            scene.add_all(loaded.objects())
        self._change(edit, "loaded %s" % path, current)
        return loaded.copy()

    # ------------------------------------------------------------------ checks
    def sweep(self, a: Sequence[float], b: Sequence[float]) -> float:
        """[m] a bound on how far any point of the arm moves on the straight joint move a -> b."""
        return sum(w * abs(x - y) for w, x, y in zip(self.weights, a, b))

    def configurations(self, samples: Sequence[Sequence[float]]
                       ) -> Iterator[Tuple[int, float, Tuple[float, ...]]]:
        """(k, f, q) along the path: the first sample (0, 0.0, q), then the configurations of each
        chord from sample k to k + 1 at fractions f (0 < f <= 1) no more than ``max_sweep`` apart."""
        qs = [tuple(float(v) for v in q) for q in samples]
        if qs:
            yield 0, 0.0, qs[0]
        for k in range(1, len(qs)):
            a, b = qs[k - 1], qs[k]
            n = max(1, int(math.ceil(self.sweep(a, b) / self.max_sweep)))
            for j in range(1, n + 1):
                f = j / n
                yield k - 1, f, (b if j == n else tuple(x + f * (y - x) for x, y in zip(a, b)))

    def first_collision(self, checker: Any, samples: Sequence[Sequence[float]]
                        ) -> Optional[Tuple[int, float, Tuple[float, ...]]]:
        """(k, f, q): the first configuration in collision (:meth:`configurations`); None when the
        path is free. A path that starts in collision (an object added where the arm stands) may
        move out of it: until its first free configuration it may touch only what the start
        touches (the same link / link-or-object pairs) and never deeper than it was at the previous
        check (the smallest signed distance over the checked pairs); from there on everything
        must be free. One that never gets free (a short jog step) must end farther out than it
        started."""
        configurations = list(self.configurations(samples))
        # every configuration checked in one call a chunk (the same check, less Python around it);
        # the first that collides is the answer unless it is the start (the rules below)
        hit = first_in_collision(checker, [q for _, _, q in configurations], YIELD_EVERY, hand_over)
        if hit is None:
            return None
        if hit > 0:
            return configurations[hit]
        escaping: Optional[set] = None
        depth = start_depth = 0.0
        last = None
        for n, (k, f, q) in enumerate(configurations):
            last = (k, f, q)
            if n % YIELD_EVERY == YIELD_EVERY - 1:
                hand_over()
            if not checker.in_collision(q):
                escaping = None
                continue
            pairs = {(c.link_a, c.other) for c in checker.contacts(q)}
            if f == 0.0:                                   # the start
                escaping, depth = pairs, checker.min_distance(q)
                start_depth = depth
                continue
            if escaping is None or not pairs <= escaping:
                return k, f, q
            d = checker.min_distance(q)
            if d < depth - 1e-6:                           # deeper in again
                return k, f, q
            depth = d
        if escaping is not None and not depth > start_depth + 1e-6:
            return last                                    # never got out, and no farther out
        return None

    def _deepest(self, checker: Any, samples: Sequence[Sequence[float]], first: Tuple[int, float]
                 ) -> Tuple[int, float, Tuple[float, ...], float]:
        """The configuration of the colliding stretch that starts at ``first`` where the arm is
        deepest in (the smallest signed distance over the checked pairs)."""
        best = None
        for k, f, q in self.configurations(samples):
            if (k, f) < first:
                continue
            if best is not None and not checker.in_collision(q):
                break
            d = checker.min_distance(q)
            if best is None or d < best[3]:
                best = (k, f, q, d)
        assert best is not None
        return best

    def _where(self, k: int, f: float, n: int, times: Optional[Sequence[float]]) -> Tuple[str, int, Optional[float]]:
        if n == 0:
            where, index = "at its only sample", 0
        elif f == 0.0:
            where, index = "at sample 0 of %d (the start)" % n, 0
        elif f >= 1.0:
            where, index = "at sample %d of %d" % (k + 1, n), k + 1
        else:
            where, index = "between samples %d and %d of %d" % (k, k + 1, n), k + 1
        t = None
        if times is not None and len(times) == n + 1:
            t = float(times[k]) + f * (float(times[min(k + 1, n)]) - float(times[k]))
            where += " (t = %.2f s)" % t
        return where, index, t

    def check_path(self, samples: Sequence[Sequence[float]], what: str,
                   times: Optional[Sequence[float]] = None) -> None:
        """Raise CollisionError when the samples (joint vectors, controller order) or a chord
        between two of them collide (module text); ``what`` names the path ("PTP path",
        "trajectory"), ``times`` [s] the samples' times when known. The message names the first
        colliding configuration and its contacts and, when the arm goes deeper further on, the
        deepest one of that stretch. Nothing is checked when checking is off."""
        if self._checker is None:
            return
        n = len(samples) - 1
        with self._gate:
            checker = self._checker
            hit = self.first_collision(checker, samples)
            if hit is None:
                return
            k, f, q = hit
            contacts = checker.contacts(q)
            dk, df, dq, depth = self._deepest(checker, samples, (k, f))
            deep = checker.contacts(dq) if (dk, df) != (k, f) and depth < min(
                (c.distance for c in contacts), default=0.0) - 1e-4 else []
            starts_in = checker.in_collision(samples[0])
        where, index, t = self._where(k, f, n, times)
        why = "; ".join(describe_contact(c, checker.padding) for c in contacts) or "in collision"
        message = "%s collides %s: %s" % (what, where, why)
        if starts_in:
            message += (" (it starts in collision: a path may only move out of that, touching nothing else and "
                        "never going deeper, and end free or farther out than it started)")
        if deep:
            message += "; deepest %s: %s" % (self._where(dk, df, n, times)[0],
                                             "; ".join(describe_contact(c, checker.padding) for c in deep))
        self.refusals += 1
        self.last_refusal = message
        log.warning("collision: %s", message)
        raise CollisionError(message, contacts, index, t)

    def describe(self) -> Dict[str, str]:
        """Key / value pairs for /diagnostics."""
        scene = self.scene()
        state = ("on" if self.active else
                 "OFF (collision_check is false)" if not self.enabled else "OFF (%s)" % self.unavailable)
        return {"collision checking": state,
                "scene objects": str(len(scene)),
                "scene": ", ".join("%s %s" % (o.shape, o.name) for o in scene) or "-",
                "collision padding [m]": "%g" % self.padding,
                "collision refusals": str(self.refusals),
                "last collision refusal": self.last_refusal or "-"}
