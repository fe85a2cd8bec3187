"""Tests of pyprofibus_vendor.config: from_dict validation, YAML/INI files, the robot default.

Plain assert functions (no pytest fixtures) so they also run under nose.
"""
from __future__ import annotations

import copy
import os
import shutil
import tempfile
from typing import Any, Dict

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pyprofibus_vendor.config import (
    ROBOT_IDENT,
    ROBOT_MODULES,
    BusConfig,
    ConfigValueError,
    PhyConfig,
    default_robot_config,
    find_gsd_file,
    load_config,
)
from pyprofibus_vendor.errors import ConfigError, ProfibusError

HERE = os.path.dirname(os.path.abspath(__file__))
PKG = os.path.dirname(HERE)
ROBOT_GSD = os.path.join(PKG, "gsd", "PAN06C6.gsd")
TEST_GSD = os.path.join(HERE, "data", "test_station.gsd")
EXAMPLE_YAML = os.path.join(PKG, "config", "vr006l_bus.yaml")
EXAMPLE_INI = os.path.join(PKG, "config", "vr006l_bus.ini")

THESIS_CFG = bytes([0x13, 0x13, 0x13, 0x11, 0x23, 0x23, 0x23, 0x21])


def robot_dict() -> Dict[str, Any]:
    return {
        "master_address": 2,
        "baud": 19200,
        "phy": {"type": "serial", "device": "/dev/ttyUSB0"},
        "slaves": [{"name": "vr006l", "address": 4, "gsd": ROBOT_GSD, "modules": list(ROBOT_MODULES)}],
    }


def config_error(data: Dict[str, Any], base_dir: str = HERE) -> ConfigValueError:
    try:
        BusConfig.from_dict(data, base_dir=base_dir)
    except ConfigValueError as exc:
        assert isinstance(exc, ConfigError) and isinstance(exc, ValueError)
        return exc
    raise AssertionError("no ConfigValueError for %r" % (data,))


def changed(path: str, value: Any) -> Dict[str, Any]:
    """robot_dict() with one key (``a.b``, ``slaves.0.c``) set; value ``...`` deletes it."""
    data = robot_dict()
    parts = path.split(".")
    target: Any = data
    for part in parts[:-1]:
        target = target[int(part)] if part.isdigit() else target[part]
    if value is Ellipsis:
        del target[parts[-1]]
    else:
        target[parts[-1]] = value
    return data


def file_error(text: str, name: str) -> str:
    tmp = tempfile.mkdtemp()
    try:
        path = os.path.join(tmp, name)
        with open(path, "w") as handle:
            handle.write(text)
        try:
            load_config(path)
        except ConfigValueError as exc:
            return str(exc).replace(tmp + os.sep, "")
        raise AssertionError("no error for %s:\n%s" % (name, text))
    finally:
        shutil.rmtree(tmp)


def load_text(text: str, name: str) -> BusConfig:
    tmp = tempfile.mkdtemp()
    try:
        path = os.path.join(tmp, name)
        with open(path, "w") as handle:
            handle.write(text)
        return load_config(path)
    finally:
        shutil.rmtree(tmp)


# ---------------------------------------------------------------------------------------------
# Good configurations
# ---------------------------------------------------------------------------------------------

def test_robot_dict_derives_ident_cfg_and_lengths():
    cfg = BusConfig.from_dict(robot_dict())
    slave = cfg.slaves[0]
    assert (cfg.master_address, cfg.baud, cfg.cycle_rate_hz) == (2, 19200, 20.0)
    assert cfg.retry_limit is None and cfg.slot_time is None
    assert cfg.phy == PhyConfig(type="serial", device="/dev/ttyUSB0", baud=19200)
    assert (slave.ident, slave.cfg, slave.input_len, slave.output_len) == (0x06C6, THESIS_CFG, 14, 14)
    assert slave.modules == ROBOT_MODULES
    assert slave.watchdog_ms == 300 and slave.user_prm_data == b""
    assert slave.gsd is not None and slave.gsd.ident_number == 0x06C6
    assert cfg.slave(4) is slave and cfg.slave("vr006l") is slave


def test_module_order_is_configurable():
    data = changed("slaves.0.modules", ["4 Bytes Out"] * 3 + ["2 Bytes Out"] + ["4 Bytes In"] * 3
                   + ["2 Bytes In"])
    slave = BusConfig.from_dict(data).slaves[0]
    assert slave.cfg == bytes([0x23, 0x23, 0x23, 0x21, 0x13, 0x13, 0x13, 0x11])
    assert (slave.input_len, slave.output_len) == (14, 14)


