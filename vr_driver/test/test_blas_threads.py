"""Every process of the driver runs numpy's BLAS on one thread.

OpenBLAS (Debian's numpy) starts a thread per core that spins while it waits for work. With the
driver's processes side by side on two cores they took the CPU from the bus and the virtual arm: a
2 s calibration fit ran over 500 s beside two busy loops. `import vr_driver` (every node's first
import) and the support package's modules set OPENBLAS_NUM_THREADS=1 before numpy loads; a value the
user set is kept. Checked in a fresh interpreter against the library numpy actually loaded.
"""
import os
import subprocess
import sys

import pytest

PROBE = r"""
import ctypes, sys
import {first}
import numpy
lib = None
with open("/proc/self/maps") as maps:
    for line in maps:
        path = line.split()[-1]
        if "blas" in path.rsplit("/", 1)[-1] and path.endswith((".so", ".so.0", ".so.3")) or "openblas" in path:
            try:
                candidate = ctypes.CDLL(path)
                candidate.openblas_get_num_threads
            except (OSError, AttributeError):
                continue
            lib = candidate
            break
print(-1 if lib is None else lib.openblas_get_num_threads())
"""


def _threads(first, **env_extra):
    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}
    env.update(env_extra)
    out = subprocess.run([sys.executable, "-c", PROBE.format(first=first)], env=env,
                         capture_output=True, text=True, timeout=60, check=True).stdout
    return int(out.split()[-1])


def _openblas_or_skip():
    n = _threads("os")   # numpy alone, nothing set: OpenBLAS's own default (one per core)
    if n < 0:
        pytest.skip("numpy's BLAS here is not OpenBLAS")
    return n


@pytest.mark.parametrize("first", ["vr_driver", "panasonic_vr006l_support"])
def test_one_blas_thread_after_the_packages_import(first):
    default = _openblas_or_skip()
    assert _threads(first) == 1, "OpenBLAS default here: %d threads" % default


def test_a_value_the_user_set_is_kept():
    _openblas_or_skip()
    assert _threads("vr_driver", OPENBLAS_NUM_THREADS="2") == 2
