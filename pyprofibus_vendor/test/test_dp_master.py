"""DP master: every state transition with an injected clock, plus the blocking API."""
from __future__ import annotations

import logging
import threading
import unittest
from typing import Callable, List, Optional

from pyprofibus_vendor.dp import (DiagStatus1, GcCommand, Sap, SlaveDiag, reply_frame,
                                  watchdog_factors)
from pyprofibus_vendor.dp_master import (BusTiming, DpMaster, MasterSlaveState as S, SlaveSpec)
from pyprofibus_vendor.dp_slave import DpSlave, SlaveLink, SlaveServer, SlaveState
from pyprofibus_vendor.errors import ConfigError, DpError, DpTimeoutError, PhyError
from pyprofibus_vendor.fdl import (Frame, FrameControl, RequestFunction, ResponseStatus, Sd1, Sd2, ShortAck,
                                   StationType, decode_frame)
from pyprofibus_vendor.phy import FaultyLink, MemoryLink

from _helpers import (MASTER, ROBOT_CFG, ROBOT_IDENT, SLAVE, FakeClock, ScriptedLink,
                      transform)
from test_fdl import (CHK_CFG_REQ, DIAG_REPLY_1, DIAG_REPLY_2, DIAG_REQ, DX_REPLY, DX_REQ,
                      FDL_STATUS_REPLY, FDL_STATUS_REQ, SET_PRM_REQ)

ROBOT = SlaveSpec(SLAVE, ROBOT_IDENT, ROBOT_CFG, watchdog=0.3)
STARTUP = [(S.INIT, S.WAIT_DIAG), (S.WAIT_DIAG, S.SET_PRM), (S.SET_PRM, S.CHK_CFG),
           (S.CHK_CFG, S.CHECK_DIAG), (S.CHECK_DIAG, S.DATA_EXCHANGE)]


class Rig:
    """Master + in-process echo slave, both on one fake clock."""

    def __init__(self, spec: SlaveSpec = ROBOT, slave_ident: int = ROBOT_IDENT,
                 slave_cfg: bytes = ROBOT_CFG, wrap: Optional[Callable] = None, **kw) -> None:
        self.clock = FakeClock()
        self.slave = DpSlave(SLAVE, slave_ident, slave_cfg, clock=self.clock)
        self.slave.on_outputs = self._echo
        self.slave_outputs: List[bytes] = []
        self.link = SlaveLink(self.slave)
        link = wrap(self.link) if wrap else self.link
        self.changes: List[tuple] = []
        self.master = DpMaster(link, MASTER, 19200, clock=self.clock,
                               on_state_change=lambda h, o, n, r: self.changes.append((o, n, r)),
                               **kw)
        self.h = self.master.add_slave(spec)

    def _echo(self, data: bytes) -> None:
        self.slave_outputs.append(data)
        if len(data) == self.slave.input_size:
            self.slave.inputs = transform(data)

    def steps(self, n: int, dt: float = 0.001) -> None:
        for _ in range(n):
            self.master.step()
            self.clock.advance(dt)

    def until(self, pred: Callable[[], bool], max_steps: int = 10000, dt: float = 0.001) -> int:
        for i in range(max_steps):
            if pred():
                return i
            self.master.step()
            self.clock.advance(dt)
        raise AssertionError("condition not reached")

    def transitions(self) -> List[tuple]:
        return [(o, n) for o, n, _ in self.changes]


class TimingTest(unittest.TestCase):
    def test_table(self):
        expect = {9600: (100, 1), 19200: (100, 1), 93750: (100, 1), 187500: (100, 1),
                  500000: (200, 1), 1500000: (300, 1), 3000000: (400, 2), 6000000: (600, 3),
                  12000000: (1000, 4)}
        for baud, (slot, retry) in expect.items():
            t = BusTiming.for_baud(baud)
            self.assertEqual((t.slot_bits, t.max_retry), (slot, retry), baud)
        self.assertAlmostEqual(BusTiming.for_baud(19200).slot_time, 100 / 19200)
        self.assertEqual(BusTiming.for_baud(19200, max_retry=3).max_retry, 3)

    def test_bad_and_odd_baud(self):
        for bad in (1200, 12_000_001, "19200"):
            with self.assertRaises(ConfigError):
                BusTiming.for_baud(bad)
        with self.assertLogs("pyprofibus_vendor.dp_master", logging.WARNING):
            self.assertEqual(BusTiming.for_baud(115200).slot_bits, 100)

    def test_reply_timeout(self):
        m = DpMaster(SlaveLink(DpSlave(SLAVE, ROBOT_IDENT, ROBOT_CFG)), baud=9600,
                     reply_timeout_floor=0.0)
        # 23 + 23 characters at 9600 baud plus TSYN and slot time
        self.assertAlmostEqual(m._reply_timeout(23, 23), 46 * 11 / 9600 + 133 / 9600)
        m2 = DpMaster(SlaveLink(DpSlave(SLAVE, ROBOT_IDENT, ROBOT_CFG)), baud=12_000_000)
        self.assertEqual(m2._reply_timeout(23, 23), 0.05)

    def test_a_known_adapter_latency_timer_lengthens_the_reply_timeout(self):
        from pyprofibus_vendor.adapter import AdapterSetup
        link = SlaveLink(DpSlave(SLAVE, ROBOT_IDENT, ROBOT_CFG))
        link.adapter = AdapterSetup("/dev/ttyUSB0", True, 32, None)
        m = DpMaster(link, baud=19200)
        wire = 46 * 11 / 19200 + 133 / 19200
        self.assertAlmostEqual(m._reply_timeout(23, 23), wire + 0.032)      # past the 50 ms floor
        link.adapter = AdapterSetup("/dev/ttyUSB0", True, 1, 16)             # lowered at open: 1 ms
        m.replace_link(link)
        self.assertEqual(m._reply_timeout(23, 23), 0.05)

    def test_replies_are_timed_against_the_wire_on_a_serial_device_only(self):
        from pyprofibus_vendor.adapter import AdapterSetup
        link = SlaveLink(DpSlave(SLAVE, ROBOT_IDENT, ROBOT_CFG))
        self.assertFalse(DpMaster(link).wire_timed)                         # no serial device
        link.adapter, link.is_pty = AdapterSetup("/dev/pts/3", False, None, None), True
        self.assertFalse(DpMaster(link).wire_timed)                         # a pty: no baud timing
        link.is_pty = False
        m = DpMaster(link)
        self.assertTrue(m.wire_timed)
        self.assertFalse(DpMaster(link, wire_timed=False).wire_timed)
        link.is_pty = True
        m.replace_link(link)
        self.assertFalse(m.wire_timed)


