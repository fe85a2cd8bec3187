"""The virtual G2's entry point: ``python3 -m vr_driver.controller.program`` runs its command line
(:mod:`vr_driver.controller.cli`, ``--help``), and the names code outside this package has imported
from here since it was one module are here still. ROS-free.

Where each piece lives (doc/virtual_controller.md, doc/layout.md):

- :mod:`~vr_driver.controller.virtual_controller`: :class:`VirtualController` (the DP slave, the
  program loop in a thread, the simulated arm) and :func:`robot_slave`;
- :mod:`~vr_driver.controller.programs`: which program runs which protocol; the programs themselves
  in :mod:`~vr_driver.controller.program_v1` (the thesis' handshake), ``program_v2``, ``program_v3``
  and the link side they share in :mod:`~vr_driver.controller.session`;
- :mod:`~vr_driver.controller.options`: :class:`SimOptions`, :data:`ASSUMPTIONS`, :class:`LoopTiming`;
- :mod:`~vr_driver.controller.pty_link`: :class:`SimPort`, the link's lock, ``auto`` links
  (:func:`auto_pty_link`, :func:`resolve_link`);
- :mod:`~vr_driver.controller.simulator`: :class:`Simulator`, :func:`run_simulator`, the errors and
  the exit codes the simulators share.

New code imports from those modules."""
from __future__ import annotations

import sys

from .cli import _parser, main  # noqa: F401  (_parser: tests read its defaults)
from .options import (ASSUMPTIONS, DEFAULT_ADDRESS, DEFAULT_BAUD, DEFAULT_BRAKE_TIME, DEFAULT_LOOP_PERIOD, PARAM_NAMES,
                      PROTOCOLS, LoopTiming, SimOptions, true_kinematics, true_zero_offsets)
from .program_v1 import ControllerProgramV1
from .pty_link import AUTO_LINK, SimPort, auto_pty_link, resolve_link
from .simulator import (EXIT_DEVICE, EXIT_FAILURE, EXIT_OK, EXIT_USAGE, SimDeviceError, SimError, Simulator,
                        run_simulator)
from .virtual_controller import FAULTS, VirtualController, robot_slave

#: v1's program under the name it had before the programs were named by their protocol
ControllerProgram = ControllerProgramV1

__all__ = [
    "ASSUMPTIONS", "AUTO_LINK", "DEFAULT_ADDRESS", "DEFAULT_BAUD", "DEFAULT_BRAKE_TIME", "DEFAULT_LOOP_PERIOD",
    "EXIT_DEVICE", "EXIT_FAILURE", "EXIT_OK", "EXIT_USAGE", "FAULTS", "LoopTiming", "PARAM_NAMES", "PROTOCOLS",
    "SimError", "SimDeviceError", "SimOptions", "ControllerProgram", "ControllerProgramV1", "Simulator",
    "VirtualController", "SimPort", "auto_pty_link", "resolve_link", "robot_slave", "main", "run_simulator",
    "true_kinematics", "true_zero_offsets",
]

if __name__ == "__main__":
    sys.exit(main())
