"""vr_driver.csr: the .csr writer / parser (golden files, round trips, every error naming its line),
the joint-angle convention, the waypoint export with its safety envelope, and the command line
(in-process and as subprocesses, incl. the rosrun shim). Plain asserts, no pytest fixtures."""
from __future__ import annotations

import contextlib
import datetime
import io
import math
import os
import subprocess
import sys
import tempfile

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vr_driver import csr
from vr_driver.csr import (CsrProgram, Description, ExportSettings, JointConvention, Move, Pose, RawCommand,
                           RawSection, Tool, Variable)
from vr_driver.errors import CsrConversionError, CsrError
from vr_driver.params import DriverParams
from vr_driver.poses import ControllerPose, Workspace

HERE = os.path.dirname(os.path.abspath(__file__))
PKG = os.path.dirname(HERE)
REPO = os.path.dirname(PKG)
DATA = os.path.join(HERE, "data")
EXAMPLES = os.path.join(PKG, "examples")
PYTHONPATH = os.pathsep.join(os.path.join(REPO, p, "src") for p in ("vr_driver", "panasonic_vr006l_support",
                                                                    "pyprofibus_vendor"))
DATE = datetime.datetime(2024, 1, 1, 12, 0, 0)


def read(path):
    with open(path, newline="") as f:
        return f.read()


def kin():
    return csr.kinematics_for(DriverParams())


def raises(exc_type, func, *args, **kwargs):
    with pytest.raises(exc_type) as info:
        func(*args, **kwargs)
    return info.value


# ======================================================================================== golden

def golden_program():
    """The program of test/data/golden_aj.csr, built through the API (not the parser)."""
    variables = list(csr.default_variables())
    variables[5] = Variable("LI", "LI001", "counter", "5")
    return CsrProgram(
        Description(comment="golden example", sub_comment1="written by hand",
                    created=DATE, updated=datetime.datetime(2024, 2, 29, 23, 59, 58)),
        (Pose("P001", "AJ", (0, 0, 0, 0, -90, 0)),
         Pose("P002", "AJ", (30, 10, -5, 0, -85, 0)),
         Pose("P003", "AJ", (-12.345, 20.5, -6, 1.25, -60.125, 170)),
         Pose("P004", "AJ", (-10, 25, -8, 0, -60, 0)),
         Pose("P005", "AJ", (-5, 28, -10, 0, -60, 0))),
        (Tool("1:TOOL01"),
         Move("MOVEP", "P001", 10.0),
         Move("MOVEP", "P002", 15.0),
         RawCommand("DELAY, 0.50"),
         Move("MOVEL", "P003", 2.5, smooth=3),
         Move("MOVEC", "P003", 5.0),
         Move("MOVEC", "P004", 5.0, option="CIR_NORMAL"),
         Move("MOVEC", "P005", 5.0),
         RawCommand("REM back to the start"),
         Move("MOVEP", "P001", 10.0, smooth=0)),
        tuple(variables))


def test_writer_reproduces_the_hand_written_golden_file():
    assert csr.format_program(golden_program(), "\n") == read(os.path.join(DATA, "golden_aj.csr"))


def test_parser_reads_the_golden_file():
    p = csr.read_program(os.path.join(DATA, "golden_aj.csr"))
    assert p == golden_program()
    d = p.description
    assert (d.robot, d.comment, d.sub_comment1, d.tool, d.creator, d.edit) == \
        ("VR-006L", "golden example", "written by hand", "1:TOOL01", "ROS", 0)
    assert d.updated == datetime.datetime(2024, 2, 29, 23, 59, 58)
    assert p.pose("P003").values == (-12.345, 20.5, -6.0, 1.25, -60.125, 170.0)
    assert p.pose("P003").line == 19
    moves = p.moves()
    assert [m.opcode for m in moves] == ["MOVEP", "MOVEP", "MOVEL", "MOVEC", "MOVEC", "MOVEC", "MOVEP"]
    assert moves[4].option == "CIR_NORMAL" and moves[2].smooth == 3 and moves[2].speed == 2.5
    raw = [c.text for c in p.commands if isinstance(c, RawCommand)]
    assert raw == ["DELAY, 0.50", "REM back to the start"]
    assert p.variables[5] == Variable("LI", "LI001", "counter", "5")


def test_golden_au_file_keeps_work_section_key_spelling_and_no_variables():
    path = os.path.join(DATA, "golden_au.csr")
    text = read(path)
    p = csr.parse_program(text, path)
    assert p.variables is None
    assert p.pose_columns == csr.CARTESIAN_COLUMNS
    assert p.extra_sections == (RawSection("Work", ("Position, 5, 0, 0, 10, -0, 0, 0",), "Description"),)
    assert p.description.user_coordinates_key == "User coordinate"
    assert p.description.robot == "TA1400(G3)" and p.description.edit == 1
    assert p.pose("P2").values == (1000.0, -300.0, 450.0, 0.0, 80.0, 0.0)
    assert p.moves()[1].weld == "W" and p.moves()[1].smooth == 5
    assert csr.format_program(p, "\n") == text


