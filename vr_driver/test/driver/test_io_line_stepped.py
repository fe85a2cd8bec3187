"""The I/O stations beside the controller, stepped: our DP master cycles the virtual controller's slave
(4) and the virtual I/O island (8) over one in-memory multi-drop link with a fake clock, one thread;
:class:`IoLine` judges the island after every cycle. No pty, no threads, no sleeps."""
from __future__ import annotations

import os
from typing import Callable, Optional, Set

import pytest

from pyprofibus_vendor.config import load_config
from pyprofibus_vendor.dp_master import DpMaster, SlaveSpec
from pyprofibus_vendor.dp_slave import SlaveState

from vr_driver.controller.virtual_controller import robot_slave
from vr_driver.driver.link.stations import IoLine
from vr_driver.errors import SignalMapError
from vr_driver.controller.io_island import GRIPPER_DELAY, IslandProgram, island_slave
from vr_driver.io_signals import SignalMap, lengths_from_bus, load_signal_map

from _world import FakeClock, SteppedLink

CONFIG = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "config")
BUS = load_config(os.path.join(CONFIG, "io_line_bus.yaml"))
SIGNALS = load_signal_map(os.path.join(CONFIG, "io_island_signals.yaml"), lengths_from_bus(BUS))
PERIOD = 0.05           # the bus cycle (20 Hz, as the default launch)
INPUT_TIMEOUT = 0.5     # the driver's link_timeout


class LineLink(SteppedLink):
    """The multi-drop line in memory: every telegram reaches every plugged station."""

    def __init__(self, slaves, clock: FakeClock) -> None:
        super().__init__(slaves, clock)
        self.unplugged: Set[int] = set()

    def respond(self, frame):
        reply = None
        for slave in self.slaves:
            if slave.address in self.unplugged:
                continue
            r = slave.handle(frame, self.clock())
            if r is not None and reply is None:
                reply = r
        return None if reply is None else reply.encode()


class Line:
    def __init__(self, dx_tolerance: float = INPUT_TIMEOUT) -> None:
        self.clock = FakeClock()
        self.robot = robot_slave(clock=self.clock)
        self.island = island_slave(clock=self.clock)
        self.program = IslandProgram(self.island)
        self.link = LineLink([self.robot, self.island], self.clock)
        self.master = DpMaster(self.link, BUS.master_address, BUS.baud, clock=self.clock,
                               dx_tolerance=dx_tolerance, retry_steps=True, backoff_max=0.5)
        self.robot_handle = self.master.add_slave(SlaveSpec.from_config(BUS.slave(4)))
        self.io = IoLine(SIGNALS, INPUT_TIMEOUT)
        self.io.add_slaves(self.master, BUS)
        self.handle = self.master.slave(8)
        self.robot_dropped = False
        self.silent = False          # the master does not cycle (the driver's process stopped)

    @property
    def now(self) -> float:
        return self.clock.t

    def tick(self) -> None:
        """One bus period: the island's program loop, one DP cycle, the judgement."""
        start = self.clock.t
        self.program.step(self.now)
        self.robot.step(self.now)
        if not self.silent:
            self.master.cycle(timeout=1.0)
        self.robot_dropped |= not self.robot_handle.connected and self.robot_handle.was_connected
        if self.clock.t < start + PERIOD:
            self.clock.t = start + PERIOD
        self.program.step(self.now)
        self.io.update(self.now)

    @property
    def snap(self):
        return self.io.snapshot()

    def run_until(self, pred: Callable[[], bool], timeout: float, what: str) -> float:
        start = self.now
        while not pred():
            assert self.now - start <= timeout, "%s not within %.2f s; %s" % (what, timeout, self.snap)
            self.tick()
        return self.now - start

    def value(self, name: str) -> Optional[float]:
        sig = self.snap.signal(name)
        assert sig is not None
        return sig.value

    def online(self) -> bool:
        st = self.snap.station("io_island")
        return st is not None and st.online

    def up(self) -> None:
        self.run_until(lambda: self.online() and self.robot_handle.connected, 3.0, "both stations online")


@pytest.fixture
def line() -> Line:
    line = Line()
    line.up()
    return line


