"""The virtual line's bit rate as a UART sees it (vr_driver.controller.line_rate.resample): equal rates
pass every byte, and between any two different standard rates no telegram survives -- a master off the
stations' rate is never answered. The pty side (tty_speed, the hub) runs in test_scan_line.py."""
from __future__ import annotations

import itertools

import pytest

from pyprofibus_vendor.dp import Sap, request_frame
from pyprofibus_vendor.fdl import Deframer, FrameControl, RequestFunction, Sd1
from pyprofibus_vendor.gsd import STANDARD_BAUDRATES

from vr_driver.controller.line_rate import resample

#: the rates a USB RS-485 adapter commonly offers (up to 1.5 Mbit/s: the faster ones' bursts take long to play)
RATES = tuple(r for r in STANDARD_BAUDRATES if r <= 1_500_000)
TELEGRAMS = [Sd1(a, 0, FrameControl.req(RequestFunction.FDL_STATUS)).encode() for a in (1, 6, 9, 125)] + [
    request_frame(6, 0, True, False, Sap.SLAVE_DIAG).encode(), request_frame(9, 0, True, False, Sap.GET_CFG).encode()]


def test_equal_rates_carry_every_byte():
    data = bytes(range(256))
    for rate in STANDARD_BAUDRATES:
        assert resample(data, rate, rate) == data


@pytest.mark.parametrize("tx, rx", list(itertools.permutations(RATES, 2)))
def test_no_telegram_crosses_two_different_rates(tx, rx):
    for raw in TELEGRAMS:
        got = resample(raw, tx, rx)
        assert got != raw
        deframer = Deframer()
        assert deframer.feed(got) == [], (tx, rx, raw.hex(" "), got.hex(" "))


def test_a_receiver_at_half_the_rate_reads_no_start_bit_in_0xff():
    # worked by hand: 0xFF at 19200 is start bit 0, eight 1s, parity 0, stop 1 (sender's bit T); a
    # 9600 receiver finds the start edge and samples its start bit at 1 T -- in data bit 0, high: no
    # start bit. The next low level, the parity bit, is sampled at its end, in the stop bit: none again
    assert resample(b"\xff", 19200, 9600) == b""
    # the other way round, 0xFF at 9600 read at 19200 (receiver's bit T, sender's 2 T): start sampled at
    # 0.5 T (low), data bits at 1.5 .. 8.5 T read the sender's start, d0, d0, d1, d1, d2, d2, d3 ->
    # 0 1 1 1 1 1 1 1 = 0xFE; parity at 9.5 T reads d3 (1: even over seven ones, right); stop at 10.5 T
    # reads d4 (1): a valid character, and a wrong one
    assert resample(b"\xff", 9600, 19200)[:1] == b"\xfe"
