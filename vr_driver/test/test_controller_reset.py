"""Exactly once across a reset of the card, on the controller's side alone (doc/controller_program.md
§4 rule 10, §9.3 rule 5, §10.4 rule 3): the virtual G2's programs (v1, v2, v3) on their DpSlave,
stepped with a fake clock, and a minimal master whose telegrams go straight into the slave
(_slave_rig). The card is reset -- its watchdog after the master fell silent, or a new Set_Prm /
Chk_Cfg between two program loops -- and afterwards its input image still holds a command of before
(a master that keeps its outputs across the reset). The program must not take it before it has
read the idle record in the new session.

Both settings of the virtual G2's assumption ``data_exchange_bit`` (controller.session): with the
card's Data_Exchange status the program sees every reset; with its input bytes only it sees a reset
where the card's safe image is no record (v2, v3) and a loop read it -- and v1, whose idle record
*is* the safe image, cannot keep exactly once across a reset by itself: there it rests on the
master's idle record at the start of every session (driver/link/link.py;
driver/test_reset_exactly_once_stepped.py runs both ends). Nothing here sleeps."""
from __future__ import annotations

from collections import Counter
from typing import Any, Callable, List

import pytest

from pyprofibus_vendor.dp_slave import SlaveState

from vr_driver.controller.arm import Outcome, SimArm
from vr_driver.controller.cli import _parser
from vr_driver.controller.options import SimOptions
from vr_driver.controller.program_v1 import ControllerProgramV1 as ControllerProgram
from vr_driver.controller.simulator import SimError
from vr_driver.controller.virtual_controller import robot_slave, VirtualController
from vr_driver.controller.program_v2 import ControllerProgramV2
from vr_driver.controller.program_v3 import ControllerProgramV3
from vr_driver.controller.stream_arm import SimStreamArm
from vr_driver.errors import VrDriverError
from vr_driver.protocol import v2, v3
from vr_driver.protocol.v1 import Command, ControllerState, Feedback, WireMoveType

from _slave_rig import SlaveRig, StreamRig

START_JOINTS = (0.0, 0.4, -0.3, 0.0, 0.6, 0.0)
A = Command.from_pose((1000, 0, 700, 0, 60, 0), WireMoveType.PTP)
B = Command.from_pose((900, 300, 500, 0, 90, 30), WireMoveType.PTP)
SETTINGS = pytest.mark.parametrize("dx_bit", [True, False], ids=["data_exchange_bit", "bytes_only"])
RESETS = pytest.mark.parametrize("how", ["watchdog", "set_prm"])


def reset(rig: SlaveRig, how: str) -> None:
    """Reset the card, the master's record unchanged: ``watchdog`` -- the master falls silent, the
    card's watchdog expires, the program runs on for a few loops, the master parameterises the card
    again; ``set_prm`` -- a new Set_Prm and Chk_Cfg between two program loops (no loop sees the card
    out of Data_Exchange). Both end with one Data_Exchange of the old record and a program loop."""
    if how == "watchdog":
        rig.exchanging = False
        rig.until(lambda *_: rig.slave.state is SlaveState.WAIT_PRM, 1.0)
        rig.loop(5)
        rig.exchanging = True
    rig.connect()
    assert rig.slave.state is SlaveState.DATA_EXCH


def sees(dx_bit: bool, how: str) -> bool:
    """Whether a v2 / v3 program sees the reset: always with the card's status; from its bytes only
    if a loop read the card's safe image."""
    return dx_bit or how == "watchdog"


