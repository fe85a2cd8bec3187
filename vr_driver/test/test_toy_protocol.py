"""Adding a controller protocol is one module, one registration and its code at each end -- shown
with a toy protocol that lives in this test only.

The toy ("toy", version byte 9) is protocol v2 whose records differ in one byte, the first: its
module is :class:`ProtocolToy` (the protocol object: the version byte, the codec), its controller
program :class:`ToyProgram` (v2's program reading and writing the toy's records), its sequencer the
stream sequencer, its stream family joint targets sent as planned; the registration is ``registry.register(TOY)`` and ``TOY.implement(...)``. Nothing
in ``vr_driver`` names it. It runs through the driver core and the virtual G2 (its
:class:`~vr_driver.controller.virtual_controller.VirtualController`, on the in-memory link of
``driver/_world.py``, stepped with a fake clock in one thread): a target goes end to end.

A protocol nobody registered a program, a sequencer or a stream family for is refused in words -- even one whose
capabilities are v2's to the letter, which the virtual G2 once ran on v2's program."""
from __future__ import annotations

import os
import struct
import sys

import pytest
from pyprofibus_vendor.phy import MemoryLink

from vr_driver.controller.program_v2 import ControllerProgramV2
from vr_driver.controller.programs import BUILT_IN as PROGRAMS
from vr_driver.controller.virtual_controller import VirtualController
from vr_driver.driver import DriverCore
from vr_driver.driver.sequencers import BUILT_IN as SEQUENCERS
from vr_driver.driver.sequencers import STREAM_FAMILIES
from vr_driver.driver.checks.stream_prep import JointStreams
from vr_driver.driver.motion.streaming import StreamSequencer
from vr_driver.errors import ProtocolError
from vr_driver.params import DriverParams
from vr_driver.poses import ControllerPose, MoveType
from vr_driver.protocol import registry
from vr_driver.protocol.base import framed_record
from vr_driver.protocol.v2 import RECORD_SIZE_V2, V2, CommandV2, FeedbackV2, ProtocolV2, crc16
from vr_driver.controller.options import SimError
from vr_driver.driver.motion.jobs import MoveRequest

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "driver"))
from _world import WORLD_PARAMS, FakeClock, SteppedLink  # noqa: E402

DEG = 3.141592653589793 / 180.0


# ------------------------------------------------------------------------ the toy protocol's module

def _with_version(raw: bytes, version: int) -> bytes:
    """A v2-layout record with another version byte, its CRC-16 computed again over it."""
    body = bytes([version]) + bytes(raw[1:-2])
    return body + struct.pack("<H", crc16(body))


class ProtocolToy(ProtocolV2):
    """v2's records with version byte 9: everything else -- the layout, the CRC, the capabilities,
    the Chk_Cfg -- is v2's, so only the code registered for this protocol tells them apart."""

    name = "toy"
    version = 9
    summary = "protocol v2 with version byte 9 (a test's toy)"

    def _to_v2(self, data, what: str) -> bytes:
        raw = framed_record(data, RECORD_SIZE_V2, self.version, what)
        if crc16(raw[:-2]) != struct.unpack("<H", raw[-2:])[0]:
            raise ProtocolError("%s record: CRC does not match its bytes" % what)
        return _with_version(raw, V2.version)

    def encode(self, command: CommandV2, byte_order="little") -> bytes:
        return _with_version(command.encode(), self.version)

    def idle_record(self, byte_order="little") -> bytes:
        return self.encode(CommandV2())

    def decode_feedback(self, data, byte_order="little") -> FeedbackV2:
        return FeedbackV2.decode(self._to_v2(data, "toy feedback"))

    def decode_command(self, data, byte_order="little") -> CommandV2:
        return CommandV2.decode(self._to_v2(data, "toy command"))

    def encode_feedback(self, feedback: FeedbackV2, byte_order="little") -> bytes:
        return _with_version(feedback.encode(), self.version)


TOY = ProtocolToy()


class ToyProgram(ControllerProgramV2):
    """The toy's controller program: v2's rules, the toy's records."""

    def decode_record(self, raw: bytes) -> CommandV2:
        return TOY.decode_command(raw)

    def make_feedback(self, now: float):
        feedback, _v2_bytes = super().make_feedback(now)
        return feedback, TOY.encode_feedback(feedback)


@pytest.fixture
def toy():
    """The registration: the protocol by its name, its program, its sequencer and its stream family
    (undone after the test: the registry is the process's)."""
    registry.register(TOY)
    TOY.implement(controller_program=ToyProgram, sequencer=StreamSequencer, stream_family=JointStreams)
    yield TOY
    registry.unregister(TOY.name)


@pytest.fixture
def bare():
    """A protocol registered by its name and nothing else: v2's capabilities to the letter, no
    program, no sequencer."""
    proto = ProtocolToy()
    proto.name, proto.version = "bare", 8
    registry.register(proto)
    yield proto
    registry.unregister(proto.name)


# ----------------------------------------------------------------------------------- the world

