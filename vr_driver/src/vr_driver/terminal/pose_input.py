"""The pose terminal's logic, ROS-free: parse and validate what an operator types, and run the
dialogue (prompt, preview, confirm, send, progress, result) against a :class:`Backend`. A sent
move's handle, progress display and watch until it ends (Ctrl-C, timeout, the outcome) are
:mod:`vr_driver.terminal.sent_move`; how poses are written, :mod:`vr_driver.terminal.pose_text`
(both re-exported here).

The ROS node ``pose_terminal`` (vr_driver.ros.pose_terminal) only provides the backend (the
driver's ``move_to_pose`` action, ``stop_motion``, ``robot_status``, ``tool_pose``); tests use a fake.

What is typed, at the first prompt of an entry (the X prompt)::

    <Enter> or a number       X; then Y, Z, Rx, Ry, Rz and the move type are asked one by one,
                              Enter keeping the default shown in brackets (the home pose
                              1120 0 725 0 45 0 and PTP at first, then the last entry's)
    x y z rx ry rz [type]     a whole pose on one line (type ptp, lin or circ; default ptp)
    ... circ via x y z [rx ry rz]   a circular move through a via point
    plan x y z rx ry rz       a collision-free motion there, planned around the cell (the driver's
    plan NAME                 plan action), or to a named state of the SRDF (home, zero); timed at
                              the driver's velocity scaling (default 0.1) unless the line ends in
                              ``scaling S`` (0 < S <= 1) or the terminal runs with --velocity-scaling
    home stop status history help quit

At every later prompt of the entry (Y ... Rz, move type, via point, the confirmation) ``cancel`` or
Ctrl-C abandons the half-typed entry and returns to the first prompt; ``home`` abandons it and moves
home, ``quit`` leaves; ``stop``, ``status``, ``history`` and ``help`` run and ask the same again. Only
a move that was sent becomes the next entry's defaults (a refused or abandoned one does not).

Every value is checked before anything goes to the driver: a finite number, inside the driver's
workspace box (also after rounding to the controller's whole mm / deg), then the driver previews the
move (reachability, joint limits, the path) and only a confirmed, previewed move is sent. A plan is
previewed by the plan action (preview_only: its duration and planning time shown, the path in RViz)
with the speed it will run at (the velocity scaling, the TCP's and the fastest joint's peak speed:
also with --yes, before anything moves) and, confirmed, exactly the previewed trajectory runs
(through joint_trajectory_action).
"""
from __future__ import annotations

import argparse
import math
import re
import sys
import time
from dataclasses import dataclass, field, replace
from typing import Any, Callable, List, Optional, Sequence, TextIO, Tuple

from ..kinematics.preview import MoveType
from ..poses import HOME_POSE, ControllerPose, Workspace
from ..protocol.common import round_half_away
from .pose_text import FIELDS, Field, fmt_joints_deg, fmt_number, fmt_pose
from .sent_move import MoveHandle, MoveProgress, MoveResult, MoveWatch, ProgressPrinter

__all__ = [
    "EXIT_OK", "EXIT_REFUSED", "EXIT_USAGE", "EXIT_NO_DRIVER",
    "FIELDS", "COMMANDS", "InputError", "RangeError", "PoseRequest", "PreviewResult", "MoveProgress", "MoveResult",
    "PlanRequest", "PlanPreview", "parse_plan_line", "check_velocity_scaling",
    "StatusInfo", "Backend", "MoveHandle", "Terminal", "ProgressPrinter",
    "fmt_number", "fmt_pose", "fmt_joints_deg", "field_range", "prompt_text", "parse_number",
    "check_value", "parse_move_type", "check_pose", "parse_pose_line", "parse_command",
    "build_arg_parser", "request_from_args",
]

#: exit codes of ``pose_terminal`` (and of Terminal.run_once)
EXIT_OK = 0            # the target was reached (or, with --preview, it is valid and reachable)
EXIT_REFUSED = 1       # refused (invalid, unreachable, motion not possible), not confirmed, failed, stopped
EXIT_USAGE = 2         # bad command line
EXIT_NO_DRIVER = 3     # no ROS master / driver, or no answer in time

COMMANDS = ("home", "stop", "status", "history", "help", "quit", "cancel")
_COMMAND_ALIASES = {"exit": "quit", "q": "quit", "?": "help", "h": "help"}

_MOVE_TYPE_WORDS = {
    "ptp": MoveType.PTP, "p": MoveType.PTP, "movep": MoveType.PTP, "1": MoveType.PTP,
    "lin": MoveType.LIN, "l": MoveType.LIN, "movel": MoveType.LIN, "linear": MoveType.LIN, "2": MoveType.LIN,
    "circ": MoveType.CIRC, "c": MoveType.CIRC, "movec": MoveType.CIRC, "circular": MoveType.CIRC,
    "3": MoveType.CIRC,
}
_MOVE_TYPE_NAMES = {MoveType.PTP: "PTP (joint interpolated, MOVEP)",
                    MoveType.LIN: "LIN (straight line, MOVEL)",
                    MoveType.CIRC: "CIRC (arc through a via point, MOVEC)"}

# a plain decimal number: what an operator types (no hex, no underscores, no 'nan' / 'inf')
_NUMBER = re.compile(r"^[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?$")
_NOT_FINITE = re.compile(r"^[+-]?(nan|inf|infinity)$", re.IGNORECASE)


class InputError(ValueError):
    """Something typed that cannot be used; the message says what is wrong and what is allowed."""


