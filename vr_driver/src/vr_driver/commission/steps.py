"""The commissioning steps: each measures one or more assumptions of protocol v3 about the G2
(doc/controller_program.md §10.9) from the bus and says what follows. ROS-free.

Every step has a name (``--skip NAME``), says what it will do before the arm moves
(:attr:`Step.describe`), runs on a :class:`Context` (the bus, the model's kinematics, the sizes of
the moves) and returns :class:`Finding` rows -- assumption, expected, measured, consequence -- and
the values it measured (:attr:`Context.measured`, the YAML's keys). The steps, in their order:

``card``          Data_Exchange with the v3 configuration, the byte order, the program armed; the
                  controller's identity (no motion). The card's Data_Exchange status (§10.9) is listed
                  as not measurable, with why (:func:`data_exchange_finding`).
``check_word``    the controller's records pass the check word; the program ignores a command whose
                  check word fails and one whose seq copy differs (a target at the arm's own pose:
                  nothing moves even if it is taken).
``loop``          the heartbeat at rest (the loop's period and spread, :func:`analysis.loop_spread`:
                  "not resolved" where the watch cannot tell), then during a MOVE of joint 6: does the
                  loop keep running, or block until the move ends? (What a blocking loop hides, the
                  later steps list in :attr:`Context.not_measured`, never as values.)
``send_ahead``    a target one number ahead waits (the rule) or is refused (targets at the arm's pose).
``speed``         MOVEP's speed unit: three timed moves of one joint (+L, -2L, +L); the cruise speed
                  against the commanded one (from the move times when the loop blocks).
``lookahead``     a stream of points at smooth 5, then at smooth 0: does the arm blend through the
                  points (the interpreter reads ahead) or stop at each? The ring's size.
``configuration`` a pose with two solutions (joint 6 one turn apart), taken while the arm is on its
                  way: nearest the previous target's joints or the arm's?
``ramps``         per axis, a long move out and back, logged every cycle: the time from rest to full
                  speed (the acceleration) and the ramp's shape; the ramp time from every joint's
                  ramps with its error (:func:`analysis.ramp_times`).
``unreachable``   a pose out of reach: refused (code 4) or an alarm that halts the program (last:
                  a halted program needs the pendant).

Each moving step says how far it turns each joint (:meth:`Step.reach`); :func:`clear_space` is
what the start, the steps' words and doc/commissioning.md say. Moves are joint offsets from where
the arm stands (its joints solved from the reported pose with the driver's model), sent as the
Cartesian poses of those joints (the G2 solves them itself); the arm's joints during a move are
tracked from the reported poses, each record dated by its heartbeat.
"""
from __future__ import annotations

import logging
import math
import struct
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

from ..bus.worker import normal_scheduling
from ..errors import KinematicsError, PoseError
from ..kinematics.solver import stretched_elbow
from ..poses import ControllerPose
from ..protocol.common import ByteOrder, StatusBits
from ..protocol.v3 import (CartesianSlot, CommandV3, Control, FeedbackV3, RejectCode, StreamState, check_word,
                           next_seq, seq_after)
from . import analysis
from .bus import CommissionBus, CommissionError, Cycle, heartbeat_brackets, heartbeat_samples, new_loops

log = logging.getLogger("vr_driver.commission")

__all__ = ["Finding", "StepResult", "Sizes", "Context", "Step", "STEPS", "STEP_NAMES", "Reach", "clear_space",
           "clear_space_table", "clear_space_words"]

JOINTS = 6


@dataclass(frozen=True)
class Finding:
    """One row of the final table."""

    assumption: str
    expected: str
    measured: str
    consequence: str
    ok: Optional[bool] = None          # True: as assumed; False: differs; None: not measured

    def as_dict(self) -> Dict[str, Any]:
        return {"assumption": self.assumption, "expected": self.expected, "measured": self.measured,
                "consequence": self.consequence, "ok": self.ok}


@dataclass
class StepResult:
    name: str
    status: str = "done"               # done | skipped | failed
    findings: List[Finding] = field(default_factory=list)
    seconds: float = 0.0               # robot time the step took
    error: str = ""


@dataclass(frozen=True)
class Sizes:
    """How long and how far the steps measure (defaults: a real arm at the pendant's distance; the
    tests give smaller ones). Degrees, percent of the joint speed limits, seconds."""

    connect_timeout: float = 10.0
    heartbeat_time: float = 20.0       # at rest
    loop_move: float = 20.0            # joint 6, for the loop during a MOVE
    loop_percent: float = 20.0
    speed_joint: int = 1
    speed_move: float = 20.0           # L of +L, -2L, +L
    speed_percent: float = 20.0
    stream_points: int = 5
    stream_step: float = 10.0          # joint 1 per point (joint 2 zig-zags a third of it)
    stream_percent: float = 50.0
    stream_smooth: int = 5
    config_turn: float = 110.0         # joint 6: the first target this far, the second as far again
    config_percent: float = 20.0
    ramp_axes: Tuple[int, ...] = (1, 2, 3, 4, 5, 6)
    ramp_move: float = 60.0            # joints 1-4 (joints 5-6: twice this)
    ramp_move_max: float = 120.0       # a joint that reached no cruise moves again, up to this (5-6: twice)
    ramp_percent: float = 100.0
    hold_time: float = 0.3             # a record that must not be taken is held this long (and 10 loops)


