"""Each protocol's stop (vr_driver.protocol.base.Protocol.stop_record / is_stop): the record the bus
process sends when the driver dies, and the test by which it puts a stop on the wire at once, never
behind a record not yet carried (vr_driver.bus.process)."""
from __future__ import annotations

import pytest

from vr_driver.poses import ControllerPose
from vr_driver.protocol.base import WireTarget
from vr_driver.protocol.v1 import V1, Command, WireMoveType
from vr_driver.protocol.v2 import V2
from vr_driver.protocol.v3 import V3

POSE = ControllerPose(1120, 0, 725, 0, 45, 0)


def target(seq: int) -> WireTarget:
    return WireTarget(seq, (0.1, 0.2, 0.3, 0.0, 0.5, 0.0), POSE, 300, 2)


@pytest.mark.parametrize("wire", [V2, V3], ids=["v2", "v3"])
def test_a_stream_stop_is_a_stop_and_its_own_stop(wire):
    start = wire.encode(wire.stream_command([target(5), target(6)], start=True))
    ahead = wire.encode(wire.stream_command([target(6)]))
    stop = wire.encode(wire.stream_command((), stop=True))
    assert wire.stop_record(start) == stop
    assert wire.is_stop(stop) and wire.stop_record(stop) == stop
    for record in (start, ahead, wire.idle_record()):
        assert not wire.is_stop(record)
    assert not wire.is_stop(b"\xff" * len(stop))          # not a command of this protocol


def test_v1_stop_is_the_target_with_the_stop_flag():
    move = Command(1120, 0, 725, 0, 45, 0, True, WireMoveType.LIN).encode()
    stop = V1.stop_record(move)
    assert V1.is_stop(stop) and not V1.is_stop(move)
    assert Command.decode(stop) == Command(1120, 0, 725, 0, 45, 0, False, WireMoveType.LIN).with_stop()
    assert not V1.is_stop(V1.idle_record()) and V1.stop_record(V1.idle_record()) == V1.idle_record()
    assert not V1.is_stop(b"\x00" * 13)                     # a record of the wrong size