class RangeError(InputError):
    """A proper number outside the driver's workspace (a refusal rather than a typing error)."""


# ------------------------------------------------------------------------------------ formatting

def field_range(workspace: Workspace, name: str) -> Tuple[float, float]:
    return getattr(workspace, name) if len(name) == 1 else workspace.angle


def prompt_text(fld: Field, workspace: Workspace, default: Optional[float], prefix: str = "") -> str:
    """``X [mm, 100..1400] (1120): `` (no default: no brackets)."""
    lo, hi = field_range(workspace, fld.name)
    text = "%s%s [%s, %s..%s]" % (prefix, fld.label, fld.unit, fmt_number(lo), fmt_number(hi))
    if default is not None:
        text += " (%s)" % fmt_number(default)
    return text + ": "


# ------------------------------------------------------------------------------------ parsing

def check_value(value: float, fld: Field, workspace: Workspace, what: str = "") -> float:
    """``value`` if it is finite and inside the workspace, also once rounded to what is sent."""
    name = (what + " " if what else "") + fld.label
    lo, hi = field_range(workspace, fld.name)
    if not math.isfinite(value):
        raise InputError("%s: %s is not %s: a finite number in %s..%s %s is needed"
                         % (name, value, fld.quantity, fmt_number(lo), fmt_number(hi), fld.unit))
    if not lo <= value <= hi:
        side = "below" if value < lo else "above"
        raise RangeError("%s = %s %s is %s the workspace: allowed %s..%s %s"
                         % (name, fmt_number(value), fld.unit, side, fmt_number(lo), fmt_number(hi), fld.unit))
    sent = round_half_away(value)
    if not lo <= sent <= hi:
        raise RangeError("%s = %s %s is sent as %d %s (the controller takes whole %s), which is outside "
                         "%s..%s %s" % (name, fmt_number(value), fld.unit, sent, fld.unit, fld.unit,
                                        fmt_number(lo), fmt_number(hi), fld.unit))
    return value


def parse_number(text: str, fld: Field, workspace: Workspace, default: Optional[float] = None,
                 what: str = "") -> float:
    """The value typed for ``fld``: '' takes ``default``; InputError says what is wrong."""
    name = (what + " " if what else "") + fld.label
    text = text.strip()
    if not text:
        if default is None:
            raise InputError("%s: a value is needed (there is no default)" % name)
        return check_value(float(default), fld, workspace, what)
    if _NOT_FINITE.match(text):
        lo, hi = field_range(workspace, fld.name)
        raise InputError("%s: %r is not %s: a finite number in %s..%s %s is needed"
                         % (name, text, fld.quantity, fmt_number(lo), fmt_number(hi), fld.unit))
    if not _NUMBER.match(text):
        raise InputError("%s: %r is not a number (type e.g. 1120, -12.5 or 1.2e3)" % (name, text))
    return check_value(float(text), fld, workspace, what)


def parse_move_type(text: str, default: Optional[MoveType] = None) -> MoveType:
    word = text.strip().lower()
    if not word:
        if default is None:
            raise InputError("move type: a value is needed (ptp, lin or circ)")
        return default
    try:
        return _MOVE_TYPE_WORDS[word]
    except KeyError:
        raise InputError("move type: %r is not one of ptp, lin, circ" % text.strip()) from None


def check_pose(values: Sequence[object], workspace: Workspace, what: str = "") -> ControllerPose:
    """Six numbers (or texts of numbers) in the workspace -> ControllerPose; InputError otherwise."""
    if len(values) != 6:
        raise InputError("%sa pose is 6 values (X Y Z mm, Rx Ry Rz deg), got %d"
                         % ((what + ": ") if what else "", len(values)))
    out = []
    for value, fld in zip(values, FIELDS):
        if isinstance(value, str):
            out.append(parse_number(value, fld, workspace, what=what))
        else:
            try:
                number = float(value)
            except (TypeError, ValueError):
                raise InputError("%s%s: %r is not a number" % ((what + " ") if what else "", fld.label,
                                                               value)) from None
            out.append(check_value(number, fld, workspace, what))
    return ControllerPose(*out)


@dataclass(frozen=True)
class PoseRequest:
    """A validated move: target (and via for CIRC) inside the workspace."""

    move_type: MoveType
    target: ControllerPose
    via: Optional[ControllerPose] = None

    def __post_init__(self) -> None:
        if (self.move_type is MoveType.CIRC) != (self.via is not None):
            raise InputError("a via point goes with a circular move (circ) and only with it")

    def describe(self) -> str:
        text = "%s to %s" % (self.move_type.name, fmt_pose(self.target))
        if self.via is not None:
            text += "\n        via %s" % fmt_pose(self.via)
        return text

    def sent_values(self) -> List[Tuple[int, ...]]:
        """What the controller receives (whole mm / deg): [via,] target."""
        poses = ([self.via] if self.via is not None else []) + [self.target]
        return [tuple(round_half_away(v) for v in p.as_tuple()) for p in poses]

    def is_rounded(self) -> bool:
        poses = ([self.via] if self.via is not None else []) + [self.target]
        return any(tuple(p.as_tuple()) != tuple(float(v) for v in s)
                   for p, s in zip(poses, self.sent_values()))


def _tokens(text: str) -> List[str]:
    return text.replace(",", " ").replace(";", " ").split()


_LINE_SYNTAX = "x y z rx ry rz [ptp|lin|circ] [via x y z [rx ry rz]]"


