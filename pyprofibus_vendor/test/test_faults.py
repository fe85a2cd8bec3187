"""Fault injection between master and slave: corrupted bytes, drops, a cut line."""
from __future__ import annotations

import struct
import unittest
from typing import List, Set

from pyprofibus_vendor.dp_master import DpMaster, SlaveSpec
from pyprofibus_vendor.dp_slave import DpSlave, SlaveLink, SlaveServer
from pyprofibus_vendor.phy import FaultyLink, MemoryLink

from _helpers import MASTER, ROBOT_CFG, ROBOT_IDENT, SLAVE, FakeClock, transform

SPEC = SlaveSpec(SLAVE, ROBOT_IDENT, ROBOT_CFG, watchdog=1.0)


def image(i: int) -> bytes:
    """A distinct 14-byte output image per cycle."""
    return struct.pack("<7H", *[(i * 7 + k) & 0xFFFF for k in range(7)])


class EndToEndRecorder:
    """Master + slave on one fake clock; records every image either side saw."""

    def __init__(self, max_retry: int = 1, **faults) -> None:
        self.clock = FakeClock()
        self.slave = DpSlave(SLAVE, ROBOT_IDENT, ROBOT_CFG, clock=self.clock,
                             on_outputs=self.on_outputs)
        self.link = FaultyLink(SlaveLink(self.slave), clock=self.clock, **faults)
        self.master = DpMaster(self.link, MASTER, 19200, clock=self.clock, max_retry=max_retry)
        self.h = self.master.add_slave(SPEC)
        self.outputs_sent: Set[bytes] = {bytes(14)}        # the initial/safe image
        self.inputs_set: Set[bytes] = {bytes(14)}
        self.to_slave: List[bytes] = []
        self.to_master: List[bytes] = []

    def slave_fcs_errors(self) -> int:
        return self.link.inner.deframer.counters.fcs_errors

    def on_outputs(self, data: bytes) -> None:
        self.to_slave.append(data)
        self.slave.inputs = transform(data)
        self.inputs_set.add(transform(data))

    def cycle(self, outputs: bytes) -> None:
        """Set new outputs and step until one bus cycle with traffic completed."""
        self.h.outputs = outputs
        self.outputs_sent.add(outputs)
        before = self.h.inputs_time
        while True:
            target = self.master.counters.cycles + 1
            requests = self.master.counters.requests
            while self.master.counters.cycles < target:
                self.master.step()
                self.clock.advance(0.005)
            if self.master.counters.requests != requests:
                break
        if self.h.inputs_time != before:
            self.to_master.append(self.h.inputs)


class CorruptionTest(unittest.TestCase):
    def test_two_percent_bit_errors_on_8e1_line_never_deliver_wrong_data(self):
        """2 % of the characters hit by line noise (one flipped bit each), received by
        a UART with even-parity checking, as on a real PROFIBUS line (SerialLink turns
        INPCK|IGNPAR on). Parity plus LE/FCS/ED checks must stop every bad telegram."""
        rec = EndToEndRecorder(corrupt=0.02, bit_errors=1, parity=True, seed=2024,
                               max_retry=4)
        for i in range(1500):
            rec.cycle(image(i))
        # every image an application received was really sent by the other side
        self.assertEqual([d for d in rec.to_slave if d not in rec.outputs_sent], [])
        self.assertEqual([d for d in rec.to_master if d not in rec.inputs_set], [])
        # ... the faults really happened and were handled
        self.assertGreater(rec.link.counters.corrupted, 500)
        self.assertEqual(rec.link.counters.parity_drops, rec.link.counters.corrupted)
        self.assertGreater(rec.master.counters.retries, 300)
        self.assertGreater(rec.slave.counters.duplicates, 50)     # lost replies repeated
        # ... and the exchange still goes on
        self.assertGreater(rec.h.counters.data_exchanges, 900)

    def test_two_percent_random_bytes_without_parity(self):
        """A byte link without parity (pty, socket): 2 % of the bytes replaced by
        arbitrary values. Only the 8-bit sum FCS, LE/LEr, ED, addresses, FC, SAPs and
        length stand between them and the application; about 1 in 256 telegrams with
        two bad bytes passes an 8-bit sum, so this is a measured bound, not zero."""
        rec = EndToEndRecorder(corrupt=0.02, seed=2024, max_retry=4)
        for i in range(1500):
            rec.cycle(image(i))
        wrong = ([d for d in rec.to_slave if d not in rec.outputs_sent]
                 + [d for d in rec.to_master if d not in rec.inputs_set])
        rejected = rec.master.counters.fcs_errors + rec.slave_fcs_errors()
        self.assertGreater(rec.link.counters.corrupted, 1500)
        self.assertGreater(rejected, 300)
        self.assertLessEqual(len(wrong), max(1, rejected // 100))
        self.assertGreater(rec.h.counters.data_exchanges, 800)

    def test_dropped_bytes_never_deliver_wrong_data(self):
        rec = EndToEndRecorder(drop=0.02, seed=7, max_retry=4)
        for i in range(800):
            rec.cycle(image(i))
        self.assertEqual([d for d in rec.to_slave if d not in rec.outputs_sent], [])
        self.assertEqual([d for d in rec.to_master if d not in rec.inputs_set], [])
        self.assertGreater(rec.link.counters.dropped, 200)
        self.assertGreater(rec.h.counters.data_exchanges, 500)

    def test_matching_pairs_when_clean(self):
        rec = EndToEndRecorder()
        for i in range(200):
            rec.cycle(image(i))
            if rec.h.connected and i > 10:
                self.assertEqual(rec.h.inputs, transform(image(i)))


class CutLineTest(unittest.TestCase):
    """Real threads and time: the slave is served on a memory link."""

    def test_cut_detected_and_recovered_without_restart(self):
        master_end, slave_end = MemoryLink.pair()
        slave = DpSlave(SLAVE, ROBOT_IDENT, ROBOT_CFG)
        slave.on_outputs = lambda d: setattr(slave, "inputs", transform(d))
        server = SlaveServer(slave_end, slave)
        server.start()
        link = FaultyLink(master_end)
        master = DpMaster(link, MASTER, 19200, reply_timeout_floor=0.05, backoff_min=0.02,
                          backoff_max=0.1)
        h = master.add_slave(SlaveSpec(SLAVE, ROBOT_IDENT, ROBOT_CFG, watchdog=0.2))
        try:
            self.assertTrue(master.wait_connected(SLAVE, 10))
            master.run_cycles(20)
            link.cut()
            for _ in range(200):
                master.cycle(timeout=5)
                if not h.connected:
                    break
            self.assertFalse(h.connected)
            self.assertEqual(master.counters.losses, 1)
            self.assertGreaterEqual(master.counters.timeouts, 1)
            self.assertGreater(link.counters.cut_discarded, 0)
            stale_age = master.inputs(SLAVE)[1]
            self.assertIsNotNone(stale_age)
            link.restore()
            self.assertTrue(master.wait_connected(SLAVE, 10))
            self.assertEqual(master.counters.reconnects, 1)
            h.outputs = image(99)
            master.run_cycles(3)
            self.assertEqual(h.inputs, transform(image(99)))
            self.assertIs(server.error, None)
        finally:
            server.stop()


if __name__ == "__main__":
    unittest.main()
