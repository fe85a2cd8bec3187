"""The keyboard jog's logic (vr_driver.terminal.jog) without a terminal: keys in, targets out."""
from __future__ import annotations

import math

import pytest

from vr_driver.terminal.jog import LIMIT_MARGIN, SPEEDS, Jogger, decode_keys

NAMES = tuple("joint_%d" % i for i in range(1, 7))
LOWER = (-2.705, -1.745, -3.0, -3.316, -4.712, -6.28)
UPPER = (2.705, 2.618, 1.3, 4.712, 4.712, 6.28)
HOME = [0.0, 0.6, -0.3, 0.0, 0.4, 0.0]


@pytest.fixture
def jog():
    return Jogger(NAMES, LOWER, UPPER, rate=20.0)


def test_decode_keys_arrows_and_controls():
    assert decode_keys("\x1b[A\x1b[B\x1b[C\x1b[D") == ["up", "down", "right", "left"]
    assert decode_keys("2+ q\x03\x04") == ["2", "+", " ", "q", "ctrl-c", "ctrl-d"]
    assert decode_keys("\x1bOC") == ["right"]


def test_nothing_is_published_while_holding(jog):
    assert jog.tick(HOME) == (None, "")
    jog.key("3")
    assert jog.tick(HOME) == (None, "")


def test_plus_moves_the_selected_joint_at_the_jog_speed_from_the_arm(jog):
    jog.key("2")
    assert "joint_2 +" in jog.key("+")
    step = math.radians(SPEEDS[jog.speed_index]) / 20.0
    t1, _ = jog.tick(HOME)
    t2, _ = jog.tick([9.0] * 6)                 # later joint_states do not reset a running move
    assert t1 == pytest.approx([0.0, 0.6 + step, -0.3, 0.0, 0.4, 0.0])
    assert t2 == pytest.approx([0.0, 0.6 + 2 * step, -0.3, 0.0, 0.4, 0.0])


def test_space_stops_and_the_next_move_starts_from_the_arm(jog):
    jog.key("+")
    jog.tick(HOME)
    assert jog.key(" ") == "stop: holding"
    assert jog.tick(HOME) == (None, "")
    jog.key("-")
    arm = [0.1, 0.6, -0.3, 0.0, 0.4, 0.0]
    t, _ = jog.tick(arm)
    assert t[0] == pytest.approx(0.1 - math.radians(SPEEDS[jog.speed_index]) / 20.0)


def test_the_reverse_key_stops_first(jog):
    jog.key("+")
    assert "stop" in jog.key("-")
    assert jog.tick(HOME) == (None, "")


def test_speed_steps_are_bounded(jog):
    for _ in range(20):
        jog.key("]")
    assert jog.speed == pytest.approx(math.radians(SPEEDS[-1]))
    for _ in range(20):
        jog.key("down")
    assert jog.speed == pytest.approx(math.radians(SPEEDS[0]))


def test_a_joint_stops_short_of_its_limit(jog):
    jog.key("1")
    for _ in range(6):
        jog.key("]")                            # 45 deg/s
    jog.key("+")
    q = [UPPER[0] - LIMIT_MARGIN - 0.01] + HOME[1:]
    t, line = jog.tick(q)
    assert t[0] == pytest.approx(UPPER[0] - LIMIT_MARGIN) and "limit" in line
    assert jog.tick(q) == (None, "")            # holding


def test_selecting_a_joint_holds(jog):
    jog.key("+")
    jog.tick(HOME)
    assert "joint_4 selected" in jog.key("4")
    assert jog.tick(HOME) == (None, "")
    assert jog.key("7") == "" and jog.joint == 3


def test_no_joint_states_no_motion(jog):
    jog.key("+")
    t, line = jog.tick(None)
    assert t is None and "no joint_states" in line
    assert jog.direction == 0


@pytest.mark.parametrize("key", ["q", "ctrl-c", "ctrl-d"])
def test_quit_keys(jog, key):
    jog.key("+")
    assert jog.key(key) == "quit" and jog.done and jog.tick(HOME) == (None, "")


def test_hold_to_run_a_move_stops_when_its_key_stops_repeating():
    jog = Jogger(NAMES, LOWER, UPPER, rate=20.0, hold=0.6)
    assert "+" in jog.key("+", now=10.0)
    t1, _ = jog.tick(HOME, now=10.05)
    assert t1 is not None and t1[0] > HOME[0]
    assert jog.key("+", now=10.5) == ""               # the terminal repeats the held key: keep moving
    t2, _ = jog.tick(HOME, now=11.0)
    assert t2 is not None and t2[0] > t1[0]
    target, line = jog.tick(HOME, now=11.2)           # 0.7 s after the last repeat: released
    assert target is None and "key released" in line and jog.direction == 0
    assert jog.tick(HOME, now=11.25) == (None, "")


def test_hold_0_latches_the_move():
    jog = Jogger(NAMES, LOWER, UPPER, rate=20.0, hold=0.0)
    jog.key("+", now=0.0)
    t, _ = jog.tick(HOME, now=100.0)
    assert t is not None and jog.direction == 1
