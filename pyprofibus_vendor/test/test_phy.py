"""In-memory link pair and the fault-injecting wrapper."""
from __future__ import annotations

import random
import threading
import unittest

from pyprofibus_vendor.errors import PhyError
from pyprofibus_vendor.phy import FaultyLink, MemoryLink

from _helpers import FakeClock


class MemoryLinkTest(unittest.TestCase):
    def test_both_directions(self):
        a, b = MemoryLink.pair()
        a.send(b"hello")
        b.send(b"\x00\xff")
        self.assertEqual(b.recv(100, 0), b"hello")
        self.assertEqual(a.recv(100, 0), b"\x00\xff")
        self.assertEqual(a.recv(100, 0), b"")

    def test_max_bytes_and_flush(self):
        a, b = MemoryLink.pair()
        a.send(bytes(range(10)))
        self.assertEqual(b.recv(4, 0), bytes(range(4)))
        b.flush_input()
        self.assertEqual(b.recv(10, 0), b"")

    def test_timeout_returns_empty(self):
        a, b = MemoryLink.pair()
        self.assertEqual(b.recv(10, 0.01), b"")

    def test_blocking_recv_is_woken_by_send(self):
        a, b = MemoryLink.pair()
        got = []
        started = threading.Event()

        def reader():
            started.set()
            got.append(b.recv(10, None))     # waits for ever until data comes

        t = threading.Thread(target=reader)
        t.start()
        started.wait(5)
        a.send(b"x")
        t.join(5)
        self.assertFalse(t.is_alive())
        self.assertEqual(got, [b"x"])

    def test_close_semantics(self):
        a, b = MemoryLink.pair()
        a.send(b"last")
        with a:
            pass
        self.assertTrue(a.closed)
        a.close()                      # idempotent
        self.assertEqual(b.recv(10, 0), b"last")   # data sent before close is kept
        with self.assertRaises(PhyError):
            b.recv(10, 0)
        with self.assertRaises(PhyError):
            b.send(b"x")
        for op in (lambda: a.send(b"x"), lambda: a.recv(1, 0), a.flush_input):
            with self.assertRaises(PhyError):
                op()

    def test_close_wakes_blocked_reader(self):
        a, b = MemoryLink.pair()
        errors = []
        started = threading.Event()

        def reader():
            started.set()
            try:
                b.recv(10, None)
            except PhyError as err:
                errors.append(err)

        t = threading.Thread(target=reader)
        t.start()
        started.wait(5)
        a.close()
        t.join(5)
        self.assertEqual(len(errors), 1)


class FaultyLinkTest(unittest.TestCase):
    def test_transparent_by_default(self):
        a, b = MemoryLink.pair()
        f = FaultyLink(a)
        f.send(bytes(range(256)))
        self.assertEqual(b.recv(300, 0), bytes(range(256)))
        b.send(b"abc")
        self.assertEqual(f.recv(10, 0), b"abc")
        self.assertEqual((f.counters.bytes_sent, f.counters.bytes_received), (256, 3))

    def test_drop_all(self):
        a, b = MemoryLink.pair()
        f = FaultyLink(a, drop=1.0)
        f.send(b"12345")
        b.send(b"678")
        self.assertEqual(b.recv(10, 0), b"")
        self.assertEqual(f.recv(10, 0), b"")
        self.assertEqual(f.counters.dropped, 8)

    def test_corrupt_changes_every_byte(self):
        a, b = MemoryLink.pair()
        f = FaultyLink(a, corrupt=1.0, directions="tx", seed=3)
        data = bytes(range(200))
        f.send(data)
        got = b.recv(300, 0)
        self.assertEqual(len(got), 200)
        self.assertTrue(all(x != y for x, y in zip(data, got)))
        self.assertEqual(f.counters.corrupted, 200)
        b.send(data)                           # rx direction untouched
        self.assertEqual(f.recv(300, 0), data)

    def test_rates_are_roughly_right_and_seeded(self):
        def run(seed):
            a, b = MemoryLink.pair()
            f = FaultyLink(a, drop=0.1, corrupt=0.1, seed=seed)
            f.send(bytes(5000))
            return b.recv(10000, 0), f.counters

        out1, c1 = run(7)
        out2, c2 = run(7)
        self.assertEqual(out1, out2)           # deterministic for a seed
        self.assertTrue(300 < c1.dropped < 700)
        self.assertTrue(300 < c1.corrupted < 700)
        self.assertEqual(len(out1), 5000 - c1.dropped)
        self.assertEqual(sum(1 for x in out1 if x), c1.corrupted)

    def test_cut_and_restore(self):
        a, b = MemoryLink.pair()
        f = FaultyLink(a)
        f.cut()
        self.assertTrue(f.is_cut)
        f.send(b"lost")
        b.send(b"also lost")
        self.assertEqual(b.recv(10, 0), b"")
        self.assertEqual(f.recv(20, 0), b"")
        self.assertEqual(f.counters.cut_discarded, 4 + 9)
        f.cut()
        self.assertEqual(f.counters.cuts, 1)
        f.restore()
        f.send(b"ok")
        b.send(b"back")
        self.assertEqual(b.recv(10, 0), b"ok")
        self.assertEqual(f.recv(10, 0), b"back")

    def test_delay_with_injected_clock(self):
        clock = FakeClock()
        a, b = MemoryLink.pair()
        f = FaultyLink(a, delay=1.0, delay_s=0.5, clock=clock, rng=random.Random(1))
        b.send(b"AB")
        self.assertEqual(f.recv(10, 0), b"")         # both held back (order kept)
        clock.advance(0.4)
        self.assertEqual(f.recv(10, 0), b"")
        clock.advance(0.2)
        self.assertEqual(f.recv(10, 0), b"A")         # each byte delayed again after the first
        clock.advance(0.5)
        self.assertEqual(f.recv(10, 0), b"B")
        self.assertEqual(f.counters.delayed, 2)
        b.send(b"C")
        f.flush_input()
        clock.advance(5)
        self.assertEqual(f.recv(10, 0), b"")

    def test_bad_arguments(self):
        a, _ = MemoryLink.pair()
        with self.assertRaises(ValueError):
            FaultyLink(a, drop=1.5)
        with self.assertRaises(ValueError):
            FaultyLink(a, directions="up")

    def test_close_passes_through(self):
        a, b = MemoryLink.pair()
        f = FaultyLink(a)
        f.close()
        self.assertTrue(f.closed)
        with self.assertRaises(PhyError):
            f.send(b"x")


if __name__ == "__main__":
    unittest.main()
