"""The commissioning tool's own bus: the driver's link supervisor on the serial port, one DP cycle per
call, every cycle logged. ROS-free.

:class:`CommissionBus` runs :class:`~vr_driver.driver.link.link.LinkSupervisor` in this process (no bus
process: the tool does nothing else while the bus runs, and it must see *every* record, where a bus
process hands over only the newest) at the configured cycle rate. Each :meth:`CommissionBus.cycle`
sends the record it is given, runs one Data_Exchange and appends a :class:`Cycle` -- the request's
time, the reply's arrival, the decoded feedback (or why there was none) and the command -- to the
log that the analysis (:mod:`vr_driver.commission.analysis`) reads and that :meth:`CommissionBus.dump`
writes out as JSON lines.

Timing: a record's heartbeat ``h`` was written by the program loop *between* the request of the last
cycle that brought an older heartbeat and the arrival of the reply that brought ``h`` (the card
answers a request with the image the program wrote before it answered). :func:`heartbeat_brackets`
gives those intervals: they hold whatever the scheduling of either end did.

The port is the tool's alone: :func:`port_users` names the other processes that hold a serial
device open (the driver node, a terminal program), and the port is opened exclusively.
"""
from __future__ import annotations

import json
import logging
import os
import time
from dataclasses import dataclass
from typing import Any, Callable, Dict, Iterable, Iterator, List, Optional, Tuple

from ..driver.link.link import LinkSample, LinkState, LinkSupervisor
from ..errors import VrDriverError
from ..params import DriverParams
from ..protocol.v3 import FeedbackV3

__all__ = ["Cycle", "CommissionBus", "CommissionError", "LinkDown", "port_problem", "port_users", "heartbeat_brackets", "heartbeat_samples", "new_loops"]

log = logging.getLogger("vr_driver.commission")


class CommissionError(VrDriverError):
    """A commissioning step cannot go on (the message says why and what to do)."""


class LinkDown(CommissionError):
    """The controller's link was lost (or never came up) while a step needed it."""


@dataclass(frozen=True)
class Cycle:
    """One bus cycle as the tool saw it."""

    index: int
    request: float                        # clock time the cycle began (the request went out)
    time: float                           # clock time the cycle ended
    state: LinkState
    feedback: Optional[FeedbackV3]        # the record that arrived in this cycle (None: none / bad)
    arrival: Optional[float]              # when it arrived (the reply's end)
    command: bytes                        # the record sent in this cycle
    reason: str = ""                      # the link's reason when it is not connected

    def to_json(self) -> str:
        fb = self.feedback
        row: Dict[str, Any] = {"i": self.index, "t_req": round(self.request, 6), "t": round(self.time, 6),
                               "link": self.state.value, "out": self.command.hex()}
        if fb is not None:
            row.update(arrival=round(self.arrival or 0.0, 6), hb=fb.heartbeat, state=fb.state.name,
                       armed=fb.armed, status=int(fb.status), accepted=fb.accepted_seq, done=fb.done_seq,
                       active=fb.active_seq, rejected=fb.rejected_seq, code=int(fb.reject_code), tcp=list(fb.tcp))
        elif self.reason:
            row["reason"] = self.reason
        return json.dumps(row, separators=(",", ":"))


def port_users(device: str, proc: str = "/proc") -> List[Tuple[int, str]]:
    """Other processes that hold ``device`` open: (pid, command line) each, read from /proc (empty
    where /proc cannot be read). A pseudo terminal (/dev/pts/N) is not checked: its other end (a
    virtual controller) holds it open on purpose."""
    try:
        target = os.path.realpath(device)
        if target.startswith("/dev/pts/") or not os.path.exists(target):
            return []
        pids = [int(p) for p in os.listdir(proc) if p.isdigit()]
    except OSError:
        return []
    me = os.getpid()
    out = []
    for pid in pids:
        if pid == me:
            continue
        fd_dir = os.path.join(proc, str(pid), "fd")
        try:
            fds = os.listdir(fd_dir)
        except OSError:
            continue
        for fd in fds:
            try:
                if os.path.realpath(os.path.join(fd_dir, fd)) == target:
                    break
            except OSError:
                continue
        else:
            continue
        try:
            with open(os.path.join(proc, str(pid), "cmdline"), "rb") as fh:
                cmd = fh.read().replace(b"\0", b" ").decode("utf-8", "replace").strip()
        except OSError:
            cmd = "?"
        out.append((pid, cmd))
    return out


