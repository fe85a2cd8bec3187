"""vr_driver.terminal.pose_input: parsing and validation of what an operator types, and the terminal dialogue
against a fake driver backend (ROS-free; the end-to-end version through a pseudo-terminal and the
real driver is test/pose_terminal_check.py)."""
from __future__ import annotations

import io
import os
import subprocess
import sys
import threading
from typing import List, Optional

import pytest

from vr_driver.kinematics.preview import MoveType
from vr_driver.terminal.pose_input import (EXIT_NO_DRIVER, EXIT_OK, EXIT_REFUSED, FIELDS, Backend, InputError,
                                  MoveHandle, MoveProgress, MoveResult, PoseRequest, PreviewResult,
                                  ProgressPrinter, RangeError, StatusInfo, Terminal, build_arg_parser,
                                  check_pose, check_value, fmt_number, parse_command, parse_move_type, parse_number,
                                  parse_pose_line, prompt_text, request_from_args)
from vr_driver.poses import HOME_POSE, ControllerPose, Workspace

WS = Workspace()
X, Y, Z, RX, RY, RZ = FIELDS


# ----------------------------------------------------------------------------------- parsing

def test_prompts_show_unit_range_and_default():
    assert prompt_text(X, WS, 1120.0) == "X [mm, 100..1400] (1120): "
    assert prompt_text(Y, WS, 0.0) == "Y [mm, -900..900] (0): "
    assert prompt_text(RY, WS, 45.0) == "Ry [deg, -180..180] (45): "
    assert prompt_text(X, WS, None, "Via ") == "Via X [mm, 100..1400]: "
    narrow = Workspace(x=(200.5, 900), angle=(-90, 90))
    assert prompt_text(X, narrow, 812.25) == "X [mm, 200.5..900] (812.25): "
    assert prompt_text(RZ, narrow, -0.0) == "Rz [deg, -90..90] (0): "


@pytest.mark.parametrize("text, expected", [
    ("", 1120.0), ("  ", 1120.0), ("1000", 1000.0), (" +1000 ", 1000.0), ("1.2e3", 1200.0),
    ("100", 100.0), ("1400", 1400.0), ("999.", 999.0), (".5e3", 500.0), ("0100", 100.0),
])
def test_numbers_and_the_default(text, expected):
    assert parse_number(text, X, WS, default=1120.0) == expected


@pytest.mark.parametrize("text, words, kind", [
    ("abc", "'abc' is not a number", InputError),
    ("12,5", "is not a number", InputError),
    ("0x10", "is not a number", InputError),
    ("1_000", "is not a number", InputError),
    ("nan", "'nan' is not a position: a finite number in 100..1400 mm", InputError),
    ("-inf", "is not a position", InputError),
    ("Infinity", "is not a position", InputError),
    ("1e999", "inf is not a position", InputError),
    ("1500", "X = 1500 mm is above the workspace: allowed 100..1400 mm", RangeError),
    ("99.9", "X = 99.9 mm is below the workspace: allowed 100..1400 mm", RangeError),
    ("1400.4", "X = 1400.4 mm is above the workspace", RangeError),     # the stated range, not the rounded one
])
def test_bad_numbers_say_what_is_wrong(text, words, kind):
    with pytest.raises(kind) as err:
        parse_number(text, X, WS, default=1120.0)
    assert words in str(err.value)
    assert str(err.value).startswith("X")


def test_rounding_to_what_is_sent_is_checked_too():
    ws = Workspace(x=(100.4, 1400.0))
    assert parse_number("1399.6", X, ws) == 1399.6           # sent as 1400
    with pytest.raises(RangeError, match=r"X = 100.45 mm is sent as 100 mm \(the controller takes whole mm\), "
                                         r"which is outside 100.4..1400 mm"):
        parse_number("100.45", X, ws)


def test_no_default_needs_a_value():
    with pytest.raises(InputError, match="a value is needed"):
        parse_number("", X, WS, default=None)


def test_angles_use_the_angle_range():
    assert parse_number("-180", RX, WS) == -180.0
    with pytest.raises(RangeError, match=r"Rz = 181 deg is above the workspace: allowed -180..180 deg"):
        parse_number("181", RZ, WS)