class ToyWorld:
    """The driver core and the virtual G2 of the toy protocol in one thread, one fake clock: the
    virtual G2 built by VirtualController (its program the one the protocol names), its slave
    answering the driver's master on the in-memory link synchronously (_world.SteppedLink)."""

    def __init__(self, kin, wire) -> None:
        self.clock = FakeClock()
        unused, _ = MemoryLink.pair()            # the controller's own port: never served here
        self.g2 = VirtualController(unused, protocol=wire, kinematics=kin, clock=self.clock)
        self.link = SteppedLink(self.g2.slave, self.clock)
        self.params = DriverParams.from_dict(dict(WORLD_PARAMS, protocol=wire.name))
        self.core = DriverCore(self.params, kinematics=kin, clock=self.clock,
                               open_link=lambda device, baud: self.link)
        self.next_bus = self.next_loop = self.clock.t

    def tick(self) -> None:
        self.clock.t = max(self.clock.t, min(self.next_loop, self.next_bus))
        if self.clock.t >= self.next_loop:
            self.g2.step(self.clock.t)
            self.next_loop = max(self.next_loop + self.g2.loop_period, self.clock.t)
        if self.clock.t >= self.next_bus:
            self.core.spin_once()
            self.core.run_planning()
            self.next_bus = self.core.next_cycle(self.clock.t, max(self.next_bus + 1.0 / self.params.cycle_rate,
                                                                   self.clock.t))

    def run_until(self, predicate, timeout: float, what: str) -> None:
        end = self.clock.t + timeout
        while not predicate():
            assert self.clock.t < end, "%s not within %.0f s of world time: %s" % (
                what, timeout, self.core.status(self.clock.t).link_reason)
            self.tick()

    def close(self) -> None:
        self.g2.stop()


# ------------------------------------------------------------------------------------ the tests

def test_the_toy_runs_through_the_driver_core_and_the_virtual_controller(kin, toy):
    world = ToyWorld(kin, toy)
    try:
        assert type(world.g2.program) is ToyProgram            # the program the protocol names
        assert type(world.core.sequencer) is toy.sequencer() is StreamSequencer
        world.run_until(lambda: world.core.status(world.clock.t).motion_possible, 5.0, "driver ready")
        target = ControllerPose(1000, -600, 800, 0, 45, 0)
        job = world.core.submit(MoveRequest(MoveType.PTP, target))
        world.run_until(lambda: job.done, 30.0, "the move")
        assert job.result.success, job.result.reason
        # the arm is where the preview said, the target taken exactly once per point
        assert max(abs(a - b) for a, b in zip(world.g2.joints, job.preview.joint_target)) <= 0.001 * DEG
        seqs = [e.seq for e in world.g2.log.entries()]
        assert len(seqs) == len(set(seqs)) == len(job.points) >= 1
        # and every record on the wire was the toy's: the program decoded them all
        assert world.g2.program.bad_records == 0
        assert world.g2.slave.inputs[0] == toy.version
    finally:
        world.close()


def test_a_v2_record_is_no_toy_record_and_the_error_names_the_protocol(toy):
    v2_record = V2.idle_record()
    with pytest.raises(ProtocolError, match=r"version byte 2, expected 9 \(is the other end running protocol v2\?\)"):
        toy.decode_command(v2_record)
    with pytest.raises(ProtocolError, match=r"version byte 9, expected 2 \(is the other end running protocol toy\?\)"):
        V2.decode_command(toy.idle_record())
    assert toy.decode_command(toy.idle_record()) == CommandV2()


def test_a_protocol_without_a_program_is_refused_in_words_never_given_another(kin, bare):
    assert bare.streams and bare.joint_targets and bare.chk_cfg == V2.chk_cfg   # v2's capabilities
    with pytest.raises(SimError, match="protocol bare has no controller program registered: the virtual G2 "
                                       "cannot run it"):
        VirtualController(MemoryLink.pair()[0], protocol=bare, kinematics=kin)
    with pytest.raises(ProtocolError, match="protocol bare has no sequencer registered: the driver cannot run it"):
        bare.sequencer()
    with pytest.raises(ProtocolError, match="protocol bare has no stream family registered: the driver's stream "
                                            "preparation cannot run it"):
        bare.stream_family()


def test_a_protocol_runs_on_one_program_only(toy):
    toy.implement(controller_program=ToyProgram)                 # the same again: harmless
    with pytest.raises(ProtocolError, match="protocol toy already has a controller program"):
        toy.implement(controller_program=ControllerProgramV2)
    assert toy.controller_program() is ToyProgram


def test_the_registry_keeps_names_and_version_bytes_apart(toy):
    twin = ProtocolToy()
    with pytest.raises(ProtocolError, match="toy already has that name"):
        registry.register(twin)
    twin.name = "twin"
    with pytest.raises(ProtocolError, match="toy already has that version byte"):
        registry.register(twin)
    with pytest.raises(ProtocolError, match="built in"):
        registry.unregister(V2.name)


def test_the_registration_ends_with_the_test(toy):
    registry.unregister(toy.name)
    with pytest.raises(ProtocolError, match="unknown protocol 'toy'"):
        registry.get("toy")
    with pytest.raises(ProtocolError, match="no controller program"):
        toy.controller_program()
    registry.register(toy)                      # for the fixture's own unregister


def test_every_built_in_protocol_has_its_program_and_its_sequencer():
    """Each built-in protocol names one program and one sequencer, registered by the package of that
    end (programs.py, sequencers.py) -- and no other protocol shares a program."""
    for proto, program in PROGRAMS:
        assert proto.controller_program() is program
    for proto, sequencer in SEQUENCERS:
        assert proto.sequencer() is sequencer
    assert [p.name for p, _ in PROGRAMS] == [p.name for p, _ in SEQUENCERS] == list(registry.names())
    assert len({program for _, program in PROGRAMS}) == len(PROGRAMS)
    for proto, family in STREAM_FAMILIES:
        assert proto.streams and proto.stream_family() is family
    assert {p.name for p, _ in STREAM_FAMILIES} == {p.name for p, _ in PROGRAMS if p.streams}
