"""The keyboard jog's logic (``rosrun vr_driver jog``), ROS-free and terminal-free: keys in,
joint targets out, at a fixed rate. The ROS node (:mod:`vr_driver.ros.jog`) reads the keys from the
terminal, the arm's joints from ``joint_states`` and publishes what :meth:`Jogger.tick` returns on
``joint_command``.

Keys:

- ``1`` .. ``6``: select the joint (the arm holds);
- ``+`` / ``=`` / right arrow / ``l``: move the selected joint up; ``-`` / left arrow / ``h``: down,
  hold to run: the joint moves while the key is held (the terminal repeats it) and stops ``hold``
  seconds (0.8: longer than the usual 0.5-0.66 s delay before a held key repeats) after the last
  repeat -- a jog never runs on by itself, as a teach pendant's does not
  (``hold`` 0: latched, it keeps moving until space, another joint, a limit or the reverse key);
- ``]`` / up arrow / ``k``: faster; ``[`` / down arrow / ``j``: slower (the steps of ``SPEEDS``);
- space: stop -- the arm holds where it is (nothing more is published: the driver's stream ends
  at rest at the last target after its joint_command_timeout);
- ``q``, Ctrl-C, Ctrl-D: quit (the arm holds).

A move starts from the arm's joints (joint_states) and each tick moves the target by speed x
period; it stops a margin short of the joint's limit (the driver would refuse a target beyond it).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import List, Optional, Sequence, Tuple

__all__ = ["Jogger", "SPEEDS", "LIMIT_MARGIN", "KEYS", "decode_keys"]

#: deg/s: the jog speeds ([ and ] step through them)
SPEEDS = (0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 45.0)
#: rad: a jogged joint stops this far inside its limit
LIMIT_MARGIN = math.radians(0.5)

#: key names (decode_keys) -> action
KEYS = {
    "+": "up", "=": "up", "right": "up", "l": "up",
    "-": "down", "left": "down", "h": "down",
    "]": "faster", "up": "faster", "k": "faster",
    "[": "slower", "down": "slower", "j": "slower",
    " ": "stop", "q": "quit", "ctrl-c": "quit", "ctrl-d": "quit",
}


def decode_keys(data: str) -> List[str]:
    """Key names from the characters a terminal in cbreak mode sends (arrows as escape sequences
    ``ESC [ A`` .. ``ESC [ D``; ``\\x03`` Ctrl-C, ``\\x04`` Ctrl-D); other characters as they are."""
    arrows = {"A": "up", "B": "down", "C": "right", "D": "left"}
    keys = []
    i = 0
    while i < len(data):
        c = data[i]
        if c == "\x1b" and data[i + 1:i + 2] in ("[", "O") and data[i + 2:i + 3] in arrows:
            keys.append(arrows[data[i + 2]])
            i += 3
            continue
        keys.append({"\x03": "ctrl-c", "\x04": "ctrl-d"}.get(c, c))
        i += 1
    return keys


@dataclass
class Jogger:
    """See the module docstring. ``lower`` / ``upper``: the joint limits [rad]; ``rate``: the
    publishing rate [Hz]."""

    names: Tuple[str, ...]
    lower: Tuple[float, ...]
    upper: Tuple[float, ...]
    rate: float
    joint: int = 0
    speed_index: int = 3                   # SPEEDS[3] = 5 deg/s
    direction: int = 0                     # -1, 0 (holding), +1
    target: Optional[List[float]] = None   # the last target sent (None: holding, none)
    done: bool = False
    hold: float = 0.8                      # [s] a move stops this long after its key's last repeat (0: latched)
    until: float = 0.0                     # when the move stops unless its key repeats

    @property
    def speed(self) -> float:
        """The jog speed [rad/s]."""
        return math.radians(SPEEDS[self.speed_index])

    def key(self, name: str, now: float = 0.0) -> str:
        """Apply one key (a name from :func:`decode_keys`) at time ``now`` [s]; returns a line saying
        what it did ("" for a key that does nothing)."""
        if name in "123456" and len(name) == 1 and int(name) <= len(self.names):
            self._hold()
            self.joint = int(name) - 1
            return "joint %s selected (holding)" % self.names[self.joint]
        action = KEYS.get(name)
        if action in ("up", "down"):
            new = 1 if action == "up" else -1
            if self.direction == -new:
                self._hold()
                return "%s: stop" % self.names[self.joint]
            self.until = now + self.hold
            if self.direction == new:
                return ""                              # the key repeats: keep moving
            self.direction = new
            return "%s %s at %g deg/s" % (self.names[self.joint], "+" if new > 0 else "-",
                                         SPEEDS[self.speed_index])
        if action in ("faster", "slower"):
            step = 1 if action == "faster" else -1
            self.speed_index = min(len(SPEEDS) - 1, max(0, self.speed_index + step))
            return "speed %g deg/s" % SPEEDS[self.speed_index]
        if action == "stop":
            self._hold()
            return "stop: holding"
        if action == "quit":
            self._hold()
            self.done = True
            return "quit"
        return ""

    def _hold(self) -> None:
        self.direction = 0
        self.target = None

    def tick(self, joints: Optional[Sequence[float]], now: float = 0.0) -> Tuple[Optional[List[float]], str]:
        """The next target to publish (None: nothing, the arm holds) and a line to show ("" for
        none) at time ``now`` [s]. ``joints``: the arm's joints now (None: unknown -- nothing moves)."""
        if self.direction == 0:
            return None, ""
        if self.hold > 0.0 and now > self.until:
            self._hold()
            return None, "%s: key released: stop" % self.names[self.joint]
        if self.target is None:
            if joints is None:
                self._hold()
                return None, "no joint_states: cannot start (holding)"
            self.target = [float(v) for v in joints]
        j = self.joint
        value = self.target[j] + self.direction * self.speed / self.rate
        lo, hi = self.lower[j] + LIMIT_MARGIN, self.upper[j] - LIMIT_MARGIN
        if value > hi or value < lo:
            value = min(max(value, lo), hi)
            self.target[j] = value
            out = list(self.target)
            self.direction = 0
            self.target = None
            return out, "%s at its limit (%.1f deg): stop" % (self.names[j], math.degrees(value))
        self.target[j] = value
        return list(self.target), ""
