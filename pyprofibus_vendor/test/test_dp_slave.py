"""DP slave engine: every state transition, driven by telegrams and a fake clock."""
from __future__ import annotations

import threading
import unittest
from typing import List, Optional

from pyprofibus_vendor.dp import (DiagStatus1, DiagStatus2, GcCommand, GlobalControl,
                                  PrmStationStatus, Sap, SetPrm, SetSlaveAdd, SlaveDiag,
                                  global_control_frame, request_frame)
from pyprofibus_vendor.dp_slave import DpSlave, SlaveLink, SlaveServer, SlaveState
from pyprofibus_vendor.errors import DpError, PhyError
from pyprofibus_vendor.fdl import (Deframer, FcbRequester, Frame, FrameControl, RequestFunction,
                                   ResponseStatus, Sd1, Sd2, Sd3, Sd4, ShortAck, decode_frame)
from pyprofibus_vendor.phy import MemoryLink

from _helpers import MASTER, ROBOT_BYTES, ROBOT_CFG, ROBOT_IDENT, SLAVE, FakeClock, transform

LOCK_WD = PrmStationStatus.LOCK_REQ | PrmStationStatus.WD_ON


class Requester:
    """A minimal master side: builds requests with a correct FCB sequence."""

    def __init__(self, slave: DpSlave, address: int = MASTER) -> None:
        self.slave = slave
        self.address = address
        self.fcb = FcbRequester()

    def frame(self, sap: Optional[int], payload: bytes = b"") -> Frame:
        fcb, fcv = self.fcb.bits()
        return request_frame(self.slave.address, self.address, fcb, fcv, sap, payload)

    def call(self, sap: Optional[int], payload: bytes = b"") -> Optional[Frame]:
        reply = self.slave.handle(self.frame(sap, payload))
        self.fcb.acknowledge()
        return reply

    def diag(self) -> SlaveDiag:
        reply = self.call(Sap.SLAVE_DIAG)
        assert isinstance(reply, (Sd2, Sd3)), reply
        assert (reply.dsap, reply.ssap, reply.da) == (62, 60, self.address)
        return SlaveDiag.decode(reply.data)

    def set_prm(self, **kw) -> Optional[Frame]:
        args = dict(ident=ROBOT_IDENT, station_status=LOCK_WD, wd_fact1=10, wd_fact2=1)
        args.update(kw)
        return self.call(Sap.SET_PRM, SetPrm(**args).encode())

    def chk_cfg(self, cfg: bytes = ROBOT_CFG) -> Optional[Frame]:
        return self.call(Sap.CHK_CFG, cfg)

    def dx(self, outputs: bytes) -> Optional[Frame]:
        return self.call(None, outputs)


class SlaveTestBase(unittest.TestCase):
    def setUp(self) -> None:
        self.clock = FakeClock()
        self.delivered: List[bytes] = []
        self.changes: List[tuple] = []
        self.slave = DpSlave(SLAVE, ROBOT_IDENT, ROBOT_CFG, clock=self.clock,
                             on_outputs=self.on_outputs,
                             on_state_change=lambda o, n, r: self.changes.append((o, n)))
        self.m = Requester(self.slave)

    def on_outputs(self, data: bytes) -> None:
        self.delivered.append(data)
        self.slave.inputs = transform(data)

    def to_data_exchange(self) -> None:
        self.assertIsInstance(self.m.set_prm(), ShortAck)
        self.assertIsInstance(self.m.chk_cfg(), ShortAck)
        self.assertIs(self.slave.state, SlaveState.DATA_EXCH)