# ------------------------------------------------------------------------------------------ v1
class RigV1(SlaveRig):
    """The v1 program (with the two-telegram rule, the VirtualController's default for v1) on its
    slave and a SimArm; the master sends ``self.record`` in one Data_Exchange per program loop."""

    def __init__(self, kin, dx_bit: bool, period: float = 0.01) -> None:
        super().__init__(period, watchdog_units=10)          # 100 ms
        self.slave = robot_slave(4, self.clock)
        self.arm = SimArm(kin, speed_factor=4.0, clock=self.clock)
        self.prog = ControllerProgram(self.slave, self.arm, confirm_records=True, data_exchange_bit=dx_bit)
        self.record = Command.idle()

    def loop(self, n: int = 1) -> Feedback:
        fb = None
        for _ in range(n):
            self.t += self.period
            if self.exchanging and self.slave.state is SlaveState.DATA_EXCH:
                self.call(None, self.record.encode())
            fb = self.prog.step(self.t)
        assert fb is not None
        return fb

    def until(self, pred: Callable[[Feedback], bool], max_time: float = 30.0) -> Feedback:
        end = self.t + max_time
        fb = self.loop()
        while not pred(fb):
            assert self.t < end, "condition not reached within %.1f s of fake time" % max_time
            fb = self.loop()
        return fb

    def outcomes(self) -> List[tuple]:
        return [(e.target, e.outcome, "already raised" in e.reason) for e in self.prog.log.entries()]


@SETTINGS
@RESETS
def test_v1_a_request_still_in_the_inputs_after_a_reset(kin, dx_bit, how):
    """A was executed; its flag is still raised (the master has not seen DONE) when the card is
    reset, and the master goes on sending it."""
    rig = RigV1(kin, dx_bit)
    rig.connect()
    rig.until(lambda fb: fb.state is ControllerState.READY and rig.prog.armed, 1.0)
    rig.record = A
    rig.until(lambda fb: fb.state is ControllerState.DONE, 10.0)
    assert rig.outcomes() == [(A.values, Outcome.EXECUTED, False)]
    reset(rig, how)
    fb = rig.loop(20)
    if dx_bit:
        # the program saw the reset: disarmed; the raised flag is answered REJECTED, nothing runs
        assert rig.prog.link_losses == 1 and not rig.prog.armed
        assert fb.state is ControllerState.REJECTED and not rig.arm.moving
        assert rig.outcomes() == [(A.values, Outcome.EXECUTED, False), (A.values, Outcome.REJECTED, True)]
    elif how == "set_prm":
        # only its bytes, and no loop read the safe image: no reset for this program -- DONE is
        # held while the flag is raised, as if nothing had happened
        assert rig.prog.link_losses == 0 and fb.state is ControllerState.DONE
        assert rig.outcomes() == [(A.values, Outcome.EXECUTED, False)]
    else:
        # only its bytes, and it read the safe image (all zero) for several loops: that *is* v1's
        # idle record -- DONE released, and the raised flag of the new session is a new request:
        # A runs a second time. This program cannot keep v1 exactly once across a reset; the
        # master's idle record at the start of every session does (driver/link/link.py)
        assert not rig.prog.sees_resets and rig.prog.link_losses == 0
        assert rig.outcomes() == [(A.values, Outcome.EXECUTED, False), (A.values, Outcome.EXECUTED, False)]
    # in every case: after the idle record the next request runs, once
    done = len(rig.prog.log)
    rig.record = Command.idle()
    fb = rig.until(lambda fb: fb.state is ControllerState.READY and rig.prog.armed, 1.0)
    rig.record = B
    rig.until(lambda fb: fb.state is ControllerState.DONE, 10.0)
    rig.record = Command.idle()
    rig.loop(10)
    assert rig.outcomes()[done:] == [(B.values, Outcome.EXECUTED, False)]
    assert rig.arm.reported_pose() == B.values


