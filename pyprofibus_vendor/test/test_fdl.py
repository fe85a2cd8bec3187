"""FDL telegrams: golden bytes, round trips, every decode error, deframing, FCB/FCV."""
from __future__ import annotations

import unittest

from pyprofibus_vendor.errors import FcsError, FdlError, FrameError, TruncatedFrameError
from pyprofibus_vendor.fdl import (Deframer, FcbRequester, FcbResponder, FrameControl,
                                   RequestFunction, ResponseStatus, Sd1, Sd2, Sd3, Sd4,
                                   ShortAck, StationType, data_frame, decode_frame, fcs,
                                   frame_length, sd2_body, sd2_data, sd2_encode)

# a recorded real start-up (pyprofibus_vendor/README.md: slave 8, master 2, ident 0x4D14)
FDL_STATUS_REQ = bytes.fromhex("10 08 02 49 53 16")
FDL_STATUS_REPLY = bytes.fromhex("10 02 08 00 0A 16")
DIAG_REQ = bytes.fromhex("68 05 05 68 88 82 6D 3C 3E F1 16")
DIAG_REPLY_1 = bytes.fromhex("A2 82 88 08 3E 3C 02 05 00 FF 4D 14 F3 16")
SET_PRM_REQ = bytes.fromhex("68 0C 0C 68 88 82 5D 3D 3E 88 1E 01 00 4D 14 01 EB 16")
CHK_CFG_REQ = bytes.fromhex("68 06 06 68 88 82 7D 3E 3E 3D 40 16")
DIAG_REPLY_2 = bytes.fromhex("A2 82 88 08 3E 3C 00 0C 00 02 4D 14 FB 16")
DX_REQ = bytes.fromhex("68 11 11 68 08 02 7D") + bytes(range(1, 15)) + bytes.fromhex("F0 16")
DX_REPLY = bytes.fromhex("68 11 11 68 02 08 08") + bytes(range(1, 15)) + bytes.fromhex("7B 16")
GOLDEN = [FDL_STATUS_REQ, FDL_STATUS_REPLY, DIAG_REQ, DIAG_REPLY_1, SET_PRM_REQ, b"\xE5",
          CHK_CFG_REQ, DIAG_REPLY_2, DX_REQ, DX_REPLY]


class GoldenBytes(unittest.TestCase):
    def test_fdl_status_request(self):
        f = Sd1(8, 2, FrameControl.req(RequestFunction.FDL_STATUS))
        self.assertEqual(f.encode(), FDL_STATUS_REQ)
        self.assertEqual(decode_frame(FDL_STATUS_REQ), f)

    def test_fdl_status_reply(self):
        f = decode_frame(FDL_STATUS_REPLY)
        self.assertIsInstance(f, Sd1)
        self.assertFalse(f.fc.request)
        self.assertEqual(f.fc.status, ResponseStatus.OK)
        self.assertEqual(f.fc.station_type, StationType.SLAVE)
        self.assertEqual((f.da, f.sa), (2, 8))

    def test_diag_request_first_frame_bits(self):
        f = decode_frame(DIAG_REQ)
        self.assertIsInstance(f, Sd2)
        self.assertEqual((f.da, f.sa, f.dsap, f.ssap, f.data), (8, 2, 60, 62, b""))
        self.assertEqual((f.fc.function, f.fc.fcb, f.fc.fcv),
                         (RequestFunction.SRD_HIGH, True, False))
        self.assertEqual(f.encode(), DIAG_REQ)

    def test_diag_reply_is_sd3(self):
        f = decode_frame(DIAG_REPLY_1)
        self.assertIsInstance(f, Sd3)
        self.assertEqual((f.da, f.sa, f.dsap, f.ssap), (2, 8, 62, 60))
        self.assertEqual(f.data, bytes.fromhex("02 05 00 FF 4D 14"))
        self.assertEqual(f.fc.status, ResponseStatus.DL)
        self.assertEqual(f.encode(), DIAG_REPLY_1)
        # data_frame picks SD3 for an 8-byte data unit
        self.assertEqual(data_frame(2, 8, f.fc, f.data, 62, 60).encode(), DIAG_REPLY_1)

    def test_set_prm_and_chk_cfg(self):
        prm = decode_frame(SET_PRM_REQ)
        self.assertEqual((prm.dsap, prm.ssap, prm.fc.fcb, prm.fc.fcv), (61, 62, False, True))
        self.assertEqual(prm.data, bytes.fromhex("88 1E 01 00 4D 14 01"))
        cfg = decode_frame(CHK_CFG_REQ)
        self.assertEqual((cfg.dsap, cfg.data, cfg.fc.fcb), (62, b"\x3d", True))
        self.assertEqual(prm.encode(), SET_PRM_REQ)
        self.assertEqual(cfg.encode(), CHK_CFG_REQ)

    def test_data_exchange(self):
        req = decode_frame(DX_REQ)
        self.assertEqual((req.dsap, req.ssap, req.data), (None, None, bytes(range(1, 15))))
        rep = decode_frame(DX_REPLY)
        self.assertEqual(rep.fc.status, ResponseStatus.DL)
        self.assertEqual(Sd2(2, 8, FrameControl.resp(ResponseStatus.DL),
                             bytes(range(1, 15))).encode(), DX_REPLY)

    def test_short_ack_and_token(self):
        self.assertEqual(ShortAck().encode(), b"\xE5")
        self.assertEqual(decode_frame(b"\xE5"), ShortAck())
        self.assertEqual(Sd4(3, 2).encode(), b"\xDC\x03\x02")
        self.assertEqual(decode_frame(b"\xDC\x03\x02"), Sd4(3, 2))

    def test_fcs(self):
        self.assertEqual(fcs(bytes.fromhex("08 02 49")), 0x53)
        self.assertEqual(fcs(bytes([0xFF, 0x02])), 0x01)


