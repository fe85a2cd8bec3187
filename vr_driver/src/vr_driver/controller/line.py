"""The virtual RS-485 line: a hub that joins the ptys of several simulated DP stations into one
multi-drop line. ROS-free.

RS-485 is multi-drop: every station hears every telegram and only the addressed one answers. Each
simulated station (the virtual controller, the virtual I/O island) serves its own pty in its own
process, so that one can be killed on its own; :class:`LineHub` opens every station's pty as a
client would, creates one more pty for the master (:attr:`LineHub.device_path`, optionally
symlinked at ``pty_link``) and copies bytes:

- master -> every connected station (each station's DP slave ignores telegrams not for it);
- any station -> master.

A station whose pty fails (its process died: EIO / end of file) is dropped at once -- the master
then sees its telegrams unanswered, as on a line whose station was unplugged -- and its path is
tried again every ``reopen_period`` seconds, so a restarted station (same ``--pty-link`` path)
joins the line again. A path whose ``<path>.lock`` names a process that is gone (a station killed
before it could remove its symlink) is not opened: its pty number may already belong to someone else.

``baud`` (optional) paces the line: each chunk is delivered only after its bytes would have been
on a real line at that bit rate (11 bits per character, one direction at a time), so cycle rates
measured through the hub show the bus time. Without it the ptys move bytes as fast as they can.

``rate`` (optional) is the stations' bit rate: the line answers only a master whose port is set to it
(the speed the master set on its pty, :func:`~vr_driver.controller.line_rate.tty_speed`). Bytes
between a master at another rate and the stations pass through a UART's view of the wire
(:func:`~vr_driver.controller.line_rate.resample`): the stations receive a few wrong characters or
none and do not answer, as on a real line. Without it the line carries any rate's bytes intact.

``adapter`` (optional, an :class:`~vr_driver.controller.adapter_model.AdapterBehaviour`) puts the
USB-RS-485 adapter's behaviours on the master's side: a latency timer (replies handed over in
bursts), the echo of the master's own transmission, a slow turnaround that loses a prompt reply's
first bytes (:mod:`~vr_driver.controller.adapter_model`).

``python3 -m vr_driver.controller.line [--pty-link PATH] [--baud B] [--rate R] [--latency-ms MS] [--echo]
[--turnaround-ms MS] STATION_PATH...`` runs it from the
shell (:func:`main`; the first line on stdout is the master's device path).
"""
from __future__ import annotations

import heapq
import logging
import os
import select
import sys
import threading
import time
import tty
from dataclasses import dataclass
from typing import IO, Any, Callable, List, Optional, Sequence, Tuple

from pyprofibus_vendor.errors import PhyError
from pyprofibus_vendor.phy_serial import FdLink

from .adapter_model import AdapterBehaviour, AdapterModel
from .line_rate import resample, tty_speed
from .pty_link import SimPort, pid_alive
from .simulator import EXIT_OK, SimError, Simulator, parse_simulator_args, run_simulator, simulator_parser

__all__ = ["LineCounters", "LineHub", "add_adapter_args", "adapter_from_args", "main"]

log = logging.getLogger(__name__)

Clock = Callable[[], float]


@dataclass
class LineCounters:
    to_stations: int = 0          # bytes from the master copied to the stations (per station)
    to_master: int = 0            # bytes from the stations copied to the master
    station_opens: int = 0
    station_drops: int = 0
    off_rate_chunks: int = 0      # chunks carried between a master and stations at different rates


class _Station:
    def __init__(self, path: str) -> None:
        self.path = path
        self.link: Optional[FdLink] = None
        self.next_open = 0.0
        self.why = "not opened yet"


def _lock_owner_gone(path: str) -> bool:
    """``path.lock`` names a process that no longer runs (its symlink is stale)."""
    try:
        with open(path + ".lock") as f:
            text = f.read().strip()
    except OSError:
        return False
    return text.isdigit() and not pid_alive(int(text))