class Context:
    """What the steps share: the bus, the kinematics, the sizes, what was measured so far, and the
    output (``say``: one line of text)."""

    def __init__(self, bus: CommissionBus, kin: Any, sizes: Sizes, say: Callable[[str], None]) -> None:
        self.bus = bus
        self.kin = kin
        self.sizes = sizes
        self.say = say
        self.measured: Dict[str, Any] = {}
        #: the controller facts a step could not measure: {key: why} (the YAML lists them under
        #: controller/not_measured, the reasons under commissioning; the driver keeps its assumption)
        self.not_measured: Dict[str, str] = {}
        self.identity: Dict[str, Any] = {}
        self.seq = 0                   # the last sequence number sent
        self.start_joints: Optional[Tuple[float, ...]] = None
        self.vmax = tuple(kin.limits.velocity)
        self.elbow = stretched_elbow(kin)

    # ------------------------------------------------------------------------- the program
    @property
    def order(self) -> ByteOrder:
        return ByteOrder.parse(self.bus.order)

    @property
    def feedback(self) -> FeedbackV3:
        fb = self.bus.feedback
        if fb is None:
            raise CommissionError("no record from the controller yet")
        return fb

    @property
    def loop_period(self) -> float:
        """The measured loop period (10 ms until the loop step measured it)."""
        return float(self.measured.get("loop_period") or 0.01)

    @property
    def loop_blocks(self) -> bool:
        return bool(self.measured.get("loop_blocks_during_move", False))

    def hold(self) -> float:
        """How long a record that must not be taken is held: the hold time, 10 loops, 10 cycles."""
        return max(self.sizes.hold_time, 10 * self.loop_period, 10 * self.bus.period)

    def idle(self, seconds: float = 0.0) -> List[Cycle]:
        self.bus.send(CommandV3().encode(self.order))
        return self.bus.run_for(seconds) if seconds > 0 else []

    def next_seq(self) -> int:
        """A new sequence number: after the program's accepted_seq and after every number this tool
        sent (a number not after accepted_seq would be ignored as a repeat, §10.4 rule 1)."""
        acc = self.feedback.accepted_seq
        self.seq = next_seq(self.seq if seq_after(self.seq, acc) else acc)
        return self.seq

    def slot(self, seq: int, pose: ControllerPose, percent: float, smooth: int = 0) -> CartesianSlot:
        return CartesianSlot.from_pose(seq, pose, max(1, min(1000, int(round(percent * 10)))), smooth)

    def wait_rest(self, timeout: float = 30.0) -> Cycle:
        """Until the arm stands (IDLE or WAITING, not in motion)."""
        return self.bus.run(lambda c: c.feedback is not None and _at_rest(c.feedback), timeout)

    # ------------------------------------------------------------------------- streams
    def stream(self, slots: Sequence[CartesianSlot], ahead: int = 1, timeout: float = 60.0) -> List[Cycle]:
        """Send the slots as one stream (START on the first), one record per cycle, ``ahead`` = 2:
        the next before the acknowledgement of the one before (§10.4 rule 7). Until the last is done
        and the arm stands; CommissionError on a refusal. The cycles of the stream."""
        seqs = [s.seq for s in slots]
        first = len(self.bus.log)
        state = {"sent": -1}
        old = (self.feedback.rejected_seq, self.feedback.reject_code)     # a refusal from before

        def record(c: Cycle) -> Optional[bytes]:
            fb = c.feedback or self.bus.feedback
            acc = fb.accepted_seq if fb is not None else 0
            i = seqs.index(acc) + 1 if acc in seqs else 0
            if i >= len(slots):
                return CommandV3().encode(self.order)
            if ahead > 1 and state["sent"] == i and i + 1 < len(slots):
                i += 1
            state["sent"] = i
            return CommandV3(Control.START if i == 0 else Control(0), slots[i]).encode(self.order)

        def done(c: Cycle) -> bool:
            fb = c.feedback
            if fb is None:
                return False
            if fb.rejected_seq in seqs and fb.reject_code is not RejectCode.NONE \
                    and (fb.rejected_seq, fb.reject_code) != old:
                raise CommissionError("target %d refused by the controller: %s (%s)" % (
                    fb.rejected_seq, fb.reject_code.name, slots[seqs.index(fb.rejected_seq)].describe()))
            return fb.done_seq == seqs[-1] and _at_rest(fb)

        self.bus.send(record(self.bus.log[-1]) or b"")
        self.bus.run(done, timeout, record)
        self.idle()
        return self.bus.log[first:]

    def move_to(self, joints: Sequence[float], percent: float, timeout: float = 60.0) -> List[Cycle]:
        """One MOVEP (smooth 0) to the pose of ``joints`` (the model's FK)."""
        seq = self.next_seq()
        return self.stream([self.slot(seq, self.kin.fk_pose(joints), percent)], timeout=timeout)

    def still_slot(self, seq: int) -> CartesianSlot:
        """A target at the pose the arm reports now (nothing moves if it runs)."""
        return CartesianSlot(seq, 1, 0, 100, tuple(self.feedback.tcp))

    # ------------------------------------------------------------------------- the arm's joints
    def current_joints(self, seed: Optional[Sequence[float]] = None) -> Tuple[float, ...]:
        try:
            return tuple(self.kin.ik_pose(self.feedback.pose, seed=seed))
        except (KinematicsError, PoseError) as exc:
            raise CommissionError("the reported pose %s has no solution in the driver's model: %s "
                                  "(calibrate the model, README \"Calibrating the model\")"
                                  % (self.feedback.pose, exc)) from None

    def while_cycling(self, fn: Callable[..., Any], *args: Any) -> Any:
        """``fn(*args)``, computed in a thread of its own while this thread keeps the bus cycling
        with the record it holds: the card's watchdog must never see the bus stand still for an
        analysis (the IK of every record of a move, in this thread, stalled the bus 160-280 ms at
        100 and 250 cycles/s and the card's 300 ms watchdog ended the link)."""
        out: Dict[str, Any] = {}

        def work() -> None:
            normal_scheduling()         # a thread inherits the bus thread's SCHED_FIFO (--rt-priority)
            try:
                out["value"] = fn(*args)
            except BaseException as exc:  # raised again below, in the step's thread
                out["error"] = exc
        worker = threading.Thread(target=work, name="commission-analysis", daemon=True)
        worker.start()
        self.bus.run(lambda c: not worker.is_alive(), timeout=300.0)
        worker.join()
        if "error" in out:
            raise out["error"]
        return out["value"]

    def track(self, cycles: Sequence[Cycle], seed: Sequence[float]) -> List[Tuple[float, Tuple[float, ...]]]:
        """(time, joints) for every new record of ``cycles``: dated by its heartbeat, the joints
        solved from its pose nearest the previous record's (continuous through the move). Computed
        while the bus keeps cycling (:meth:`while_cycling`)."""
        return self.while_cycling(self._track, list(cycles), tuple(seed))

    def _track(self, cycles: Sequence[Cycle], seed: Sequence[float]) -> List[Tuple[float, Tuple[float, ...]]]:
        brackets = heartbeat_brackets(cycles)
        dates = analysis.date_loops(brackets, stall=max(3.0 * self.loop_period, 3.0 * self.bus.period))
        out: List[Tuple[float, Tuple[float, ...]]] = []
        q = tuple(seed)
        k_of: Dict[int, int] = {id(c): k for c, k, _prev in new_loops(cycles)}
        for c in cycles:
            k = k_of.get(id(c), -1)
            if k < 0 or c.feedback is None:
                continue
            t = dates.get(k, c.request) if k > 0 else c.request
            try:
                q = tuple(self.kin.ik_pose(c.feedback.pose, seed=q))
            except (KinematicsError, PoseError):
                continue
            out.append((t, q))
        return out

    def offset(self, base: Sequence[float], joint: int, degrees: float) -> Tuple[float, ...]:
        q = list(base)
        q[joint - 1] += math.radians(degrees)
        return tuple(q)

    def fits(self, base: Sequence[float], joint: int, degrees: float) -> bool:
        """Whether ``joint`` (1-based) turned by ``degrees`` from ``base`` stays 2 deg inside its limits
        (and, joint_3, short of the stretched elbow: :meth:`room`)."""
        return abs(degrees) <= self.room(base, joint, 1.0 if degrees >= 0 else -1.0)

    #: [deg] a joint_3 move stops this short of the stretched elbow
    ELBOW_MARGIN = 5.0

    def room(self, base: Sequence[float], joint: int, sign: float) -> float:
        """[deg] how far ``joint`` (1-based) can turn from ``base`` in the direction ``sign`` and stay
        2 deg inside its limits (0 when it cannot); joint_3 also stays :attr:`ELBOW_MARGIN` short of the
        stretched elbow, where the two elbow branches of a pose meet and the joints worked out from the
        reported poses (:meth:`track`) could not follow the arm through."""
        q, margin = base[joint - 1], math.radians(2.0)
        far = (self.kin.limits.upper[joint - 1] - margin - q) if sign > 0 else (q - self.kin.limits.lower[joint - 1] - margin)
        if joint == 3 and self.elbow is not None:
            ahead = (self.elbow - q) * (1.0 if sign > 0 else -1.0)
            if ahead > 0.0:
                far = min(far, ahead - math.radians(self.ELBOW_MARGIN))
        return max(0.0, math.degrees(far))

    def direction(self, base: Sequence[float], joint: int, *reaches: float) -> float:
        """+1 or -1: the sign for which ``joint`` (1-based) turned by every one of ``reaches``
        (degrees, signed) times it stays within its limits, +1 first; CommissionError when neither."""
        for sign in (1.0, -1.0):
            if all(self.fits(base, joint, sign * r) for r in reaches):
                return sign
        lo, hi = self.kin.limits.lower[joint - 1], self.kin.limits.upper[joint - 1]
        raise CommissionError("joint_%d at %.1f deg has no room for %s deg within its limits (%.0f .. %.0f deg%s): "
                              "move the arm nearer the middle of its range, or give smaller moves"
                              % (joint, math.degrees(base[joint - 1]), " and ".join("%+.0f" % r for r in reaches),
                                 math.degrees(lo), math.degrees(hi),
                                 "" if joint != 3 or self.elbow is None else
                                 "; the stretched elbow at %.1f deg" % math.degrees(self.elbow)))


#: {joint (1-based): (degrees the way a step turns it first, degrees the other way)}
Reach = Dict[int, Tuple[float, float]]


def _at_rest(fb: FeedbackV3) -> bool:
    return fb.state in (StreamState.IDLE, StreamState.WAITING) and not (fb.status & StatusBits.IN_MOTION)


def _ms(seconds: Optional[float]) -> str:
    return "?" if seconds is None else "%.2f ms" % (seconds * 1e3)


# ------------------------------------------------------------------------------------ the steps

class Step:
    """A step: its ``name``, whether it moves the arm, what it will do (:meth:`describe`, said
    before it runs) and :meth:`run`."""

    name = ""
    moves = True
    title = ""

    def describe(self, ctx: Context) -> str:
        raise NotImplementedError

    def reach(self, sizes: Sizes) -> Reach:
        """How far [deg] this step may turn each joint from where the arm stands: {joint (1-based):
        (the way it turns first, the other way)} -- from the moves :meth:`run` makes (the clear space
        the user must give it: :func:`clear_space`)."""
        return {}

    def run(self, ctx: Context) -> List[Finding]:
        raise NotImplementedError


