"""Tests of pyprofibus_vendor.gsd: parsing, Cfg decoding, Chk_Cfg building, errors and the CLI.

Plain assert functions (no pytest fixtures) so they also run under nose.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pyprofibus_vendor.errors import ConfigError, GsdError
from pyprofibus_vendor.gsd import (
    STANDARD_BAUDRATES,
    Gsd,
    GsdParseError,
    baud_name,
    build_chk_cfg,
    build_user_prm_data,
    cfg_io_lengths,
    decode_cfg,
    format_hex,
    load_gsd,
    main,
    parse_gsd,
)

HERE = os.path.dirname(os.path.abspath(__file__))
PKG = os.path.dirname(HERE)
SRC = os.path.join(PKG, "src")
ROBOT_GSD = os.path.join(PKG, "gsd", "PAN06C6.gsd")
TEST_GSD = os.path.join(HERE, "data", "test_station.gsd")
PYTHON = "/usr/bin/python3" if os.path.exists("/usr/bin/python3") else sys.executable

THESIS_MODULES = ["4 Bytes In"] * 3 + ["2 Bytes In"] + ["4 Bytes Out"] * 3 + ["2 Bytes Out"]
OUTPUTS_FIRST = ["4 Bytes Out"] * 3 + ["2 Bytes Out"] + ["4 Bytes In"] * 3 + ["2 Bytes In"]

MINIMAL = 'Vendor_Name = "V"\nIdent_Number = 0x1234\n'


def gsd_error(text: str, source: str = "bad.gsd") -> GsdError:
    """Parse text that must fail; return the GsdError."""
    try:
        parse_gsd(text, source=source)
    except GsdError as exc:
        return exc
    raise AssertionError("no GsdError for:\n" + text)


def chk_cfg_error(gsd: Gsd, names) -> str:
    try:
        build_chk_cfg(gsd, names)
    except GsdError as exc:
        return str(exc)
    raise AssertionError("no GsdError for %r" % (names,))


# ---------------------------------------------------------------------------------------------
# The robot's GSD
# ---------------------------------------------------------------------------------------------

def test_robot_gsd_identity():
    gsd = load_gsd(ROBOT_GSD)
    assert gsd.ident_number == 0x06C6
    assert gsd.vendor_name == "Matsushita Welding Systems"
    assert "YA-1NPEP1" in gsd.model_name
    assert gsd.station_type == 0
    assert gsd.protocol_ident == 0
    assert gsd.source == ROBOT_GSD


def test_robot_gsd_bauds_and_limits():
    gsd = load_gsd(ROBOT_GSD)
    assert gsd.baud_rates == STANDARD_BAUDRATES
    assert gsd.max_tsdr[19200] == 60 and gsd.max_tsdr[12000000] == 800
    assert gsd.modular_station is True
    assert (gsd.max_input_len, gsd.max_output_len, gsd.max_data_len) == (72, 72, 144)   # v2: 72 each way
    assert gsd.max_module == 8
    assert gsd.user_prm_data == b"" and gsd.user_prm_data_len == 0
    assert not gsd.freeze_supported and not gsd.sync_supported and not gsd.fail_safe
    assert gsd.unknown["FMS_supp"] == "0"       # unknown keywords are kept


def test_robot_gsd_modules():
    gsd = load_gsd(ROBOT_GSD)
    expected = {"4 Bytes In": (b"\x13", 4, 0), "2 Bytes In": (b"\x11", 2, 0),
                "4 Bytes Out": (b"\x23", 0, 4), "2 Bytes Out": (b"\x21", 0, 2),
                "1 Byte In": (b"\x10", 1, 0), "8 Bytes Out": (b"\x27", 0, 8),
                "14 Bytes In/Out": (b"\x3D", 14, 14), "14 Bytes In/Out consistent": (b"\xBD", 14, 14),
                "7 Words In/Out consistent": (b"\xF6", 14, 14),
                "32 Bytes In": (b"\x5F", 32, 0), "32 Bytes Out": (b"\x6F", 0, 32)}
    for name, (cfg, in_len, out_len) in expected.items():
        mod = gsd.module(name)
        assert (mod.cfg, mod.input_len, mod.output_len) == (cfg, in_len, out_len), name


def test_thesis_module_list_gives_thesis_chk_cfg():
    gsd = load_gsd(ROBOT_GSD)
    cfg = build_chk_cfg(gsd, THESIS_MODULES)
    assert cfg == bytes([0x13, 0x13, 0x13, 0x11, 0x23, 0x23, 0x23, 0x21])
    assert format_hex(cfg) == "13 13 13 11 23 23 23 21"
    assert cfg_io_lengths(cfg) == (14, 14)


def test_chk_cfg_order_is_configurable():
    gsd = load_gsd(ROBOT_GSD)
    cfg = build_chk_cfg(gsd, OUTPUTS_FIRST)
    assert format_hex(cfg) == "23 23 23 21 13 13 13 11"
    assert cfg_io_lengths(cfg) == (14, 14)


def test_single_in_out_module_alternatives():
    gsd = load_gsd(ROBOT_GSD)
    assert build_chk_cfg(gsd, ["14 Bytes In/Out"]) == b"\x3D"
    assert build_chk_cfg(gsd, ["14 Bytes In/Out consistent"]) == b"\xBD"


def test_module_lookup_ignores_case_and_blanks():
    gsd = load_gsd(ROBOT_GSD)
    assert gsd.module("4  bytes in").name == "4 Bytes In"


def test_summary_and_dict():
    gsd = load_gsd(ROBOT_GSD)
    text = gsd.summary()
    assert "0x06C6" in text and "12M" in text and '"4 Bytes In"' in text and "Cfg 13" in text
    data = json.loads(json.dumps(gsd.to_dict()))
    assert data["ident_number"] == "0x06C6" and len(data["modules"]) == len(gsd.modules)


def test_baud_name():
    assert [baud_name(b) for b in (9600, 45450, 1500000, 12000000)] == ["9.6k", "45.45k", "1.5M", "12M"]


# ---------------------------------------------------------------------------------------------
# The test GSD: continuations, comments, special format, ExtUserPrmData, unknown keywords
# ---------------------------------------------------------------------------------------------

def test_test_gsd_header_strings_and_continuation():
    gsd = load_gsd(TEST_GSD)
    assert gsd.vendor_name == "M\u00fcller Test; GmbH"        # ISO-8859-1 byte, ';' inside a string
    assert gsd.model_name == "Test Station 42"              # string continued with '\'
    assert gsd.ident_number == 0x4D14                       # lower-case keyword
    assert gsd.gsd_revision == 3 and gsd.revision_number == 2
    assert gsd.implementation_type == "SPC3" and gsd.order_number == "TS-42"


def test_test_gsd_bauds_flags_limits():
    gsd = load_gsd(TEST_GSD)
    assert gsd.baud_rates == (9600, 19200, 187500, 1500000)   # 45.45_supp = 0 is not supported
    assert not gsd.supports_baud(45450)
    assert gsd.max_tsdr == {9600: 60, 19200: 60, 187500: 60, 1500000: 150}
    assert gsd.freeze_supported and gsd.sync_supported and gsd.fail_safe and gsd.auto_baud_supported
    assert not gsd.set_slave_add_supported
    assert (gsd.min_slave_interval, gsd.max_diag_data_len, gsd.max_module) == (6, 16, 4)
    assert (gsd.input_limit, gsd.output_limit, gsd.data_limit) == (32, 24, 48)


def test_test_gsd_unknown_keywords_and_blocks_kept():
    gsd = load_gsd(TEST_GSD)
    assert gsd.unknown["Bitmap_Device"] == '"TS42_N"'
    assert gsd.unknown["Slave_Family"] == "3@TdF@Test"
    assert gsd.unknown["31.25_supp"] == "1"
    assert gsd.unknown["24V_Pins"] == "0"
    kinds = [(b.keyword, b.value, len(b.lines)) for b in gsd.blocks]
    assert kinds == [("PrmText", "1", 2), ("Unit_Diag_Area", "16-17", 2)]


def test_test_gsd_user_prm_data_from_ext_user_prm_data():
    gsd = load_gsd(TEST_GSD)
    # Const(0)=0x80, Ref(0) -> Bit(2)=1 -> 0x84; Ref(1) -> Unsigned16 300 big-endian -> 01 2C
    assert gsd.user_prm_data == bytes([0x84, 0x01, 0x2C])
    assert gsd.ext_user_prm[3].bits == (4, 6) and gsd.ext_user_prm[4].maximum == 4
    analog = gsd.module("Analog in 2 words consistent")
    assert analog.prm_data == bytes([0x50, 0x02])           # BitArea(4-6)=5, Unsigned8 2
    assert analog.reference == 2 and analog.extra["Info_Text"] == '"two channels"'
    assert build_user_prm_data(gsd, ["8 DI", "Analog in 2 words consistent"]) == bytes(
        [0x84, 0x01, 0x2C, 0x50, 0x02])


def test_test_gsd_special_format_modules():
    gsd = load_gsd(TEST_GSD)
    table = {m.name: (m.cfg, m.input_len, m.output_len) for m in gsd.modules}
    assert table["Analog in 2 words consistent"] == (b"\xD1", 4, 0)
    assert table["Special 3 in + 2 out"] == (b"\xC0\x01\x02", 3, 2)
    assert table["Special in 4 words + manuf"] == (b"\x42\x43\xAA\xBB", 8, 0)
    assert table["Special out 2 consistent"] == (b"\x80\x81", 0, 2)
    assert table["Empty slot"] == (b"\x00", 0, 0)
    assert build_chk_cfg(gsd, ["8 DI", "Special 3 in + 2 out", "Empty slot"]) == b"\x10\xC0\x01\x02\x00"


# ---------------------------------------------------------------------------------------------
# Cfg identifier decoding (golden vectors from the PROFIBUS-DP standard's Cfg byte layout)
# ---------------------------------------------------------------------------------------------

def test_decode_cfg_general_format():
    cases = {
        "13": (4, 0), "11": (2, 0), "23": (0, 4), "21": (0, 2), "10": (1, 0), "2F": (0, 16),
        "3D": (14, 14), "BD": (14, 14), "76": (14, 14), "F6": (14, 14), "2D 1D": (14, 14),
        "50": (2, 0), "6F": (0, 32),
    }
    for text, lengths in cases.items():
        assert cfg_io_lengths(bytes.fromhex(text)) == lengths, text
    (bd,) = decode_cfg(b"\xBD")
    assert bd.consistent and not bd.words and not bd.special and bd.describe() == "in/out 14 consistent"
    (f6,) = decode_cfg(b"\xF6")
    assert f6.words and f6.consistent


def test_decode_cfg_special_format():
    assert cfg_io_lengths(bytes.fromhex("C0 0D 0D")) == (14, 14)
    assert cfg_io_lengths(bytes.fromhex("C0 8D 8D")) == (14, 14)
    assert cfg_io_lengths(bytes.fromhex("40 0D")) == (14, 0)          # input length byte
    assert cfg_io_lengths(bytes.fromhex("80 4D")) == (0, 28)          # output, 14 words
    assert cfg_io_lengths(bytes.fromhex("80 3F")) == (0, 64)          # longest: 64 units
    (ident,) = decode_cfg(bytes.fromhex("42 43 AA BB"))
    assert ident.special and ident.input_len == 8 and ident.manufacturer_data == b"\xAA\xBB"
    (empty,) = decode_cfg(b"\x00")
    assert empty.describe() == "empty slot"
    (both,) = decode_cfg(bytes.fromhex("C0 01 82"))
    assert (both.output_len, both.input_len, both.consistent) == (2, 3, True)   # output first
    assert [i.raw for i in decode_cfg(bytes.fromhex("13 C0 0D 0D 21"))] == [
        b"\x13", b"\xC0\x0D\x0D", b"\x21"]


def test_decode_cfg_truncated_special_format():
    for text in ("C0 0D", "40", "83 01 02", "03 AA"):
        try:
            decode_cfg(bytes.fromhex(text))
        except ConfigError as exc:
            assert "needs" in str(exc) and "more byte" in str(exc), str(exc)
        else:
            raise AssertionError(text)


# ---------------------------------------------------------------------------------------------
# Error branches: every message names the file, the line and the keyword
# ---------------------------------------------------------------------------------------------

def test_error_missing_ident_number():
    exc = gsd_error('Vendor_Name = "x"\n')
    assert str(exc) == "bad.gsd: Ident_Number: missing (every GSD must declare Ident_Number)"
    assert isinstance(exc, GsdParseError) and exc.key == "Ident_Number" and exc.line is None


def test_error_bad_number():
    exc = gsd_error('Vendor_Name = "x"\nIdent_Number = 0x12G4\n')
    assert str(exc) == "bad.gsd:2: Ident_Number: bad number '0x12G4' (expected decimal or 0x hex)"
    assert exc.line == 2


def test_error_number_out_of_range():
    assert str(gsd_error("Ident_Number = 0x10000")) == \
        "bad.gsd:1: Ident_Number: 65536 is outside 0..65535"
    exc = gsd_error(MINIMAL + "Max_Input_Len = 245\n")
    assert str(exc) == "bad.gsd:3: Max_Input_Len: 245 is outside 0..244"


def test_error_bool_and_string_values():
    assert str(gsd_error(MINIMAL + "Fail_Safe = 2\n")) == "bad.gsd:3: Fail_Safe: expected 0 or 1, got '2'"
    assert str(gsd_error(MINIMAL + "Model_Name = abc\n")) == \
        "bad.gsd:3: Model_Name: expected a quoted string, got 'abc'"
    assert "9.6_supp: expected 0 or 1" in str(gsd_error(MINIMAL + "9.6_supp = yes\n"))
    assert "MaxTsdr_12M: bad number" in str(gsd_error(MINIMAL + "MaxTsdr_12M = x\n"))
    assert "User_Prm_Data: bad byte list" in str(gsd_error(MINIMAL + "User_Prm_Data = 1,,2\n"))
    assert "User_Prm_Data: byte value above 0xFF" in str(gsd_error(MINIMAL + "User_Prm_Data = 0x100\n"))


def test_error_unterminated_module():
    exc = gsd_error(MINIMAL + 'Module = "4 Bytes In" 0x13\n; comment\n1\n')
    assert str(exc) == ("bad.gsd:3: Module: unterminated Module '4 Bytes In': missing EndModule "
                        "before the end of the file")


def test_error_module_inside_module():
    exc = gsd_error(MINIMAL + 'Module = "a" 0x13\nModule = "b" 0x23\nEndModule\n')
    assert str(exc) == ("bad.gsd:4: Module: new block inside Module 'a' started on line 3 "
                        "(missing EndModule)")


def test_error_wrong_block_end():
    exc = gsd_error(MINIMAL + 'PrmText = 1\nText(0) = "x"\nEndModule\n')
    assert str(exc) == ("bad.gsd:5: EndModule: found inside PrmText started on line 3 "
                        "(expected EndPrmText)")
    assert str(gsd_error(MINIMAL + "EndModule\n")) == \
        "bad.gsd:3: EndModule: block end without a matching block start"


def test_error_module_cfg_bytes():
    assert str(gsd_error(MINIMAL + 'Module = "a"\nEndModule\n')) == \
        "bad.gsd:3: Module: module 'a' has no Cfg bytes"
    assert str(gsd_error(MINIMAL + 'Module = "a" 0x13 zz\nEndModule\n')) == \
        "bad.gsd:3: Module: module 'a': bad Cfg byte list '0x13 zz'"
    assert "Cfg byte above 0xFF" in str(gsd_error(MINIMAL + 'Module = "a" 0x130\nEndModule\n'))
    exc = gsd_error(MINIMAL + 'Module = "a" 0xC0 0x0D\nEndModule\n')
    assert str(exc).startswith("bad.gsd:3: Module: module 'a': Cfg identifier 0xC0 at offset 0 needs")
    assert "expected '\"name\" cfg-bytes" in str(gsd_error(MINIMAL + "Module = a 0x13\nEndModule\n"))
    exc = gsd_error(MINIMAL + 'Module = "a" 0x13\n???\nEndModule\n')
    assert str(exc) == ("bad.gsd:4: in Module 'a': expected 'Keyword = value' or a module "
                        "reference number, got '???'")


def test_error_unterminated_string_and_garbage():
    assert str(gsd_error('Vendor_Name = "abc\nIdent_Number = 1\n')) == \
        "bad.gsd:1: unterminated string (missing closing '\"')"
    assert str(gsd_error(MINIMAL + "just some words\n")) == \
        "bad.gsd:3: expected 'Keyword = value', got 'just some words'"
    assert "unsupported preprocessor line '#if 1'" in str(gsd_error("#if 1\n" + MINIMAL))


def test_error_duplicate_keyword():
    exc = gsd_error(MINIMAL + "IDENT_NUMBER = 0x4321\n")
    assert str(exc) == "bad.gsd:3: IDENT_NUMBER: given twice (first on line 2)"


def test_error_ext_user_prm_data():
    assert "no ExtUserPrmData with reference 7" in str(
        gsd_error(MINIMAL + "Ext_User_Prm_Data_Ref(0) = 7\n"))
    exc = gsd_error(MINIMAL + "User_Prm_Data_Len = 1\nExt_User_Prm_Data_Const(1) = 5\n")
    assert str(exc) == ("bad.gsd:4: Ext_User_Prm_Data_Const(1): offset 1 is beyond "
                        "User_Prm_Data_Len = 1")
    exc = gsd_error(MINIMAL + 'ExtUserPrmData = 1 "x"\nBit(9) 0 0-1\nEndExtUserPrmData\n')
    assert str(exc) == "bad.gsd:4: ExtUserPrmData 1: bit range 9-9 is outside 0-7"
    exc = gsd_error(MINIMAL + 'ExtUserPrmData = 1 "x"\nUnsigned8 300 0-255\nEndExtUserPrmData\n')
    assert "default 300 does not fit Unsigned8 (0..255)" in str(exc)
    exc = gsd_error(MINIMAL + 'ExtUserPrmData = 1 "x"\nPrm_Text_Ref = 1\nEndExtUserPrmData\n')
    assert str(exc) == "bad.gsd:3: ExtUserPrmData: ExtUserPrmData 1 has no data type line"
    exc = gsd_error(MINIMAL + "User_Prm_Data_Len = 1\nUser_Prm_Data = 1,2\n")
    assert "User_Prm_Data: 2 bytes but User_Prm_Data_Len = 1" in str(exc)


def test_error_parse_gsd_needs_text():
    try:
        parse_gsd(b"Ident_Number = 1", source="x.gsd")  # type: ignore[arg-type]
    except GsdError as exc:
        assert "x.gsd: GSD text must be str" in str(exc)
    else:
        raise AssertionError


def test_error_load_missing_file():
    try:
        load_gsd("/nonexistent/dir/none.gsd")
    except GsdError as exc:
        assert str(exc).startswith("/nonexistent/dir/none.gsd: cannot read GSD file:")
    else:
        raise AssertionError


def test_error_unknown_module_name():
    gsd = load_gsd(ROBOT_GSD)
    message = chk_cfg_error(gsd, ["4 Bytes In", "4 Byte In"])
    assert message.startswith(ROBOT_GSD + ": Module: unknown module '4 Byte In'; did you mean '4 Bytes In'")


def test_error_chk_cfg_over_limits():
    gsd = load_gsd(ROBOT_GSD)
    assert chk_cfg_error(gsd, THESIS_MODULES + ["1 Byte In"]).startswith(
        ROBOT_GSD + ": Max_Module: 9 modules exceed Max_Module = 8")
    assert chk_cfg_error(gsd, ["32 Bytes In"] * 2 + ["8 Bytes In", "1 Byte In"]).startswith(
        ROBOT_GSD + ": Max_Input_Len: 73 input bytes exceed Max_Input_Len = 72")
    assert chk_cfg_error(gsd, ["32 Bytes Out"] * 2 + ["8 Bytes Out", "1 Byte Out"]).startswith(
        ROBOT_GSD + ": Max_Output_Len: 73 output bytes exceed Max_Output_Len = 72")
    text = MINIMAL + ("Modular_Station = 1\nMax_Module = 4\nMax_Input_Len = 8\nMax_Output_Len = 8\n"
                      "Max_Data_Len = 10\nModule = \"6 in\" 0x15\nEndModule\n"
                      "Module = \"6 out\" 0x25\nEndModule\n")
    message = chk_cfg_error(parse_gsd(text, "d.gsd"), ["6 in", "6 out"])
    assert message == ("d.gsd: Max_Data_Len: 12 input + output bytes exceed Max_Data_Len = 10 "
                       "(selection: 6 in, 6 out)")


def test_error_chk_cfg_selection_shape():
    gsd = load_gsd(ROBOT_GSD)
    assert "no modules selected" in chk_cfg_error(gsd, [])
    assert "got the single string '4 Bytes In'" in chk_cfg_error(gsd, "4 Bytes In")


def test_compact_station_allows_one_module():
    gsd = parse_gsd(MINIMAL + 'Module = "all" 0x3D\nEndModule\nModule = "other" 0x13\nEndModule\n', "c.gsd")
    assert build_chk_cfg(gsd, ["all"]) == b"\x3D"
    assert "2 modules exceed Max_Module = 1" in chk_cfg_error(gsd, ["all", "other"])


def test_blank_lines_crlf_and_bom():
    gsd = parse_gsd("\ufeff#Profibus_DP\r\n\r\n  Ident_Number = 7 ; c\r\n", "w.gsd")
    assert gsd.ident_number == 7 and gsd.modules == ()


# ---------------------------------------------------------------------------------------------
# Fuzzing: random input either parses or raises GsdError, nothing else
# ---------------------------------------------------------------------------------------------

def _parse_or_gsd_error(text: str) -> None:
    try:
        gsd = parse_gsd(text, source="fuzz.gsd")
    except GsdError as exc:
        assert str(exc).startswith("fuzz.gsd")
        return
    assert isinstance(gsd, Gsd)
    gsd.summary()
    for mod in gsd.modules:
        try:
            build_chk_cfg(gsd, [mod.name])
        except GsdError:
            pass


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.text(max_size=400))
def test_fuzz_random_text(text):
    _parse_or_gsd_error(text)


_FRAGMENTS = [
    "Ident_Number = 0x06C6", "Ident_Number = ", "Module = \"m\" 0x13", "Module = \"m\" 0xC0 0x01",
    "Module = \"x\"", "EndModule", "1", "Ext_Module_Prm_Data_Len = 2", "Ext_User_Prm_Data_Ref(0) = 1",
    "Ext_User_Prm_Data_Const(0) = 0x01,0x02", "ExtUserPrmData = 1 \"p\"", "Bit(3) 1 0-1",
    "BitArea(2-5) 3 0-7", "Unsigned16 5 0-9", "Signed8 -3 -5-5", "EndExtUserPrmData",
    "PrmText = 1", "Text(0) = \"a\"", "EndPrmText", "User_Prm_Data_Len = 2", "User_Prm_Data = 1,2",
    "Max_Module = 2", "Modular_Station = 1", "9.6_supp = 1", "MaxTsdr_9.6 = 60", "#Profibus_DP",
    "\"open", "\\", ";", "x = \"a;b\"", "Unit_Diag_Area = 1-2", "Unit_Diag_Area_End", "Data_Area_Beg",
    "Max_Input_Len = 300", "Fail_Safe = 1", "=", "()", "(99999999999) = 1",
]


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.one_of(st.sampled_from(_FRAGMENTS), st.text(max_size=12)), max_size=25),
       st.sampled_from(["\n", "\r\n", "\r", " \\\n"]))
def test_fuzz_gsd_like_lines(lines, newline):
    _parse_or_gsd_error(newline.join(lines))


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=40))
def test_fuzz_decode_cfg(data):
    try:
        idents = decode_cfg(data)
    except ConfigError:
        return
    assert b"".join(i.raw for i in idents) == data


# ---------------------------------------------------------------------------------------------
# Command line
# ---------------------------------------------------------------------------------------------

def run_cli(*args: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=SRC)
    return subprocess.run([PYTHON, "-m", "pyprofibus_vendor.gsd"] + list(args), env=env,
                          stdout=subprocess.PIPE, stderr=subprocess.PIPE, universal_newlines=True,
                          timeout=60)


def test_cli_help():
    result = run_cli("--help")
    assert result.returncode == 0 and "--modules" in result.stdout and "Exit status" in result.stdout


def test_cli_usage_errors():
    assert run_cli().returncode == 2
    result = run_cli(ROBOT_GSD, "--bogus")
    assert result.returncode == 2 and "unrecognized arguments" in result.stderr


def test_cli_summary():
    result = run_cli(ROBOT_GSD)
    assert result.returncode == 0, result.stderr
    assert "Ident_Number      0x06C6" in result.stdout
    assert "9.6k" in result.stdout and "12M" in result.stdout
    assert "input 72, output 72, data 144" in result.stdout
    assert '"4 Bytes In"' in result.stdout and "Cfg 13" in result.stdout


def test_cli_modules():
    result = run_cli(ROBOT_GSD, "--modules", ",".join(THESIS_MODULES))
    assert result.returncode == 0, result.stderr
    assert "Chk_Cfg           13 13 13 11 23 23 23 21" in result.stdout
    assert "Input  (slave -> master) 14 bytes" in result.stdout
    assert "Output (master -> slave) 14 bytes" in result.stdout


def test_cli_json():
    result = run_cli(ROBOT_GSD, "--json", "--modules", ",".join(OUTPUTS_FIRST))
    assert result.returncode == 0, result.stderr
    data = json.loads(result.stdout)
    assert data["ident_number"] == "0x06C6"
    assert data["selection"] == {"modules": OUTPUTS_FIRST, "chk_cfg": "23 23 23 21 13 13 13 11",
                                 "input_len": 14, "output_len": 14, "user_prm_data": ""}


def test_cli_parse_error_names_file_and_line():
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "broken.gsd")
        with open(path, "w") as handle:
            handle.write('#Profibus_DP\nIdent_Number = 0x06C6\nMax_Module = many\n')
        result = run_cli(path)
    assert result.returncode == 1
    assert result.stderr.strip() == "error: %s:3: Max_Module: bad number 'many' (expected decimal " \
                                    "or 0x hex)" % path
    assert result.stdout == ""


def test_cli_bad_selection_and_missing_file():
    result = run_cli(ROBOT_GSD, "--modules", "32 Bytes In,32 Bytes In,32 Bytes In")
    assert result.returncode == 1 and "exceed Max_Input_Len = 72" in result.stderr
    result = run_cli(ROBOT_GSD, "--modules", "nope")
    assert result.returncode == 1 and "unknown module 'nope'" in result.stderr
    result = run_cli("/nonexistent.gsd")
    assert result.returncode == 1 and "/nonexistent.gsd: cannot read GSD file" in result.stderr


def test_main_in_process_return_codes():
    assert main([TEST_GSD, "--modules", "8 DI,Special 3 in + 2 out"]) == 0
    assert main(["--help"]) == 0
    assert main([]) == 2
    assert main([TEST_GSD, "--modules", "8 DI,8 DI,8 DI,8 DI,8 DI"]) == 1