class SpecTest(unittest.TestCase):
    def test_derived(self):
        self.assertEqual((ROBOT.input_size, ROBOT.output_size), (14, 14))
        prm = ROBOT.set_prm()
        self.assertEqual(prm.encode(), bytes.fromhex("88 1E 01 00 06 C6 00"))
        off = SlaveSpec(SLAVE, ROBOT_IDENT, ROBOT_CFG, watchdog=None, sync_req=True,
                        freeze_req=True, group_ident=2).set_prm()
        self.assertIsNone(off.watchdog_time)
        self.assertEqual(off.encode()[0], 0xB0)
        self.assertEqual(SlaveSpec(SLAVE, 1, ROBOT_CFG, watchdog=5.0).set_prm().encode()[1:3],
                         bytes(watchdog_factors(5.0)))

    def test_invalid(self):
        for kw in (dict(address=126), dict(ident=-1), dict(cfg=b""), dict(cfg=b"\xC0"),
                   dict(watchdog=1000.0)):
            args = dict(address=SLAVE, ident=ROBOT_IDENT, cfg=ROBOT_CFG)
            args.update(kw)
            with self.assertRaises(ConfigError):
                SlaveSpec(**args)


class StartupTest(unittest.TestCase):
    def test_every_startup_transition_and_fc_sequence(self):
        rig = Rig()
        sent: List[Frame] = []
        real_send = rig.link.send
        rig.link.send = lambda data: (sent.append(decode_frame(data)), real_send(data))
        rig.until(lambda: rig.h.state is S.DATA_EXCHANGE)
        self.assertEqual(rig.transitions(), STARTUP)
        self.assertIs(rig.slave.state, SlaveState.DATA_EXCH)
        self.assertEqual([f.fc.encode() for f in sent], [0x49, 0x6D, 0x5D, 0x7D, 0x5D])
        self.assertEqual([getattr(f, "dsap", None) for f in sent], [None, 60, 61, 62, 60])
        self.assertTrue(rig.h.connected)
        self.assertEqual(rig.h.last_diag.master_address, MASTER)
        rig.steps(4)
        self.assertEqual([f.fc.encode() for f in sent[5:7]], [0x7D, 0x5D])  # FCB toggles
        self.assertEqual(rig.master.counters.state_changes, 5)
        self.assertEqual(rig.master.counters.reconnects, 0)

    def test_reproduces_the_recorded_startup_byte_for_byte(self):
        """Master 2, slave 8, ident 0x4D14, cfg 3D, WD 300 ms, group 1 (a recorded real start-up, as in pyprofibus_vendor/README.md)."""
        script = {FDL_STATUS_REQ: FDL_STATUS_REPLY, DIAG_REQ: DIAG_REPLY_1,
                  SET_PRM_REQ: b"\xE5", CHK_CFG_REQ: b"\xE5"}
        tx: List[bytes] = []

        def respond(frame: Frame) -> Optional[bytes]:
            raw = frame.encode()
            tx.append(raw)
            if raw in script:
                return script[raw]
            if getattr(frame, "dsap", None) == 60:
                return DIAG_REPLY_2
            if raw == DX_REQ:
                return DX_REPLY
            return None

        clock = FakeClock()
        m = DpMaster(ScriptedLink(respond), 2, 19200, clock=clock)
        h = m.add_slave(SlaveSpec(8, 0x4D14, b"\x3d", watchdog=0.3, group_ident=1))
        h.outputs = bytes(range(1, 15))
        for _ in range(20):
            m.step()
            clock.advance(0.001)
            if h.inputs is not None:
                break
        self.assertEqual(tx[:6], [FDL_STATUS_REQ, DIAG_REQ, SET_PRM_REQ, CHK_CFG_REQ,
                                  bytes.fromhex("68 05 05 68 88 82 5D 3C 3E E1 16"), DX_REQ])
        self.assertEqual(h.inputs, bytes(range(1, 15)))

    def test_accepts_sd2_diag_reply(self):
        """Many slaves send the 8-byte diag unit as SD2, not SD3; both must work."""
        slave = DpSlave(SLAVE, ROBOT_IDENT, ROBOT_CFG)

        def respond(frame: Frame) -> Optional[bytes]:
            reply = slave.handle(frame)
            if reply is None:
                return None
            if getattr(reply, "ssap", None) == 60:
                reply = Sd2(reply.da, reply.sa, reply.fc, reply.data, reply.dsap, reply.ssap)
            return reply.encode()

        clock = FakeClock()
        m = DpMaster(ScriptedLink(respond), MASTER, clock=clock)
        h = m.add_slave(ROBOT)
        for _ in range(12):
            m.step()
        self.assertIs(h.state, S.DATA_EXCHANGE)