@pytest.mark.parametrize("text, kind", [
    ("ptp", MoveType.PTP), ("PTP", MoveType.PTP), ("p", MoveType.PTP), ("movep", MoveType.PTP), ("1", MoveType.PTP),
    ("lin", MoveType.LIN), ("l", MoveType.LIN), ("linear", MoveType.LIN), ("MOVEL", MoveType.LIN), ("2", MoveType.LIN),
    ("circ", MoveType.CIRC), ("c", MoveType.CIRC), ("movec", MoveType.CIRC), ("3", MoveType.CIRC),
])
def test_move_types(text, kind):
    assert parse_move_type(text) is kind


def test_move_type_default_and_errors():
    assert parse_move_type("", MoveType.LIN) is MoveType.LIN
    with pytest.raises(InputError, match="'spline' is not one of ptp, lin, circ"):
        parse_move_type("spline", MoveType.PTP)
    with pytest.raises(InputError, match="a value is needed"):
        parse_move_type("")


def test_pose_lines():
    r = parse_pose_line("1000 200 800 0 45 0", WS)
    assert (r.move_type, r.target, r.via) == (MoveType.PTP, ControllerPose(1000, 200, 800, 0, 45, 0), None)
    r = parse_pose_line("1000, 200, 800, 0, 45, 0, LIN", WS)
    assert r.move_type is MoveType.LIN
    r = parse_pose_line("1000 150 800 0 45 0 circ via 1100 0 800", WS)
    assert r.move_type is MoveType.CIRC
    assert r.via == ControllerPose(1100, 0, 800, 0, 45, 0)          # orientation of the target
    r = parse_pose_line("1000 150 800 0 45 0 circ VIA 1100 0 800 10 20 30", WS)
    assert r.via == ControllerPose(1100, 0, 800, 10, 20, 30)
    r = parse_pose_line("1000 150 800 0 45 0 via 1100 0 800", WS)     # via implies circ
    assert r.move_type is MoveType.CIRC


@pytest.mark.parametrize("line, words", [
    ("1000 200 800", "a pose line is x y z rx ry rz [ptp|lin|circ] [via x y z [rx ry rz]]; got 3"),
    ("1000 200 800 0 45 0 lin extra", "got 8"),
    ("1000 200 800 0 45 0 spline", "'spline' is not one of ptp, lin, circ"),
    ("1000 200 800 0 45 0 circ", "a circular move needs a via point"),
    ("1000 200 800 0 45 0 lin via 1100 0 800", "'via' is only for circular moves (circ), not LIN"),
    ("1000 200 800 0 45 0 circ via 1100 0", "the via point is 3 or 6 values"),
    ("1000 200 800 0 45 0 circ via 1100 x 800", "via Y: 'x' is not a number"),
    ("1000 200 800 0 45 0 circ via 1100 0 1500", "via Z = 1500 mm is above the workspace"),
    ("1000 nan 800 0 45 0", "Y: 'nan' is not a position"),
    ("1000 200 -5 0 45 0", "Z = -5 mm is below the workspace: allowed 0..1400 mm"),
])
def test_bad_pose_lines(line, words):
    with pytest.raises(InputError) as err:
        parse_pose_line(line, WS)
    assert words in str(err.value)


def test_commands():
    for word in ("home", "stop", "status", "history", "help", "quit"):
        assert parse_command(word) == word
        assert parse_command("  %s " % word.upper()) == word
    assert parse_command("exit") == parse_command("q") == "quit"
    assert parse_command("?") == "help"
    assert parse_command("1000") is None
    assert parse_command("") is None
    assert parse_command("homes") is None


def test_requests_know_what_is_sent():
    r = PoseRequest(MoveType.PTP, ControllerPose(1000.5, -200.5, 800.4, 0, 45, 0))
    assert r.sent_values() == [(1001, -201, 800, 0, 45, 0)]
    assert r.is_rounded()
    assert not PoseRequest(MoveType.PTP, HOME_POSE).is_rounded()
    with pytest.raises(InputError):
        PoseRequest(MoveType.CIRC, HOME_POSE)
    with pytest.raises(InputError):
        PoseRequest(MoveType.LIN, HOME_POSE, HOME_POSE)


