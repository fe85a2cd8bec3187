"""The USB adapter's behaviours on the virtual line (controller.adapter_model), over REAL ptys: the
virtual controller behind the line hub paced at 19.2 kbit/s, our DP master on the hub's pty, the
driver's line check (bus.line_check) fed its counters. A 16 ms latency timer with echo: the link
holds, the echo is counted as the adapter's and the replies' wait is seen; a slow turnaround that
loses a prompt reply's first bytes: resends counted and said with their cause. Waiting is on bus
cycles (the master blocks in the link); nothing sleeps to synchronise."""
from __future__ import annotations

import logging
import time

import pytest

from pyprofibus_vendor.config import ROBOT_IDENT, default_robot_config
from pyprofibus_vendor.dp_master import DpMaster, MasterSlaveState, SlaveSpec
from pyprofibus_vendor.phy_serial import SerialLink

from vr_driver.bus.line_check import LineCheck
from vr_driver.controller.adapter_model import AdapterBehaviour, AdapterModel
from vr_driver.controller.line import LineHub
from vr_driver.controller.virtual_controller import VirtualController

BAUD = 19200
ROBOT_CFG = default_robot_config("virtual", phy_type="memory").slave(4).cfg


def test_the_model_holds_bytes_for_its_timer_echoes_and_loses_a_prompt_replys_first_bytes():
    m = AdapterModel(AdapterBehaviour(latency_ms=16, echo=True, turnaround_ms=1.0))
    assert m.sent(b"\x10\x04\x02\x49\x4f\x16", end=0.100) == b"\x10\x04\x02\x49\x4f\x16"
    char = 11.0 / BAUD
    assert m.heard(b"\x10\x02\x04\x00\x06\x16", start=0.1002, char_time=char) == b"\x04\x00\x06\x16"
    assert m.counters.lost == 2
    assert m.heard(b"\xe5", start=0.102, char_time=char) == b"\xe5"       # the receiver listens again
    assert m.hold(b"abc", 0.101) == b""                    # held until the timer's next expiry
    assert m.next_due() == pytest.approx(0.112)
    assert m.due(0.111) == b"" and m.due(0.112) == b"abc"
    assert m.hold(bytes(70), 0.2) == bytes(62)             # a full USB packet goes at once
    assert m.due(0.2081) == bytes(8)
    with pytest.raises(ValueError, match="latency_ms"):
        AdapterBehaviour(latency_ms=300)


@pytest.fixture
def line(tmp_path):
    made = []

    def make(**adapter):
        g2 = VirtualController(pty_link=str(tmp_path / "g2"), baud=BAUD).start()
        hub = LineHub([str(tmp_path / "g2")], pty_link=str(tmp_path / "line"), baud=BAUD,
                      adapter=AdapterBehaviour(**adapter)).start()
        link = SerialLink(str(tmp_path / "line"), BAUD)
        master = DpMaster(link, 2, BAUD, dx_tolerance=0.5, retry_steps=True, backoff_max=0.3)
        robot = master.add_slave(SlaveSpec(4, ROBOT_IDENT, ROBOT_CFG, watchdog=0.3))
        made.extend([master, hub, g2])
        check = LineCheck(BAUD, 20.0, [(robot.spec.output_size, robot.spec.input_size)], link.adapter,
                          window=2.0, hold=1.0)
        return master, robot, hub, check
    yield make
    for thing in made:
        (thing.close if isinstance(thing, DpMaster) else thing.stop)()


def run(master, robot, check, seconds):
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        master.cycle(timeout=1.0)
        check.update(time.monotonic(), vars(master.counters), robot.state is MasterSlaveState.DATA_EXCHANGE)


def test_latency_timer_and_echo_the_link_holds_and_both_are_said(line, caplog):
    master, robot, hub, check = line(latency_ms=16, echo=True)
    deadline = time.monotonic() + 10.0
    while not robot.connected:
        assert time.monotonic() < deadline, "no Data_Exchange through the adapter"
        master.cycle(timeout=1.0)
    c = master.counters
    before = (c.requests, c.retries, c.echoes, c.unexpected_frames)
    with caplog.at_level(logging.INFO, logger="vr_driver.driver"):
        run(master, robot, check, 4.0)
    assert robot.connected and c.losses == 0
    # every transmission's echo (a request's, a resend's) recognised: read before its reply, behind an
    # earlier try's late reply, or among the stale bytes the next request's TSYN drops. Uncounted only
    # those still in the adapter when the run stops: the last turn's transmissions after the one whose
    # late reply ended it, or all of a turn ended without a reply (tolerated): at most 1 + max_retry
    sent = c.requests - before[0] + c.retries - before[1]
    assert sent > 0 and c.echoes - before[2] >= sent - 1 - master.timing.max_retry, (sent, c)
    assert c.unexpected_frames == before[3]                     # none taken for another station's
    v = check.verdict()
    assert v.reply_wait is not None and v.reply_wait > 0.004          # the timer's hold, seen
    assert "the adapter echoes its transmission" in caplog.text
    assert "the adapter echoes its transmission (%d frames)" % v.echoes in v.summary
    assert hub.adapter.counters.echoed > 0


def test_a_slow_turnaround_is_resent_and_said_or_fails_naming_the_cause(line, caplog):
    master, robot, hub, check = line(turnaround_ms=1.0)
    with caplog.at_level(logging.WARNING, logger="vr_driver.driver"):
        run(master, robot, check, 5.0)
    assert hub.adapter.counters.lost > 0
    c = master.counters
    assert c.retries > 0 and c.garbage_bytes > 0
    v = check.verdict()
    if robot.connected:           # the link holds: the resends are counted and, when they slow it, said
        assert c.retries > 0
        assert not v.slow or "replies losing their first bytes" in v.summary
    else:                         # it fails: the error names the cause
        assert "replies losing their first bytes (an adapter slow to turn its receiver on" in v.summary
        assert "replies losing their first bytes" in caplog.text