class LineHub(Simulator):
    """See the module docstring. :meth:`start` serves in a thread; :meth:`serve` in the caller's."""

    def __init__(self, stations: Sequence[str], *, pty_link: Optional[str] = None, baud: Optional[int] = None,
                 reopen_period: float = 0.2, clock: Clock = time.monotonic, rate: Optional[int] = None,
                 adapter: Optional[AdapterBehaviour] = None) -> None:
        if not stations:
            raise SimError("the line needs at least one station path")
        for name, value in (("baud", baud), ("rate", rate)):
            if value is not None and not 9600 <= value <= 12_000_000:
                raise SimError("%s %r outside 9600..12000000" % (name, value))
        self.stations = [_Station(p) for p in stations]
        self.baud = baud
        self.rate = rate
        self.reopen_period = reopen_period
        self.clock = clock
        self.counters = LineCounters()
        self.port = SimPort(None, baud or 19200, pty_link)
        self.master = self.port.link
        self._queue: List[Tuple[float, int, int, bytes]] = []     # (due, seq, target (-1 master), bytes)
        self._seq = 0
        self._line_free = 0.0
        # the USB adapter on the master's side (adapter_model.py), None: a perfect one
        self.adapter = AdapterModel(adapter) if adapter is not None and adapter.active else None
        super().__init__()

    def connected(self) -> List[str]:
        """The station paths joined to the line now."""
        return [s.path for s in self.stations if s.link is not None]

    # ------------------------------------------------------------------------ stations
    def _open(self, st: _Station, now: float) -> None:
        st.next_open = now + self.reopen_period
        if not os.path.exists(st.path) or _lock_owner_gone(st.path):
            st.why = "no station at %s" % st.path
            return
        try:
            fd = os.open(st.path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        except OSError as exc:
            st.why = "cannot open %s: %s" % (st.path, exc)
            return
        try:
            tty.setraw(fd)
        except Exception:  # noqa: BLE001 - not a tty (a FIFO in tests): raw bytes anyway
            pass
        st.link = FdLink(fd, owns_fd=True, name="station(%s)" % st.path)
        st.link.flush_input()
        self.counters.station_opens += 1
        log.info("line: station %s joined", st.path)

    def _drop(self, st: _Station, why: str, now: float) -> None:
        if st.link is not None:
            st.link.close()
            st.link = None
            self.counters.station_drops += 1
            log.warning("line: station %s dropped (%s); retrying every %.2g s", st.path, why, self.reopen_period)
        st.why = why
        st.next_open = now + self.reopen_period

    # ------------------------------------------------------------------------ the loop
    def master_rate(self) -> Optional[int]:
        """The bit rate the master set on its end of the line (None: not readable)."""
        pty = self.port.pty
        return tty_speed(pty.keep_fd if pty is not None and pty.keep_fd >= 0 else self.master.fd)

    def _at_rates(self, data: bytes, to_master: bool) -> bytes:
        """``data`` as received across the line's rate and the master's (unchanged when they agree)."""
        theirs = self.master_rate()
        if self.rate is None or theirs is None or theirs == self.rate:
            return data
        self.counters.off_rate_chunks += 1
        return resample(data, self.rate, theirs) if to_master else resample(data, theirs, self.rate)

    def _deliver(self, target: int, data: bytes, now: float) -> None:
        if target < 0:
            if self.adapter is not None:
                data = self.adapter.hold(data, now)
            if data:
                self.master.send(data)
                self.counters.to_master += len(data)
            return
        for i, st in enumerate(self.stations):
            if st.link is None or (target != len(self.stations) and target != i):
                continue
            try:
                st.link.send(data)
                self.counters.to_stations += len(data)
            except PhyError as exc:
                self._drop(st, str(exc), now)

    def _forward(self, target: int, data: bytes, now: float, sent: Optional[bytes] = None) -> None:
        """``data`` onto the line for ``target`` (-1: the master). ``sent``: what the master wrote, when
        the line's rate made the wire's bytes differ from it (its adapter echoes what it sent)."""
        char = 11.0 / self.baud if self.baud is not None else 0.0
        start = max(now, self._line_free) if self.baud is not None else now
        end = start + len(data) * char
        if self.baud is not None:
            self._line_free = end
        adapter = self.adapter
        if adapter is not None:
            if target < 0:
                data = adapter.heard(data, start, char)
            else:
                echo = adapter.sent(data if sent is None else sent, end)
                if echo:
                    self._queue_at(end, -1, echo, now)
        if data:
            self._queue_at(end, target, data, now)

    def _queue_at(self, due: float, target: int, data: bytes, now: float) -> None:
        if due <= now and not self._queue:
            return self._deliver(target, data, now)
        self._seq += 1
        heapq.heappush(self._queue, (due, self._seq, target, data))

    def step(self, timeout: float) -> None:
        """Wait up to ``timeout`` for bytes, copy them; reopen stations that are due."""
        now = self.clock()
        for st in self.stations:
            if st.link is None and now >= st.next_open:
                self._open(st, now)
        while self._queue and self._queue[0][0] <= now:
            _, _, target, data = heapq.heappop(self._queue)
            self._deliver(target, data, now)
        if self.adapter is not None:
            burst = self.adapter.due(now)
            if burst:
                self.master.send(burst)
                self.counters.to_master += len(burst)
            due = self.adapter.next_due()
            if due is not None:
                timeout = min(timeout, max(0.0, due - now))
        if self._queue:
            timeout = min(timeout, max(0.0, self._queue[0][0] - now))
        fds = {self.master.fd: None}
        fds.update({st.link.fd: st for st in self.stations if st.link is not None})
        ready, _, _ = select.select(list(fds), [], [], timeout)
        now = self.clock()
        for fd in ready:
            st = fds[fd]
            if st is None:
                raw = self.master.recv(4096, 0.0)       # PhyError: the hub's own pty failed
                data = self._at_rates(raw, to_master=False) if raw and self.rate is not None else raw
                if data:
                    self._forward(len(self.stations), data, now, sent=raw)
                continue
            try:
                data = st.link.recv(4096, 0.0) if st.link is not None else b""
            except PhyError as exc:
                self._drop(st, str(exc), now)
                continue
            if data and self.rate is not None:
                data = self._at_rates(data, to_master=True)
            if data:
                self._forward(-1, data, now)

    def serve(self, stop: Optional[threading.Event] = None) -> None:
        stop = stop or self._stop
        while not stop.is_set():
            self.step(min(0.05, self.reopen_period))

    def start(self) -> "LineHub":
        def run() -> None:
            try:
                self.serve(self._stop)
            except Exception as exc:  # noqa: BLE001 - record, report
                self.error = exc
                log.exception("line hub stopped")
        if self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(target=run, name="line-hub", daemon=True)
            self._thread.start()
        return self

    def _close(self) -> None:
        for st in self.stations:
            if st.link is not None:
                st.link.close()
                st.link = None
        self.port.close()


def add_adapter_args(p: Any) -> None:
    """The adapter's options of the line's command line (and the bench's)."""
    p.add_argument("--latency-ms", type=float, default=0.0, metavar="MS",
                   help="the USB adapter's latency timer: replies reach the master in bursts (0: at once)")
    p.add_argument("--echo", action="store_true", help="the adapter echoes the master's transmission back to it")
    p.add_argument("--turnaround-ms", type=float, default=0.0, metavar="MS",
                   help="the adapter's receiver is deaf this long after sending (a prompt reply loses its "
                        "first bytes)")


def adapter_from_args(args: Any) -> Optional[AdapterBehaviour]:
    """The behaviour the options ask for (ValueError out of range), None for a perfect adapter."""
    b = AdapterBehaviour(latency_ms=args.latency_ms, echo=args.echo, turnaround_ms=args.turnaround_ms)
    return b if b.active else None


def main(argv: Optional[Sequence[str]] = None, stdout: Optional[IO[str]] = None) -> int:
    p = simulator_parser("line", "The virtual RS-485 line: joins the ptys of simulated DP stations (virtual "
                         "controller, virtual I/O island) into one multi-drop line. The first line on stdout is "
                         "the device path the master opens. Stops cleanly on SIGINT / SIGTERM.", internal_error=False)
    p.add_argument("stations", nargs="+", metavar="STATION_PATH", help="a station's pty (or its symlink)")
    p.add_argument("--pty-link", metavar="PATH", help="symlink the master's pty at PATH (removed on exit)")
    p.add_argument("--baud", type=int, help="pace the line at this bit rate (default: as fast as the ptys)")
    p.add_argument("--rate", type=int, help="the stations' bit rate: a master whose port is set to another rate "
                   "meets garbled characters and no reply, as on a wire (default: any rate's bytes pass)")
    add_adapter_args(p)
    args = parse_simulator_args(p, argv)
    try:
        adapter = adapter_from_args(args)
    except ValueError as exc:
        p.error(str(exc))
    out = stdout if stdout is not None else sys.stdout
    def serve(hub: LineHub, stop: threading.Event, prog: str) -> int:
        hub.serve(stop)                 # in the foreground (a PhyError: the runner's device error)
        return EXIT_OK
    return run_simulator(p.prog, lambda: LineHub(args.stations, pty_link=args.pty_link, baud=args.baud,
                                                         rate=args.rate, adapter=adapter),
                         out, serve)


if __name__ == "__main__":
    sys.exit(main())
