"""Which sequencer the driver runs for which protocol: the driver package registers each built-in
protocol's sequencer with the protocol object (:meth:`vr_driver.protocol.base.Protocol.implement`),
and the driver core asks the protocol object for it (:meth:`~vr_driver.protocol.base.Protocol.
sequencer`): v1 the handshake sequencer (:class:`~vr_driver.driver.sequencer.HandshakeSequencer`, one
target at a time), v2 and v3 the stream sequencer (:class:`~vr_driver.driver.streaming.
StreamSequencer`, which puts targets on the wire through the protocol object's ``stream_command``).
A protocol without one is refused in words, never run on another protocol's. ROS-free.

A new streaming protocol whose records the stream sequencer can drive registers it from its own
module: ``MY_PROTOCOL.implement(sequencer=StreamSequencer)`` (``vr_driver/test/test_toy_protocol.py``)."""
from __future__ import annotations

from ..protocol.v1 import V1
from ..protocol.v2 import V2
from ..protocol.v3 import V3
from .sequencer import HandshakeSequencer
from .streaming import StreamSequencer

__all__ = ["BUILT_IN"]

#: (protocol, the sequencer that drives it) of the protocols this package ships
BUILT_IN = ((V1, HandshakeSequencer), (V2, StreamSequencer), (V3, StreamSequencer))

for _protocol, _sequencer in BUILT_IN:
    _protocol.implement(sequencer=_sequencer)