def test_crlf_is_the_default_and_both_line_ends_read_back():
    text_lf = read(os.path.join(DATA, "golden_aj.csr"))
    program = csr.parse_program(text_lf)
    text_crlf = csr.format_program(program)
    assert text_crlf == text_lf.replace("\n", "\r\n")
    assert csr.parse_program(text_crlf) == program
    assert csr.program_bytes(program).count(b"\r\n") == text_lf.count("\n")


# ==================================================================================== round trips

def test_write_parse_write_is_identical_and_values_match_to_printed_precision():
    import random
    rng = random.Random(7)
    joints = [tuple(rng.uniform(-170, 170) for _ in range(6)) for _ in range(20)]
    poses = tuple(Pose("P%03d" % (i + 1), "AJ", q) for i, q in enumerate(joints))
    commands = (Tool(),) + tuple(Move("MOVEP", p.name, rng.uniform(1, 100)) for p in poses)
    program = CsrProgram(Description(created=DATE), poses, commands)
    text = csr.format_program(program)
    back = csr.parse_program(text)
    assert csr.format_program(back) == text
    for q, p in zip(joints, back.poses):
        assert all(abs(a - b) <= 0.0005 + 1e-9 for a, b in zip(q, p.values))
    for m, n in zip(program.moves(), back.moves()):
        assert abs(m.speed - n.speed) <= 0.005 + 1e-9


def test_negative_zero_is_written_as_zero():
    program = CsrProgram(Description(created=DATE), (Pose("P1", "AJ", (-0.0, -0.0001, 0, 0, 0, 0)),),
                         (Move("MOVEP", "P1", 10),))
    assert "P1, AJ, 0.000, 0.000, 0.000," in csr.format_program(program)


def test_fifteen_decimals_as_dtps_writes_them_survive_a_round_trip():
    text = read(os.path.join(DATA, "golden_aj.csr")).replace("-12.345,", "-12.345678901234567,")
    p = csr.parse_program(text)
    assert p.decimals == 15
    assert csr.parse_program(csr.format_program(p)).pose("P003").values[0] == pytest.approx(-12.345678901234567,
                                                                                           abs=1e-15)


_printable = st.text(st.characters(min_codepoint=32, max_codepoint=126, blacklist_characters=","), max_size=30)
_field_text = _printable.map(str.strip)


@st.composite
def programs(draw):
    n = draw(st.integers(1, 8))
    kinds = draw(st.lists(st.sampled_from(["AJ", "AU"]), min_size=n, max_size=n))
    kinds = [kinds[0]] * n if draw(st.booleans()) else kinds
    value = st.floats(-2000, 2000, allow_nan=False).map(lambda v: round(v, 3))
    poses = [Pose("P%03d" % (i + 1), k, tuple(draw(value) for _ in range(6))) for i, k in enumerate(kinds)]
    names = [p.name for p in poses]
    commands = [Tool("%d:TOOL%02d" % ((draw(st.integers(1, 30)),) * 2))]
    speed = st.floats(0.01, 180, allow_nan=False).map(lambda v: round(v, 2))
    for _ in range(draw(st.integers(0, 6))):
        what = draw(st.sampled_from(["p", "l", "c", "raw"]))
        point = draw(st.sampled_from(names))
        if what == "p":
            commands.append(Move("MOVEP", point, draw(speed), smooth=draw(st.integers(-1, 10))))
        elif what == "l":
            commands.append(Move("MOVEL", point, draw(speed), cl=draw(st.integers(0, 5)),
                                 weld=draw(st.sampled_from("NW"))))
        elif what == "c":
            for k in range(draw(st.integers(3, 4))):
                commands.append(Move("MOVEC", draw(st.sampled_from(names)), draw(speed),
                                     option=draw(st.sampled_from(["", "CIR_NORMAL", "CIR_SPLIT-OFF"]))))
        else:
            commands.append(RawCommand(draw(st.sampled_from(["DELAY, 1.00", "REM " + "x" * 3, "ARC-OFF, ArcEnd1.rpg, 1",
                                                             "OUT O1#(8:O1#008)=ON", "PAUSE, hello", "HOLD"]))))
    desc = Description(comment=draw(_field_text), creator=draw(_field_text)[:16].strip(), sub_comment1=draw(_field_text),
                       created=draw(st.datetimes(datetime.datetime(1990, 1, 1), datetime.datetime(2099, 12, 31))),
                       edit=draw(st.sampled_from([0, 1, 2])))
    one = Variable("LI", "LI001", draw(_field_text), str(draw(st.integers(-32768, 32767))))
    variables = draw(st.sampled_from([None, csr.default_variables(), (one,)]))
    return CsrProgram(desc, tuple(poses), tuple(commands), variables, None, draw(st.integers(0, 6)))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(programs(), st.sampled_from(["\r\n", "\n"]))
def test_random_programs_round_trip(program, newline):
    text = csr.format_program(program, newline)
    back = csr.parse_program(text)
    assert csr.format_program(back, newline) == text
    assert len(back.poses) == len(program.poses) and len(back.commands) == len(program.commands)
    tol = 0.5 * 10.0 ** -program.decimals + 1e-9
    for a, b in zip(program.poses, back.poses):
        assert all(abs(x - y) <= max(tol, abs(x) * 1e-12) for x, y in zip(a.values, b.values))


