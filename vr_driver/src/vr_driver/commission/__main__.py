"""python3 -m vr_driver.commission: the same as ``rosrun vr_driver commission``."""
import sys

from .cli import main

sys.exit(main())
