"""Bus configuration: read once, validated, into frozen dataclasses.

A configuration is a plain dict (from YAML, from an INI file, or from ROS parameters)::

    master_address: 2              # 0..125, not the address of any slave
    baud: 19200                    # one of STANDARD_BAUDRATES, supported by every slave's GSD
    cycle_rate_hz: 20.0            # optional, default 20
    retry_limit: 1                 # optional override (0..7)
    slot_time: 300                 # optional override, bit times (37..16383)
    phy: {type: serial, device: /dev/ttyUSB0}     # type serial | memory
    slaves:
      - name: vr006l
        address: 4                 # 0..125
        gsd: PAN06C6.gsd           # relative to the config file, else the package's gsd/ dir
        ident: 0x06C6              # optional: taken from the GSD; if both are given they must match
        modules: [4 Bytes In, ...] # GSD module names in Chk_Cfg order ...
        # cfg: "13 13 13 11 23 23 23 21"   # ... or raw Cfg bytes (hex string or list of ints)
        input_len: 14              # optional: derived from the modules; if given it must match
        output_len: 14
        watchdog_ms: 300           # 0 or null = watchdog off; default 300
        sync: false                # need Sync_Mode_supp / Freeze_Mode_supp in the GSD
        freeze: false
        group_mask: 0              # Group_Ident bits
        user_prm_data: ""          # default: the GSD's defaults

:meth:`BusConfig.from_dict` checks every value and raises
:class:`ConfigValueError` (a :class:`~pyprofibus_vendor.errors.ConfigError`) naming the key path,
e.g. ``slaves[0].address: 130 is outside 0..125``; unknown keys are errors too (typo protection).
:func:`load_config` reads ``.yaml``/``.yml`` or ``.ini``/``.conf`` files and adds the file name and
line to the message. The INI form uses sections ``[bus]``, ``[phy]`` and one ``[slave_<n>]`` per
slave (in file order), with the same key names; modules are listed as ``module_0``, ``module_1``,
... (as in pyprofibus' .conf) or as one comma-separated ``modules`` line.

Direction naming is PROFIBUS's: input = slave -> master, output = master -> slave.
"""
from __future__ import annotations

import ast
import configparser
import difflib
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import yaml

from . import _cli
from .errors import ConfigError, GsdError
from .gsd import (
    DP_MAX_USER_PRM_DATA_LEN,
    STANDARD_BAUDRATES,
    Gsd,
    baud_name,
    build_chk_cfg,
    build_user_prm_data,
    cfg_io_lengths,
    format_hex,
    load_gsd,
)

__all__ = [
    "ConfigValueError",
    "PhyConfig",
    "SlaveConfig",
    "BusConfig",
    "load_config",
    "find_gsd_file",
    "default_robot_config",
    "ROBOT_GSD_FILE",
    "ROBOT_IDENT",
    "ROBOT_MODULES",
    "PHY_TYPES",
]

#: The GSD file of the robot's PROFIBUS card, shipped in this package's gsd/ directory.
ROBOT_GSD_FILE = "PAN06C6.gsd"
#: Ident_Number of the YA-1NPEP1 card.
ROBOT_IDENT = 0x06C6
#: The project's default module list in Chk_Cfg order (Chk_Cfg 13 13 13 11 23 23 23 21):
#: 14 input bytes (controller -> PC) then 14 output bytes (PC -> controller).
ROBOT_MODULES: Tuple[str, ...] = (
    "4 Bytes In", "4 Bytes In", "4 Bytes In", "2 Bytes In",
    "4 Bytes Out", "4 Bytes Out", "4 Bytes Out", "2 Bytes Out",
)
PHY_TYPES: Tuple[str, ...] = ("serial", "memory")

_ADDRESS_RANGE = (0, 125)
_WATCHDOG_MAX_MS = 10 * 255 * 255          # 10 ms x WD_Fact_1 x WD_Fact_2
_DEFAULT_WATCHDOG_MS = 300
_DEFAULT_CYCLE_RATE_HZ = 20.0
_RETRY_RANGE = (0, 7)
_SLOT_TIME_RANGE = (37, 16383)              # bit times
_GSD_DIR_ENV = "PYPROFIBUS_VENDOR_GSD_DIR"

_MISSING = object()