# ======================================================================= invalid files name the line

def _golden_lines():
    return read(os.path.join(DATA, "golden_aj.csr")).split("\n")


def _mutate(lineno, new):
    lines = _golden_lines()
    lines[lineno - 1] = new
    return "\n".join(lines)


BAD_FILES = [
    # (line, replacement, expected line, expected words in the message)
    (3, "Comment, this comment is much longer than thirty", 3, ["Comment", "at most 30"]),
    (8, "Creator, a creator named too long", 8, ["Creator", "at most 16"]),
    (11, "Update, 2018, 3, 7, 9, 35 55", 11, ["Update", "6 numbers"]),           # the thesis' missing comma
    (10, "Create, 2024, 02, 30, 12, 00, 00", 10, ["Create", "not a valid date"]),
    (6, "Mechanism, 1", 6, ["Mechanism"]),
    (13, "Edit, 3", 13, ["Edit"]),
    (17, "P001, AJ, 0.000, 0.000, 0.000, 0.000, -90.000", 17, ["pose P001", "5 values", "6 columns"]),
    (18, "P002, AJ, 30.000, 10.000, -5.000 0.000, -85.000, 0.000", 18, ["pose P002", "5 values"]),
    (18, "P002, AJ, 30.000, 10.000, -5.000, 0.000, -85.000, x", 18, ["pose P002 TW", "finite number"]),
    (16, "/Name, Type, RT, UA, FA, RW, BW, TW, G4, G5", 17, ["pose P001", "8 columns"]),   # thesis header bug
    (19, "P001, AJ, 0.000, 0.000, 0.000, 0.000, -90.000, 0.000", 19, ["pose P001", "used twice", "line 17"]),
    (29, "LI, LI001_TOO_LONG, , 0", 29, ["variable name", "at most 8"]),
    (29, "LI, LI001, a comment that is longer than thirty-two chars, 0", 29, ["comment", "at most 32"]),
    (29, "LI, LI001, , 99999", 29, ["LI001 value", "outside"]),
    (29, "LI, LI001, 0", 29, ["variable", "4 fields"]),
    (30, "LI, LI001, , 0", 30, ["variable LI001", "used twice", "line 29"]),
    (47, "MOVEP, P001, 10.00, m/min, N", 47, ["MOVEP", "6 fields"]),
    (47, "MOVEP, P001, -10.00, m/min, N, -1", 47, ["MOVEP speed", "outside"]),
    (47, "MOVEP, P001, fast, m/min, N, -1", 47, ["MOVEP speed", "finite number"]),
    (47, "MOVEP, P001, 500.00, m/min, N, -1", 47, ["MOVEP speed", "outside"]),
    (47, "MOVEP, P001, 10.00, mm/s, N, -1", 47, ["MOVEP unit"]),
    (47, "MOVEP, P001, 10.00, m/min, X, -1", 47, ["MOVEP N/W"]),
    (47, "MOVEP, P001, 10.00, m/min, N, 11", 47, ["MOVEP smooth level"]),
    (47, "MOVEP, P009, 10.00, m/min, N, -1", 47, ["MOVEP point", "not in [Pose]"]),
    (50, "MOVEL, P003, 2.50, m/min, 0, N, 3, CIR_NORMAL", 50, ["MOVEL", "7 fields"]),
    (52, "MOVEC, P004, 5.00, m/min, 0, N, -1, CIR_WRONG", 52, ["MOVEC option"]),
    (53, "MOVEL, P005, 5.00, m/min, 0, N, -1", 51, ["MOVEC", "at least 3", "has 2"]),
    (46, "TOOL, TOOL01", 46, ["TOOL", "n:NAME"]),
]


@pytest.mark.parametrize("lineno,new,line,words", BAD_FILES)
def test_invalid_file_errors_name_line_and_field(lineno, new, line, words):
    err = raises(CsrError, csr.parse_program, _mutate(lineno, new), "bad.csr")
    assert err.line == line, str(err)
    text = str(err)
    assert text.startswith("bad.csr:%d: " % line), text
    for word in words:
        assert word in text, (word, text)
    assert "\n" not in text


def test_structural_errors():
    lines = _golden_lines()
    no_command = "\n".join(lines[:lines.index("[Command]") - 1])
    assert "no [Command] section" in str(raises(CsrError, csr.parse_program, no_command))
    err = raises(CsrError, csr.parse_program, "junk\n" + "\n".join(lines))
    assert err.line == 1 and "before the first" in str(err)
    swapped = "\n".join(lines).replace("[Pose]", "[Tmp]").replace("[Variable]", "[Pose]").replace("[Tmp]", "[Variable]")
    assert raises(CsrError, csr.parse_program, swapped).line > 0
    no_robot = "\n".join(l for l in lines if not l.startswith("Robot"))
    err = raises(CsrError, csr.parse_program, no_robot)
    assert err.line == 1 and "no Robot line" in str(err)
    no_header = "\n".join(l for l in lines if not l.startswith("/Name"))
    assert raises(CsrError, csr.parse_program, no_header).line == 16
    twice = "\n".join(lines).replace("Tool, 1:TOOL01\n", "Tool, 1:TOOL01\nComment, again\n")
    err = raises(CsrError, csr.parse_program, twice)
    assert err.line == 8 and "twice" in str(err)


