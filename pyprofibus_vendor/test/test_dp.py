"""DP service payloads: golden bytes, round trips, errors, helpers."""
from __future__ import annotations

import unittest

from pyprofibus_vendor.dp import (ChkCfg, DataExchange, DiagStatus1, DiagStatus2, DiagStatus3,
                                  GcCommand, GetCfg, GlobalControl, PrmStationStatus, Sap,
                                  SetPrm, SetSlaveAdd, SlaveDiag, cfg_io_lengths, explain_diag,
                                  global_control_frame, parse_ext_diag, reply_frame,
                                  request_frame, watchdog_factors)
from pyprofibus_vendor.errors import ConfigError, DpError
from pyprofibus_vendor.fdl import RequestFunction, ResponseStatus, Sd1, Sd2, Sd3, decode_frame

from _helpers import ROBOT_CFG, ROBOT_IDENT
from test_fdl import CHK_CFG_REQ, DIAG_REQ, DIAG_REPLY_1, DIAG_REPLY_2, SET_PRM_REQ


class SlaveDiagTest(unittest.TestCase):
    def test_golden_power_up(self):
        d = SlaveDiag.decode(bytes.fromhex("02 05 00 FF 4D 14"))
        self.assertEqual(d.status1, DiagStatus1.STATION_NOT_READY)
        self.assertEqual(d.status2, DiagStatus2.PRM_REQ | DiagStatus2.ALWAYS_ONE)
        self.assertIsNone(d.locked_by)
        self.assertEqual(d.ident, 0x4D14)
        self.assertFalse(d.ready_for(2))
        self.assertEqual(d.encode(), bytes.fromhex("02 05 00 FF 4D 14"))

    def test_golden_ready(self):
        d = SlaveDiag.decode(bytes.fromhex("00 0C 00 02 4D 14"))
        self.assertTrue(d.ready_for(2))
        self.assertFalse(d.ready_for(3))
        self.assertEqual(d.locked_by, 2)
        self.assertTrue(d.status2 & DiagStatus2.WD_ON)

    def test_in_frames(self):
        self.assertEqual(SlaveDiag.decode(decode_frame(DIAG_REPLY_1).data).ident, 0x4D14)
        self.assertTrue(SlaveDiag.decode(decode_frame(DIAG_REPLY_2).data).ready_for(2))

    def test_ext_diag_round_trip_and_parse(self):
        ext = bytes.fromhex("43 01 02 81 01 02 03 AA BB")
        d = SlaveDiag(DiagStatus1.EXT_DIAG, DiagStatus2.ALWAYS_ONE, DiagStatus3(0), 2,
                      ROBOT_IDENT, ext)
        self.assertEqual(SlaveDiag.decode(d.encode()), d)
        blocks = parse_ext_diag(ext)
        self.assertEqual([b.kind for b in blocks], ["identifier", "channel", "device"])
        self.assertEqual(blocks[2].data, b"\x03\xAA\xBB")

    def test_ext_diag_errors(self):
        for bad in (b"\xC1", b"\x00", b"\x05\x01", b"\x81\x01"):
            with self.assertRaises(DpError):
                parse_ext_diag(bad)

    def test_decode_errors(self):
        with self.assertRaises(DpError):
            SlaveDiag.decode(b"\x00\x04\x00\xFF\x06")
        with self.assertRaises(DpError):
            SlaveDiag.decode(bytes(245))
        with self.assertRaises(DpError):
            SlaveDiag(ident=0x10000)
        with self.assertRaises(DpError):
            SlaveDiag(master_address=256)
        with self.assertRaises(DpError):
            SlaveDiag(status1=0x100)
        with self.assertRaises(DpError):
            SlaveDiag(ext_diag=bytes(239))

    def test_words(self):
        d = SlaveDiag.decode(bytes.fromhex("46 05 00 FF 06 C6"))
        text = explain_diag(d, 2)
        for words in ("not ready", "configuration fault", "parameter fault",
                      "requests new parameters"):
            self.assertIn(words, text)
        other = SlaveDiag.decode(bytes.fromhex("00 0C 00 05 06 C6"))
        self.assertIn("locked by another master (5)", explain_diag(other, 2))
        self.assertNotIn("another master", explain_diag(other, 5))
        self.assertIn("always-one", explain_diag(SlaveDiag.decode(bytes(6))))
        self.assertIn("unparsable", explain_diag(SlaveDiag(ext_diag=b"\xC0")))
        self.assertIn("ok", explain_diag(SlaveDiag.decode(bytes.fromhex("00 04 00 02 06 C6"))))