class ConfigValueError(ConfigError):
    """A bad configuration value. ``key`` is the key path (``slaves[0].address``); ``source`` and
    ``line`` are set when the value came from a file. ``str(err)`` reads
    ``"<source>:<line>: <key>: <reason>"``."""

    def __init__(self, key: str, reason: str, source: Optional[str] = None,
                 line: Optional[int] = None) -> None:
        self.key = key
        self.reason = reason
        self.source = source
        self.line = line
        where = ""
        if source:
            where = "%s:%d: " % (source, line) if line else "%s: " % source
        super().__init__("%s%s%s" % (where, "%s: " % key if key else "", reason))

    def located(self, source: str, line: Optional[int]) -> "ConfigValueError":
        """The same error, with the file name and line added."""
        return ConfigValueError(self.key, self.reason, source, line)


# --------------------------------------------------------------------------------------------------
# Dataclasses
# --------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class PhyConfig:
    """How to reach the bus: ``type`` 'serial' (``device`` = path or pyserial URL) or 'memory'
    (in-process link; ``device`` is an optional channel name)."""

    type: str
    device: str
    baud: int


@dataclass(frozen=True)
class SlaveConfig:
    """One DP slave. ``cfg`` is the Chk_Cfg byte string; ``modules`` the GSD module names it was
    built from (empty when raw cfg bytes were given). ``watchdog_ms`` None = watchdog off
    (``dp.watchdog_factors(watchdog_ms / 1000)`` gives the Set_Prm factors)."""

    name: str
    address: int
    ident: int
    cfg: bytes
    input_len: int
    output_len: int
    modules: Tuple[str, ...] = ()
    gsd_path: Optional[str] = None
    watchdog_ms: Optional[int] = _DEFAULT_WATCHDOG_MS
    sync: bool = False
    freeze: bool = False
    group_mask: int = 0
    user_prm_data: bytes = b""
    gsd: Optional[Gsd] = field(default=None, compare=False, repr=False)

    def to_dict(self) -> Dict[str, Any]:
        """The dict form accepted by ``from_dict`` (modules or cfg, hex strings for bytes)."""
        out: Dict[str, Any] = {"name": self.name, "address": self.address, "ident": self.ident}
        if self.gsd_path is not None:
            out["gsd"] = self.gsd_path
        if self.modules:
            out["modules"] = list(self.modules)
        else:
            out["cfg"] = format_hex(self.cfg)
        out.update({"input_len": self.input_len, "output_len": self.output_len,
                    "watchdog_ms": self.watchdog_ms, "sync": self.sync, "freeze": self.freeze,
                    "group_mask": self.group_mask, "user_prm_data": format_hex(self.user_prm_data)})
        return out


