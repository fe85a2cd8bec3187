#!/usr/bin/python3
"""Soak test of the driver under link faults: nothing lost, nothing done twice (issue 10).

    scripts/bench soak -- [--targets 1000] [--corrupt 0.02] [--cut-every 20] [--seed 1] [...]

(issue 10's full run: --targets 5000; about 0.5 s per target at 2 % corruption, so ~40 min)

A DriverCore (the ROS-free core of the `interface` node) drives the virtual G2 controller over a
REAL pty pair; the driver's serial link is wrapped in a FaultyLink that corrupts bytes (both
directions, --corrupt per byte: XOR with a random non-zero mask), optionally drops (--drop) and
delays (--delay, --delay-s) them, and -- with --cut-every S -- cuts the line completely at random
times around every S seconds (uniform 0.5 S .. 1.5 S apart) for a random 0.2 .. 1 s
(--cut-min / --cut-max), then restores it. The pty carries no parity bit, so by default only the
DP telegram checks (FCS, lengths, ED) catch corrupted bytes; --parity emulates the 8E1 UART parity
check a real RS-485 port adds (odd-weight errors are dropped instead of delivered).

Targets (seeded RNG, --seed): a PTP / LIN / CIRC mix (--mix, default 50/30/20 %). PTP targets are
FK of random joints within the limits, rounded to whole mm / deg and inside the workspace box; LIN
and CIRC targets are random offsets of up to 150 mm / 10 deg around the current pose (a CIRC's via
and end both). Every wire target (a CIRC's via point is a target of its own) is unique over the
whole run -- perturbed by 1 mm in X where needed -- so each entry of the controller's execution
log names exactly one commanded target. Targets are submitted one after another: submit, wait for
the job's result, next. A submit the driver refuses because motion is not possible now (link
down, no joint state yet) is retried after the next status change -- that is not a loss; a target
the driver refuses as invalid or unplannable (its preview fails) is replaced by a new one and never
counted as commanded.

At the end the commanded list is compared with the controller's execution log, by the unique
target values (and the wire move type):

  commanded   wire targets handed to the driver (submit() returned a job)
  executed    the log shows the target executed (a via point: stored) -- once or more
  rejected    not executed, the log shows the controller refused it, and the driver reported it
  aborted     not executed, and the driver ended the job with a reason (link lost, timeout,
              stopped mid-motion -- the log then says rejected/aborted -- or never sent: an earlier
              part of the move failed)
  duplicated  executed more than once (must be 0)
  lost        not executed and the driver never reported a reason: the job succeeded, or it never
              ended within --job-timeout (must be 0)

Also printed: targets executed although the driver reported the job failed (its reason said the
target was given up, e.g. "link lost"; the controller may finish a motion it started), log entries
that match no commanded target (only an undetected corrupted telegram can cause them), the
reconnect time of every cut (from the restore to the first driver status with motion possible
that is based on a record received after the restore; a cut the link rode out costs one cycle)
and the longest gap between two DriverStatus listener calls of the core (the ROS node publishes
robot_status on every snapshot change plus a 10 Hz timer, so this gap bounds robot_status's).
On every listener call the arm's exact TCP is checked against the workspace box (bus cycles
outside, the farthest), and while the arm rests the driver's joints against the arm's (cycles more
than 20 deg apart: another configuration -- v1 and v3 report only a rounded pose); submit refusals are
counted by reason. A run in which no target is taken for 60 s while motion is possible
ends early and says why (the last refusal, the arm's pose and joints).

Last line, exactly:
  commanded=N executed=N rejected=N aborted=N duplicated=N lost=N reconnect_max_s=X status_gap_max_s=X

In v1 the virtual controller runs its two-telegram rule (a master record counts only once it
arrived unchanged in two consecutive Data_Exchange telegrams); --no-confirm turns it off to show
what it prevents (v2 and v3 act at the first telegram: v2's CRC-16 and v3's check word and seq copy
do the rule's job): at 2 % corruption about 1.7e-4 of the requests pass the 8-bit FCS with wrong bytes, and
the controller then runs a target nobody commanded (an "unknown" log entry, the commanded one
lost) or runs one twice. A pty has no baud timing: --baud only sets the DP timing parameters;
bytes move at pty speed.
Figures only; the exit status is 1 when duplicated or lost is not 0, the arm left the box, the
driver's joints were another configuration, or the run could not finish.
"""
from __future__ import annotations

import argparse
import collections
import logging
import math
import os
import random
import re
import shutil
import statistics
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from typing import Callable, Dict, List, Optional, Sequence, Tuple

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
for _pkg in ("vr_driver", "pyprofibus_vendor", "panasonic_vr006l_support"):
    _src = os.path.join(REPO, _pkg, "src")
    if _src not in sys.path:
        sys.path.insert(0, _src)

