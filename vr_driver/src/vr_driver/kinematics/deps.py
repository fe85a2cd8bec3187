"""The optional libraries of collision-aware planning, imported in one place so that a machine
without them gets one clear :class:`~vr_driver.errors.MissingDependency` (naming the PyPI package and
scripts/setup) instead of an ImportError deep inside a node.

    pin = require("pinocchio")          # the module, or MissingDependency
    missing = missing_dependencies()    # [(package, reason)] of the ones that cannot be imported

The modules stay optional for everything else: nothing here is imported by vr_driver's other
modules at import time."""
from __future__ import annotations

import importlib
from types import ModuleType
from typing import Dict, List, Tuple

from vr_driver.errors import MissingDependency

# import name -> PyPI name (pinned in scripts/setup)
PACKAGES: Dict[str, str] = {
    "pinocchio": "pin",
    "coal": "coal",
    "ompl": "ompl",
    "toppra": "toppra",
}

_FEATURE = "collision-aware planning (vr_driver.kinematics.collision / planner)"


def require(module: str, feature: str = _FEATURE) -> ModuleType:
    """Import ``module`` (one of :data:`PACKAGES`, or any other import name) or raise
    MissingDependency naming its PyPI package, the feature and the reason."""
    package = PACKAGES.get(module, module)
    try:
        return importlib.import_module(module)
    except ImportError as exc:  # absent, or a wheel that does not load (wrong Python, ABI)
        reason = "%s: %s" % (type(exc).__name__, exc)
        inner = (getattr(exc, "name", None) or "").split(".")[0]
        if inner and inner != module.split(".")[0]:     # the module is there, a library it imports is not
            reason = "needed by %s; %s" % (module, reason)
            module, package = inner, PACKAGES.get(inner, inner)
        raise MissingDependency(package, module, feature, reason) from exc


def missing_dependencies(modules: Tuple[str, ...] = tuple(PACKAGES)) -> List[Tuple[str, str]]:
    """[(package, reason)] for each of ``modules`` that cannot be imported; [] when all can."""
    out = []
    for module in modules:
        try:
            require(module)
        except MissingDependency as exc:
            out.append((exc.package, str(exc)))
    return out