@dataclass(frozen=True)
class BusConfig:
    """The whole bus: this master, the PHY, the slaves and the cycle settings.

    ``retry_limit`` / ``slot_time`` are None when the master should derive them from the baud rate.
    """

    master_address: int
    baud: int
    phy: PhyConfig
    slaves: Tuple[SlaveConfig, ...]
    cycle_rate_hz: float = _DEFAULT_CYCLE_RATE_HZ
    retry_limit: Optional[int] = None
    slot_time: Optional[int] = None

    _KEYS = ("master_address", "baud", "phy", "slaves", "cycle_rate_hz", "retry_limit", "slot_time")

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], base_dir: Optional[Union[str, "os.PathLike[str]"]] = None
                  ) -> "BusConfig":
        """Validate ``data`` and build the configuration.

        Relative GSD paths are resolved against ``base_dir`` (default: the current directory),
        then, for a bare file name, in the package's gsd/ directory. Raises ConfigValueError.
        """
        base = Path(base_dir) if base_dir is not None else Path.cwd()
        _check_mapping(data, "", cls._KEYS, required=("master_address", "baud", "phy", "slaves"))
        master = _int(data["master_address"], "master_address", *_ADDRESS_RANGE)
        baud = _int(data["baud"], "baud")
        if baud not in STANDARD_BAUDRATES:
            raise ConfigValueError("baud", "%d is not a PROFIBUS-DP bit rate (use one of %s)"
                                   % (baud, ", ".join(str(b) for b in STANDARD_BAUDRATES)))
        phy = _phy(data["phy"], baud)
        raw_slaves = data["slaves"]
        if not isinstance(raw_slaves, (list, tuple)):
            raise ConfigValueError("slaves", "expected a list of slaves, got %s" % _kind(raw_slaves))
        if not raw_slaves:
            raise ConfigValueError("slaves", "at least one slave is required")
        slaves = tuple(_slave(item, "slaves[%d]" % i, base) for i, item in enumerate(raw_slaves))
        _check_bus(master, baud, slaves)
        rate = data.get("cycle_rate_hz", _DEFAULT_CYCLE_RATE_HZ)
        rate = _DEFAULT_CYCLE_RATE_HZ if rate is None else _number(rate, "cycle_rate_hz")
        if not 0 < rate <= 1000:
            raise ConfigValueError("cycle_rate_hz", "%g is outside (0, 1000]" % rate)
        retry = _optional_int(data.get("retry_limit"), "retry_limit", *_RETRY_RANGE)
        slot = _optional_int(data.get("slot_time"), "slot_time", *_SLOT_TIME_RANGE)
        return cls(master_address=master, baud=baud, phy=phy, slaves=slaves,
                   cycle_rate_hz=float(rate), retry_limit=retry, slot_time=slot)

    def slave(self, key: Union[int, str]) -> SlaveConfig:
        """The slave with this address (int) or name (str)."""
        for slave in self.slaves:
            if slave.address == key if isinstance(key, int) else slave.name == key:
                return slave
        raise ConfigValueError("slaves", "no slave %r (have %s)"
                               % (key, ", ".join("%s@%d" % (s.name, s.address) for s in self.slaves)))

    def to_dict(self) -> Dict[str, Any]:
        """The dict form accepted by ``from_dict``."""
        return {
            "master_address": self.master_address,
            "baud": self.baud,
            "cycle_rate_hz": self.cycle_rate_hz,
            "retry_limit": self.retry_limit,
            "slot_time": self.slot_time,
            "phy": {"type": self.phy.type, "device": self.phy.device},
            "slaves": [s.to_dict() for s in self.slaves],
        }


# --------------------------------------------------------------------------------------------------
# Value checks (each raises ConfigValueError naming the key path)
# --------------------------------------------------------------------------------------------------

def _kind(value: Any) -> str:
    if value is None:
        return "nothing (null)"
    return "%s %r" % (type(value).__name__, value) if not isinstance(value, (dict, list)) \
        else type(value).__name__


def _join(path: str, key: str) -> str:
    return key if not path else "%s.%s" % (path, key)


def _check_mapping(data: Any, path: str, allowed: Sequence[str], required: Sequence[str] = ()) -> None:
    if not isinstance(data, Mapping):
        raise ConfigValueError(path or "(top level)", "expected a mapping of keys, got %s" % _kind(data))
    for key in data:
        if not isinstance(key, str) or key not in allowed:
            close = difflib.get_close_matches(str(key), allowed, n=1)
            raise ConfigValueError(_join(path, str(key)), "unknown key%s (allowed: %s)" % (
                " - did you mean %r?" % close[0] if close else "", ", ".join(allowed)))
    for key in required:
        if data.get(key) is None:
            raise ConfigValueError(_join(path, key), "required key is missing")


def _int(value: Any, path: str, lo: Optional[int] = None, hi: Optional[int] = None) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ConfigValueError(path, "expected an integer, got %s" % _kind(value))
    if lo is not None and hi is not None and not lo <= value <= hi:
        raise ConfigValueError(path, "%d is outside %d..%d" % (value, lo, hi))
    return value


def _optional_int(value: Any, path: str, lo: int, hi: int) -> Optional[int]:
    return None if value is None else _int(value, path, lo, hi)


