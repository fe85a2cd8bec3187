"""The virtual I/O island: a DP slave (station 8, ident 0x0F1A, GSD ``VRIO0F1A.gsd``, 2 bytes in /
2 bytes out, Chk_Cfg ``11 21`` = modules "16 DI", "16 DO") with a simulated gripper and part sensor.
ROS-free.

Process image (the signal map ``config/io_island_signals.yaml`` names exactly these):

- output byte 0 bit 0 ``gripper_close``: the valve; 1 closes the gripper;
- input byte 0 bit 0 ``gripper_closed``: follows ``gripper_close`` :data:`GRIPPER_DELAY` (0.3 s)
  later (a command that does not last that long never shows);
- input byte 0 bit 1 ``part_present``: set by :meth:`IslandProgram.set_part_present` (tests, the
  node's ``~set_part_present`` service).

Outside Data_Exchange the island acts on its safe outputs (all 0: the gripper opens): the DP slave
replaces its outputs by the safe image when it leaves Data_Exchange -- the DP watchdog expired (the
master fell silent) or the master re-parameterised it -- and :class:`IslandProgram` takes no output
image as a command unless the slave is in Data_Exchange.

:class:`VirtualIoIsland` serves the slave on its own pty (:class:`~vr_driver.controller.pty_link.SimPort`)
with the program loop in a thread; on the virtual line the hub (:mod:`pyprofibus_vendor.line`)
joins its pty with the controller's. ``python3 -m vr_driver.controller.io_island`` runs it from the shell
(:func:`main`); the ROS node is ``virtual_io_island`` (:mod:`vr_driver.ros.io_island`).
"""
from __future__ import annotations

import logging
import sys
import threading
import time
from typing import IO, Callable, Optional, Sequence, Union

from pyprofibus_vendor.dp_slave import DpSlave, SlaveServer, SlaveState
from pyprofibus_vendor.phy import Link

from .pty_link import SimPort
from .simulator import Simulator, int_option, parse_simulator_args, positive_option, run_simulator, simulator_parser

__all__ = ["ISLAND_ADDRESS", "ISLAND_IDENT", "ISLAND_CFG", "ISLAND_GSD", "GRIPPER_DELAY", "island_slave",
           "IslandProgram", "VirtualIoIsland", "main"]

log = logging.getLogger(__name__)

Clock = Callable[[], float]

ISLAND_ADDRESS = 8
ISLAND_IDENT = 0x0F1A
ISLAND_CFG = bytes([0x11, 0x21])          # "16 DI", "16 DO" of VRIO0F1A.gsd: 2 bytes in, 2 out
ISLAND_GSD = "VRIO0F1A.gsd"
GRIPPER_DELAY = 0.3                        # s from gripper_close to gripper_closed
DEFAULT_LOOP_PERIOD = 0.01


def island_slave(address: int = ISLAND_ADDRESS, clock: Clock = time.monotonic) -> DpSlave:
    """The island's DP slave (safe outputs: all 0)."""
    return DpSlave(address, ISLAND_IDENT, ISLAND_CFG, clock=clock)


class IslandProgram:
    """The island's application, stepped: :meth:`step` (``now`` injected) checks the DP watchdog,
    takes the valve command from the output image (only in Data_Exchange), moves the gripper and
    writes the input image. Thread-safe: :meth:`set_part_present` may be called from anywhere."""

    def __init__(self, slave: DpSlave, delay: float = GRIPPER_DELAY) -> None:
        self.slave = slave
        self.delay = delay
        self.command = 0                  # gripper_close as the island acts on it
        self.outputs = bytes(slave.safe_outputs)   # the output image the island acts on (safe
        #                                            outside Data_Exchange)
        self.command_since: Optional[float] = None
        self.closed = 0                   # gripper_closed
        self._part_present = 0
        self._lock = threading.Lock()

    def set_part_present(self, present: bool) -> None:
        with self._lock:
            self._part_present = 1 if present else 0
        self._write_inputs()

    @property
    def part_present(self) -> int:
        return self._part_present

    def step(self, now: float) -> bytes:
        """One program loop; returns the input image written."""
        self.slave.step(now)              # the DP watchdog: outputs safe when the master is silent
        outputs = self.slave.outputs if self.slave.state is SlaveState.DATA_EXCH else self.slave.safe_outputs
        self.outputs = bytes(outputs)
        command = outputs[0] & 1
        if command != self.command or self.command_since is None:
            if command != self.command:
                log.info("island: gripper_close %d", command)
            self.command, self.command_since = command, now
        if self.closed != self.command and now - self.command_since >= self.delay - 1e-9:   # float times
            self.closed = self.command
        return self._write_inputs()

    def _write_inputs(self) -> bytes:
        with self._lock:
            image = bytes([self.closed | self._part_present << 1, 0])
        self.slave.inputs = image
        return image


