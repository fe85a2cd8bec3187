"""The virtual I/O island (stepped, fake clock, in-memory link), its GSD, its command line, the line
hub's station handling and pacing, and the per-station auto links."""
from __future__ import annotations

import os
import select
import signal
import subprocess
import sys

import pytest

from pyprofibus_vendor.dp_master import DpMaster, SlaveSpec
from pyprofibus_vendor.dp_slave import SlaveLink, SlaveState
from pyprofibus_vendor.gsd import build_chk_cfg, load_gsd

from vr_driver.controller.pty_link import auto_pty_link, resolve_link
from vr_driver.controller.simulator import SimError
from vr_driver.controller.io_island import (GRIPPER_DELAY, ISLAND_ADDRESS, ISLAND_CFG, ISLAND_GSD, ISLAND_IDENT, IslandProgram,
                                 island_slave)
from vr_driver.controller.line import LineHub, _lock_owner_gone

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SRC = os.path.join(REPO, "vr_driver", "src")
PYTHONPATH = os.pathsep.join([SRC, os.path.join(REPO, "pyprofibus_vendor", "src"),
                              os.path.join(REPO, "panasonic_vr006l_support", "src")])


WATCHDOG = 1.0


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_the_gsd_describes_the_island():
    gsd = load_gsd(os.path.join(REPO, "pyprofibus_vendor", "gsd", ISLAND_GSD))
    assert gsd.ident_number == ISLAND_IDENT
    assert build_chk_cfg(gsd, ["16 DI", "16 DO"]) == ISLAND_CFG
    slave = island_slave()
    assert (slave.address, slave.input_size, slave.output_size) == (ISLAND_ADDRESS, 2, 2)


def connected_island():
    clock = Clock()
    slave = island_slave(clock=clock)
    program = IslandProgram(slave)
    master = DpMaster(SlaveLink(slave), 2, 19200, clock=clock)
    handle = master.add_slave(SlaveSpec(ISLAND_ADDRESS, ISLAND_IDENT, ISLAND_CFG, watchdog=WATCHDOG))
    for _ in range(20):
        master.cycle(timeout=0.2)
        program.step(clock.t)
        if handle.connected:
            break
    assert handle.connected
    return clock, slave, program, master, handle


def test_gripper_closed_follows_the_command_after_the_delay_and_short_pulses_never_show():
    clock, slave, program, master, handle = connected_island()
    handle.outputs = b"\x01\x00"
    master.cycle(timeout=0.2)
    t0 = clock.t
    program.step(t0)
    assert program.command == 1 and program.closed == 0
    program.step(t0 + GRIPPER_DELAY - 0.01)
    assert slave.inputs == b"\x00\x00"
    program.step(t0 + GRIPPER_DELAY)
    assert slave.inputs == b"\x01\x00"
    clock.t = t0 + GRIPPER_DELAY
    # a pulse shorter than the delay: the gripper never reports open
    handle.outputs = b"\x00\x00"
    master.cycle(timeout=0.2)
    program.step(clock.t + 0.1)
    handle.outputs = b"\x01\x00"
    master.cycle(timeout=0.2)
    program.step(clock.t + 0.2)
    program.step(clock.t + 0.6)
    assert slave.inputs == b"\x01\x00"


def test_part_present_and_safe_state_on_watchdog_expiry():
    clock, slave, program, master, handle = connected_island()
    program.set_part_present(True)
    assert slave.inputs == b"\x02\x00"
    handle.outputs = b"\x01\x00"
    master.cycle(timeout=0.2)
    program.step(clock.t)
    program.step(clock.t + GRIPPER_DELAY)
    assert slave.inputs == b"\x03\x00"
    # the master falls silent: after its watchdog the island leaves Data_Exchange, outputs safe
    program.step(clock.t + WATCHDOG - 0.01)
    assert slave.state is SlaveState.DATA_EXCH and program.command == 1
    program.step(clock.t + WATCHDOG + 0.01)
    assert slave.state is not SlaveState.DATA_EXCH
    assert slave.outputs == b"\x00\x00" and program.command == 0
    program.step(clock.t + WATCHDOG + 0.02 + GRIPPER_DELAY)
    assert slave.inputs == b"\x02\x00"                   # gripper open, part still there


def test_outputs_outside_data_exchange_are_not_a_command():
    clock = Clock()
    slave = island_slave(clock=clock)
    program = IslandProgram(slave)
    slave._outputs = b"\x01\x00"                          # whatever the image holds: not in Data_Exchange
    program.step(clock.t)
    program.step(clock.t + 1.0)
    assert program.command == 0 and slave.inputs == b"\x00\x00"