class DataExchangeTest(unittest.TestCase):
    def test_latched_outputs_and_inputs_with_age(self):
        rig = Rig()
        rig.until(lambda: rig.h.connected)
        self.assertEqual(rig.h.outputs, bytes(14))
        rig.h.outputs = b"\x01" * 14
        rig.until(lambda: rig.h.inputs == transform(b"\x01" * 14))
        t_in = rig.h.inputs_time
        for _ in range(5):                       # no new set: the latched image goes out
            rig.steps(2)
        self.assertEqual(rig.slave_outputs[-5:], [b"\x01" * 14] * 5)
        self.assertGreater(rig.h.inputs_time, t_in)
        data, age = rig.master.inputs(SLAVE)
        self.assertEqual(data, transform(b"\x01" * 14))
        self.assertGreaterEqual(age, 0.0)
        self.assertEqual(rig.h.inputs_age(rig.h.inputs_time + 0.25), 0.25)
        rig.master.set_outputs(SLAVE, b"\x02" * 14)
        rig.steps(4)
        self.assertEqual(rig.slave.outputs, b"\x02" * 14)
        self.assertGreater(rig.master.counters.cycles, 10)
        with self.assertRaises(DpError):
            rig.h.outputs = b"\x00"

    def test_retry_keeps_fcb_and_slave_repeats_reply(self):
        rig = Rig()
        rig.until(lambda: rig.h.connected)
        drops = {"n": 1}
        real_send = rig.link.send
        sent: List[bytes] = []

        def lossy_send(data: bytes) -> None:
            sent.append(bytes(data))
            real_send(data)
            if drops["n"]:
                drops["n"] -= 1
                rig.link.flush_input()       # the reply is lost on the way back

        rig.link.send = lossy_send
        rig.h.outputs = b"\x09" * 14
        rig.until(lambda: rig.h.inputs == transform(b"\x09" * 14), dt=0.02)
        self.assertEqual(sent[0], sent[1])                  # identical retry, same FCB
        self.assertEqual(rig.master.counters.retries, 1)
        self.assertEqual(rig.slave.counters.duplicates, 1)
        self.assertEqual(rig.slave_outputs.count(b"\x09" * 14), 1)   # executed once
        self.assertTrue(rig.h.connected)

    def test_adapter_echo_is_recognised_and_skipped(self):
        """An RS-485 adapter whose receiver stays on while it sends reads the master's own request
        back before the reply: counted as the adapter's echo, never as a telegram of the line."""
        rig = Rig()
        real_send = rig.link.send
        echoed = {"n": 0}

        def echoing_send(data: bytes) -> None:
            real_send(data)
            reply = rig.link.recv(4096, 0.0)
            rig.link._rx[:0] = bytes(data)        # the echo is read before the reply
            rig.link._rx += reply
            echoed["n"] += 1

        rig.link.send = echoing_send
        rig.until(lambda: rig.h.connected)
        rig.h.outputs = b"\x03" * 14
        rig.until(lambda: rig.h.inputs == transform(b"\x03" * 14))
        c = rig.master.counters
        self.assertEqual(c.echoes, echoed["n"])
        self.assertEqual(c.unexpected_frames, 0)
        self.assertEqual(c.retries, 0)
        self.assertEqual(c.invalid_replies, 0)
        self.assertGreater(c.dx_timed, 0)

    def _held_by_a_latency_timer(self, rig: Rig, period: float) -> dict:
        """An echoing adapter with a latency timer longer than the reply timeout: each
        transmission's echo and its reply are held to the timer's next expiry, so a try is often
        resent before they come; then the first try's reply, the resend's echo and its reply come
        in one chunk (the interleaving seen on a loaded pty through the virtual line)."""
        link, real_send, real_recv = rig.link, rig.link.send, rig.link.recv
        held = {"bytes": bytearray(), "due": None, "echoes": 0}

        def send(data: bytes) -> None:
            real_send(data)
            reply = real_recv(4096, 0.0)
            held["bytes"] += bytes(data) + reply
            if held["due"] is None:
                held["due"] = (int(rig.clock() / period) + 1) * period

        def recv(n: int = 4096, timeout: Optional[float] = 0.0) -> bytes:
            if held["due"] is not None and rig.clock() >= held["due"]:
                held["echoes"] += held["bytes"].count(held["bytes"][:7])   # the requests, read back
                link._rx += held["bytes"]
                held["bytes"].clear()
                held["due"] = None
            return real_recv(n, timeout)

        link.send, link.recv = send, recv
        return held

    def test_an_echo_behind_a_late_reply_is_counted(self):
        """The resend's echo after the first try's late reply, in the chunk whose reply ends the
        turn: the adapter's echo, counted (it was dropped uncounted with the rest of the chunk)."""
        rig = Rig()
        rig.until(lambda: rig.h.connected)
        c = rig.master.counters
        e0, q0, r0 = c.echoes, c.requests, c.retries
        held = self._held_by_a_latency_timer(rig, 0.064)
        rig.steps(3000)
        rig.until(lambda: not held["bytes"])
        self.assertGreater(c.retries - r0, 5)                 # the interleaving happened
        self.assertTrue(rig.h.connected)
        self.assertEqual(c.echoes - e0, c.requests - q0 + c.retries - r0)   # every transmission's
        self.assertEqual(c.unexpected_frames, 0)
        self.assertEqual(c.garbage_bytes, 0)

    def test_stale_echoes_dropped_before_a_request_are_counted(self):
        """Bytes still unread when the next request goes out (TSYN) are dropped, not parsed as its
        reply; the echoes among them -- a whole one and the start of one whose rest the adapter
        still holds, in a burst arriving while they are dropped -- are counted, the rest is not
        taken for garbage or another station's."""
        rig = Rig()
        rig.until(lambda: rig.h.connected)
        c = rig.master.counters
        rig.until(lambda: rig.master._pending is None)
        rig.link._rx += DX_REQ + DX_REPLY
        real_recv, reads = rig.link.recv, []

        def recv(n: int = 4096, timeout: Optional[float] = 0.0) -> bytes:
            data = real_recv(n, timeout)
            if not reads:                          # the next burst comes just after the first read
                rig.link._rx += DX_REQ[:6]
            reads.append(data)
            return data

        rig.link.recv = recv
        e0, g0, u0 = c.echoes, c.garbage_bytes, c.unexpected_frames
        rig.steps(1)                               # the next request: its TSYN drops them
        self.assertEqual(c.echoes - e0, 2)
        self.assertEqual(reads[:2], [DX_REQ + DX_REPLY, DX_REQ[:6]])
        self.assertEqual((c.garbage_bytes, c.unexpected_frames), (g0, u0))
        rig.until(lambda: rig.master._pending is None)
        rig.link._rx += DX_REQ[:5]                 # too short to tell whose: dropped uncounted
        rig.steps(1)
        self.assertEqual(c.echoes - e0, 2)
        self.assertTrue(rig.h.connected)

    def _late_second_try(self, echo: bool, delays: tuple = (0.06, 0.04, 0.035), lead: int = 0,
                         prompt: float = 0.002, wire_timed: bool = False, **kw) -> tuple:
        """An adapter that hands over each transmission's bytes (its echo when ``echo``, then the
        slave's reply) ``delays[n]`` seconds after transmission n, in order. By default the first
        try of request A (outputs X) is answered after its timeout, so A is resent; the first try's
        reply ends A's turn, request B (outputs Y) goes out, and the resend's reply -- the slave's
        repeat of A's, inputs from X -- comes before B's own. ``lead``: transmissions (answered
        after ``prompt`` s, outputs X) before A; ``wire_timed`` from then on. Returns (the inputs each turn ended
        with after B was sent, the master's counters)."""
        rig = Rig(**kw)
        rig.until(lambda: rig.h.connected)
        x, y = b"\x05" * 14, b"\x06" * 14
        rig.h.outputs = x
        rig.until(lambda: rig.h.inputs == transform(x))
        rig.until(lambda: rig.master._pending is None)
        link, real_send, real_recv = rig.link, rig.link.send, rig.link.recv
        # delays: A try 1, A try 2, B; then prompt
        queue: List[list] = []                             # [release time, bytes], in order
        sent: List[bytes] = []

        def send(data: bytes) -> None:
            real_send(data)
            due = rig.clock() + (delays[len(sent)] if len(sent) < len(delays) else prompt)
            queue.append([max([due] + [q[0] for q in queue]),
                          (bytes(data) if echo else b"") + real_recv(4096, 0.0)])
            sent.append(bytes(data))
            if len(sent) > lead:
                rig.h.outputs = y                          # B (the next new request) carries Y

        def recv(n: int = 4096, timeout: Optional[float] = 0.0) -> bytes:
            while queue and queue[0][0] <= rig.clock():
                link._rx += queue.pop(0)[1]
            return real_recv(n, timeout)

        link.send, link.recv = send, recv
        rig.master.wire_timed = wire_timed
        ends: List[Optional[bytes]] = []
        turns = rig.master._turns
        for _ in range(400):
            rig.master.step()
            if rig.master._turns != turns:
                turns = rig.master._turns
                if len(sent) >= lead + 3:                   # a turn ended after B went out
                    ends.append(rig.h.inputs)
            rig.clock.advance(0.001)
        self.assertEqual(sent[lead], sent[lead + 1])        # A was resent (the interleaving happened)
        self.assertNotEqual(sent[lead + 2], sent[lead])
        self.assertTrue(rig.h.connected)
        return ends, rig.master.counters

    def test_late_replies_to_a_turn_that_ended_without_one_are_skipped_behind_an_echo(self):
        """Both tries of A answered only after A's turn ended without a reply (tolerated), then
        read while B awaits its reply: an adapter seen echoing (a transmission before A) shows they come before B's echo, so they are
        skipped. Without an echo they cannot be told from B's reply (no FCB in a reply, no repeat
        owed): the master takes the first -- the limit doc/adapters.md states."""
        for echo in (True, False):
            with self.subTest(echo=echo):
                ends, c = self._late_second_try(echo, (0.002, 0.12, 0.07, 0.03), lead=1,
                                                dx_tolerance=0.5)
                self.assertEqual(c.dx_missed, 1)
                if echo:
                    self.assertEqual(ends[0], transform(b"\x06" * 14))
                    self.assertEqual(c.late_replies, 2)
                else:
                    self.assertEqual(ends[0], transform(b"\x05" * 14))

    def test_late_replies_read_sooner_than_the_wire_allows_are_skipped(self):
        """The same without an echo, on a line whose bytes take their time on the wire (every reply
        here comes at least the request's and the reply's time on the wire, 27 ms, after its request):
        A's replies, read 20 ms after B went out, cannot be B's; B's own, after 30 ms, is taken."""
        ends, c = self._late_second_try(False, (0.03, 0.12, 0.07, 0.03), lead=1, prompt=0.03,
                                        dx_tolerance=0.5, wire_timed=True)
        self.assertEqual(c.dx_missed, 1)
        self.assertEqual(ends[0], transform(b"\x06" * 14))
        self.assertEqual(c.late_replies, 2)
        self.assertNotIn(transform(b"\x05" * 14), ends)

    def test_a_late_reply_to_a_resend_is_not_taken_for_the_next_requests(self):
        """The resend's reply of the previous request, read while the next request awaits its own:
        not taken as that request's reply (its inputs are a cycle old), with and without an echo."""
        for echo in (True, False):
            with self.subTest(echo=echo):
                ends, c = self._late_second_try(echo)
                self.assertEqual(ends[0], transform(b"\x06" * 14))   # B's turn ends with B's inputs
                self.assertNotIn(transform(b"\x05" * 14), ends)
                self.assertEqual(c.late_replies, 1)

    def test_an_adapter_that_stops_echoing_costs_one_resend(self):
        """A request after an echoed one awaits its own echo before taking a reply; when the
        adapter stops echoing, that request's reply is skipped once and its resend (no echo read
        since the first try) takes the reply."""
        rig = Rig()
        real_send = rig.link.send
        echo = {"on": True}

        def maybe_echoing_send(data: bytes) -> None:
            real_send(data)
            if echo["on"]:
                reply = rig.link.recv(4096, 0.0)
                rig.link._rx[:0] = bytes(data)
                rig.link._rx += reply

        rig.link.send = maybe_echoing_send
        rig.until(lambda: rig.h.connected)
        rig.until(lambda: rig.master._pending is None)
        c = rig.master.counters
        r0, l0 = c.retries, c.late_replies
        self.assertEqual(l0, 0)
        echo["on"] = False
        rig.h.outputs = b"\x07" * 14
        rig.until(lambda: rig.h.inputs == transform(b"\x07" * 14))
        rig.steps(200)
        self.assertEqual((c.retries - r0, c.late_replies - l0), (1, 1))
        self.assertTrue(rig.h.connected)

    def test_another_masters_request_is_no_echo(self):
        rig = Rig()
        rig.until(lambda: rig.h.connected)
        real_send = rig.link.send
        other = Sd1(SLAVE, MASTER + 1, FrameControl.req(RequestFunction.FDL_STATUS)).encode()

        def with_other(data: bytes) -> None:
            rig.link._rx += other                 # another master's request heard on the line
            real_send(data)

        rig.link.send = with_other
        rig.steps(10)
        self.assertEqual(rig.master.counters.echoes, 0)
        self.assertGreater(rig.master.counters.unexpected_frames, 0)

    def test_output_only_slave(self):
        spec = SlaveSpec(SLAVE, ROBOT_IDENT, b"\x2D")
        rig = Rig(spec, slave_cfg=b"\x2D")
        rig.until(lambda: rig.h.connected)
        rig.h.outputs = b"\x05" * 14
        rig.until(lambda: rig.slave.outputs == b"\x05" * 14)
        rig.steps(2)
        self.assertEqual(rig.h.inputs, b"")
        self.assertEqual(rig.master.counters.invalid_replies, 0)