def test_example_yaml_and_ini_load_to_the_same_config():
    from_yaml = load_config(EXAMPLE_YAML)
    from_ini = load_config(EXAMPLE_INI)
    assert from_yaml == from_ini
    assert from_yaml == default_robot_config("/dev/ttyUSB0")
    assert from_yaml.slaves[0].cfg == THESIS_CFG
    assert os.path.samefile(from_yaml.slaves[0].gsd_path, ROBOT_GSD)


def test_default_robot_config():
    cfg = default_robot_config("/dev/ttyS1", baud=187500)
    slave = cfg.slaves[0]
    assert (cfg.master_address, cfg.baud, cfg.phy.device, cfg.phy.baud) == (2, 187500, "/dev/ttyS1", 187500)
    assert (slave.address, slave.ident, slave.cfg, slave.input_len, slave.output_len) == (
        4, ROBOT_IDENT, THESIS_CFG, 14, 14)
    memory = default_robot_config("", phy_type="memory")
    assert memory.phy == PhyConfig(type="memory", device="", baud=19200)


def test_raw_cfg_without_gsd():
    data = robot_dict()
    data["slaves"] = [{"address": 8, "ident": 0x4D14, "cfg": "3D"},
                      {"address": 9, "ident": 0x4D14, "cfg": [0xC0, 0x0D, 0x0D], "watchdog_ms": 0}]
    cfg = BusConfig.from_dict(data)
    first, second = cfg.slaves
    assert (first.name, first.cfg, first.input_len, first.output_len, first.modules) == (
        "slave_8", b"\x3D", 14, 14, ())
    assert (second.cfg, second.input_len, second.output_len, second.watchdog_ms) == (
        b"\xC0\x0D\x0D", 14, 14, None)
    assert first.gsd is None and first.gsd_path is None


def test_raw_cfg_checked_against_gsd():
    data = changed("slaves.0.modules", ...)
    data["slaves"][0]["cfg"] = "0x13, 0x13, 0x13, 0x11, 0x23, 0x23, 0x23, 0x21"
    assert BusConfig.from_dict(data).slaves[0].cfg == THESIS_CFG
    data["slaves"][0]["cfg"] = "5F 5F 5F"                # 96 inputs
    assert str(config_error(data)) == "slaves[0].cfg: 96 bytes exceed Max_Input_Len = 72 in PAN06C6.gsd"


def test_optional_overrides_and_flags():
    data = robot_dict()
    data.update(retry_limit=3, slot_time=400, cycle_rate_hz=10)
    data["slaves"][0]["gsd"] = TEST_GSD
    data["slaves"][0]["modules"] = ["8 DI", "Analog in 2 words consistent"]
    data["slaves"][0].update(sync=True, freeze=True, group_mask=0x81, ident=0x4D14)
    cfg = BusConfig.from_dict(data)
    slave = cfg.slaves[0]
    assert (cfg.retry_limit, cfg.slot_time, cfg.cycle_rate_hz) == (3, 400, 10.0)
    assert slave.sync and slave.freeze and slave.group_mask == 0x81
    assert slave.user_prm_data == bytes([0x84, 0x01, 0x2C, 0x50, 0x02])   # GSD defaults
    data["slaves"][0]["user_prm_data"] = "00 00 00 00 01"
    assert BusConfig.from_dict(data).slaves[0].user_prm_data == b"\x00\x00\x00\x00\x01"


def test_gsd_found_relative_to_base_dir_and_in_package():
    data = changed("slaves.0.gsd", "data/test_station.gsd")
    data["slaves"][0]["modules"] = ["8 DI"]
    assert BusConfig.from_dict(data, base_dir=HERE).slaves[0].ident == 0x4D14
    data = changed("slaves.0.gsd", "PAN06C6.gsd")        # bare name: the package's gsd/ dir
    assert BusConfig.from_dict(data, base_dir=HERE).slaves[0].ident == 0x06C6


def test_to_dict_round_trip():
    cfg = default_robot_config("/dev/ttyUSB0")
    assert BusConfig.from_dict(cfg.to_dict()) == cfg


