"""One reader of integers in text inside pyprofibus_vendor (_cli.int_or_none): the command line,
the GSD parser and INI configurations use it, with the same rules."""
import argparse
import os
import sys

import pytest

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "src"))

from pyprofibus_vendor import _cli, gsd  # noqa: E402
from pyprofibus_vendor.config import _ini_value  # noqa: E402


@pytest.mark.parametrize("text, signed, expected", [
    ("12", False, 12), (" 0x1F ", False, 31), ("0X10", False, 16), ("-12", False, None), ("-12", True, -12),
    ("-0x10", True, -16), ("1_000", False, None), ("١٢", False, None), ("12.0", False, None), ("", True, None),
])
def test_int_or_none(text, signed, expected):
    assert _cli.int_or_none(text, signed) == expected


def test_gsd_cli_and_ini_share_it():
    assert gsd._parse_int is _cli.int_or_none
    assert _cli.parse_int(" 0x7F ") == 127
    with pytest.raises(argparse.ArgumentTypeError, match="'-3' is not a number"):
        _cli.parse_int("-3")
    assert _ini_value("baud", "0x4B00") == 19200 and _ini_value("baud", "-5") == -5
    assert _ini_value("baud", "fast") == "fast"          # left as text: from_dict names the key
