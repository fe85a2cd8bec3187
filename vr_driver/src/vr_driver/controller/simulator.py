"""What the simulated DP stations share (the virtual G2, :mod:`vr_driver.controller.virtual_controller`;
the virtual I/O island, :mod:`vr_driver.controller.io_island`; the line hub,
:mod:`vr_driver.controller.line`): their errors, the checks of their numeric options, the
life-cycle of their background thread (:class:`Simulator`) and their command-line life
(:func:`simulator_parser`, :func:`parse_simulator_args`, :func:`run_simulator`, the exit codes).
ROS-free."""
from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading
from typing import IO, Any, Callable, Optional, Sequence

from pyprofibus_vendor.errors import PhyError

from .. import validate
from ..errors import VrDriverError

__all__ = ["EXIT_OK", "EXIT_FAILURE", "EXIT_USAGE", "EXIT_DEVICE", "SimError", "SimDeviceError", "Simulator",
           "positive_option", "int_option", "simulator_parser", "parse_simulator_args", "run_simulator"]

#: exit codes of the command line
EXIT_OK, EXIT_FAILURE, EXIT_USAGE, EXIT_DEVICE = 0, 1, 2, 3


class SimError(VrDriverError):
    """A bad virtual-controller option (the message names it), or its device cannot be served."""


class SimDeviceError(SimError):
    """The link / device / pty / symlink cannot be created or served."""


def positive_option(value: Any, name: str) -> float:
    """``value`` as a finite number > 0; SimError naming the option ``name`` otherwise."""
    return validate.number(value, lambda _: SimError("%s must be a finite number > 0, got %r" % (name, value)),
                           0.0, lo_open=True)


def int_option(value: Any, name: str, lo: int, hi: int) -> int:
    """``value`` as an integer in ``lo..hi`` (an integral number or its text); SimError naming the
    option ``name`` otherwise."""
    def fail(got: Optional[float]) -> SimError:
        if got is None:
            return SimError("%s must be an integer in %d..%d, got %r" % (name, lo, hi, value))
        return SimError("%s = %d is outside %d..%d" % (name, got, lo, hi))
    return validate.integer(value, fail, lo, hi, text=True, integral=True)



class Simulator:
    """The life-cycle the simulators share (VirtualController, VirtualIoIsland, LineHub): a
    background thread started by the subclass's ``start()`` (returning self) and watching
    ``self._stop``; :meth:`stop` ends it and then :meth:`_close` closes what the subclass opened;
    a context manager. The subclass calls ``Simulator.__init__`` and opens ``self.port`` (the
    :class:`~vr_driver.controller.pty_link.SimPort` a master connects to)."""

    port: Any      # a vr_driver.controller.pty_link.SimPort

    def __init__(self) -> None:
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None
        self.error: Optional[BaseException] = None     # what ended the thread, if anything did

    @property
    def device_path(self) -> str:
        """What a master opens (pty slave path or the device)."""
        return self.port.device_path

    @property
    def symlink(self) -> Optional[str]:
        return self.port.symlink

    def start(self) -> Any:
        raise NotImplementedError

    def _close(self) -> None:
        """Close what the simulator opened (after its thread ended)."""

    def request_stop(self) -> None:
        """Ask the threads to end, without waiting (safe from a signal handler / ROS shutdown hook,
        which may interrupt a thread holding a lock that :meth:`stop` needs)."""
        self._stop.set()

    def stop(self) -> None:
        """Stop the threads, close what this object opened (removes a pty symlink). Idempotent."""
        self._stop.set()
        thread, self._thread = self._thread, None
        if thread is not None:
            thread.join(5.0)
        self._close()

    def close(self) -> None:
        self.stop()

    def __enter__(self) -> Any:
        return self.start()

    def __exit__(self, *exc: Any) -> None:
        self.stop()


def _watch(sim: Any, stop: threading.Event, prog: str) -> int:
    """Wait for ``stop`` while ``sim``'s threads run; end early on their device or internal error."""
    while not stop.wait(0.2):
        if sim.server_error is not None:
            print("%s: device error: %s" % (prog, sim.server_error), file=sys.stderr)
            return EXIT_DEVICE
        if sim.error is not None:
            print("%s: internal error: %s" % (prog, sim.error), file=sys.stderr)
            return EXIT_FAILURE
    return EXIT_OK


def simulator_parser(module: str, description: str, internal_error: bool = True) -> argparse.ArgumentParser:
    """The command line every simulator starts from: ``python3 -m vr_driver.controller.<module>`` (an
    empty ``module``: ``python3 -m vr_driver.controller``, the virtual G2),
    its ``description``, :func:`run_simulator`'s exit statuses as the epilog (``internal_error``:
    its threads can end in EXIT_FAILURE) and ``-v`` (:func:`parse_simulator_args`)."""
    p = argparse.ArgumentParser(
        prog="python3 -m vr_driver.controller" + ("." + module if module else ""), description=description,
        epilog="exit status: %d stopped by a signal, %d bad option, %d device problem%s" % (
            EXIT_OK, EXIT_USAGE, EXIT_DEVICE, ", %d internal error" % EXIT_FAILURE if internal_error else ""))
    p.add_argument("-v", "--verbose", action="count", default=0, help="more log output on stderr")
    return p


def parse_simulator_args(parser: argparse.ArgumentParser, argv: Optional[Sequence[str]]) -> argparse.Namespace:
    """``argv`` parsed (argparse exits 2 on a bad option); the log on stderr at WARNING, INFO with
    ``-v``, DEBUG with ``-vv``."""
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING - 10 * min(2, args.verbose), stream=sys.stderr,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    return args


def run_simulator(prog: str, make: Callable[[], Any], out: IO[str],
                  serve: Optional[Callable[[Any, threading.Event, str], int]] = None,
                  usage: Optional[Callable[[], None]] = None) -> int:
    """The command-line life of a simulator (virtual controller, I/O island, line hub): SIGINT /
    SIGTERM stop it; ``make()`` builds and starts it (SimDeviceError -> EXIT_DEVICE, SimError ->
    ``usage()`` and EXIT_USAGE); its ``device_path`` is the first line on ``out``; ``serve(sim,
    stop, prog)`` (default: watch its threads' errors) runs until a signal and gives the exit status
    (a PhyError -> EXIT_DEVICE); ``sim.stop()`` and the old signal handlers always come back."""
    stop = threading.Event()
    old = {sig: signal.signal(sig, lambda *_: stop.set()) for sig in (signal.SIGINT, signal.SIGTERM)}
    sim: Any = None
    try:
        try:
            sim = make()
        except SimDeviceError as exc:
            print("%s: device error: %s" % (prog, exc), file=sys.stderr)
            return EXIT_DEVICE
        except SimError as exc:
            if usage is not None:
                usage()
            print("%s: error: %s" % (prog, exc), file=sys.stderr)
            return EXIT_USAGE
        print(sim.device_path, file=out, flush=True)
        try:
            return (serve or _watch)(sim, stop, prog)
        except PhyError as exc:
            print("%s: device error: %s" % (prog, exc), file=sys.stderr)
            return EXIT_DEVICE
    finally:
        if sim is not None:
            sim.stop()
        for sig, handler in old.items():
            signal.signal(sig, handler)