class CardStep(Step):
    name = "card"
    moves = False
    title = "the card's configuration, byte order and identity"

    def describe(self, ctx: Context) -> str:
        sc = ctx.bus.bus_config.slaves[0]
        return ("bring the card (station %d, ident 0x%04X) to Data_Exchange at %d bit/s with the v3 modules %s, "
                "read the program's records in either byte order, wait until the program is armed. No motion."
                % (sc.address, sc.ident, ctx.bus.bus_config.baud, sc.cfg.hex(" ")))

    def run(self, ctx: Context) -> List[Finding]:
        # the connection itself is made by the runner (it may switch the byte order): here the verdicts
        fb = ctx.feedback
        bus = ctx.bus
        sc = bus.bus_config.slaves[0]
        tried = ctx.measured.get("byte_order_tried", bus.order)
        found = bus.order
        findings = [
            Finding("card configuration", "Data_Exchange with modules %s (28 bytes in, 24 out)" % sc.cfg.hex(" "),
                    "Data_Exchange reached", "none", True),
            Finding("byte order (16-bit words)", "%s (first byte the low byte)" % "little",
                    "%s%s" % (found, "" if found == tried else " (the records failed the check word in %s)" % tried),
                    "none" if found == "little" else "byte_order: %s (set in the YAML)" % found, found == "little"),
        ]
        end = bus.clock() + max(2.0, 20 * ctx.loop_period)
        fb = bus.run(lambda c: c.feedback is not None and c.feedback.armed or bus.clock() >= end, 30.0).feedback or fb
        if not fb.armed:
            findings.append(Finding("arming (§10.4 rule 3)", "ARMED after the idle record", "not armed after %.1f s"
                                    % max(2.0, 20 * ctx.loop_period), "the program takes no target: check that it "
                                    "arms on an empty record (§10.7)", False))
            raise _Abort(findings, "the program does not arm: no target can be sent")
        findings.append(Finding("arming (§10.4 rule 3)", "ARMED after the idle record", "armed", "none", True))
        bad = [w for bit, w in ((StatusBits.ESTOP, "e-stop pressed"), (StatusBits.ERROR, "error set"))
               if fb.status & bit]
        if not fb.status & StatusBits.DRIVES_POWERED:
            bad.append("drives off")
        if bad:
            raise _Abort(findings, "the controller reports %s: clear it at the pendant and start again"
                         % ", ".join(bad))
        ctx.start_joints = ctx.current_joints()
        ctx.identity.update({
            "protocol": "v3", "version": 3, "station_address": sc.address, "ident": "0x%04X" % sc.ident,
            "chk_cfg": sc.cfg.hex(" "), "input_bytes": sc.input_len, "output_bytes": sc.output_len,
            "baud": bus.bus_config.baud, "port": bus.device, "byte_order": found,
            "status_bits": fb.status.describe(), "heartbeat_at_start": fb.heartbeat,
            "pose_at_start": [round(v, 2) for v in fb.pose.as_tuple()],
            "joints_at_start_deg": [round(math.degrees(q), 2) for q in ctx.start_joints],
        })
        diag = bus.supervisor.last_diag
        if diag:
            ctx.identity["diag"] = diag
        ctx.measured["byte_order"] = found
        findings.append(data_exchange_finding(bus.bus_config.baud, len(sc.cfg)))
        ctx.say("  the arm's joints as the driver's model solves the reported pose: %s deg -- compare them "
                "with the pendant's joint display (they must agree within a degree, else calibrate first)"
                % ", ".join("%.1f" % math.degrees(q) for q in ctx.start_joints))
        return findings


#: characters of the quickest reset a master makes of its card, back to Data_Exchange: Slave_Diag
#: (request 11, answer 11 + 6), Set_Prm (11 + 7, answer 1), Chk_Cfg (11 + the configuration's bytes,
#: answer 1), Slave_Diag again; SD2 telegrams with SAPs. Each request after a sync pause of 33 bits,
#: each answer after at least 11
RESET_CHARS = 11 + 17 + 18 + 1 + 11 + 1 + 11 + 17
RESET_PAUSE_BITS = 4 * (33 + 11)


def reset_time(baud: int, cfg_bytes: int) -> float:
    """[s] the quickest reset of the card the master can make at ``baud``: the card leaves
    Data_Exchange and is back in it with a new session."""
    return ((RESET_CHARS + cfg_bytes) * 11 + RESET_PAUSE_BITS) / float(baud)


def data_exchange_finding(baud: int, cfg_bytes: int) -> Finding:
    """The card's Data_Exchange status (§10.9: can the program read it?) -- not measurable from the
    bus, and why: a v3 program without it sees a reset in the card's safe image (all zero: no v3
    record) at its next loop; the two differ only for a reset over within one loop, and the quickest
    the master can make takes :func:`reset_time` (63 ms at 19.2 kbit/s, 10-20 ms loops)."""
    t = reset_time(baud, cfg_bytes)
    return Finding(
        "the card's Data_Exchange status read by the program (§10.9)", "readable: the program sees every reset "
        "of its card",
        "not measurable from the bus: a v3 program without it still sees a reset in the card's safe image (all "
        "zero, no v3 record) at its next loop, and disarms as with it -- the two differ only for a reset over "
        "within one program loop, and the quickest the master can make (Slave_Diag, Set_Prm, Chk_Cfg, "
        "Slave_Diag) takes %.1f ms at %d bit/s%s" % (
            t * 1e3, baud, ", longer than a loop of 10-20 ms: the bus cannot tell the two apart" if t >= 0.02 else
            ": within a slow loop, but this tool does not reset the card under a running program"),
        "none for v3 either way (exactly once across a reset holds: the program takes a target only after the "
        "master's idle record of the new session); v1, whose idle record is the safe image, rests on the "
        "master there -- check the program's card-status variable at the pendant (doc/controller_program.md "
        "§10.9)", None)


class _Abort(CommissionError):
    """A step found what makes the rest impossible: its findings so far, and why."""

    def __init__(self, findings: List[Finding], why: str) -> None:
        super().__init__(why)
        self.findings = findings


class CheckWordStep(Step):
    name = "check_word"
    moves = False
    title = "the check word, both ways"

    def describe(self, ctx: Context) -> str:
        return ("count the controller's records that fail the check word; send a target at the arm's own pose "
                "with a wrong check word, then one with a torn seq copy (each held %.1f s: the program must "
                "ignore both), then the good one (taken, nothing moves)." % ctx.hold())

    def run(self, ctx: Context) -> List[Finding]:
        bus = ctx.bus
        counters = bus.supervisor.counters
        bus.run_for(ctx.hold())
        good = sum(1 for c in bus.log if c.feedback is not None)
        findings = [Finding("check word, controller -> master", "every record passes in %s" % bus.order,
                            "%d records passed, %d refused" % (good, counters.protocol_errors),
                            "none" if counters.protocol_errors == 0 else
                            "records refused: a program that computes the word in another way (§10.3) or a noisy line",
                            counters.protocol_errors == 0)]
        ctx.wait_rest()
        before = ctx.feedback
        seq = ctx.next_seq()
        good_record = CommandV3(Control.START, ctx.still_slot(seq)).encode(ctx.order)
        corrupted = bytearray(good_record)
        corrupted[6] ^= 0x01                      # the speed word changed, the check word not
        torn = self._torn(good_record, seq, ctx.order)
        verdicts = []
        for what, raw in (("a wrong check word", bytes(corrupted)), ("a torn seq copy", torn)):
            bus.send(raw)
            cycles = bus.run_for(ctx.hold())
            taken = any(c.feedback is not None and c.feedback.accepted_seq == seq for c in cycles)
            refused = any(c.feedback is not None and c.feedback.rejected_seq == seq
                          and c.feedback.rejected_seq != before.rejected_seq for c in cycles)
            verdicts.append((what, taken, refused))
            if taken:
                ctx.wait_rest()
                seq = ctx.next_seq()
                good_record = CommandV3(Control.START, ctx.still_slot(seq)).encode(ctx.order)
                torn = self._torn(good_record, seq, ctx.order)
        bus.send(good_record)
        try:
            bus.run(lambda c: c.feedback is not None and c.feedback.done_seq == seq and _at_rest(c.feedback),
                    max(2.0, 50 * ctx.loop_period))
            good_taken = True
        except CommissionError:
            good_taken = False
        ctx.idle()
        for what, taken, refused in verdicts:
            findings.append(Finding(
                "check word, master -> controller: %s" % what, "ignored (neither taken nor refused)",
                "taken" if taken else ("refused" if refused else "ignored"),
                "none" if not taken and not refused else
                "the program acts on a corrupted record: a corrupted telegram could start a wrong move -- "
                "edit the program to check the word and the seq copy (§10.3, §10.7 GETCMD3)", not taken and not refused))
        findings.append(Finding("a good record is taken", "taken and done (no motion)",
                                "taken" if good_taken else "not taken within %.1f s" % max(2.0, 50 * ctx.loop_period),
                                "none" if good_taken else "the program does not take a START target: check §10.7",
                                good_taken))
        ctx.measured["check_word"] = all(not t and not r for _, t, r in verdicts) and good_taken
        return findings

    @staticmethod
    def _torn(record: bytes, seq: int, order: ByteOrder) -> bytes:
        """``record`` with another seq in its copy (bytes 21-22) and a check word that matches."""
        fmt = order.struct_prefix + "H"
        body = bytearray(record)
        struct.pack_into(fmt, body, 20, next_seq(seq))
        struct.pack_into(fmt, body, 22, check_word(bytes(body[:22]), order))
        return bytes(body)


