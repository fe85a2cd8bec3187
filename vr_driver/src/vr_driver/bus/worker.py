"""A worker process: a Python module run as a child with its end of a socket pair, its scheduling,
its exit watched and named, its stop. The bus process (:mod:`vr_driver.bus.process`) and the plan
action's planning process (:mod:`vr_driver.driver.planning.plan_process`) are both started, watched and
stopped here; it imports nothing of vr_driver.

The parent's side, :class:`WorkerProcess`::

    worker = WorkerProcess("vr_driver.bus.process", [FD], "bus process", new_session=True)
    worker.conn                  # our end: a multiprocessing Connection (the child's fd is FD)
    worker.exit_words()          # "still running" | "exit code 1" | "killed by SIGKILL"
    worker.stop(polite=lambda: channel.send(Close()))    # the message, then EOF, SIGTERM, SIGKILL
    worker.kill()                # SIGKILL at once (a plan cancelled: it holds nothing but copies)

- **Started** with :class:`subprocess.Popen` (a new interpreter, never a fork of the parent: a fork
  copies the parent's threads' locks, rospy's included, in whatever state they were), the parent's
  module path (``PYTHONPATH``: e.g. a source tree), stdin from /dev/null, and only its end of the
  socket pair passed (``pass_fds``). Both ends blocking, whatever ``socket.setdefaulttimeout()``
  says: rospy sets one (60 s), which makes new sockets non-blocking underneath, and the child's end
  shares the flag -- its recv raised BlockingIOError on a message not all there yet. The parent
  keeps no copy of the child's end: the child's death is the parent's EOF.
- **Its exit** in words (:func:`exit_words`: the exit code, or the signal that killed it by name).
- **Stopped** politely first (the caller's message, then our end closed: EOF), then SIGTERM, then
  SIGKILL, each after its grace; the process is always reaped and our end always closed.

The child's side: :func:`child_end` (its end of the socket, a Ctrl-C left to the parent),
:func:`end_with_parent` (ends the process when the parent's end closes, also while it computes),
:func:`child_scheduling` (niceness and real-time priority, in words). The scheduling helpers
(:func:`set_priority`, :func:`set_process_priority`, :func:`process_normal_scheduling`,
:func:`normal_scheduling`) are also used by the nodes, the commissioning tool and the benchmarks.
"""
from __future__ import annotations

import os
import select
import signal
import socket
import subprocess
import sys
import threading
from multiprocessing.connection import Connection
from typing import Callable, List, Optional, Sequence

__all__ = ["WorkerProcess", "WorkerStartError", "FD", "exit_words", "child_end", "end_with_parent",
           "child_scheduling", "set_priority", "set_process_priority", "process_normal_scheduling",
           "normal_scheduling"]

#: in a worker's arguments: replaced by the number of its end of the socket pair
FD = "{fd}"


class WorkerStartError(OSError):
    """The worker process could not be started (the words name the command and the reason)."""


def exit_words(returncode: Optional[int]) -> str:
    """How a process ended, in words: "still running" (None), "exit code N", "killed by SIGKILL"."""
    if returncode is None:
        return "still running"
    if returncode < 0:
        try:
            return "killed by %s" % signal.Signals(-returncode).name
        except ValueError:
            return "killed by signal %d" % -returncode
    return "exit code %d" % returncode


class WorkerProcess:
    """``python3 -m module *args`` as a child with its end of a new socket pair (``args``: FD in
    them is the child's fd), started at once; :attr:`conn` our end. ``what`` names it in words
    ("bus process"); ``new_session``: the child in a session of its own (no signal to the parent's
    process group reaches it). Raises :class:`WorkerStartError` when it cannot start (nothing is
    left open then)."""

    def __init__(self, module: str, args: Sequence[str] = (FD,), what: str = "worker process",
                 new_session: bool = False) -> None:
        self.module = module
        self.what = what
        ours, theirs = socket.socketpair()
        ours.setblocking(True)
        theirs.setblocking(True)
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(p for p in sys.path if p)   # the parent's modules
        fd = str(theirs.fileno())
        argv = [sys.executable, "-m", module] + [fd if a == FD else a for a in args]
        try:
            self.proc = subprocess.Popen(argv, pass_fds=(theirs.fileno(),), stdin=subprocess.DEVNULL, env=env,
                                         start_new_session=new_session)
        except OSError as exc:
            ours.close()
            raise WorkerStartError(exc.errno, "cannot start the %s (%s -m %s): %s"
                                   % (what, sys.executable, module, exc.strerror or exc)) from None
        finally:
            theirs.close()                   # the child's copy is its only one: its death is our EOF
        self.conn = Connection(ours.detach())

    @property
    def pid(self) -> int:
        return self.proc.pid

    def returncode(self) -> Optional[int]:
        """Its exit code (negative: the signal that killed it), None while it runs."""
        return self.proc.poll()

    @property
    def running(self) -> bool:
        return self.proc.poll() is None

    def exit_words(self) -> str:
        """How it ended, in words (:func:`exit_words`)."""
        return exit_words(self.proc.poll())

    def wait(self, timeout: Optional[float] = None) -> Optional[int]:
        """Its exit code once it ended, waiting at most ``timeout`` [s]; None when it still runs."""
        try:
            return self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            return None

    def reap(self, timeout: float = 5.0) -> str:
        """How it ended, once its end of the socket closed (it is ending): waits at most ``timeout``,
        then kills it ("its socket closed; it was stopped")."""
        if self.wait(timeout) is None:
            self.kill()
            return "its socket closed; it was stopped"
        return self.exit_words()

    def kill(self) -> None:
        """SIGKILL at once and reaped; our end closed."""
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait()
        self.conn.close()

    def stop(self, polite: Optional[Callable[[], None]] = None, grace: float = 1.0,
             term_grace: float = 1.0) -> str:
        """Stop it: ``polite()`` (e.g. a close message; an OSError from it is ignored: it is gone),
        our end closed (EOF), ``grace`` [s] to end; then SIGTERM and ``term_grace``; then SIGKILL.
        Returns how it ended, in words."""
        if polite is not None and not self.conn.closed:
            try:
                polite()
            except (OSError, ValueError):
                pass
        self.conn.close()
        for sig, wait in ((None, grace), (signal.SIGTERM, term_grace)):
            if sig is not None and self.proc.poll() is None:
                self.proc.send_signal(sig)
            if self.wait(wait) is not None:
                return self.exit_words()
        self.kill()
        return self.exit_words()


