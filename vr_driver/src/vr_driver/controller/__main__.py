"""``python3 -m vr_driver.controller``: the virtual G2's command line (:mod:`vr_driver.controller.cli`,
``--help``). ROS-free."""
import sys

from .cli import main

sys.exit(main())