class InitialAndFdl(SlaveTestBase):
    def test_power_up_diag(self):
        self.assertIs(self.slave.state, SlaveState.WAIT_PRM)
        self.assertEqual(self.m.diag().encode(), bytes.fromhex("02 05 00 FF 06 C6"))
        self.assertEqual(self.slave.input_size, ROBOT_BYTES)
        self.assertEqual(self.slave.output_size, ROBOT_BYTES)

    def test_fdl_status_any_state(self):
        req = Sd1(SLAVE, MASTER, FrameControl.req(RequestFunction.FDL_STATUS))
        self.assertEqual(self.slave.handle(req).encode(), bytes.fromhex("10 02 04 00 06 16"))
        self.to_data_exchange()
        self.assertEqual(self.slave.handle(req).encode(), bytes.fromhex("10 02 04 00 06 16"))

    def test_ignores_what_is_not_for_it(self):
        s = self.slave
        other = request_frame(SLAVE + 1, MASTER, True, False, Sap.SLAVE_DIAG)
        resp = Sd1(SLAVE, MASTER, FrameControl.resp(ResponseStatus.OK))
        for frame in (other, resp, Sd4(SLAVE, MASTER), ShortAck(),
                      Sd1(127, MASTER, FrameControl.req(RequestFunction.FDL_STATUS))):
            self.assertIsNone(s.handle(frame))
        self.assertEqual(s.counters.requests, 1)   # only the broadcast FDL_Status counted

    def test_unsupported_requests_get_rs(self):
        s = self.slave
        for frame in (
            request_frame(SLAVE, MASTER, True, False, 49),                      # DP-V1 SAP
            Sd2(SLAVE, MASTER, FrameControl.req(RequestFunction.SRD_HIGH, True), b"\x01",
                dsap=60),                                                       # no SSAP
            Sd1(SLAVE, MASTER, FrameControl.req(RequestFunction.SDA_HIGH)),     # SDA
        ):
            reply = s.handle(frame)
            self.assertIsInstance(reply, Sd1)
            self.assertEqual(reply.fc.status, ResponseStatus.RS)
        self.assertEqual(s.counters.rejected, 3)