def test_offline_before_data_exchange_then_every_signal_online():
    line = Line()
    assert [s.value for s in line.snap.signals] == [None, None, None]
    assert not line.online()
    line.up()
    assert {s.name: s.value for s in line.snap.signals} == {"gripper_close": 0, "gripper_closed": 0,
                                                           "part_present": 0}
    assert all(s.online for s in line.snap.signals)
    assert line.snap.station("io_island").dp_state == "DATA_EXCHANGE"
    assert line.io.read("gripper_closed").value == "0"


def test_gripper_closed_follows_gripper_close_after_the_delay(line):
    result = line.io.write("gripper_close", "1")
    assert result.success, result.message
    assert line.handle.outputs == b"\x01\x00"          # in the image the next cycle sends
    assert line.value("gripper_close") == 1
    t0 = line.now
    took = line.run_until(lambda: line.value("gripper_closed") == 1, 1.0, "gripper_closed")
    assert GRIPPER_DELAY <= took <= GRIPPER_DELAY + 3 * PERIOD
    assert line.io.read("gripper_closed").value == "1"
    assert line.island.outputs == b"\x01\x00" and line.now > t0
    assert line.io.write("gripper_close", "false").success
    line.run_until(lambda: line.value("gripper_closed") == 0, 1.0, "gripper open again")
    assert not line.robot_dropped


def test_part_present_is_an_input_set_by_the_island(line):
    line.program.set_part_present(True)
    line.tick()
    line.tick()
    assert line.value("part_present") == 1
    line.program.set_part_present(False)
    line.run_until(lambda: line.value("part_present") == 0, 0.5, "part gone")


@pytest.mark.parametrize("name, value, reason", [
    ("gripper_opne", "1", "unknown signal 'gripper_opne'"),
    ("gripper_closed", "1", "is an input"),
    ("part_present", "0", "is an input"),
    ("gripper_close", "2", "'2' is not a bit value"),
    ("gripper_close", 2, "2 does not fit bit (0..1)"),
    ("gripper_close", "yes please", "is not a bit value"),
    ("gripper_close", "", "is not a bit value"),
])
def test_refused_writes_change_nothing(line, name, value, reason):
    before = line.handle.outputs
    result = line.io.write(name, value)
    assert not result.success
    assert reason in result.message
    assert line.handle.outputs == before
    line.tick()
    assert line.island.outputs == before and line.value("gripper_close") == 0


def test_unplugged_island_reads_offline_at_once_outputs_safe_robot_untouched(line):
    assert line.io.write("gripper_close", "1").success
    line.run_until(lambda: line.value("gripper_closed") == 1, 1.0, "closed")
    line.link.unplugged.add(8)
    took = line.run_until(lambda: not line.online(), 2.0, "island offline")
    assert took <= INPUT_TIMEOUT + 2 * PERIOD
    assert [s.value for s in line.snap.signals] == [None, None, None]
    assert not any(s.online for s in line.snap.signals)
    assert line.handle.outputs == b"\x00\x00"           # safe values in the image at the loss
    assert line.snap.station("io_island").reason
    assert line.io.read("gripper_closed").success is False
    refused = line.io.write("gripper_close", "1")       # never queued for later
    assert not refused.success and "not in Data_Exchange" in refused.message
    assert line.handle.outputs == b"\x00\x00"
    line.run_until(lambda: line.snap.station("io_island").dp_state == "BACKOFF", 2.0, "master gave up")
    assert line.robot_handle.connected and not line.robot_dropped
    # the island's own watchdog put its outputs to the safe state: the gripper opens
    line.run_until(lambda: line.island.state is not SlaveState.DATA_EXCH, 1.0, "island watchdog")
    assert line.island.outputs == b"\x00\x00"
    line.run_until(lambda: line.program.closed == 0, 1.0, "gripper opened by the island")
    # back: online with its outputs at the safe values, and they stay there until set again
    line.link.unplugged.clear()
    line.run_until(line.online, 3.0, "island back")
    for _ in range(10):
        line.tick()
        assert line.value("gripper_close") == 0 and line.value("gripper_closed") == 0
    assert line.island.outputs == b"\x00\x00"
    st = line.snap.station("io_island")
    assert st.losses == 1 and st.outputs_safe
    assert line.io.write("gripper_close", "1").success
    line.run_until(lambda: line.value("gripper_closed") == 1, 1.0, "closed after the return")
    assert not line.robot_dropped