def test_check_pose_takes_numbers_too():
    assert check_pose([1120, 0, 725, 0, 45, 0], WS) == HOME_POSE
    with pytest.raises(InputError, match="X: None is not a number"):
        check_pose([None, 0, 725, 0, 45, 0], WS)
    with pytest.raises(InputError, match="6 values"):
        check_pose([1, 2], WS)


def test_fmt_number():
    assert [fmt_number(v) for v in (1120.0, -0.0, 12.5, 0.1234, -900)] == ["1120", "0", "12.5", "0.123", "-900"]


# ----------------------------------------------------------------------------------- command line

def args(*argv):
    return build_arg_parser().parse_args(list(argv))


def test_command_line_requests():
    r = request_from_args(args("--pose", "1000", "-150", "800", "0", "45", "0", "--type", "lin"), WS)
    assert (r.move_type, r.target.y) == (MoveType.LIN, -150.0)
    r = request_from_args(args("--pose", "1000", "150", "800", "0", "45", "0", "--via", "1100", "0", "800",
                               "0", "45", "0"), WS)
    assert r.move_type is MoveType.CIRC
    assert request_from_args(args("--pose", *"1120 0 725 0 45 0".split()), WS).move_type is MoveType.PTP


@pytest.mark.parametrize("argv, kind, words", [
    (["--pose", "1120", "0", "nan", "0", "45", "0"], InputError, "Z: 'nan'"),
    (["--pose", "1120", "0", "725", "0", "45", "0", "--type", "circ"], InputError, "--type circ needs --via"),
    (["--pose", "1120", "0", "725", "0", "45", "0", "--type", "lin", "--via"] + ["1"] * 6, InputError,
     "only for --type circ"),
    (["--pose", "1120", "0", "725", "0", "45", "0", "--type", "x"], InputError, "not one of"),
    (["--pose", "1500", "0", "725", "0", "45", "0"], RangeError, "X = 1500 mm is above"),
    (["--type", "lin"], InputError, "go with --pose"),
])
def test_bad_command_line_requests(argv, kind, words):
    with pytest.raises(kind) as err:
        request_from_args(args(*argv), WS)
    assert words in str(err.value)
    if kind is InputError:
        assert not isinstance(err.value, RangeError)


def test_node_main_refuses_bad_usage_before_touching_ros(capsys):
    from vr_driver.ros.pose_terminal import main
    for argv in (["--pose", "1", "2"], ["--pose", "1120", "0", "inf", "0", "45", "0"], ["--type", "lin"],
                 ["--pose", "1120", "0", "725", "0", "45", "0", "--type", "circ"], ["--bogus"]):
        with pytest.raises(SystemExit) as exc:
            main(argv)
        assert exc.value.code == 2, argv
    assert "usage: pose_terminal" in capsys.readouterr().err


# ----------------------------------------------------------------------------------- the dialogue

class FakeHandle(MoveHandle):
    """A move that reports ``steps`` progress values, one per wait(); ``interrupt_at``: raise
    KeyboardInterrupt (Ctrl-C) at that wait; ``ignores_cancel``: the driver does not end it."""

    def __init__(self, backend, request, steps=3, interrupt_at=None, ignores_cancel=False, outcome="succeeded"):
        self.backend, self.request = backend, request
        self.steps, self.n = steps, 0
        self.interrupt_at = interrupt_at
        self.ignores_cancel = ignores_cancel
        self.cancelled = False
        self.outcome = outcome

    def wait(self, timeout):
        self.n += 1
        if self.interrupt_at is not None and self.n == self.interrupt_at:
            raise KeyboardInterrupt
        if self.cancelled and not self.ignores_cancel:
            return True
        if self.backend.stopped and self.ignores_cancel:
            self.cancelled, self.ignores_cancel = True, False
            return True
        if self.ignores_cancel or self.outcome == "hang":
            threading.Event().wait(timeout)
            return False
        return self.n > self.steps

    def progress(self):
        left = max(0, self.steps - self.n)
        return MoveProgress("moving", 100.0 * left, 0.0)

    def cancel(self):
        self.cancelled = True
        self.backend.calls.append("cancel")

    def result(self):
        if self.cancelled:
            return MoveResult("cancelled", "goal cancelled by the client", ControllerPose(1050, 0, 750, 0, 45, 0))
        if self.outcome == "failed":
            return MoveResult("failed", "the controller rejected the target", HOME_POSE)
        return MoveResult("succeeded", "", self.request.target)


