"""What a move will do, said before anything moves (ROS-free, no I/O): the time and the TCP's top
speed the protocol delivers for a plan or a move -- one function for the terminal (through the move
and plan actions), the plan action and the trajectory action, so that the figures a user reads before
confirming are those of the run (issue 46).

- A streaming protocol (v2, v3) runs a plan on its own timing: the plan's duration -- after a hold at
  the start where the bus brings the first targets slower than the plan passes them (v3), later
  only where it still does -- the TCP's top speed along it (the planned samples, the straight joint
  moves between them).
- v1 runs each target at the robot program's own constant speed (MOVEP ``controller/program_speed``
  for a PTP target, MOVEL / MOVEC ``program_path_speed`` for a LIN / CIRC; the documented program's
  10 and 5 m/min, doc/controller_program.md section 5), whatever the plan's timing, and stops at
  every target: each move is the arm's own profile slowed down evenly until its TCP stays within
  that speed (:func:`~vr_driver.kinematics.preview.at_tcp_speed`, the model the virtual G2 runs,
  section 10.9), plus the handshake of each target (:data:`HANDSHAKE_CYCLES` bus cycles). A velocity
  scaling asked for does not apply there: :func:`scaling_words` says so in words.

The durations count from the first target on the wire to the arm at rest at the end, as the driver
sees it (a stream: the plan's time, its hold at the start if any, and :data:`STREAM_LATENCY_CYCLES`
bus cycles): the preparation
before it is said apart (the trajectory action's result).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, List, Sequence, Tuple

import numpy as np

from ...errors import ProtocolError
from ...kinematics.preview import at_tcp_speed, peak_tcp_speed
from ...kinematics.solver import Kinematics
from ...protocol.base import Protocol
from .stream_points import hold_lead

__all__ = ["Announced", "HANDSHAKE_CYCLES", "STREAM_LATENCY_CYCLES", "announce_moves", "announce_plan", "fed_times",
           "plan_peak_speed", "program_duration", "scaling_words"]

#: bus cycles a stream takes besides the plan's time: its first target reaches the controller's program
#: a cycle after it left, and the feedback that says the arm reached the last point comes back two
#: records later (doc/controller_program.md section 10.4 rule 7); on the stepped world a plan ran 3.1-3.3
#: cycles longer than planned (0.12-0.13 s at 25 cycles/s)
STREAM_LATENCY_CYCLES = 3.0

#: bus cycles one v1 target costs besides its motion: the record with the request reaches the program,
#: its DONE comes back, the master clears the flag and sees READY before it sends the next
#: (doc/controller_program.md section 4)
HANDSHAKE_CYCLES = 4.0


@dataclass(frozen=True)
class Announced:
    """``duration`` [s] from the first target to the arm at rest at the end; ``top_speed`` [mm/s] the
    TCP's largest speed; ``words`` both in words, naming where they come from; ``program``: v1 (the
    program's speed, not the plan's); ``times`` (a streaming protocol) each planned point's time as the
    stream runs it [s from its start]: the plan after the hold, later where the bus brings points later
    (:func:`fed_times`) -- the run to compare with the plan at the same time (empty on v1: its stops)."""

    duration: float
    top_speed: float
    words: str
    program: bool = False
    times: Tuple[float, ...] = ()


def plan_peak_speed(kin: Kinematics, times: Sequence[float], positions: Sequence[Sequence[float]]) -> float:
    """[mm/s] the TCP's largest speed along a planned joint path (between consecutive samples)."""
    if len(times) < 2:
        return 0.0
    xyz = np.array([kin.fk_pose(q).as_tuple()[:3] for q in positions])
    dt = np.diff(np.asarray(times, dtype=float))
    dp = np.linalg.norm(np.diff(xyz, axis=0), axis=1)
    moving = dt > 0.0
    return float(np.max(dp[moving] / dt[moving], initial=0.0))


def fed_times(times: Sequence[float], stream: Sequence[Any]) -> List[float]:
    """The plan's sample ``times`` as its ``stream`` (driver.motion.jobs.StreamPoint) runs them: each
    stream point's planned ``time`` moved to its ``fed`` arrival, the samples between two points moved
    as the two are (linearly), those before the first fed point and after the last by their shift."""
    pts = sorted((float(p.time), float(p.fed)) for p in stream if p.fed is not None and not p.hold)
    if not pts:
        return [float(t) for t in times]
    planned = np.array([t for t, _ in pts])
    shift = np.array([f - t for t, f in pts])
    at = np.asarray(times, dtype=float)
    return (at + np.interp(at, planned, shift)).tolist()


