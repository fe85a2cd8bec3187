"""The protocol registry: each controller protocol's object by its name (the ``protocol``
parameter). Nothing outside ``vr_driver.protocol`` compares protocol names: it asks the object
(``vr_driver/test/test_protocol_seam.py``)."""
from __future__ import annotations

from typing import Any, Dict, Tuple

from ..errors import ProtocolError
from .base import _IMPLEMENTATIONS, _VERSIONS, Protocol
from .v1 import V1
from .v2 import V2
from .v3 import V3

__all__ = ["get", "names", "register", "unregister", "DEFAULT"]

_ALL: Dict[str, Protocol] = {}
#: the protocol of an unchanged G2 program (the thesis')
DEFAULT = V1.name


def names() -> Tuple[str, ...]:
    """Every protocol's name, in version order."""
    return tuple(_ALL)


def get(name: Any) -> Protocol:
    """The protocol called ``name`` (a Protocol passes through); ProtocolError naming the known
    ones otherwise."""
    if isinstance(name, Protocol):
        return name
    try:
        return _ALL[name]
    except (KeyError, TypeError):
        raise ProtocolError("unknown protocol %r (known: %s)" % (name, ", ".join(_ALL))) from None


def register(wire: Protocol) -> Protocol:
    """Make ``wire`` one of the protocols the ``protocol`` parameter may name (returned as it
    is). ProtocolError for an object that is no Protocol, without a name, or whose name or version
    byte another protocol has (a record must name the protocol that sent it). The code that runs it
    at each end registers with the protocol object (:meth:`~vr_driver.protocol.base.Protocol.implement`)."""
    if not isinstance(wire, Protocol) or not wire.name:
        raise ProtocolError("register() takes a Protocol with a name, got %r" % (wire,))
    for other in _ALL.values():
        if other is wire:
            return wire
        if other.name == wire.name or other.version == wire.version:
            raise ProtocolError("protocol %s (version byte %d): %s already has that %s"
                                % (wire.name, wire.version, other.name,
                                   "name" if other.name == wire.name else "version byte"))
    _ALL[wire.name] = wire
    _VERSIONS[wire.name] = wire.version
    return wire


def unregister(name: str) -> None:
    """Forget the protocol called ``name`` and what was registered to run it (a test's own protocol,
    when the test ends); the built-in ones stay. ProtocolError for one of them."""
    if name in _BUILT_IN:
        raise ProtocolError("protocol %s is built in: it stays registered" % name)
    _ALL.pop(name, None)
    _VERSIONS.pop(name, None)
    for key in [key for key in _IMPLEMENTATIONS if key[0] == name]:
        del _IMPLEMENTATIONS[key]


for _protocol in (V1, V2, V3):
    register(_protocol)
_BUILT_IN = frozenset(_ALL)