class FakeBackend(Backend):
    def __init__(self, refuse: str = "", motion_possible: Optional[bool] = True, unavailable=False, **handle_kw):
        self.refuse = refuse
        self.unavailable = unavailable
        self.motion_possible = motion_possible
        self.handle_kw = handle_kw
        self.previews: List[PoseRequest] = []
        self.sent: List[PoseRequest] = []
        self.calls: List[str] = []
        self.stopped = False

    def preview(self, request):
        self.previews.append(request)
        if self.unavailable:
            return PreviewResult(False, "no answer from the driver within 15 s", unavailable=True)
        if self.refuse:
            return PreviewResult(False, self.refuse)
        return PreviewResult(True, "", (0.0, 0.6, -0.3, 0.0, 0.4, 0.0), 1.25)

    def start_move(self, request):
        self.sent.append(request)
        return FakeHandle(self, request, **self.handle_kw)

    def stop(self):
        self.stopped = True
        self.calls.append("stop")
        return True, "stop sent; 1 job(s) ended"

    def status(self):
        why = "" if self.motion_possible else "the emergency stop is active"
        return StatusInfo(link="connected, 50.0 cycles/s", motion_possible=self.motion_possible, why_no_motion=why,
                          mode="auto", e_stopped=not self.motion_possible, drives_powered=True, in_motion=False,
                          in_error=False, pose=HOME_POSE, joints=(0.0, 0.6, -0.3, 0.0, 0.4, 0.0), age=0.1)


class Script:
    """input() from a list: strings are typed lines, EOFError / KeyboardInterrupt are raised."""

    def __init__(self, out, lines):
        self.out, self.lines, self.prompts = out, list(lines), []

    def __call__(self, prompt):
        self.prompts.append(prompt)
        self.out.write(prompt)
        if not self.lines:
            raise EOFError
        item = self.lines.pop(0)
        if isinstance(item, type) and issubclass(item, BaseException):
            self.out.write("\n")
            raise item()
        self.out.write(item + "\n")
        return item


def session(backend, lines, **kw):
    out = io.StringIO()
    script = Script(out, lines)
    term = Terminal(backend, WS, out=out, input_fn=script, tty=kw.pop("tty", False), poll_period=0.01,
                    stop_wait=kw.pop("stop_wait", 0.4), **kw)
    code = term.run_interactive()
    return code, out.getvalue(), script.prompts, term


def test_defaults_accepted_with_enter():
    backend = FakeBackend()
    code, text, prompts, _ = session(backend, ["", "", "", "", "", "", "", "y", "quit"])
    assert code == EXIT_OK
    assert prompts[:7] == ["X [mm, 100..1400] (1120): ", "Y [mm, -900..900] (0): ", "Z [mm, 0..1400] (725): ",
                           "Rx [deg, -180..180] (0): ", "Ry [deg, -180..180] (45): ", "Rz [deg, -180..180] (0): ",
                           "Move type [ptp, lin, circ] (ptp): "]
    assert prompts[7] == "Send this PTP move to the robot? [y/N]: "
    assert backend.previews == backend.sent == [PoseRequest(MoveType.PTP, HOME_POSE)]
    assert "Preview: reachable; estimated duration 1.2 s" in text
    assert "joint target [deg]: J1 0.0  J2 34.4  J3 -17.2  J4 0.0  J5 22.9  J6 0.0" in text
    assert "moving   distance to go" in text
    assert "Reached X 1120  Y 0  Z 725  Rx 0  Ry 45  Rz 0 (0.0 mm, 0.0 deg from the target)" in text
    assert text.rstrip().endswith("Bye.")


