"""The commissioning tools (master, slave, sniff; gsd's CLI plumbing) as subprocesses on real ptys.

Processes that run for a while are read line by line with a deadline (no sleeping); every
subprocess has a timeout, so a hanging tool fails the test instead of blocking the run.
"""
from __future__ import annotations

import json
import os
import queue
import random
import re
import signal
import subprocess
import sys
import threading
import time
from typing import Dict, List, Optional

import pytest

from pyprofibus_vendor.dp import (DataExchange, GcCommand, GlobalControl, Sap,
                                  global_control_frame, reply_frame, request_frame)
from pyprofibus_vendor.dp_slave import DpSlave, SlaveServer
from pyprofibus_vendor.fdl import FrameControl, ResponseStatus, Sd1, decode_frame
from pyprofibus_vendor.phy_serial import open_pty_pair
from pyprofibus_vendor.sniff import SniffDecoder, parse_hex_dump_line

from _helpers import MASTER, ROBOT_CFG, ROBOT_IDENT, SLAVE

PYTHON = sys.executable
SRC = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "src")
ENV = dict(os.environ, PYTHONPATH=SRC)
OUT14 = bytes(range(1, 15))
IN14 = bytes(range(0xA0, 0xAE))


def hx(data: bytes) -> str:
    return " ".join("%02X" % b for b in data)


def run_tool(tool: str, *args: str, stdin: Optional[bytes] = None,
             timeout: float = 30) -> subprocess.CompletedProcess:
    result = subprocess.run([PYTHON, "-m", "pyprofibus_vendor.%s" % tool] + list(args), env=ENV,
                            input=stdin, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            timeout=timeout)
    result.out = result.stdout.decode("utf-8", "replace")  # type: ignore[attr-defined]
    result.err = result.stderr.decode("utf-8", "replace")  # type: ignore[attr-defined]
    assert "Traceback" not in result.err, result.err
    return result


class Proc:
    """A tool running in the background; its stdout/stderr lines are collected by threads."""

    def __init__(self, tool: str, *args: str) -> None:
        self.popen = subprocess.Popen([PYTHON, "-m", "pyprofibus_vendor.%s" % tool] + list(args),
                                      env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                      universal_newlines=True)
        self.lines: Dict[str, List[str]] = {"out": [], "err": []}
        self._queues: Dict[str, "queue.Queue[Optional[str]]"] = {"out": queue.Queue(),
                                                                 "err": queue.Queue()}
        self._readers = [threading.Thread(target=self._read, args=(name, stream), daemon=True)
                         for name, stream in (("out", self.popen.stdout), ("err", self.popen.stderr))]
        for reader in self._readers:
            reader.start()

    def _read(self, name: str, stream) -> None:
        for line in stream:
            self._queues[name].put(line.rstrip("\n"))
        self._queues[name].put(None)

    def wait_line(self, needle: str, stream: str = "out", timeout: float = 10.0) -> str:
        """The first new line containing ``needle``; fails after ``timeout`` seconds or at EOF."""
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise AssertionError("no %r on std%s within %g s; got %r"
                                     % (needle, stream, timeout, self.lines[stream]))
            try:
                line = self._queues[stream].get(timeout=left)
            except queue.Empty:
                continue
            if line is None:
                self._queues[stream].put(None)
                raise AssertionError("std%s ended without %r; got %r"
                                     % (stream, needle, self.lines[stream]))
            self.lines[stream].append(line)
            if needle in line:
                return line

    def finish(self, timeout: float = 10.0) -> int:
        """Wait for the exit, collect the remaining output, return the exit status."""
        rc = self.popen.wait(timeout)
        for reader in self._readers:
            reader.join(timeout)
        for name, q in self._queues.items():
            while True:
                line = q.get_nowait() if not q.empty() else None
                if line is None:
                    break
                self.lines[name].append(line)
        return rc

    def kill(self) -> None:
        if self.popen.poll() is None:
            self.popen.kill()
            self.popen.wait(5)