# ---------------------------------------------------------------------------------- the child's side
def child_end(fd: int) -> Connection:
    """The child's end of the socket (blocking); a Ctrl-C (roslaunch's SIGINT to the process
    group) is the parent's to act on: the child sees it end (a SIGTERM or SIGKILL still ends it)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    os.set_blocking(fd, True)
    return Connection(fd)


def end_with_parent(fd: int) -> None:
    """A daemon thread that ends the process when the parent's end of the socket closes -- also
    while the main thread computes and reads nothing."""
    def watch() -> None:
        poller = select.poll()
        poller.register(fd, select.POLLRDHUP)
        while True:
            for _fd, events in poller.poll():
                if events & (select.POLLRDHUP | select.POLLHUP | select.POLLERR | select.POLLNVAL):
                    os._exit(0)
    threading.Thread(target=watch, name="worker-parent", daemon=True).start()


def child_scheduling(priority: int = 0, nice: int = 0) -> str:
    """The calling process's scheduling: ``nice`` above its parent's (0: none), then SCHED_FIFO at
    ``priority`` where the system allows it (0: not asked); how it runs, in words (with the remedy
    when real-time priority was refused)."""
    if nice > 0:
        os.nice(nice)
        if priority <= 0:
            return "normal scheduling, nice +%d" % nice
    return set_priority(priority) + (", nice +%d" % nice if nice > 0 else "")


def set_priority(priority: int) -> str:
    """Ask for SCHED_FIFO at ``priority`` (0: do not ask); returns how the process is scheduled, in
    words (with the remedy when the system refused)."""
    if priority <= 0:
        return "normal scheduling (rt_priority 0)"
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (PermissionError, OSError, AttributeError) as exc:
        return ("normal scheduling: real-time priority %d refused (%s); allow it with `ulimit -r %d` "
                "(limits.conf rtprio) or `setcap cap_sys_nice+ep` on the Python binary, or start the "
                "driver under `chrt -f %d`" % (priority, getattr(exc, "strerror", None) or exc,
                                               priority, priority))
    return "SCHED_FIFO %d" % priority


def _other_threads(policy: int, priority: int, tasks: str) -> int:
    """``policy`` at ``priority`` for every thread of the process but the calling one (listed in
    ``tasks``); how many could not be set (a thread that ended meanwhile, or refused)."""
    me = threading.get_native_id()
    failed = 0
    try:
        tids: List[int] = [int(t) for t in os.listdir(tasks) if t.isdigit()]
    except OSError:
        return 0
    for tid in tids:
        if tid == me:
            continue
        try:
            os.sched_setscheduler(tid, policy, os.sched_param(priority))
        except (PermissionError, OSError):
            failed += 1
    return failed


def set_process_priority(priority: int, tasks: str = "/proc/self/task") -> str:
    """:func:`set_priority` for the calling thread, then the same policy for every other thread the
    process has already (on Linux the policy is a thread's: those started before -- rospy's, at
    init_node -- keep normal scheduling, and one of them holding the interpreter's lock while a
    CPU hog runs holds the real-time threads back with it: a virtual G2 at SCHED_FIFO 30 whose
    loop then ran late let the arm stop at a point whose next target was already in its card).
    Threads started later inherit the policy of the thread that starts them. Returns the words of
    :func:`set_priority`, with the threads that could not be raised."""
    words = set_priority(priority)
    if priority <= 0 or not words.startswith("SCHED_FIFO"):
        return words
    failed = _other_threads(os.SCHED_FIFO, priority, tasks)
    return words + ("" if not failed else " (%d of its other threads not raised)" % failed)


def process_normal_scheduling(tasks: str = "/proc/self/task") -> None:
    """Every thread of the process back at normal scheduling (:func:`normal_scheduling` for the
    calling one, the same for the others): what a process raised with :func:`set_process_priority`
    does before work that may spin -- a node's ROS shutdown (ros/support.py,
    virtual_hardware_priority). Leaving SCHED_FIFO needs no privilege."""
    normal_scheduling()
    _other_threads(os.SCHED_OTHER, 0, tasks)


def normal_scheduling() -> None:
    """The calling thread back at normal scheduling (SCHED_OTHER) -- on Linux the policy is a
    thread's, and a thread inherits the one of the thread that starts it; leaving SCHED_FIFO needs
    no privilege. Nothing where the system has no such call."""
    try:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    except (PermissionError, OSError, AttributeError):
        pass
