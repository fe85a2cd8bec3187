"""A part of the driver core that runs one named daemon thread of its own (the bus loop, the
planning thread): started once by :meth:`DriverCore.start`, joined at shutdown. ROS-free."""
from __future__ import annotations

import threading
from typing import Optional

__all__ = ["OwnThread"]


class OwnThread:
    """Runs :meth:`_run` in a daemon thread called :attr:`thread_name` (set by the subclass)."""

    thread_name = ""
    _thread: Optional[threading.Thread] = None

    @property
    def thread(self) -> Optional[threading.Thread]:
        """The thread while it runs (None: not started, or joined)."""
        return self._thread

    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name=self.thread_name, daemon=True)
        self._thread.start()

    def join(self, timeout: float) -> None:
        if self._thread is not None:
            self._thread.join(timeout)
            self._thread = None

    def _run(self) -> None:
        raise NotImplementedError