def announce_plan(kin: Kinematics, wire: Protocol, times: Sequence[float], positions: Sequence[Sequence[float]],
                  previews: Sequence[Any] = (), params: Any = None, cycle_time: float = 0.0,
                  stream: Sequence[Any] = ()) -> Announced:
    """The figures of a planned trajectory on the protocol ``wire``: a streaming protocol its timing --
    as its ``stream`` (driver.motion.jobs.StreamPoint) is fed: the plan, after the hold its first
    point may be (``hold``: the arm waits just off its start while the bus brings the first targets,
    then runs the plan's own timing), and later than that only where the bus still brings a target
    later than the plan passes it (its last point's ``fed`` arrival) -- and
    :data:`STREAM_LATENCY_CYCLES` of ``cycle_time`` (the bus cycle [s]); the TCP's top speed is the
    plan's (the hold is slower, no segment faster) -- where later points are shifted, the plan's as
    the stream runs it (:func:`fed_times`: a peak on a segment the bus stretches is lower; a run said
    at 1055 mm/s went at most 846). v1 (no stream): the PTP ``previews`` it sends
    between the plan's stop points (``JobControl.prepare_trajectory``), at ``params.controller``'s
    program speed, each with its handshake."""
    if wire.streams:
        planned = float(times[-1]) if len(times) else 0.0
        last = stream[-1] if stream else None
        lead = hold_lead(stream)
        late = max(0.0, last.fed - float(last.time)) if last is not None and last.fed is not None else 0.0
        latency = STREAM_LATENCY_CYCLES * cycle_time if planned > 0.0 else 0.0
        shifted = late - lead > 0.005                 # later points than the hold's lead alone
        run = fed_times(times, stream)                # (the hold's lead alone shifts every point alike)
        top = plan_peak_speed(kin, run, positions)
        said = planned + late + latency
        parts = ["the plan's %.2f s" % planned]
        if lead > 0.005:
            parts.append("a %.2f s hold at the start while the bus brings its first targets" % lead)
        if shifted:
            parts.append("%.2f s more where it brings later ones slower than the plan passes them" % (late - lead))
        if latency:
            parts.append("the bus's %g cycles to the arm and back" % STREAM_LATENCY_CYCLES)
        how = "" if len(parts) == 1 else " (%s and %s)" % (", ".join(parts[:-1]), parts[-1])
        return Announced(said, top, "protocol %s runs the plan's timing: %.2f s%s, the TCP at most %.0f mm/s"
                         % (wire.name, said, how, top), times=tuple(run))
    return announce_moves(wire, previews, params, cycle_time)


def announce_moves(wire: Protocol, previews: Sequence[Any], params: Any, cycle_time: float) -> Announced:
    """v1: the figures of its targets ``previews`` (driver.motion.jobs.Preview: a move each, as previewed at
    the arm's full speed) at the program's speeds, one after the other, each with its handshake."""
    facts = params.controller
    duration = top = 0.0
    kinds = set()
    for preview in previews:
        kind = preview.request.move_type
        kinds.add(kind.name)
        moved = at_tcp_speed(preview.trajectory, _program_speed(wire, preview, facts))
        duration += moved.duration + HANDSHAKE_CYCLES * cycle_time       # (program_duration)
        top = max(top, peak_tcp_speed(moved))
    speeds = []
    if "PTP" in kinds:
        speeds.append("MOVEP %g m/min (%.0f mm/s)" % (facts.program_speed, facts.program_speed * 1000.0 / 60.0))
    if kinds - {"PTP"}:
        speeds.append("MOVEL / MOVEC %g m/min (%.0f mm/s)"
                      % (facts.program_path_speed, facts.program_path_speed * 1000.0 / 60.0))
    n = len(previews)
    words = ("protocol %s runs %s at the robot program's own speed, %s, not a plan's timing, and stops at %s: "
             "%.2f s (%.2f s of it the handshakes, %g bus cycles each), the TCP at most %.0f mm/s"
             % (wire.name, "it" if n == 1 else "its %d targets" % n, " and ".join(speeds) or "none",
                "the target" if n == 1 else "each", duration, n * HANDSHAKE_CYCLES * cycle_time,
                HANDSHAKE_CYCLES, top))
    return Announced(duration, top, words, program=True)


def program_duration(wire: Protocol, preview: Any, facts: Any) -> float:
    """[s] a previewed move (driver.motion.jobs.Preview) as the v1 program runs it, at its speed
    (``facts``: ``params.controller``)."""
    return at_tcp_speed(preview.trajectory, _program_speed(wire, preview, facts)).duration


def _program_speed(wire: Protocol, preview: Any, facts: Any) -> float:
    """[mm/s] the TCP speed the program of ``wire`` runs ``preview``'s move at
    (:meth:`~vr_driver.protocol.base.Protocol.program_speed` of ``facts``' program speeds); ProtocolError
    for a protocol that runs a plan's own timing (a streaming one: no program speed)."""
    speed = wire.program_speed(preview.request.move_type, facts.program_speed, facts.program_path_speed)
    if speed is None:
        raise ProtocolError("protocol %s runs a plan's own timing: it has no program speed" % wire.name)
    return speed


def scaling_words(announced: Announced, scaling: float, default: bool, planned_speed: float) -> str:
    """The warning where a plan's velocity scaling cannot be honoured ("" where it is): on v1 the
    program's speed applies whatever the plan's timing (``planned_speed`` [mm/s]: the plan's top TCP
    speed at ``scaling``; ``default``: the scaling is the driver's default, not the user's)."""
    if not announced.program or not scaling or not math.isfinite(planned_speed):
        return ""
    how = ("faster than" if announced.top_speed > planned_speed * 1.05 else
           "slower than" if announced.top_speed < planned_speed * 0.95 else "about")
    return ("velocity scaling %g%s does not apply on this protocol: the robot program's speed does (the TCP at "
            "most %.0f mm/s, %s the plan's %.0f mm/s)"
            % (scaling, " (the driver's default)" if default else "", announced.top_speed, how, planned_speed))
