"""The driver set from the commissioning (doc/commissioning.md): what the measured G2
(``params.controller``, :class:`vr_driver.params.ControllerFacts`) changes in the driver, and the words
it says at connect. ROS-free.

Where each fact acts:

- ``speed_scale`` (MOVEP's speed unit): every stream target's speed is sent divided by it
  (:func:`vr_driver.driver.motion.streaming.wire_speed`), so the arm runs the planned time; where that
  needs more than speed 1000 the arm runs slower than planned -- the planner must have been given
  the scaled velocity limits (``planning_limits``, the commissioning's ``joint_limits.yaml``);
- ``interpreter_lookahead``: 0 makes every stream point an exact stop (``stream_smooth`` 0, set by
  DriverParams); 2 and more let stream segments be shorter (:func:`min_segment_cycles`);
- ``send_ahead`` other than accepted: one target per acknowledgement
  (:attr:`vr_driver.params.DriverParams.wire`), and stream segments twice as long
  (:func:`min_segment_cycles`);
- ``loop_blocks_during_move``: a streaming protocol is refused at start (DriverParams);
- ``configuration`` (the G2's rule for a Cartesian target's joint solution): the driver predicts
  the G2's solution by it -- ``joint_states`` on v1 and v3 (:class:`~.tracking.JointTracker`), the
  v3 stream check and the wire poses (:class:`~.stream_prep.CartesianStreams`: under
  ``current_joints`` each point checked from where the arm may be when the G2 takes it, up to
  ``ring_size`` + 1 points back, and points kept closer together);
- ``not_measured`` (the keys the bus hid, e.g. the look-ahead and the ring where the program loop
  blocked during a MOVE): their assumptions stand, said at connect; an unmeasured look-ahead runs
  every stream point as a stop (``stream_smooth`` 0, DriverParams) and never shortens segments;
- ``planning_limits`` (not a controller fact, the file beside the commissioning's): the plan
  action's joint speed and acceleration limits (:func:`planning_kinematics`).

:func:`controller_notes` says each of these in words (DriverCore logs them at every connect, the
node's /diagnostics shows them).
"""
from __future__ import annotations

import copy
import dataclasses
import math
from typing import TYPE_CHECKING, List, Optional, Tuple

from ...params import ControllerFacts, DriverParams, read_planning_limits
from ...protocol.base import Protocol
from ..motion.stream_points import MIN_SEGMENT_CYCLES
from .wire_targets import CARTESIAN_MAX_STEP

if TYPE_CHECKING:
    from ...kinematics.solver import Kinematics

__all__ = ["controller_notes", "feed_cycles", "min_segment_cycles", "planning_kinematics", "plain_names"]


def plain_names(params: DriverParams) -> Tuple[str, ...]:
    """The arm's joint names without the prefix (the names of the commissioning's files)."""
    n = len(params.prefix)
    return tuple(name[n:] for name in params.controller_joint_names)


def _one_per_acknowledgement(wire: Protocol) -> bool:
    """A one-slot streaming record whose master does not send ahead: one new target every other
    bus cycle (the acknowledgement of a record comes a cycle after it)."""
    return wire.streams and wire.look_ahead_slots <= 1 and wire.send_ahead <= wire.look_ahead_slots


def feed_cycles(wire: Protocol) -> float:
    """The bus cycles the master takes to bring the controller one stream target with the protocol
    object ``wire`` (``params.wire``): 1 (it sends ahead), 2 where it sends one per acknowledgement
    (a new target only every other cycle)."""
    return 2.0 if _one_per_acknowledgement(wire) else 1.0


def min_segment_cycles(params: DriverParams, wire: Optional[Protocol] = None) -> float:
    """The shortest stream segment [bus cycles] the bus feeds without a gap, for this G2:
    MIN_SEGMENT_CYCLES with the assumed G2 (an interpreter look-ahead of 1, targets sent ahead);
    divided by the look-ahead where it is larger (the interpreter holds that many points beyond the
    one the arm runs to: the next target may come that much later); times :func:`feed_cycles`
    (doubled where the master sends one target per acknowledgement). A look-ahead of 0 counts as 1:
    every point is a stop there, the segments' length does not starve anything. ``wire``: the
    protocol object when the caller holds it (``params.wire`` builds one at every call)."""
    return MIN_SEGMENT_CYCLES * feed_cycles(params.wire if wire is None else wire) \
        / max(1, params.controller.interpreter_lookahead)


def planning_kinematics(params: DriverParams, kin: Kinematics) -> Kinematics:
    """The model the plan action plans with: ``kin`` itself without ``planning_limits``; else a
    shallow copy of it (the same solver: use it in one thread, as ``kin``) whose joint speed and
    acceleration limits are the file's (position limits stay the model's)."""
    if not params.planning_limits:
        return kin
    velocity, acceleration = read_planning_limits(params.planning_limits, plain_names(params))
    out = copy.copy(kin)
    out.limits = dataclasses.replace(kin.limits, velocity=velocity, acceleration=acceleration)
    return out


def _ramp_words(params: DriverParams, model_ramp: Optional[float]) -> str:
    facts = params.controller
    if facts.ramp_time is not None:
        return "%.2g s, the measured ramp" % facts.ramp_time
    if model_ramp is not None:
        return "%.2g s with the model's accelerations (not measured)" % model_ramp
    return "the arm's ramp time"