class LossAndRecoveryTest(unittest.TestCase):
    def test_no_station_backs_off_with_growing_delay(self):
        clock = FakeClock()
        link = ScriptedLink(lambda f: None)
        m = DpMaster(link, MASTER, clock=clock, backoff_min=0.1, backoff_max=0.4)
        h = m.add_slave(ROBOT)
        starts = []
        for _ in range(30000):
            m.step()
            if h.state is S.INIT and (not starts or starts[-1][1] is not S.INIT):
                starts.append((clock.t, S.INIT))
            elif h.state is not S.INIT and starts and starts[-1][1] is S.INIT:
                starts.append((clock.t, h.state))
            clock.advance(0.001)
            if len(starts) >= 12:
                break
        inits = [t for t, s in starts if s is S.INIT]
        gaps = [round(b - a, 2) for a, b in zip(inits, inits[1:])]
        # each attempt: 2 x 50 ms timeouts, then back-off 0.1, 0.2, 0.4, 0.4 ...
        self.assertEqual(gaps[:4], [0.2, 0.3, 0.5, 0.5])
        self.assertTrue(all(f.encode() == link.sent[0].encode() for f in link.sent))
        self.assertEqual(m.counters.retries, m.counters.timeouts)   # one retry each
        self.assertEqual(m.counters.losses, 0)

    def test_cut_link_leaves_dx_and_recovers_after_restore(self):
        faulty: List[FaultyLink] = []
        rig = Rig(wrap=lambda l: faulty.append(FaultyLink(l)) or faulty[0])
        rig.until(lambda: rig.h.connected)
        faulty[0].cut()
        rig.until(lambda: not rig.h.connected, dt=0.01)
        self.assertEqual(rig.changes[-1][1], S.BACKOFF)
        self.assertIn("no reply to Data_Exchange", rig.changes[-1][2])
        self.assertEqual(rig.master.counters.losses, 1)
        rig.steps(300, dt=0.01)                              # still cut: stays away
        self.assertFalse(rig.h.connected)
        rig.slave.step()                  # (a slave server would do this on its own)
        self.assertIs(rig.slave.state, SlaveState.WAIT_PRM)  # slave watchdog expired
        faulty[0].restore()
        rig.until(lambda: rig.h.connected, dt=0.01)
        self.assertEqual(rig.master.counters.reconnects, 1)
        self.assertEqual(rig.h.counters.reconnects, 1)

    def test_slave_watchdog_rs_reply_reinitialises(self):
        rig = Rig()
        rig.until(lambda: rig.h.connected)
        rig.clock.advance(1.0)                               # slave watchdog runs out
        rig.until(lambda: not rig.h.connected)
        self.assertIn("refused", rig.changes[-1][2])
        self.assertIn("RS", rig.changes[-1][2])
        rig.until(lambda: rig.h.connected)
        self.assertEqual(rig.master.counters.reconnects, 1)
        self.assertEqual(rig.transitions()[-7:], [(S.DATA_EXCHANGE, S.BACKOFF),
                                                  (S.BACKOFF, S.INIT)] + STARTUP)

    def test_dh_fetches_diag_then_continues(self):
        rig = Rig()
        rig.until(lambda: rig.h.connected)
        rig.slave.set_diag(b"\x43\x01\x02")
        rig.until(lambda: rig.h.state is S.DX_DIAG)
        rig.until(lambda: rig.h.state is S.DATA_EXCHANGE)
        self.assertEqual(rig.transitions()[-2:], [(S.DATA_EXCHANGE, S.DX_DIAG),
                                                  (S.DX_DIAG, S.DATA_EXCHANGE)])
        self.assertEqual(rig.h.last_diag.ext_diag, b"\x43\x01\x02")
        self.assertEqual(rig.master.counters.losses, 0)

    def test_dh_with_prm_req_reinitialises(self):
        slave = DpSlave(SLAVE, ROBOT_IDENT, ROBOT_CFG)
        restarted = {"yes": False}

        def respond(frame: Frame) -> Optional[bytes]:
            reply = slave.handle(frame)
            if restarted["yes"] and slave.state is SlaveState.DATA_EXCH and reply is not None \
                    and isinstance(reply, Sd2) and reply.dsap is None:
                reply = Sd2(reply.da, reply.sa, FrameControl.resp(ResponseStatus.DH), reply.data)
                slave._transition(SlaveState.WAIT_PRM, "test: restart")
                slave._locker = None
            return None if reply is None else reply.encode()

        clock = FakeClock()
        changes: List[tuple] = []
        m = DpMaster(ScriptedLink(respond), MASTER, clock=clock,
                     on_state_change=lambda h, o, n, r: changes.append((o, n)))
        h = m.add_slave(ROBOT)
        while not h.connected:
            m.step()
        restarted["yes"] = True
        for _ in range(4):
            m.step()
        self.assertEqual(changes[-2:], [(S.DATA_EXCHANGE, S.DX_DIAG), (S.DX_DIAG, S.BACKOFF)])
        self.assertTrue(h.last_diag.status1 & DiagStatus1.STATION_NOT_READY)
        restarted["yes"] = False
        for _ in range(20):
            m.step()
        self.assertTrue(h.connected)
        self.assertEqual(h.counters.reconnects, 1)

    def test_link_failure_raises_phy_error_and_marks_slave_lost(self):
        rig = Rig()
        rig.until(lambda: rig.h.connected)
        rig.link.close()
        with self.assertRaises(PhyError):
            rig.steps(3)
        self.assertIs(rig.h.state, S.BACKOFF)
        self.assertEqual(rig.master.counters.phy_errors, 1)
        rig.master.replace_link(SlaveLink(rig.slave))
        rig.until(lambda: rig.h.connected)