class LoopStep(Step):
    name = "loop"
    title = "the program loop: period, steadiness, and during a MOVE"

    def reach(self, sizes: Sizes) -> Reach:
        return {6: (sizes.loop_move, 0.0)}

    def describe(self, ctx: Context) -> str:
        return ("watch the heartbeat for %.0f s at rest (up to %.0f s where the loop's spread needs it); then move "
                "joint_6 by %.0f deg at %.0f %% and back, watching it while the arm moves."
                % (ctx.sizes.heartbeat_time, self.LONGEST_WATCH * ctx.sizes.heartbeat_time, ctx.sizes.loop_move,
                   ctx.sizes.loop_percent))

    #: the longest the loop step watches the heartbeat at rest, in heartbeat times, where the spread
    #: needs a longer watch (a bus cycle longer than the loop: 19.2 kbit/s)
    LONGEST_WATCH = 4.0

    def run(self, ctx: Context) -> List[Finding]:
        watched = ctx.idle(ctx.sizes.heartbeat_time)
        rest = analysis.loop_timing(heartbeat_brackets(watched))
        if rest is None:
            raise _Abort([Finding("program loop", "the heartbeat counts every loop", "the heartbeat does not move",
                                  "the program is not running (or does not count): start it", False)],
                         "the heartbeat stands still")
        spread = ctx.while_cycling(analysis.loop_spread, heartbeat_samples(watched), ctx.bus.period)
        more = analysis.watch_more(spread, self.LONGEST_WATCH * ctx.sizes.heartbeat_time)
        if more > 0.0:
            ctx.say("  the loop's spread is not resolved in %.0f s at this bus rate: watching %.0f s more (nothing "
                    "moves)" % (spread.span, more))
            watched = watched + ctx.idle(more)
            rest = analysis.loop_timing(heartbeat_brackets(watched)) or rest
            spread = ctx.while_cycling(analysis.loop_spread, heartbeat_samples(watched), ctx.bus.period)
        ctx.measured["loop_period"] = rest.period
        if spread.resolved and spread.spread is not None:
            ctx.measured["loop_period_spread"] = spread.spread
        else:
            ctx.not_measured["loop_period_spread"] = "the spread of the loop's periods was not resolved: %s" % spread.why
        verdict = {"steady": "steady: spread %s" % spread.why, "irregular": "irregular: spread %s" % spread.why,
                   "not resolved": "spread not resolved: %s" % spread.why}[spread.verdict]
        findings = [Finding(
            "program loop at rest (heartbeat)", "steady",
            "period %s, longest gap %s (%d loops in %.1f s); %s" % (
                _ms(rest.period), _ms(rest.max_gap), rest.loops, rest.span, verdict),
            {"steady": "none", "irregular": "the driver dates each record by the heartbeat (record_clock), assuming a "
             "steady loop: its joint_states stamps may be off by the loops' wander (%s a period)" % _ms(spread.spread),
             "not resolved": "unknown: if the loop is irregular, the driver's joint_states stamps (dated by the "
             "heartbeat) may be off by its wander -- watch longer (--heartbeat-time) or on a faster bus"}[spread.verdict],
            {"steady": True, "irregular": False, "not resolved": None}[spread.verdict])]
        q0 = ctx.current_joints(ctx.start_joints)
        sign = ctx.direction(q0, 6, ctx.sizes.loop_move)
        moved = ctx.move_to(ctx.offset(q0, 6, sign * ctx.sizes.loop_move), ctx.sizes.loop_percent)
        ctx.move_to(q0, ctx.sizes.loop_percent)
        window = _motion_window(moved)
        if window is None:
            raise CommissionError("the move of joint_6 was not seen (no record showed it active): check the "
                                  "program's active_seq / done_seq (§10.7)")
        inside = moved[window[0]:window[1] + 1]
        duration = inside[-1].request - inside[0].request
        # loops the program ran while the arm moved, less the one that reports it done (records, at a
        # bus slower than the loop, each bring several: counting them took a running loop for blocked)
        beats = analysis.loops_seen(heartbeat_brackets(inside)) - 1
        expected = duration / rest.period
        blocks = beats < 0.2 * expected
        during = analysis.loop_timing(heartbeat_brackets(inside))
        gap = during.max_gap if during is not None else duration
        ctx.measured["loop_blocks_during_move"] = blocks
        if during is not None and not blocks:
            ctx.measured["loop_period_moving"] = during.period
        findings.append(Finding(
            "program loop during a MOVE", "keeps running (inputs read, outputs written while the arm moves)",
            "blocks: %d new heartbeats in the %.2f s move (%.0f expected)" % (max(0, beats), duration, expected)
            if blocks else
            ("runs: period %s, longest gap %s" % (_ms(during.period), _ms(gap)) if during is not None else
             "runs: %d new heartbeats in the %.2f s move (%.0f expected)" % (beats, duration, expected)),
            "v3 cannot stream with it: the feedback freezes while the arm moves, a target is taken only between "
            "two MOVEs and STOP is not seen; the driver refuses v3 at start. Use protocol v1 (ROSLINK, §5; "
            "protocol: v1, the card's v1 modules) or run the fieldbus part of the program in a parallel task"
            if blocks else "none", not blocks))
        return findings


class SendAheadStep(Step):
    name = "send_ahead"
    moves = False
    title = "a target sent ahead (§10.4 rule 7)"

    def describe(self, ctx: Context) -> str:
        return ("targets at the arm's own pose: one (taken), then the one after the next (held %.1f s: it must wait, "
                "neither taken nor refused), then the next and that one. Nothing moves." % ctx.hold())

    def run(self, ctx: Context) -> List[Finding]:
        bus = ctx.bus
        ctx.wait_rest()
        s1 = ctx.next_seq()
        ctx.stream([ctx.still_slot(s1)])
        s2 = next_seq(s1)
        s3 = next_seq(s2)
        ctx.seq = s3
        bus.send(CommandV3(Control(0), ctx.still_slot(s3)).encode(ctx.order))
        cycles = bus.run_for(ctx.hold())
        fbs = [c.feedback for c in cycles if c.feedback is not None]
        taken = any(fb.accepted_seq == s3 for fb in fbs)
        refused = any(fb.rejected_seq == s3 and fb.reject_code is RejectCode.OUT_OF_ORDER for fb in fbs)
        ctx.idle()
        if taken:
            verdict, ok = "taken out of order", False
            consequence = ("exactly once is broken: a target after a missed one runs -- edit the program "
                           "(§10.7: only accepted_seq + 1 is taken); until then controller/send_ahead: taken makes "
                           "the driver send one target per acknowledgement")
        elif refused:
            verdict, ok = "refused OUT_OF_ORDER", False
            consequence = ("a driver sending one target ahead of the acknowledgement would end every stream at "
                           "its second target: controller/send_ahead: refused makes it send one target per "
                           "acknowledgement (a new target every other bus cycle). Or edit the program (§10.7: "
                           "IF W(1) = LI001 + 2 THEN GOTO *RUN)")
        else:
            verdict, ok, consequence = "waits (neither taken nor refused)", True, "none"
        ctx.measured["send_ahead"] = {True: "accepted"}.get(ok, "taken" if taken else "refused")
        if not taken:
            ctx.wait_rest()
            ctx.stream([ctx.still_slot(s2), ctx.still_slot(s3)])
        return [Finding("a target sent ahead (accepted_seq + 2)", "waits", verdict, consequence, ok)]


