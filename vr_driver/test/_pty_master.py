"""Shared by the pty tests of the virtual controller (v1 test_controller_sim_pty.py, v2
test_controller_v2_pty.py): our DpMaster on a link, run at a fixed cycle in its own thread. A
subclass sets up its state, then calls :meth:`start`, and does its per-cycle work in
``_on_cycle`` under ``self.cond``; the test waits on conditions with deadlines."""
from __future__ import annotations

import threading
from typing import Callable, Optional

from pyprofibus_vendor.config import ROBOT_IDENT
from pyprofibus_vendor.dp_master import DpMaster, SlaveSpec
from pyprofibus_vendor.phy_serial import SerialLink


class ThreadedMaster:
    def __init__(self, path, baud: int, cfg: bytes, watchdog: float, cycle: float) -> None:
        self.link = SerialLink(path, baud) if isinstance(path, str) else path
        self.master = DpMaster(self.link, 2, baud, reply_timeout_floor=0.2)
        self.handle = self.master.add_slave(SlaveSpec(4, ROBOT_IDENT, cfg, watchdog=watchdog))
        self.cycle = cycle
        self.cond = threading.Condition()
        self.stop_event = threading.Event()
        self.error: Optional[BaseException] = None
        self._thread: Optional[threading.Thread] = None

    def start(self, name: str) -> None:
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        try:
            self.master.run(self.cycle, self.stop_event, self._on_cycle)
        except BaseException as exc:  # noqa: BLE001 - reported by wait()
            self.error = exc
            with self.cond:
                self.cond.notify_all()

    def _on_cycle(self, master: DpMaster) -> None:  # pragma: no cover - subclasses define it
        raise NotImplementedError

    def wait(self, predicate: Callable[[], bool], timeout: float) -> bool:
        with self.cond:
            ok = self.cond.wait_for(lambda: self.error is not None or predicate(), timeout)
        if self.error is not None:
            raise self.error
        return ok

    def stop(self) -> None:
        self.stop_event.set()
        if self._thread is not None:
            self._thread.join(5.0)
        self.master.close()