def test_bad_values_are_re_prompted_with_the_reason():
    backend = FakeBackend()
    lines = ["1500",                          # X out of range: the entry starts again
             "abc",                           # not a number
             "1000", "nan", "1000", "-200",   # Y: nan, out of range, then good
             "", "", "", "1e999", "-30", "lin", "y", "quit"]
    code, text, prompts, _ = session(backend, lines)
    assert code == EXIT_OK
    assert "  X = 1500 mm is above the workspace: allowed 100..1400 mm" in text
    assert "  X: 'abc' is not a number" in text
    assert "  Y: 'nan' is not a position: a finite number in -900..900 mm is needed" in text
    assert "  Y = 1000 mm is above the workspace: allowed -900..900 mm" in text
    assert "  Rz: inf is not an angle: a finite number in -180..180 deg is needed" in text
    assert [p for p in prompts if p.startswith("Y ")] == ["Y [mm, -900..900] (0): "] * 3
    assert backend.sent == [PoseRequest(MoveType.LIN, ControllerPose(1000, -200, 725, 0, 45, -30))]


def test_a_refused_preview_sends_nothing():
    backend = FakeBackend(refuse="PTP target (1400, 0, 1400 mm, 0, 0, 0 deg): pose unreachable: too far")
    code, text, prompts, _ = session(backend, ["1400 0 1400 0 0 0 ptp", "quit"])
    assert code == EXIT_OK
    assert "Refused, nothing was sent: PTP target (1400, 0, 1400 mm, 0, 0, 0 deg): pose unreachable" in text
    assert len(backend.previews) == 1 and backend.sent == []
    assert not any("[y/N]" in p for p in prompts)


def test_out_of_workspace_never_reaches_the_driver():
    backend = FakeBackend()
    code, text, _, _ = session(backend, ["1000 0 1500 0 45 0 lin", "quit"])
    assert "Z = 1500 mm is above the workspace" in text
    assert backend.previews == [] and backend.sent == []


def test_declined_and_motion_not_possible_send_nothing():
    backend = FakeBackend()
    code, text, _, term = session(backend, ["1000 0 800 0 45 0", "n", "1000 0 800 0 45 0", "", "quit"])
    assert text.count("Not sent.") == 2 and backend.sent == []
    assert [e.outcome for e in term.history] == ["not sent (not confirmed)"] * 2
    backend = FakeBackend(motion_possible=False)
    code, text, prompts, _ = session(backend, ["1000 0 800 0 45 0", "quit"])
    assert "Not sent: motion is not possible now: the emergency stop is active" in text
    assert backend.sent == [] and not any("[y/N]" in p for p in prompts)


def test_circular_move_field_by_field():
    backend = FakeBackend()
    lines = ["1000", "150", "800", "", "", "", "circ",
             "", "1100", "0", "800", "", "", "", "y", "quit"]        # via X: Enter is refused (no default)
    code, text, prompts, _ = session(backend, lines)
    assert "Via X [mm, 100..1400]: " in prompts
    assert "Via Rx [deg, -180..180] (0): " in prompts
    assert "  via X: a value is needed (there is no default)" in text
    assert backend.sent == [PoseRequest(MoveType.CIRC, ControllerPose(1000, 150, 800, 0, 45, 0),
                                        ControllerPose(1100, 0, 800, 0, 45, 0))]


def test_the_last_target_becomes_the_default():
    backend = FakeBackend()
    code, text, prompts, _ = session(backend, ["1000 -150 800 0 45 0 lin", "y", "quit"])
    assert prompts[-1] == "X [mm, 100..1400] (1000): "
    backend = FakeBackend()
    code, text, prompts, _ = session(backend, ["1000 -150 800 0 45 0 lin", "y", "", "", "", "", "", "", "", "y", "quit"])
    assert prompts[3] == "Y [mm, -900..900] (-150): "
    assert prompts[8] == "Move type [ptp, lin, circ] (lin): "
    assert backend.sent[1] == backend.sent[0]


def test_ctrl_c_during_a_move_stops_it_and_returns_to_the_prompt():
    backend = FakeBackend(steps=50, interrupt_at=3)
    code, text, prompts, term = session(backend, ["1000 650 800 0 45 0 lin", "y", "quit"])
    assert code == EXIT_OK
    assert "Ctrl-C: stopping the arm ..." in text
    assert "Stopped at X 1050  Y 0  Z 750  Rx 0  Ry 45  Rz 0: goal cancelled by the client" in text
    assert backend.calls == ["cancel"]
    assert prompts[-1].startswith("X [mm")
    assert term.history[-1].outcome == \
        "stopped at X 1050  Y 0  Z 750  Rx 0  Ry 45  Rz 0 (at rest): goal cancelled by the client"