from pyprofibus_vendor.phy import FaultyLink, Link  # noqa: E402
from pyprofibus_vendor.phy_serial import SerialLink  # noqa: E402

from vr_driver.controller.virtual_controller import VirtualController  # noqa: E402
from vr_driver.driver import DriverCore, DriverError, DriverStatus, JobResult, MoveJob, MoveRequest  # noqa: E402
from vr_driver.errors import VrDriverError  # noqa: E402
from vr_driver.kinematics.solver import Kinematics  # noqa: E402
from vr_driver.kinematics.preview import MoveType  # noqa: E402
from vr_driver.params import DriverParams  # noqa: E402
from vr_driver.poses import ControllerPose  # noqa: E402
from vr_driver.protocol import registry as protocols  # noqa: E402
from vr_driver.protocol.v1 import round_half_away  # noqa: E402
from vr_driver.protocol.v2 import joints_to_wire  # noqa: E402
from vr_driver.protocol.v3 import pose_to_wire  # noqa: E402
from vr_driver.controller.arm import LogEntry, Outcome  # noqa: E402

IntPose = Tuple[int, int, int, int, int, int]
Key = Tuple[str, IntPose]              # (wire move type name, target values): unique per target


# ------------------------------------------------------------------------------------ configuration

@dataclass
class SoakConfig:
    targets: int = 1000
    corrupt: float = 0.02
    drop: float = 0.0
    delay: float = 0.0
    delay_s: float = 0.01
    parity: bool = False
    confirm_records: Optional[bool] = None  # the two-telegram rule (None: the protocol's default)
    cut_every: float = 20.0             # mean seconds between cuts; 0 = no cuts
    cut_times: Tuple[float, ...] = ()   # or: cut at these times [s from the start] (tests)
    cut_min: float = 0.2
    cut_max: float = 1.0
    seed: int = 1
    mix: Tuple[float, float, float] = (0.5, 0.3, 0.2)    # PTP, LIN, CIRC
    speed_factor: float = 100.0
    baud: int = 187500
    cycle_rate: float = 50.0
    loop_period: float = 0.01
    job_timeout: float = 60.0           # a job without a result after this long counts as lost
    stall_timeout: float = 60.0         # no motion possible, or no target taken, this long: give up
    progress_every: int = 0             # print a progress line every N targets (0: never)
    workdir: Optional[str] = None
    protocol: str = "v1"                # v2 / v3: every move is streamed (each streamed point a target)
    driver_params: Dict[str, object] = field(default_factory=dict)   # overrides


@dataclass
class Commanded:
    index: int                          # 0.. in submission order
    job_id: int
    move_type: str                      # MoveType name of the job (PTP / LIN / CIRC)
    keys: Tuple[Key, ...]               # the wire targets, in sending order
    submitted: float
    result: Optional[JobResult] = None
    finished: Optional[float] = None


@dataclass
class Cut:
    start: float
    restore: float
    reconnect: Optional[float] = None   # seconds from restore to motion possible on fresh data
    ready: Optional[float] = None       # ... and the handshake ready to send the next target


#: [deg] the driver's joints at rest further than this from the arm's: another configuration (v1's
#: whole mm / deg feedback alone moves a joint by a few degrees at most, near a singularity)
MISMATCH_DEG = 20.0