def test_unknown_description_keys_and_commands_are_kept_verbatim():
    text = "\n".join(_golden_lines()).replace("Edit, 0\n", "Edit, 0\nSomeNewKey, 1, 2\n").replace(
        "REM back to the start", "WEAVEP,  P003 ,2.00 , m/min")
    p = csr.parse_program(text)
    assert p.description.extra_lines == ("SomeNewKey, 1, 2",)
    assert RawCommand("WEAVEP,  P003 ,2.00 , m/min") in p.commands
    assert csr.format_program(p, "\n") == text


# =========================================================================== writer-side validation

def test_writer_refuses_values_the_format_cannot_hold():
    assert raises(CsrError, Description, comment="x" * 31).field == "Comment"
    assert "comma" in str(raises(CsrError, Description, comment="a, b"))
    assert raises(CsrError, Description, creator="c" * 17).field == "Creator"
    assert raises(CsrError, Description, comment=" padded").field == "Comment"
    assert raises(CsrError, Description, tool="TOOL01").field == "Tool"
    for bad in (0.0, -1.0, 180.01, float("nan"), float("inf"), "fast", None, True, 0.004):
        assert raises(CsrError, Move, "MOVEL", "P1", bad).field == "MOVEL speed", bad
    assert Move("MOVEP", "P1", 100.0, unit="%").line_text() == "MOVEP, P1, 100.00, %, N, -1"
    assert raises(CsrError, Move, "MOVEP", "P1", 101.0, unit="%").field == "MOVEP speed"
    assert raises(CsrError, Move, "MOVEJ", "P1", 10).field == "move opcode"
    assert raises(CsrError, Move, "MOVEL", "P1", 10, option="CIR_NORMAL").field == "MOVEL option"
    assert raises(CsrError, Pose, "P1", "AJ", (1, 2, 3, 4, 5)).field == "pose P1"
    assert raises(CsrError, Pose, "P 1", "AJ", (0,) * 6).field == "pose name"
    assert raises(CsrError, Pose, "P1", "AJ", (0, 0, 0, 0, 0, float("nan"))).field == "pose P1 value"
    assert raises(CsrError, RawCommand, "MOVEP, P1, 10.00, m/min, N, -1").field == "command"
    assert raises(CsrError, RawCommand, "[Pose]").field == "command"
    assert raises(CsrError, Variable, "LB", "LB001", "", "256").field == "variable LB001 value"
    assert raises(CsrError, Variable, "LR", "LR001", "", "x").field == "variable LR001 value"
    two_circ = CsrProgram(Description(created=DATE), (Pose("P1", "AJ", (0,) * 6),),
                          (Move("MOVEC", "P1", 5), Move("MOVEC", "P1", 5)))
    assert "at least 3" in str(raises(CsrError, csr.format_program, two_circ))
    undefined = CsrProgram(Description(created=DATE), (Pose("P1", "AJ", (0,) * 6),), (Move("MOVEP", "P2", 5),))
    assert "not in [Pose]" in str(raises(CsrError, csr.format_program, undefined))
    mixed = CsrProgram(Description(created=DATE), (Pose("P1", "AJ", (0,) * 6), Pose("P2", "AJ", (0,) * 7)), ())
    assert "7 values" in str(raises(CsrError, csr.format_program, mixed))
    non_ascii = CsrProgram(Description(comment="caf\u00e9", created=DATE), (), ())
    assert raises(CsrError, csr.program_bytes, non_ascii).line == 3


def test_write_program_replaces_never_appends():
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "out.csr")
        program = golden_program()
        csr.write_program(program, path)
        csr.write_program(program, path)
        assert read(path) == csr.format_program(program)
        assert os.listdir(tmp) == ["out.csr"]


# ======================================================================== joint-angle conventions

def test_default_convention_is_the_identity_in_degrees():
    c = JointConvention()
    q = (0.1, -0.2, 0.3, -0.4, 0.5, -0.6)
    assert c.to_aj(q) == pytest.approx([math.degrees(v) for v in q])
    assert c.from_aj(c.to_aj(q)) == pytest.approx(q)


def test_horizontal_fa_flips_and_offsets():
    c = JointConvention.from_options("horizontal", "UA,bw", ["BW=-90", "TW=5.5"])
    q = (0.1, 0.2, -0.3, 0.0, 0.5, 0.0)
    aj = c.to_aj(q)
    assert aj[1] == pytest.approx(-math.degrees(0.2))
    assert aj[2] == pytest.approx(math.degrees(-0.3 + 0.2))       # forearm angle to the horizontal
    assert aj[4] == pytest.approx(-math.degrees(0.5) - 90.0)
    assert aj[5] == pytest.approx(5.5)
    assert c.from_aj(aj) == pytest.approx(q)
    opposite = JointConvention("horizontal", coupling=-1)
    assert opposite.to_aj(q)[2] == pytest.approx(math.degrees(-0.3 - 0.2))
    assert opposite.from_aj(opposite.to_aj(q)) == pytest.approx(q)
    assert JointConvention.coupling_of(kin()) == 1                # joint_2, joint_3 both about +y
    assert "FA relative to the horizontal, flipped: UA,BW, offsets: BW-90,TW+5.5" == c.describe()