def parse_pose_line(text: str, workspace: Workspace) -> PoseRequest:
    """``x y z rx ry rz [type] [via x y z [rx ry rz]]`` -> PoseRequest; InputError says what is wrong.
    A via point given as 3 values takes the target's orientation (the arc does not use it)."""
    tokens = _tokens(text)
    via_tokens: Optional[List[str]] = None
    lowered = [t.lower() for t in tokens]
    if "via" in lowered:
        at = lowered.index("via")
        tokens, via_tokens = tokens[:at], tokens[at + 1:]
    kind_word = None
    if len(tokens) == 7:
        kind_word = tokens[6]
        tokens = tokens[:6]
    if len(tokens) != 6:
        raise InputError("a pose line is %s; got %d value(s) before the move type"
                         % (_LINE_SYNTAX, len(tokens)))
    target = check_pose(tokens, workspace)
    kind = parse_move_type(kind_word or "", default=MoveType.CIRC if via_tokens is not None else MoveType.PTP)
    if kind is MoveType.CIRC and via_tokens is None:
        raise InputError("a circular move needs a via point: x y z rx ry rz circ via x y z [rx ry rz]")
    if kind is not MoveType.CIRC and via_tokens is not None:
        raise InputError("'via' is only for circular moves (circ), not %s" % kind.name)
    via = None
    if via_tokens is not None:
        if len(via_tokens) == 3:
            via_tokens = via_tokens + [str(v) for v in target.as_tuple()[3:]]
        if len(via_tokens) != 6:
            raise InputError("the via point is 3 or 6 values (x y z [rx ry rz]), got %d" % len(via_tokens))
        via = check_pose(via_tokens, workspace, what="via")
    return PoseRequest(kind, target, via)


_STATE_NAME = re.compile(r"\A[A-Za-z_][A-Za-z0-9_]*\Z")
_PLAN_SYNTAX = ("plan x y z rx ry rz, or plan NAME (a named state of the SRDF, e.g. home), "
                "optionally followed by scaling S (0 < S <= 1)")


def check_velocity_scaling(value: object, what: str = "scaling") -> float:
    """A plan's velocity scaling: a finite number in (0, 1] (0: the driver's default), or InputError
    naming ``what``."""
    text = str(value).strip()
    if not _NUMBER.match(text):
        raise InputError("%s: %r is not a number (0 < S <= 1; 0: the driver's default)" % (what, value))
    scaling = float(text)
    if not (math.isfinite(scaling) and 0.0 <= scaling <= 1.0):
        raise InputError("%s: %s is outside 0 < S <= 1 (0: the driver's default)" % (what, text))
    return scaling


@dataclass(frozen=True)
class PlanRequest:
    """A collision-free motion to plan: to ``target`` (checked: inside the workspace) or to the named
    state ``state`` of the SRDF, timed at ``velocity_scaling`` (0: the driver's parameter
    ``velocity_scaling``, 0.1 unless configured otherwise)."""

    target: Optional[ControllerPose] = None
    state: str = ""
    velocity_scaling: float = 0.0

    def __post_init__(self) -> None:
        if (self.target is None) == (not self.state):
            raise InputError("a plan goes to a pose or to a named state: %s" % _PLAN_SYNTAX)
        check_velocity_scaling(self.velocity_scaling)

    def describe(self) -> str:
        scaling = " at velocity scaling %g" % self.velocity_scaling if self.velocity_scaling else ""
        if self.target is not None:
            return "PLAN to %s%s" % (fmt_pose(self.target), scaling)
        return "PLAN to the named state %s%s" % (self.state, scaling)


def is_plan_line(text: str) -> bool:
    tokens = _tokens(text)
    return bool(tokens) and tokens[0].lower() == "plan"


def parse_plan_line(text: str, workspace: Workspace) -> PlanRequest:
    """``plan x y z rx ry rz`` or ``plan NAME``, each optionally followed by ``scaling S`` ->
    PlanRequest; InputError says what is wrong."""
    tokens = _tokens(text)
    if not tokens or tokens[0].lower() != "plan":
        raise InputError("a plan line starts with 'plan': %s" % _PLAN_SYNTAX)
    rest = tokens[1:]
    scaling = 0.0
    if len(rest) >= 2 and rest[-2].lower() == "scaling":
        scaling = check_velocity_scaling(rest[-1])
        if scaling == 0.0:
            raise InputError("scaling: 0 < S <= 1 (leave 'scaling S' out for the driver's default)")
        rest = rest[:-2]
    if len(rest) == 1 and not _NUMBER.match(rest[0]) and not _NOT_FINITE.match(rest[0]):
        if not _STATE_NAME.match(rest[0]):
            raise InputError("plan: %r is not a state name (letters, digits, _): %s" % (rest[0], _PLAN_SYNTAX))
        return PlanRequest(state=rest[0], velocity_scaling=scaling)
    if len(rest) != 6:
        raise InputError("%s; got %d value(s) after 'plan'" % (_PLAN_SYNTAX, len(rest)))
    return PlanRequest(target=check_pose(rest, workspace), velocity_scaling=scaling)


def parse_command(text: str) -> Optional[str]:
    """The command named by ``text`` (one of COMMANDS), or None when it is not a command."""
    word = text.strip().lower()
    word = _COMMAND_ALIASES.get(word, word)
    return word if word in COMMANDS else None


# ------------------------------------------------------------------------------------ backend

@dataclass(frozen=True)
class PreviewResult:
    ok: bool
    reason: str = ""                                  # why not, when not ok; when ok: how it runs (the
    #                                                   time and top speed the protocol delivers), or ""
    joint_target: Tuple[float, ...] = ()              # rad, J1..J6
    duration: float = 0.0                             # s, the driver's estimate
    unavailable: bool = False                         # no driver / no answer (not a refusal)