@dataclass
class SoakResult:
    config: SoakConfig
    commanded: int = 0
    jobs: int = 0
    executed: int = 0
    rejected: int = 0
    aborted: int = 0
    duplicated: int = 0                 # targets executed more than once
    extra_executions: int = 0           # executions beyond the first, summed
    lost: int = 0
    hung: int = 0                       # jobs without a result within job_timeout
    executed_but_failed: int = 0        # executed although the driver reported the job failed
    unknown_entries: int = 0            # log entries that match no commanded target
    refused_not_possible: int = 0       # submit refused: motion not possible now (retried)
    refused_invalid: int = 0            # submit refused: invalid / unplannable target (replaced)
    reasons: Dict[str, int] = field(default_factory=dict)   # driver reasons of failed jobs
    refusals: Dict[str, int] = field(default_factory=dict)  # submit refusals, by reason
    outside_samples: int = 0            # bus cycles that saw the arm outside the workspace box
    outside_max: float = 0.0            # the farthest out [mm or deg] ...
    outside_pose: Optional[ControllerPose] = None   # ... and where
    mismatch_samples: int = 0           # bus cycles at rest with the driver's joints off the arm's
    mismatch_max: float = 0.0           # ... by this much at most [deg]
    cuts: List[Cut] = field(default_factory=list)
    status_calls: int = 0
    status_gap_max: float = 0.0
    status_gap_at: float = 0.0
    duration: float = 0.0
    link_counters: Dict[str, int] = field(default_factory=dict)
    driver_counters: Dict[str, int] = field(default_factory=dict)
    master_counters: Dict[str, int] = field(default_factory=dict)
    log_entries: int = 0
    lost_details: List[str] = field(default_factory=list)
    duplicate_details: List[str] = field(default_factory=list)
    unknown_details: List[str] = field(default_factory=list)
    complete: bool = True
    error: str = ""

    @property
    def reconnect_times(self) -> List[float]:
        return [c.reconnect for c in self.cuts if c.reconnect is not None]

    @property
    def unrecovered_cuts(self) -> int:
        return sum(1 for c in self.cuts if c.reconnect is None)

    @property
    def reconnect_max(self) -> float:
        times = self.reconnect_times
        if self.unrecovered_cuts:
            return math.inf
        return max(times) if times else 0.0

    @property
    def reconnect_median(self) -> float:
        times = self.reconnect_times
        return statistics.median(times) if times else 0.0

    def final_line(self) -> str:
        return ("commanded=%d executed=%d rejected=%d aborted=%d duplicated=%d lost=%d "
                "reconnect_max_s=%.3f status_gap_max_s=%.3f"
                % (self.commanded, self.executed, self.rejected, self.aborted, self.duplicated,
                   self.lost, self.reconnect_max, self.status_gap_max))

    def summary(self) -> List[str]:
        c = self.config
        lines = [
            "soak: %d jobs, %d wire targets in %.1f s (%.1f targets/s); corrupt %.3g, drop %.3g, "
            "delay %.3g x %.0f ms, parity %s, two-telegram rule %s, cuts every ~%s s for %.1f..%.1f s, seed %d, speed x%g"
            % (self.jobs, self.commanded, self.duration, self.commanded / max(self.duration, 1e-9),
               c.corrupt, c.drop, c.delay, c.delay_s * 1e3, "on" if c.parity else "off",
               ("on" if c.confirm_records else "off") if c.confirm_records is not None
               else _confirm_default(c.protocol),
               ("%g" % c.cut_every) if c.cut_every > 0 else "-", c.cut_min, c.cut_max, c.seed,
               c.speed_factor),
            "outcomes: executed %d, rejected %d, aborted %d, lost %d (jobs without result %d); "
            "duplicated %d (extra executions %d)"
            % (self.executed, self.rejected, self.aborted, self.lost, self.hung, self.duplicated,
               self.extra_executions),
            "executed although reported failed: %d; log entries matching no commanded target: %d; "
            "log entries %d" % (self.executed_but_failed, self.unknown_entries, self.log_entries),
            "submit refused: motion not possible (retried) %d, invalid/unplannable (replaced) %d"
            % (self.refused_not_possible, self.refused_invalid),
            "workspace: the arm was outside the box in %d bus cycles%s"
            % (self.outside_samples, "" if self.outside_pose is None else
               " (farthest %.3f out, at %s)" % (self.outside_max, self.outside_pose)),
            "joints: the driver's off the arm's by more than %g deg (at rest) in %d bus cycles%s"
            % (MISMATCH_DEG, self.mismatch_samples,
               " (at most %.1f deg)" % self.mismatch_max if self.mismatch_samples else ""),
        ]
        times = sorted(self.reconnect_times)
        if self.cuts:
            lines.append("cuts: %d (%.2f..%.2f s long); reconnect median %.3f s, max %s s, "
                         "unrecovered %d; all: %s"
                         % (len(self.cuts), min(cu.restore - cu.start for cu in self.cuts),
                            max(cu.restore - cu.start for cu in self.cuts), self.reconnect_median,
                            "%.3f" % self.reconnect_max, self.unrecovered_cuts,
                            " ".join("%.2f" % t for t in times) if len(times) <= 40
                            else "(%d values)" % len(times)))
            ready = sorted(c.ready for c in self.cuts if c.ready is not None)
            if ready:
                lines.append("cuts: next target sendable (link up and the handshake settled) after "
                             "the restore: median %.3f s, max %.3f s"
                             % (statistics.median(ready), ready[-1]))
            rides = [c for c in self.cuts if c.reconnect is not None and c.reconnect < 0.1]
            lines.append("cuts ridden out without a reconnect (< 0.1 s to fresh data): %d of %d"
                         % (len(rides), len(self.cuts)))
        else:
            lines.append("cuts: none")
        lines.append("status: %d listener calls, longest gap %.3f s (at t=%.1f s)"
                     % (self.status_calls, self.status_gap_max, self.status_gap_at))
        if self.reasons:
            top = sorted(self.reasons.items(), key=lambda kv: -kv[1])[:8]
            lines.append("failed job reasons: " + "; ".join("%dx %s" % (n, r) for r, n in top))
        if self.refusals:
            top = sorted(self.refusals.items(), key=lambda kv: -kv[1])[:6]
            lines.append("submit refusals: " + "; ".join("%dx %s" % (n, r) for r, n in top))
        lines.append("fault link: " + ", ".join("%s %d" % kv for kv in self.link_counters.items()))
        lines.append("driver: " + ", ".join("%s %d" % kv for kv in self.driver_counters.items()))
        lines.append("master: " + ", ".join("%s %d" % kv for kv in self.master_counters.items()
                                            if kv[1]))
        for what, details in (("LOST", self.lost_details), ("DUPLICATED", self.duplicate_details),
                              ("UNKNOWN", self.unknown_details)):
            for line in details[:20]:
                lines.append("%s: %s" % (what, line))
        if self.error:
            lines.append("run ended early: %s" % self.error)
        return lines