class FrameControlTest(unittest.TestCase):
    def test_request_bits(self):
        self.assertEqual(FrameControl.req(RequestFunction.SRD_HIGH, True, True).encode(), 0x7D)
        self.assertEqual(FrameControl.req(RequestFunction.SRD_HIGH, False, True).encode(), 0x5D)
        self.assertEqual(FrameControl.req(RequestFunction.SRD_HIGH, True, False).encode(), 0x6D)
        self.assertEqual(FrameControl.req(RequestFunction.SDN_HIGH).encode(), 0x46)

    def test_response_bits(self):
        fc = FrameControl.decode(0x0A)
        self.assertEqual((fc.request, fc.status), (False, ResponseStatus.DH))
        self.assertEqual(FrameControl.resp(ResponseStatus.OK, StationType.MASTER_IN_RING)
                         .encode(), 0x30)

    def test_round_trip_all_valid_bytes(self):
        valid = 0
        for b in range(256):
            try:
                fc = FrameControl.decode(b)
            except FrameError:
                continue
            valid += 1
            self.assertEqual(fc.encode(), b)
        self.assertGreater(valid, 50)

    def test_invalid(self):
        with self.assertRaises(FrameError):
            FrameControl.decode(0x80 | 0x49)           # reserved bit
        with self.assertRaises(FrameError):
            FrameControl.decode(0x41)                  # request function 1 undefined
        with self.assertRaises(FrameError):
            FrameControl.decode(0x04)                  # response status 4 undefined
        with self.assertRaises(FrameError):
            FrameControl(False, 0, fcb=True)
        with self.assertRaises(FrameError):
            FrameControl.decode(0x1FF)
        with self.assertRaises(FrameError):
            FrameControl.decode(0x49).status
        with self.assertRaises(FrameError):
            FrameControl.decode(0x08).function

    def test_str(self):
        self.assertIn("SRD_HIGH", str(FrameControl.decode(0x7D)))
        self.assertIn("DL", str(FrameControl.decode(0x08)))


class RoundTrips(unittest.TestCase):
    def test_all_golden(self):
        for raw in GOLDEN:
            with self.subTest(raw=raw.hex()):
                self.assertEqual(decode_frame(raw).encode(), raw)

    def test_sd2_sizes(self):
        fc = FrameControl.req(RequestFunction.SRD_HIGH, True, True)
        for n in (1, 7, 9, 100, 246):
            f = Sd2(5, 1, fc, bytes(range(256))[:n])
            self.assertEqual(decode_frame(f.encode()), f)
            self.assertEqual(len(f.encode()), n + 9)
        for n in (0, 244):
            f = Sd2(5, 1, fc, bytes(n), dsap=61, ssap=62)
            self.assertEqual(decode_frame(f.encode()), f)

    def test_only_one_sap(self):
        fc = FrameControl.resp(ResponseStatus.DL)
        f = Sd2(5, 1, fc, b"\x01\x02", dsap=None, ssap=9)
        self.assertEqual(f.encode()[5], 0x81)
        self.assertEqual(decode_frame(f.encode()), f)

    def test_broadcast_and_data_frame_choice(self):
        fc = FrameControl.req(RequestFunction.SDN_HIGH)
        gc = data_frame(127, 2, fc, b"\x02\x00", 58, 62)
        self.assertIsInstance(gc, Sd2)
        self.assertEqual(decode_frame(gc.encode()).da, 127)
        self.assertIsInstance(data_frame(1, 2, fc), Sd1)
        self.assertIsInstance(data_frame(1, 2, fc, bytes(8)), Sd3)