class FaultsDuringInitTest(unittest.TestCase):
    def test_wrong_ident_prm_fault_backs_off_without_spinning(self):
        rig = Rig(slave_ident=0x4D14)
        with self.assertLogs("pyprofibus_vendor.dp_master", logging.INFO) as logs:
            rig.steps(5000, dt=0.001)                        # 5 simulated seconds
        self.assertFalse(rig.h.connected)
        text = "\n".join(logs.output)
        self.assertIn("parameter fault", text)
        self.assertIn("reports ident 0x4D14", text)
        self.assertIn((S.CHECK_DIAG, S.BACKOFF), rig.transitions())
        # back-off capped at 1 s: a handful of attempts, not thousands
        self.assertLess(rig.master.counters.requests, 60)
        self.assertGreater(rig.h.counters.faults, 3)

    def test_cfg_fault(self):
        rig = Rig(slave_cfg=b"\x3D")
        rig.steps(200)
        self.assertFalse(rig.h.connected)
        self.assertTrue(rig.h.last_diag.status1 & DiagStatus1.CFG_FAULT)
        self.assertIn("configuration fault", rig.changes[-1][2])

    def test_locked_by_another_master(self):
        rig = Rig()
        from test_dp_slave import Requester
        other = Requester(rig.slave, address=3)
        other.set_prm()
        rig.steps(20)
        self.assertFalse(rig.h.connected)
        self.assertIn((S.WAIT_DIAG, S.BACKOFF), rig.transitions())
        self.assertIn("locked by another master (3)", rig.changes[-1][2])

    def test_not_ready_then_ready_and_state_limit(self):
        slave = DpSlave(SLAVE, ROBOT_IDENT, ROBOT_CFG)
        holdoff = {"n": 3}

        def respond(frame: Frame) -> Optional[bytes]:
            reply = slave.handle(frame)
            if (getattr(reply, "ssap", None) == 60 and slave.state is SlaveState.DATA_EXCH
                    and holdoff["n"]):
                holdoff["n"] -= 1
                busy = SlaveDiag(DiagStatus1.STATION_NOT_READY, 0x0C, 0, MASTER, ROBOT_IDENT)
                reply = reply_frame(frame, SLAVE, busy.encode())
            return None if reply is None else reply.encode()

        clock = FakeClock()
        changes: List[tuple] = []
        m = DpMaster(ScriptedLink(respond), MASTER, clock=clock,
                     on_state_change=lambda h, o, n, r: changes.append((o, n)))
        h = m.add_slave(ROBOT)
        for _ in range(30):
            m.step()
        self.assertTrue(h.connected)
        self.assertEqual(changes, STARTUP)
        self.assertGreaterEqual(h.counters.diag_reads, 5)
        # a slave that never becomes ready hits the CHECK_DIAG time limit
        holdoff["n"] = 10 ** 6
        slave._transition(SlaveState.WAIT_PRM, "test")
        slave._locker = None
        for _ in range(3000):
            m.step()
            clock.advance(0.001)
        self.assertIn((S.CHECK_DIAG, S.BACKOFF), changes)

    def _scripted(self, respond_fn) -> tuple:
        slave = DpSlave(SLAVE, ROBOT_IDENT, ROBOT_CFG)
        clock = FakeClock()
        changes: List[tuple] = []
        m = DpMaster(ScriptedLink(lambda f: respond_fn(slave, f)), MASTER, clock=clock,
                     on_state_change=lambda h, o, n, r: changes.append((o, n, r)))
        m.add_slave(ROBOT)
        for _ in range(40):
            m.step()
            clock.advance(0.03)
        return changes

    def test_set_prm_refused(self):
        def respond(slave, frame):
            if getattr(frame, "dsap", None) == Sap.SET_PRM:
                return Sd1(MASTER, SLAVE, FrameControl.resp(ResponseStatus.RS)).encode()
            reply = slave.handle(frame)
            return None if reply is None else reply.encode()

        changes = self._scripted(respond)
        self.assertEqual(changes[2][:2], (S.SET_PRM, S.BACKOFF))
        self.assertIn("set_prm refused", changes[2][2])

    def test_chk_cfg_unanswered(self):
        def respond(slave, frame):
            reply = slave.handle(frame)
            if getattr(frame, "dsap", None) == Sap.CHK_CFG:
                return None
            return None if reply is None else reply.encode()

        changes = self._scripted(respond)
        self.assertEqual(changes[3][:2], (S.CHK_CFG, S.BACKOFF))
        self.assertIn("no reply to Chk_Cfg after 1 retries", changes[3][2])

    def test_fdl_status_from_a_master_station(self):
        reply = Sd1(MASTER, SLAVE, FrameControl.resp(ResponseStatus.OK,
                                                     StationType.MASTER_IN_RING)).encode()
        clock = FakeClock()
        m = DpMaster(ScriptedLink(lambda f: reply), MASTER, clock=clock)
        h = m.add_slave(ROBOT)
        m.step()
        m.step()
        self.assertIs(h.state, S.BACKOFF)

    def test_invalid_replies_are_ignored(self):
        bad_replies = [
            Sd1(MASTER, SLAVE + 1, FrameControl.resp(ResponseStatus.OK)).encode(),   # wrong SA
            Sd1(MASTER + 1, SLAVE, FrameControl.resp(ResponseStatus.OK)).encode(),   # wrong DA
            ShortAck().encode(),                                  # SC to FDL_Status
        ]
        clock = FakeClock()
        m = DpMaster(ScriptedLink(lambda f: b"".join(bad_replies)), MASTER, clock=clock)
        h = m.add_slave(ROBOT)
        m.step()
        m.step()
        self.assertIs(h.state, S.INIT)
        self.assertEqual(m.counters.invalid_replies, 1)
        self.assertEqual(m.counters.unexpected_frames, 2)

    def test_wrong_length_and_saps_in_data_exchange_not_delivered(self):
        rig = Rig()
        rig.until(lambda: rig.h.connected)
        good_inputs = rig.h.inputs
        fc = FrameControl.resp(ResponseStatus.DL)
        forged = [Sd2(MASTER, SLAVE, fc, b"\x01" * 13).encode(),
                  Sd2(MASTER, SLAVE, fc, b"\x01" * 14, 62, 60).encode(),
                  Sd2(MASTER, SLAVE, FrameControl.resp(ResponseStatus.NR), b"\x01" * 14).encode(),
                  ShortAck().encode()]
        rig.link.send = lambda data: rig.link._rx.extend(b"".join(forged))
        rig.steps(3)
        self.assertEqual(rig.h.inputs, good_inputs)
        self.assertEqual(rig.master.counters.invalid_replies, 4)


