"""The v2 virtual controller over a REAL pty pair: our DpMaster (SlaveSpec with CHK_CFG_V2, 72 bytes
each way) brings it to Data_Exchange and streams five joint targets with a look-ahead slot; each is
taken and executed exactly once. The master thread paces its bus cycles; the test waits on
conditions with deadlines, nothing sleeps to synchronise."""
from __future__ import annotations

from typing import List, Optional, Set

from pyprofibus_vendor.dp_master import DpMaster

from vr_driver.controller.virtual_controller import VirtualController
from vr_driver.errors import ProtocolError
from vr_driver.protocol.v2 import (CHK_CFG_V2, RECORD_SIZE_V2, CommandV2, Control, FeedbackV2, StreamState,
                                   TargetSlot, joints_to_wire)
from vr_driver.controller.arm import Outcome

from _pty_master import ThreadedMaster

BAUD = 187500
CYCLE = 0.002
LOOP = 0.005


class StreamingMaster(ThreadedMaster):
    """DpMaster in a thread; each cycle it puts the first target the controller has not taken into
    slot 0 and the next into slot 1 (START on the first), by the accepted_seq it last read."""

    def __init__(self, path: str, targets: List[TargetSlot]) -> None:
        super().__init__(path, BAUD, CHK_CFG_V2, watchdog=1.0, cycle=CYCLE)
        self.targets = targets
        self.feedback: Optional[FeedbackV2] = None
        self.beats: Set[int] = set()                   # heartbeats seen while connected
        self.sent: List[CommandV2] = []
        self.start("test-v2-master")

    def _on_cycle(self, master: DpMaster) -> None:
        h = self.handle
        with self.cond:
            if h.connected and h.inputs is not None:
                try:
                    self.feedback = FeedbackV2.decode(h.inputs)
                    self.beats.add(self.feedback.heartbeat)
                except ProtocolError:
                    pass                                 # before the program's first loop
            accepted = self.feedback.accepted_seq if self.feedback is not None else 0
            seqs = [t.seq for t in self.targets]
            i = seqs.index(accepted) + 1 if accepted in seqs else 0
            # empty records first, for several program loops: they arm the controller (rule 9.3.5)
            slots = self.targets[i:i + 2] if len(self.beats) >= 5 else []
            record = CommandV2() if not slots else CommandV2(
                Control.START if i == 0 else Control(0), slots[0], slots[1] if len(slots) > 1 else TargetSlot())
            if not self.sent or self.sent[-1] != record:
                self.sent.append(record)
            self.cond.notify_all()
        h.outputs = record.encode()



def test_dp_master_streams_five_targets_to_the_v2_controller_each_once(kin):
    vc = VirtualController(kinematics=kin, protocol="v2", speed_factor=4.0, loop_period=LOOP, baud=BAUD)
    pts = [(0.1 * i, 0.4 + (0.06 if i % 2 else 0.0), -0.3, 0.02 * i, 0.6, 0.04 * i) for i in range(1, 6)]
    targets = [TargetSlot.joint_target(i + 1, q, 0.5, 4 if i < 4 else 0) for i, q in enumerate(pts)]
    vc.start()
    driver = StreamingMaster(vc.device_path, targets)
    try:
        assert driver.wait(lambda: driver.handle.connected, 10.0), "the master did not connect"
        assert driver.handle.spec.cfg == CHK_CFG_V2
        assert driver.handle.spec.input_size == driver.handle.spec.output_size == RECORD_SIZE_V2
        assert vc.slave.input_size == vc.slave.output_size == RECORD_SIZE_V2
        assert driver.wait(lambda: driver.feedback is not None and driver.feedback.done_seq == 5
                           and driver.feedback.state is StreamState.IDLE, 30.0), driver.feedback
        assert vc.log.wait_for(5, 5.0)
    finally:
        driver.stop()
        vc.stop()
    assert vc.error is None and vc.server_error is None
    entries = vc.log.entries()
    assert [e.seq for e in entries] == [1, 2, 3, 4, 5]
    assert all(e.outcome in (Outcome.BLENDED, Outcome.EXECUTED) for e in entries)
    assert entries[-1].outcome is Outcome.EXECUTED
    assert entries[-1].final_joints == joints_to_wire(pts[-1]) == driver.feedback.joints
    assert driver.feedback.accepted_seq == 5 and driver.feedback.rejected_seq == 0
    assert vc.program.bad_records == 0
