"""The protocol registry: each controller protocol's object by its name (the ``protocol``
parameter). Nothing outside ``vr_driver.protocol`` compares protocol names: it asks the object
(``vr_driver/test/test_protocol_seam.py``)."""
from __future__ import annotations

from typing import Any, Dict, Tuple

from ..errors import ProtocolError
from .base import Protocol
from .v1 import V1
from .v2 import V2
from .v3 import V3

__all__ = ["get", "names", "DEFAULT"]

_ALL: Dict[str, Protocol] = {p.name: p for p in (V1, V2, V3)}
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