@dataclass(frozen=True)
class StatusInfo:
    """What the driver reports (None = unknown)."""

    link: str = ""                                    # e.g. "connected, 50.0 cycles/s"
    motion_possible: Optional[bool] = None
    why_no_motion: str = ""
    mode: str = ""
    e_stopped: Optional[bool] = None
    drives_powered: Optional[bool] = None
    in_motion: Optional[bool] = None
    in_error: Optional[bool] = None
    error_code: int = 0
    pose: Optional[ControllerPose] = None
    joints: Optional[Tuple[float, ...]] = None
    age: Optional[float] = None                       # s since the last robot_status


@dataclass(frozen=True)
class PlanPreview:
    """What the driver planned (Backend.plan): ``token`` is the backend's own copy of the trajectory,
    the one :meth:`Backend.start_plan` runs."""
    ok: bool
    reason: str = ""                                  # why not, when not ok
    duration: float = 0.0                             # s, the trajectory's
    planning_time: float = 0.0                        # s
    joint_target: Tuple[float, ...] = ()              # rad, J1..J6: the trajectory's end
    target: Optional[ControllerPose] = None           # the TCP at the end
    points: int = 0
    planner: str = ""
    unavailable: bool = False                         # no answer (not a refusal)
    token: object = None
    # the speed it runs at (the plan action's result; 0 / "" when the driver did not say)
    velocity_scaling: float = 0.0                     # the fraction of the joint limits it was timed with
    peak_tcp_speed: float = 0.0                       # mm/s
    peak_joint: str = ""                              # the joint closest to its speed limit
    peak_joint_speed: float = 0.0                     # deg/s
    peak_joint_fraction: float = 0.0                  # of that joint's speed limit
    # what the protocol delivers (the plan action's run_*: on v1 the program's speed): s, mm/s, words
    run_duration: float = 0.0
    run_peak_tcp_speed: float = 0.0
    run_words: str = ""

    def describe_speed(self, default: bool = False) -> str:
        """The speed the plan runs at, in words ("" when the driver did not say); ``default``: the
        scaling is the driver's default (the request gave none)."""
        if not self.velocity_scaling:
            return ""
        text = "velocity scaling %g%s" % (self.velocity_scaling, " (the driver's default)" if default else "")
        if self.peak_joint:
            text += "; at its fastest the TCP moves %.0f mm/s, %s %.1f deg/s (%.0f %% of its limit)" % (
                self.peak_tcp_speed, self.peak_joint, self.peak_joint_speed, 100.0 * self.peak_joint_fraction)
        return text


class Backend:
    """What the terminal needs from the driver (the ROS node implements it with the action)."""

    def preview(self, request: PoseRequest) -> PreviewResult:
        raise NotImplementedError

    def start_move(self, request: PoseRequest) -> MoveHandle:
        raise NotImplementedError

    def plan(self, request: PlanRequest) -> PlanPreview:
        """Plan (and show) a collision-free motion; sends nothing."""
        return PlanPreview(False, "this driver does not plan")

    def start_plan(self, preview: PlanPreview) -> MoveHandle:
        """Run exactly the previewed trajectory."""
        raise NotImplementedError

    def stop(self) -> Tuple[bool, str]:
        raise NotImplementedError

    def status(self) -> Optional[StatusInfo]:
        raise NotImplementedError


# ------------------------------------------------------------------------------------ terminal

HELP = """\
Enter a pose field by field (Enter keeps the value in brackets), or a whole line:
  x y z rx ry rz [ptp|lin|circ]              e.g. 1000 200 800 0 45 0 lin
  x y z rx ry rz circ via x y z [rx ry rz]   a circular move through a via point
  plan x y z rx ry rz                        a collision-free motion around the cell (the driver's planner)
  plan NAME                                  the same to a named state of the SRDF (home, zero)
  plan ... scaling S                         a plan at velocity scaling S (0 < S <= 1; default: the driver's, 0.1)
X Y Z in mm, Rx Ry Rz in degrees (R = Rz*Ry*Rx), the TCP in frame `base`; the controller
takes whole mm / deg. Every move is previewed by the driver and sent only when you confirm; a plan's preview shows its
duration, planning time and speed (the path in RViz), and exactly that trajectory runs when you confirm.
Commands:
  home      move (PTP) to the home pose 1120 0 725 0 45 0
  stop      stop the arm now (the driver's stop_motion)
  status    the driver's and the controller's state, the current pose
  history   the moves of this session and how they ended
  help      this text
  cancel    abandon the entry being typed and return to the first prompt (also Ctrl-C)
  quit      leave (also Ctrl-D)
Every command works at every prompt: cancel, home and quit abandon the entry being typed (home
then moves home); stop, status, history and help run and ask the same question again. Only a
move that was sent becomes the next defaults. Ctrl-C during a move stops the arm and returns to
the prompt."""


class _EntryEnd(Exception):
    """Leaves the entry being typed: ``then`` is 'cancel' (back to the first prompt), 'home' or 'quit'."""

    def __init__(self, then: str) -> None:
        super().__init__(then)
        self.then = then


@dataclass
class HistoryEntry:
    request: "PoseRequest | PlanRequest"
    outcome: str
    when: float = field(default_factory=time.time)


def _yes(answer: str) -> bool:
    return answer.strip().lower() in ("y", "yes", "j", "ja")


