"""The virtual multi-drop line over REAL ptys: the virtual controller (slave 4) in this process, the
virtual I/O island (slave 8) in its own process, the line hub joining their ptys, and our DP master
cycling both on the hub's pty. The island is killed on its own: slave 4 stays in Data_Exchange, the
island's signals read offline; a new island on the same link joins again with its outputs safe.

Waiting is on deadlines around bus cycles (the master's cycle blocks in the link) and on the island
process's stdout line; nothing sleeps to synchronise."""
from __future__ import annotations

import os
import select
import subprocess
import sys
import time
from typing import Callable, Optional

import pytest

from pyprofibus_vendor.config import load_config
from pyprofibus_vendor.dp_master import DpMaster, SlaveSpec
from pyprofibus_vendor.phy_serial import SerialLink

from vr_driver.controller.virtual_controller import VirtualController
from vr_driver.driver.link.stations import IoLine
from vr_driver.io_signals import lengths_from_bus, load_signal_map
from vr_driver.controller.line import LineHub

SRC = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "src")
REPO = os.path.dirname(os.path.dirname(SRC))
CONFIG = os.path.join(REPO, "vr_driver", "config")
PYTHONPATH = os.pathsep.join([SRC, os.path.join(REPO, "pyprofibus_vendor", "src"),
                              os.path.join(REPO, "panasonic_vr006l_support", "src")])
BUS = load_config(os.path.join(CONFIG, "io_line_bus.yaml"))
SIGNALS = load_signal_map(os.path.join(CONFIG, "io_island_signals.yaml"), lengths_from_bus(BUS))
BAUD = 187500


def start_island(link: str, idle: Optional[Callable[[], None]] = None) -> subprocess.Popen:
    """Start an island process and wait for its device path; ``idle()`` is called meanwhile (the
    master keeps cycling the line: a master that stopped for the island's start-up would let the
    controller's DP watchdog expire)."""
    env = dict(os.environ, PYTHONPATH=PYTHONPATH)
    proc = subprocess.Popen([sys.executable, "-m", "vr_driver.controller.io_island", "--pty-link", link, "--baud", str(BAUD)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, text=True)
    deadline = time.monotonic() + 20.0
    while not select.select([proc.stdout], [], [], 0.0 if idle is not None else 20.0)[0]:
        assert time.monotonic() < deadline, "the island printed no device path within 20 s"
        if idle is not None:
            idle()
    path = proc.stdout.readline().strip()
    assert path.startswith("/dev/pts/"), (path, proc.stderr.read() if proc.poll() is not None else "")
    return proc


class Rig:
    def __init__(self, tmp) -> None:
        self.controller = VirtualController(pty_link=str(tmp / "g2"), baud=BAUD, speed_factor=20.0).start()
        self.island_link = str(tmp / "island")
        self.island = start_island(self.island_link)
        self.hub = LineHub([str(tmp / "g2"), self.island_link], pty_link=str(tmp / "line"),
                           reopen_period=0.1).start()
        self.master = DpMaster(SerialLink(str(tmp / "line"), BAUD), BUS.master_address, BAUD,
                               dx_tolerance=0.5, retry_steps=True, backoff_max=0.3)
        self.robot = self.master.add_slave(SlaveSpec.from_config(BUS.slave(4)))
        self.io = IoLine(SIGNALS, 0.5)
        self.io.add_slaves(self.master, BUS)
        self.handle = self.master.slave(8)
        self.robot_losses = 0

    def cycle(self) -> None:
        self.master.cycle(timeout=1.0)
        self.robot_losses = self.robot.counters.losses
        self.io.update(time.monotonic())

    def until(self, pred: Callable[[], bool], timeout: float, what: str) -> float:
        start = time.monotonic()
        while not pred():
            assert time.monotonic() - start < timeout, "%s not within %.1f s: %s" % (what, timeout, self.io.snapshot())
            self.cycle()
        return time.monotonic() - start

    def value(self, name: str):
        return self.io.snapshot().signal(name).value

    def island_online(self) -> bool:
        return self.io.snapshot().station("io_island").online

    def close(self) -> None:
        for proc in (self.island,):
            if proc.poll() is None:
                proc.kill()
                proc.wait(10)
        self.master.close()
        self.hub.stop()
        self.controller.stop()


@pytest.fixture
def rig(tmp_path):
    rig = Rig(tmp_path)
    yield rig
    rig.close()
    assert rig.hub.error is None


def test_master_cycles_controller_and_island_on_one_line_and_the_island_dies_alone(rig, tmp_path):
    rig.until(lambda: rig.robot.connected and rig.island_online(), 15.0, "both stations in Data_Exchange")
    assert sorted(rig.hub.connected()) == sorted([str(tmp_path / "g2"), rig.island_link])
    assert rig.io.write("gripper_close", "1").success
    took = rig.until(lambda: rig.value("gripper_closed") == 1, 5.0, "gripper_closed")
    assert took >= 0.3 - 0.05                            # the island's gripper delay
    assert rig.controller.slave_state.value == "DATA_EXCH"

    rig.island.kill()                                    # SIGKILL: no clean-up in the island
    rig.island.wait(10)
    rig.until(lambda: not rig.island_online(), 3.0, "island offline")
    assert rig.value("gripper_closed") is None and rig.value("gripper_close") is None
    rig.until(lambda: not rig.handle.connected, 5.0, "the master drops slave 8")
    assert rig.hub.counters.station_drops == 1 and rig.hub.connected() == [str(tmp_path / "g2")]
    for _ in range(20):                                  # the arm's station keeps cycling
        rig.cycle()
    assert rig.robot.connected and rig.robot.counters.losses == 0
    assert rig.controller.slave_state.value == "DATA_EXCH"
    assert not rig.io.write("gripper_close", "1").success

    rig.island = start_island(rig.island_link, idle=rig.cycle)   # a new island on the same link
    rig.until(rig.island_online, 15.0, "island back")
    assert rig.value("gripper_close") == 0 and rig.value("gripper_closed") == 0
    assert rig.handle.outputs == b"\x00\x00"
    assert rig.robot.counters.losses == 0 and rig.hub.counters.station_opens == 3
