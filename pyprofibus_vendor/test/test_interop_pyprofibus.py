"""Interop with an independent DP master: pyprofibus 1.13 (PyPI) drives OUR slave over a pty.

The master runs in its own interpreter ($VR_PEER_PYTHON, the test-peer venv made by
``scripts/setup --test-peers`` and exported by ``scripts/env``) as
``peers/pyprofibus_master.py``; our package never imports pyprofibus. Our
:class:`DpSlave` (ident 0x06C6, address 4, Chk_Cfg 13 13 13 11 23 23 23 21, 14/14 bytes)
is served on the pty's master fd by a :class:`SlaveServer` thread; the peer opens the
pty's slave path with pyprofibus's own serial PHY, configures the slave from our GSD and
checks every Data_Exchange reply (the slave application returns outputs XOR 0xA5).

The peer's stdout is read line by line with a deadline (no sleeping as synchronisation);
its last line is ``PEER SUMMARY {json}``. Skipped only when VR_PEER_PYTHON is unset; a
set but broken peer fails the test.
"""
from __future__ import annotations

import hashlib
import json
import os
import selectors
import subprocess
import threading
import time
import unittest
from typing import Dict, List, Optional, Tuple

from pyprofibus_vendor.dp_slave import DpSlave, SlaveServer, SlaveState
from pyprofibus_vendor.phy_serial import open_pty_pair

from _helpers import MASTER, ROBOT_CFG, ROBOT_IDENT, SLAVE, transform

HERE = os.path.dirname(os.path.abspath(__file__))
PEER = os.path.join(HERE, "peers", "pyprofibus_master.py")
GSD = os.path.join(os.path.dirname(HERE), "gsd", "PAN06C6.gsd")
PEER_PYTHON = os.environ.get("VR_PEER_PYTHON")
DEADLINE = 15.0   # seconds per peer run


class PeerRun:
    """One finished peer process: its exit status, ``PEER`` lines and summary."""

    def __init__(self, rc: Optional[int], lines: List[str], summary: Optional[Dict]) -> None:
        self.rc = rc
        self.lines = lines
        self.summary = summary

    def words(self, tag: str) -> List[List[str]]:
        return [ln.split()[2:] for ln in self.lines if ln.startswith("PEER " + tag)]

    def __str__(self) -> str:
        return f"exit {self.rc}; output:\n" + "\n".join(self.lines[-40:])


