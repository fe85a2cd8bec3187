"""``python3 -m vr_driver.csr``: the csr_export command line (:mod:`vr_driver.csr.cli`)."""
import sys

from .cli import main

sys.exit(main(prog="python3 -m vr_driver.csr"))