class SetPrmTransitions(SlaveTestBase):
    def test_good_set_prm_goes_to_wait_cfg(self):
        self.assertIsInstance(self.m.set_prm(), ShortAck)
        self.assertIs(self.slave.state, SlaveState.WAIT_CFG)
        self.assertEqual(self.slave.locked_by, MASTER)
        self.assertAlmostEqual(self.slave.watchdog_time, 0.1)
        self.assertEqual(self.m.diag().encode(), bytes.fromhex("02 0C 00 02 06 C6"))
        self.assertEqual(self.changes, [(SlaveState.WAIT_PRM, SlaveState.WAIT_CFG)])

    def test_wrong_ident_prm_fault(self):
        self.assertIsInstance(self.m.set_prm(ident=0x4D14), ShortAck)
        self.assertIs(self.slave.state, SlaveState.WAIT_PRM)
        d = self.m.diag()
        self.assertTrue(d.status1 & DiagStatus1.PRM_FAULT)
        self.assertTrue(d.status2 & DiagStatus2.PRM_REQ)
        self.assertIsNone(d.locked_by)
        # a good Set_Prm clears the fault
        self.m.set_prm()
        self.assertFalse(self.m.diag().status1 & DiagStatus1.PRM_FAULT)

    def test_prm_fault_in_wait_cfg_goes_back_to_wait_prm(self):
        self.m.set_prm()
        self.m.set_prm(ident=0x1234)
        self.assertIs(self.slave.state, SlaveState.WAIT_PRM)
        self.assertIsNone(self.slave.locked_by)
        self.assertEqual(self.changes, [(SlaveState.WAIT_PRM, SlaveState.WAIT_CFG),
                                        (SlaveState.WAIT_CFG, SlaveState.WAIT_PRM)])

    def test_malformed_and_bad_parameters(self):
        self.m.call(Sap.SET_PRM, b"\x88\x01\x01")
        self.assertTrue(self.m.diag().status1 & DiagStatus1.PRM_FAULT)
        self.m.set_prm(wd_fact1=0)
        self.assertIs(self.slave.state, SlaveState.WAIT_PRM)
        self.assertEqual(self.slave.counters.prm_faults, 2)

    def test_user_prm_check(self):
        s = DpSlave(SLAVE, ROBOT_IDENT, ROBOT_CFG, clock=self.clock,
                    prm_check=lambda prm: prm.user_prm_data == b"\x01")
        m = Requester(s)
        m.set_prm(user_prm_data=b"\x02")
        self.assertIs(s.state, SlaveState.WAIT_PRM)
        self.assertTrue(m.diag().status1 & DiagStatus1.PRM_FAULT)
        m.set_prm(user_prm_data=b"\x01")
        self.assertIs(s.state, SlaveState.WAIT_CFG)
        self.assertEqual(s.prm.user_prm_data, b"\x01")

    def test_lock0_unlock0_only_min_tsdr(self):
        self.m.set_prm(station_status=PrmStationStatus(0), min_tsdr=42)
        self.assertIs(self.slave.state, SlaveState.WAIT_PRM)
        self.assertEqual(self.slave.min_tsdr, 42)

    def test_unlock_releases(self):
        self.to_data_exchange()
        self.m.dx(bytes(range(14)))
        self.m.set_prm(station_status=PrmStationStatus.UNLOCK_REQ)
        self.assertIs(self.slave.state, SlaveState.WAIT_PRM)
        self.assertIsNone(self.slave.locked_by)
        self.assertEqual(self.delivered[-1], bytes(14))     # safe outputs on leaving DX

    def test_new_set_prm_in_data_exchange_back_to_wait_cfg(self):
        self.to_data_exchange()
        self.m.dx(b"\x01" * 14)
        self.m.set_prm()
        self.assertIs(self.slave.state, SlaveState.WAIT_CFG)
        self.assertEqual(self.slave.outputs, bytes(14))

    def test_locked_by_another_master(self):
        self.to_data_exchange()
        other = Requester(self.slave, address=3)
        self.assertIsInstance(other.set_prm(), ShortAck)
        self.assertIs(self.slave.state, SlaveState.DATA_EXCH)
        self.assertEqual(self.slave.locked_by, MASTER)
        d = other.diag()
        self.assertEqual(d.master_address, MASTER)           # the other master sees the owner
        self.assertFalse(d.ready_for(3))
        self.assertIn("locked by another master (2)", " ".join(d.words(3)))
        other.chk_cfg(b"\x3d")                               # ignored, no Cfg_Fault
        self.assertFalse(self.m.diag().status1 & DiagStatus1.CFG_FAULT)
        reply = other.dx(bytes(14))
        self.assertEqual(reply.fc.status, ResponseStatus.RS)
        other.set_prm(station_status=PrmStationStatus.UNLOCK_REQ)   # cannot unlock either
        self.assertEqual(self.slave.locked_by, MASTER)
        self.assertEqual(self.slave.counters.prm_refused, 3)
        self.assertEqual(self.slave.counters.rejected, 1)


class ChkCfgTransitions(SlaveTestBase):
    def test_good_cfg_goes_to_data_exchange(self):
        self.m.set_prm()
        self.assertIsInstance(self.m.chk_cfg(), ShortAck)
        self.assertIs(self.slave.state, SlaveState.DATA_EXCH)
        self.assertEqual(self.m.diag().encode(), bytes.fromhex("00 0C 00 02 06 C6"))

    def test_cfg_mismatch_stays_with_cfg_fault(self):
        self.m.set_prm()
        for wrong in (b"\x3d", ROBOT_CFG[::-1]):
            self.assertIsInstance(self.m.chk_cfg(wrong), ShortAck)
            self.assertIs(self.slave.state, SlaveState.WAIT_CFG)
            self.assertTrue(self.m.diag().status1 & DiagStatus1.CFG_FAULT)
        self.m.call(Sap.CHK_CFG)                             # empty cfg is a mismatch too
        self.assertEqual(self.slave.counters.cfg_faults, 3)
        self.m.chk_cfg()
        self.assertIs(self.slave.state, SlaveState.DATA_EXCH)
        self.assertFalse(self.m.diag().status1 & DiagStatus1.CFG_FAULT)

    def test_cfg_mismatch_in_data_exchange(self):
        self.to_data_exchange()
        self.m.dx(b"\x07" * 14)
        self.m.chk_cfg(b"\x3d")
        self.assertIs(self.slave.state, SlaveState.WAIT_CFG)
        self.assertEqual(self.slave.outputs, bytes(14))

    def test_chk_cfg_before_set_prm_ignored(self):
        self.m.chk_cfg()
        self.assertIs(self.slave.state, SlaveState.WAIT_PRM)