def block(lines: List[str], title: str) -> Dict[str, str]:
    """The indented ``name  value`` rows after the line ``title``."""
    start = lines.index(title)
    rows = {}
    for line in lines[start + 1:]:
        match = re.match(r"^  (\S.*?)\s{2,}(\S.*)$", line)
        if not match:
            break
        rows[match.group(1)] = match.group(2)
    return rows


@pytest.fixture
def pty_slave():
    """A DpSlave (robot ident and Cfg, fixed inputs) served in this process on a fresh pty."""
    made = []

    def make(ident: int = ROBOT_IDENT, cfg: bytes = ROBOT_CFG, inputs: bytes = IN14):
        pair = open_pty_pair()
        slave = DpSlave(SLAVE, ident, cfg)
        slave.inputs = inputs
        server = SlaveServer(pair.master_link(), slave)
        server.start()
        made.append((pair, server))
        return pair.slave_path, slave, server

    yield make
    for pair, server in made:
        server.stop()
        server.link.close()
        pair.close()


def master_args(device: str, *extra: str, ident: int = ROBOT_IDENT, cfg: bytes = ROBOT_CFG):
    return ["--device", device, "--addr", str(SLAVE), "--ident", "0x%04X" % ident,
            "--cfg", hx(cfg)] + list(extra)


# ---------------------------------------------------------------------------------------------
# --help and usage errors
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("tool", ["master", "slave", "sniff", "scan"])
def test_help_describes_the_tool_and_lists_exit_codes(tool):
    result = run_tool(tool, "--help")
    assert result.returncode == 0
    assert "usage: python3 -m pyprofibus_vendor.%s" % tool in result.out
    assert "Exit status:" in result.out
    for code in range(4):
        assert re.search(r"^  %d  \S" % code, result.out, re.M), (code, result.out)
    assert "Examples:" in result.out


def test_gsd_uses_the_shared_one_line_usage_errors():
    result = run_tool("gsd", "--bogus")
    assert result.returncode == 2
    assert result.err.strip().startswith("error: ")
    assert len(result.err.strip().splitlines()) == 1


def test_master_usage_errors_are_one_line_and_status_2():
    cases = [
        (["--addr", "126"], "argument --addr: address 126 is outside 0..125"),
        (["--ident", "0x10000"], "argument --ident: ident 0x10000 is outside 0x0000..0xFFFF"),
        (["--out", "01 zz"], "argument --out: 'zz' is not hex"),
        (["--out", "123"], "'123' has an odd number of hex digits"),
        (["--cfg", "C0"], "argument --cfg: bad Cfg bytes C0"),
        (["--baud", "300"], "baud 300 is outside 9600..12000000"),
        (["--master-addr", "4"], "--master-addr 4 is the slave's address"),
        (["--watchdog", "0.1", "--period", "0.2"], "must be longer than --period"),
    ]
    for extra, message in cases:
        result = run_tool("master", *master_args("/dev/pb-never-opened", "--cycles", "1", *extra))
        assert result.returncode == 2, (extra, result.err)
        assert message in result.err, (extra, result.err)
        assert len(result.err.strip().splitlines()) == 1, result.err
    result = run_tool("master", "--addr", "4", "--cycles", "1")
    assert result.returncode == 2 and "missing --device, --ident, --cfg" in result.err
    result = run_tool("master", *master_args("/dev/pb-never-opened"))
    assert result.returncode == 2 and "--cycles" in result.err


def test_master_missing_device_is_status_3_with_the_os_reason():
    result = run_tool("master", *master_args("/dev/pb-missing-xyz", "--cycles", "1"))
    assert result.returncode == 3
    assert result.err.strip() == "error: cannot open /dev/pb-missing-xyz: No such file or directory"
    assert result.out == ""


def test_master_checks_the_output_length_before_sending_anything():
    pair = open_pty_pair()
    try:
        result = run_tool("master", *master_args(pair.slave_path, "--cycles", "1", "--out", "01 02"))
        assert result.returncode == 2
        assert ("--out has 2 bytes, but the Cfg 13 13 13 11 23 23 23 21 declares 14 output bytes"
                in result.err)
        os.set_blocking(pair.master_fd, False)
        with pytest.raises(BlockingIOError):
            os.read(pair.master_fd, 100)      # not a single byte reached the line
    finally:
        pair.close()