def _tri(value: Optional[bool], yes: str = "yes", no: str = "no") -> str:
    return "unknown" if value is None else (yes if value else no)


def history_lines(history: Sequence["HistoryEntry"]) -> List[str]:
    """The ``history`` command's lines: each entry's time, request and outcome."""
    if not history:
        return ["No moves yet."]
    lines = []
    for n, entry in enumerate(history, 1):
        stamp = time.strftime("%H:%M:%S", time.localtime(entry.when))
        lines += ["%3d  %s  %s" % (n, stamp, entry.request.describe()), "               -> %s" % entry.outcome]
    return lines


def status_lines(s: Any) -> List[str]:
    """The ``status`` command's lines from the backend's status (None: none received yet)."""
    if s is None:
        return ["No robot_status from the driver yet."]
    lines = []
    if s.age is not None and s.age > 2.0:
        lines.append("Warning: the last robot_status is %.1f s old (is the driver running?)" % s.age)
    lines.append("link:            %s" % (s.link or "unknown"))
    possible = _tri(s.motion_possible)
    if s.motion_possible is False and s.why_no_motion:
        possible += " (%s)" % s.why_no_motion
    lines.append("motion possible: %s" % possible)
    lines.append("mode: %s, e-stop: %s, drives: %s, in motion: %s, error: %s%s"
                 % (s.mode or "unknown", _tri(s.e_stopped, "PRESSED", "released"),
                    _tri(s.drives_powered, "on", "off"), _tri(s.in_motion), _tri(s.in_error),
                    " (code %d)" % s.error_code if s.error_code else ""))
    lines.append("pose:            %s" % (fmt_pose(s.pose) if s.pose is not None else "unknown (no feedback)"))
    if s.joints is not None:
        lines.append("joints [deg]:    %s" % fmt_joints_deg(s.joints))
    return lines


def plan_lines(request: PlanRequest, preview: PlanPreview) -> List[str]:
    """A plan's preview in words (before the confirmation): its duration, points, planning time and
    planner, the joint target, the TCP at the end and the speed it runs at."""
    lines = ["Plan: collision-free; duration %.1f s (%d points), planned in %.0f ms%s"
             % (preview.duration, preview.points, preview.planning_time * 1000.0,
                " by %s" % preview.planner if preview.planner else ""),
             "  joint target [deg]: %s" % fmt_joints_deg(preview.joint_target)]
    if preview.target is not None:
        lines.append("  TCP at the end: %s" % fmt_pose(preview.target))
    speed = preview.describe_speed(default=not request.velocity_scaling)
    lines.append("  speed: %s" % (speed or "not reported by the driver (velocity scaling %s)"
                                  % ("%g" % request.velocity_scaling if request.velocity_scaling
                                     else "the driver's default")))
    if preview.run_words:
        lines.append("  the run: %s" % preview.run_words)
    return lines