def test_find_gsd_file():
    assert os.path.samefile(find_gsd_file(), ROBOT_GSD)
    try:
        find_gsd_file("NOPE.gsd")
    except ConfigValueError as exc:
        assert "NOPE.gsd not found; looked in:" in str(exc) and "PYPROFIBUS_VENDOR_GSD_DIR" in str(exc)
    else:
        raise AssertionError
    tmp = tempfile.mkdtemp()
    old = os.environ.get("PYPROFIBUS_VENDOR_GSD_DIR")
    try:
        shutil.copy(TEST_GSD, os.path.join(tmp, "PAN06C6.gsd"))
        os.environ["PYPROFIBUS_VENDOR_GSD_DIR"] = tmp
        assert find_gsd_file() == os.path.join(tmp, "PAN06C6.gsd")
    finally:
        if old is None:
            del os.environ["PYPROFIBUS_VENDOR_GSD_DIR"]
        else:
            os.environ["PYPROFIBUS_VENDOR_GSD_DIR"] = old
        shutil.rmtree(tmp)


# ---------------------------------------------------------------------------------------------
# Error branches of from_dict: the message names the key path
# ---------------------------------------------------------------------------------------------

def test_error_address_out_of_range():
    exc = config_error(changed("slaves.0.address", 130))
    assert str(exc) == "slaves[0].address: 130 is outside 0..125"
    assert exc.key == "slaves[0].address" and exc.source is None
    assert str(config_error(changed("master_address", 126))) == "master_address: 126 is outside 0..125"


def test_error_duplicate_slave_address_and_name():
    data = robot_dict()
    data["slaves"].append(dict(data["slaves"][0], name="second"))
    assert str(config_error(data)) == "slaves[1].address: 4 is already used by slaves[0] 'vr006l'"
    data["slaves"][1]["address"] = 5
    data["slaves"][1]["name"] = "vr006l"
    assert str(config_error(data)) == "slaves[1].name: 'vr006l' is already used by slaves[0]"


def test_error_master_equals_slave_address():
    assert str(config_error(changed("master_address", 4))) == \
        "master_address: 4 is also the address of slaves[0] 'vr006l'"


def test_error_unknown_keys():
    assert str(config_error(changed("bauds", 19200))) == (
        "bauds: unknown key - did you mean 'baud'? (allowed: master_address, baud, phy, slaves, "
        "cycle_rate_hz, retry_limit, slot_time)")
    assert str(config_error(changed("slaves.0.adress", 5))).startswith(
        "slaves[0].adress: unknown key - did you mean 'address'?")
    assert str(config_error(changed("phy.port", "x"))).startswith("phy.port: unknown key")


def test_error_wrong_types():
    assert str(config_error(changed("slaves.0.address", "four"))) == \
        "slaves[0].address: expected an integer, got str 'four'"
    assert str(config_error(changed("slaves.0.address", True))) == \
        "slaves[0].address: expected an integer, got bool True"
    assert str(config_error(changed("slaves.0.sync", "yes"))) == \
        "slaves[0].sync: expected true or false, got str 'yes'"
    assert str(config_error(changed("slaves", {"address": 4}))) == \
        "slaves: expected a list of slaves, got dict"
    assert str(config_error(changed("phy", "serial"))) == \
        "phy: expected a mapping of keys, got str 'serial'"
    assert str(config_error(changed("cycle_rate_hz", "fast"))) == \
        "cycle_rate_hz: expected a number, got str 'fast'"
    assert str(config_error(changed("slaves.0.modules", "4 Bytes In"))) == \
        "slaves[0].modules: expected a list of module names, got str '4 Bytes In'"
    assert str(config_error(changed("slaves.0.name", ""))) == \
        "slaves[0].name: expected a non-empty string, got str ''"
    assert str(config_error(changed("slaves.0.user_prm_data", 5))) == \
        "slaves[0].user_prm_data: expected a hex string or a list of bytes, got int 5"
    assert str(config_error([1, 2])) == "(top level): expected a mapping of keys, got list"  # type: ignore


def test_error_missing_required_keys():
    assert str(config_error(changed("baud", ...))) == "baud: required key is missing"
    assert str(config_error(changed("slaves.0.address", ...))) == "slaves[0].address: required key is missing"
    assert str(config_error(changed("slaves", []))) == "slaves: at least one slave is required"