def test_a_cancel_the_driver_ignores_is_followed_by_stop_motion():
    backend = FakeBackend(steps=50, interrupt_at=2, ignores_cancel=True)
    code, text, _, _ = session(backend, ["1000 650 800 0 45 0 lin", "y", "quit"])
    assert backend.calls == ["cancel", "stop"]
    assert "calling stop_motion" in text and "Stopped at" in text


def test_ctrl_d_at_a_prompt_quits_cleanly():
    code, text, _, _ = session(FakeBackend(), [EOFError])
    assert code == EXIT_OK and text.rstrip().endswith("Bye.")
    code, text, _, _ = session(FakeBackend(), ["1000", "0", EOFError])     # in the middle of an entry
    assert code == EXIT_OK and text.rstrip().endswith("Bye.")


FIRST_PROMPT = "X [mm, 100..1400] (1120): "
# the answers that reach each later prompt of a field-by-field entry: Y, Z, Rx, Ry, Rz, move type, confirm
LATER_PROMPTS = [("Y [", ["1000"]), ("Z [", ["1000", "0"]), ("Rx [", ["1000", "0", "800"]),
                 ("Ry [", ["1000", "0", "800", ""]), ("Rz [", ["1000", "0", "800", "", ""]),
                 ("Move type", ["1000", "0", "800", "", "", ""]),
                 ("Send this", ["1000", "0", "800", "", "", "", "lin"])]


@pytest.mark.parametrize("key", ["cancel", "CANCEL ", KeyboardInterrupt])
@pytest.mark.parametrize("at,typed", LATER_PROMPTS, ids=[p for p, _ in LATER_PROMPTS])
def test_cancel_or_ctrl_c_at_any_later_prompt_abandons_the_entry_not_the_session(at, typed, key):
    backend = FakeBackend()
    code, text, prompts, term = session(backend, typed + [key, "1000 200 800 0 45 0 lin", "y", "quit"])
    assert code == EXIT_OK
    n = len(typed)
    assert prompts[n].startswith(at)
    assert prompts[n + 1] == FIRST_PROMPT                    # back to the first prompt, defaults unchanged
    assert ("Not sent." if at == "Send this" else "Entry abandoned") in text
    assert backend.sent == [PoseRequest(MoveType.LIN, ControllerPose(1000, 200, 800, 0, 45, 0))]
    assert prompts[-1] == "X [mm, 100..1400] (1000): "        # the session went on: the sent move is the default


def test_ctrl_c_at_the_first_prompt_does_not_leave():
    backend = FakeBackend()
    code, text, prompts, _ = session(backend, [KeyboardInterrupt, "home", "y", "quit"])
    assert code == EXIT_OK
    assert "Entry abandoned (Ctrl-C); 'quit' or Ctrl-D leaves." in text
    assert prompts[:2] == [FIRST_PROMPT, FIRST_PROMPT]
    assert backend.sent == [PoseRequest(MoveType.PTP, HOME_POSE)]


@pytest.mark.parametrize("at,typed", LATER_PROMPTS, ids=[p for p, _ in LATER_PROMPTS])
def test_quit_at_any_prompt_leaves_and_sends_nothing(at, typed):
    backend = FakeBackend()
    code, text, prompts, _ = session(backend, typed + ["quit", "1000 0 800 0 45 0", "y"])
    assert code == EXIT_OK
    assert prompts[-1].startswith(at) and len(prompts) == len(typed) + 1
    assert text.rstrip().endswith("Bye.")
    assert backend.previews == ([] if at != "Send this" else backend.previews) and backend.sent == []


@pytest.mark.parametrize("at,typed", LATER_PROMPTS, ids=[p for p, _ in LATER_PROMPTS])
def test_home_at_any_prompt_abandons_the_entry_and_moves_home(at, typed):
    backend = FakeBackend()
    code, text, prompts, _ = session(backend, typed + ["home", "y", "quit"])
    assert code == EXIT_OK
    assert backend.sent == [PoseRequest(MoveType.PTP, HOME_POSE)]
    assert prompts[len(typed) + 1] == "Send this PTP move to the robot? [y/N]: "
    assert "Reached X 1120  Y 0  Z 725" in text


