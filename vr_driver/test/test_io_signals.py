"""The signal map of the I/O stations (vr_driver.io_signals): every bad entry is refused with an error
naming the station and key; every type packs and unpacks, at both byte orders; values given as text
are parsed per type and refused when they do not fit."""
from __future__ import annotations

import copy
import os
import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vr_driver.errors import SignalMapError
from vr_driver.io_signals import TYPES, Signal, SignalMap, lengths_from_bus, load_signal_map

CONFIG = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "config")
LENGTHS = {8: (2, 2), 9: (8, 8)}


def station(signals, address=8, name="island"):
    return {"stations": {name: {"address": address, "signals": signals}}}


GOOD = {
    "gripper_close": {"direction": "out", "type": "bit", "byte": 0, "bit": 0, "safe": 0},
    "gripper_closed": {"direction": "in", "type": "bit", "byte": 0, "bit": 0},
    "part_present": {"direction": "in", "type": "bit", "byte": 0, "bit": 1},
    "lamp": {"direction": "out", "type": "uint8", "byte": 1, "safe": 3},
}


def test_a_good_map_and_its_safe_image():
    m = SignalMap.from_dict(station(GOOD), LENGTHS)
    assert [s.name for s in m.signals] == list(GOOD)
    assert m.signal("lamp").safe == 3 and m.signal("gripper_closed").safe is None
    assert m.signal("nope") is None
    assert m.stations[0].safe_image() == b"\x00\x03"
    assert [s.name for s in m.stations[0].outputs] == ["gripper_close", "lamp"]


def test_the_shipped_example_names_exactly_the_island_signals():
    from pyprofibus_vendor.config import load_config
    bus = load_config(os.path.join(CONFIG, "io_line_bus.yaml"))
    assert [(s.name, s.address) for s in bus.slaves] == [("vr006l", 4), ("io_island", 8)]
    m = load_signal_map(os.path.join(CONFIG, "io_island_signals.yaml"), lengths_from_bus(bus))
    assert {(s.name, s.direction, s.type, s.byte, s.bit) for s in m.signals} == {
        ("gripper_close", "out", "bit", 0, 0), ("gripper_closed", "in", "bit", 0, 0),
        ("part_present", "in", "bit", 0, 1)}


def _bad(signal_changes=None, remove=(), extra=None, name="gripper_close"):
    signals = copy.deepcopy(GOOD)
    body = signals[name]
    body.update(signal_changes or {})
    for key in remove:
        body.pop(key)
    signals.update(extra or {})
    return station(signals)