# --------------------------------------------------------------------------------- fault injection

class FaultLine:
    """The open_link factory: every (re)opened serial link is wrapped in a FaultyLink with the
    configured faults; :meth:`cut` / :meth:`restore` act on the current one (and on any opened
    while cut). Counters are summed over all links opened."""

    def __init__(self, config: SoakConfig, rng: random.Random) -> None:
        self.config = config
        self.rng = rng
        self.links: List[FaultyLink] = []
        self._lock = threading.Lock()
        self._cut = False

    def open_link(self, device: str, baud: int) -> Link:
        c = self.config
        inner = SerialLink(device, baud)
        link = FaultyLink(inner, drop=c.drop, corrupt=c.corrupt, delay=c.delay, delay_s=c.delay_s,
                          rng=random.Random(self.rng.getrandbits(64)), parity=c.parity)
        with self._lock:
            if self._cut:
                link.cut()
            self.links.append(link)
        return link

    def cut(self) -> None:
        with self._lock:
            self._cut = True
            for link in self.links[-1:]:
                link.cut()

    def restore(self) -> None:
        with self._lock:
            self._cut = False
            for link in self.links:
                link.restore()

    def counters(self) -> Dict[str, int]:
        total: Dict[str, int] = collections.OrderedDict()
        for link in self.links:
            for name, value in vars(link.counters).items():
                total[name] = total.get(name, 0) + value
        return total


class Cutter(threading.Thread):
    """Cuts the line at random times around every ``cut_every`` s for cut_min..cut_max s."""

    def __init__(self, line: FaultLine, config: SoakConfig, rng: random.Random,
                 recorder: "StatusRecorder", clock: Callable[[], float] = time.monotonic) -> None:
        super().__init__(name="soak-cutter", daemon=True)
        self.line = line
        self.recorder = recorder
        self.config = config
        self.rng = rng
        self.clock = clock
        self.cuts: List[Cut] = []
        self.stop_event = threading.Event()

    def _pauses(self):
        c = self.config
        if c.cut_times:
            last = 0.0
            for t in sorted(c.cut_times):
                yield max(0.0, t - last)
                last = t
            return
        while True:
            yield self.rng.uniform(0.5, 1.5) * c.cut_every

    def run(self) -> None:
        c = self.config
        started = self.clock()
        elapsed = 0.0
        for pause in self._pauses():
            elapsed += pause
            if c.cut_times:              # absolute times: do not drift by the cuts' own lengths
                pause = max(0.0, started + elapsed - self.clock())
            if self.stop_event.wait(pause):
                return
            length = self.rng.uniform(c.cut_min, c.cut_max)
            start = self.clock()
            self.line.cut()
            self.stop_event.wait(length)        # restore even when stopping
            self.line.restore()
            cut = Cut(start, self.clock())
            self.cuts.append(cut)
            self.recorder.when_possible_after(
                cut.restore, lambda t, cut=cut: setattr(cut, "reconnect", max(0.0, t - cut.restore)))
            self.recorder.when_possible_after(
                cut.restore, lambda t, cut=cut: setattr(cut, "ready", max(0.0, t - cut.restore)),
                handshake_ready=True)
            if self.stop_event.is_set():
                return


# ------------------------------------------------------------------------------- status recording