def test_quit_and_cancel_at_the_confirmation_of_home_typed_inside_an_entry():
    code, text, prompts, _ = session(FakeBackend(), ["1000", "home", "quit", "1000 0 800 0 45 0", "y"])
    assert code == EXIT_OK and text.rstrip().endswith("Bye.") and prompts[-1].startswith("Send this PTP")
    backend = FakeBackend()
    code, text, prompts, _ = session(backend, ["1000", "home", "cancel", "quit"])
    assert code == EXIT_OK and backend.sent == [] and prompts[-1] == FIRST_PROMPT


def test_other_commands_at_a_later_prompt_run_and_ask_the_same_again():
    backend = FakeBackend()
    code, text, prompts, _ = session(backend, ["1000", "status", "help", "200", "", "", "", "stop", "", "lin",
                                               "y", "quit"])
    assert prompts[1] == prompts[2] == prompts[3] == "Y [mm, -900..900] (0): "
    assert "link:            connected, 50.0 cycles/s" in text and "\n  cancel " in text
    assert prompts[7] == prompts[8] == "Rz [deg, -180..180] (0): "
    assert backend.calls[0] == "stop"
    assert backend.sent == [PoseRequest(MoveType.LIN, ControllerPose(1000, 200, 725, 0, 45, 0))]


def test_only_a_sent_move_becomes_the_default():
    """A refused, declined or abandoned entry leaves the defaults as they were."""
    backend = FakeBackend(refuse="pose unreachable")
    code, text, prompts, term = session(backend, ["1400 0 1400 0 0 0 ptp", "1300", "100", "1000", "", "", "", "lin",
                                                  "quit"])
    assert "Refused, nothing was sent: pose unreachable" in text
    assert prompts[1] == FIRST_PROMPT                          # not (1400) after the refusal
    assert prompts[2] == "Y [mm, -900..900] (0): "
    assert prompts[-1] == FIRST_PROMPT and term.default_type is MoveType.PTP
    backend = FakeBackend()
    code, text, prompts, term = session(backend, ["1000 0 800 0 45 0 lin", "n", "1000 0 800 0 45 0 lin", "y", "quit"])
    assert prompts[2] == FIRST_PROMPT                          # declined: still the home pose
    assert prompts[-1] == "X [mm, 100..1400] (1000): " and term.default_type is MoveType.LIN
    backend = FakeBackend(motion_possible=False)
    code, text, prompts, _ = session(backend, ["1000 0 800 0 45 0 lin", "quit"])
    assert "Not sent: motion is not possible now" in text and prompts[-1] == FIRST_PROMPT


def test_messages_name_the_quantity():
    for fld, word in zip(FIELDS, ["a position"] * 3 + ["an angle"] * 3):
        with pytest.raises(InputError) as err:
            parse_number("inf", fld, WS)
        assert "%s: 'inf' is not %s" % (fld.label, word) in str(err.value)
        with pytest.raises(InputError) as err:
            check_value(float("nan"), fld, WS)
        assert "%s: nan is not %s" % (fld.label, word) in str(err.value)


def test_ctrl_c_at_the_confirmation_declines():
    backend = FakeBackend()
    code, text, prompts, _ = session(backend, ["1000 0 800 0 45 0", KeyboardInterrupt, "quit"])
    assert "Not sent." in text and backend.sent == []
    assert prompts[-1].startswith("X [mm")


def test_commands_in_the_dialogue():
    backend = FakeBackend()
    code, text, _, term = session(backend, ["help", "status", "home", "y", "stop", "history", "exit"])
    assert code == EXIT_OK
    for word in ("home", "stop", "status", "history", "help", "quit"):
        assert "\n  %s " % word in text
    assert "link:            connected, 50.0 cycles/s" in text
    assert "motion possible: yes" in text
    assert "pose:            X 1120  Y 0  Z 725  Rx 0  Ry 45  Rz 0" in text
    assert backend.sent == [PoseRequest(MoveType.PTP, HOME_POSE)]
    assert "Stop sent: stop sent; 1 job(s) ended" in text
    assert "  1  " in text and "-> reached" in text
    code, text, _, _ = session(FakeBackend(), ["history", "quit"])
    assert "No moves yet." in text


