"""Shared by the pty tests of the virtual controller (v1 test_controller_sim_pty.py, v2
test_controller_v2_pty.py): our DpMaster on a link, run at a fixed cycle in its own thread. A
subclass sets up its state, then calls :meth:`start`, and does its per-cycle work in
``_on_cycle`` under ``self.cond``; the test waits on conditions with deadlines.

Link losses (the slave left Data_Exchange: the card's watchdog after a stall of this thread, a
missing reply, a new Set_Prm) are recorded in :attr:`ThreadedMaster.losses`. With ``idle_record``
the master does what the driver's link supervisor does (exactly once across a reset,
doc/controller_program.md §4 rule 10): the slave's outputs fall back to the idle record the moment
it leaves Data_Exchange, so the first Data_Exchange of the next session carries it and never the
command of before; the subclass hears of the loss in :meth:`_on_link_lost` (the bus thread, inside
the cycle, before the next Data_Exchange).

:attr:`cycles` counts the bus cycles: a test can count its deadlines in them, so that a machine too
busy to run this thread on time stretches the deadlines with it. :attr:`max_gap` is the longest
time between the ends of two cycles (a stall of this thread)."""
from __future__ import annotations

import threading
import time
from typing import Callable, List, Optional, Tuple

from pyprofibus_vendor.config import ROBOT_IDENT
from pyprofibus_vendor.dp_master import DpMaster, MasterSlaveState, SlaveHandle, SlaveSpec
from pyprofibus_vendor.phy_serial import SerialLink

_CONNECTED = (MasterSlaveState.DATA_EXCHANGE, MasterSlaveState.DX_DIAG)


class ThreadedMaster:
    def __init__(self, path, baud: int, cfg: bytes, watchdog: float, cycle: float,
                 idle_record: Optional[bytes] = None) -> None:
        self.link = SerialLink(path, baud) if isinstance(path, str) else path
        self.master = DpMaster(self.link, 2, baud, reply_timeout_floor=0.2,
                               on_state_change=self._on_state_change)
        self.handle = self.master.add_slave(SlaveSpec(4, ROBOT_IDENT, cfg, watchdog=watchdog))
        self.idle_record = idle_record
        if idle_record is not None:
            self.handle.outputs = idle_record
        self.cycle = cycle
        self.cond = threading.Condition()
        self.stop_event = threading.Event()
        self.error: Optional[BaseException] = None
        self.losses: List[Tuple[float, str]] = []      # (time, the master's reason) per link loss
        self.cycles = 0                                # bus cycles run
        self.last_cycle_end: Optional[float] = None
        self.prev_cycle_end: Optional[float] = None    # the end of the cycle before the last one
        self.max_gap = 0.0
        self._thread: Optional[threading.Thread] = None

    def start(self, name: str) -> None:
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        try:
            self.master.run(self.cycle, self.stop_event, self._cycle_done)
        except BaseException as exc:  # noqa: BLE001 - reported by wait()
            self.error = exc
            with self.cond:
                self.cond.notify_all()

    def _cycle_done(self, master: DpMaster) -> None:
        self._on_cycle(master)
        now = time.monotonic()
        with self.cond:
            if self.last_cycle_end is not None:
                self.max_gap = max(self.max_gap, now - self.last_cycle_end)
            self.prev_cycle_end, self.last_cycle_end = self.last_cycle_end, now
            self.cycles += 1
            self.cond.notify_all()

    def _on_state_change(self, slave: SlaveHandle, old: MasterSlaveState, new: MasterSlaveState,
                         reason: str) -> None:
        if slave is not self.handle or old not in _CONNECTED or new in _CONNECTED:
            return
        if self.idle_record is not None:
            slave.outputs = self.idle_record
        with self.cond:
            self.losses.append((time.monotonic(), reason))
            self._on_link_lost(reason)
            self.cond.notify_all()

    def _on_link_lost(self, reason: str) -> None:
        """The slave left Data_Exchange (called under ``self.cond``, in the bus thread)."""

    def _on_cycle(self, master: DpMaster) -> None:  # pragma: no cover - subclasses define it
        raise NotImplementedError

    def wait(self, predicate: Callable[[], bool], timeout: float) -> bool:
        with self.cond:
            ok = self.cond.wait_for(lambda: self.error is not None or predicate(), timeout)
        if self.error is not None:
            raise self.error
        return ok

    def wait_cycles(self, predicate: Callable[[], bool], cycles: int, hang: float = 600.0) -> bool:
        """Wait until ``predicate()`` holds (True) or ``cycles`` more bus cycles have run (False).
        ``hang``: seconds after which a bus thread that stopped cycling altogether fails the wait."""
        with self.cond:
            end = self.cycles + cycles
            self.cond.wait_for(lambda: self.error is not None or predicate() or self.cycles >= end, hang)
            ok = predicate()
        if self.error is not None:
            raise self.error
        return ok

    def stop(self) -> None:
        self.stop_event.set()
        if self._thread is not None:
            self._thread.join(5.0)
        self.master.close()