class SpeedStep(Step):
    name = "speed"
    title = "MOVEP's speed unit"

    def reach(self, sizes: Sizes) -> Reach:
        return {sizes.speed_joint: (sizes.speed_move, sizes.speed_move)}        # +L, -2L, +L

    def describe(self, ctx: Context) -> str:
        s = ctx.sizes
        return ("joint_%d: three MOVEPs at speed %d (%.0f %% of its limit, %.0f deg/s as assumed): +%.0f deg, "
                "-%.0f deg, +%.0f deg (back where it started), each timed (twice where the loop blocks during a MOVE)."
                % (s.speed_joint, int(round(s.speed_percent * 10)), s.speed_percent,
                   math.degrees(ctx.vmax[s.speed_joint - 1]) * s.speed_percent / 100.0,
                   s.speed_move, 2 * s.speed_move, s.speed_move))

    def run(self, ctx: Context) -> List[Finding]:
        s = ctx.sizes
        j = s.speed_joint
        q0 = ctx.current_joints(ctx.start_joints)
        sign = ctx.direction(q0, j, s.speed_move, -s.speed_move)
        # a loop that blocks during a MOVE is timed by its moves alone: two rounds, which must agree
        legs = [sign * s.speed_move, -2.0 * sign * s.speed_move, sign * s.speed_move] * (2 if ctx.loop_blocks else 1)
        commanded = s.speed_percent / 100.0 * ctx.vmax[j - 1]
        q = q0
        scales, times = [], []
        for leg in legs:
            target = ctx.offset(q, j, leg)
            cycles = ctx.move_to(target, s.speed_percent)
            times.append(_move_time(cycles, ctx.bus.period))
            if not ctx.loop_blocks:
                track = ctx.track(cycles, q)
                samples = [(t, qq[j - 1]) for t, qq in track]
                fit = analysis.fit_move(samples, ctx.loop_period)
                cr = analysis.cruise(samples) if fit is None else None
                speed = fit.speed if fit is not None else (cr.speed if cr is not None else None)
                if speed is not None:
                    scales.append(abs(speed) / commanded)
            q = ctx.current_joints(target)
        if len(scales) >= 2:
            scale = sum(scales) / len(scales)
            how = "cruise speed of %d moves (%s)" % (len(scales), ", ".join("%.3f" % x for x in scales))
        elif None not in times:
            spans = [t for t, _ in times]
            d, why = _one_move_at_speed(times)
            if d is None:
                ctx.not_measured["speed_scale"] = why
                return [Finding("MOVEP speed unit", "0.1 % of the joint speed limit", "not measured (%s)" % why,
                                "run it again on a quieter machine; until then the driver keeps speed_scale 1", None)]
            scale = math.radians(s.speed_move) / d / commanded
            how = "move times %s s (the ramps cancel)" % ", ".join("%.3f" % t for t in spans)
        else:
            return [Finding("MOVEP speed unit", "0.1 % of the joint speed limit", "not measured (no cruise, no times)",
                            "give a longer --speed-move", None)]
        ok = abs(scale - 1.0) <= 0.02
        ctx.measured["speed_scale"] = round(scale, 4)
        return [Finding("MOVEP speed unit", "speed 1000 = the joint speed limit (0.1 % units)",
                        "x %.3f of the assumed speed (%s)" % (scale, how),
                        "none" if ok else "the arm runs %.0f %% of the commanded speed: controller/speed_scale: %.3f "
                        "(the driver sends each stream speed / %.3f; not told, a stream runs up to %.2f times the planned "
                        "time; the planner's max_velocity is scaled in joint_limits.yaml where below 1)"
                        % (100 * scale, scale, scale, 1.0 / scale), ok)]


#: the speed unit from move times is given only where late bus cycles may have moved it by less than
#: this share (the verdict's own tolerance). Dated by request times alone, a cycle late at a move's
#: end lengthens that move by its lateness: beside the suite's real-time tests the tool's 250 Hz bus
#: came 20-95 ms late at times, and one fresh-clone run read the loop-blocking G2's speed 7 % slow
#: (x 0.929: its move of 2 L some 30 ms long)
SPEED_SURE = 0.02


def _motion_window(cycles: Sequence[Cycle]) -> Optional[Tuple[int, int]]:
    """(index of the first record that shows a target active, index of the first that then shows it
    done with the arm at rest) within ``cycles``; None if no target was seen active."""
    seq = first = None
    for i, c in enumerate(cycles):
        fb = c.feedback
        if fb is None:
            continue
        if seq is None and fb.active_seq:
            seq, first = fb.active_seq, i
        if seq is not None and fb.done_seq == seq and _at_rest(fb):
            return first, i
    return None


def _one_move_at_speed(times: Sequence[Tuple[float, float]]) -> Tuple[Optional[float], str]:
    """The time of one L at speed from rounds of three moves +L, -2L, +L (``times``: each move's
    (time, how much late bus cycles may have moved it), :func:`_move_time`): per round the 2L move
    less the mean of the two L moves (the ramps cancel). A round the bus's lateness leaves unsure by
    more than SPEED_SURE is not used; two rounds used must agree within SPEED_SURE (a late answer of
    the controller lengthens a move too, and no bus time shows it: one fresh-clone run read x 1.094
    for x 1 with every bus cycle on time). (the time, "") or (None, why not, in words)."""
    spans = ", ".join("%.3f" % t for t, _ in times)
    sure: List[float] = []
    unsure: Optional[float] = None      # [s] the lateness of a round that was not used
    for r in range(0, len(times) - 2, 3):
        (a, la), (b, lb), (c, lc) = times[r:r + 3]
        d, late = b - (a + c) / 2.0, lb + (la + lc) / 2.0
        if d > 0 and late <= SPEED_SURE * d:
            sure.append(d)
        elif d > 0:
            unsure = late
    if not sure:
        if unsure is not None:
            return None, ("move times %s s, unsure by up to %.0f ms: a bus cycle came late at a move's start "
                          "or end (the tool's bus did not get the CPU)" % (spans, 1e3 * unsure))
        return None, "move times %s s: the 2L move no longer than the L moves" % spans
    if max(sure) - min(sure) > SPEED_SURE * min(sure):
        return None, ("move times %s s: its rounds gave %s s for one L at speed, more than %.0f %% apart (a move "
                      "answered late)" % (spans, " and ".join("%.3f" % d for d in sure), 100 * SPEED_SURE))
    return sum(sure) / len(sure), ""


def _bracket(cycles: Sequence[Cycle], k: int) -> Tuple[float, float]:
    """(start, end) of the time within which the record first seen in cycle ``k`` was written: after
    the request of the cycle before it that brought a record (which did not show it yet), by the
    request of cycle ``k``."""
    j = k - 1
    while j >= 0 and cycles[j].feedback is None:
        j -= 1
    return (cycles[j].request if j >= 0 else cycles[k].request), cycles[k].request


def _move_time(cycles: Sequence[Cycle], period: float) -> Optional[Tuple[float, float]]:
    """(the time from the target seen active to it seen done at rest, how much late bus cycles may
    have moved it): each event dated at the middle of its bracket (:func:`_bracket`), which on a
    bus cycling every ``period`` is as the request times gave it; a bracket longer than ``period`` (a
    cycle late) leaves its event unsure by half its excess. None: no motion seen."""
    window = _motion_window(cycles)
    if window is None:
        return None
    (a0, a1), (b0, b1) = _bracket(cycles, window[0]), _bracket(cycles, window[1])
    late = 0.5 * (max(0.0, a1 - a0 - period) + max(0.0, b1 - b0 - period))
    return 0.5 * (b0 + b1) - 0.5 * (a0 + a1), late


#: a point is a stop where the arm's steady speed (analysis.steady_speeds) near it falls below this
#: share of its cruise: in a recorded run the exact stops dipped to 0.19-0.35 of it, the blends through
#: the same points at the same speed kept 0.86-1.0
STOP_SPEED = 0.5