class StatusRecorder:
    """The core's listener (bus thread): gaps between calls, motion-possible transitions with the
    time of the record they are based on, and a condition to wait on."""

    def __init__(self, clock: Callable[[], float] = time.monotonic,
                 handshake_ready: Callable[[], bool] = lambda: True,
                 probe: Callable[[DriverStatus], None] = lambda status: None) -> None:
        self.clock = clock
        self.handshake_ready = handshake_ready
        self.probe = probe
        self.calls = 0
        self.last: Optional[float] = None
        self.gap_max = 0.0
        self.gap_at = 0.0
        self.t0 = clock()
        # (since, need the handshake, targets sent when registered, callback)
        self._fresh_wanted: List[Tuple[float, bool, int, Callable[[float], None]]] = []
        self.targets_sent = 0
        self._lock = threading.Lock()
        self.cond = threading.Condition()

    def __call__(self, status: DriverStatus) -> None:
        now = self.clock()
        if self.last is not None and now - self.last > self.gap_max:
            self.gap_max = now - self.last
            self.gap_at = now - self.t0
        self.last = now
        self.calls += 1
        self.probe(status)
        fb_time = status.feedback_time
        self.targets_sent = status.counters.targets_sent
        if self._fresh_wanted and status.motion_possible and fb_time is not None:
            ready = self.handshake_ready()
            sent = status.counters.targets_sent
            with self._lock:
                due = [w for w in self._fresh_wanted
                       if fb_time >= w[0] and (not w[1] or ready or sent > w[2])]
                self._fresh_wanted = [w for w in self._fresh_wanted if w not in due]
            for _since, _ready, _sent, done in due:
                done(now)
        with self.cond:
            self.cond.notify_all()

    def when_possible_after(self, since: float, done: Callable[[float], None],
                            handshake_ready: bool = False) -> None:
        """Call ``done(t)`` (bus thread) at the first status with motion possible whose feedback
        record arrived at or after ``since`` (and, with ``handshake_ready``, once the driver's
        handshake can send a target -- it is ready, or it sent one since)."""
        with self._lock:
            self._fresh_wanted.append((since, handshake_ready, self.targets_sent, done))

    def wait_change(self, timeout: float) -> None:
        with self.cond:
            self.cond.wait(timeout)


# ----------------------------------------------------------------------------- target generation

