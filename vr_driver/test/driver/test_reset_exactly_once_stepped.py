"""Exactly once across a reset of the controller's PROFIBUS card (doc/controller_program.md §4 rule 10,
§9.3 rule 5, §10.4 rule 3), both ends, stepped with a fake clock in one thread (_world.World): the
driver's bus loop stands still for 1 s mid-move (v1) or mid-stream (v2, v3) -- longer than the
card's 300 ms watchdog, so the card leaves Data_Exchange and the controller program resets -- then
runs on. The driver's job ends with the link loss as its reason, nothing is sent again by itself,
and the next command after the reconnection runs once; the controller's log shows no command twice
and nothing the driver did not send.

Each case runs with both settings of the virtual G2's assumption ``data_exchange_bit``: the program
reads its card's Data_Exchange status, or only its input bytes (then v1 cannot see the reset at all
and the arm finishes its move; v2 and v3 see the card's safe image and stop)."""
from __future__ import annotations

import functools
from collections import Counter
from typing import List, Set, Tuple

import pytest

from pyprofibus_vendor.dp_slave import SlaveState

import _world
from vr_driver.controller.arm import Outcome
from vr_driver.controller.program_v1 import ControllerProgramV1 as ControllerProgram
from vr_driver.controller.program_v2 import ControllerProgramV2
from vr_driver.controller.program_v3 import ControllerProgramV3
from vr_driver.driver import JobPhase, LinkState, MoveRequest
from vr_driver.poses import ControllerPose, MoveType
from vr_driver.protocol.v1 import Command
from vr_driver.protocol.v2 import CommandV2, RejectCode
from vr_driver.protocol.v3 import CommandV3

from test_streaming_stepped import smooth_path, trajectory

FAR = ControllerPose(1000, -600, 800, 0, 45, 0)
NEXT = ControllerPose(1000, 0, 800, 0, 45, 0)
STALL = 1.0                           # s the driver's bus loop stands still (the card's watchdog: 0.3 s)
SETTINGS = pytest.mark.parametrize("dx_bit", [True, False], ids=["data_exchange_bit", "bytes_only"])


def world_with(kin, monkeypatch, protocol: str, dx_bit: bool) -> _world.World:
    """A World whose controller program has ``data_exchange_bit=dx_bit``, recording every record
    the card received from the master in Data_Exchange (``world.received``)."""
    for name, cls in (("ControllerProgram", ControllerProgram), ("ControllerProgramV2", ControllerProgramV2),
                      ("ControllerProgramV3", ControllerProgramV3)):
        monkeypatch.setattr(_world, name, functools.partial(cls, data_exchange_bit=dx_bit))
    world = _world.World(kin, protocol=protocol)
    assert world.program.data_exchange_bit is dx_bit
    world.received = []
    chained = world.slave.on_outputs

    def spy(data: bytes) -> None:
        if world.slave.state is SlaveState.DATA_EXCH:       # not the card's own safe image
            world.received.append(bytes(data))
        chained(data)
    world.slave.on_outputs = spy
    return world


def stall(world: _world.World) -> None:
    """The driver stands still for STALL seconds; the card's watchdog expires meanwhile."""
    expiries = world.slave.counters.watchdog_expiries
    world.freeze(STALL)
    assert world.slave.counters.watchdog_expiries == expiries + 1
    assert world.slave.state is SlaveState.WAIT_PRM


def reconnected(world: _world.World) -> None:
    world.run_until(lambda: world.status().link is LinkState.CONNECTED, 10.0, "link back")
    world.ready(10.0)


# ------------------------------------------------------------------------------------------ v1
def requests_sent(world) -> Set[Tuple[str, Tuple[int, ...]]]:
    commands = [Command.decode(raw, world.program.byte_order) for raw in world.received]
    return {(c.move_type.name, c.values) for c in commands if c.request}


