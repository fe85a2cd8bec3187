"""The link supervisor's parts on their own, stepped by hand: Reopening (driver/link/link_port.py: when
the port is opened again; a port that cannot be opened is a warning, then once an error after
PORT_ERROR_AFTER) and CardDiagnosis (driver/link/card_diagnosis.py: why the controller's card is not in
Data_Exchange, logged once for each kind of failure). The supervisor with both is tested in
test_core_stepped.py and, on a pty with real faults, in test_port_faults.py."""
from __future__ import annotations

import logging
from types import SimpleNamespace

from vr_driver.driver.link.card_diagnosis import CardDiagnosis
from vr_driver.driver.link.link_port import PORT_ERROR_AFTER, Reopening

LOGGER = "vr_driver.driver"


def messages(caplog, level):
    return [r.getMessage() for r in caplog.records if r.name == LOGGER and r.levelno == level]


def test_reopening_is_due_at_once_then_a_period_after_each_failure():
    reopen = Reopening(0.5)
    assert reopen.due(0.0)
    reopen.later(10.0)
    assert not reopen.due(10.49) and reopen.due(10.5)


def test_a_missing_port_is_a_warning_then_one_error_after_port_error_after(caplog):
    caplog.set_level(logging.INFO, logger=LOGGER)
    reopen = Reopening(0.5)
    missing = FileNotFoundError(2, "No such file or directory")
    reason, now, last = "", 100.0, "not started"
    while now < 100.0 + 3 * PORT_ERROR_AFTER:
        reason = reopen.cannot_open(now, "/dev/ttyX", missing, last)
        assert reopen.next_open == now + 0.5
        last, now = reason, now + 0.5
    assert reason.startswith("cannot open /dev/ttyX: ") and "No such file" in reason
    assert messages(caplog, logging.WARNING) == ["%s (retrying every 0.5 s)" % reason]
    errors = messages(caplog, logging.ERROR)
    assert errors == ["%s for %.0f s now (still retrying every 0.5 s)" % (reason, PORT_ERROR_AFTER)]
    # another reason is news again: a warning at once, its own error after PORT_ERROR_AFTER
    denied = PermissionError(13, "Permission denied")
    reason = reopen.cannot_open(now, "/dev/ttyX", denied, last)
    assert "read and write access" in reason
    assert messages(caplog, logging.WARNING)[-1] == "%s (retrying every 0.5 s)" % reason
    for k in range(1, 12):
        reopen.cannot_open(now + 0.5 * k, "/dev/ttyX", denied, reason)
    assert len(messages(caplog, logging.ERROR)) == 2


def _master(garbage=0, fcs=0):
    return SimpleNamespace(counters=SimpleNamespace(garbage_bytes=garbage, fcs_errors=fcs))


def _slave(address=6):
    return SimpleNamespace(address=address, last_diag=None)


def test_no_reply_says_garbled_only_when_bytes_came_since_the_last_good_record():
    card = CardDiagnosis(SimpleNamespace(ident=0x06C6, cfg=b"\x13"), 187500)
    master = _master(garbage=40)
    card.attempt_failed(_slave(), "no reply to FDL_Status", master)
    assert card.reason.startswith("controller's PROFIBUS card (slave 6): no reply to FDL_Status; ")
    assert "form no valid telegram" in card.reason
    card.attempt_failed(_slave(), "no reply to FDL_Status", master)       # nothing new garbled
    assert "nothing valid received" in card.reason and "187500 bit/s" in card.reason
    card.good_record(_master(garbage=45, fcs=1))
    card.attempt_failed(_slave(), "no reply to FDL_Status", _master(garbage=45, fcs=1))
    assert "nothing valid received" in card.reason
    card.link_up()
    assert card.reason == ""


def test_each_kind_of_failure_is_logged_once_until_data_exchange(caplog):
    caplog.set_level(logging.INFO, logger=LOGGER)
    card = CardDiagnosis(SimpleNamespace(ident=0x06C6, cfg=b"\x13"), 187500)
    for address in (6, 6, 7):                 # another number is not another kind
        card.attempt_failed(_slave(address), "no reply to FDL_Status", None)
    assert len(messages(caplog, logging.WARNING)) == 1
    card.attempt_failed(_slave(), "timeout in Set_Prm", None)
    assert len(messages(caplog, logging.WARNING)) == 2
    card.data_exchange()
    card.attempt_failed(_slave(), "timeout in Set_Prm", None)
    assert messages(caplog, logging.WARNING)[-1] == card.reason
    assert len(messages(caplog, logging.WARNING)) == 3
