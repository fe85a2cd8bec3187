"""pyprofibus 1.13 (PyPI, the independent test peer) as the master of the virtual I/O island: it
configures the island from our GSD VRIO0F1A.gsd with the modules "16 DI", "16 DO", writes
``gripper_close`` (output byte 0 bit 0) and reads ``gripper_closed`` (input byte 0 bit 0) at 1, the
gripper's delay later. The peer runs in its own interpreter ($VR_PEER_PYTHON, made by
``scripts/setup --test-peers``); skipped only when that is unset."""
from __future__ import annotations

import os
import sys

import pytest

from vr_driver.controller.io_island import GRIPPER_DELAY, ISLAND_ADDRESS, ISLAND_CFG, VirtualIoIsland

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PEER_TESTS = os.path.join(REPO, "pyprofibus_vendor", "test")
PEER = os.path.join(PEER_TESTS, "peers", "pyprofibus_island.py")
GSD = os.path.join(REPO, "pyprofibus_vendor", "gsd", "VRIO0F1A.gsd")
PEER_PYTHON = os.environ.get("VR_PEER_PYTHON")


@pytest.mark.skipif(not PEER_PYTHON, reason="VR_PEER_PYTHON is unset: the pyprofibus 1.13 peer venv is made by "
                    "scripts/setup --test-peers and exported by scripts/env")
def test_pyprofibus_closes_the_gripper_of_the_virtual_island():
    if PEER_TESTS not in sys.path:
        sys.path.insert(0, PEER_TESTS)
    import test_interop_pyprofibus as interop                     # its run_peer: output lines with a deadline
    island = VirtualIoIsland(baud=19200).start()
    try:
        run = interop.run_peer("--port", island.device_path, "--gsd", GSD, "--modules", "16 DI", "16 DO",
                               "--size", "2", "--slave", str(ISLAND_ADDRESS), "--output", "0100",
                               "--until", "0100/0100", script=PEER)
    finally:
        island.stop()
    assert run.summary is not None, str(run)
    assert run.summary["error"] is None and run.summary["ok"] and run.rc == 0, str(run)
    assert run.summary["matched_s"] >= GRIPPER_DELAY - 0.05, str(run)
    assert run.words("INPUTS")[0][-1] == "0000", str(run)          # open before: the delay is real
    assert island.program.command == 1 and island.slave.counters.cfg_accepted == 1
    assert island.slave.cfg == ISLAND_CFG
