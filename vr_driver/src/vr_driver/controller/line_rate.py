"""The bit rate of the virtual line (:mod:`vr_driver.controller.line`): what a master whose port is set
to another rate than the stations' meets on a real RS-485 line. ROS-free.

A pty carries bytes, not bits: whatever rate a master sets on it, the bytes arrive intact. On a wire
each character is a start bit, 8 data bits (LSB first), an even parity bit and a stop bit (PROFIBUS'
11-bit 8E1 character) at the sender's bit time, and a receiver at another rate samples them at its
own: :func:`resample` plays that, bit by bit. The receiver waits for a low level (the start bit),
samples the middle of each of its 11 bit times from there, and drops a character whose stop bit
reads low (a framing error) or whose parity is wrong (a UART with parity checking, as
:class:`~pyprofibus_vendor.phy_serial.SerialLink` sets up real ports); the others it delivers, right
or wrong. Equal rates deliver every byte unchanged. A master off the stations' rate thus gets no
reply (its requests reach them as a few wrong characters, if any) -- as on the wire, not by a rule.

:func:`tty_speed` reads the rate a program set on a pty (pyserial sets non-standard rates such as
93750 through ``termios2``; the pty keeps the number), from either end of the pair.
"""
from __future__ import annotations

import array
import fcntl
import sys
import termios
from typing import Dict, Optional

__all__ = ["CHAR_BITS", "resample", "tty_speed"]

#: bits of a PROFIBUS character: start, 8 data, even parity, stop
CHAR_BITS = 11

# Linux asm-generic _IOR('T', 0x2A, struct termios2): the ioctl pyserial sets custom rates with
_TCGETS2 = 0x802C542A
_BOTHER = 0o010000
# struct termios2: 4 flag words, c_line and 19 c_cc bytes (36 bytes), then c_ispeed, c_ospeed
_OSPEED_INDEX = 10

_SPEEDS: Dict[int, int] = {getattr(termios, "B%d" % rate): rate for rate in (
    50, 75, 110, 134, 150, 200, 300, 600, 1200, 1800, 2400, 4800, 9600, 19200, 38400, 57600, 115200,
    230400, 460800, 500000, 576000, 921600, 1000000, 1152000, 1500000, 2000000, 2500000, 3000000,
    3500000, 4000000) if hasattr(termios, "B%d" % rate)}


def tty_speed(fd: int) -> Optional[int]:
    """The output bit rate set on the tty ``fd`` (a pty: either end), or None when it cannot be read."""
    try:
        attrs = termios.tcgetattr(fd)
    except (termios.error, OSError):
        return None
    speed = attrs[5]
    if speed in _SPEEDS:
        return _SPEEDS[speed]
    if speed == _BOTHER and sys.platform.startswith("linux"):
        buf = array.array("i", [0] * 64)
        try:
            fcntl.ioctl(fd, _TCGETS2, buf)
        except OSError:
            return None
        return buf[_OSPEED_INDEX] or None
    return None


def _char_bits(byte: int) -> list:
    data = [(byte >> i) & 1 for i in range(8)]
    return [0] + data + [sum(data) & 1, 1]


def resample(data: bytes, tx_rate: int, rx_rate: int) -> bytes:
    """The bytes a UART at ``rx_rate`` receives from ``data`` sent back to back at ``tx_rate`` (see
    the module docstring). Exact integer time: the unit is 1 / (2 tx_rate rx_rate) s, so a sender's
    bit lasts 2 rx_rate units and a receiver's 2 tx_rate."""
    if tx_rate == rx_rate or not data:
        return bytes(data)
    bits = [b for byte in data for b in _char_bits(byte)]
    tx_bit, rx_bit = 2 * rx_rate, 2 * tx_rate
    end = len(bits) * tx_bit

    def level(t: int) -> int:
        k = t // tx_bit
        return bits[k] if k < len(bits) else 1              # idle after the last character: high

    out = bytearray()
    t = 0
    while t < end:
        if level(t):                                           # wait for the next low level
            k = -(-t // tx_bit)
            while k < len(bits) and bits[k]:
                k += 1
            if k >= len(bits):
                break
            t = k * tx_bit
        samples = [level(t + i * rx_bit + rx_bit // 2) for i in range(CHAR_BITS)]
        if samples[0]:                                         # a glitch, not a start bit
            t += rx_bit // 2 + 1
            continue
        value = sum(bit << i for i, bit in enumerate(samples[1:9]))
        if samples[10] and samples[9] == sum(samples[1:9]) & 1:
            out.append(value)                                  # framing and parity right
        t += (CHAR_BITS - 1) * rx_bit + rx_bit // 2           # ready again after the stop bit's middle
    return bytes(out)
