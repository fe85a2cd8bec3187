"""Interop over a real Linux pty: our master (serial PHY on the pty path) and our
slave (served on the pty master fd by a thread)."""
from __future__ import annotations

import struct
import unittest
from typing import List

from pyprofibus_vendor.dp_master import DpMaster, SlaveSpec
from pyprofibus_vendor.dp_slave import DpSlave, SlaveServer, SlaveState
from pyprofibus_vendor.fdl import FrameControl, RequestFunction, Sd1
from pyprofibus_vendor.phy_serial import SerialLink, open_pty_pair

from _helpers import MASTER, ROBOT_CFG, ROBOT_IDENT, SLAVE, transform

CYCLES = 10_000


def image(i: int) -> bytes:
    return struct.pack("<7H", *[(i * 7 + k) & 0xFFFF for k in range(7)])


class PtyInteropTest(unittest.TestCase):
    def setUp(self) -> None:
        self.pair = open_pty_pair()
        self.slave = DpSlave(SLAVE, ROBOT_IDENT, ROBOT_CFG)
        self.received: List[bytes] = []
        self.slave.on_outputs = self._echo
        self.server = SlaveServer(self.pair.master_link(), self.slave)

    def _echo(self, data: bytes) -> None:
        self.received.append(data)
        self.slave.inputs = transform(data)

    def tearDown(self) -> None:
        self.server.stop()
        self.server.link.close()
        self.pair.close()

    def master(self, baud: int = 19200) -> DpMaster:
        link = SerialLink(self.pair.slave_path, baud)
        m = DpMaster(link, MASTER, baud, reply_timeout_floor=0.5)
        m.add_slave(SlaveSpec(SLAVE, ROBOT_IDENT, ROBOT_CFG, watchdog=2.0))
        return m

    def test_ten_thousand_cycles_14_by_14(self):
        self.server.start()
        m = self.master()
        try:
            h = m.slave(SLAVE)
            self.assertTrue(m.wait_connected(SLAVE, 10))
            first = len(self.received)
            mismatches = 0
            for i in range(CYCLES):
                out = image(i)
                h.outputs = out
                self.assertTrue(m.cycle(timeout=5))
                if h.inputs != transform(out):
                    mismatches += 1
            self.assertEqual(mismatches, 0)
            # the slave application saw every image exactly once, in order
            self.assertEqual(self.received[first:], [image(i) for i in range(CYCLES)])
            self.assertEqual(h.counters.losses, 0)
            self.assertGreaterEqual(h.counters.data_exchanges, CYCLES)
            self.assertEqual(m.counters.fcs_errors, 0)
            self.assertIs(self.slave.state, SlaveState.DATA_EXCH)
        finally:
            m.close()
        self.assertIsNone(self.server.error)

    def test_master_restarts_on_the_same_pty_and_baud(self):
        """Re-opening a pty at the speed it already has hits the EINVAL quirk."""
        self.server.start()
        for run in range(3):
            m = self.master(9600)
            try:
                self.assertTrue(m.wait_connected(SLAVE, 10), f"run {run}")
                m.slave(SLAVE).outputs = image(run)
                m.run_cycles(3)
                self.assertEqual(m.slave(SLAVE).inputs, transform(image(run)))
            finally:
                m.close()

    def test_backlog_is_flushed_when_the_slave_starts(self):
        link = SerialLink(self.pair.slave_path, 19200)
        try:
            stale = Sd1(SLAVE, MASTER, FrameControl.req(RequestFunction.FDL_STATUS)).encode()
            link.send(stale * 200)                   # written while nobody serves the pty
        finally:
            link.close()
        self.server.start()
        m = self.master()
        try:
            self.assertTrue(m.wait_connected(SLAVE, 10))
            self.assertLess(self.slave.counters.requests, 50)
        finally:
            m.close()


if __name__ == "__main__":
    unittest.main()
