"""Which sequencer and which stream family the driver runs for which protocol: the driver package
registers each built-in protocol's with the protocol object
(:meth:`vr_driver.protocol.base.Protocol.implement`), and the driver core asks the protocol object
for them (:meth:`~vr_driver.protocol.base.Protocol.sequencer`,
:meth:`~vr_driver.protocol.base.Protocol.stream_family`): v1 the handshake sequencer
(:class:`~vr_driver.driver.motion.handshake.HandshakeSequencer`, one target at a time), v2 and v3 the stream
sequencer (:class:`~vr_driver.driver.motion.streaming.StreamSequencer`, which puts targets on the wire
through the protocol object's ``stream_command``) with their stream families (v2 joint targets sent
as planned: :class:`~vr_driver.driver.checks.stream_prep.JointStreams`; v3 Cartesian targets solved as the
controller will: :class:`~vr_driver.driver.checks.stream_prep.CartesianStreams`). A protocol without them
is refused in words, never run on another protocol's. ROS-free.

A new streaming protocol whose records the stream sequencer can drive registers them from its own
module: ``MY_PROTOCOL.implement(sequencer=StreamSequencer, stream_family=JointStreams)``
(``vr_driver/test/test_toy_protocol.py``)."""
from __future__ import annotations

from ..protocol.v1 import V1
from ..protocol.v2 import V2
from ..protocol.v3 import V3
from .motion.handshake import HandshakeSequencer
from .checks.stream_prep import CartesianStreams, JointStreams
from .motion.streaming import StreamSequencer

__all__ = ["BUILT_IN", "STREAM_FAMILIES"]

#: (protocol, the sequencer that drives it) of the protocols this package ships
BUILT_IN = ((V1, HandshakeSequencer), (V2, StreamSequencer), (V3, StreamSequencer))
#: (streaming protocol, the stream family that makes its streams ready) of those
STREAM_FAMILIES = ((V2, JointStreams), (V3, CartesianStreams))

for _protocol, _sequencer in BUILT_IN:
    _protocol.implement(sequencer=_sequencer)
for _protocol, _family in STREAM_FAMILIES:
    _protocol.implement(stream_family=_family)