def test_the_command_line_prints_the_device_and_stops_on_sigterm(tmp_path):
    link = str(tmp_path / "island")
    proc = subprocess.Popen([sys.executable, "-m", "vr_driver.controller.io_island", "--pty-link", link, "--part-present"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=dict(os.environ, PYTHONPATH=PYTHONPATH))
    try:
        ready, _, _ = select.select([proc.stdout], [], [], 20.0)
        assert ready
        path = proc.stdout.readline().strip()
        assert os.path.realpath(link) == path
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(10) == 0
        assert not os.path.lexists(link) and not os.path.exists(link + ".lock")
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_the_command_line_refuses_a_bad_address():
    proc = subprocess.run([sys.executable, "-m", "vr_driver.controller.io_island", "--addr", "200"], capture_output=True,
                          text=True, timeout=30, env=dict(os.environ, PYTHONPATH=PYTHONPATH))
    assert proc.returncode == 2 and "addr" in proc.stderr


def test_the_command_line_reports_a_missing_device(tmp_path, capsys):
    from vr_driver.controller.io_island import main
    assert main(["--device", str(tmp_path / "no-such-tty")]) == 3
    assert "device error" in capsys.readouterr().err


def test_auto_links_are_per_station():
    env = {"ROS_MASTER_URI": "http://localhost:11411", "ROS_LOG_DIR": "/logs"}
    assert auto_pty_link(env) == "/logs/vr006l_virtual_g2_11411"
    assert auto_pty_link(env, "io_island") == "/logs/vr006l_virtual_io_island_11411"
    assert resolve_link("/dev/x") == "/dev/x"
    with pytest.raises(SimError, match="bad station name"):
        auto_pty_link(env, "../x")


def test_a_stale_station_link_is_not_opened(tmp_path):
    path = str(tmp_path / "station")
    with open(path + ".lock", "w") as f:
        f.write("%d\n" % os.getpid())
    assert not _lock_owner_gone(path)
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    with open(path + ".lock", "w") as f:
        f.write("%d\n" % dead.pid)
    assert _lock_owner_gone(path)


def test_the_hub_paces_the_line_and_joins_a_station_that_appears_late(tmp_path):
    """Two FIFOs stand in for a station's pty: what the master writes reaches the station only after
    its wire time; a station path that does not exist yet is opened once it does."""
    class FakeClock:
        t = 0.0

        def __call__(self):
            return self.t
    clock = FakeClock()
    missing = str(tmp_path / "late")
    hub = LineHub([missing], baud=9600, reopen_period=0.5, clock=clock)
    try:
        hub.step(0.0)
        assert hub.connected() == [] and hub.stations[0].why.startswith("no station")
        pair_fd, other = os.openpty()
        os.symlink(os.ttyname(other), missing)
        clock.t = 0.6
        hub.step(0.0)
        assert hub.connected() == [missing]
        master = os.open(hub.device_path, os.O_RDWR | os.O_NOCTTY)
        import tty
        tty.setraw(master)
        tty.setraw(pair_fd)
        os.write(master, b"\x10\x08\x02\x49\x53\x16")       # 6 bytes: 6.875 ms at 9600 bit/s
        hub.step(0.2)
        assert hub._queue and abs(hub._queue[0][0] - (0.6 + 6 * 11 / 9600)) < 1e-9
        assert select.select([pair_fd], [], [], 0.05)[0] == []    # not delivered before its time
        clock.t = 0.6 + 6 * 11 / 9600
        hub.step(0.0)
        assert select.select([pair_fd], [], [], 2.0)[0]
        assert os.read(pair_fd, 64) == b"\x10\x08\x02\x49\x53\x16"
        os.close(master)
        os.close(pair_fd)
        os.close(other)
    finally:
        hub.stop()


def test_the_line_command_prints_the_master_end_and_stops_on_sigterm(tmp_path):
    link = str(tmp_path / "line")
    proc = subprocess.Popen([sys.executable, "-m", "vr_driver.controller.line", "--pty-link", link, str(tmp_path / "none")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=dict(os.environ, PYTHONPATH=PYTHONPATH))
    try:
        ready, _, _ = select.select([proc.stdout], [], [], 20.0)
        assert ready
        assert os.path.realpath(link) == proc.stdout.readline().strip()
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(10) == 0
        assert not os.path.lexists(link)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_the_line_needs_a_station_and_a_bit_rate_in_range():
    with pytest.raises(SimError, match="at least one station"):
        LineHub([])
    with pytest.raises(SimError, match="baud"):
        LineHub(["/dev/null"], baud=100)