def test_v1_a_request_raised_before_the_reset_but_not_yet_taken(kin):
    """With the card's Data_Exchange status: B reached the card in one telegram only (not confirmed,
    §4 rule 9) when the master fell silent; after the reset B is in the inputs again: stale,
    REJECTED, nothing moves until the idle record. (A program that reads only its bytes reads B
    twice in the card's buffer before the watchdog expires and runs it: the case above.)"""
    rig = RigV1(kin, True)
    rig.connect()
    rig.until(lambda fb: rig.prog.armed, 1.0)
    rig.t += rig.period
    rig.call(None, B.encode())                      # one telegram, then silence
    rig.exchanging = False
    rig.record = B
    rig.until(lambda fb: rig.slave.state is SlaveState.WAIT_PRM, 1.0)
    assert len(rig.prog.log) == 0 and not rig.arm.moving
    rig.loop(5)
    rig.exchanging = True
    rig.connect()
    fb = rig.loop(20)
    assert fb.state is ControllerState.REJECTED and rig.outcomes() == [(B.values, Outcome.REJECTED, True)]
    assert rig.arm.reported_pose() == (1120, 0, 725, 0, 45, 0) and rig.prog.link_losses == 1
    rig.record = Command.idle()
    rig.until(lambda fb: fb.state is ControllerState.READY and rig.prog.armed, 1.0)
    rig.record = B
    rig.until(lambda fb: fb.state is ControllerState.DONE, 10.0)
    assert rig.outcomes()[1:] == [(B.values, Outcome.EXECUTED, False)]


# ------------------------------------------------------------------------------------ v2, v3
class StreamRigFor(StreamRig):
    """The v2 or v3 program on its slave and a SimStreamArm (braking 0.2 s); the master sends
    ``self.record``, or streams ``self.stream`` (START on its first target)."""

    def __init__(self, kin, protocol: str, dx_bit: bool, period: float = 0.005) -> None:
        super().__init__(period, watchdog_units=10)          # 100 ms
        self.protocol = protocol
        self.slave = robot_slave(4, self.clock, protocol)
        self.arm = SimStreamArm(kin, clock=self.clock, brake_time=0.2, initial_joints=START_JOINTS)
        if protocol == "v2":
            self.prog: Any = ControllerProgramV2(self.slave, self.arm, data_exchange_bit=dx_bit)
        else:
            self.prog = ControllerProgramV3(self.slave, self.arm, kinematics=kin, data_exchange_bit=dx_bit)
        self.kin = kin
        self.record = self.idle()

    def idle(self) -> Any:
        return v2.CommandV2() if self.protocol == "v2" else v3.CommandV3()

    def encode(self, record: Any) -> bytes:
        return record.encode()

    def decode(self, data: bytes) -> Any:
        return (v2.FeedbackV2 if self.protocol == "v2" else v3.FeedbackV3).decode(data)

    def command(self, start: bool, *slots: Any) -> Any:
        control = (v2.Control if self.protocol == "v2" else v3.Control)
        flags = control.START if start else control(0)
        if self.protocol == "v2":
            return v2.CommandV2(flags, slots[0], slots[1] if len(slots) > 1 else v2.TargetSlot())
        return v3.CommandV3(flags, slots[0])

    def streamed_record(self) -> Any:
        i = self.accepted_index()
        if i >= len(self.stream):
            return self.idle()
        return self.command(i == 0, *self.stream[i:i + (2 if self.protocol == "v2" else 1)])

    def targets(self, first_seq: int, n: int, speed: float = 0.1, smooth: int = 5) -> List[Any]:
        """``n`` targets (J1 advancing, J2 zig-zagging) from the arm's joints, numbered from ``first_seq``."""
        q0 = self.arm.joints
        out = []
        for i in range(1, n + 1):
            q = (q0[0] + 0.1 * i, q0[1] + (0.06 if i % 2 else 0.0), q0[2] - 0.02 * i, q0[3], q0[4], q0[5])
            seq = first_seq + i - 1
            if self.protocol == "v2":
                out.append(v2.TargetSlot.joint_target(seq, q, speed, smooth))
            else:
                pose = v3.pose_to_wire(self.kin.fk_pose(q))
                out.append(v3.CartesianSlot(seq, v3.CartesianKind.MOVEP, smooth, round(speed * 1000), pose))
        return out


def taken_twice(rig: StreamRigFor) -> List[int]:
    seqs = [e.seq for e in rig.prog.log.entries() if e.outcome is not Outcome.REJECTED]
    return [s for s, n in Counter(seqs).items() if n > 1]