def port_problem(device: str, dev: str = "/dev") -> str:
    """Why ``device`` cannot be opened, in words (empty: it can be tried) -- said at once, before the
    connect timeout: a port that does not exist (the adapter unplugged, another name: the serial
    ports there named) or that this user may not open. A URL (``socket://``, ``rfc2217://``) is
    not checked."""
    if not device or "://" in device:
        return ""
    if not os.path.exists(device):
        try:
            near = sorted(os.path.join(dev, n) for n in os.listdir(dev) if n.startswith(("ttyUSB", "ttyACM", "ttyS")))
        except OSError:
            near = []
        by_id = os.path.join(dev, "serial", "by-id")
        try:
            near = sorted(os.path.join(by_id, n) for n in os.listdir(by_id)) + near
        except OSError:
            pass
        shown = [p for p in near if "ttyS" not in p][:8] or near[:4]
        return ("the port %s does not exist (is the USB-RS-485 adapter plugged in?); serial ports here: %s -- "
                "give --port" % (device, ", ".join(shown) if shown else "none"))
    if not os.access(device, os.R_OK | os.W_OK):
        return ("no permission to open %s: add this user to the port's group (ls -l %s names it, usually "
                "dialout: sudo adduser $USER dialout) and log in again" % (device, device))
    return ""


def _open_exclusive(device: str, baud: int) -> Any:
    """The serial link, opened exclusively (nobody else opens the port while the tool runs)."""
    from pyprofibus_vendor.phy_serial import SerialLink
    if "://" in device:
        return SerialLink(device, baud)
    return SerialLink(device, baud, exclusive=True)


class CommissionBus:
    """The link supervisor of ``params`` (its protocol, byte order, port, cycle rate), stepped by
    :meth:`cycle`. ``clock`` and ``sleep`` are injectable; ``open_link`` too (tests)."""

    def __init__(self, params: DriverParams, clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep,
                 open_link: Optional[Callable[[str, int], Any]] = None) -> None:
        self.params = params
        self.bus_config = params.bus()
        self.clock = clock
        self.sleep = sleep
        self.period = 1.0 / params.cycle_rate
        self.supervisor = LinkSupervisor(params, self.bus_config, clock,
                                         open_link=open_link or _open_exclusive)
        self.log: List[Cycle] = []
        self.order = params.byte_order
        self.record = params.wire.idle_record(params.byte_order)
        self.feedback: Optional[FeedbackV3] = None      # the newest good record
        self.last_sample: Optional[LinkSample] = None
        self._next = clock()
        self._dumped = 0

    @property
    def device(self) -> str:
        return self.bus_config.phy.device

    @property
    def connected(self) -> bool:
        return self.supervisor.state is LinkState.CONNECTED

    def send(self, record: bytes) -> None:
        """The record sent from the next cycle on (held until another is given)."""
        self.record = record
        self.supervisor.set_outputs(record)

    def cycle(self) -> Cycle:
        """Wait for the cycle's time, run one DP cycle with the current record, log it."""
        now = self.clock()
        if now < self._next:
            self.sleep(self._next - now)
            now = self.clock()
        self._next = max(self._next + self.period, now)
        self.supervisor.set_outputs(self.record)
        sample = self.supervisor.step(now)
        self.last_sample = sample
        fb = sample.fresh if isinstance(sample.fresh, FeedbackV3) else None
        if fb is not None:
            self.feedback = fb
        entry = Cycle(len(self.log), now, sample.time, sample.state, fb,
                      sample.feedback_time if fb is not None else None, self.record,
                      "" if sample.connected else sample.reason)
        self.log.append(entry)
        return entry

    def run(self, until: Callable[[Cycle], bool], timeout: float,
            record: Optional[Callable[[Cycle], Optional[bytes]]] = None, need_link: bool = True) -> Cycle:
        """Cycle until ``until(cycle)`` (that cycle is returned) or ``timeout`` seconds passed
        (CommissionError). ``record(cycle)``, if given, may return the record to send next.
        ``need_link``: a link that is not connected raises LinkDown (with the link's reason)."""
        end = self.clock() + timeout
        while True:
            c = self.cycle()
            if need_link and c.state is not LinkState.CONNECTED:
                raise LinkDown("the link to the controller is down: %s" % (c.reason or c.state.value))
            if until(c):
                return c
            if record is not None:
                nxt = record(c)
                if nxt is not None:
                    self.send(nxt)
            if self.clock() >= end:
                raise CommissionError("no answer within %.1f s (last record: %s)"
                                      % (timeout, self.feedback.describe() if self.feedback else "none"))

    def run_for(self, seconds: float, record: Optional[Callable[[Cycle], Optional[bytes]]] = None,
                need_link: bool = True) -> List[Cycle]:
        """Cycle for ``seconds``; the cycles of that time."""
        first = len(self.log)
        end = self.clock() + seconds
        self.run(lambda c: c.time >= end, seconds + 5.0, record, need_link)
        return self.log[first:]

    def connect(self, timeout: float, bad_records: int = 20) -> LinkSample:
        """Cycle until the link is up (a good record of this session), ``bad_records`` records in a
        row could not be decoded (another byte order? the caller reads the reason), or ``timeout``;
        the last sample either way (the caller reads its state and reason)."""
        end = self.clock() + timeout
        counters = self.supervisor.counters
        while True:
            c = self.cycle()
            sample = self.last_sample
            assert sample is not None
            if c.state is LinkState.CONNECTED or self.clock() >= end or counters.protocol_errors >= bad_records:
                return sample

    def dump(self, fh: Any) -> None:
        """Write the cycles not yet written as JSON lines."""
        for c in self.log[self._dumped:]:
            fh.write(c.to_json() + "\n")
        self._dumped = len(self.log)

    def close(self) -> None:
        """Send the idle record for a few cycles, then close the port."""
        try:
            if self.connected:
                self.send(self.params.wire.idle_record(self.order))
                for _ in range(3):
                    self.cycle()
        finally:
            self.supervisor.close()