class DecodeErrors(unittest.TestCase):
    def check(self, raw, exc=FrameError):
        with self.assertRaises(exc):
            decode_frame(raw)

    def test_empty_and_unknown_sd(self):
        self.check(b"", TruncatedFrameError)
        self.check(b"\x11\x00", FrameError)

    def test_wrong_decoder(self):
        with self.assertRaises(FrameError):
            Sd2.decode(FDL_STATUS_REQ)
        with self.assertRaises(TruncatedFrameError):
            Sd1.decode(b"")

    def test_sd1(self):
        self.check(FDL_STATUS_REQ[:-1], TruncatedFrameError)
        self.check(FDL_STATUS_REQ + b"\x00")                       # trailing byte
        self.check(FDL_STATUS_REQ[:4] + b"\x54\x16", FcsError)
        self.check(FDL_STATUS_REQ[:5] + b"\x17")                   # bad ED
        self.check(bytes.fromhex("10 88 02 49 D3 16"))             # ext bit without DU
        self.check(bytes.fromhex("10 02 7F 00 81 16"))             # SA broadcast

    def test_sd2_header(self):
        self.check(DIAG_REQ[:3], TruncatedFrameError)
        self.check(bytes.fromhex("68 05 06 68") + DIAG_REQ[4:])    # LE != LEr
        self.check(bytes.fromhex("68 03 03 68 08 02 49 53 16"))    # LE too small
        self.check(bytes.fromhex("68 FA FA 68") + bytes(252))      # LE too big
        self.check(bytes.fromhex("68 05 05 69") + DIAG_REQ[4:])    # second SD
        self.check(DIAG_REQ[:-2], TruncatedFrameError)

    def test_sd2_tail_and_content(self):
        self.check(DIAG_REQ[:-2] + b"\xF2\x16", FcsError)
        self.check(DIAG_REQ[:-1] + b"\x00")                        # bad ED

        def sd2(body: bytes) -> bytes:
            n = len(body)
            return bytes([0x68, n, n, 0x68]) + body + bytes([fcs(body), 0x16])

        self.check(sd2(bytes([0x88, 0x82, 0x6D, 0x3C])))            # SAE missing
        self.check(sd2(bytes([0x88, 0x02, 0x6D, 0xBC, 0x01])))      # chained extension
        self.check(sd2(bytes([0x88, 0x02, 0x6D, 0x7C, 0x01])))      # segment address
        self.check(sd2(bytes([0x08, 0x7F, 0x6D, 0x01])))            # SA 127
        self.check(sd2(bytes([0x08, 0x02, 0xC9, 0x01])))            # reserved FC bit
        ok = Sd2.decode(sd2(bytes([0x08, 0x82, 0x6D, 0x3E])))       # only an SAE
        self.assertEqual((ok.dsap, ok.ssap, ok.data), (None, 0x3E, b""))

    def test_sd3(self):
        self.check(DIAG_REPLY_1[:-1], TruncatedFrameError)
        self.check(DIAG_REPLY_1 + b"\x16")
        self.check(DIAG_REPLY_1[:-2] + b"\xF4\x16", FcsError)
        self.check(DIAG_REPLY_1[:-1] + b"\x10")

    def test_sd4_and_sc(self):
        self.check(b"\xDC\x03", TruncatedFrameError)
        self.check(b"\xDC\x83\x02")
        self.check(b"\xDC\x03\x7F")
        self.check(b"\xE5\xE5")

    def test_construction_checks(self):
        fc = FrameControl.req(RequestFunction.SRD_HIGH)
        for bad in (lambda: Sd1(128, 2, fc), lambda: Sd1(3, 127, fc), lambda: Sd1(-1, 2, fc),
                    lambda: Sd1(3, 2, 0x49), lambda: Sd2(3, 2, fc, b""),
                    lambda: Sd2(3, 2, fc, bytes(247)), lambda: Sd2(3, 2, fc, b"x", dsap=64),
                    lambda: Sd2(3, 2, fc, b"x", ssap=-1), lambda: Sd3(3, 2, fc, bytes(7)),
                    lambda: Sd3(3, 2, fc, bytes(8), dsap=1), lambda: Sd4(127, 2),
                    lambda: Sd2(3, 2, "fc", b"x")):
            with self.assertRaises(FrameError):
                bad()

    def test_frame_error_is_fdl_error(self):
        self.assertTrue(issubclass(FcsError, FdlError))
        with self.assertRaises(FrameError):
            frame_length(b"\x00")