class DataExchangeTest(SlaveTestBase):
    def test_exchange_and_callbacks(self):
        self.to_data_exchange()
        for i in range(5):
            out = bytes([i]) * 14
            reply = self.m.dx(out)
            self.assertIsInstance(reply, Sd2)
            self.assertEqual(reply.fc.status, ResponseStatus.DL)
            self.assertEqual((reply.da, reply.dsap, reply.ssap), (MASTER, None, None))
            self.assertEqual(reply.data, transform(out))
        self.assertEqual(self.delivered, [bytes([i]) * 14 for i in range(5)])
        self.assertEqual(self.slave.outputs, bytes([4]) * 14)

    def test_repeated_fcb_returns_stored_reply_without_redelivery(self):
        self.to_data_exchange()
        frame = self.m.frame(None, b"\x11" * 14)
        first = self.slave.handle(frame)
        self.slave.inputs = b"\x99" * 14                   # would change a fresh reply
        again = self.slave.handle(frame)                   # retry: same FCB, FCV=1
        self.assertEqual(again, first)
        self.assertEqual(self.delivered, [b"\x11" * 14])
        self.assertEqual(self.slave.counters.duplicates, 1)
        self.m.fcb.acknowledge()
        self.m.dx(b"\x12" * 14)                            # a toggled FCB executes again
        self.assertEqual(self.delivered[-1], b"\x12" * 14)

    def test_not_in_data_exchange_rs(self):
        reply = self.m.dx(bytes(14))
        self.assertEqual(reply.fc.status, ResponseStatus.RS)
        self.m.set_prm()
        self.assertEqual(self.m.dx(bytes(14)).fc.status, ResponseStatus.RS)
        self.assertEqual(self.delivered, [])

    def test_wrong_length_ue_not_delivered(self):
        self.to_data_exchange()
        reply = self.m.dx(bytes(13))
        self.assertEqual(reply.fc.status, ResponseStatus.UE)
        self.assertEqual(self.delivered, [])

    def test_diag_pending_gives_dh_until_read(self):
        self.to_data_exchange()
        self.slave.set_diag(b"\x43\x01\x02")
        self.assertEqual(self.m.dx(bytes(14)).fc.status, ResponseStatus.DH)
        d = self.m.diag()
        self.assertTrue(d.status1 & DiagStatus1.EXT_DIAG)
        self.assertEqual(d.ext_diag, b"\x43\x01\x02")
        self.assertEqual(self.m.dx(bytes(14)).fc.status, ResponseStatus.DL)
        self.slave.set_diag(stat_diag=True)
        self.assertTrue(self.m.diag().status2 & DiagStatus2.STAT_DIAG)

    def test_ext_diag_overflow(self):
        self.slave.set_diag(b"\x05" + bytes(250))
        d = self.m.diag()
        self.assertEqual(len(d.encode()), 244)
        self.assertTrue(d.status3)

    def test_output_only_slave_short_ack(self):
        s = DpSlave(SLAVE, ROBOT_IDENT, b"\x2D", clock=self.clock)
        m = Requester(s)
        m.set_prm()
        m.chk_cfg(b"\x2D")
        self.assertIsInstance(m.dx(bytes(14)), ShortAck)
        s.set_diag(b"\x41")
        reply = m.dx(bytes(14))
        self.assertEqual((type(reply), reply.fc.status), (Sd1, ResponseStatus.DH))

    def test_read_services(self):
        self.to_data_exchange()
        self.m.dx(b"\x05" * 14)
        self.assertEqual(self.m.call(Sap.GET_CFG).data, ROBOT_CFG)
        self.assertEqual(self.m.call(Sap.RD_INP).data, transform(b"\x05" * 14))
        self.assertEqual(self.m.call(Sap.RD_OUTP).data, b"\x05" * 14)

    def test_get_inputs_callback(self):
        s = DpSlave(SLAVE, ROBOT_IDENT, ROBOT_CFG, clock=self.clock,
                    get_inputs=lambda: b"\x42" * 14)
        m = Requester(s)
        m.set_prm()
        m.chk_cfg()
        self.assertEqual(m.dx(bytes(14)).data, b"\x42" * 14)
        s.get_inputs = lambda: b"\x42"
        with self.assertRaises(DpError):
            m.dx(bytes(14))