class ServicesTest(unittest.TestCase):
    def test_global_control_broadcast(self):
        rig = Rig()
        rig.until(lambda: rig.h.connected)
        rig.h.outputs = b"\x03" * 14
        rig.steps(4)
        rig.master.global_control(GcCommand.CLEAR_DATA)
        sent: List[bytes] = []
        real = rig.link.send
        rig.link.send = lambda d: (sent.append(bytes(d)), real(d))
        rig.steps(1)
        self.assertEqual(sent[0], bytes.fromhex("68 07 07 68 FF 82 46 3A 3E 02 00 41 16"))
        self.assertEqual(rig.slave.outputs, bytes(14))
        self.assertEqual(rig.master.counters.global_controls, 1)

    def test_acyclic_reads(self):
        rig = Rig()
        rig.until(lambda: rig.h.connected)
        rig.h.outputs = b"\x04" * 14
        rig.steps(4)
        jobs = [rig.master.request(SLAVE, sap) for sap in (Sap.GET_CFG, Sap.RD_INP,
                                                            Sap.RD_OUTP)]
        rig.until(lambda: all(j.done for j in jobs))
        self.assertEqual([j.result for j in jobs],
                         [ROBOT_CFG, transform(b"\x04" * 14), b"\x04" * 14])
        self.assertTrue(rig.h.connected)
        with self.assertRaises(ConfigError):
            rig.master.request(SLAVE, Sap.SET_PRM)

    def test_acyclic_refused_or_lost(self):
        rig = Rig()
        rig.until(lambda: rig.h.connected)
        rig.slave._sap_handlers.pop(Sap.RD_OUTP)
        job = rig.master.request(SLAVE, Sap.RD_OUTP)
        rig.until(lambda: job.done)
        self.assertIsInstance(job.error, DpError)
        faulty = FaultyLink(rig.link)
        rig.master.replace_link(faulty)
        faulty.cut()
        job = rig.master.request(SLAVE, Sap.GET_CFG)
        rig.until(lambda: job.done, dt=0.01)
        self.assertIsInstance(job.error, DpTimeoutError)

    def test_configuration_errors(self):
        m = DpMaster(SlaveLink(DpSlave(SLAVE, ROBOT_IDENT, ROBOT_CFG)), MASTER)
        m.add_slave(ROBOT)
        with self.assertRaises(ConfigError):
            m.add_slave(ROBOT)
        with self.assertRaises(ConfigError):
            m.add_slave(SlaveSpec(MASTER, ROBOT_IDENT, ROBOT_CFG))
        with self.assertRaises(ConfigError):
            m.slave(99)
        with self.assertRaises(ConfigError):
            DpMaster(m.link, 126)
        with self.assertRaises(DpError):
            SlaveLink([])