def test_master_bad_config_file_is_status_2_naming_file_and_key(tmp_path):
    path = tmp_path / "bus.yaml"
    path.write_text("master_address: 2\nbaud: 19200\nphy: {type: serial, device: /dev/null}\n"
                    "slaves:\n  - address: 4\n    cfg: '3D'\n    ident: 0x1234\n    watchdg_ms: 3\n")
    result = run_tool("master", "--config", str(path), "--cycles", "1")
    assert result.returncode == 2
    assert str(path) in result.err and "slaves[0].watchdg_ms" in result.err


def test_slave_usage_errors(tmp_path):
    base = ["--addr", "4", "--ident", "0x06C6", "--cfg", "3D"]
    result = run_tool("slave", "--pty", *base, "--inputs", "01 02")
    assert result.returncode == 2
    assert "--inputs has 2 bytes, but the Cfg 3D declares 14 input bytes" in result.err
    assert result.out == ""                   # checked before the pty was made
    taken = tmp_path / "taken"
    taken.write_text("keep me")
    result = run_tool("slave", "--pty", "--link", str(taken), *base, "--echo")
    assert result.returncode == 2 and "exists and is not a symlink" in result.err
    assert taken.read_text() == "keep me"
    result = run_tool("slave", "--device", "/dev/pb-missing-xyz", *base)
    assert result.returncode == 3
    assert result.err.strip() == "error: cannot open /dev/pb-missing-xyz: No such file or directory"
    result = run_tool("slave", "--pty", *base, "--echo", "--inputs", "00")
    assert result.returncode == 2 and "not allowed with argument" in result.err
    result = run_tool("slave", "--device", "/dev/null", "--link", str(tmp_path / "l"), *base)
    assert result.returncode == 2 and "--link needs --pty" in result.err


# ---------------------------------------------------------------------------------------------
# master <-> slave over ptys
# ---------------------------------------------------------------------------------------------

def test_master_tool_against_slave_tool_on_a_pty(tmp_path):
    link = str(tmp_path / "vr006l")
    slave = Proc("slave", "--pty", "--link", link, "--addr", str(SLAVE), "--ident", "0x06C6",
                 "--cfg", hx(ROBOT_CFG), "--echo", "--duration", "20")
    try:
        first = slave.wait_line("")
        assert re.match(r"^device: /dev/pts/\d+$", first), first
        device = first.split(": ", 1)[1]
        assert os.path.islink(link) and os.readlink(link) == device
        slave.wait_line("serving on %s" % device)

        result = run_tool("master", *master_args(link, "--cycles", "20", "--out", hx(OUT14),
                                                 "--watchdog", "0.3"))
        assert result.returncode == 0, result.err
        lines = result.out.splitlines()
        assert "inputs: %s" % hx(OUT14) in lines           # echoed by the slave
        stats = block(lines, "statistics:")
        assert stats["cycles ok"] == "20 of 20"
        assert stats["cycles failed"] == "0"
        assert stats["FCS errors"] == "0" and stats["timeouts"] == "0"
        for name in ("retries", "requests", "losses", "cycles/s", "cycle time", "connect time"):
            assert name in stats
        assert float(stats["cycles/s"]) > 0

        slave.wait_line("state: WAIT_PRM -> WAIT_CFG (parameterised by master %d)" % MASTER)
        slave.wait_line("state: WAIT_CFG -> DATA_EXCH (configuration accepted)")
        slave.wait_line("watchdog expired: no telegram from master %d for 0.300 s" % MASTER)
        slave.wait_line("state: DATA_EXCH -> WAIT_PRM (watchdog expired)")
        slave.popen.send_signal(signal.SIGINT)
        assert slave.finish() == 0
        counters = block(slave.lines["out"], "counters:")
        assert counters["data_exchanges"] == "20"
        assert counters["watchdog_expiries"] == "1"
        assert counters["cfg_accepted"] == "1" and counters["fcs_errors"] == "0"
        assert "final state: WAIT_PRM" in slave.lines["out"]
        assert not os.path.lexists(link)                     # the symlink is removed on exit
    finally:
        slave.kill()