class LookAheadStep(Step):
    name = "lookahead"
    title = "the interpreter look-ahead and blending"

    def reach(self, sizes: Sizes) -> Reach:
        return {1: (sizes.stream_points * sizes.stream_step, 0.0), 2: (sizes.stream_step / 3.0, 0.0)}

    def describe(self, ctx: Context) -> str:
        s = ctx.sizes
        return ("a stream of %d points, joint_1 +%.0f deg each (joint_2 zig-zags %.1f deg: a corner at every point) at "
                "%.0f %%, smooth %d; back; the same at smooth 0; back." % (
                    s.stream_points, s.stream_step, s.stream_step / 3.0, s.stream_percent, s.stream_smooth))

    def run(self, ctx: Context) -> List[Finding]:
        s = ctx.sizes
        q0 = ctx.current_joints(ctx.start_joints)
        sign = ctx.direction(q0, 1, s.stream_points * s.stream_step)
        results = {}
        ring = 0
        for smooth in (s.stream_smooth, s.stream_smooth, 0):
            if smooth in results and _verdict(results[smooth])[0] is not None:
                continue                           # a second smooth stream only if the first was unclear
            pts = []
            for i in range(1, s.stream_points + 1):
                q = list(ctx.offset(q0, 1, sign * s.stream_step * i))
                q[1] += math.radians(s.stream_step / 3.0) * (1 if i % 2 else 0)
                pts.append(tuple(q))
            seqs = []
            slots = []
            for i, q in enumerate(pts):
                seq = ctx.next_seq()
                seqs.append(seq)
                slots.append(ctx.slot(seq, ctx.kin.fk_pose(q), s.stream_percent, smooth if i < len(pts) - 1 else 0))
            ahead = 2 if ctx.measured.get("send_ahead", "accepted") == "accepted" else 1
            cycles = ctx.stream(slots, ahead=ahead)
            for c in cycles:
                if c.feedback is not None:
                    ring = max(ring, (c.feedback.accepted_seq - c.feedback.done_seq) % 65535)
            results[smooth] = self._stops(ctx, cycles, q0, pts, seqs)
            ctx.move_to(q0, s.stream_percent)
        blended, blended_words = _verdict(results[s.stream_smooth])
        exact, exact_words = _verdict(results[0])
        findings = []
        hidden = ("the program loop blocks during a MOVE: each MOVE ends before the next record is read, so the "
                  "bus shows neither the interpreter's look-ahead nor the ring (a program whose fieldbus part runs "
                  "in a parallel task may have both -- commission again after that change)")
        if ctx.loop_blocks:
            ctx.not_measured["interpreter_lookahead"] = hidden
            ctx.not_measured["ring_size"] = hidden
            lookahead = None
            measured = "not measured: each point a stop under this program (the loop blocks during a MOVE)"
        elif blended is None:
            lookahead = None
            ctx.not_measured["interpreter_lookahead"] = "unclear at smooth %d: %s" % (s.stream_smooth, blended_words)
            measured = "unclear at smooth %d: %s" % (s.stream_smooth, blended_words)
        else:
            lookahead = 0 if blended else 1
            measured = "%s at smooth %d" % (blended_words, s.stream_smooth)
        if lookahead is not None:
            ctx.measured["interpreter_lookahead"] = lookahead
        if not ctx.loop_blocks and ring >= 1:
            ctx.measured["ring_size"] = ring
        consequence = {0: "no blending: v3 runs a path as a string of stops (the smooth level is lost: no "
                          "look-ahead, or the input read between two MOVEPs ends the blend). Streams take longer "
                          "by a ramp at every point; stream_smooth: 0 (the driver then times each point as a stop)",
                       1: "none (at least 1: the bus cannot tell 1 from more while the program's ring feeds it)"}
        if ctx.loop_blocks:
            why = ("none under protocol v1 (one MOVE at a time); written as not measured (controller/not_measured): "
                   "the driver keeps its assumption and says so, and a v3 program must be commissioned again")
        else:
            why = consequence.get(lookahead, "unclear: run the step again, watch the arm")
        findings.append(Finding("interpreter look-ahead (blending through a point)", "reads at least one MOVE ahead",
                                measured + ("" if lookahead is None else ": look-ahead %s" %
                                            ("0" if lookahead == 0 else ">= 1")),
                                why, None if lookahead is None else lookahead >= 1))
        if not ctx.loop_blocks:
            findings.append(Finding("smooth 0 (an exact stop)", "stops at every point", exact_words,
                                    "none" if exact else "unclear: run the step again, watch the arm" if exact is None
                                    else "the program does not pass the smooth level to MOVEP: check §10.7", exact))
            findings.append(Finding("the program's ring (§10.4 rule 2)", "4 positions", "%d targets taken ahead of "
                                    "the arm at most" % ring, "none" if ring >= 2 else "fewer than two: the stream "
                                    "starves between points", ring >= 2))
        else:
            findings.append(Finding("the program's ring (§10.4 rule 2)", "4 positions", "not measured: the loop "
                                    "blocks during a MOVE (one target at a time)", "as for the look-ahead", None))
        return findings

    def _stops(self, ctx: Context, cycles: Sequence[Cycle], q0: Sequence[float], pts: Sequence[Sequence[float]],
               seqs: Sequence[int]) -> Optional[List[Optional[bool]]]:
        """For each inner point: did joint_1 (nearly) stop there (True), blend through it (False), or
        was the next target not yet taken half a segment before it (None: the master was late, the
        arm had nothing to blend into)? None when the records are too sparse."""
        if ctx.loop_blocks:
            return None
        track = ctx.track(cycles, q0)
        samples = [(t, q[0]) for t, q in track]
        speeds = [v for _, v in analysis.steady_speeds(samples)]
        if len(speeds) < 4 * len(pts):
            return None
        cruise = analysis.top_speed(speeds)
        seg = math.radians(ctx.sizes.stream_step) / (ctx.sizes.stream_percent / 100.0 * ctx.vmax[0])
        window = max(0.35 * seg, 1.5 * ctx.loop_period)
        inner = [p[0] for p in pts[:-1]]
        lows = analysis.min_speed_near(samples, inner, window)
        passing = analysis.passing_times(samples, inner)
        out: List[Optional[bool]] = []
        for k, (low, at) in enumerate(zip(lows, passing)):
            taken = next((c.arrival or c.time for c in cycles if c.feedback is not None
                          and (c.feedback.accepted_seq == seqs[k + 1] or seq_after(c.feedback.accepted_seq, seqs[k + 1]))),
                         None)
            if low is None or at is None or taken is None or taken > at - 0.5 * seg:
                out.append(None)
            else:
                out.append(low < STOP_SPEED * cruise)
        return out


def _verdict(stops: Optional[List[Optional[bool]]]) -> Tuple[Optional[bool], str]:
    """(True: a stop at every point, False: at none, None: unclear), in words."""
    if stops is None:
        return None, "too few records during the stream"
    known = [x for x in stops if x is not None]
    late = len(stops) - len(known)
    words = "stops at %d of %d inner points%s" % (sum(known), len(known),
                                                  " (%d left out: the next target came late)" % late if late else "")
    if len(known) < 2 or 0 < sum(known) < len(known):
        return None, words
    return bool(known[0]), words