def test_status_when_motion_is_not_possible():
    code, text, _, _ = session(FakeBackend(motion_possible=False), ["status", "quit"])
    assert "motion possible: no (the emergency stop is active)" in text
    assert "e-stop: PRESSED" in text


def test_one_shot_exit_codes():
    def once(backend, request=PoseRequest(MoveType.LIN, ControllerPose(1000, 0, 800, 0, 45, 0)), **kw):
        out = io.StringIO()
        term = Terminal(backend, WS, out=out, input_fn=Script(out, kw.pop("lines", [])), tty=False,
                        poll_period=0.01, stop_wait=0.2, assume_yes=kw.pop("yes", True))
        return term.run_once(request, **kw), out.getvalue()

    assert once(FakeBackend())[0] == EXIT_OK
    assert once(FakeBackend(refuse="unreachable"))[0] == EXIT_REFUSED
    assert once(FakeBackend(outcome="failed"))[0] == EXIT_REFUSED
    assert once(FakeBackend(motion_possible=False))[0] == EXIT_REFUSED
    assert once(FakeBackend(unavailable=True))[0] == EXIT_NO_DRIVER
    backend = FakeBackend()
    code, text = once(backend, preview_only=True)
    assert code == EXIT_OK and backend.sent == [] and "Preview: reachable" in text
    backend = FakeBackend()
    assert once(backend, yes=False, lines=["n"])[0] == EXIT_REFUSED and backend.sent == []
    assert once(backend, yes=False, lines=[])[0] == EXIT_REFUSED and backend.sent == []   # EOF: no
    assert once(FakeBackend(), yes=False, lines=["yes"])[0] == EXIT_OK
    backend = FakeBackend(outcome="hang")
    out = io.StringIO()
    term = Terminal(backend, WS, out=out, input_fn=Script(out, []), tty=False, poll_period=0.01, stop_wait=0.2,
                    assume_yes=True)
    assert term.execute(PoseRequest(MoveType.PTP, HOME_POSE), move_timeout=0.1) == EXIT_NO_DRIVER
    assert "No result from the driver within" in out.getvalue() and "cancel" in backend.calls


def test_rounded_values_are_announced():
    code, text, _, _ = session(FakeBackend(), ["1000.4 0 800 0 45.5 0", "n", "quit"])
    assert "sent as 1000 0 800 0 46 0" in text


def test_progress_on_a_terminal_is_updated_in_place():
    out = io.StringIO()
    printer = ProgressPrinter(out, tty=True)
    printer.update(MoveProgress("sending", 300.0, 0.0))
    printer.update(MoveProgress("moving", 250.0, 0.0))
    printer.update(MoveProgress("moving", 250.0, 0.0))
    printer.update(MoveProgress("moving", 5.0, 0.0))
    printer.finish()
    lines = out.getvalue().split("\n")
    assert len(lines) == 3 and lines[-1] == ""
    assert lines[0].startswith("\r  sending  distance to go   300.0 mm")
    assert lines[1].count("\r") == 2 and lines[1].endswith("distance to go     5.0 mm, angle to go   0.0 deg")


def test_progress_in_a_log_is_one_line_per_phase_and_period():
    now = [0.0]
    out = io.StringIO()
    printer = ProgressPrinter(out, tty=False, period=1.0, clock=lambda: now[0])
    for t, d in ((0.0, 300.0), (0.2, 250.0), (1.1, 100.0), (1.3, 50.0)):
        now[0] = t
        printer.update(MoveProgress("moving", d, 0.0))
    assert out.getvalue().count("\n") == 2


def test_pose_input_imports_without_ros():
    src = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "src")
    repo = os.path.dirname(os.path.dirname(src))
    script = ("import sys\n"
              "for name in ('rospy', 'rospkg', 'roslib', 'actionlib', 'rosgraph', 'std_msgs', 'vr_driver.msg'):\n"
              "    sys.modules[name] = None\n"
              "sys.path[:0] = %r\n"
              "import vr_driver.terminal.pose_input, vr_driver.ros.pose_terminal\n"
              "print('ok')\n" % [src, os.path.join(repo, "pyprofibus_vendor", "src"),
                                 os.path.join(repo, "panasonic_vr006l_support", "src")])
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and proc.stdout.strip() == "ok", proc.stderr