class WatchdogTest(SlaveTestBase):
    def test_expiry_in_data_exchange(self):
        self.to_data_exchange()
        self.m.dx(b"\x33" * 14)
        for _ in range(5):                        # requests within 0.1 s keep it alive
            self.clock.advance(0.09)
            self.m.dx(b"\x33" * 14)
            self.slave.step()
        self.assertIs(self.slave.state, SlaveState.DATA_EXCH)
        self.assertAlmostEqual(self.slave.next_deadline(), self.clock.t + 0.1)
        self.clock.advance(0.11)
        self.slave.step()
        self.assertIs(self.slave.state, SlaveState.WAIT_PRM)
        self.assertEqual(self.delivered[-1], bytes(14))
        d = self.m.diag()
        self.assertTrue(d.status2 & DiagStatus2.PRM_REQ)
        self.assertIsNone(d.locked_by)
        self.assertEqual(self.slave.counters.watchdog_expiries, 1)
        self.assertIsNone(self.slave.next_deadline())

    def test_expiry_checked_before_a_late_request(self):
        self.to_data_exchange()
        self.clock.advance(0.5)
        reply = self.m.dx(bytes(14))             # arrives after the watchdog ran out
        self.assertEqual(reply.fc.status, ResponseStatus.RS)

    def test_expiry_in_wait_cfg_and_custom_safe_image(self):
        s = DpSlave(SLAVE, ROBOT_IDENT, ROBOT_CFG, clock=self.clock, safe_outputs=b"\xEE" * 14)
        m = Requester(s)
        m.set_prm()
        self.clock.advance(0.2)
        s.step()
        self.assertIs(s.state, SlaveState.WAIT_PRM)
        self.assertEqual(s.outputs, b"\xEE" * 14)

    def test_no_watchdog_without_wd_on(self):
        self.m.set_prm(station_status=PrmStationStatus.LOCK_REQ)
        self.m.chk_cfg()
        self.clock.advance(1000)
        self.slave.step()
        self.assertIs(self.slave.state, SlaveState.DATA_EXCH)
        self.assertFalse(self.m.diag().status2 & DiagStatus2.WD_ON)

    def test_foreign_master_does_not_retrigger(self):
        self.to_data_exchange()
        other = Requester(self.slave, address=3)
        for _ in range(3):
            self.clock.advance(0.06)
            other.diag()
        self.assertIs(self.slave.state, SlaveState.WAIT_PRM)