BAD_ENTRIES = [
    # (map, words the message must contain)
    (_bad({"typ": "bit"}), ["station 'island' signal 'gripper_close' key 'typ'", "unknown key"]),
    (_bad({"type": "bool"}), ["key 'type'", "'bool' is not one of bit, uint8"]),
    (_bad({"direction": "inout"}), ["key 'direction'", "not one of in, out"]),
    (_bad(remove=("type",)), ["key 'type'", "required key is missing"]),
    (_bad(remove=("byte",)), ["key 'byte'", "required key is missing"]),
    (_bad(remove=("direction",)), ["key 'direction'", "required key is missing"]),
    (_bad({"byte": -1}), ["key 'byte'", "offset >= 0"]),
    (_bad({"byte": "0"}), ["key 'byte'", "offset >= 0"]),
    (_bad({"byte": 2}), ["key 'byte'", "past the end", "2-byte output image"]),
    (_bad({"type": "int16", "byte": 1, "safe": 0}, remove=("bit",)), ["key 'byte'", "bytes 1..2", "past the end"]),
    (_bad(remove=("bit",)), ["key 'bit'", "needs its bit offset"]),
    (_bad({"bit": 8}), ["key 'bit'", "expected 0..7"]),
    (_bad({"bit": True}), ["key 'bit'", "expected 0..7"]),
    (_bad({"type": "uint8", "bit": 3}), ["key 'bit'", "only a signal of type bit"]),
    (_bad({"byte_order": "big"}), ["key 'byte_order'", "1-byte bit has no byte order"]),
    (_bad({"type": "int16", "byte_order": "middle"}, remove=("bit",)), ["key 'byte_order'", "not one of big, little"]),
    (_bad({"safe": 2}), ["key 'safe'", "2 does not fit bit (0..1)"]),
    (_bad({"safe": "0"}), ["key 'safe'", "expected an integer"]),
    (_bad({"type": "uint8", "safe": -1}, remove=("bit",)), ["key 'safe'", "-1 does not fit uint8 (0..255)"]),
    (_bad({"safe": 0}, name="gripper_closed"), ["signal 'gripper_closed' key 'safe'", "only outputs"]),
    (_bad(extra={"lamp2": {"direction": "out", "type": "bit", "byte": 1, "bit": 0}}),
     ["signal 'lamp2'", "overlaps signal 'lamp'", "output image at byte 1 bit 0"]),
    (_bad(extra={"sensor": {"direction": "in", "type": "bit", "byte": 0, "bit": 1}}),
     ["signal 'sensor'", "overlaps signal 'part_present'", "input image at byte 0 bit 1"]),
    (_bad(extra={"9lives": {"direction": "in", "type": "bit", "byte": 1, "bit": 0}}),
     ["signal '9lives'", "a letter followed"]),
    (_bad(extra={"raw": "in"}), ["signal 'raw'", "expected a mapping"]),
    ({"stations": {"island": {"address": 7, "signals": GOOD}}}, ["station 'island' key 'address'", "no slave 7",
                                                                 "have 8, 9"]),
    ({"stations": {"island": {"address": "8", "signals": GOOD}}}, ["key 'address'", "expected the station's DP address"]),
    ({"stations": {"island": {"address": 8, "signals": {}}}}, ["key 'signals'", "expected a mapping"]),
    ({"stations": {"island": {"address": 8, "signals": GOOD, "gsd": "x"}}}, ["station 'island' key 'gsd'", "unknown key"]),
    ({"stations": {"island": {"address": 8, "signals": GOOD},
                   "other": {"address": 9, "signals": {"lamp": {"direction": "out", "type": "uint8", "byte": 0}}}}},
     ["station 'other' signal 'lamp'", "duplicate signal name", "already in station 'island'"]),
    ({"stations": {"island": {"address": 8, "signals": GOOD},
                   "again": {"address": 8, "signals": {"x": {"direction": "out", "type": "uint8", "byte": 0}}}}},
     ["station 'again' key 'address'", "already station 'island'"]),
    ({"stations": {}}, ["'stations'"]),
    ({"station": {}}, ["exactly one top-level key 'stations'"]),
    ([], ["exactly one top-level key 'stations'"]),
]


@pytest.mark.parametrize("data, words", BAD_ENTRIES)
def test_every_bad_entry_is_refused_naming_station_and_key(data, words):
    with pytest.raises(SignalMapError) as err:
        SignalMap.from_dict(data, LENGTHS)
    for word in words:
        assert word in str(err.value)


def test_a_file_with_a_duplicate_key_is_refused(tmp_path):
    path = tmp_path / "signals.yaml"
    path.write_text("stations:\n  island:\n    address: 8\n    signals:\n"
                    "      lamp: {direction: out, type: uint8, byte: 1}\n"
                    "      lamp: {direction: out, type: uint8, byte: 0}\n")
    with pytest.raises(SignalMapError, match="signals.lamp.*duplicate key"):
        load_signal_map(str(path), LENGTHS)
    with pytest.raises(SignalMapError, match="signal map .*missing.yaml"):
        load_signal_map(str(tmp_path / "missing.yaml"), LENGTHS)


