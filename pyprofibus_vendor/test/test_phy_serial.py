"""Serial PHY on pyserial URLs and on Linux ptys (quirks included), raw-fd link."""
from __future__ import annotations

import errno
import logging
import os
import socket
import termios
import unittest
from unittest import mock

import serial

from pyprofibus_vendor import phy_serial
from pyprofibus_vendor.errors import PhyError
from pyprofibus_vendor.phy_serial import FdLink, SerialLink, is_pty, open_pty_pair


class UrlTest(unittest.TestCase):
    def test_loop_url(self):
        with SerialLink("loop://", 19200) as link:
            self.assertEqual(link.recv(10, 0.0), b"")
            link.send(b"\x10\x02\x08\x00\x0A\x16")
            self.assertEqual(link.recv(3, 1.0), b"\x10\x02\x08")
            self.assertEqual(link.recv(10, 1.0), b"\x00\x0A\x16")
            link.send(b"junk")
            link.flush_input()
            self.assertEqual(link.recv(10, 0.01), b"")
            self.assertEqual(link.serial.parity, serial.PARITY_EVEN)
        self.assertTrue(link.closed)
        with self.assertRaises(PhyError):
            link.send(b"x")

    def test_socket_url(self):
        server = socket.socket()
        server.bind(("127.0.0.1", 0))
        server.listen(1)
        try:
            port = server.getsockname()[1]
            link = SerialLink(f"socket://127.0.0.1:{port}", 187500)
            conn, _ = server.accept()
            try:
                conn.sendall(b"\xE5")
                self.assertEqual(link.recv(10, 5.0), b"\xE5")
                link.send(b"\xDC\x02\x01")
                self.assertEqual(conn.recv(10), b"\xDC\x02\x01")
                conn.close()                          # peer vanished
                with self.assertRaises(PhyError):
                    for _ in range(3):
                        link.recv(10, 1.0)
            finally:
                link.close()
        finally:
            server.close()

    def test_missing_device_names_path(self):
        with self.assertRaises(PhyError) as ctx:
            SerialLink("/dev/does-not-exist-pb", 19200)
        self.assertIn("/dev/does-not-exist-pb", str(ctx.exception))

    def test_bad_baud_and_bad_url(self):
        with self.assertRaises(PhyError):
            SerialLink("loop://", 300)
        with self.assertRaises(PhyError):
            SerialLink("nosuchproto://x", 19200)

    def test_einval_on_a_real_port_is_reported(self):
        def fail(*args, **kwargs):
            raise termios.error(errno.EINVAL, "Invalid argument")

        with mock.patch.object(phy_serial.serial, "serial_for_url", fail):
            with self.assertRaises(PhyError) as ctx:
                SerialLink("loop://", 19200)
        self.assertIn("EINVAL", str(ctx.exception))


class PtyTest(unittest.TestCase):
    def setUp(self) -> None:
        self.pair = open_pty_pair()
        self.master = self.pair.master_link()

    def tearDown(self) -> None:
        self.master.close()
        self.pair.close()

    def test_is_pty(self):
        self.assertTrue(is_pty(self.pair.slave_path))
        self.assertFalse(is_pty("/dev/null"))
        self.assertFalse(is_pty("/nonexistent"))

    def test_reopen_at_same_baud_works(self):
        """The Linux pty EINVAL quirk: open, close, open again at the same speed."""
        for baud in (19200, 19200, 9600, 9600, 187500, 187500, 12_000_000, 12_000_000):
            link = SerialLink(self.pair.slave_path, baud)
            try:
                link.send(b"\x10\x08\x02\x49\x53\x16")
                self.assertEqual(self.master.recv(100, 5.0), b"\x10\x08\x02\x49\x53\x16")
                self.master.send(b"\xE5")
                self.assertEqual(link.recv(10, 5.0), b"\xE5")
            finally:
                link.close()

    def test_fallback_to_no_parity_with_warning(self):
        SerialLink(self.pair.slave_path, 19200).close()
        with mock.patch.object(phy_serial, "_preset_other_speed", lambda path: None):
            with self.assertLogs("pyprofibus_vendor.phy_serial", logging.WARNING) as logs:
                link = SerialLink(self.pair.slave_path, 19200)
        try:
            self.assertIn("no parity", "\n".join(logs.output))
            self.assertEqual(link.serial.parity, serial.PARITY_NONE)
            link.send(b"\xE5")
            self.assertEqual(self.master.recv(10, 5.0), b"\xE5")
        finally:
            link.close()

    def test_reopen_method_and_binary_transparency(self):
        link = SerialLink(self.pair.slave_path, 19200)
        try:
            link.reopen()
            data = bytes(range(256))
            link.send(data)
            got = b""
            while len(got) < 256:
                chunk = self.master.recv(512, 5.0)
                self.assertTrue(chunk)
                got += chunk
            self.assertEqual(got, data)
            self.master.send(data)
            got = b""
            while len(got) < 256:
                chunk = link.recv(512, 5.0)
                self.assertTrue(chunk)
                got += chunk
            self.assertEqual(got, data)
        finally:
            link.close()

    def test_device_vanishes(self):
        link = SerialLink(self.pair.slave_path, 19200)
        try:
            self.master.close()
            self.pair.close()                 # no master side any more: EIO
            with self.assertRaises(PhyError):
                link.recv(10, 1.0)
            with self.assertRaises(PhyError):
                link.send(b"\x00" * 10)
        finally:
            link.close()

    def test_fd_link_flush_and_close(self):
        link = SerialLink(self.pair.slave_path, 19200)
        try:
            link.send(b"backlog")
            self.assertEqual(self.master.recv(3, 5.0), b"bac")
            self.master.flush_input()             # drops the unread rest
            self.assertEqual(self.master.recv(10, 0.0), b"")
            link.send(b"new")
            self.assertEqual(self.master.recv(10, 5.0), b"new")
        finally:
            link.close()
        self.master.close()
        self.assertTrue(self.master.closed)
        with self.assertRaises(PhyError):
            self.master.recv(1, 0)
        with self.assertRaises(PhyError):
            self.pair.master_link()


class FdLinkTest(unittest.TestCase):
    def test_pipe_eof_and_flush(self):
        r, w = os.pipe()
        reader, writer = FdLink(r, name="r"), FdLink(w, name="w")
        writer.send(b"abc")
        self.assertEqual(reader.recv(10, 1.0), b"abc")
        writer.send(b"def")
        reader.flush_input()              # not a tty: read and discard
        self.assertEqual(reader.recv(10, 0.0), b"")
        writer.close()
        with self.assertRaises(PhyError):
            reader.recv(10, 1.0)
        reader.close()
        with self.assertRaises(PhyError):
            writer.send(b"x")

    def test_write_to_closed_pipe(self):
        r, w = os.pipe()
        os.close(r)
        writer = FdLink(w)
        with self.assertRaises(PhyError):
            writer.send(b"x")
        writer.close()


if __name__ == "__main__":
    unittest.main()
