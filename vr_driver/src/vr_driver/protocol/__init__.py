"""The wire protocols between the PROFIBUS master and the G2 controller card, each one object
(:class:`~vr_driver.protocol.base.Protocol`) chosen once from the ``protocol`` parameter with
:func:`vr_driver.protocol.registry.get`: v1 (the thesis' 14-byte Cartesian target record and its
handshake), v2 (streamed joint targets) and v3 (streamed Cartesian targets for the G2 as it is). Imports only the vocabulary modules (errors, poses,
validate).

Nothing outside this package compares protocol names: it asks the protocol object
(``vr_driver/test/test_protocol_seam.py``)."""