def test_convention_option_errors():
    assert raises(CsrError, JointConvention.from_options, "ua", "XX").field == "flip"
    assert raises(CsrError, JointConvention.from_options, "ua", "", ["BW"]).field == "offset"
    assert raises(CsrError, JointConvention.from_options, "ua", "", ["BW=abc"]).field == "offset BW"
    assert raises(CsrError, JointConvention, "vertical").field == "FA reference"


# ================================================================================ waypoint export

WAYPOINTS = """\
program:
  comment: unit test
  date: 2024-01-01 12:00:00
defaults:
  speed: 12.5
waypoints:
  - joints_deg: [0, 36.983, -16.045, 0, 24.063, 0]
  - pose: [1000, -300, 450, 0, 80, 0]
    move: lin
  - pose: [1000, -300, 300, 0, 80, 0]
    speed: 3
    smooth: 2
"""


def export(text, source="wp.yaml", **kwargs):
    wfile = csr.parse_waypoints(text, source)
    settings = ExportSettings(description=Description(created=DATE), **kwargs)
    return csr.export_program(wfile.waypoints, settings, kin())


def test_export_joint_and_cartesian_waypoints():
    k = kin()
    wfile = csr.parse_waypoints(WAYPOINTS, "wp.yaml")
    assert [w.line for w in wfile.waypoints] == [7, 8, 10]
    assert wfile.program["comment"] == "unit test" and wfile.defaults["speed"] == 12.5
    program = export(WAYPOINTS, default_speed=12.5)
    assert [p.name for p in program.poses] == ["P001", "P002", "P003"]
    assert program.commands[0] == Tool("1:TOOL01")
    assert [c.line_text() for c in program.commands[1:]] == [
        "MOVEP, P001, 12.50, m/min, N, -1", "MOVEL, P002, 12.50, m/min, 0, N, -1", "MOVEP, P003, 3.00, m/min, N, 2"]
    assert program.poses[0].values == pytest.approx((0, 36.983, -16.045, 0, 24.063, 0))
    for pose, target in zip(program.poses[1:], ((1000, -300, 450, 0, 80, 0), (1000, -300, 300, 0, 80, 0))):
        q = JointConvention().from_aj([round(v, 3) for v in pose.values])
        dp, da = k.fk_pose(q).distance_to(ControllerPose(*target))
        assert dp < 0.05 and da < 0.01                 # mm, deg: 3 printed decimals of a degree
    # seeded point to point: no configuration flip between neighbours
    assert max(abs(a - b) for a, b in zip(program.poses[1].values, program.poses[2].values)) < 20


def test_export_writes_au_rows_when_asked():
    program = export("- pose: [1120, 0, 725, 0, 45, 0]\n- pose: [1000, -300, 450, 0, 80, 0]\n", cartesian="au")
    assert program.pose_columns == csr.CARTESIAN_COLUMNS
    assert program.poses[1] == Pose("P002", "AU", (1000, -300, 450, 0, 80, 0))


def test_refused_waypoints_are_all_reported_by_input_line():
    text = """\
waypoints:
  - pose: [1120, 0, 725, 0, 45, 0]
  - pose: [1500, 0, 725, 0, 45, 0]
  - pose: [1390, 0, 100, 0, 0, 0]
  - joints_deg: [0, 0, 0, 0, 0, 400]
  - joints_deg: [150, 0, 0, 0, 0, 0]
  - pose: [1120, 0, 725, 0, 45, 0]
"""
    err = raises(CsrConversionError, export, text)
    lines = [(p.line, p.field) for p in err.problems]
    assert lines == [(3, "waypoint 2"), (4, "waypoint 3"), (5, "waypoint 4"), (6, "waypoint 5")]
    messages = [str(p) for p in err.problems]
    assert "outside the workspace" in messages[0] and "X = 1500" in messages[0]
    assert "no IK solution" in messages[1]
    assert "joint_6" in messages[2] and "limits" in messages[2]
    assert "TCP at these joints" in messages[3] and "workspace" in messages[3]
    assert str(err).startswith("wp.yaml:3: waypoint 2:") and "(and 3 more)" in str(err)


def test_workspace_box_is_the_one_given():
    small = Workspace(x=(100.0, 1000.0))
    err = raises(CsrConversionError, export, "- pose: [1120, 0, 725, 0, 45, 0]\n", workspace=small)
    assert "X = 1120" in str(err)