def test_slave_tool_stops_after_duration_and_on_sigterm():
    slave = Proc("slave", "--pty", "--addr", "5", "--ident", "0x1234", "--cfg", "10",
                 "--duration", "0.3")
    try:
        slave.wait_line("device: /dev/pts/")
        assert slave.finish() == 0
        assert "final state: WAIT_PRM" in slave.lines["out"]
    finally:
        slave.kill()
    slave = Proc("slave", "--pty", "--addr", "5", "--ident", "0x1234", "--cfg", "10")
    try:
        slave.wait_line("serving on")
        slave.popen.send_signal(signal.SIGTERM)
        assert slave.finish() == 0
        assert "counters:" in slave.lines["out"]
    finally:
        slave.kill()


def test_scan_lists_the_slave_on_a_pty_and_leaves_it_unparameterised(pty_slave):
    device, slave, _server = pty_slave()
    result = run_tool("scan", "--device", device, "--rates", "19200", "--addresses", "1..6", "--listen", "0.05",
                      "--reply-timeout", "0.1", "--json")
    assert result.returncode == 0, result.err
    data = json.loads(result.out)
    assert data["rate"] == 19200 and data["echo"] is False and data["other_masters"] == {}
    (station,) = data["rates"][0]["stations"]
    assert (station["address"], station["station_type"], station["ident"], station["owner"]) == (SLAVE, "slave", "0x06C6", None)
    assert station["cfg"] == hx(ROBOT_CFG) and station["gsd"]["file"] == "PAN06C6.gsd"
    assert slave.state.name == "WAIT_PRM" and slave.counters.requests == 3    # FDL status, Slave_Diag, Get_Cfg


def test_master_json_against_in_test_slave_server(pty_slave):
    device, slave, _server = pty_slave()
    result = run_tool("master", *master_args(device, "--cycles", "5", "--out", hx(OUT14),
                                             "--json", "--period", "0.01"))
    assert result.returncode == 0, result.err
    data = json.loads(result.out)
    assert data["inputs"] == hx(IN14)
    assert data["connected"] is True
    assert data["statistics"]["cycles_ok"] == 5 and data["statistics"]["cycles_failed"] == 0
    assert data["statistics"]["fcs_errors"] == 0
    assert slave.outputs == OUT14                     # the slave received the --out bytes
    assert slave.counters.data_exchanges == 5


def test_master_with_config_file_and_overrides(pty_slave, tmp_path):
    device, slave, _server = pty_slave()
    path = tmp_path / "bus.yaml"
    path.write_text("master_address: 3\nbaud: 19200\ncycle_rate_hz: 100\n"
                    "phy: {type: serial, device: /dev/pb-overridden}\n"
                    "slaves:\n  - name: vr006l\n    address: %d\n    gsd: PAN06C6.gsd\n"
                    "    modules: [4 Bytes In, 4 Bytes In, 4 Bytes In, 2 Bytes In,\n"
                    "              4 Bytes Out, 4 Bytes Out, 4 Bytes Out, 2 Bytes Out]\n"
                    "    watchdog_ms: 500\n" % SLAVE)
    result = run_tool("master", "--config", str(path), "--device", device, "--cycles", "3",
                      "--out", hx(OUT14))
    assert result.returncode == 0, result.err
    assert "master 3, slave 4 on %s" % device in result.out
    assert "Chk_Cfg 13 13 13 11 23 23 23 21" in result.out and "watchdog 0.5 s" in result.out
    assert slave.locked_by == 3 and slave.outputs == OUT14
    assert slave.watchdog_time == pytest.approx(0.5)