class SetPrmTest(unittest.TestCase):
    def test_golden(self):
        payload = decode_frame(SET_PRM_REQ).data
        prm = SetPrm.decode(payload)
        self.assertEqual(prm.station_status, PrmStationStatus.LOCK_REQ | PrmStationStatus.WD_ON)
        self.assertEqual((prm.wd_fact1, prm.wd_fact2, prm.min_tsdr, prm.ident, prm.group_ident),
                         (30, 1, 0, 0x4D14, 1))
        self.assertAlmostEqual(prm.watchdog_time, 0.3)
        self.assertEqual(prm.encode(), payload)

    def test_user_prm_and_no_watchdog(self):
        prm = SetPrm(ROBOT_IDENT, PrmStationStatus.LOCK_REQ, 1, 1, 11, 0, b"\x00\x01\x02")
        self.assertIsNone(prm.watchdog_time)
        self.assertEqual(SetPrm.decode(prm.encode()), prm)

    def test_errors(self):
        with self.assertRaises(DpError):
            SetPrm.decode(bytes(6))
        with self.assertRaises(DpError):
            SetPrm(ROBOT_IDENT, wd_fact1=256)
        with self.assertRaises(DpError):
            SetPrm(0x1FFFF)
        with self.assertRaises(DpError):
            SetPrm(ROBOT_IDENT, user_prm_data=bytes(238))

    def test_watchdog_factors(self):
        self.assertEqual(watchdog_factors(0.3), (30, 1))
        self.assertEqual(watchdog_factors(0.01), (1, 1))
        self.assertEqual(watchdog_factors(650.25), (255, 255))
        for seconds in (2.55, 2.56, 3.0, 10.0, 99.99, 300.0):
            f1, f2 = watchdog_factors(seconds)
            self.assertTrue(1 <= f1 <= 255 and 1 <= f2 <= 255)
            got = 0.01 * f1 * f2
            self.assertGreaterEqual(got + 1e-9, seconds)
            self.assertLess(got - seconds, 0.01 * f2 + 1e-9)
        self.assertEqual(watchdog_factors(0.001), (1, 1))      # rounded up to 10 ms
        for bad in (0.0, -1.0, 651.0):
            with self.assertRaises(ConfigError):
                watchdog_factors(bad)


class CfgTest(unittest.TestCase):
    def test_robot_cfg(self):
        self.assertEqual(cfg_io_lengths(ROBOT_CFG), (14, 14))

    def test_equivalent_forms(self):
        for cfg in ("3D", "BD", "2D 1D", "76", "F6", "C0 0D 0D", "C0 8D 8D"):
            self.assertEqual(cfg_io_lengths(bytes.fromhex(cfg)), (14, 14), cfg)
        self.assertEqual(cfg_io_lengths(bytes.fromhex("00")), (0, 0))          # empty slot
        self.assertEqual(cfg_io_lengths(bytes.fromhex("42 03 AA BB")), (4, 0))  # 2 manuf bytes
        self.assertEqual(cfg_io_lengths(bytes.fromhex("80 41")), (0, 4))         # 2 words out

    def test_truncated(self):
        for bad in ("C0 0D", "40", "03 AA"):
            with self.assertRaises(DpError):
                cfg_io_lengths(bytes.fromhex(bad))

    def test_payloads(self):
        self.assertEqual(ChkCfg.decode(decode_frame(CHK_CFG_REQ).data).cfg, b"\x3d")
        self.assertEqual(GetCfg.decode(ROBOT_CFG).encode(), ROBOT_CFG)
        for cls in (ChkCfg, GetCfg):
            with self.assertRaises(DpError):
                cls.decode(b"")
            with self.assertRaises(DpError):
                cls.decode(bytes(245))


class OtherServicesTest(unittest.TestCase):
    def test_data_exchange(self):
        self.assertEqual(DataExchange.decode(bytes(range(14))).encode(), bytes(range(14)))
        with self.assertRaises(DpError):
            DataExchange(bytes(245))

    def test_global_control(self):
        gc = GlobalControl(GcCommand.SYNC | GcCommand.CLEAR_DATA, 0x03)
        self.assertEqual(gc.encode(), b"\x22\x03")
        self.assertEqual(GlobalControl.decode(b"\x22\x03"), gc)
        self.assertTrue(gc.addresses_group(0x02))
        self.assertFalse(gc.addresses_group(0x04))
        self.assertTrue(GlobalControl(GcCommand.FREEZE).addresses_group(0))
        with self.assertRaises(DpError):
            GlobalControl.decode(b"\x02")
        with self.assertRaises(DpError):
            GlobalControl(GcCommand(0), 300)
        f = decode_frame(global_control_frame(2, gc).encode())
        self.assertEqual((f.da, f.dsap, f.ssap, f.fc.encode()), (127, 58, 62, 0x46))

    def test_set_slave_add(self):
        s = SetSlaveAdd(5, ROBOT_IDENT, True, b"\x01")
        self.assertEqual(s.encode(), b"\x05\x06\xC6\x01\x01")
        self.assertEqual(SetSlaveAdd.decode(s.encode()), s)
        with self.assertRaises(DpError):
            SetSlaveAdd.decode(b"\x05\x06")
        with self.assertRaises(DpError):
            SetSlaveAdd(126, ROBOT_IDENT)
        with self.assertRaises(DpError):
            SetSlaveAdd(3, -1)

    def test_request_and_reply_frames(self):
        req = request_frame(8, 2, True, False, Sap.SLAVE_DIAG)
        self.assertEqual(req.encode(), DIAG_REQ)
        rep = reply_frame(req, 8, bytes.fromhex("02 05 00 FF 4D 14"))
        self.assertIsInstance(rep, Sd3)
        self.assertEqual(rep.encode(), DIAG_REPLY_1)
        dx = request_frame(8, 2, False, True, None, bytes(14))
        self.assertIsInstance(dx, Sd2)
        self.assertEqual(dx.fc.function, RequestFunction.SRD_HIGH)
        nothing = reply_frame(dx, 8, b"", ResponseStatus.DL)
        self.assertIsInstance(nothing, Sd1)


if __name__ == "__main__":
    unittest.main()
