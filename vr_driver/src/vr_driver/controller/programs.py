"""Which virtual G2 program runs which protocol: the controller package registers each built-in
protocol's program with the protocol object (:meth:`vr_driver.protocol.base.Protocol.implement`),
and the virtual G2 asks the protocol object for it (:meth:`~vr_driver.protocol.base.Protocol.
controller_program`) -- never by the protocol's name, never by its capabilities, so a protocol
nobody wrote a program for is refused in words instead of running on another protocol's. ROS-free.

A new protocol's program registers the same way, from its own module:
``MY_PROTOCOL.implement(controller_program=MyProgram)``, ``MyProgram`` a
:class:`~vr_driver.controller.session.SessionProgram` with ``ARM_TYPE``, ``make_arm`` and
``from_options`` (``vr_driver/test/test_toy_protocol.py``)."""
from __future__ import annotations

from ..protocol.v1 import V1
from ..protocol.v2 import V2
from ..protocol.v3 import V3
from .program_v1 import ControllerProgramV1
from .program_v2 import ControllerProgramV2
from .program_v3 import ControllerProgramV3

__all__ = ["BUILT_IN"]

#: (protocol, the program that runs it) of the protocols this package ships
BUILT_IN = ((V1, ControllerProgramV1), (V2, ControllerProgramV2), (V3, ControllerProgramV3))

for _protocol, _program in BUILT_IN:
    _protocol.implement(controller_program=_program)