class ConfigurationStep(Step):
    name = "configuration"
    title = "the configuration rule (a pose with two solutions)"

    def reach(self, sizes: Sizes) -> Reach:
        # B lies 2 x turn one way; nearest the arm's joints the G2 runs it one turn back, 360 - 2 x turn
        # the other way (both joints of the same pose)
        return {6: (2.0 * sizes.config_turn, max(0.0, 360.0 - 2.0 * sizes.config_turn))}

    def describe(self, ctx: Context) -> str:
        s = ctx.sizes
        ahead, back = self.reach(s)[6]
        return ("joint_6 turns %.0f deg (target A, at %.0f %%); the next target B, sent while the arm is on its way, "
                "is %.0f deg further: reachable also one turn the other way. Nearest A's joints the arm goes on %.0f "
                "deg, to %.0f deg from where it stands; nearest its joints at the time it turns back %.0f deg, to %.0f "
                "deg the other side. Then back in steps of 90 deg. Keep cables and tools clear for joint_6 %.0f deg "
                "one way and %.0f deg the other."
                % (s.config_turn, s.config_percent, s.config_turn, s.config_turn, ahead, s.config_turn + back, back,
                   ahead, back))

    def run(self, ctx: Context) -> List[Finding]:
        s = ctx.sizes
        q0 = ctx.current_joints(ctx.start_joints)
        if not 90.0 < s.config_turn < 180.0:
            raise CommissionError("--config-turn must be between 90 and 180 deg (B = 2 x turn lies beyond 180 deg)")
        sign = ctx.direction(q0, 6, 2 * s.config_turn, 2 * s.config_turn - 360.0)
        qa = ctx.offset(q0, 6, sign * s.config_turn)
        qb = ctx.offset(q0, 6, sign * 2 * s.config_turn)
        qb_other = ctx.offset(q0, 6, sign * (2 * s.config_turn - 360.0))
        sa = ctx.next_seq()
        sb = ctx.next_seq()
        slots = [ctx.slot(sa, ctx.kin.fk_pose(qa), s.config_percent),
                 ctx.slot(sb, ctx.kin.fk_pose(qb), s.config_percent)]
        cycles = ctx.stream(slots, ahead=1)
        end6 = ctx.track(cycles, q0)[-1][1][5] if not ctx.loop_blocks else None
        j6 = math.degrees
        findings = []
        if ctx.loop_blocks or end6 is None:
            ctx.not_measured["configuration"] = ("the loop blocks during a MOVE: each target is taken with the arm at "
                                                 "the previous one, where both rules agree")
            findings.append(Finding("configuration of a Cartesian target", "nearest the previous target's joints",
                                    "not told apart: the loop blocks, each target is taken with the arm at the "
                                    "previous one (where both rules agree)", "none while targets are taken at rest",
                                    None))
            rest6 = ctx.current_joints(qb)[5]
        else:
            d_prev, d_cur = abs(end6 - qb[5]), abs(end6 - qb_other[5])
            rule = "previous_target" if d_prev < d_cur else "current_joints"
            if min(d_prev, d_cur) > math.radians(5.0):
                rule = "unknown"
            ctx.measured["configuration"] = rule if rule != "unknown" else None
            findings.append(Finding(
                "configuration of a Cartesian target", "nearest the previous target's joints (previous_target)",
                "%s (joint_6 ended at %.1f deg; %.1f nearest A, %.1f nearest the arm)" % (
                    rule, j6(end6), j6(qb[5]), j6(qb_other[5])),
                "none" if rule == "previous_target" else "the driver checks every stream point and tracks the "
                "joints assuming previous_target: a point taken while the arm is on its way may run another "
                "configuration than the one checked -- controller/configuration: %s (information: the driver "
                "says so at connect; keep stream points clear of configuration changes)" % rule,
                rule == "previous_target"))
            rest6 = end6
        # back in steps of at most 90 deg, where both rules agree
        here = list(ctx.current_joints(qb))
        here[5] = rest6
        while abs(here[5] - q0[5]) > 1e-6:
            step = max(-math.pi / 2, min(math.pi / 2, q0[5] - here[5]))
            here[5] += step
            ctx.move_to(tuple(here), s.config_percent)
        return findings