@SETTINGS
def test_v1_a_stall_mid_move_ends_the_job_and_nothing_runs_twice(kin, monkeypatch, dx_bit):
    world = world_with(kin, monkeypatch, "v1", dx_bit)
    world.ready()
    job = world.core.submit(MoveRequest(MoveType.LIN, FAR))
    world.run_until(lambda: job.phase is JobPhase.MOVING, 5.0, "moving")
    world.run_for(0.2)
    assert world.arm.moving
    stall(world)
    result = world.finish(job, 5.0)
    assert not result.success and "lost" in result.reason and "not re-sent" in result.reason, result.reason
    reconnected(world)
    world.run_for(2.0)                               # nothing is sent again by itself
    assert [e.target for e in world.log.entries()] == [FAR.as_tuple()]
    second = world.core.submit(MoveRequest(MoveType.LIN, NEXT))
    assert world.finish(second).success
    world.run_for(2.0)
    entries = world.log.entries()
    assert [(e.move_type, e.target) for e in entries] == [("LIN", FAR.as_tuple()), ("LIN", NEXT.as_tuple())]
    assert [e.seq for e in entries] == [1, 2] and entries[1].outcome is Outcome.EXECUTED
    assert {(e.move_type, tuple(e.target)) for e in entries} <= requests_sent(world)
    assert not [e for e in entries if "already raised" in e.reason]
    assert world.status().counters.targets_sent == 2
    if dx_bit:
        # the program saw the reset: the arm stopped at the watchdog deadline, the target REJECTED
        assert world.program.link_losses == 1
        assert entries[0].outcome is Outcome.REJECTED and entries[0].aborted and "watchdog" in entries[0].reason
    else:
        # only its input bytes: the card's safe image reads as flag 0, a reset cannot be seen -- the
        # move runs to its end; the master's idle record first in the new session keeps it once
        assert world.program.link_losses == 0 and not world.program.sees_resets
        assert entries[0].outcome is Outcome.EXECUTED


# ------------------------------------------------------------------------------------ v2, v3
def slots_sent(world) -> Set[Tuple[int, Tuple[int, ...]]]:
    """(seq, target as on the wire) of every non-empty slot the card received."""
    out = set()
    for raw in world.received:
        if world.protocol == "v2":
            command = CommandV2.decode(raw)
            out |= {(s.seq, s.joints) for s in (command.slot0, command.slot1) if not s.empty}
        else:
            slot = CommandV3.decode(raw, world.program.byte_order).slot
            if not slot.empty:
                out.add((slot.seq, slot.pose))
    return out


@pytest.mark.parametrize("protocol", ["v2", "v3"])
@SETTINGS
def test_a_stall_mid_stream_ends_the_stream_and_nothing_runs_twice(kin, monkeypatch, protocol, dx_bit):
    world = world_with(kin, monkeypatch, protocol, dx_bit)
    world.ready()
    times, points = smooth_path(world.status().joints, n=30, duration=3.0)
    run = world.core.submit_trajectory(trajectory(world, times, points))
    job = run.jobs[0]
    world.run_until(lambda: job.points_done >= 5, 10.0, "5 points done")
    assert world.arm.moving
    stall(world)
    world.finish(job, 5.0)
    assert job.result.phase is JobPhase.FAILED, job.result
    assert "link to the controller lost" in job.result.reason and "not re-sent" in job.result.reason
    # both settings see this reset (v2 / v3's idle record is not the card's safe image): the arm
    # braked, the rest of the stream was dropped, the program disarmed until our idle record
    assert world.program.link_losses == 1 and world.program.sees_resets
    taken_before = world.program.accepted_seq
    reconnected(world)
    world.run_for(2.0)                               # nothing is sent again by itself
    assert world.program.accepted_seq == taken_before and world.program.armed
    q = world.status().joints
    run2 = world.core.submit_trajectory(trajectory(world, [1.0], [tuple(v + 0.05 for v in q)]))
    assert world.finish(run2.jobs[0]).success, run2.jobs[0].result
    world.run_for(1.0)
    entries = world.log.entries()
    seqs: List[int] = [e.seq for e in entries]
    assert not [s for s, n in Counter(seqs).items() if n > 1], "a target handled twice: %s" % seqs
    assert not [e for e in entries if e.outcome is Outcome.REJECTED], "refused: %s" % entries
    assert {(e.seq, tuple(e.target)) for e in entries} <= slots_sent(world)
    after = [e for e in entries if e.seq > taken_before]
    assert [e.seq for e in after] == run2.jobs[0].seqs                 # the new stream, once
    assert after[-1].outcome is Outcome.EXECUTED
    assert world.program.reject_code is RejectCode.NONE
