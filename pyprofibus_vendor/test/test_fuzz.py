"""Property and fuzz tests (hypothesis): only typed errors, lossless round trips."""
from __future__ import annotations

import unittest

from hypothesis import HealthCheck, given, settings, strategies as st

from pyprofibus_vendor.dp import (ChkCfg, GlobalControl, SetPrm, SetSlaveAdd, SlaveDiag,
                                  cfg_io_lengths, parse_ext_diag)
from pyprofibus_vendor.dp_master import DpMaster, SlaveSpec
from pyprofibus_vendor.dp_slave import DpSlave
from pyprofibus_vendor.errors import DpError, FrameError
from pyprofibus_vendor.fdl import (Deframer, FrameControl, RequestFunction, ResponseStatus, Sd1,
                                   Sd2, Sd3, Sd4, ShortAck, data_frame, decode_frame, sd2_data,
                                   sd2_encode)

from _helpers import MASTER, ROBOT_CFG, ROBOT_IDENT, SLAVE, FakeClock, ScriptedLink

SETTINGS = settings(max_examples=300, deadline=None, database=None,
                    suppress_health_check=[HealthCheck.too_slow])

addresses = st.integers(0, 126)
saps = st.one_of(st.none(), st.integers(0, 63))
fcs_ = st.one_of(
    st.builds(FrameControl.req, st.sampled_from(list(RequestFunction)), st.booleans(),
              st.booleans()),
    st.builds(FrameControl.resp, st.sampled_from(list(ResponseStatus)), st.integers(0, 3)))


@st.composite
def frames(draw):
    kind = draw(st.sampled_from(["sd1", "data", "sd3", "sd4", "sc"]))
    da = draw(st.one_of(addresses, st.just(127)))
    sa = draw(addresses)
    fc = draw(fcs_)
    if kind == "sd1":
        return Sd1(da, sa, fc)
    if kind == "sd4":
        return Sd4(draw(addresses), sa)
    if kind == "sc":
        return ShortAck()
    dsap, ssap = draw(saps), draw(saps)
    nsap = (dsap is not None) + (ssap is not None)
    if kind == "sd3":
        return Sd3(da, sa, fc, draw(st.binary(min_size=8 - nsap, max_size=8 - nsap)), dsap, ssap)
    data = draw(st.binary(min_size=0 if nsap else 1, max_size=246 - nsap))
    return Sd2(da, sa, fc, data, dsap, ssap)


def request_frames_for_slave():
    """Frames a slave at SLAVE might see: mostly addressed to it, plausible SAPs."""
    fc = st.builds(FrameControl.req, st.sampled_from(list(RequestFunction)), st.booleans(),
                   st.booleans())
    sap = st.one_of(st.none(), st.integers(48, 63))
    return st.builds(lambda da, sa, f, data, dsap, ssap: data_frame(da, sa, f, data, dsap, ssap),
                     st.sampled_from([SLAVE, 127, SLAVE + 1]), st.sampled_from([MASTER, 3]),
                     fc, st.binary(max_size=30), sap, st.sampled_from([None, 62, 62, 1]))


VALID_FC = sorted({fc.encode() for fc in
                   [FrameControl.req(f, b, v) for f in RequestFunction for b in (0, 1) for v in (0, 1)]
                   + [FrameControl.resp(r, t) for r in ResponseStatus for t in range(4)]})


class Sd2CodecProperties(unittest.TestCase):
    """sd2_encode / sd2_data (the master's fast path) agree with Sd2 and the general decoder."""

    @SETTINGS
    @given(st.one_of(addresses, st.just(127)), addresses, fcs_, saps, saps, st.binary(max_size=244))
    def test_encode_equals_the_frame_encoder(self, da, sa, fc, dsap, ssap, data):
        frame = Sd2(da, sa, fc, data or b"\x00", dsap, ssap)
        raw_da = da | (0x80 if dsap is not None else 0)
        raw_sa = sa | (0x80 if ssap is not None else 0)
        self.assertEqual(sd2_encode(raw_da, raw_sa, fc.encode(), frame.du), frame.encode())

    @SETTINGS
    @given(frames(), st.data())
    def test_data_agrees_with_the_decoder(self, frame, data):
        raw = bytearray(frame.encode())
        if raw and data.draw(st.booleans()):
            raw[data.draw(st.integers(0, len(raw) - 1))] = data.draw(st.integers(0, 255))
        if data.draw(st.booleans()):
            raw = raw[:data.draw(st.integers(0, len(raw)))]
        raw = bytes(raw)
        # the header the caller expects: a valid one (DA 0..127, SA 0..126, a valid FC), often
        # the telegram's own
        own = len(raw) >= 7 and raw[4] <= 127 and raw[5] <= 126 and raw[6] in VALID_FC
        if own and data.draw(st.booleans()):
            da, sa, fc = raw[4], raw[5], raw[6]
        else:
            da, sa, fc = (data.draw(st.integers(0, 127)), data.draw(addresses),
                          data.draw(st.sampled_from(VALID_FC)))
        try:
            decoded = decode_frame(raw)
        except FrameError:
            decoded = None
        expected = None
        if (isinstance(decoded, Sd2) and decoded.dsap is None and decoded.ssap is None
                and (decoded.da, decoded.sa, decoded.fc.encode()) == (da, sa, fc)):
            expected = decoded.data
        self.assertEqual(sd2_data(raw, da, sa, fc), expected)