def test_master_names_a_wrong_ident(pty_slave):
    device, slave, _server = pty_slave(ident=0x1234)
    result = run_tool("master", *master_args(device, "--cycles", "3", "--timeout", "1"))
    assert result.returncode == 1
    assert "slave 4 did not reach Data_Exchange within 1 s: wrong ident: the slave reports ident " \
           "0x1234, the master was given 0x06C6" in result.err
    assert "parameter fault" in result.err
    assert slave.counters.prm_faults >= 1 and slave.counters.data_exchanges == 0


def test_master_names_a_cfg_fault_and_the_slaves_cfg(pty_slave):
    device, slave, _server = pty_slave(cfg=bytes.fromhex("3D"))
    result = run_tool("master", *master_args(device, "--cycles", "3", "--timeout", "1",
                                             cfg=bytes.fromhex("BD")))
    assert result.returncode == 1
    assert "configuration fault (Cfg_Fault): the slave rejects Chk_Cfg BD; Get_Cfg says the slave " \
           "uses 3D" in result.err
    assert slave.counters.cfg_faults >= 1


def test_master_reports_no_answer():
    pair = open_pty_pair()                    # nobody serves the other end
    try:
        result = run_tool("master", *master_args(pair.slave_path, "--cycles", "1", "--timeout",
                                                 "1"))
        assert result.returncode == 1
        assert "no answer from station 4" in result.err and "no reply to FDL_Status" in result.err
        assert "inputs:" not in result.out
    finally:
        pair.close()


# ---------------------------------------------------------------------------------------------
# sniff
# ---------------------------------------------------------------------------------------------

def startup_bytes() -> List[bytes]:
    """The recorded real start-up (as in pyprofibus_vendor/README.md), byte for byte (master 2, slave 8, ident 0x4D14)."""
    return [bytes.fromhex(h) for h in (
        "10 08 02 49 53 16",
        "10 02 08 00 0A 16",
        "68 05 05 68 88 82 6D 3C 3E F1 16",
        "A2 82 88 08 3E 3C 02 05 00 FF 4D 14 F3 16",
        "68 0C 0C 68 88 82 5D 3D 3E 88 1E 01 00 4D 14 01 EB 16",
        "E5",
        "68 06 06 68 88 82 7D 3E 3E 3D 40 16",
        "E5",
        "68 05 05 68 88 82 5D 3C 3E E1 16",
        "A2 82 88 08 3E 3C 00 0C 00 02 4D 14 FB 16",
    )]


STARTUP_SERVICES = [
    ("SD1", "FDL_Status", "request"), ("SD1", "FDL_Status", "reply"),
    ("SD2", "Slave_Diag", "request"), ("SD3", "Slave_Diag", "reply"),
    ("SD2", "Set_Prm", "request"), ("SC", "Set_Prm", "ack"),
    ("SD2", "Chk_Cfg", "request"), ("SC", "Chk_Cfg", "ack"),
    ("SD2", "Slave_Diag", "request"), ("SD3", "Slave_Diag", "reply"),
]


def exchange_bytes() -> bytes:
    """Data_Exchange request and reply, a Global_Control, an RS refusal, all encoded by our FDL."""
    req = request_frame(8, 2, True, True, None, DataExchange(OUT14).encode())
    rep = reply_frame(req, 8, IN14, ResponseStatus.DH)
    gc = global_control_frame(2, GlobalControl(GcCommand.CLEAR_DATA | GcCommand.SYNC, 0))
    diag_req = request_frame(8, 2, False, True, Sap.SLAVE_DIAG)
    refusal = Sd1(2, 8, FrameControl.resp(ResponseStatus.RS))
    return b"".join(f.encode() for f in (req, rep, gc, diag_req, refusal))