class Terminal:
    """The dialogue. ``input_fn(prompt)`` reads a line (EOFError at the end, KeyboardInterrupt on
    Ctrl-C), ``out`` gets everything printed. ``assume_yes`` skips the confirmation.
    ``velocity_scaling`` (0 < S <= 1) times every plan that does not give its own (0: the driver's
    default)."""

    def __init__(self, backend: Backend, workspace: Workspace, out: TextIO = sys.stdout,
                 input_fn: Callable[[str], str] = input, assume_yes: bool = False, tty: Optional[bool] = None,
                 poll_period: float = 0.1, clock: Callable[[], float] = time.monotonic,
                 stop_wait: float = 10.0, velocity_scaling: float = 0.0):
        self.backend = backend
        self.velocity_scaling = check_velocity_scaling(velocity_scaling, "velocity_scaling")
        self.workspace = workspace
        self.out = out
        self.input_fn = input_fn
        self.assume_yes = assume_yes
        self.tty = out.isatty() if tty is None else tty
        self.poll_period = poll_period
        self.clock = clock
        self.stop_wait = stop_wait
        self.history: List[HistoryEntry] = []
        self.defaults = HOME_POSE
        self.default_type = MoveType.PTP
        self._sending = False

    # -------------------------------------------------------------- output helpers
    def say(self, text: str = "") -> None:
        self.out.write(text + "\n")
        self.out.flush()

    def ask(self, prompt: str) -> str:
        return self.input_fn(prompt)

    # -------------------------------------------------------------- interactive
    def run_interactive(self) -> int:
        """Until quit / Ctrl-D / Ctrl-C at a prompt. Returns EXIT_OK."""
        self.say("Pose terminal: X Y Z in mm, Rx Ry Rz in deg; Enter keeps the value in brackets.")
        self.say("A whole line works too: x y z rx ry rz ptp|lin|circ. 'help' lists the commands.")
        self.say("'cancel' or Ctrl-C at any prompt abandons the entry; 'quit' or Ctrl-D leaves.")
        go_home = False
        while True:
            try:
                if go_home:                        # 'home' typed inside an entry
                    go_home = False
                    self.command("home")
                    continue
                request = self._read_request()
                if isinstance(request, (PoseRequest, PlanRequest)):
                    self.execute_guarded(request)
                elif request == "quit":
                    raise _EntryEnd("quit")
            except EOFError:
                self.say()
                self.say("Bye.")
                return EXIT_OK
            except KeyboardInterrupt:
                self.say()
                self.say("Entry abandoned (Ctrl-C); 'quit' or Ctrl-D leaves.")
            except _EntryEnd as end:
                if end.then == "quit":
                    self.say("Bye.")
                    return EXIT_OK
                if end.then == "home":
                    go_home = True
                else:
                    self.say("Entry abandoned.")

    def execute_guarded(self, request: PoseRequest, **kwargs) -> int:
        """:meth:`execute`, with Ctrl-C outside the move loop (during the preview or while the goal
        is being sent) handled: back to the prompt, and a stop when a goal may have gone out."""
        try:
            return self.execute(request, **kwargs)
        except KeyboardInterrupt:
            self.say()
            if self._sending:
                self.say("Interrupted while sending: calling stop_motion ...")
                self._call_stop()
            else:
                self.say("Interrupted; nothing was sent.")
            self._record(request, "interrupted")
            return EXIT_REFUSED
        finally:
            self._sending = False

    def _read_request(self):
        """One entry: a command (its name; already handled unless 'quit'), a PoseRequest, or None
        after an error (its reason printed)."""
        first = self.ask(prompt_text(FIELDS[0], self.workspace, self.defaults.x))
        command = parse_command(first)
        if command is not None:
            if command == "quit":
                return "quit"
            if command == "cancel":
                self.say("  Nothing to abandon: this is the first prompt.")
                return None
            self.command(command)
            return command
        if is_plan_line(first):
            try:
                return parse_plan_line(first, self.workspace)
            except InputError as exc:
                self.say("  %s" % exc)
                return None
        if len(_tokens(first)) > 1:
            try:
                return parse_pose_line(first, self.workspace)
            except InputError as exc:
                self.say("  %s" % exc)
                return None
        try:
            x = parse_number(first, FIELDS[0], self.workspace, self.defaults.x)
        except InputError as exc:
            self.say("  %s" % exc)
            return None
        values = [x]
        for fld in FIELDS[1:]:
            values.append(self._ask_number(fld, getattr(self.defaults, fld.name)))
        target = ControllerPose(*values)
        kind = self._ask_move_type()
        via = None
        if kind is MoveType.CIRC:
            via_values = []
            for fld in FIELDS:
                default = None if len(fld.name) == 1 else getattr(target, fld.name)
                via_values.append(self._ask_number(fld, default, what="via"))
            via = ControllerPose(*via_values)
        return PoseRequest(kind, target, via)

    def _ask_in_entry(self, prompt: str) -> str:
        """A later prompt of an entry: the answer, once no command was typed. cancel, home and quit
        (and Ctrl-C) end the entry (:class:`_EntryEnd`); the other commands run, then ask again."""
        while True:
            try:
                text = self.ask(prompt)
            except KeyboardInterrupt:
                self.say()
                raise _EntryEnd("cancel") from None
            command = parse_command(text)
            if command is None:
                return text
            if command in ("cancel", "home", "quit"):
                raise _EntryEnd(command)
            self.command(command)

    def _ask_number(self, fld: Field, default: Optional[float], what: str = "") -> float:
        prefix = (what.capitalize() + " ") if what else ""
        while True:
            text = self._ask_in_entry(prompt_text(fld, self.workspace, default, prefix))
            try:
                return parse_number(text, fld, self.workspace, default, what=what)
            except InputError as exc:
                self.say("  %s" % exc)

    def _ask_move_type(self) -> MoveType:
        while True:
            text = self._ask_in_entry("Move type [ptp, lin, circ] (%s): " % self.default_type.value)
            try:
                return parse_move_type(text, self.default_type)
            except InputError as exc:
                self.say("  %s" % exc)

    def _remember(self, request, target: Optional[ControllerPose] = None) -> None:
        """The next entry's defaults: this one's target and move type (called once it was sent; a
        plan leaves the move type and gives the TCP pose it ends at)."""
        if isinstance(request, PlanRequest):
            if target is not None:
                self.defaults = target
            return
        self.defaults = request.target
        self.default_type = request.move_type

    # -------------------------------------------------------------- commands
    def command(self, name: str) -> int:
        if name == "help":
            self.say(HELP)
        elif name == "history":
            self.show_history()
        elif name == "status":
            self.show_status()
        elif name == "stop":
            ok, message = self.backend.stop()
            self.say(("Stop sent: %s" if ok else "Stop failed: %s") % message)
            return EXIT_OK if ok else EXIT_REFUSED
        elif name == "home":
            return self.execute_guarded(PoseRequest(MoveType.PTP, HOME_POSE))
        return EXIT_OK

    def show_history(self) -> None:
        for line in history_lines(self.history):
            self.say(line)

    def show_status(self) -> None:
        for line in status_lines(self.backend.status()):
            self.say(line)

    # -------------------------------------------------------------- one move
    def _record(self, request: PoseRequest, outcome: str) -> None:
        self.history.append(HistoryEntry(request, outcome))

    def execute(self, request, confirm: bool = True, preview_only: bool = False,
                move_timeout: Optional[float] = None) -> int:
        """Preview, confirm, send, show progress, report. Returns an EXIT_* code."""
        if isinstance(request, PlanRequest):
            return self.execute_plan(request, confirm, preview_only, move_timeout)
        self.say("Checking %s" % request.describe())
        if request.is_rounded():
            self.say("  (the controller takes whole mm / deg: sent as %s)"
                     % " then ".join(" ".join(str(v) for v in s) for s in request.sent_values()))
        preview = self.backend.preview(request)
        if not preview.ok:
            reason = preview.reason
            self.say("Refused, nothing was sent: %s" % reason)
            self._record(request, "refused: %s" % reason)
            return EXIT_NO_DRIVER if preview.unavailable else EXIT_REFUSED
        self.say("Preview: reachable; estimated duration %.1f s" % preview.duration)
        if preview.reason:                 # (an accepted preview's words: what the protocol delivers)
            self.say("  the run: %s" % preview.reason)
        self.say("  joint target [deg]: %s" % fmt_joints_deg(preview.joint_target))
        stop = self._go_ahead(request, preview_only, confirm, "previewed (not sent)",
                              "Send this %s move to the robot? [y/N]: " % request.move_type.name)
        if stop is not None:
            return stop
        return self._run_move(request, preview, move_timeout)

    def _go_ahead(self, request: Any, preview_only: bool, confirm: bool, shown: str, question: str
                  ) -> Optional[int]:
        """None when the previewed or planned ``request`` may go to the robot now; else the exit
        status: EXIT_OK after recording ``shown`` when only a preview was asked for, EXIT_REFUSED
        when motion is not possible or the user does not answer ``question`` with yes."""
        if preview_only:
            self._record(request, shown)
            return EXIT_OK
        if not self._motion_possible(request):
            return EXIT_REFUSED
        if confirm and not self.assume_yes and not self._confirm(request, question):
            return EXIT_REFUSED
        return None

    def _motion_possible(self, request) -> bool:
        status = self.backend.status()
        if status is not None and status.motion_possible is False:
            why = status.why_no_motion or "the driver says motion is not possible"
            self.say("Not sent: motion is not possible now: %s" % why)
            self._record(request, "not sent: motion not possible (%s)" % why)
            return False
        return True

    def _confirm(self, request, question: str) -> bool:
        """Ask ``question``; True on yes. home / quit typed here end the entry after 'Not sent.'."""
        then = None
        try:
            answer = self._ask_in_entry(question)
        except EOFError:
            answer = ""
            self.say()
        except _EntryEnd as end:
            answer, then = "", end
        if not _yes(answer):
            self.say("Not sent.")
            self._record(request, "not sent (not confirmed)")
            if then is not None and then.then != "cancel":
                raise then                    # home / quit: the dialogue acts on it
            return False
        return True

    def execute_plan(self, request: PlanRequest, confirm: bool = True, preview_only: bool = False,
                     move_timeout: Optional[float] = None) -> int:
        """Plan (the driver's plan action, preview only), show it, confirm, run exactly that
        trajectory, show progress, report. The speed it will run at is said before the confirmation
        (also with ``assume_yes``). Returns an EXIT_* code."""
        if self.velocity_scaling and not request.velocity_scaling:
            request = replace(request, velocity_scaling=self.velocity_scaling)
        self.say("Planning a collision-free motion: %s" % request.describe())
        preview = self.backend.plan(request)
        if not preview.ok:
            self.say("Refused, nothing was sent: %s" % preview.reason)
            self._record(request, "refused: %s" % preview.reason)
            return EXIT_NO_DRIVER if preview.unavailable else EXIT_REFUSED
        if preview.points <= 1:
            self.say("Plan: the arm is at the goal already (planned in %.0f ms); nothing to run."
                     % (preview.planning_time * 1000.0))
            self._record(request, "already there")
            return EXIT_OK
        for line in plan_lines(request, preview):
            self.say(line)
        stop = self._go_ahead(request, preview_only, confirm, "planned (not run)",
                              "Run this planned motion on the robot? [y/N]: ")
        if stop is not None:
            return stop
        return self._run_move(request, preview, move_timeout, start=lambda: self.backend.start_plan(preview))

    def _run_move(self, request, preview, move_timeout: Optional[float],
                  start: Optional[Callable[[], MoveHandle]] = None) -> int:
        """Send the previewed ``request`` (``start``: how, the backend's start_move by default) and
        watch it to its end (:class:`MoveWatch`); it becomes the next entry's defaults."""
        started = self.clock()
        duration = max(preview.duration, getattr(preview, "run_duration", 0.0))
        timeout = move_timeout if move_timeout is not None else 3.0 * duration + 15.0
        target = getattr(request, "target", None) or getattr(preview, "target", None)
        self._sending = True
        handle = start() if start is not None else self.backend.start_move(request)
        self._sending = False
        self._remember(request, target)
        self.say("Sent. Ctrl-C stops the arm.")
        watch = MoveWatch(handle, ProgressPrinter(self.out, self.tty, clock=self.clock), self.say,
                          self._call_stop, clock=self.clock, poll_period=self.poll_period,
                          stop_wait=self.stop_wait)
        end = watch.follow(target, started, timeout)
        self._record(request, end.outcome)
        return EXIT_OK if end.reached else EXIT_REFUSED if end.answered else EXIT_NO_DRIVER

    def _call_stop(self) -> None:
        ok, message = self.backend.stop()
        self.say("  stop_motion: %s" % message if ok else "  stop_motion failed: %s" % message)

    # -------------------------------------------------------------- one shot
    def run_once(self, request: PoseRequest, preview_only: bool = False) -> int:
        try:
            return self.execute_guarded(request, preview_only=preview_only)
        except _EntryEnd:                          # home / quit at the confirmation: not sent, done
            return EXIT_REFUSED