class FrameProperties(unittest.TestCase):
    @SETTINGS
    @given(frames())
    def test_round_trip(self, frame):
        raw = frame.encode()
        self.assertEqual(decode_frame(raw), frame)
        self.assertEqual(decode_frame(raw).encode(), raw)

    @SETTINGS
    @given(st.lists(frames(), min_size=1, max_size=8), st.data())
    def test_deframer_any_chunking(self, fs, data):
        stream = b"".join(f.encode() for f in fs)
        cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=10)))
        d = Deframer()
        out = []
        prev = 0
        for c in cuts + [len(stream)]:
            out += d.feed(stream[prev:c])
            prev = c
        self.assertEqual(out, fs)
        self.assertEqual(d.counters.garbage_bytes, 0)

    @SETTINGS
    @given(st.binary(max_size=600))
    def test_random_bytes_only_typed_errors(self, blob):
        try:
            decode_frame(blob)
        except FrameError:
            pass
        d = Deframer()
        for f in d.feed(blob):
            self.assertIn(f.encode(), blob)     # anything found really is in the input
        self.assertLessEqual(d.counters.garbage_bytes + d.pending, len(blob))

    @SETTINGS
    @given(st.lists(frames(), min_size=1, max_size=5), st.data())
    def test_mutated_streams(self, fs, data):
        stream = bytearray(b"".join(f.encode() for f in fs))
        for _ in range(data.draw(st.integers(1, 4))):
            i = data.draw(st.integers(0, len(stream) - 1))
            op = data.draw(st.sampled_from(["flip", "drop", "insert"]))
            if op == "flip":
                stream[i] ^= data.draw(st.integers(1, 255))
            elif op == "drop" and len(stream) > 1:
                del stream[i]
            else:
                stream.insert(i, data.draw(st.integers(0, 255)))
        d = Deframer()
        got = d.feed(bytes(stream))
        for f in got:
            self.assertIn(f.encode(), bytes(stream))


class DpProperties(unittest.TestCase):
    @SETTINGS
    @given(st.binary(max_size=300))
    def test_decoders_only_dp_errors(self, blob):
        for decode in (SlaveDiag.decode, SetPrm.decode, ChkCfg.decode, GlobalControl.decode,
                       SetSlaveAdd.decode, cfg_io_lengths, parse_ext_diag):
            try:
                decode(blob)
            except DpError:
                pass

    @SETTINGS
    @given(st.integers(0, 255), st.integers(0, 255), st.integers(0, 255), st.integers(0, 255),
           st.integers(0, 0xFFFF), st.binary(max_size=238))
    def test_diag_round_trip(self, s1, s2, s3, master, ident, ext):
        d = SlaveDiag(s1, s2, s3, master, ident, ext)
        self.assertEqual(SlaveDiag.decode(d.encode()), d)


class EngineFuzz(unittest.TestCase):
    @SETTINGS
    @given(st.lists(request_frames_for_slave(), max_size=40),
           st.lists(st.floats(0, 0.2), max_size=40))
    def test_slave_never_raises_on_frames(self, fs, dts):
        clock = FakeClock()
        s = DpSlave(SLAVE, ROBOT_IDENT, ROBOT_CFG, clock=clock)
        for i, f in enumerate(fs):
            reply = s.handle(f)
            if reply is not None:
                decode_frame(reply.encode())             # replies are always valid telegrams
            clock.advance(dts[i] if i < len(dts) else 0.0)
            s.step()

    @SETTINGS
    @given(st.binary(max_size=800))
    def test_slave_on_random_bytes(self, blob):
        s = DpSlave(SLAVE, ROBOT_IDENT, ROBOT_CFG, clock=FakeClock())
        d = Deframer()
        for f in d.feed(blob):
            s.handle(f)

    @settings(max_examples=100, deadline=None, database=None)
    @given(st.lists(st.binary(max_size=40), min_size=1, max_size=30))
    def test_master_on_random_replies(self, replies):
        it = iter(replies)
        clock = FakeClock()
        m = DpMaster(ScriptedLink(lambda f: next(it, b"")), MASTER, clock=clock)
        h = m.add_slave(SlaveSpec(SLAVE, ROBOT_IDENT, ROBOT_CFG))
        for _ in range(len(replies) * 3):
            m.step()
            clock.advance(0.02)
        self.assertIn(h.inputs, (None,))                 # random bytes never become inputs


if __name__ == "__main__":
    unittest.main()