def run_peer(*args: str, deadline: float = DEADLINE, script: str = PEER) -> PeerRun:
    """Run the peer script (default ``peers/pyprofibus_master.py``), collecting its output lines
    until it exits or ``deadline`` s."""
    assert PEER_PYTHON
    proc = subprocess.Popen([PEER_PYTHON, script, *args], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
    end = time.monotonic() + deadline
    lines: List[str] = []
    summary = None
    buf = b""
    sel = selectors.DefaultSelector()
    sel.register(proc.stdout, selectors.EVENT_READ)
    try:
        eof = False
        while not eof:
            left = end - time.monotonic()
            if left <= 0:
                break
            if not sel.select(left):
                continue
            chunk = os.read(proc.stdout.fileno(), 65536)
            eof = not chunk
            buf += chunk
            *done, buf = buf.split(b"\n")
            if eof and buf:
                done.append(buf)
            for raw in done:
                line = raw.decode("utf-8", "replace").rstrip()
                lines.append(line)
                if line.startswith("PEER SUMMARY "):
                    summary = json.loads(line[len("PEER SUMMARY "):])
        rc = proc.wait(max(0.1, end - time.monotonic())) if eof else None
    except subprocess.TimeoutExpired:
        rc = None
    finally:
        sel.close()
        if proc.poll() is None:
            proc.kill()
            proc.wait()
            lines.append(f"(peer killed after the {deadline:.0f} s deadline)")
        proc.stdout.close()
    return PeerRun(rc, lines, summary)


@unittest.skipUnless(PEER_PYTHON, "VR_PEER_PYTHON is unset: the pyprofibus 1.13 peer venv is "
                     "made by scripts/setup --test-peers and exported by scripts/env "
                     "(scripts/test runs this test)")
class PyprofibusMasterInteropTest(unittest.TestCase):
    def setUp(self) -> None:
        self.pair = open_pty_pair()
        self.slave = DpSlave(SLAVE, ROBOT_IDENT, ROBOT_CFG)
        self.dx_outputs: List[bytes] = []        # outputs delivered while in DATA_EXCH
        self.states: List[Tuple[SlaveState, SlaveState]] = []
        self.in_dx = threading.Event()
        self.slave.on_outputs = self._app
        self.slave.on_state_change = self._state
        self.server = SlaveServer(self.pair.master_link(), self.slave)
        self.server.start()

    def tearDown(self) -> None:
        self.server.stop()
        self.server.link.close()
        self.pair.close()
        self.assertIsNone(self.server.error)

    def _app(self, data: bytes) -> None:
        if self.slave.state is SlaveState.DATA_EXCH:   # not the safe image on leaving it
            self.dx_outputs.append(data)
        self.slave.inputs = transform(data)

    def _state(self, old: SlaveState, new: SlaveState, reason: str) -> None:
        self.states.append((old, new))
        if new is SlaveState.DATA_EXCH:
            self.in_dx.set()

    def peer(self, *args: str) -> PeerRun:
        return run_peer("--port", self.pair.slave_path, "--gsd", GSD, "--slave", str(SLAVE),
                        "--master", str(MASTER), "--xor", "0xA5", *args)

    def assert_good(self, run: PeerRun, cycles: int) -> Dict:
        self.assertIsNotNone(run.summary, f"no PEER SUMMARY line: {run}")
        s = run.summary
        self.assertIsNone(s["error"], str(run))
        self.assertEqual(run.rc, 0, str(run))
        self.assertTrue(s["ok"], str(run))
        self.assertEqual(s["cycles"], cycles, str(run))
        self.assertEqual(s["mismatches"], 0, str(run))
        self.assertEqual(run.words("MISMATCH"), [])
        self.assertEqual(s["chk_cfg"], ROBOT_CFG.hex())   # pyprofibus built it from our GSD
        return s

    def test_pyprofibus_master_exchanges_data_with_our_slave(self):
        cycles = 300
        run = self.peer("--cycles", str(cycles), "--seed", "7")
        s = self.assert_good(run, cycles)
        self.assertEqual((s["rs_errors"], s["reconnects"]), (0, 0), str(run))
        # our side: Set_Prm, Chk_Cfg accepted once, Data_Exchange reached
        self.assertTrue(self.in_dx.is_set())
        self.assertEqual(self.states[:2], [(SlaveState.WAIT_PRM, SlaveState.WAIT_CFG),
                                          (SlaveState.WAIT_CFG, SlaveState.DATA_EXCH)])
        c = self.slave.counters
        self.assertEqual((c.prm_accepted, c.cfg_accepted, c.prm_faults, c.cfg_faults),
                         (1, 1, 0, 0))
        self.assertEqual(self.slave.locked_by, MASTER)
        self.assertEqual(c.rejected, 0)
        self.assertEqual(c.data_exchanges, cycles)
        # every image the peer sent reached our application once, in order
        self.assertEqual(len(self.dx_outputs), cycles)
        self.assertEqual(hashlib.sha256(b"".join(self.dx_outputs)).hexdigest(),
                         s["sent_sha256"])
        self.assertEqual(self.server.deframer.counters.fcs_errors, 0)

    def test_rs_after_our_watchdog_expired_is_survived(self):
        """pyprofibus raises DpError on an RS reply; the peer counts it and runs on.

        The peer's application stalls for 0.3 s with a 100 ms watchdog: our slave drops to
        WAIT_PRM (safe outputs) and answers the next Data_Exchange with RS, as the standard
        says for a SAP that is not active; pyprofibus then re-parameterises it.
        """
        cycles = 120
        run = self.peer("--cycles", str(cycles), "--watchdog-ms", "100", "--stall-at", "40",
                        "--stall-s", "0.3", "--seed", "3")
        s = self.assert_good(run, cycles)
        self.assertGreaterEqual(s["rs_errors"], 1, str(run))
        self.assertGreaterEqual(s["reconnects"], 1, str(run))
        c = self.slave.counters
        self.assertGreaterEqual(c.watchdog_expiries, 1)
        self.assertGreaterEqual(c.rejected, 1)          # the RS replies
        self.assertIn((SlaveState.DATA_EXCH, SlaveState.WAIT_PRM), self.states)
        self.assertEqual(len(self.dx_outputs), cycles)
        self.assertEqual(hashlib.sha256(b"".join(self.dx_outputs)).hexdigest(),
                         s["sent_sha256"])

    def test_master_restarts_on_the_same_pty_at_9600(self):
        """pyprofibus re-opening a pty at the speed it has hits the PARENB/EINVAL quirk
        unless the peer presets another speed; our slave accepts the restarted master."""
        for n in range(3):
            run = self.peer("--cycles", "20", "--baud", "9600", "--seed", str(n))
            s = self.assert_good(run, 20)
            self.assertTrue(s["pty_preset"])
        self.assertEqual(self.slave.counters.prm_accepted, 3)
        self.assertEqual(len(self.dx_outputs), 60)


if __name__ == "__main__":
    unittest.main()
