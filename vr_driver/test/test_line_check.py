"""bus.line_check: the measured cycle rate against cycle_rate and the likely cause, stepped with
made-up master counters (no clock, no line)."""
from __future__ import annotations

import logging

import pytest

from vr_driver.bus.line_check import LineCheck, line_time

EXCHANGES = [(24, 28), (2, 2)]          # v3's controller and the I/O island


def feed(check, rate, seconds, wait=0.0005, retry_share=0.0, garbage_per_retry=0.0, echo=False, connected=True):
    counters = dict(cycles=0, requests=0, retries=0, dx_timed=0, reply_wait=0.0, garbage_bytes=0, echoes=0)
    t = 0.0
    while t < seconds:
        t += 1.0 / rate
        counters["cycles"] += 1
        counters["requests"] += 2
        counters["dx_timed"] += 2
        counters["reply_wait"] += 2 * wait
        counters["retries"] = int(counters["requests"] * retry_share)
        counters["garbage_bytes"] = int(counters["retries"] * garbage_per_retry)
        counters["echoes"] += 2 if echo else 0
        check.update(t, counters, connected)
    return check.verdict()


def test_the_line_time_of_the_thesis_bus():
    # 19.2 kbit/s: 2 x 18 characters of framing + 56 data bytes, plus 2 x 44 bits
    assert line_time(19200, EXCHANGES) == pytest.approx((92 * 11 + 88) / 19200)
    assert 1 / line_time(19200, EXCHANGES) < 20.0      # the shipped rate of before could not be met


def test_a_rate_met_is_ok_and_says_nothing(caplog):
    check = LineCheck(19200, 15.0, EXCHANGES, window=5, hold=5)
    with caplog.at_level(logging.WARNING):
        v = feed(check, 15.0, 20)
    assert not v.slow and v.measured == pytest.approx(15.0, rel=0.05)
    assert caplog.text == ""


def test_the_adapters_latency_is_named_with_its_fix_once(caplog):
    check = LineCheck(19200, 15.0, EXCHANGES, window=5, hold=5)
    with caplog.at_level(logging.WARNING):
        v = feed(check, 11.0, 20, wait=0.008)
    assert v.slow and v.reply_wait == pytest.approx(0.008)
    assert "the USB adapter's latency: each reply reaches the driver 8.0 ms (mean)" in v.summary
    assert "latency timer at 1 ms and low-latency mode" in v.summary
    assert caplog.text.count("under the 15.0 asked") == 1
    with caplog.at_level(logging.INFO):
        feed(check, 15.0, 20)
    assert "back at" in caplog.text


def test_a_rate_the_line_cannot_give_names_the_line_and_a_cycle_rate_it_can():
    check = LineCheck(19200, 20.0, EXCHANGES, window=5, hold=5)
    v = feed(check, 16.0, 20)
    assert v.slow and "the line: at 19200 bit/s the telegrams of 2 stations take" in v.summary
    assert "cycle_rate 14 or less" in v.summary and "fewer stations" in v.summary


def test_resends_with_garbled_replies_name_the_turnaround_even_without_data_exchange():
    check = LineCheck(19200, 15.0, EXCHANGES, window=5, hold=5)
    v = feed(check, 8.0, 20, retry_share=0.3, garbage_per_retry=4)
    assert v.slow and "replies losing their first bytes (an adapter slow to turn" in v.summary
    v = feed(LineCheck(19200, 15.0, EXCHANGES), 8.0, 3, retry_share=0.5, garbage_per_retry=5, connected=False)
    assert v.summary.startswith("not in Data_Exchange: 50 % of the requests resent")


def test_the_echo_is_said_as_the_adapters(caplog):
    check = LineCheck(19200, 15.0, EXCHANGES)
    with caplog.at_level(logging.WARNING):
        v = feed(check, 15.0, 6, echo=True)
    assert "the adapter echoes its transmission (%d frames)" % v.echoes in v.summary
    assert caplog.text.count("the adapter echoes its transmission") == 1