def _number(value: Any, path: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigValueError(path, "expected a number, got %s" % _kind(value))
    return float(value)


def _bool(value: Any, path: str) -> bool:
    if not isinstance(value, bool):
        raise ConfigValueError(path, "expected true or false, got %s" % _kind(value))
    return value


def _str(value: Any, path: str) -> str:
    if not isinstance(value, str) or not value.strip():
        raise ConfigValueError(path, "expected a non-empty string, got %s" % _kind(value))
    return value.strip()


def _bytes(value: Any, path: str) -> bytes:
    """A list of ints 0..255, or a string of hex bytes ("13 13 11" / "0x13,0x13")."""
    if isinstance(value, str):
        items = [t for t in re.split(r"[\s,]+", value.strip()) if t]
        out = []
        for i, token in enumerate(items):
            if not re.match(r"(?:0[xX])?[0-9A-Fa-f]{1,2}\Z", token):
                raise ConfigValueError(path, "item %d: %r is not a hex byte (write e.g. \"13 23\" or "
                                             "\"0x13, 0x23\")" % (i, token))
            out.append(int(token, 16))
        return bytes(out)
    if isinstance(value, (list, tuple)):
        for i, item in enumerate(value):
            _int(item, "%s[%d]" % (path, i), 0, 255)
        return bytes(value)
    raise ConfigValueError(path, "expected a hex string or a list of bytes, got %s" % _kind(value))


# --------------------------------------------------------------------------------------------------
# Sections
# --------------------------------------------------------------------------------------------------

def _phy(data: Any, baud: int) -> PhyConfig:
    _check_mapping(data, "phy", ("type", "device", "baud"), required=("type",))
    kind = _str(data["type"], "phy.type")
    if kind not in PHY_TYPES:
        raise ConfigValueError("phy.type", "%r is not one of %s" % (kind, ", ".join(PHY_TYPES)))
    device = data.get("device")
    if kind == "serial":
        if device is None:
            raise ConfigValueError("phy.device", "required for a serial PHY (a device path such as "
                                                 "/dev/ttyUSB0 or a pyserial URL)")
        device = _str(device, "phy.device")
    else:
        device = "" if device is None else _str(device, "phy.device")
    if data.get("baud") is not None and _int(data["baud"], "phy.baud") != baud:
        raise ConfigValueError("phy.baud", "%d differs from baud = %d (give the bit rate once, "
                                           "at the top level)" % (data["baud"], baud))
    return PhyConfig(type=kind, device=device, baud=baud)


_SLAVE_KEYS = ("name", "address", "gsd", "ident", "modules", "cfg", "input_len", "output_len",
               "watchdog_ms", "sync", "freeze", "group_mask", "user_prm_data")


def _slave(data: Any, path: str, base: Path) -> SlaveConfig:
    _check_mapping(data, path, _SLAVE_KEYS, required=("address",))
    address = _int(data["address"], _join(path, "address"), *_ADDRESS_RANGE)
    name = "slave_%d" % address if data.get("name") is None else _str(data["name"], _join(path, "name"))

    gsd: Optional[Gsd] = None
    gsd_path: Optional[str] = None
    if data.get("gsd") is not None:
        key = _join(path, "gsd")
        gsd_path = _resolve_gsd(_str(data["gsd"], key), base, key)
        try:
            gsd = load_gsd(gsd_path)
        except GsdError as exc:
            raise ConfigValueError(key, str(exc)) from exc
    gsd_name = os.path.basename(gsd_path) if gsd_path else ""

    if data.get("ident") is not None:
        ident = _int(data["ident"], _join(path, "ident"), 0, 0xFFFF)
        if gsd is not None and ident != gsd.ident_number:
            raise ConfigValueError(_join(path, "ident"), "0x%04X does not match Ident_Number 0x%04X "
                                   "in %s" % (ident, gsd.ident_number, gsd_name))
    elif gsd is not None:
        ident = gsd.ident_number
    else:
        raise ConfigValueError(_join(path, "ident"), "required when no gsd is given")

    modules, cfg = _slave_cfg(data, path, gsd, gsd_name)
    in_len, out_len = cfg_io_lengths(cfg)
    for key, given, derived, what in (("input_len", data.get("input_len"), in_len, "input"),
                                      ("output_len", data.get("output_len"), out_len, "output")):
        if given is not None and _int(given, _join(path, key), 0, 244) != derived:
            raise ConfigValueError(_join(path, key), "%d does not match the %d %s bytes of the %s"
                                   % (given, derived, what, "modules" if modules else "cfg bytes"))

    watchdog = data.get("watchdog_ms", _DEFAULT_WATCHDOG_MS)
    if watchdog is not None:
        watchdog = _int(watchdog, _join(path, "watchdog_ms"), 0, _WATCHDOG_MAX_MS) or None
    sync = _bool(data.get("sync", False), _join(path, "sync"))
    freeze = _bool(data.get("freeze", False), _join(path, "freeze"))
    if gsd is not None:
        for key, wanted, supported, keyword in (("sync", sync, gsd.sync_supported, "Sync_Mode_supp"),
                                                ("freeze", freeze, gsd.freeze_supported, "Freeze_Mode_supp")):
            if wanted and not supported:
                raise ConfigValueError(_join(path, key), "%s does not declare %s = 1"
                                       % (gsd_name, keyword))
    group_mask = _int(data.get("group_mask", 0), _join(path, "group_mask"), 0, 255)

    key = _join(path, "user_prm_data")
    expected = None
    if gsd is not None:
        try:
            expected = build_user_prm_data(gsd, modules)
        except GsdError as exc:
            raise ConfigValueError(_join(path, "modules"), str(exc)) from exc
    if data.get("user_prm_data") is None:
        prm = expected if expected is not None else b""
    else:
        prm = _bytes(data["user_prm_data"], key)
        if len(prm) > DP_MAX_USER_PRM_DATA_LEN:
            raise ConfigValueError(key, "%d bytes exceed the DP limit of %d"
                                   % (len(prm), DP_MAX_USER_PRM_DATA_LEN))
        if expected is not None and len(prm) != len(expected):
            raise ConfigValueError(key, "%d bytes, but %s expects %d (User_Prm_Data_Len plus "
                                        "module parameters)" % (len(prm), gsd_name, len(expected)))

    return SlaveConfig(name=name, address=address, ident=ident, cfg=cfg, input_len=in_len,
                       output_len=out_len, modules=modules, gsd_path=gsd_path, watchdog_ms=watchdog,
                       sync=sync, freeze=freeze, group_mask=group_mask, user_prm_data=prm, gsd=gsd)


def _slave_cfg(data: Mapping[str, Any], path: str, gsd: Optional[Gsd], gsd_name: str
               ) -> Tuple[Tuple[str, ...], bytes]:
    """(module names, Chk_Cfg bytes) from either ``modules`` (needs a GSD) or raw ``cfg``."""
    has_modules = data.get("modules") is not None
    has_cfg = data.get("cfg") is not None
    if has_modules and has_cfg:
        raise ConfigValueError(_join(path, "cfg"), "give either modules or cfg, not both")
    if has_modules:
        key = _join(path, "modules")
        names = data["modules"]
        if not isinstance(names, (list, tuple)):
            raise ConfigValueError(key, "expected a list of module names, got %s" % _kind(names))
        if gsd is None:
            raise ConfigValueError(key, "module names need a gsd file (or give raw cfg bytes)")
        if not names:
            raise ConfigValueError(key, "the list is empty")
        resolved = []
        for i, name in enumerate(names):
            item = "%s[%d]" % (key, i)
            try:
                resolved.append(gsd.module(_str(name, item)).name)
            except GsdError as exc:
                raise ConfigValueError(item, "%s: %s" % (gsd_name, getattr(exc, "reason", exc))) from exc
        try:
            cfg = build_chk_cfg(gsd, resolved)
        except GsdError as exc:
            raise ConfigValueError(key, "%s: %s" % (gsd_name, getattr(exc, "reason", exc))) from exc
        return tuple(resolved), cfg
    if has_cfg:
        key = _join(path, "cfg")
        cfg = _bytes(data["cfg"], key)
        if not cfg:
            raise ConfigValueError(key, "no Cfg bytes given")
        try:
            in_len, out_len = cfg_io_lengths(cfg)
        except ConfigError as exc:
            raise ConfigValueError(key, str(exc)) from exc
        if gsd is not None:
            for keyword, value, limit in (("Max_Input_Len", in_len, gsd.input_limit),
                                          ("Max_Output_Len", out_len, gsd.output_limit),
                                          ("Max_Data_Len", in_len + out_len, gsd.data_limit)):
                if value > limit:
                    raise ConfigValueError(key, "%d bytes exceed %s = %d in %s"
                                           % (value, keyword, limit, gsd_name))
        return (), cfg
    if gsd is not None and not gsd.modular_station and len(gsd.modules) == 1:
        return (gsd.modules[0].name,), gsd.modules[0].cfg
    raise ConfigValueError(_join(path, "modules"), "required: the module names in Chk_Cfg order "
                                                   "(or raw cfg bytes)")


def _check_bus(master: int, baud: int, slaves: Sequence[SlaveConfig]) -> None:
    by_address: Dict[int, int] = {}
    by_name: Dict[str, int] = {}
    for i, slave in enumerate(slaves):
        if slave.address == master:
            raise ConfigValueError("master_address", "%d is also the address of slaves[%d] %r"
                                   % (master, i, slave.name))
        if slave.address in by_address:
            j = by_address[slave.address]
            raise ConfigValueError("slaves[%d].address" % i, "%d is already used by slaves[%d] %r"
                                   % (slave.address, j, slaves[j].name))
        if slave.name in by_name:
            raise ConfigValueError("slaves[%d].name" % i, "%r is already used by slaves[%d]"
                                   % (slave.name, by_name[slave.name]))
        by_address[slave.address] = i
        by_name[slave.name] = i
        if slave.gsd is not None and not slave.gsd.supports_baud(baud):
            raise ConfigValueError("baud", "%d (%s) is not supported by slaves[%d] %r: %s supports %s"
                                   % (baud, baud_name(baud), i, slave.name,
                                      os.path.basename(slave.gsd.source),
                                      ", ".join(baud_name(b) for b in slave.gsd.baud_rates) or "none"))


# --------------------------------------------------------------------------------------------------
# GSD files
# --------------------------------------------------------------------------------------------------

def _gsd_dirs() -> List[Path]:
    """Directories searched for packaged GSD files, in order."""
    package = Path(__file__).resolve().parent
    dirs: List[Path] = []
    env = os.environ.get(_GSD_DIR_ENV)
    if env:
        dirs.append(Path(env))
    dirs.append(package.parent.parent / "gsd")           # source tree: <pkg>/src/pyprofibus_vendor/
    dirs.extend(p / "share" / "pyprofibus_vendor" / "gsd" for p in package.parents)   # catkin install
    for prefix in os.environ.get("CMAKE_PREFIX_PATH", "").split(os.pathsep):
        if prefix:
            dirs.append(Path(prefix) / "share" / "pyprofibus_vendor" / "gsd")
    unique: List[Path] = []
    for d in dirs:
        if d not in unique:
            unique.append(d)
    return unique


def find_gsd_file(name: str = ROBOT_GSD_FILE) -> str:
    """Path of a GSD file shipped with this package (source tree ``pyprofibus_vendor/gsd/`` or an
    installed ``share/pyprofibus_vendor/gsd/``; ``$PYPROFIBUS_VENDOR_GSD_DIR`` first if set)."""
    dirs = _gsd_dirs()
    for directory in dirs:
        candidate = directory / name
        if candidate.is_file():
            return str(candidate)
    raise ConfigValueError("gsd", "%s not found; looked in: %s (set $%s to the directory holding it)"
                           % (name, ", ".join(str(d) for d in dirs), _GSD_DIR_ENV))


def _resolve_gsd(value: str, base: Path, key: str) -> str:
    path = Path(os.path.expanduser(value))
    candidate = path if path.is_absolute() else base / path
    if candidate.is_file():
        return str(candidate.resolve())
    if not path.is_absolute() and path.name == value:
        try:
            return str(Path(find_gsd_file(value)).resolve())
        except ConfigValueError:
            pass
    raise ConfigValueError(key, "GSD file %r not found (looked for %s%s)" % (
        value, candidate,
        "" if path.is_absolute() or path.name != value else " and in the package's gsd/ directory"))


# --------------------------------------------------------------------------------------------------
# Files
# --------------------------------------------------------------------------------------------------

def _yaml_lines(node: Any, path: str, out: Dict[str, int], source: str) -> None:
    """Map key paths to line numbers; reject duplicate keys (PyYAML silently keeps the last)."""
    if isinstance(node, yaml.MappingNode):
        seen: Dict[str, int] = {}
        for key_node, value_node in node.value:
            key = str(key_node.value)
            sub = _join(path, key)
            line = key_node.start_mark.line + 1
            if key in seen:
                raise ConfigValueError(sub, "duplicate key (first on line %d)" % seen[key], source, line)
            seen[key] = line
            out[sub] = line
            _yaml_lines(value_node, sub, out, source)
    elif isinstance(node, yaml.SequenceNode):
        for i, item in enumerate(node.value):
            sub = "%s[%d]" % (path, i)
            out[sub] = item.start_mark.line + 1
            _yaml_lines(item, sub, out, source)


def _read_yaml(text: str, source: str) -> Tuple[Any, Dict[str, int]]:
    try:
        node = yaml.compose(text, Loader=yaml.SafeLoader)
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = mark.line + 1 if mark is not None else None
        raise ConfigValueError("", "not valid YAML: %s" % (getattr(exc, "problem", None) or exc),
                               source, line) from exc
    lines: Dict[str, int] = {}
    _yaml_lines(node, "", lines, source)
    return data, lines


_INI_INT = ("master_address", "baud", "retry_limit", "slot_time", "address", "ident", "input_len",
            "output_len", "watchdog_ms", "group_mask")
_INI_FLOAT = ("cycle_rate_hz",)
_INI_BOOL = {"true": True, "yes": True, "on": True, "1": True,
             "false": False, "no": False, "off": False, "0": False}
_INI_SLAVE_RE = re.compile(r"slave(?:[_ .:-].*)?\Z", re.IGNORECASE)
_INI_MODULE_RE = re.compile(r"module_([0-9]+)\Z", re.IGNORECASE)


def _ini_value(key: str, text: str) -> Any:
    """INI strings -> the types YAML would give; left as text when it does not convert, so that
    from_dict reports the key."""
    value = text.strip()
    if value == "" or value.lower() in ("none", "null"):
        return None
    if key in _INI_INT:
        number = _cli.int_or_none(value, signed=True)
        return value if number is None else number
    if key in _INI_FLOAT:
        try:
            return float(value)
        except ValueError:
            return value
    if key in ("sync", "freeze"):
        return _INI_BOOL.get(value.lower(), value)
    if key == "modules":
        return [m.strip() for m in re.split(r"[,\n]", value) if m.strip()]
    return value


def _read_ini(text: str, source: str) -> Tuple[Dict[str, Any], Dict[str, int]]:
    parser = configparser.ConfigParser(interpolation=None, inline_comment_prefixes=(";", "#"),
                                       strict=True, default_section="\x00no default section")
    parser.optionxform = str     # keep key case; from_dict reports unknown keys
    try:
        parser.read_string(text, source=source)
    except configparser.Error as exc:
        line = getattr(exc, "lineno", None)
        if isinstance(exc, configparser.DuplicateOptionError):
            reason = "key %r given twice in section [%s]" % (exc.option, exc.section)
        elif isinstance(exc, configparser.DuplicateSectionError):
            reason = "section [%s] given twice" % exc.section
        elif isinstance(exc, configparser.MissingSectionHeaderError):
            reason = "a key before the first [section]: %r" % exc.line.strip()
        elif isinstance(exc, configparser.ParsingError) and exc.errors:
            line, text = exc.errors[0]        # text is repr() of the line
            try:
                text = ast.literal_eval(text)
            except (ValueError, SyntaxError):
                pass
            reason = "cannot parse %r" % str(text).strip()
        else:
            reason = str(exc).split("\n")[0]
        raise ConfigValueError("", "not a valid INI file: %s" % reason, source, line) from exc

    # line numbers: (section lower-case, key or None) -> line
    raw_lines: Dict[Tuple[str, Optional[str]], int] = {}
    section = None
    for number, line in enumerate(text.splitlines(), 1):
        head = re.match(r"\s*\[([^\]]+)\]", line)
        if head:
            section = head.group(1).strip().lower()
            raw_lines[(section, None)] = number
            continue
        item = re.match(r"([^\s=:;#\[][^=:]*?)\s*[=:]", line)
        if item and section is not None:
            raw_lines.setdefault((section, item.group(1).strip()), number)

    data: Dict[str, Any] = {}
    lines: Dict[str, int] = {}
    slaves: List[Dict[str, Any]] = []
    for name in parser.sections():
        lower = name.lower()
        items = parser.items(name)
        if lower == "bus":
            prefix, target = "", data
        elif lower == "phy":
            prefix, target = "phy", data.setdefault("phy", {})
        elif _INI_SLAVE_RE.match(name):
            prefix, target = "slaves[%d]" % len(slaves), {}
            slaves.append(target)
        else:
            raise ConfigValueError("[%s]" % name, "unknown section (use [bus], [phy] and [slave_<n>])",
                                   source, raw_lines.get((lower, None)))
        if prefix:
            lines[prefix] = raw_lines.get((lower, None), 0)
        numbered: List[Tuple[int, str, str]] = []
        for key, value in items:
            module = _INI_MODULE_RE.match(key)
            line = raw_lines.get((lower, key), raw_lines.get((lower, None), 0))
            if module and prefix.startswith("slaves"):
                numbered.append((int(module.group(1)), key, value))
                continue
            target[key] = _ini_value(key, value)
            lines[_join(prefix, key)] = line
        if numbered:
            numbered.sort()
            if "modules" in target:
                raise ConfigValueError(_join(prefix, "modules"), "give either 'modules' or "
                                       "module_0, module_1, ... lines, not both",
                                       source, raw_lines.get((lower, "modules")))
            target["modules"] = [value.strip() for _, _, value in numbered]
            for i, (_, key, _) in enumerate(numbered):
                lines["%s[%d]" % (_join(prefix, "modules"), i)] = raw_lines.get((lower, key), 0)
            lines[_join(prefix, "modules")] = raw_lines.get((lower, numbered[0][1]), 0)
    if slaves:
        data["slaves"] = slaves
    return data, lines


def _line_for(key: str, lines: Mapping[str, int]) -> Optional[int]:
    """Line of ``key`` or of its nearest parent that has one."""
    while key:
        if lines.get(key):
            return lines[key]
        cut = max(key.rfind("."), key.rfind("["))
        key = key[:cut] if cut > 0 else ""
    return None


def load_config(path: Union[str, "os.PathLike[str]"]) -> BusConfig:
    """Read a ``.yaml``/``.yml`` or ``.ini``/``.conf`` bus configuration file.

    Errors name the file, the line and the key path. GSD paths are relative to the file's directory.
    """
    source = str(path)
    ext = os.path.splitext(source)[1].lower()
    if ext not in (".yaml", ".yml", ".ini", ".conf"):
        raise ConfigValueError("", "unknown configuration file type %r (use .yaml, .yml, .ini or .conf)"
                               % (ext or "no extension"), source)
    try:
        with open(source, "r", encoding="utf-8") as handle:
            text = handle.read()
    except (OSError, UnicodeDecodeError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        raise ConfigValueError("", "cannot read configuration file: %s" % reason, source) from exc
    if ext in (".yaml", ".yml"):
        data, lines = _read_yaml(text, source)
    else:
        data, lines = _read_ini(text, source)
    if data is None:
        raise ConfigValueError("", "the file is empty", source)
    try:
        return BusConfig.from_dict(data, base_dir=os.path.dirname(os.path.abspath(source)))
    except ConfigValueError as exc:
        raise exc.located(source, _line_for(exc.key, lines)) from None


def default_robot_config(device: str, baud: int = 19200, *, phy_type: str = "serial",
                         master_address: int = 2, slave_address: int = 4,
                         watchdog_ms: Optional[int] = _DEFAULT_WATCHDOG_MS,
                         cycle_rate_hz: float = _DEFAULT_CYCLE_RATE_HZ) -> BusConfig:
    """The project's default bus: master 2, the VR-006L's G2 controller as slave 4 (ident 0x06C6,
    PAN06C6.gsd, modules ROBOT_MODULES = Chk_Cfg 13 13 13 11 23 23 23 21, 14 bytes each way)."""
    return BusConfig.from_dict({
        "master_address": master_address,
        "baud": baud,
        "cycle_rate_hz": cycle_rate_hz,
        "phy": {"type": phy_type, "device": device or None},
        "slaves": [{
            "name": "vr006l",
            "address": slave_address,
            "gsd": find_gsd_file(ROBOT_GSD_FILE),
            "ident": ROBOT_IDENT,
            "modules": list(ROBOT_MODULES),
            "input_len": 14,
            "output_len": 14,
            "watchdog_ms": watchdog_ms,
        }],
    })
