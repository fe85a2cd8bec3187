"""pyprofibus_vendor.adapter: low-latency mode and the latency timer, on a real pty and a fake sysfs."""
from __future__ import annotations

import os

import pytest

from pyprofibus_vendor.adapter import latency_timer_path, tune_port
from pyprofibus_vendor.phy_serial import SerialLink, open_pty_pair


@pytest.fixture
def pty():
    pair = open_pty_pair()
    yield pair
    pair.close()


def test_a_pty_is_no_serial_driver_and_says_so(pty):
    link = SerialLink(pty.slave_path, 19200)
    try:
        setup = link.adapter
        assert setup is not None and setup.low_latency is False
        assert setup.latency_timer_ms is None
        assert "cannot set low-latency on %s: not a serial driver; fine for the virtual line" % (
            os.path.realpath(pty.slave_path)) in setup.describe()
    finally:
        link.close()


def test_a_url_is_not_tuned():
    link = SerialLink("loop://", 19200)
    try:
        assert link.adapter is None
    finally:
        link.close()


def _sysfs(tmp_path, name, value, writable=True):
    d = tmp_path / name
    d.mkdir()
    f = d / "latency_timer"
    f.write_text("%d\n" % value)
    if not writable:
        f.chmod(0o444)
    return str(tmp_path)


def test_the_latency_timer_is_read_through_a_symlink_and_lowered_where_writable(tmp_path, pty):
    name = os.path.basename(pty.slave_path)
    sysfs = _sysfs(tmp_path, name, 16)
    link = tmp_path / "by-id"
    link.symlink_to(pty.slave_path)
    assert latency_timer_path(str(link), sysfs) == os.path.join(sysfs, name, "latency_timer")
    setup = tune_port(str(link), pty.keep_fd, is_pty=True, sysfs=sysfs)
    assert (setup.latency_timer_was, setup.latency_timer_ms) == (16, 1)
    assert "latency timer set from 16 ms to 1 ms" in setup.describe()
    with open(os.path.join(sysfs, name, "latency_timer")) as f:
        assert f.read() == "1"


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes a read-only file")
def test_a_latency_timer_that_cannot_be_set_is_named_with_the_fix(tmp_path, pty):
    name = os.path.basename(pty.slave_path)
    sysfs = _sysfs(tmp_path, name, 16, writable=False)
    setup = tune_port(pty.slave_path, pty.keep_fd, is_pty=True, sysfs=sysfs)
    assert setup.latency_timer_ms == 16 and setup.latency_timer_was is None
    assert "latency timer is 16 ms and cannot be set here" in setup.describe()
    assert "udev rule" in setup.describe()
