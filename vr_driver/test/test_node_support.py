"""The virtual devices' nodes open their device through one helper (ros/support.py): a port that
cannot be opened ends the node with 3 and a wrong setting with 2, each said in words; ``~pty_link``
``auto`` is this launch's own link, its folder made."""
import logging
import os

import pytest

from vr_driver.controller.program import EXIT_DEVICE, EXIT_OK, EXIT_USAGE, SimDeviceError, SimError
from vr_driver.ros.support import open_device, own_link


def _raise(exc):
    def make():
        raise exc
    return make


def test_a_device_that_opens_is_returned_with_exit_ok():
    device = object()
    assert open_device("virtual_x", lambda: device) == (device, EXIT_OK)


@pytest.mark.parametrize("exc, status, words", [
    (SimDeviceError("cannot open /dev/ttyX: no such file"), EXIT_DEVICE, "virtual_x: device error: cannot open"),
    (SimError("baud must be one of ..."), EXIT_USAGE, "virtual_x: baud must be one of"),
    (ValueError("invalid literal for int()"), EXIT_USAGE, "virtual_x: invalid literal"),
])
def test_a_device_that_fails_ends_the_node_in_words(exc, status, words, caplog):
    with caplog.at_level(logging.DEBUG):
        assert open_device("virtual_x", _raise(exc)) == (None, status)
    assert words in caplog.text


def test_an_internal_error_is_not_taken_for_a_setting():
    with pytest.raises(KeyError):
        open_device("virtual_x", _raise(KeyError("bug")))


def test_own_link(tmp_path, monkeypatch):
    monkeypatch.setenv("ROS_LOG_DIR", str(tmp_path / "log"))
    monkeypatch.setenv("ROS_MASTER_URI", "http://localhost:11399")
    monkeypatch.delenv("ROS_NAMESPACE", raising=False)
    assert own_link("", "line") is None and own_link(None, "line") is None
    assert own_link("/tmp/some/link", "line") == "/tmp/some/link"
    path = own_link("auto", "line")
    assert path == str(tmp_path / "log" / "vr006l_virtual_line_11399") and os.path.isdir(tmp_path / "log")
    assert own_link("auto:io_island", "line") == str(tmp_path / "log" / "vr006l_virtual_io_island_11399")
    with pytest.raises(SimError, match="~pty_link must be a path"):
        own_link(5, "line")