def test_sniff_decodes_golden_frames_written_into_a_pty():
    pair = open_pty_pair()
    sniff = Proc("sniff", "--device", pair.slave_path, "--count", "5", "--duration", "15")
    try:
        sniff.wait_line("listening on %s" % pair.slave_path, "err")
        frames = startup_bytes()
        bad_fcs = bytearray(frames[2])
        bad_fcs[-2] ^= 0x01
        os.write(pair.master_fd, frames[0] + b"\x00\xFF\x12" + frames[1] + bytes(bad_fcs)
                 + frames[3] + frames[4] + frames[5])
        assert sniff.finish() == 0
    finally:
        sniff.kill()
        pair.close()
    out = sniff.lines["out"]
    assert len(out) == 7, out                 # 5 telegrams, one garbage line, one FCS error
    stamp = r"^\s*\d+\.\d{6}  "
    assert all(re.match(stamp, line) for line in out), out
    assert re.match(stamp + r"SD1  DA=8     SA=2     FC=49 req FDL status FCB=0 FCV=0 \| "
                    r"FDL_Status request$", out[0]), out[0]
    assert out[1].endswith("??   garbage, 3 bytes: 00 FF 12")
    assert "SD1  DA=2     SA=8     FC=00 resp OK, slave | FDL_Status reply: slave, OK" in out[2]
    assert "!!   FCS error (FCS 0xF0, computed 0xF1): 68 05 05 68 88 82 6D 3C 3E F0 16" in out[3]
    assert "SD3  DA=2:62  SA=8:60  FC=08 resp DL data low, slave | Slave_Diag reply: ident 0x4D14, " \
           "master none" in out[4]
    assert "station not ready for data exchange; slave requests new parameters" in out[4]
    assert "| data 02 05 00 FF 4D 14" in out[4]
    assert "SD2  DA=8:61  SA=2:62  FC=5D req SRD high FCB=0 FCV=1 | Set_Prm request: " \
           "WD_ON|LOCK_REQ, watchdog 300 ms (30 x 1), min TSDR 0, ident 0x4D14" in out[5]
    assert out[6].endswith("SC   short acknowledge | Set_Prm ack")
    assert "summary: 5 telegrams, 1 errors (1 FCS), 3 garbage bytes" in "\n".join(sniff.lines["err"])


def test_sniff_hex_dump_file_as_json(tmp_path):
    path = tmp_path / "startup.hex"
    path.write_text("# captured start-up\n" + "\n".join(
        hx(f) + ("   # Set_Prm" if i == 4 else "") for i, f in enumerate(startup_bytes())) + "\n")
    result = run_tool("sniff", "--file", str(path), "--json")
    assert result.returncode == 0, result.err
    events = [json.loads(line) for line in result.out.splitlines()]
    assert [(e["type"], e["service"], e["role"]) for e in events] == STARTUP_SERVICES
    offsets = [0]
    for frame in startup_bytes()[:-1]:
        offsets.append(offsets[-1] + len(frame))
    assert [e["offset"] for e in events] == offsets
    assert events[3]["dsap"] == 62 and events[3]["ssap"] == 60 and events[3]["da"] == 2
    assert "slave requests new parameters" in events[3]["decode"]
    assert events[6]["decode"] == "3D=in/out 14 (in 14, out 14)"
    assert events[9]["decode"].startswith("ident 0x4D14, master 2")
    assert events[2]["fcb"] is True and events[2]["fcv"] is False
    assert events[4]["decode"].endswith("ident 0x4D14, groups 0x01")


