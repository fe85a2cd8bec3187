"""Each protocol's stop record (vr_driver.protocol.base.Protocol.stop_record): what the bus process
sends when the driver dies (vr_driver.bus.process), for what the record on the wire set going."""
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
def test_a_stream_is_stopped_by_its_stop_command_whatever_it_runs(wire):
    stop = wire.encode(wire.stream_command((), stop=True))
    for record in (wire.encode(wire.stream_command([target(5), target(6)], start=True)),
                   wire.encode(wire.stream_command([target(6)])), wire.idle_record(), stop):
        assert wire.stop_record(record) == stop
    assert wire.decode_command(stop).control == 1          # STOP, no target


def test_v1_stop_is_the_target_on_the_wire_with_the_stop_flag():
    move = Command(1120, 0, 725, 0, 45, 0, True, WireMoveType.LIN).encode()
    stop = V1.stop_record(move)
    assert Command.decode(stop) == Command(1120, 0, 725, 0, 45, 0, False, WireMoveType.LIN).with_stop()
    assert V1.stop_record(stop) == stop
    assert V1.stop_record(V1.idle_record()) == V1.idle_record()     # nothing runs: nothing to stop