def controller_notes(params: DriverParams, kin: Optional[Kinematics] = None) -> Tuple[str, ...]:
    """What the commissioned G2 changes, in words, one sentence each (empty: the G2 as assumed, or
    no commissioning). ``kin``: the driver's model (its ramp time and speed limits, for the
    figures; None: said without them)."""
    facts = params.controller
    wire = params.wire
    model_ramp = kin.limits.ramp_time if kin is not None else None
    notes: List[str] = []
    if params.commissioning:
        info = params.commissioning
        ident = info.get("controller") if isinstance(info.get("controller"), dict) else {}
        notes.append("the G2 as commissioned on %s (controller ident %s, %s): %s" % (
            info.get("date", "an unknown date"), ident.get("ident", "?"), ident.get("chk_cfg", "?"),
            "as assumed" if facts == type(facts)() else "it differs from the assumptions, below"))
    if wire.streams:
        if facts.interpreter_lookahead == 0:
            notes.append(
                "the G2 reads no MOVE ahead (controller/interpreter_lookahead 0: no look-ahead, or the input "
                "read between two MOVEPs ends the blend): protocol %s runs every stream point as an exact "
                "stop (stream_smooth 0); each stop costs up to a ramp (%s) -- a stream of n points runs up to "
                "n times that longer than planned" % (params.wire.name, _ramp_words(params, model_ramp)))
        elif facts.interpreter_lookahead > 1:
            notes.append("the G2's interpreter reads %d MOVEs ahead (controller/interpreter_lookahead): stream "
                         "segments down to %g bus cycles" % (facts.interpreter_lookahead,
                                                            min_segment_cycles(params)))
        if facts.speed_scale != 1.0:
            notes.append(_speed_words(params, kin))
        if facts.send_ahead != "accepted" and _one_per_acknowledgement(wire):
            what = ("refuses a target sent ahead" if facts.send_ahead == "refused" else
                    "RUNS a target sent ahead out of order (exactly once then rests on the driver never "
                    "sending ahead: fix the program, doc/commissioning.md)")
            notes.append("the G2's program %s (controller/send_ahead %s): the driver sends one target per "
                         "acknowledgement -- a new target every other bus cycle, stream segments of at least "
                         "%g cycles" % (what, facts.send_ahead, min_segment_cycles(params)))
        if not facts.check_word:
            notes.append("the G2's program acts on a record whose check word is wrong (controller/check_word "
                         "false): a corrupted target could run -- edit GETCMD3 (doc/controller_program.md "
                         "§10.3) before running streams")
    if facts.not_measured:
        notes.append(_not_measured_words(params))
    if facts.unreachable == "alarm_halt":
        notes.append("an unreachable target raises an alarm that halts the G2's program (controller/"
                     "unreachable alarm_halt): the driver checks every pose against its model before sending "
                     "it; if it happens, reset the alarm at the pendant and restart the program")
    if facts.configuration == "current_joints" and not wire.joint_targets:
        text = ("the G2 solves a Cartesian target nearest its joints at that moment (controller/configuration "
                "current_joints): the driver's joint_states apply that rule to what it sent")
        if wire.streams:
            window = facts.ring_size + 1
            text += ("; each stream point is checked from wherever the arm may be when the G2 takes it, up to %d "
                     "points before it (controller/ring_size %d + 1), and stream points are kept at most %.0f deg "
                     "apart (more points where a joint turns fast)"
                     % (window, facts.ring_size, math.degrees(CARTESIAN_MAX_STEP / window)))
        notes.append(text)
    return tuple(notes)


def _not_measured_words(params: DriverParams) -> str:
    """What the driver does with the facts the commissioning could not measure."""
    facts = params.controller
    assumed = ControllerFacts()
    text = ("the commissioning could not measure %s (controller/not_measured: the bus hid %s; the reasons are in "
            "the file's commissioning/not_measured): the driver keeps the assumption%s" % (
                ", ".join(facts.not_measured), "them" if len(facts.not_measured) > 1 else "it",
                "s" if len(facts.not_measured) > 1 else ""))
    kept = ["%s %s" % (key, getattr(assumed, key)) for key in facts.not_measured
            if key in ("ring_size", "configuration", "ramp_shape", "loop_period_spread")]
    if kept:
        text += " (%s)" % ", ".join(kept)
    if "interpreter_lookahead" in facts.not_measured and params.wire.streams:
        text += ("; the look-ahead unknown, protocol %s runs every stream point as an exact stop (stream_smooth 0: "
                 "right for any look-ahead, slower where the G2 could blend) and streams no shorter segments"
                 % params.wire.name)
    if {"accelerations", "ramp_time"} & set(facts.not_measured):
        text += "; the planner keeps the model's accelerations"
    return text + " -- commission again once the program changed (doc/commissioning.md)"


def _speed_words(params: DriverParams, kin: Optional[Kinematics]) -> str:
    scale = params.controller.speed_scale
    text = ("MOVEP's speed unit is x%.3g (controller/speed_scale): the driver sends each stream speed "
            "divided by %.3g so that the arm runs the planned time" % (scale, scale))
    if scale >= 1.0:
        return text
    text += ("; the arm's top speed is %.0f %% of the model's joint speed limits, so a segment planned "
             "faster runs at speed 1000, slower than planned" % (100.0 * scale))
    if not params.planning_limits:
        return text + " -- give the planner the scaled velocity limits (planning_limits: the " \
            "commissioning's joint_limits.yaml)"
    if kin is not None:
        velocity, _ = read_planning_limits(params.planning_limits, plain_names(params))
        over = [name for name, v, vm in zip(plain_names(params), velocity, kin.limits.velocity)
                if v > scale * vm * 1.001]
        if over:
            return text + " -- planning_limits (%s) allows more for %s: plans may run slower there" % (
                params.planning_limits, ", ".join(over))
    return text + "; the plan action plans with planning_limits (%s)" % params.planning_limits