def test_error_baud():
    assert str(config_error(changed("baud", 38400))).startswith(
        "baud: 38400 is not a PROFIBUS-DP bit rate (use one of 9600, 19200, 45450,")
    data = changed("baud", 45450)
    data["slaves"][0].update(gsd=TEST_GSD, modules=["8 DI"])
    assert str(config_error(data)) == ("baud: 45450 (45.45k) is not supported by slaves[0] 'vr006l': "
                                       "test_station.gsd supports 9.6k, 19.2k, 187.5k, 1.5M")


def test_error_unknown_module_name():
    data = changed("slaves.0.modules", ["4 Bytes In", "4 Byte Out"])
    assert str(config_error(data)).startswith(
        "slaves[0].modules[1]: PAN06C6.gsd: unknown module '4 Byte Out'; did you mean '4 Bytes Out'")


def test_error_modules_over_gsd_limits():
    data = changed("slaves.0.modules", ["32 Bytes In"] * 3)
    assert str(config_error(data)) == ("slaves[0].modules: PAN06C6.gsd: 96 input bytes exceed "
                                       "Max_Input_Len = 72 (selection: 32 Bytes In, 32 Bytes In, "
                                       "32 Bytes In)")
    data = changed("slaves.0.modules", list(ROBOT_MODULES) + ["1 Byte In"])
    assert "slaves[0].modules: PAN06C6.gsd: 9 modules exceed Max_Module = 8" in str(config_error(data))


def test_error_ident():
    assert str(config_error(changed("slaves.0.ident", 0x1234))) == \
        "slaves[0].ident: 0x1234 does not match Ident_Number 0x06C6 in PAN06C6.gsd"
    data = robot_dict()
    data["slaves"] = [{"address": 4, "cfg": "3D"}]
    assert str(config_error(data)) == "slaves[0].ident: required when no gsd is given"
    assert str(config_error(changed("slaves.0.ident", 0x10000))) == \
        "slaves[0].ident: 65536 is outside 0..65535"


def test_error_modules_and_cfg_combinations():
    data = changed("slaves.0.cfg", "3D")
    assert str(config_error(data)) == "slaves[0].cfg: give either modules or cfg, not both"
    data = changed("slaves.0.modules", ...)
    assert str(config_error(data)) == \
        "slaves[0].modules: required: the module names in Chk_Cfg order (or raw cfg bytes)"
    data = changed("slaves.0.gsd", ...)
    data["slaves"][0]["ident"] = 0x06C6
    assert str(config_error(data)) == \
        "slaves[0].modules: module names need a gsd file (or give raw cfg bytes)"
    data = changed("slaves.0.modules", [])
    assert str(config_error(data)) == "slaves[0].modules: the list is empty"
    data = changed("slaves.0.modules", ...)
    data["slaves"][0]["cfg"] = "13 zz"
    assert str(config_error(data)).startswith("slaves[0].cfg: item 1: 'zz' is not a hex byte")
    data["slaves"][0]["cfg"] = "C0 0D"
    assert str(config_error(data)).startswith("slaves[0].cfg: Cfg identifier 0xC0 at offset 0 needs")
    data["slaves"][0]["cfg"] = [0x13, 256]
    assert str(config_error(data)) == "slaves[0].cfg[1]: 256 is outside 0..255"


def test_error_lengths_must_match():
    assert str(config_error(changed("slaves.0.input_len", 16))) == \
        "slaves[0].input_len: 16 does not match the 14 input bytes of the modules"
    assert str(config_error(changed("slaves.0.output_len", 0))) == \
        "slaves[0].output_len: 0 does not match the 14 output bytes of the modules"


def test_error_sync_freeze_not_supported():
    assert str(config_error(changed("slaves.0.sync", True))) == \
        "slaves[0].sync: PAN06C6.gsd does not declare Sync_Mode_supp = 1"
    assert str(config_error(changed("slaves.0.freeze", True))) == \
        "slaves[0].freeze: PAN06C6.gsd does not declare Freeze_Mode_supp = 1"


def test_error_ranges():
    assert str(config_error(changed("slaves.0.watchdog_ms", 700000))) == \
        "slaves[0].watchdog_ms: 700000 is outside 0..650250"
    assert str(config_error(changed("retry_limit", 8))) == "retry_limit: 8 is outside 0..7"
    assert str(config_error(changed("slot_time", 10))) == "slot_time: 10 is outside 37..16383"
    assert str(config_error(changed("cycle_rate_hz", 0))) == "cycle_rate_hz: 0 is outside (0, 1000]"
    assert str(config_error(changed("slaves.0.group_mask", 256))) == \
        "slaves[0].group_mask: 256 is outside 0..255"