# ------------------------------------------------------------------------------------ command line

DESCRIPTION = """\
Command the VR-006L from the terminal through the driver (node `interface`, action move_to_pose).
Without --pose: interactive (prompts for X Y Z Rx Ry Rz and the move type; 'help' there).
With --pose: one move, then exit: 0 reached (or --preview: reachable), 1 refused / not confirmed /
failed / stopped, 2 usage error, 3 no ROS master or driver, or no answer in time (130: Ctrl-C
while waiting for the driver)."""


class _ArgumentParser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # argparse exits 2 too; keep its one-line form
        self.print_usage(sys.stderr)
        self.exit(EXIT_USAGE, "%s: error: %s\n" % (self.prog, message))


_NAMESPACE = re.compile(r"\A/?(?:[A-Za-z][A-Za-z0-9_]*(?:/[A-Za-z][A-Za-z0-9_]*)*/?)?\Z")


def _namespace(text: str) -> str:
    """``--ns``: a ROS namespace (``arm1``, ``/cell/arm1``) or empty; argparse reports the error."""
    if not _NAMESPACE.match(text):
        raise argparse.ArgumentTypeError("%r is not a ROS namespace (names of a letter followed by "
                                         "letters, digits and underscores, separated by /)" % text)
    return text


def in_namespace(ns: str, name: str) -> str:
    """``name`` (a topic, action, service or node of the driver) inside the namespace ``ns``: an
    absolute name and an empty ``ns`` leave it as it is (then resolved in the terminal's own
    namespace, as before ``--ns``)."""
    if not ns or name.startswith("/"):
        return name
    return ns.rstrip("/") + "/" + name