class GlobalControlTest(SlaveTestBase):
    def gc(self, command: GcCommand, group: int = 0, sa: int = MASTER) -> None:
        self.assertIsNone(self.slave.handle(global_control_frame(sa, GlobalControl(command,
                                                                                     group))))

    def test_clear_data(self):
        self.to_data_exchange()
        self.m.dx(b"\x01" * 14)
        self.gc(GcCommand.CLEAR_DATA)
        self.assertEqual(self.delivered[-1], bytes(14))
        self.assertEqual(self.slave.counters.global_controls, 1)

    def test_ignored_from_other_master_wrong_group_or_state(self):
        self.gc(GcCommand.CLEAR_DATA)                      # not in DATA_EXCH
        self.to_data_exchange()
        self.gc(GcCommand.CLEAR_DATA, sa=3)
        self.gc(GcCommand.CLEAR_DATA, group=0x04)           # slave is in no group
        self.slave.handle(request_frame(127, MASTER, False, False, Sap.GLOBAL_CONTROL, b"\x02",
                                        function=RequestFunction.SDN_HIGH))  # malformed
        self.assertEqual(self.slave.counters.global_controls, 0)
        self.assertEqual(self.delivered, [])

    def test_sync_and_freeze(self):
        ss = LOCK_WD | PrmStationStatus.SYNC_REQ | PrmStationStatus.FREEZE_REQ
        self.m.set_prm(station_status=ss, group_ident=0x01)
        self.m.chk_cfg()
        self.m.dx(b"\x01" * 14)
        self.gc(GcCommand.SYNC, group=0x01)
        self.assertTrue(self.m.diag().status2 & DiagStatus2.SYNC_MODE)
        self.m.dx(b"\x02" * 14)                            # held while in sync mode
        self.assertEqual(self.slave.outputs, b"\x01" * 14)
        self.gc(GcCommand.SYNC)
        self.assertEqual(self.slave.outputs, b"\x02" * 14)
        self.gc(GcCommand.UNSYNC | GcCommand.SYNC)          # Unsync wins
        self.m.dx(b"\x03" * 14)
        self.assertEqual(self.slave.outputs, b"\x03" * 14)
        # freeze: inputs are latched at the Freeze command
        self.slave.inputs = b"\x10" * 14
        self.gc(GcCommand.FREEZE)
        self.slave.inputs = b"\x20" * 14
        self.assertEqual(self.m.call(Sap.RD_INP).data, b"\x10" * 14)
        self.assertTrue(self.m.diag().status2 & DiagStatus2.FREEZE_MODE)
        self.gc(GcCommand.UNFREEZE)
        self.assertEqual(self.m.call(Sap.RD_INP).data, b"\x20" * 14)

    def test_sync_without_sync_req_ignored(self):
        self.to_data_exchange()
        self.gc(GcCommand.SYNC)
        self.assertFalse(self.m.diag().status2 & DiagStatus2.SYNC_MODE)


class SetSlaveAddTest(unittest.TestCase):
    def test_change_once(self):
        s = DpSlave(126, ROBOT_IDENT, ROBOT_CFG, address_changeable=True, clock=FakeClock())
        m = Requester(s)
        self.assertIsInstance(m.call(Sap.SET_SLAVE_ADD,
                                     SetSlaveAdd(SLAVE, ROBOT_IDENT, True).encode()), ShortAck)
        self.assertEqual(s.address, SLAVE)
        m.fcb.reset()
        m.call(Sap.SET_SLAVE_ADD, SetSlaveAdd(7, ROBOT_IDENT).encode())
        self.assertEqual(s.address, SLAVE)                  # No_Add_Chg locked it
        reply = m.call(Sap.SET_SLAVE_ADD, b"\x01")
        self.assertEqual(reply.fc.status, ResponseStatus.UE)

    def test_refused_when_not_changeable(self):
        s = DpSlave(SLAVE, ROBOT_IDENT, ROBOT_CFG, clock=FakeClock())
        Requester(s).call(Sap.SET_SLAVE_ADD, SetSlaveAdd(9, ROBOT_IDENT).encode())
        self.assertEqual(s.address, SLAVE)


class ConstructionTest(unittest.TestCase):
    def test_bad_arguments(self):
        for kw in (dict(address=127), dict(ident=0x10000), dict(cfg=b""),
                   dict(safe_outputs=b"\x00")):
            args = dict(address=SLAVE, ident=ROBOT_IDENT, cfg=ROBOT_CFG)
            args.update(kw)
            with self.assertRaises(DpError):
                DpSlave(**args)
        s = DpSlave(SLAVE, ROBOT_IDENT, ROBOT_CFG)
        with self.assertRaises(DpError):
            s.inputs = b"\x00"