class BlockingApiTest(unittest.TestCase):
    """Real time, a slave server thread on a memory link; waits are event driven."""

    def setUp(self) -> None:
        self.master_end, slave_end = MemoryLink.pair()
        self.slave = DpSlave(SLAVE, ROBOT_IDENT, ROBOT_CFG)
        self.slave.on_outputs = lambda d: setattr(self.slave, "inputs", transform(d))
        self.server = SlaveServer(slave_end, self.slave, flush_on_start=False)
        self.server.start()
        self.master = DpMaster(self.master_end, MASTER, 19200, reply_timeout_floor=0.5)
        self.h = self.master.add_slave(ROBOT)

    def tearDown(self) -> None:
        self.server.stop()

    def test_cycles_and_reads(self):
        self.assertTrue(self.master.wait_connected(SLAVE, 10))
        for i in range(50):
            out = bytes([i]) * 14
            self.h.outputs = out
            self.assertTrue(self.master.cycle(timeout=5))
            self.assertEqual(self.h.inputs, transform(out))
        self.master.run_cycles(5)
        self.assertEqual(self.master.get_cfg(SLAVE), ROBOT_CFG)
        self.assertEqual(self.master.read_outputs(SLAVE), bytes([49]) * 14)
        self.assertEqual(self.master.read_inputs(SLAVE), transform(bytes([49]) * 14))

    def test_fixed_rate_loop_stops_on_event(self):
        stop = threading.Event()
        seen = []

        def on_cycle(m: DpMaster) -> None:
            seen.append(m.counters.cycles)
            if m.slave(SLAVE).connected and len(seen) >= 20:
                stop.set()

        self.master.run(0.001, stop, on_cycle)
        self.assertTrue(self.h.connected)
        self.assertEqual(seen, sorted(seen))

    def test_absent_slave_does_not_spin(self):
        m = DpMaster(MemoryLink.pair()[0], MASTER, reply_timeout_floor=0.01,
                     backoff_min=0.05, backoff_max=0.05)
        h = m.add_slave(SlaveSpec(9, ROBOT_IDENT, ROBOT_CFG))
        m.run_cycles(6)
        self.assertFalse(h.connected)
        # every cycle either waited for a reply or for the back-off: few requests
        self.assertLessEqual(m.counters.requests, 8)


if __name__ == "__main__":
    unittest.main()