class TargetGenerator:
    def __init__(self, kin: Kinematics, params: DriverParams, rng: random.Random,
                 mix: Sequence[float]) -> None:
        self.kin = kin
        self.workspace = params.workspace
        self.rng = rng
        total = float(sum(mix))
        self.mix = [m / total for m in mix]
        self.used: set = set()

    def _round(self, values: Sequence[float]) -> Optional[IntPose]:
        try:
            ints = tuple(round_half_away(v) for v in values)
            pose = ControllerPose(*ints)
        except (VrDriverError, ValueError, OverflowError):
            return None
        if not self.workspace.contains(pose):
            return None
        return ints  # type: ignore[return-value]

    def _unique(self, values: IntPose) -> Optional[IntPose]:
        """``values``, or the nearest in X (x + 1, x - 1, x + 2, ...) not used yet."""
        for step in range(200):
            dx = 0 if step == 0 else ((step + 1) // 2) * (1 if step % 2 else -1)
            cand = (values[0] + dx,) + tuple(values[1:])
            if cand not in self.used and self.workspace.contains(ControllerPose(*cand)):
                return cand  # type: ignore[return-value]
        return None

    def _near(self, pose: ControllerPose, reach: float = 150.0, turn: float = 10.0
              ) -> Optional[IntPose]:
        r = self.rng
        values = pose.as_tuple()
        moved = [values[i] + r.uniform(-reach, reach) for i in range(3)]
        moved += [values[i] + r.uniform(-turn, turn) for i in range(3, 6)]
        return self._round(moved)

    def next(self, current: Optional[ControllerPose]) -> Optional[MoveRequest]:
        """A candidate move (None: try again); its wire targets are not yet marked used."""
        r = self.rng.random()
        kind = MoveType.PTP if r < self.mix[0] or current is None else \
            MoveType.LIN if r < self.mix[0] + self.mix[1] else MoveType.CIRC
        if kind is MoveType.PTP:
            values = self._round(self.kin.fk_pose(self.kin.random_joints(self.rng)).as_tuple())
            values = values and self._unique(values)
            return MoveRequest(MoveType.PTP, values) if values else None
        assert current is not None
        end = self._near(current)
        end = end and self._unique(end)
        if not end:
            return None
        if kind is MoveType.LIN:
            return MoveRequest(MoveType.LIN, end)
        via = self._near(current)
        via = via and self._unique(via)
        if not via or via == end:
            return None
        return MoveRequest(MoveType.CIRC, end, via=via)

    def mark(self, keys: Sequence[Key]) -> None:
        for _kind, values in keys:
            self.used.add(values)


# ------------------------------------------------------------------------------------------ the run

def driver_params(config: SoakConfig, path: str) -> DriverParams:
    params = {"port": path, "baud": config.baud, "cycle_rate": config.cycle_rate,
              "protocol": config.protocol,
              "link_timeout": 0.5, "reconnect_period": 0.5, "watchdog_ms": 300,
              "accept_timeout": 1.0, "release_timeout": 1.0}
    params.update(config.driver_params)
    return DriverParams.from_dict(params)


def _count(counts: Dict[str, int], reason: str) -> None:
    """Count ``reason`` with its numbers masked, so that like reasons add up."""
    short = re.sub(r"[0-9]+(\.[0-9]+)?", "#", reason)[:110]
    counts[short] = counts.get(short, 0) + 1


def _confirm_default(protocol: str) -> str:
    """The two-telegram rule as the protocol's controller runs it by default, in words."""
    if protocols.get(protocol).confirm_records:
        return "on"
    return "off (%s: its records' integrity check)" % protocol


def _keys(job: MoveJob, protocol: str = "v1") -> Tuple[Key, ...]:
    """The wire targets of ``job`` as the controller's log names them. A stream's points (protocol
    ``streams``): joint targets (``joint_targets``, v2) in 0.001 deg, move type JOINT; Cartesian
    targets (v3) as the wire carries their pose (X Y Z 0.1 mm, Rx Ry Rz 0.01 deg), move type MOVEP.
    Otherwise (v1) the preview's handshake commands."""
    if job.points:
        if protocols.get(protocol).joint_targets:
            return tuple(("JOINT", joints_to_wire(p.joints)) for p in job.points)  # type: ignore[misc]
        return tuple(("MOVEP", pose_to_wire(p.pose)) for p in job.points)  # type: ignore[misc]
    return tuple((c.move_type.name, tuple(c.values)) for c in job.preview.commands)  # type: ignore[misc]


def run_soak(config: SoakConfig, kin: Optional[Kinematics] = None,
             progress: Optional[Callable[[str], None]] = None) -> SoakResult:
    """Run the soak described in the module docstring; returns the figures."""
    kin = kin or Kinematics.default()
    rng = random.Random(config.seed)
    result = SoakResult(config)
    own_dir = config.workdir is None
    workdir = tempfile.mkdtemp(prefix="vr_soak_") if own_dir else config.workdir
    path = os.path.join(workdir, "g2_soak_%d" % os.getpid())
    params = driver_params(config, path)
    line = FaultLine(config, random.Random(rng.getrandbits(64)))
    sim = VirtualController(pty_link=path, baud=config.baud, speed_factor=config.speed_factor,
                            loop_period=config.loop_period, kinematics=kin,
                            confirm_records=config.confirm_records, protocol=config.protocol).start()
    core = DriverCore(params, kinematics=kin, open_link=line.open_link)
    wire = protocols.get(config.protocol)

    rest: List[object] = [None, 0.0]        # the arm's pose at the last bus cycle, seen since

    def probe(status: DriverStatus) -> None:
        """Every bus cycle: the arm's exact TCP against the box; at rest, the driver's joints
        against the arm's (v1 and v3 report only a pose, the driver solves the joints: it must keep
        track of the configuration)."""
        arm = sim.program.arm
        # one read under the arm's lock: read one by one, a program loop may start the next move
        # between them (at x100 a joint turns tens of degrees in 10-20 ms), and a rest pose was
        # paired with the joints of the next move (seen as 30-53 deg "mismatches" under load)
        moving, pose, joints = arm.snapshot()
        excess = params.workspace.excess(pose)
        if excess > 1e-6:       # (not float noise on a target that lies on a bound)
            result.outside_samples += 1
            if excess > result.outside_max:
                result.outside_max, result.outside_pose = excess, pose
        if moving or rest[0] != pose:
            rest[:] = [pose, time.monotonic()]
            return
        if status.feedback_time is None or status.feedback_time < rest[1] or \
                status.joints is None or not status.joints_valid or status.pose is None:
            return              # (feedback that arrived while the arm was at rest already)
        if not wire.reports_joints:
            reported = sim.feedback         # the pose the controller reports, rounded as on the wire
            if reported is None or tuple(status.pose.as_tuple()) != tuple(reported.pose.as_tuple()):
                return          # (the driver has not seen this pose yet)
        off = max(abs(a - b) for a, b in zip(status.joints, joints))
        if off > math.radians(MISMATCH_DEG):
            result.mismatch_samples += 1
            result.mismatch_max = max(result.mismatch_max, math.degrees(off))

    recorder = StatusRecorder(handshake_ready=(lambda: True) if wire.streams
                              else (lambda: core.handshake.ready), probe=probe)
    core.add_listener(recorder)
    cutter = (Cutter(line, config, random.Random(rng.getrandbits(64)), recorder)
              if config.cut_every > 0 or config.cut_times else None)
    gen = TargetGenerator(kin, params, random.Random(rng.getrandbits(64)), config.mix)
    commanded: List[Commanded] = []
    started = time.monotonic()
    try:
        core.start()
        if cutter is not None:
            cutter.start()
        waiting_since: Optional[float] = None     # motion not possible since
        accepted_at = time.monotonic()             # the last submit taken (or the start)
        last_refusal = ""
        while len(commanded) < config.targets:
            status = core.status()
            now = time.monotonic()
            if not status.motion_possible or not status.joints_valid:
                if waiting_since is None:
                    waiting_since = now
                elif now - waiting_since > config.stall_timeout:
                    raise RuntimeError("no motion possible for %.0f s: %s"
                                       % (config.stall_timeout, status.why_no_motion()))
                recorder.wait_change(0.2)
                continue
            waiting_since = None
            if now - accepted_at > config.stall_timeout:
                raise RuntimeError("no target taken for %.0f s while motion was possible (arm at "
                                   "%s, joints %s deg); last refusal: %s"
                                   % (config.stall_timeout, status.pose,
                                      None if status.joints is None else
                                      ["%.2f" % math.degrees(j) for j in status.joints],
                                      last_refusal))
            request = gen.next(status.pose)
            if request is None:
                continue
            try:
                job = core.submit(request)
            except DriverError as exc:
                last_refusal = str(exc)
                _count(result.refusals, last_refusal)
                if "not possible" in last_refusal or "joint state" in last_refusal:
                    result.refused_not_possible += 1
                    recorder.wait_change(0.2)
                else:
                    result.refused_invalid += 1
                continue
            except VrDriverError as exc:
                last_refusal = str(exc)
                _count(result.refusals, last_refusal)
                result.refused_invalid += 1
                continue
            keys = _keys(job, config.protocol)
            gen.mark(keys)
            entry = Commanded(len(commanded), job.id, request.move_type.name, keys, time.monotonic())
            commanded.append(entry)
            entry.result = job.wait(config.job_timeout)
            entry.finished = accepted_at = time.monotonic()
            if entry.result is None:
                result.hung += 1
                core.cancel(job, "soak: no result within %.0f s" % config.job_timeout)
                job.wait(5.0)
            if progress and config.progress_every and len(commanded) % config.progress_every == 0:
                progress("%6d jobs, %.0f s, cuts %d, reconnects %d"
                         % (len(commanded), time.monotonic() - started,
                            len(cutter.cuts) if cutter else 0, core.status().counters.reconnects))
    except (RuntimeError, VrDriverError) as exc:
        result.complete = False
        result.error = str(exc)
    finally:
        if cutter is not None:
            cutter.stop_event.set()
            cutter.join(3.0)
            end = time.monotonic() + 5.0         # the last restore's reconnect, if still pending
            while any(c.reconnect is None or c.ready is None for c in cutter.cuts) \
                    and time.monotonic() < end:
                recorder.wait_change(0.2)
        # a last motion may still be running on the controller: let it end before reading the log
        sim.wait_until(lambda fb: fb.state.name in ("READY", "IDLE"), 5.0)
        time.sleep(max(0.1, 3.0 / config.cycle_rate))
        final = core.status()
        core.stop()
        sim.stop()
        if own_dir:
            shutil.rmtree(workdir, ignore_errors=True)
    result.duration = time.monotonic() - started
    result.cuts = list(cutter.cuts) if cutter is not None else []
    result.status_calls = recorder.calls
    result.status_gap_max = recorder.gap_max
    result.status_gap_at = recorder.gap_at
    result.link_counters = line.counters()
    result.driver_counters = dict(vars(final.counters))
    result.master_counters = dict(final.master_counters)
    _account(result, commanded, sim.log.entries())
    return result


def _account(result: SoakResult, commanded: List[Commanded], entries: List[LogEntry]) -> None:
    by_key: Dict[Key, List[LogEntry]] = collections.defaultdict(list)
    for e in entries:
        by_key[(e.move_type, tuple(e.target))].append(e)  # type: ignore[index]
    known = set()
    result.jobs = len(commanded)
    result.log_entries = len(entries)
    for cmd in commanded:
        res = cmd.result
        failed_reason = res.reason if res is not None and not res.success else ""
        if res is not None and not res.success:
            _count(result.reasons, failed_reason.split(";")[0])
        for key in cmd.keys:
            known.add(key)
            result.commanded += 1
            logged = by_key.get(key, [])
            done = [e for e in logged if e.outcome in (Outcome.EXECUTED, Outcome.VIA_STORED, Outcome.BLENDED)]
            if done:
                result.executed += 1
                if len(done) > 1:
                    result.duplicated += 1
                    result.extra_executions += len(done) - 1
                    result.duplicate_details.append(
                        "job %d %s %s executed %d times (seqs %s)"
                        % (cmd.job_id, key[0], key[1], len(done), [e.seq for e in done]))
                if failed_reason:
                    result.executed_but_failed += 1
                continue
            if failed_reason:
                refused = [e for e in logged if e.outcome is Outcome.REJECTED]
                if refused and not any(getattr(e, "aborted", False) for e in refused) \
                        and ("rejected" in failed_reason or "refused" in failed_reason):
                    result.rejected += 1
                else:
                    result.aborted += 1
                continue
            result.lost += 1
            result.lost_details.append(
                "job %d %s target %s: %s; log: %s"
                % (cmd.job_id, key[0], key[1],
                   "no result" if res is None else "reported success",
                   [(e.seq, e.outcome.value, e.reason) for e in logged] or "nothing"))
    for key, logged in by_key.items():
        if key not in known:
            result.unknown_entries += len(logged)
            result.unknown_details.append("%s %s: %s" % (key[0], key[1],
                                                         [(e.seq, e.outcome.value) for e in logged]))


# ---------------------------------------------------------------------------------------- the CLI

def _mix(text: str) -> Tuple[float, float, float]:
    parts = [float(p) for p in text.split(",")]
    if len(parts) != 3 or any(p < 0 for p in parts) or sum(parts) <= 0:
        raise argparse.ArgumentTypeError("--mix takes three non-negative weights PTP,LIN,CIRC")
    return parts[0], parts[1], parts[2]


def main(argv: Optional[Sequence[str]] = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--targets", type=int, default=1000, help="moves to submit (default 1000)")
    p.add_argument("--corrupt", type=float, default=0.02, help="byte corruption probability (default 0.02)")
    p.add_argument("--drop", type=float, default=0.0, help="byte drop probability (default 0)")
    p.add_argument("--delay", type=float, default=0.0, help="byte delay probability, receive side (default 0)")
    p.add_argument("--delay-s", type=float, default=0.01, help="delay of a delayed byte [s] (default 0.01)")
    p.add_argument("--parity", action="store_true", help="emulate the 8E1 parity check of a real port")
    p.add_argument("--no-confirm", action="store_true",
                   help="v1: the virtual controller acts on a record at its first telegram (no two-telegram "
                        "rule; v2 and v3 always do: their records carry an integrity check)")
    p.add_argument("--cut-every", type=float, default=20.0, metavar="SECONDS",
                   help="cut the line at random around every SECONDS s (default 20; 0: no cuts)")
    p.add_argument("--cut-min", type=float, default=0.2, help="shortest cut [s] (default 0.2)")
    p.add_argument("--cut-max", type=float, default=1.0, help="longest cut [s] (default 1.0)")
    p.add_argument("--seed", type=int, default=1, help="random seed (default 1)")
    p.add_argument("--mix", type=_mix, default=(0.5, 0.3, 0.2), help="PTP,LIN,CIRC weights (default 0.5,0.3,0.2)")
    p.add_argument("--speed-factor", type=float, default=100.0, help="virtual controller speed (default 100)")
    p.add_argument("--baud", type=int, default=187500, help="DP bit rate (default 187500)")
    p.add_argument("--cycle-rate", type=float, default=50.0, help="driver bus cycles per second (default 50)")
    p.add_argument("--job-timeout", type=float, default=60.0, help="a job without result after this is lost (default 60)")
    p.add_argument("--progress", type=int, default=500, metavar="N", help="progress line every N jobs (0: none)")
    p.add_argument("--log-file", help="write the driver's and controller's log (INFO) here")
    p.add_argument("--protocol", choices=protocols.names(), default=protocols.DEFAULT,
                   help="controller protocol of both ends (v2 / v3: moves streamed as joint / Cartesian "
                        "targets, each one accounted as a target; default %(default)s)")
    args = p.parse_args(argv)
    if args.targets < 1:
        p.error("--targets must be >= 1")
    for name in ("corrupt", "drop", "delay"):
        if not 0.0 <= getattr(args, name) <= 1.0:
            p.error("--%s must be a probability in [0, 1]" % name)
    if not 0.0 < args.cut_min <= args.cut_max:
        p.error("need 0 < --cut-min <= --cut-max")

    root = logging.getLogger()
    root.setLevel(logging.INFO if args.log_file else logging.CRITICAL)
    if args.log_file:
        handler = logging.FileHandler(args.log_file, mode="w")
        handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
        root.addHandler(handler)

    config = SoakConfig(targets=args.targets, corrupt=args.corrupt, drop=args.drop, delay=args.delay,
                        delay_s=args.delay_s, parity=args.parity,
                        confirm_records=False if args.no_confirm else None, cut_every=args.cut_every,
                        cut_min=args.cut_min, cut_max=args.cut_max, seed=args.seed, mix=args.mix,
                        speed_factor=args.speed_factor, baud=args.baud, cycle_rate=args.cycle_rate,
                        job_timeout=args.job_timeout, progress_every=args.progress,
                        protocol=args.protocol)
    result = run_soak(config, progress=lambda text: print(text, flush=True))
    for text in result.summary():
        print(text)
    print(result.final_line(), flush=True)
    ok = result.complete and result.duplicated == 0 and result.lost == 0 and \
        result.outside_samples == 0 and result.mismatch_samples == 0
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