class LinksTest(unittest.TestCase):
    def test_slave_link_answers_in_process(self):
        s = DpSlave(SLAVE, ROBOT_IDENT, ROBOT_CFG, clock=FakeClock())
        link = SlaveLink(s)
        link.send(Sd1(SLAVE, MASTER, FrameControl.req(RequestFunction.FDL_STATUS)).encode())
        self.assertEqual(link.recv(100, 1.0), bytes.fromhex("10 02 04 00 06 16"))
        link.send(b"\xE5")                                  # not a request: no reply
        link.flush_input()
        self.assertEqual(link.recv(), b"")
        with self.assertRaises(PhyError):
            link.recv(10, None)
        link.close()
        with self.assertRaises(PhyError):
            link.send(b"\x00")
        with self.assertRaises(PhyError):
            link.recv()

    def test_server_on_memory_link(self):
        master_end, slave_end = MemoryLink.pair()
        master_end.send(b"stale backlog")                   # flushed when the server starts
        s1 = DpSlave(SLAVE, ROBOT_IDENT, ROBOT_CFG)
        s2 = DpSlave(SLAVE + 1, ROBOT_IDENT, ROBOT_CFG)
        server = SlaveServer(slave_end, [s1, s2], idle_reset=0.01)
        started = threading.Event()
        real_flush = slave_end.flush_input

        def flush_and_signal():
            real_flush()
            started.set()

        slave_end.flush_input = flush_and_signal
        server.start()
        self.assertTrue(started.wait(5))
        deframer = Deframer()
        try:
            for addr in (SLAVE, SLAVE + 1):
                req = Sd1(addr, MASTER, FrameControl.req(RequestFunction.FDL_STATUS))
                master_end.send(b"\x68\x09" + req.encode())  # a partial frame first... and garbage
                frames: List[Frame] = []
                while not frames:
                    data = master_end.recv(100, 5.0)
                    self.assertTrue(data, "no reply from the server")
                    frames = deframer.feed(data)
                self.assertEqual(frames, [decode_frame(bytes([0x10, MASTER, addr, 0x00,
                                                              MASTER + addr, 0x16]))])
        finally:
            server.stop()
        self.assertIsNone(server.error)
        self.assertEqual(server.counters.replies, 2)

    def test_server_discards_partial_frame_when_line_idles(self):
        master_end, slave_end = MemoryLink.pair()
        server = SlaveServer(slave_end, DpSlave(SLAVE, ROBOT_IDENT, ROBOT_CFG),
                             idle_reset=0.01, flush_on_start=False)
        discarded = threading.Event()
        real = server.deframer.discard_partial

        def discard():
            n = real()
            discarded.set()
            return n

        server.deframer.discard_partial = discard
        server.start()
        try:
            master_end.send(b"\x68\xF0\xF0\x68\x84")        # claims 246 more bytes, never sent
            self.assertTrue(discarded.wait(5))
            master_end.send(Sd1(SLAVE, MASTER,
                                FrameControl.req(RequestFunction.FDL_STATUS)).encode())
            self.assertEqual(master_end.recv(100, 5.0), bytes.fromhex("10 02 04 00 06 16"))
        finally:
            server.stop()
        self.assertEqual(server.counters.idle_discards, 1)
        self.assertEqual(server.deframer.counters.garbage_bytes, 5)

    def test_server_records_link_failure(self):
        master_end, slave_end = MemoryLink.pair()
        server = SlaveServer(slave_end, DpSlave(SLAVE, ROBOT_IDENT, ROBOT_CFG), poll=0.01)
        thread = server.start()
        master_end.close()
        thread.join(5)
        self.assertFalse(thread.is_alive())
        self.assertIsInstance(server.error, PhyError)
        with self.assertRaises(DpError):
            SlaveServer(slave_end, [])


if __name__ == "__main__":
    unittest.main()