BAD_WAYPOINTS = [
    ("- pose: [1120, 0, 725, 0, 45]\n", 1, "waypoint 1 pose"),
    ("- joints: [0, 0, 0, 0, 0, .nan]\n", 1, "waypoint 1 joints[5]"),
    ("- pose: [1120, 0, 725, 0, 45, 0]\n  speed: 0\n", 1, "waypoint 1 speed"),
    ("- pose: [1120, 0, 725, 0, 45, 0]\n  move: spline\n", 1, "waypoint 1 move"),
    ("- pose: [1120, 0, 725, 0, 45, 0]\n  joints: [0, 0, 0, 0, 0, 0]\n", 1, "waypoint 1"),
    ("- pose: [1120, 0, 725, 0, 45, 0]\n- {psoe: [1, 2, 3, 4, 5, 6]}\n", 2, "waypoint 2"),
    ("- [1120, 0, 725, 0, 45, 0]\n", 1, "waypoint 1"),
    ("waypoints: []\n", 1, "waypoints"),
    ("waypoints:\n- pose: [1120, 0, 725, 0, 45, 0]\nprogram: {colour: red}\n", 3, "program"),
    ("wp: [1, 2]\n", 1, "input"),
    ("- pose: [1120, 0, 725\n", 2, "input"),
]


@pytest.mark.parametrize("text,line,field", BAD_WAYPOINTS)
def test_bad_waypoint_files_name_the_line(text, line, field):
    err = raises(CsrError, csr.parse_waypoints, text, "wp.yaml")
    assert (err.line, err.field) == (line, field), str(err)
    assert str(err).startswith("wp.yaml:%d: %s" % (line, field))


def test_circle_runs_need_three_points():
    text = "- joints_deg: [0, 30, 0, 0, 30, 0]\n- {joints_deg: [5, 30, 0, 0, 30, 0], move: circ}\n" \
           "- {joints_deg: [10, 30, 0, 0, 30, 0], move: circ}\n- joints_deg: [0, 30, 0, 0, 30, 0]\n"
    err = raises(CsrError, export, text)
    assert err.line == 2 and "at least 3" in str(err)


TRAJECTORY = """\
header:
  seq: 3
  stamp:
    secs: 0
    nsecs:         0
  frame_id: ''
joint_names: [joint_3, joint_1, joint_2, joint_4, joint_5, joint_6]
points:
  -
    positions: [-0.280043, 0.0, 0.645469, 0.0, 0.419972, 0.0]
    velocities: []
    accelerations: []
    effort: []
    time_from_start:
      secs: 0
      nsecs:         0
  -
    positions: [-0.25, 0.1, 0.6, 0.0, 0.4, 0.1]
    velocities: []
    accelerations: []
    effort: []
    time_from_start:
      secs: 1
      nsecs:  50000000
---
"""


def test_rostopic_echo_dump_of_a_joint_trajectory():
    wfile = csr.parse_waypoints(TRAJECTORY, "traj.yaml")
    assert wfile.kind == "trajectory"
    assert [w.line for w in wfile.waypoints] == [10, 18]
    assert wfile.waypoints[0].joints == (0.0, 0.645469, -0.280043, 0.0, 0.419972, 0.0)
    program = export(TRAJECTORY, "traj.yaml", default_speed=7.0)
    assert program.poses[1].values == pytest.approx([math.degrees(v) for v in (0.1, 0.6, -0.25, 0.0, 0.4, 0.1)])
    assert all(c.line_text().endswith("7.00, m/min, N, -1") for c in program.commands[1:])
    nested = "trajectory:\n  - joint_trajectory:\n" + "".join("      " + l + "\n" for l in TRAJECTORY.splitlines()[:-1])
    assert csr.parse_waypoints(nested, "display.yaml").waypoints[1].joints[0] == 0.1
    err = raises(CsrError, csr.parse_waypoints, TRAJECTORY.replace("joint_3,", "elbow,"), "traj.yaml")
    assert err.field == "joint_names" and err.line == 7 and "joint_3" in str(err)
    err = raises(CsrError, csr.parse_waypoints, TRAJECTORY.replace("[-0.25, 0.1,", "[0.1,"), "traj.yaml")
    assert (err.line, err.field) == (18, "point 2")


def test_csv_waypoints():
    text = "# pick\nmove, speed, x, y, z, rx, ry, rz, joint_1_deg, joint_2_deg, joint_3_deg, joint_4_deg, " \
           "joint_5_deg, joint_6_deg\n" \
           "ptp, 10, , , , , , , 0, 36.983, -16.045, 0, 24.063, 0\n\n" \
           "lin, 3, 1000, -300, 450, 0, 80, 0, , , , , ,\n"
    wfile = csr.parse_waypoints(text, "wp.csv")
    assert [w.line for w in wfile.waypoints] == [3, 5]
    assert wfile.waypoints[1].pose.as_tuple() == (1000, -300, 450, 0, 80, 0)
    assert wfile.waypoints[1].move.value == "lin" and wfile.waypoints[1].speed == 3.0
    err = raises(CsrError, csr.parse_waypoints, text.replace("1000, -300, 450", "1000, -300, "), "wp.csv")
    assert (err.line, err.field) == (5, "waypoint 2")
    err = raises(CsrError, csr.parse_waypoints, text.replace("lin, 3,", "lin, -3,"), "wp.csv")
    assert (err.line, err.field) == (5, "waypoint 2 speed")
    err = raises(CsrError, csr.parse_waypoints, "move, height\nptp, 3\n", "wp.csv")
    assert (err.line, err.field) == (1, "CSV header")