class VirtualIoIsland(Simulator):
    """The virtual I/O island: DP slave + program loop, on its own port (see
    :class:`~vr_driver.controller.pty_link.SimPort`: ``link`` None creates a pty, symlinked at
    ``pty_link``; a string serves that device; a Link is used as it is). :meth:`step` runs one
    program loop by hand (stepped tests; do not mix with :meth:`start`)."""

    def __init__(self, link: Union[None, str, Link] = None, *, address: int = ISLAND_ADDRESS,
                 baud: int = 19200, pty_link: Optional[str] = None,
                 loop_period: float = DEFAULT_LOOP_PERIOD, clock: Clock = time.monotonic) -> None:
        self.address = int_option(address, "addr", 0, 125)
        self.loop_period = positive_option(loop_period, "loop_period")
        self.clock = clock
        self.slave = island_slave(self.address, clock)
        self.program = IslandProgram(self.slave)
        self.port = SimPort(link, int_option(baud, "baud", 9600, 12_000_000), pty_link or None)
        self.server = SlaveServer(self.port.link, self.slave, clock=clock)
        super().__init__()

    @property
    def server_error(self) -> Optional[BaseException]:
        return self.server.error

    def set_part_present(self, present: bool) -> None:
        log.info("island: part_present %d", 1 if present else 0)
        self.program.set_part_present(present)

    def step(self, now: Optional[float] = None) -> bytes:
        return self.program.step(self.clock() if now is None else now)

    def start(self) -> "VirtualIoIsland":
        if self._thread is None:
            self._stop.clear()
            self.server.start()
            self._thread = threading.Thread(target=self._run, name="io-island", daemon=True)
            self._thread.start()
            log.info("virtual I/O island: DP slave %d (ident 0x%04X) on %s", self.address, ISLAND_IDENT,
                     self.device_path or self.port.link)
        return self

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                self.step()
            except Exception as exc:  # noqa: BLE001 - record, report, end the loop
                self.error = exc
                log.exception("island program loop failed")
                return
            self._stop.wait(self.loop_period)

    def _close(self) -> None:
        self.server.stop()
        self.port.close()


def main(argv: Optional[Sequence[str]] = None, stdout: Optional[IO[str]] = None) -> int:
    p = simulator_parser("io_island", "Virtual I/O island: a PROFIBUS-DP slave (ident 0x0F1A, 2 bytes in / "
                         "2 out, GSD VRIO0F1A.gsd) with a simulated gripper. Without --device it creates a pty "
                         "pair; the first line on stdout is the device path. Stops cleanly on SIGINT / SIGTERM.")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--pty-link", metavar="PATH", help="symlink the pty's device end at PATH (removed on exit)")
    where.add_argument("--device", metavar="DEV", help="serve an existing serial device")
    p.add_argument("--addr", type=int, default=ISLAND_ADDRESS, help="DP slave address (default 8)")
    p.add_argument("--baud", type=int, default=19200, help="DP bit rate (default 19200)")
    p.add_argument("--part-present", action="store_true", help="start with a part present")
    args = parse_simulator_args(p, argv)
    out = stdout if stdout is not None else sys.stdout
    def make() -> VirtualIoIsland:
        island = VirtualIoIsland(args.device, address=args.addr, baud=args.baud, pty_link=args.pty_link)
        island.set_part_present(args.part_present)
        return island.start()
    return run_simulator(p.prog, make, out)


if __name__ == "__main__":
    sys.exit(main())