def test_stale_inputs_in_data_exchange_read_offline():
    """With a long dx_tolerance the master keeps the silent island in Data_Exchange: its inputs age
    and the island reads offline after input_timeout, not later."""
    line = Line(dx_tolerance=5.0)
    line.up()
    line.link.unplugged.add(8)
    t0 = line.now
    line.run_until(lambda: not line.online(), 2.0, "offline on stale inputs")
    assert line.handle.connected                        # the master still counts it in Data_Exchange
    assert INPUT_TIMEOUT - PERIOD <= line.now - t0 <= INPUT_TIMEOUT + 2 * PERIOD
    assert "no fresh inputs" in line.snap.station("io_island").reason


def test_master_silent_island_watchdog_makes_outputs_safe(line):
    assert line.io.write("gripper_close", "1").success
    line.run_until(lambda: line.program.closed == 1, 1.0, "closed")
    line.silent = True
    took = line.run_until(lambda: line.island.state is not SlaveState.DATA_EXCH, 1.0, "watchdog expiry")
    assert took <= 0.3 + 2 * PERIOD                    # watchdog_ms 300 of the bus config
    assert line.island.outputs == b"\x00\x00"
    line.run_until(lambda: line.program.closed == 0, 1.0, "gripper opens")


def test_a_loss_between_two_updates_is_seen_without_the_state_hook(line):
    """If the master's state callback is replaced (the link supervisor owns it), the loss counter
    still tells update() that the station was lost: outputs safe, one cycle offline."""
    line.master.on_state_change = None
    assert line.io.write("gripper_close", "1").success
    line.link.unplugged.add(8)

    def cycle() -> None:                                 # no update() meanwhile
        line.program.step(line.now)
        line.master.cycle(timeout=1.0)
        line.clock.t += PERIOD
    while line.handle.connected:
        cycle()
    line.link.unplugged.clear()
    while not line.handle.connected:
        cycle()
    cycle()
    snap = line.io.update(line.now)
    assert not snap.station("io_island").online
    assert snap.station("io_island").losses == 1
    assert line.handle.outputs == b"\x00\x00"
    line.run_until(line.online, 1.0, "online again")
    assert line.value("gripper_close") == 0


def test_detach_is_offline_and_attach_checks_lengths(line):
    line.io.detach()
    snap = line.io.update(line.now)
    assert not snap.station("io_island").online and snap.station("io_island").dp_state == "closed"
    assert line.io.write("gripper_close", "1").success is False
    wrong = SignalMap.from_dict({"stations": {"io_island": {"address": 8, "signals": {
        "x": {"direction": "out", "type": "bit", "byte": 0, "bit": 0}}}}}, {8: (1, 1)})
    with pytest.raises(SignalMapError, match="station 'io_island'.*2 bytes in / 2 out"):
        IoLine(wrong, 0.5).attach(line.master)


def test_input_timeout_must_be_positive():
    with pytest.raises(SignalMapError, match="input_timeout"):
        IoLine(SIGNALS, 0.0)


@pytest.mark.parametrize("fault, words", [
    ("ident", ["reports ident 0x0F1B", "expects 0x0F1A"]),
    ("cfg", ["rejects the configuration 11 21"]),
    ("absent", ["no reply", "set to address 8"]),
])
def test_a_misconfigured_or_absent_island_never_comes_online_nor_disturbs_the_arm(fault, words):
    line = Line()
    if fault == "ident":
        line.island.ident = 0x0F1B                   # another device at address 8
    elif fault == "cfg":
        from pyprofibus_vendor.dp import ChkCfg
        line.island.cfg = ChkCfg(bytes([0x10, 0x20])).cfg   # an island with 1 byte each way
    else:
        line.link.unplugged.add(8)
    line.run_until(lambda: line.robot_handle.connected, 3.0, "the arm's station")
    for _ in range(40):                              # 2 s of bus cycles
        line.tick()
        assert not line.online() and line.value("gripper_closed") is None
        assert not line.io.write("gripper_close", "1").success
    assert line.robot_handle.connected and line.robot_handle.counters.losses == 0
    reason = line.snap.station("io_island").reason
    for word in words:
        assert word in reason, reason


def test_snapshots_compare_equal_until_something_shown_changes(line):
    first = line.snap
    line.tick()
    assert line.snap == first and line.snap.time > first.time
    line.program.set_part_present(True)
    line.tick()
    assert line.snap != first
    with pytest.raises(Exception):
        line.snap.signals[0].value = 5                # immutable