class RampStep(Step):
    name = "ramps"
    title = "per-axis acceleration and ramp shape"

    def reach(self, sizes: Sizes) -> Reach:
        # out and back; a joint that reaches no cruise moves again, up to ramp_move_max (5-6: twice)
        return {axis: (sizes.ramp_move_max * (2.0 if axis >= 5 else 1.0), 0.0) for axis in sizes.ramp_axes}

    def describe(self, ctx: Context) -> str:
        s = ctx.sizes
        return ("each of joints %s in turn: +%.0f deg (joints 5-6: %.0f) at %.0f %% and back, every record logged; "
                "the speed ramp fitted at each start and stop. A joint that reaches no cruise speed moves again, "
                "further (up to %.0f deg, joints 5-6: %.0f, within its limits) or slower." % (
                    ", ".join(str(a) for a in s.ramp_axes), s.ramp_move, 2 * s.ramp_move, s.ramp_percent,
                    s.ramp_move_max, 2 * s.ramp_move_max))

    def run(self, ctx: Context) -> List[Finding]:
        s = ctx.sizes
        if ctx.loop_blocks:
            for key in ("accelerations", "ramp_time", "ramp_shape"):
                ctx.not_measured[key] = "the loop blocks during a MOVE: no record while the arm moves"
            return [Finding("per-axis acceleration", "model: full speed in 0.1 s", "not measured: the loop blocks "
                            "during a MOVE (no record while the arm moves)", "keep the model's accelerations", None)]
        q0 = ctx.current_joints(ctx.start_joints)
        model = tuple(ctx.kin.limits.acceleration)
        measured: Dict[int, Tuple[float, List[analysis.RampFit]]] = {}     # axis: cruise speed, its ramps
        every_dt: List[float] = []                                       # [s] between records, every move
        findings = []
        for axis in s.ramp_axes:
            double = 2.0 if axis >= 5 else 1.0
            move, percent = s.ramp_move * double, s.ramp_percent
            sign = ctx.direction(q0, axis, move)
            fits: List[Tuple[float, analysis.RampFit]] = []        # (cruise speed, ramp)
            q = q0
            resized = False
            for attempt in range(3):
                peak, record_dt = 0.0, []
                for leg in (sign * move, -sign * move):
                    target = ctx.offset(q, axis, leg)
                    cycles = ctx.move_to(target, percent)
                    track = ctx.track(cycles, q)
                    samples = [(t, qq[axis - 1]) for t, qq in track]
                    fit = ctx.while_cycling(analysis.fit_move, samples, ctx.loop_period)
                    log.debug("joint_%d %+.0f deg at %.0f %%: %s", axis, leg, percent, fit)
                    if fit is not None:
                        fits.extend((abs(fit.speed), f) for f in (fit.ramp_in, fit.ramp_out))
                    peak = max([peak] + [v for _, v in analysis.steady_speeds(samples)])
                    record_dt.extend(b[0] - a[0] for a, b in zip(samples, samples[1:]))
                    every_dt.extend(b[0] - a[0] for a, b in zip(samples, samples[1:]))
                    q = ctx.current_joints(target)
                if not fits:
                    # no cruise: once, a move sized from this one's peak (module analysis.cruise_move)
                    bigger = None if resized else self._reaching(ctx, q, axis, move, percent, peak, record_dt,
                                                                 s.ramp_move_max * double)
                    if bigger is None:
                        break
                    sign, move, percent = bigger
                    resized = True
                    continue
                # four ramps that agree within 10 %: done; else once more (a record dated late on a
                # loaded machine bends a ramp), and the median of all -- where the ramps are resolved,
                # ten records and more each. Where they are not (at 20 cycles/s a 0.4 s ramp is 8
                # records) the scatter is the records' dating, which the figures carry as their error:
                # moving again for it took the step from 61 to 87 s, for nothing. Fewer ramps (a fit
                # failed): once more
                each = [v / f.duration for v, f in fits]
                spacing = sorted(record_dt)[len(record_dt) // 2] if record_dt else 0.0
                resolved = spacing <= 0.1 * sorted(f.duration for _, f in fits)[len(fits) // 2]
                if len(each) >= 4 and (not resolved or max(each) - min(each) <= 0.1 * sorted(each)[len(each) // 2]):
                    break
            if not fits:
                findings.append(Finding("joint_%d acceleration" % axis, "%.1f rad/s^2 (model)" % model[axis - 1],
                                        "not measured: no cruise reached in %.0f deg at %.0f %%" % (move, percent),
                                        "give a longer --ramp-move-max, or move the arm where joint_%d has more room"
                                        % axis, None))
                continue
            v = sorted(v for v, _ in fits)[len(fits) // 2]
            measured[axis] = (v, [f for _, f in fits])
        if not measured:
            return findings
        # the shape from every ramp of the run together (one ramp's evidence is weak at a few records
        # per ramp), then each axis's acceleration from its ramps' durations in that shape
        evidence = sum(f.s_curve_evidence for _, ramps in measured.values() for f in ramps)
        shape = "s_curve" if evidence > 0 else "linear"
        n = sum(len(ramps) for _, ramps in measured.values())
        ramps_of = {axis: (v, [f.duration_as(shape) for f in ramps]) for axis, (v, ramps) in measured.items()}
        fit = analysis.ramp_times(ramps_of, {axis: ctx.vmax[axis - 1] for axis in measured},
                                  spacing=sorted(every_dt)[len(every_dt) // 2] if every_dt else 0.0)
        accelerations = {}
        for axis in sorted(measured):
            a, da = fit.accelerations[axis]
            accelerations[axis] = a
            t_axis, dt_axis = fit.per_axis[axis]
            ok = abs(a - model[axis - 1]) <= max(0.1 * model[axis - 1], 2.0 * da)
            findings.append(Finding(
                "joint_%d acceleration" % axis, "%.1f rad/s^2 (model: full speed in %.2f s)" % (
                    model[axis - 1], ctx.vmax[axis - 1] / model[axis - 1]),
                "%.1f +- %.1f rad/s^2 (%s; this joint's own %d ramps: full speed in %.3f +- %.3f s)" % (
                    a, da, "the ramp time all joints share" if fit.shared else "its own ramps",
                    len(ramps_of[axis][1]), t_axis, dt_axis),
                "none" if ok else "the plan action's max_acceleration (joint_limits.yaml, planning_limits) takes "
                "the measured value", ok))
        ctx.measured["accelerations"] = {axis: round(a, 3) for axis, a in accelerations.items()}
        ctx.measured["ramp_time"] = round(fit.ramp_time, 4)
        ctx.measured["ramp_shape"] = shape
        findings.append(Finding(
            "ramp time (rest to full speed)", "%.2f s (the model's slowest joint)" % max(
                v / a for v, a in zip(ctx.vmax, model)),
            "%.3f +- %.3f s, %s" % (fit.ramp_time, fit.uncertainty, fit.words),
            "none" if fit.shared else "the joints ramp in times of their own: the driver counts the slowest joint's "
            "(ramp_time), the planner each joint's (joint_limits.yaml)",
            fit.shared and abs(fit.ramp_time - max(v / a for v, a in zip(ctx.vmax, model)))
            <= max(0.1 * fit.ramp_time, 2.0 * fit.uncertainty)))
        findings.append(Finding("ramp shape", "linear (constant acceleration)", "%s (%d ramps, evidence %+.1f)" % (
            shape.replace("_", "-"), n, evidence),
            "none" if shape == "linear" else "S-shaped: the peak acceleration is 1.5 times the mean the planner "
            "is given (the ramp's time and distance are the linear one's)", shape == "linear"))
        return findings

    #: [s] the cruise a resized move holds, at least: the cruise's fit needs about six records at the
    #: bus's rate, the ramps' fits some on either side
    CRUISE_RECORDS = 12
    CRUISE_TIME = 0.3

    def _reaching(self, ctx: Context, q: Sequence[float], axis: int, move: float, percent: float, peak: float,
                  record_dt: Sequence[float], longest: float) -> Optional[Tuple[float, float, float]]:
        """(sign, degrees, percent) of a move of ``axis`` that reaches a cruise where ``move`` at
        ``percent`` (which peaked at ``peak`` rad/s) did not: longer, within ``longest`` and the
        joint's room, or else slower; said before it runs. None (said) when none fits."""
        dt = sorted(record_dt)[len(record_dt) // 2] if record_dt else 0.05
        scale = ctx.measured.get("speed_scale") or 1.0
        cruise_speed = ctx.vmax[axis - 1] * percent / 100.0 * scale
        best = None
        for sign in (1.0, -1.0):
            room = min(ctx.room(q, axis, sign), longest)
            size = analysis.cruise_move(math.radians(move), peak, cruise_speed, math.radians(room),
                                        max(self.CRUISE_TIME, self.CRUISE_RECORDS * dt))
            if size is not None and (best is None or size[1] > best[2]):
                best = (sign, math.degrees(size[0]), size[1])
        if best is None:
            ctx.say("  joint_%d: no cruise speed in %.0f deg at %.0f %% (peak %.1f deg/s), and no move within %.0f deg "
                    "and its limits reaches one" % (axis, move, percent, math.degrees(peak), longest))
            return None
        sign, degrees, speed = best
        new_percent = min(percent, 100.0 * speed / (ctx.vmax[axis - 1] * scale))
        ctx.say("  joint_%d: no cruise speed in %.0f deg at %.0f %% (peak %.1f deg/s): moving %+.0f deg at %.0f %% "
                "and back" % (axis, move, percent, math.degrees(peak), sign * degrees, new_percent))
        return sign, degrees, new_percent


class UnreachableStep(Step):
    name = "unreachable"
    moves = False
    title = "an unreachable pose"

    def describe(self, ctx: Context) -> str:
        return ("send a pose 3 m from the base (out of reach; nothing can move) and watch for %.1f s: refused "
                "UNREACHABLE, or an alarm that halts the program (then the pendant is needed to go on)."
                % self._watch(ctx))

    @staticmethod
    def _watch(ctx: Context) -> float:
        """How long the answer is awaited: two hold times, at least 30 loops."""
        return max(2 * ctx.hold(), 30 * ctx.loop_period)

    def run(self, ctx: Context) -> List[Finding]:
        bus = ctx.bus
        ctx.wait_rest()
        pose = ctx.feedback.pose.as_tuple()
        far = ControllerPose(3000.0, 0.0, pose[2], *pose[3:])
        seq = ctx.next_seq()
        bus.send(CommandV3(Control.START, ctx.slot(seq, far, 10.0)).encode(ctx.order))
        cycles = bus.run_for(self._watch(ctx))
        ctx.idle()
        fbs = [c.feedback for c in cycles if c.feedback is not None]
        refused = any(fb.rejected_seq == seq and fb.reject_code is RejectCode.UNREACHABLE for fb in fbs)
        other = next((fb.reject_code for fb in fbs if fb.rejected_seq == seq
                      and fb.reject_code not in (RejectCode.NONE, RejectCode.UNREACHABLE)), None)
        brackets = heartbeat_brackets(cycles)
        last_new = brackets[-1][2] if brackets else cycles[0].request
        frozen = cycles[-1].request - last_new
        halted = not refused and frozen >= max(0.5 * (cycles[-1].request - cycles[0].request), 10 * ctx.loop_period)
        if refused:
            verdict, ok, consequence = "refused UNREACHABLE (code 4), the program goes on", True, "none"
            ctx.measured["unreachable"] = "skip"
        elif halted:
            verdict, ok = "an alarm: the program halted (the heartbeat stood still %.1f s)" % frozen, False
            consequence = ("a target the G2 cannot reach stops the program: the driver times out on it (accept_timeout) "
                           "and the program must be restarted at the pendant. The driver checks every pose against "
                           "its model before it sends it: calibrate the model so that it never sends one "
                           "(unreachable: alarm_halt)")
            ctx.measured["unreachable"] = "alarm_halt"
        elif other is not None:
            verdict, ok, consequence = "refused %s" % other.name, False, "the program's reject code for it differs (§10.4 rule 4)"
        else:
            verdict, ok, consequence = "neither refused nor halted", None, "watch the pendant: what did the G2 do?"
        return [Finding("an unreachable pose", "refused UNREACHABLE without motion", verdict, consequence, ok)]


STEPS: Tuple[Step, ...] = (CardStep(), CheckWordStep(), LoopStep(), SendAheadStep(), SpeedStep(), LookAheadStep(),
                           ConfigurationStep(), RampStep(), UnreachableStep())
STEP_NAMES = tuple(s.name for s in STEPS)


def clear_space(sizes: Sizes, skip: Sequence[str] = ()) -> Reach:
    """The clear space the steps (less ``skip``) need: {joint: (degrees one way, degrees the other)}
    from where the arm stands, the farthest of every step's moves (:meth:`Step.reach`), each side
    the larger of the two ways (a step turns a joint the way its limits allow, +1 first). What the
    start says, each step's words and doc/commissioning.md's table (a test compares them) all come
    from here."""
    out: Dict[int, Tuple[float, float]] = {}
    for step in STEPS:
        if step.name in skip:
            continue
        for joint, (ahead, back) in step.reach(sizes).items():
            far, near = max(ahead, back), min(ahead, back)
            old = out.get(joint, (0.0, 0.0))
            out[joint] = (max(old[0], far), max(old[1], near))
    return dict(sorted(out.items()))


def clear_space_table(sizes: Sizes) -> str:
    """:func:`clear_space` as doc/commissioning.md's table (Markdown): per joint, the two ways and the
    steps' own figures."""
    lines = ["| joint | one way | the other way | the steps (one way / the other) |", "| --- | --- | --- | --- |"]
    for joint, (far, near) in clear_space(sizes).items():
        steps = ", ".join("`%s` %.0f°%s" % (step.name, reach[0], " / %.0f°" % reach[1] if reach[1] else "")
                          for step in STEPS for reach in [step.reach(sizes).get(joint)] if reach)
        lines.append("| joint %d | %.0f° | %.0f° | %s |" % (joint, far, near, steps))
    return "\n".join(lines)


def clear_space_words(sizes: Sizes, skip: Sequence[str] = ()) -> str:
    """:func:`clear_space` in words: "joint_1 120 deg one way, 20 the other; ..."."""
    return "; ".join("joint_%d %.0f deg%s" % (joint, far, " one way, %.0f the other" % near if near else "")
                     for joint, (far, near) in clear_space(sizes, skip).items())


def timed(fn: Callable[[], Any], clock: Callable[[], float] = time.monotonic) -> Tuple[Any, float]:
    t = clock()
    return fn(), clock() - t