def test_sniff_raw_bytes_from_stdin_and_other_dump_formats(tmp_path):
    raw = exchange_bytes()
    result = run_tool("sniff", "--file", "-", stdin=raw)
    assert result.returncode == 0, result.err
    out = result.out.splitlines()
    assert len(out) == 5, out
    assert "Data_Exchange request: 14 output bytes | data %s" % hx(OUT14) in out[0]
    assert "FCB=1 FCV=1" in out[0]
    assert "resp DH data high (diag pending), slave | Data_Exchange reply: 14 input bytes, new " \
           "diagnosis pending | data %s" % hx(IN14) in out[1]
    assert "DA=127:58 SA=2:62" in out[2] and "req SDN high" in out[2]
    assert "Global_Control request: CLEAR_DATA|SYNC, group select 0x00" in out[2]
    assert "Slave_Diag request" in out[3]
    assert "Slave_Diag reply: refused: RS SAP not activated" in out[4]
    # the same bytes as xxd and hexdump -C output
    xxd = "".join("%08x: %s  %s\n" % (i, " ".join(raw[j:j + 2].hex()
                                                  for j in range(i, min(i + 16, len(raw)), 2)),
                                       "." * 16)
                  for i in range(0, len(raw), 16))
    dump_c = "".join("%08x  %s  |%s|\n" % (i, " ".join("%02x" % b for b in raw[i:i + 16]), "." * 16)
                     for i in range(0, len(raw), 16)) + "%08x\n" % len(raw)
    for text in (xxd, dump_c):
        assert b"".join(parse_hex_dump_line(line, "|" in text)
                        for line in text.splitlines()) == raw
        path = tmp_path / "dump.txt"
        path.write_text(text)
        again = run_tool("sniff", "--file", str(path))
        assert again.returncode == 0, again.err
        assert [l[10:] for l in again.out.splitlines()] == [l[10:] for l in out]


def test_sniff_reports_bad_input_and_unmet_count(tmp_path):
    path = tmp_path / "bad.hex"
    path.write_text("10 08 02 49 53 16\nzz 10\nA2 82 88\n")
    result = run_tool("sniff", "--file", str(path), "--count", "3")
    assert result.returncode == 1
    assert "error: only 1 of 3 telegrams seen" in result.err
    out = result.out.splitlines()
    assert "FDL_Status request" in out[0]
    assert "!!   bad hex dump line (line 2: 'zz' is not hex)" in out[1]
    assert out[2].endswith("!!   truncated telegram (telegram cut short: 3 of 14 bytes): A2 82 88")
    result = run_tool("sniff", "--file", str(tmp_path / "missing.bin"))
    assert result.returncode == 3
    assert result.err.strip() == "error: cannot open %s: No such file or directory" % (
        tmp_path / "missing.bin")
    result = run_tool("sniff", "--device", "/dev/pb-missing-xyz")
    assert result.returncode == 3 and "cannot open /dev/pb-missing-xyz" in result.err
    result = run_tool("sniff", "--file", "-", "--count", "0", stdin=b"")
    assert result.returncode == 2 and "0 must be at least 1" in result.err


def test_sniff_survives_random_bytes():
    rng = random.Random(7)
    noise = bytes(rng.getrandbits(8) for _ in range(20000)) + b"".join(startup_bytes())
    result = run_tool("sniff", "--file", "-", "--format", "raw", "--json", stdin=noise)
    assert result.returncode == 0, result.err
    events = [json.loads(line) for line in result.out.splitlines()]
    assert sum(e.get("length") or len(bytes.fromhex(e["raw"])) for e in events) == len(noise)
    assert [(e["type"], e.get("service"), e.get("role")) for e in events[-10:]] == STARTUP_SERVICES


def test_sniff_decoder_accounts_for_every_byte_in_any_chunking():
    rng = random.Random(3)
    stream = b""
    for frame in startup_bytes() + [exchange_bytes()]:
        stream += bytes(rng.randrange(256) for _ in range(rng.randrange(4))) + frame
    expected_frames = None
    for chunk_size in (1, 3, 7, 64, len(stream)):
        decoder = SniffDecoder()
        events = []
        for i in range(0, len(stream), chunk_size):
            events += decoder.feed(stream[i:i + chunk_size], 0.0)
        events += decoder.flush(0.0)
        covered = sorted((e["offset"], e["offset"] + len(bytes.fromhex(e["raw"]))) for e in events)
        pos = 0
        for start, end in covered:                       # the events tile the stream exactly
            assert start == pos
            pos = end
        assert pos == len(stream)
        frames = [(e["offset"], e["raw"]) for e in events if e["kind"] == "frame"]
        for _offset, raw_hex in frames:
            decode_frame(bytes.fromhex(raw_hex))
        if expected_frames is None:
            expected_frames = frames
        assert frames == expected_frames, chunk_size
    assert len(expected_frames) >= 15