# ========================================================================= checking a program read back

def test_check_program_names_the_line_of_a_pose_outside_the_limits():
    text = _mutate(18, "P002, AJ, 30.000, 10.000, -5.000, 0.000, -85.000, 400.000")
    program = csr.parse_program(text, "in.csr")
    rows, problems = csr.check_program(program, kin(), JointConvention(), Workspace(), "in.csr")
    assert len(rows) == 5
    assert [(p.line, p.field) for p in problems] == [(18, "pose P002")]
    assert "joint_6" in str(problems[0])
    ok_rows, ok = csr.check_program(csr.read_program(os.path.join(EXAMPLES, "waypoints.csr")), kin(),
                                    JointConvention(), Workspace())
    assert ok == [] and "TCP (1120.0, 0.0, 725.0 mm, 0.0, 45.0, 0.0 deg)" in ok_rows[0]


def test_a_pose_exactly_at_a_limit_passes_after_rounding():
    k = kin()
    q = list(k.named_states["home"])
    q[2] = k.limits.upper[2]                                    # 1.3 rad = 74.4845...
    program = CsrProgram(Description(created=DATE), (Pose("P001", "AJ", JointConvention().to_aj(q)),),
                         (Move("MOVEP", "P001", 10),))
    back = csr.parse_program(csr.format_program(program))
    assert csr.check_program(back, k, JointConvention(), Workspace(x=(-2000, 2000), z=(-2000, 2000)))[1] == []


# ============================================================================= the command line

def run_main(*argv):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = csr.main(list(argv))
    return code, out.getvalue(), err.getvalue()


@pytest.mark.parametrize("name", ["waypoints", "axis_check"])
def test_committed_examples_equal_a_fresh_export(name):
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, name + ".csr")
        code, _, err = run_main(os.path.join(EXAMPLES, name + ".yaml"), "-o", out)
        assert code == 0, err
        fresh, committed = read(out), read(os.path.join(EXAMPLES, name + ".csr"))
    # compared line by line, so a git line-end normalisation of the committed file cannot break it
    assert fresh.splitlines() == committed.splitlines()
    assert fresh.endswith("\r\n")


def test_cli_options_override_the_file_and_convention_is_applied():
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "o.csr")
        code, _, err = run_main(os.path.join(EXAMPLES, "axis_check.yaml"), "-o", out, "--comment", "override",
                                "--speed", "20", "--fa-reference", "horizontal", "--flip", "BW",
                                "--offset", "BW=-90", "--newline", "lf", "--date", "2020-05-06T07:08:09")
        assert code == 0, err
        assert "FA relative to the horizontal, flipped: BW, offsets: BW-90" in err
        p = csr.read_program(out)
    assert p.description.comment == "override" and p.description.created == datetime.datetime(2020, 5, 6, 7, 8, 9)
    assert p.pose("P004").values == (0, 10, 10, 0, -90, 0)      # UA +10 couples into FA, BW flipped and offset
    # precedence: a waypoint's own value > the option > the file's defaults block > built-in
    assert all(m.speed == 20.0 for m in p.moves())


def test_cli_usage_errors_are_one_line_exit_2():
    for argv in ([], ["a.yaml", "--from-csr", "b.csr"], ["--bogus"], ["--newline", "cr", "a.yaml"],
                 [os.path.join(DATA, "missing.yaml")],
                 [os.path.join(EXAMPLES, "waypoints.yaml"), "--comment", "x" * 31, "-o", os.devnull],
                 [os.path.join(EXAMPLES, "waypoints.yaml"), "--speed", "0", "-o", os.devnull],
                 [os.path.join(EXAMPLES, "waypoints.yaml"), "--flip", "XY", "-o", os.devnull]):
        code, out, err = run_main(*argv)
        assert code == 2, (argv, err)
        assert err.count("\n") == 1 and "error" in err and "Traceback" not in err, (argv, err)


def test_cli_from_csr_summary_reexport_and_refusal():
    code, out, err = run_main("--from-csr", os.path.join(EXAMPLES, "waypoints.csr"))
    assert code == 0, err
    assert "program 'csr_export example'" in out and "poses: 9 (AJ 9)" in out and "MOVEC 3" in out
    with tempfile.TemporaryDirectory() as tmp:
        out_path = os.path.join(tmp, "re.csr")
        code, _, err = run_main("--from-csr", os.path.join(DATA, "golden_au.csr"), "-o", out_path, "--newline", "lf")
        assert code == 0, err
        assert read(out_path) == read(os.path.join(DATA, "golden_au.csr"))
        bad = os.path.join(tmp, "bad.csr")
        with open(bad, "w") as f:
            f.write(_mutate(18, "P002, AJ, 30.000, 10.000, -5.000, 0.000, -85.000, 400.000"))
        code, out, err = run_main("--from-csr", bad)
        assert code == 1 and "bad.csr:18: pose P002" in err and "1 pose(s) refused" in out
        code, _, err = run_main("--from-csr", bad, "-o", out_path)
        assert code == 1 and read(out_path) == read(os.path.join(DATA, "golden_au.csr"))   # not overwritten