def test_error_user_prm_data_length():
    assert str(config_error(changed("slaves.0.user_prm_data", "01 02"))) == (
        "slaves[0].user_prm_data: 2 bytes, but PAN06C6.gsd expects 0 (User_Prm_Data_Len plus "
        "module parameters)")


def test_error_phy():
    assert str(config_error(changed("phy.type", "usb"))) == "phy.type: 'usb' is not one of serial, memory"
    assert str(config_error(changed("phy.device", ...))).startswith("phy.device: required for a serial PHY")
    assert str(config_error(changed("phy.baud", 9600))).startswith("phy.baud: 9600 differs from baud = 19200")
    data = changed("phy.baud", 19200)
    assert BusConfig.from_dict(data).phy.baud == 19200


def test_error_gsd_file():
    assert str(config_error(changed("slaves.0.gsd", "missing.gsd"))).startswith(
        "slaves[0].gsd: GSD file 'missing.gsd' not found (looked for ")
    tmp = tempfile.mkdtemp()
    try:
        with open(os.path.join(tmp, "broken.gsd"), "w") as handle:
            handle.write("Ident_Number = 0x06C6\nModule = \"4 Bytes In\" 0x13\n")
        exc = config_error(changed("slaves.0.gsd", "broken.gsd"), base_dir=tmp)
        assert str(exc) == ("slaves[0].gsd: %s:2: Module: unterminated Module '4 Bytes In': "
                            "missing EndModule before the end of the file" % os.path.join(tmp, "broken.gsd"))
    finally:
        shutil.rmtree(tmp)


def test_errors_are_profibus_errors():
    assert issubclass(ConfigValueError, ConfigError) and issubclass(ConfigValueError, ProfibusError)


# ---------------------------------------------------------------------------------------------
# Files: errors name the file and the line
# ---------------------------------------------------------------------------------------------

YAML_TEXT = """\
master_address: 2
baud: 19200
phy:
  type: serial
  device: /dev/ttyUSB0
slaves:
  - name: vr006l
    address: 4
    gsd: PAN06C6.gsd
    modules: [4 Bytes In, 4 Bytes In, 4 Bytes In, 2 Bytes In,
              4 Bytes Out, 4 Bytes Out, 4 Bytes Out, 2 Bytes Out]
"""

INI_TEXT = """\
[bus]
master_address = 2
baud = 19200

[phy]
type = serial
device = /dev/ttyUSB0

[slave_0]
name = vr006l
address = 4
gsd = PAN06C6.gsd
modules = 4 Bytes In, 4 Bytes In, 4 Bytes In, 2 Bytes In,
    4 Bytes Out, 4 Bytes Out, 4 Bytes Out, 2 Bytes Out
"""


def test_yaml_and_ini_texts_match_default():
    assert load_text(YAML_TEXT, "bus.yaml") == load_text(INI_TEXT, "bus.ini") == \
        default_robot_config("/dev/ttyUSB0")


def test_yaml_error_names_file_line_key():
    assert file_error(YAML_TEXT.replace("address: 4", "address: 130"), "bus.yaml") == \
        "bus.yaml:8: slaves[0].address: 130 is outside 0..125"
    assert file_error(YAML_TEXT.replace("4 Bytes Out, 2", "4 Byte Out, 2"), "bus.yml").startswith(
        "bus.yml:11: slaves[0].modules[6]: PAN06C6.gsd: unknown module '4 Byte Out'")
    assert file_error(YAML_TEXT + "    adress: 5\n", "bus.yaml").startswith(
        "bus.yaml:12: slaves[0].adress: unknown key - did you mean 'address'?")
    assert file_error(YAML_TEXT.replace("baud: 19200", "baud: 19200\nbaud: 9600"), "bus.yaml") == \
        "bus.yaml:3: baud: duplicate key (first on line 2)"
    assert file_error(YAML_TEXT.replace("phy:", "phy: [", 1), "bus.yaml") == \
        "bus.yaml:5: not valid YAML: expected ',' or ']', but got ':'"
    assert file_error("", "bus.yaml") == "bus.yaml: the file is empty"