@pytest.mark.parametrize("protocol", ["v2", "v3"])
@SETTINGS
@RESETS
def test_streams_a_target_still_in_the_inputs_after_a_reset(kin, protocol, dx_bit, how):
    """Mid-stream the card is reset; the master goes on sending a record with the next target (one
    the program has not taken: v2 beside a repeat of the last one taken). Where the program sees the
    reset it braked, disarmed, and takes nothing until the idle record; the next stream then runs,
    each target once."""
    rig = StreamRigFor(kin, protocol, dx_bit)
    rig.connect()
    stream = rig.targets(1, 6)
    rig.stream = stream
    fb = rig.until(lambda fb: fb.active_seq == 2 and fb.accepted_seq >= 3, 10.0)
    rig.stream = []
    taken = rig.prog.accepted_seq
    nxt = stream[taken]                               # seq taken + 1: not taken yet
    rig.record = rig.command(False, stream[taken - 1], nxt) if protocol == "v2" else rig.command(False, nxt)
    reset(rig, how)
    fb = rig.loop(40)
    if sees(dx_bit, how):
        assert rig.prog.link_losses == 1 and not rig.prog.armed and not fb.armed
        assert rig.prog.accepted_seq == taken                              # nothing taken
        assert fb.rejected_seq == nxt.seq and fb.reject_code is v2.RejectCode.NOT_ARMED
        fb = rig.until(lambda fb: fb.state is v2.StreamState.IDLE and not rig.arm.moving, 2.0)
        rest = rig.arm.joints
        rig.loop(20)
        assert rig.arm.joints == rest                                      # and nothing moves
        refused = [e for e in rig.prog.log.entries() if e.outcome is Outcome.REJECTED]
        assert [(e.seq, e.reject_code) for e in refused] == [(nxt.seq, int(v2.RejectCode.NOT_ARMED))]
    else:
        # only its bytes, Set_Prm between two loops: no reset for this program -- it goes on with
        # the stream as if nothing had happened; each target once all the same (the seq numbers)
        assert rig.prog.link_losses == 0 and rig.prog.armed
        rig.until(lambda fb: fb.done_seq == nxt.seq and not rig.arm.moving, 10.0)
    assert not taken_twice(rig)
    # the idle record arms the program; the next stream (START) runs, each target once
    rig.record = rig.idle()
    fb = rig.loop(3)
    assert fb.armed
    base = rig.prog.accepted_seq
    more = rig.targets(base + 1, 3, speed=0.5, smooth=0)
    fb = rig.run_stream(more, 20.0)
    after = rig.prog.log.entries()[len(rig.prog.log) - len(more):]
    assert [(e.seq, e.outcome) for e in after] == [(s.seq, Outcome.EXECUTED) for s in more]
    assert not taken_twice(rig)
    assert len([e for e in rig.prog.log.entries() if e.outcome is Outcome.REJECTED]) == int(sees(dx_bit, how))


# ------------------------------------------------------------------------------------ options
@pytest.mark.parametrize("protocol", ["v1", "v2", "v3"])
def test_the_virtual_controller_passes_data_exchange_bit_to_its_program(kin, protocol):
    for dx_bit in (True, False):
        vc = VirtualController(kinematics=kin, protocol=protocol, data_exchange_bit=dx_bit)
        try:
            assert vc.options.data_exchange_bit is dx_bit and vc.program.data_exchange_bit is dx_bit
            # v1's idle record is the card's safe image: from the bytes alone it cannot see a reset
            assert vc.program.sees_resets is (dx_bit or protocol != "v1")
        finally:
            vc.stop()


def test_data_exchange_bit_option(kin):
    assert SimOptions().data_exchange_bit is True
    assert _parser().parse_args([]).data_exchange_bit is True
    assert _parser().parse_args(["--no-data-exchange-bit"]).data_exchange_bit is False
    with pytest.raises(SimError, match="data_exchange_bit"):
        SimOptions(data_exchange_bit="no")
    slave = robot_slave(4, lambda: 0.0)
    with pytest.raises(VrDriverError, match="data_exchange_bit"):
        ControllerProgram(slave, SimArm(kin, clock=lambda: 0.0), data_exchange_bit=0)