class DeframerTest(unittest.TestCase):
    STREAM = b"".join(GOLDEN)

    def test_every_split_point(self):
        expected = [decode_frame(g) for g in GOLDEN]
        for i in range(len(self.STREAM) + 1):
            d = Deframer()
            frames = d.feed(self.STREAM[:i]) + d.feed(self.STREAM[i:])
            self.assertEqual(frames, expected, f"split at {i}")
            self.assertEqual(d.pending, 0)
            self.assertEqual(d.counters.garbage_bytes, 0)

    def test_byte_by_byte(self):
        d = Deframer()
        frames = []
        for b in self.STREAM:
            frames += d.feed(bytes([b]))
        self.assertEqual(len(frames), len(GOLDEN))
        self.assertEqual(d.counters.frames, len(GOLDEN))

    def test_garbage_before_and_between(self):
        d = Deframer()
        garbage = b"\x00\xFF\x12\x34"
        frames = d.feed(garbage + DX_REQ + garbage + b"\x55" + FDL_STATUS_REQ)
        self.assertEqual(frames, [decode_frame(DX_REQ), decode_frame(FDL_STATUS_REQ)])
        self.assertEqual(d.counters.garbage_bytes, 9)

    def test_resync_after_bad_fcs(self):
        bad = bytearray(DX_REQ)
        bad[10] ^= 0x01
        d = Deframer()
        self.assertEqual(d.feed(FDL_STATUS_REQ[:4] + b"\x54\x16"), [])
        self.assertIsInstance(d.last_error, FcsError)
        self.assertEqual(d.counters.garbage_bytes, 6)
        frames = d.feed(bytes(bad) + DIAG_REQ)
        self.assertEqual(frames, [decode_frame(DIAG_REQ)])
        self.assertEqual(d.counters.fcs_errors, 2)
        self.assertGreaterEqual(d.counters.garbage_bytes, 6 + len(DX_REQ))

    def test_resync_after_bad_header(self):
        d = Deframer()
        frames = d.feed(b"\x68\x05\x07\x68" + FDL_STATUS_REQ)
        self.assertEqual(frames, [decode_frame(FDL_STATUS_REQ)])
        # both 0x68 bytes start a candidate SD2 header that fails (LE != LEr)
        self.assertEqual(d.counters.format_errors, 2)
        self.assertEqual(d.counters.garbage_bytes, 4)

    def test_truncated_frame_followed_by_new_one(self):
        # a frame with a lost byte swallows the start of the next; the one after survives
        d = Deframer()
        frames = d.feed(DX_REQ[:-3] + DIAG_REQ + DIAG_REQ)
        self.assertEqual(frames[-1], decode_frame(DIAG_REQ))
        self.assertGreater(d.counters.garbage_bytes, 0)

    def test_partial_and_discard(self):
        d = Deframer()
        self.assertEqual(d.feed(DX_REQ[:5]), [])
        self.assertEqual(d.pending, 5)
        self.assertEqual(d.bytes_needed(), len(DX_REQ) - 5)
        self.assertEqual(d.discard_partial(), 5)
        self.assertEqual(d.counters.garbage_bytes, 5)
        d.feed(b"\x68\x05")
        self.assertIsNone(d.bytes_needed())
        d.reset()
        self.assertEqual((d.pending, d.bytes_needed()), (0, 0))