def subprocess_run(argv, env_extra=None):
    env = dict(os.environ, PYTHONPATH=PYTHONPATH)
    env.update(env_extra or {})
    return subprocess.run(argv, capture_output=True, text=True, timeout=60, env=env, cwd=REPO)


def test_cli_subprocess_exit_codes_and_messages():
    with tempfile.TemporaryDirectory() as tmp:
        wp = os.path.join(tmp, "wp.yaml")
        with open(wp, "w") as f:
            f.write("waypoints:\n  - pose: [1120, 0, 725, 0, 45, 0]\n  - pose: [1390, 0, 100, 0, 0, 0]\n"
                    "  - joints_deg: [0, 0, 0, 0, 0, 400]\n")
        out = os.path.join(tmp, "wp.csr")
        proc = subprocess_run([sys.executable, "-m", "vr_driver.csr", wp, "-o", out])
        assert proc.returncode == 1, proc.stderr
        lines = proc.stderr.splitlines()
        assert len(lines) == 2 and "Traceback" not in proc.stderr
        assert "wp.yaml:3: waypoint 2: no IK solution" in lines[0] and "wp.yaml:4: waypoint 3:" in lines[1]
        assert not os.path.exists(out)                          # nothing written on failure
        bad = os.path.join(tmp, "bad.csr")
        with open(bad, "w") as f:
            f.write(_mutate(3, "Comment, this comment is much longer than thirty"))
        proc = subprocess_run([sys.executable, "-m", "vr_driver.csr", "--from-csr", bad])
        assert proc.returncode == 2 and proc.stderr.count("\n") == 1
        assert "bad.csr:3: Comment:" in proc.stderr and "Traceback" not in proc.stderr
        proc = subprocess_run([sys.executable, "-m", "vr_driver.csr", os.path.join(EXAMPLES, "waypoints.yaml")])
        assert proc.returncode == 0 and proc.stdout.startswith("[Description]\n")   # stdout: text mode reads CRLF
        assert proc.stderr == ""


def test_rosrun_shim_and_help():
    shim = os.path.join(PKG, "nodes", "csr_export")
    assert os.access(shim, os.X_OK)
    with open(shim) as f:
        assert f.readline().strip() == "#!/usr/bin/python3"
    proc = subprocess_run([shim, "--help"])
    assert proc.returncode == 0, proc.stderr
    for words in ("--fa-reference", "--flip", "--offset", "VERIFY ON THE REAL CONTROLLER", "exit codes",
                  "--from-topic", "--from-csr"):
        assert words in proc.stdout


def test_from_topic_without_a_master_is_an_input_error():
    proc = subprocess_run([sys.executable, "-m", "vr_driver.csr", "--from-topic", "/trajectory", "--timeout", "1"],
                          {"ROS_MASTER_URI": "http://127.0.0.1:1/"})
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.count("\n") == 1 and ("no ROS master" in proc.stderr or "needs ROS" in proc.stderr)


def test_csr_module_imports_without_ros():
    script = ("import sys\nfor m in ('rospy', 'rosgraph', 'rospkg', 'trajectory_msgs', 'std_msgs'):\n"
              "    sys.modules[m] = None\nimport vr_driver.csr\nprint('ok')\n")
    proc = subprocess_run([sys.executable, "-c", script])
    assert proc.returncode == 0 and proc.stdout.strip() == "ok", proc.stderr


def test_cli_errors_name_the_option_or_the_file_line():
    wp = os.path.join(EXAMPLES, "waypoints.yaml")
    code, _, err = run_main(wp, "--comment", "x" * 31, "-o", os.devnull)
    assert code == 2 and "error: --comment: " in err and "at most 30" in err
    with tempfile.TemporaryDirectory() as tmp:
        bad = os.path.join(tmp, "wp.yaml")
        with open(bad, "w") as f:
            f.write("program:\n  creator: a creator name too long\nwaypoints:\n  - pose: [1120, 0, 725, 0, 45, 0]\n")
        code, _, err = run_main(bad, "-o", os.devnull)
        assert code == 2 and "wp.yaml:2: program Creator: " in err, err
        code, _, err = run_main(wp, "-o", os.path.join(tmp, "no", "such", "dir.csr"))
        assert code == 2 and err.count("\n") == 1 and "cannot write" in err, err


def test_shift_jis_files_are_read_and_rewritten_in_their_encoding():
    text = read(os.path.join(DATA, "golden_aj.csr")).replace("SubComment1, written by hand",
                                                             "SubComment1, \u6eb6\u63a5")
    data = text.encode("cp932")
    decoded, encoding = csr.decode_csr(data)
    assert encoding == "cp932"
    program = csr.parse_program(decoded)
    assert program.description.sub_comment1 == "\u6eb6\u63a5"
    assert csr.program_bytes(program, "\n", encoding) == data
    assert raises(CsrError, csr.decode_csr, b"[P\x81\x20]", "x.csr").source == "x.csr"