def test_ini_error_names_file_line_key():
    assert file_error(INI_TEXT.replace("address = 4", "address = 130"), "bus.ini") == \
        "bus.ini:11: slaves[0].address: 130 is outside 0..125"
    assert file_error(INI_TEXT.replace("address = 4", "address = four"), "bus.ini") == \
        "bus.ini:11: slaves[0].address: expected an integer, got str 'four'"
    assert file_error(INI_TEXT.replace("master_address = 2", "master_address = 4"), "bus.ini") == \
        "bus.ini:2: master_address: 4 is also the address of slaves[0] 'vr006l'"
    assert file_error(INI_TEXT + "[slave_1]\nname = b\naddress = 4\nmodules = 4 Bytes In\n"
                      "gsd = PAN06C6.gsd\n", "bus.conf") == \
        "bus.conf:17: slaves[1].address: 4 is already used by slaves[0] 'vr006l'"
    assert file_error(INI_TEXT.replace("[phy]", "[phys]"), "bus.ini") == \
        "bus.ini:5: [phys]: unknown section (use [bus], [phy] and [slave_<n>])"
    assert file_error(INI_TEXT + "address = 5\n", "bus.ini") == \
        "bus.ini:15: not a valid INI file: key 'address' given twice in section [slave_0]"
    assert file_error(INI_TEXT + "[phy]\n", "bus.ini") == \
        "bus.ini:15: not a valid INI file: section [phy] given twice"
    assert file_error("baud = 1\n" + INI_TEXT, "bus.ini") == \
        "bus.ini:1: not a valid INI file: a key before the first [section]: 'baud = 1'"
    assert file_error(INI_TEXT + "no equals sign here\n", "bus.ini") == \
        "bus.ini:15: not a valid INI file: cannot parse 'no equals sign here'"
    assert file_error(INI_TEXT + "baud = 9600\n", "bus.ini").startswith(
        "bus.ini:15: slaves[0].baud: unknown key (allowed: name, address,")
    assert file_error(INI_TEXT + "sync = maybe\n", "bus.ini") == \
        "bus.ini:15: slaves[0].sync: expected true or false, got str 'maybe'"
    assert file_error(INI_TEXT + "module_0 = 4 Bytes In\n", "bus.ini") == \
        "bus.ini:13: slaves[0].modules: give either 'modules' or module_0, module_1, ... lines, not both"


def test_ini_module_lines_sorted_by_number():
    text = INI_TEXT.split("modules =")[0] + "module_1 = 4 Bytes Out\nmodule_0 = 4 Bytes In\n"
    slave = load_text(text, "bus.ini").slaves[0]
    assert slave.modules == ("4 Bytes In", "4 Bytes Out") and slave.cfg == b"\x13\x23"


def test_file_type_and_missing_file():
    assert file_error("x", "bus.txt") == \
        "bus.txt: unknown configuration file type '.txt' (use .yaml, .yml, .ini or .conf)"
    try:
        load_config("/nonexistent/bus.yaml")
    except ConfigValueError as exc:
        assert str(exc).startswith("/nonexistent/bus.yaml: cannot read configuration file:")
    else:
        raise AssertionError


def test_config_dict_is_not_modified():
    data = robot_dict()
    before = copy.deepcopy(data)
    BusConfig.from_dict(data)
    assert data == before


# ---------------------------------------------------------------------------------------------
# Fuzzing: any value in any key gives a BusConfig or a ConfigValueError, nothing else
# ---------------------------------------------------------------------------------------------

_JSON_LIKE = st.recursive(
    st.none() | st.booleans() | st.integers(-10 ** 6, 10 ** 6) | st.floats() | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=5), inner, max_size=3),
    max_leaves=6)
_TOP_KEYS = ["master_address", "baud", "phy", "slaves", "cycle_rate_hz", "retry_limit", "slot_time", "x"]
_SLAVE_KEYS = ["name", "address", "gsd", "ident", "modules", "cfg", "input_len", "output_len",
               "watchdog_ms", "sync", "freeze", "group_mask", "user_prm_data", "y"]


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.dictionaries(st.sampled_from(_TOP_KEYS), _JSON_LIKE, max_size=3),
       st.dictionaries(st.sampled_from(_SLAVE_KEYS), _JSON_LIKE, max_size=3))
def test_fuzz_from_dict(top, slave):
    data = robot_dict()
    data.update(top)
    slaves = data.get("slaves")
    if isinstance(slaves, list) and slaves and isinstance(slaves[0], dict):
        slaves[0].update(slave)
    try:
        BusConfig.from_dict(data)
    except ConfigValueError as exc:
        assert exc.key is not None and str(exc)
