"""DP master on a noisy line (issue 10): dx_tolerance, retry_steps, the back-off reset when a
station answers again, and the early repeat of a garbled reply. Injected clock, in-process slave."""
from __future__ import annotations

import unittest
from typing import List, Tuple

from pyprofibus_vendor.dp_master import MasterSlaveState as S
from pyprofibus_vendor.fdl import FrameControl, decode_frame
from pyprofibus_vendor.phy import FaultyLink, Link

from test_dp_master import Rig


class Recorder(Link):
    """Passes everything through and records what the master sends, with the clock time."""

    def __init__(self, inner: Link, clock) -> None:
        self.inner = inner
        self.clock = clock
        self.sent: List[Tuple[float, bytes]] = []

    def send(self, data: bytes) -> None:
        self.sent.append((self.clock(), bytes(data)))
        self.inner.send(data)

    def recv(self, max_bytes: int = 4096, timeout=0.0) -> bytes:
        return self.inner.recv(max_bytes, timeout)

    def flush_input(self) -> None:
        self.inner.flush_input()

    def close(self) -> None:
        self.inner.close()

    @property
    def closed(self) -> bool:
        return self.inner.closed


def noisy_rig(**kw) -> Tuple[Rig, FaultyLink, Recorder]:
    parts = {}

    def wrap(link):
        parts["faulty"] = FaultyLink(link)
        return parts["faulty"]
    rig = Rig(wrap=wrap, **kw)
    rec = Recorder(rig.master.link, rig.clock)
    rig.master.link = rec
    return rig, parts["faulty"], rec


def dx_requests(rec: Recorder, since: float = 0.0) -> List[Tuple[float, FrameControl]]:
    out = []
    for t, raw in rec.sent:
        frame = decode_frame(raw)
        if t >= since and getattr(frame, "dsap", 0) is None and frame.fc.request:
            out.append((t, frame.fc))
    return out


class DxToleranceTest(unittest.TestCase):
    def test_a_lost_exchange_keeps_data_exchange_and_restarts_the_frame_count(self):
        rig, faulty, rec = noisy_rig(dx_tolerance=0.5)
        rig.until(lambda: rig.h.connected)
        rig.steps(20)
        delivered = len(rig.slave_outputs)
        faulty.cut()
        rig.until(lambda: rig.h.counters.dx_missed >= 2)
        cut_end = rig.clock()
        faulty.restore()
        rig.until(lambda: len(rig.slave_outputs) > delivered + 3)
        self.assertTrue(rig.h.connected)
        self.assertEqual(rig.master.counters.losses, 0)
        self.assertNotIn(S.BACKOFF, [n for _, n in rig.transitions()])
        first = dx_requests(rec, cut_end)[0][1]          # the request after the lost ones
        self.assertFalse(first.fcv)                      # executed as new, never "a repetition"
        self.assertEqual(rig.slave.counters.duplicates, 0)

    def test_no_good_reply_for_longer_than_the_tolerance_ends_the_connection(self):
        rig, faulty, _ = noisy_rig(dx_tolerance=0.3)
        rig.until(lambda: rig.h.connected)
        faulty.cut()
        lost_at = rig.clock()
        rig.until(lambda: not rig.h.connected)
        self.assertGreaterEqual(rig.clock() - lost_at, 0.3)
        self.assertLess(rig.clock() - lost_at, 0.5)
        self.assertEqual(rig.changes[-1][1], S.BACKOFF)
        self.assertIn("no good Data_Exchange reply for", rig.changes[-1][2])

    def test_a_slave_that_left_data_exchange_is_reinitialised_at_once(self):
        rig, _, _ = noisy_rig(dx_tolerance=5.0)
        rig.until(lambda: rig.h.connected)
        rig.clock.advance(1.0)                           # slave watchdog runs out: RS replies
        rig.until(lambda: not rig.h.connected, max_steps=50)
        self.assertIn("RS", rig.changes[-1][2])
        rig.until(lambda: rig.h.connected)


class RetryStepsTest(unittest.TestCase):
    def _cut_in(self, state, cut_for: float, **kw):
        rig, faulty, _ = noisy_rig(**kw)
        rig.until(lambda: rig.h.state is state)
        faulty.cut()
        end = rig.clock() + cut_for
        rig.until(lambda: rig.clock() >= end, max_steps=100000)
        faulty.restore()
        rig.until(lambda: rig.h.connected, max_steps=100000)
        return rig

    def test_a_lost_reply_in_the_start_up_repeats_that_step(self):
        for state in (S.WAIT_DIAG, S.SET_PRM, S.CHK_CFG, S.CHECK_DIAG):
            rig = self._cut_in(state, 0.25, retry_steps=True)   # < slave watchdog
            self.assertNotIn(S.BACKOFF, [n for _, n in rig.transitions()], state)

    def test_without_it_the_start_up_restarts_after_a_back_off(self):
        rig = self._cut_in(S.SET_PRM, 0.25)
        self.assertIn((S.SET_PRM, S.BACKOFF), rig.transitions())

    def test_the_state_limit_still_ends_a_step_without_progress(self):
        rig = self._cut_in(S.SET_PRM, 1.5, retry_steps=True, state_limit=1.0)
        self.assertTrue(any(o is S.SET_PRM and n is S.BACKOFF and "longer than" in r
                            for o, n, r in rig.changes))


class BackoffAndEarlyRepeatTest(unittest.TestCase):
    def test_back_off_starts_short_again_when_a_silent_station_answers(self):
        rig, faulty, _ = noisy_rig(backoff_min=0.1, backoff_max=0.8)
        rig.until(lambda: rig.h.connected)
        faulty.cut()
        rig.until(lambda: rig.h.failures >= 5, max_steps=100000)    # back-off at its maximum
        faulty.restore()
        rig.until(lambda: rig.h.state is S.WAIT_DIAG, max_steps=100000)
        self.assertEqual(rig.h.failures, 0)

    def test_a_garbled_reply_is_repeated_after_the_idle_time(self):
        rig, faulty, rec = noisy_rig()
        rig.until(lambda: rig.h.connected)
        rig.steps(5)
        faulty.directions, faulty.corrupt = "rx", 1.0    # the next replies arrive garbled
        rig.until(lambda: rig.master.counters.retries >= 1)
        faulty.corrupt = 0.0
        (t0, first), (t1, again) = dx_requests(rec)[-2:]  # the request and its repetition
        self.assertLess(t1 - t0, 0.01)                   # not the 50 ms reply timeout floor
        self.assertEqual(again, first)                   # a true repetition: same FCB
        rig.until(lambda: rig.h.counters.data_exchanges > 10)
        self.assertTrue(rig.h.connected)


if __name__ == "__main__":
    unittest.main()