def new_loops(cycles: Iterable[Cycle]) -> Iterator[Tuple[Cycle, int, Optional[float]]]:
    """(cycle, unwrapped heartbeat, the request time of the cycle before it) for the first record
    of ``cycles`` (heartbeat 0) and for every later one that brought a newer heartbeat: the program
    loop count, unwrapped (mod 65536) from the first record; records without a new loop skipped."""
    last_raw: Optional[int] = None
    k = 0
    prev_request: Optional[float] = None
    for c in cycles:
        fb = c.feedback
        if fb is None:
            continue
        if last_raw is None:
            last_raw = fb.heartbeat
            yield c, 0, None
        else:
            step = (fb.heartbeat - last_raw) % 65536
            if step:
                k += step
                last_raw = fb.heartbeat
                yield c, k, prev_request
        prev_request = c.request


def heartbeat_brackets(cycles: Iterable[Cycle]) -> List[Tuple[int, float, float]]:
    """(unwrapped heartbeat, earliest, latest) for every heartbeat seen first in ``cycles``: the
    program loop that wrote it ran after the request of the last cycle with an older heartbeat
    (earliest) and before the reply that brought it arrived (latest). Heartbeats are unwrapped
    (mod 65536) from the first record; a gap in the records (no reply) widens the bracket."""
    return [(k, prev if prev is not None else c.request, c.arrival if c.arrival is not None else c.time)
            for c, k, prev in new_loops(cycles) if k > 0]


def heartbeat_samples(cycles: Iterable[Cycle]) -> List[Tuple[float, int]]:
    """(request time, unwrapped heartbeat) for EVERY record of ``cycles`` (the loop count the card
    showed when the master asked; unwrapped mod 65536 from the first record): what
    :func:`~vr_driver.commission.analysis.loop_spread` reads -- a record that brought no new loop
    says as much as one that did."""
    out: List[Tuple[float, int]] = []
    last: Optional[int] = None
    k = 0
    for c in cycles:
        fb = c.feedback
        if fb is None:
            continue
        if last is not None:
            k += (fb.heartbeat - last) % 65536
        last = fb.heartbeat
        out.append((c.request, k))
    return out