class FcbTest(unittest.TestCase):
    def test_requester_sequence(self):
        r = FcbRequester()
        self.assertEqual(r.bits(), (True, False))      # first frame: FCB=1 FCV=0
        self.assertEqual(r.fc(RequestFunction.SRD_HIGH).encode(), 0x6D)
        r.acknowledge()
        self.assertEqual(r.fc(RequestFunction.SRD_HIGH).encode(), 0x5D)
        self.assertEqual(r.bits(), (False, True))      # a retry keeps it
        r.acknowledge()
        self.assertEqual(r.fc(RequestFunction.SRD_HIGH).encode(), 0x7D)
        r.acknowledge()
        self.assertEqual(r.bits(), (False, True))
        r.reset()
        self.assertEqual(r.bits(), (True, False))

    def test_responder_repeats_stored_reply(self):
        resp = FcbResponder()
        calls = []

        def execute(tag):
            def run():
                calls.append(tag)
                return ShortAck() if tag != "dx" else Sd1(2, 8, FrameControl.resp(0))
            return run

        first = FrameControl.req(RequestFunction.SRD_HIGH, True, False)
        self.assertEqual(resp.handle(2, first, execute("a")), ShortAck())
        nxt = FrameControl.req(RequestFunction.SRD_HIGH, False, True)
        r1 = resp.handle(2, nxt, execute("dx"))
        r2 = resp.handle(2, nxt, execute("dx-again"))      # retry: same FCB, FCV=1
        self.assertEqual(r1, r2)
        self.assertEqual(calls, ["a", "dx"])
        self.assertEqual(resp.duplicates, 1)
        # another master with the same bits is not a duplicate
        resp.handle(3, nxt, execute("other"))
        self.assertEqual(calls[-1], "other")
        # FCV=0 always executes (restart), even with the same FCB
        resp.handle(2, FrameControl.req(RequestFunction.SRD_HIGH, False, False), execute("re"))
        self.assertEqual(calls[-1], "re")
        resp.forget(2)
        resp.handle(2, nxt, execute("after-forget"))
        self.assertEqual(calls[-1], "after-forget")
        resp.forget()
        self.assertFalse(resp.is_repeat(2, nxt))


if __name__ == "__main__":
    unittest.main()


class Sd2CodecTest(unittest.TestCase):
    """The bytes-level SD2 codec that Sd2 and the master's Data_Exchange fast path share."""

    def test_encode_gives_the_golden_bytes(self):
        self.assertEqual(sd2_encode(8, 2, 0x7D, bytes(range(1, 15))), DX_REQ)
        self.assertEqual(sd2_encode(0x88, 0x82, 0x6D, bytes.fromhex("3C 3E")), DIAG_REQ)
        self.assertEqual(Sd2(8, 2, FrameControl.req(RequestFunction.SRD_HIGH, True, True),
                             bytes(range(1, 15))).encode(), DX_REQ)

    def test_data_accepts_exactly_the_expected_reply(self):
        self.assertEqual(sd2_data(DX_REPLY, 2, 8, 0x08), bytes(range(1, 15)))
        self.assertEqual(sd2_data(bytearray(DX_REPLY), 2, 8, 0x08), bytes(range(1, 15)))
        for da, sa, fc in ((3, 8, 0x08), (2, 9, 0x08), (2, 8, 0x0A), (0x82, 8, 0x08)):
            self.assertIsNone(sd2_data(DX_REPLY, da, sa, fc))
        for i in range(len(DX_REPLY)):          # any one byte changed: framing, header or FCS fails
            for delta in (1, 0x80):
                bad = bytearray(DX_REPLY)
                bad[i] = (bad[i] + delta) & 0xFF
                self.assertIsNone(sd2_data(bytes(bad), 2, 8, 0x08), (i, delta))
        self.assertIsNone(sd2_data(DX_REPLY[:-1], 2, 8, 0x08))
        self.assertIsNone(sd2_data(DX_REPLY + b"\x16", 2, 8, 0x08))
        self.assertIsNone(sd2_data(b"", 2, 8, 0x08))
        self.assertIsNone(sd2_data(bytes.fromhex("68 03 03 68 02 08 08 12 16"), 2, 8, 0x08))  # LE 3: no DU

    def test_body_checks_the_framing_with_typed_errors(self):
        self.assertEqual(sd2_body(DX_REPLY), DX_REPLY[4:-2])
        with self.assertRaises(TruncatedFrameError):
            sd2_body(DX_REPLY[:3])
        with self.assertRaises(TruncatedFrameError):
            sd2_body(DX_REPLY[:-1])
        with self.assertRaises(FcsError):
            sd2_body(DX_REPLY[:-2] + bytes(((DX_REPLY[-2] + 1) & 0xFF,)) + b"\x16")
        for i, value in ((1, 0x12), (3, 0x69), (-1, 0x17), (0, 0x10)):
            bad = bytearray(DX_REPLY)
            bad[i] = value
            with self.assertRaises(FrameError):
                sd2_body(bytes(bad))
