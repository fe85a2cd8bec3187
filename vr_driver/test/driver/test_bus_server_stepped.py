"""The bus process's loop (vr_driver.bus.process.BusServer) stepped by hand on the fake clock, with
the virtual G2's DP slave on an in-memory link: every record the driver decides is carried by a
Data_Exchange the card answered before the next one replaces it -- the driver decides a record at
each report and, woken by a request, between two reports, and a stream's START replaced by the next
target before any telegram carried it left the arm standing. A stop never waits."""
from __future__ import annotations

from multiprocessing import Pipe

import pytest
from pyprofibus_vendor.dp_master import BusTiming, SlaveSpec

from vr_driver.bus.process import BusServer, BusSettings
from vr_driver.controller.virtual_controller import robot_slave
from vr_driver.protocol.v3 import V3

from _world import FakeClock, SteppedLink

ADDRESS = 8


def record(n: int) -> bytes:
    """A distinct 24-byte record (the bus process does not read them)."""
    return bytes([n]) * 24


class Rig:
    def __init__(self) -> None:
        self.clock = FakeClock()
        self.slave = robot_slave(ADDRESS, clock=self.clock, protocol="v3")
        self.carried = []
        self.slave.on_outputs = self.carried.append
        self.link = SteppedLink(self.slave, self.clock)
        spec = SlaveSpec(ADDRESS, self.slave.ident, self.slave.cfg, watchdog=0.3)
        settings = BusSettings(device="memory", baud=19200, master_address=2,
                               timing=BusTiming.for_baud(19200), cycle_rate_hz=20.0, controller=ADDRESS,
                               idle_record=V3.idle_record(), watchdog=0.3)
        self.conn, theirs = Pipe()
        self.server = BusServer(theirs, self.link, settings, clock=self.clock)
        self.server._handle(("slave", spec))
        for _ in range(50):
            if self.handle.connected:
                break
            self.cycle()
        assert self.handle.connected

    @property
    def handle(self):
        return self.server.master.slave(ADDRESS)

    def out(self, data: bytes, urgent: bool = False) -> None:
        self.server._handle(("out", ADDRESS, self.server.sessions[ADDRESS], data, None, urgent))

    def cycle(self) -> bytes:
        """One bus cycle; what the card took in it (None: nothing)."""
        before = len(self.carried)
        assert self.server._cycle()
        while self.conn.poll(0):          # read the reports: the sender never blocks on a full pipe
            self.conn.recv()
        self.clock.advance(0.05)
        return self.carried[-1] if len(self.carried) > before else None


@pytest.fixture
def rig():
    return Rig()


def test_two_records_between_cycles_are_both_carried_in_order(rig):
    assert rig.cycle() == V3.idle_record()
    rig.out(record(1))                    # a request woke the driver: its record
    rig.out(record(2))                    # the next report's record, before a cycle carried the first
    assert rig.cycle() == record(1)
    assert rig.cycle() == record(2)
    assert rig.cycle() == record(2)       # repeated as a DP master repeats its image
    assert rig.server.held == 1


def test_of_several_records_waiting_the_newest_goes_next(rig):
    rig.cycle()
    rig.out(record(1))
    rig.out(record(2))
    rig.out(record(3))
    assert rig.cycle() == record(1)
    assert rig.cycle() == record(3)
    assert record(2) not in rig.carried


def test_a_record_after_a_carried_one_goes_out_at_once(rig):
    rig.cycle()
    rig.out(record(1))
    assert rig.cycle() == record(1)
    rig.out(record(2))
    assert rig.cycle() == record(2)
    assert rig.server.held == 0


def test_the_newest_word_back_to_what_waits_for_the_wire_drops_the_held_one(rig):
    rig.cycle()
    rig.out(record(1))
    rig.out(record(2))
    rig.out(record(1))                    # the driver took it back
    assert rig.cycle() == record(1)
    assert rig.cycle() == record(1)
    assert record(2) not in rig.carried


def test_a_stop_never_waits(rig):
    rig.cycle()
    stop = V3.encode(V3.stream_command((), stop=True))
    assert V3.is_stop(stop)
    rig.out(record(1))
    rig.out(stop, urgent=True)
    assert rig.cycle() == stop
    assert record(1) not in rig.carried


def test_a_record_without_a_reply_is_carried_again_before_the_next(rig):
    rig.cycle()
    rig.link.cut = True                   # the telegram is lost: no reply (dx_tolerance keeps the slave)
    rig.server.master.dx_tolerance = 10.0
    rig.out(record(1))
    rig.out(record(2))
    assert rig.cycle() is None
    rig.link.cut = False
    assert rig.cycle() == record(1)
    assert rig.cycle() == record(2)


def test_a_record_held_across_a_reset_is_never_carried(rig):
    rig.cycle()
    rig.out(record(1))
    rig.out(record(2))
    rig.link.cut = True                   # the card is gone before the first was carried
    for _ in range(20):
        rig.cycle()
        if not rig.handle.connected:
            break
    assert not rig.handle.connected
    assert rig.handle.outputs == V3.idle_record()
    rig.link.cut = False
    for _ in range(200):
        rig.cycle()
        if rig.handle.connected:
            break
    assert rig.handle.connected
    rig.cycle()
    assert rig.carried[-1] == V3.idle_record()
    assert record(1) not in rig.carried and record(2) not in rig.carried
