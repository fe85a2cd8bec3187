"""Why the controller's PROFIBUS card is not in Data_Exchange, in words: the reason the
:class:`~vr_driver.driver.link.link.LinkSupervisor` gives while its link is down. ROS-free.

The DP master ends a failed attempt to bring the card to Data_Exchange with a terse reason (a
diagnosis, no reply, ...); :class:`CardDiagnosis` adds what it most likely means -- another
device at the address, a configuration or parameters the card refuses, nothing valid received
(off, unplugged, wrong address or baud rate) or bytes that form no valid telegram (baud rate,
parity, noise) -- and logs it once for each kind of failure, not again for new numbers.
"""
from __future__ import annotations

import logging
import re
from typing import Any

from pyprofibus_vendor.dp import DiagStatus1

log = logging.getLogger("vr_driver.driver")

__all__ = ["CardDiagnosis", "diag_words"]


def diag_words(diag: Any) -> str:
    """A slave's diagnosis in words (raw when it cannot be explained)."""
    from pyprofibus_vendor.dp import explain_diag
    try:
        return explain_diag(diag)
    except Exception:  # a diag we cannot explain is still worth showing raw
        return repr(diag)


def _garbage(master: Any) -> int:
    """Bytes the master received that formed no valid telegram, and telegrams with a bad checksum."""
    return master.counters.garbage_bytes + master.counters.fcs_errors


class CardDiagnosis:
    """See the module docstring. ``slave_config``: the bus config's controller slave; ``baud``:
    the bus's. :attr:`reason` is the last failed attempt's, in words ("" when there was none
    since the port opened or the last good record)."""

    def __init__(self, slave_config: Any, baud: int) -> None:
        self.slave_config = slave_config
        self.baud = baud
        self.reason = ""
        self._logged = ""               # the last reason logged, its numbers left out
        self._garbage_seen = 0          # garbled bytes counted up to the last good record

    def port_opened(self) -> None:
        """A new master on a newly opened port: nothing failed yet, nothing garbled yet."""
        self.reason = ""
        self._garbage_seen = 0

    def good_record(self, master: Any) -> None:
        """A good record arrived: garbled bytes are counted from here."""
        if master is not None:
            self._garbage_seen = _garbage(master)

    def link_up(self) -> None:
        """The link is (still) up: no failure to report."""
        self.reason = ""

    def data_exchange(self) -> None:
        """The card entered Data_Exchange: the next failure is logged, whatever it is."""
        self._logged = ""

    def attempt_failed(self, slave: Any, reason: str, master: Any) -> None:
        """The master ended an attempt on ``slave`` (it backs off) for ``reason``; ``master``:
        the supervisor's master (None: none)."""
        self.reason = "controller's PROFIBUS card (slave %d): %s" % (
            slave.address, self._explain(slave, reason, master))
        key = re.sub(r"[0-9]+(\.[0-9]+)?", "#", self.reason)   # not for new numbers
        if key != self._logged:
            self._logged = key
            log.warning("%s", self.reason)

    def _explain(self, slave: Any, reason: str, master: Any) -> str:
        """The master's reason for ending an attempt, with what it most likely means."""
        diag = slave.last_diag
        sc = self.slave_config
        garbage = _garbage(master) if master is not None else 0
        garbled, self._garbage_seen = garbage > self._garbage_seen, garbage
        if reason.startswith("diag:") and diag is not None:
            if diag.ident != sc.ident:
                hint = ("the station at address %d reports ident 0x%04X, the driver expects 0x%04X "
                        "(another device at this address, or the wrong slave_address?)"
                        % (slave.address, diag.ident, sc.ident))
            elif diag.status1 & DiagStatus1.CFG_FAULT:
                hint = ("the card rejects the configuration %s (%d bytes in / %d out): its modules "
                        "differ from the bus config" % (sc.cfg.hex(" "), slave.spec.input_size,
                                                        slave.spec.output_size))
            elif diag.status1 & DiagStatus1.PRM_FAULT:
                hint = "the card rejects the parameters (Set_Prm: ident, watchdog, user data)"
            else:
                hint = ""
            return "%s%s (diag bytes %s)" % (hint + "; " if hint else "", reason,
                                             diag.encode()[:3].hex(" "))
        if reason.startswith("no reply"):
            if garbled:
                hint = ("bytes arrive but form no valid telegram: wrong baud rate or parity at the "
                        "other end, or a noisy line")
            else:
                hint = ("nothing valid received: is the controller on, the cable connected, the card "
                        "at address %d and %d bit/s?" % (slave.address, self.baud))
            return "%s; %s" % (reason, hint)
        extra = "; diag: %s" % diag_words(diag) if diag is not None else ""
        return reason + extra