def sig(type_name, byte=0, order="big", direction="out", bit=None):
    return Signal("s", "st", 9, direction, type_name, byte, 0 if type_name == "bit" and bit is None else bit, order)


RANGES = {"bit": (0, 1), "uint8": (0, 255), "int16": (-32768, 32767), "uint16": (0, 65535),
          "int32": (-2 ** 31, 2 ** 31 - 1)}


@pytest.mark.parametrize("type_name", sorted(RANGES))
def test_integer_types_take_their_range_and_refuse_beyond(type_name):
    lo, hi = RANGES[type_name]
    s = sig(type_name)
    assert s.check(lo) == lo and s.check(hi) == hi
    for bad in (lo - 1, hi + 1):
        with pytest.raises(SignalMapError, match="does not fit %s" % type_name):
            s.check(bad)
    for bad in ("1", None, 1.5):
        with pytest.raises(SignalMapError):
            s.check(bad)
    assert s.parse(str(hi)) == hi and s.parse(" %d " % lo) == lo
    for text in (str(hi + 1), str(lo - 1), "1.5", "one", "", "1e3"):
        with pytest.raises(SignalMapError):
            s.parse(text)


def test_bit_text_forms_and_hex_integers():
    b = sig("bit")
    assert [b.parse(t) for t in ("1", "true", "ON", "high", "0", "False", "off", "low")] == [1, 1, 1, 1, 0, 0, 0, 0]
    assert b.check(True) == 1 and b.check(False) == 0
    assert sig("uint16").parse("0x1F") == 31 and sig("int16").parse("-0x10") == -16
    with pytest.raises(SignalMapError, match="expected an integer"):
        sig("uint8").check(True)


def test_float32_values():
    f = sig("float32")
    assert f.parse("1.5") == 1.5
    assert f.check(0.1) == struct.unpack(">f", struct.pack(">f", 0.1))[0]       # rounded to single
    for bad in ("nan", "inf", "-inf", "1e39", "x", ""):
        with pytest.raises(SignalMapError):
            f.parse(bad)
    with pytest.raises(SignalMapError, match="expected a number"):
        f.check(True)
    assert f.format(2) == "2.0" and sig("int16").format(-3) == "-3"


@settings(max_examples=200, deadline=None)
@given(type_name=st.sampled_from(sorted(TYPES)), order=st.sampled_from(["big", "little"]),
       byte=st.integers(0, 4), data=st.data(), image=st.binary(min_size=8, max_size=8))
def test_write_then_read_round_trips_and_touches_only_its_bits(type_name, order, byte, data, image):
    bit = data.draw(st.integers(0, 7)) if type_name == "bit" else None
    s = sig(type_name, byte, order, bit=bit)
    if type_name == "float32":
        value = data.draw(st.floats(width=32, allow_nan=False, allow_infinity=False))
    else:
        value = data.draw(st.integers(*RANGES[type_name]))
    buf = bytearray(image)
    s.write(buf, value)
    assert s.read(bytes(buf)) == value
    taken = set(s.bits())
    for i in range(8):
        for b in range(8):
            if (i, b) not in taken:
                assert (buf[i] >> b) & 1 == (image[i] >> b) & 1
    if type_name in ("int16", "uint16", "int32", "float32"):
        code = (">" if order == "big" else "<") + TYPES[type_name][0]
        assert bytes(buf[byte:byte + s.size]) == struct.pack(code, s.check(value))


def test_a_bad_value_changes_nothing_in_the_image():
    s = sig("uint8", 1)
    buf = bytearray(b"\x11\x22")
    with pytest.raises(SignalMapError):
        s.write(buf, 256)
    assert buf == b"\x11\x22"


def test_big_endian_is_the_default_and_matches_profibus_word_order():
    m = SignalMap.from_dict(station({"w": {"direction": "in", "type": "uint16", "byte": 0}}, address=9), LENGTHS)
    assert m.signal("w").read(b"\x12\x34" + bytes(6)) == 0x1234
