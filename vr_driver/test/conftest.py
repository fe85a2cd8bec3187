"""Make vr_driver (and its sibling packages' Python code) importable from the source tree under plain
pytest; inside the catkin workspace the devel space provides the same modules."""
import os
import sys

_REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
for _pkg in ("vr_driver", "pyprofibus_vendor", "panasonic_vr006l_support"):
    _src = os.path.join(_REPO, _pkg, "src")
    if _src not in sys.path:
        sys.path.insert(0, _src)