def _scaling(text: str) -> float:
    """``--velocity-scaling``: 0 < S <= 1; argparse reports the error."""
    try:
        value = check_velocity_scaling(text, "--velocity-scaling")
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    if value == 0.0:
        raise argparse.ArgumentTypeError("--velocity-scaling: 0 < S <= 1 (leave it out for the driver's default)")
    return value


def build_arg_parser(prog: str = "pose_terminal") -> argparse.ArgumentParser:
    p = _ArgumentParser(prog=prog, description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--pose", nargs=6, metavar=("X", "Y", "Z", "RX", "RY", "RZ"),
                   help="move to this pose (mm, deg) and exit")
    p.add_argument("--type", dest="move_type", default=None, metavar="ptp|lin|circ|plan",
                   help="move type for --pose (default ptp); plan: a collision-free motion planned around "
                        "the cell (the driver's plan action)")
    p.add_argument("--plan", default=None, metavar="NAME",
                   help="plan a collision-free motion to this named state of the SRDF (home, zero) and exit")
    p.add_argument("--velocity-scaling", type=_scaling, default=0.0, metavar="S",
                   help="time plans at this fraction of the joint speed and acceleration limits, 0 < S <= 1 "
                        "(default: the driver's velocity_scaling, 0.1 unless configured otherwise)")
    p.add_argument("--via", nargs=6, metavar=("X", "Y", "Z", "RX", "RY", "RZ"),
                   help="via point of a circular move (--type circ)")
    p.add_argument("-y", "--yes", action="store_true", help="send without asking for confirmation")
    p.add_argument("--preview", action="store_true", help="with --pose: only preview, send nothing")
    p.add_argument("--wait", type=float, default=10.0, metavar="SEC",
                   help="how long to wait for the ROS master and the driver (default 10 s)")
    p.add_argument("--driver", default="interface", metavar="NODE",
                   help="the driver node whose parameters (workspace) are read (default: interface)")
    p.add_argument("--ns", default="", metavar="NS", type=_namespace,
                   help="the driver's namespace (two_arms.launch: arm1 or arm2): its move_to_pose, "
                        "stop_motion, robot_status, tool_pose, joint_states and the node NS/NODE "
                        "(default: this terminal's own namespace)")
    p.add_argument("--launch-pid", type=int, default=None, metavar="PID",
                   help="stop waiting for the driver when this process (its launch) has ended")
    return p


def request_from_args(args: argparse.Namespace, workspace: Workspace):
    """The --pose / --type / --via request, or --plan NAME's / --type plan's PlanRequest; InputError
    (a usage error) when it is not valid."""
    plan_type = (args.move_type or "").strip().lower() == "plan"
    if args.plan is not None:
        if args.pose is not None or args.move_type is not None or args.via is not None:
            raise InputError("--plan NAME goes alone (or with --preview / --yes); for a pose: --pose ... --type plan")
        return parse_plan_line("plan " + args.plan, workspace)
    if plan_type and args.via is not None:
        raise InputError("--via is only for --type circ")
    if args.pose is None:
        if args.move_type is not None or args.via is not None or args.preview:
            raise InputError("--type, --via and --preview go with --pose")
        raise InputError("no --pose given")
    if plan_type:
        for text, fld in zip(args.pose, FIELDS):
            try:
                parse_number(text, fld, workspace)
            except RangeError:
                pass
        return PlanRequest(target=check_pose(list(args.pose), workspace))
    kind = parse_move_type(args.move_type or "", default=MoveType.CIRC if args.via else MoveType.PTP)
    if kind is MoveType.CIRC and args.via is None:
        raise InputError("--type circ needs --via X Y Z RX RY RZ")
    if kind is not MoveType.CIRC and args.via is not None:
        raise InputError("--via is only for --type circ")
    # every value's syntax first (a usage error), then the ranges (a refusal)
    for values, what in ((args.pose, ""), (args.via, "via")):
        for text, fld in zip(values or (), FIELDS):
            try:
                parse_number(text, fld, workspace, what=what)
            except RangeError:
                pass
    if getattr(args, "velocity_scaling", 0.0):
        raise InputError("--velocity-scaling is for plans (--plan NAME, --pose ... --type plan)")
    target = check_pose(list(args.pose), workspace)
    via = check_pose(list(args.via), workspace, what="via") if args.via is not None else None
    return PoseRequest(kind, target, via)
