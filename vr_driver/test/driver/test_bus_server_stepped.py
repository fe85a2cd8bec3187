"""The bus process's loop (vr_driver.bus.process.BusServer) stepped by hand, with the virtual G2's DP
slave on an in-memory link: each report says which of the driver's records its cycle carried (a
record set while a cycle was under way is not carried by it, and the driver learns so), and a cycle
that is due at once waits -- at most ``answer_wait`` -- for the driver's answer to the last report,
so that what the driver decided on a report goes out in the next cycle."""
from __future__ import annotations

import pickle
import time
from multiprocessing import Pipe

from pyprofibus_vendor.dp_master import BusTiming, SlaveSpec

from vr_driver.bus.messages import FROM_BUS, AddSlave, Answer, Outputs, Report, decode
from vr_driver.bus.process import BusServer, BusSettings, RemoteSlave
from vr_driver.controller.virtual_controller import robot_slave
from vr_driver.protocol.v3 import V3

from _world import FakeClock, SteppedLink

ADDRESS = 8


def record(n: int) -> bytes:
    """A distinct 24-byte record (the bus process does not read them)."""
    return bytes([n]) * 24


class Rig:
    def __init__(self, clock=None, answer_wait: float = 0.01) -> None:
        self.clock = clock or FakeClock()
        self.slave = robot_slave(ADDRESS, clock=self.clock, protocol="v3")
        self.carried = []
        self.slave.on_outputs = self.carried.append
        # (on the real clock the link's waits still pass on a fake one of its own)
        self.link = SteppedLink(self.slave, self.clock if isinstance(self.clock, FakeClock) else FakeClock())
        spec = SlaveSpec(ADDRESS, self.slave.ident, self.slave.cfg, watchdog=None)
        settings = BusSettings(device="memory", baud=19200, master_address=2,
                               timing=BusTiming.for_baud(19200), cycle_rate_hz=20.0, controller=ADDRESS,
                               idle_record=V3.idle_record(), watchdog=None, answer_wait=answer_wait)
        self.conn, theirs = Pipe()
        self.server = BusServer(theirs, self.link, settings, clock=self.clock)
        self.server._handle(AddSlave(spec))
        self.serial = 0
        self.report = None
        for _ in range(50):
            if self.handle.connected:
                break
            self.cycle()
        assert self.handle.connected

    @property
    def handle(self):
        return self.server.master.slave(ADDRESS)

    def out(self, data: bytes) -> int:
        self.serial += 1
        self.server._handle(Outputs(ADDRESS, self.server.sessions[ADDRESS], data, None, self.serial))
        return self.serial

    def cycle(self):
        """One bus cycle: what the card took in it (None: nothing); the report is kept."""
        before = len(self.carried)
        assert self.server._cycle()
        deadline = time.monotonic() + 5.0
        while True:                        # the report sender's thread posts it
            assert self.conn.poll(max(0.0, deadline - time.monotonic())), "no report"
            msg = decode(self.conn.recv_bytes(), FROM_BUS)
            if isinstance(msg, Report) and msg.seq == self.server._report_seq:
                self.report = msg
                break
        if isinstance(self.clock, FakeClock):
            self.clock.advance(0.05)
        return self.carried[-1] if len(self.carried) > before else None


def test_each_report_names_the_record_its_cycle_carried():
    rig = Rig()
    first = rig.out(record(1))
    assert rig.cycle() == record(1)
    assert rig.report.carried == first
    rig.out(record(2))
    second = rig.out(record(3))          # two records before a cycle: the newer replaces the older
    assert rig.cycle() == record(3)
    assert rig.report.carried == second
    assert record(2) not in rig.carried


def test_a_cycle_without_a_reply_carried_nothing_the_driver_can_count_on():
    rig = Rig()
    rig.server.master.dx_tolerance = 10.0      # the slave stays in Data_Exchange through one lost reply
    first = rig.out(record(1))
    rig.cycle()
    rig.link.cut = True
    rig.out(record(2))
    assert rig.cycle() is None
    assert rig.report.carried == first
    rig.link.cut = False
    rig.cycle()
    assert rig.report.carried == rig.serial


def test_the_driver_side_knows_whether_the_last_record_was_carried():
    slave = RemoteSlave.__new__(RemoteSlave)
    slave.serial, slave.carried_serial = 5, 4
    assert not slave.carried
    slave.carried_serial = 5
    assert slave.carried


def test_a_new_session_starts_from_the_idle_record_and_carries_no_old_serial():
    rig = Rig()
    rig.out(record(1))
    rig.cycle()
    rig.link.cut = True
    for _ in range(20):
        rig.cycle()
        if not rig.handle.connected:
            break
    assert not rig.handle.connected and rig.handle.outputs == V3.idle_record()
    rig.link.cut = False
    for _ in range(200):
        rig.cycle()
        if rig.handle.connected:
            break
    rig.cycle()
    assert rig.carried[-1] == V3.idle_record()
    assert rig.report.carried == 0


def test_a_due_cycle_waits_for_the_answer_to_the_last_report_at_most_answer_wait():
    """On the real clock (the wait is a poll of the driver's socket): the counts, not the times."""
    rig = Rig(clock=time.monotonic, answer_wait=0.05)
    server = rig.server
    rig.cycle()
    server._next = time.monotonic() - 1.0           # the next cycle is due at once (a slow line)
    before = server.unanswered
    rig.conn.send_bytes(Answer(server._report_seq).encode())  # the driver answered the last report
    server._wait()
    assert server.unanswered == before
    rig.cycle()
    server._next = time.monotonic() - 1.0
    server._wait()                                   # no answer: the cycle begins after answer_wait
    assert server.unanswered == before + 1
    rig.cycle()
    server._next = time.monotonic() - 1.0
    rig.conn.send_bytes(Answer(server._report_seq - 1).encode())   # an answer to an older report does not count
    server._wait()
    assert server.unanswered == before + 2


def test_answer_wait_zero_never_waits():
    rig = Rig(clock=time.monotonic, answer_wait=0.0)
    rig.cycle()
    rig.server._next = time.monotonic() - 1.0
    rig.server._wait()
    assert rig.server.unanswered == 1


def test_a_malformed_message_from_the_driver_is_refused_in_the_log_and_changes_nothing(caplog):
    rig = Rig()
    rig.out(record(1))
    rig.cycle()
    rig.conn.send_bytes(pickle.dumps(("out", ADDRESS, rig.server.sessions[ADDRESS], record(2), None, "7")))
    rig.conn.send_bytes(b"not a pickle")
    rig.server._drain()
    assert "'out': field 5 is str '7', expected int" in caplog.text and "does not load" in caplog.text
    assert rig.handle.outputs == record(1)
    assert rig.cycle() == record(1) and rig.report.carried == rig.serial
