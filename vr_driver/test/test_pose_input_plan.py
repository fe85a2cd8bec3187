"""The pose terminal's ``plan`` (vr_driver.terminal.pose_input): ``plan x y z rx ry rz`` and
``plan NAME`` parsed and checked, previewed through the backend's plan (the driver's plan action,
preview only: duration and planning time shown), run on confirmation as exactly the previewed
trajectory (start_plan), refusals in words; the command line's --plan NAME and --type plan. Against
the fake backend of test_pose_input (ROS-free)."""
from __future__ import annotations

import pytest

from test_pose_input import WS, FakeBackend, FakeHandle, args, session
from vr_driver.terminal.pose_input import (EXIT_NO_DRIVER, EXIT_OK, EXIT_REFUSED, InputError, PlanPreview,
                                           PlanRequest, PoseRequest, RangeError, Terminal, parse_plan_line,
                                           request_from_args)
from vr_driver.kinematics.preview import MoveType
from vr_driver.poses import HOME_POSE, ControllerPose

BEHIND = ControllerPose(500, 866, 725, 0, 45, 60)
END = (1.047, 0.42, 0.056, 0.0, 0.307, 0.0)


class PlanBackend(FakeBackend):
    """FakeBackend with the plan action: ``plan_refuse`` a refusal, else a 2.8 s plan of 57 points at
    the request's velocity scaling (0: the driver's default, 0.1), its peak speeds proportional."""

    def __init__(self, plan_refuse="", plan_unavailable=False, **kw):
        super().__init__(**kw)
        self.plan_refuse = plan_refuse
        self.plan_unavailable = plan_unavailable
        self.plans = []
        self.runs = []

    def plan(self, request):
        self.plans.append(request)
        if self.plan_unavailable:
            return PlanPreview(False, "no answer from the planner within 15 s", unavailable=True)
        if self.plan_refuse:
            return PlanPreview(False, self.plan_refuse)
        target = request.target if request.target is not None else ControllerPose(1120, 0, 725, 0, 45, 0)
        scaling = request.velocity_scaling or 0.1
        return PlanPreview(True, "", 2.84, 0.213, END, target, 57, "RRTConnect", token=("trajectory", len(self.plans)),
                           velocity_scaling=scaling, peak_tcp_speed=2500.0 * scaling, peak_joint="joint_1",
                           peak_joint_speed=119.7 * scaling, peak_joint_fraction=scaling)

    def start_plan(self, preview):
        self.runs.append(preview.token)
        return FakeHandle(self, PoseRequest(MoveType.PTP, preview.target), **self.handle_kw)


# ----------------------------------------------------------------------------------- parsing

def test_plan_lines():
    assert parse_plan_line("plan 500 866 725 0 45 60", WS) == PlanRequest(target=BEHIND)
    assert parse_plan_line("PLAN 500, 866, 725, 0, 45, 60", WS) == PlanRequest(target=BEHIND)
    assert parse_plan_line("plan home", WS) == PlanRequest(state="home")
    assert parse_plan_line("  plan   zero ", WS) == PlanRequest(state="zero")
    assert PlanRequest(target=BEHIND).describe() == "PLAN to X 500  Y 866  Z 725  Rx 0  Ry 45  Rz 60"
    assert PlanRequest(state="home").describe() == "PLAN to the named state home"


@pytest.mark.parametrize("line, words, kind", [
    ("plan", "plan x y z rx ry rz, or plan NAME (a named state of the SRDF, e.g. home), optionally followed by "
             "scaling S (0 < S <= 1); got 0 value(s)", InputError),
    ("plan 500 866 725", "got 3 value(s) after 'plan'", InputError),
    ("plan 500 866 725 0 45 60 ptp", "got 7 value(s)", InputError),
    ("plan 500 866 nan 0 45 60", "Z: 'nan' is not a position", InputError),
    ("plan 500 866 1500 0 45 60", "Z = 1500 mm is above the workspace", RangeError),
    ("plan 12", "got 1 value(s)", InputError),
    ("plan ho-me", "'ho-me' is not a state name", InputError),
    ("plan nan", "got 1 value(s)", InputError),
])
def test_bad_plan_lines(line, words, kind):
    with pytest.raises(kind) as err:
        parse_plan_line(line, WS)
    assert words in str(err.value)


def test_a_plan_request_is_a_pose_or_a_state():
    with pytest.raises(InputError, match="a pose or to a named state"):
        PlanRequest()
    with pytest.raises(InputError, match="a pose or to a named state"):
        PlanRequest(target=BEHIND, state="home")


def test_command_line_plans():
    assert request_from_args(args("--plan", "home"), WS) == PlanRequest(state="home")
    assert request_from_args(args("--pose", "500", "866", "725", "0", "45", "60", "--type", "plan"), WS) \
        == PlanRequest(target=BEHIND)
    with pytest.raises(InputError, match="--plan NAME goes alone"):
        request_from_args(args("--plan", "home", "--pose", "500", "866", "725", "0", "45", "60"), WS)
    with pytest.raises(InputError, match="--via is only for --type circ"):
        request_from_args(args("--pose", *"500 866 725 0 45 60".split(), "--type", "plan", "--via",
                               *"1100 0 800 0 45 0".split()), WS)
    with pytest.raises(RangeError, match="X = 1500 mm is above"):
        request_from_args(args("--pose", "1500", "866", "725", "0", "45", "60", "--type", "plan"), WS)
    with pytest.raises(InputError, match="not a state name"):
        request_from_args(args("--plan", "a-b"), WS)
    with pytest.raises(InputError, match="--velocity-scaling is for plans"):
        request_from_args(args("--pose", *"500 866 725 0 45 60".split(), "--velocity-scaling", "0.5"), WS)


@pytest.mark.parametrize("value", ["0", "1.5", "-0.1", "nan", "fast"])
def test_a_bad_velocity_scaling_on_the_command_line_is_a_usage_error(value, capsys):
    with pytest.raises(SystemExit) as err:
        args("--plan", "home", "--velocity-scaling", value)
    assert err.value.code == 2
    assert "--velocity-scaling" in capsys.readouterr().err


def test_a_plan_line_may_ask_for_its_velocity_scaling():
    assert parse_plan_line("plan 500 866 725 0 45 60 scaling 0.5", WS) == PlanRequest(target=BEHIND,
                                                                                       velocity_scaling=0.5)
    assert parse_plan_line("plan home SCALING 1", WS) == PlanRequest(state="home", velocity_scaling=1.0)
    assert PlanRequest(state="home", velocity_scaling=0.5).describe() == \
        "PLAN to the named state home at velocity scaling 0.5"
    for line, words in (("plan home scaling 0", "0 < S <= 1"), ("plan home scaling 2", "outside 0 < S <= 1"),
                        ("plan home scaling x", "'x' is not a number"), ("plan home scaling", "got 2 value")):
        with pytest.raises(InputError, match=words):
            parse_plan_line(line, WS)


# ----------------------------------------------------------------------------------- the dialogue

def test_plan_previews_then_runs_exactly_the_previewed_trajectory_on_yes():
    backend = PlanBackend()
    code, text, prompts, term = session(backend, ["plan 500 866 725 0 45 60", "y", "quit"])
    assert code == EXIT_OK
    assert backend.plans == [PlanRequest(target=BEHIND)]
    assert "Planning a collision-free motion: PLAN to X 500  Y 866  Z 725  Rx 0  Ry 45  Rz 60" in text
    assert "Plan: collision-free; duration 2.8 s (57 points), planned in 213 ms by RRTConnect" in text
    assert "joint target [deg]: J1 60.0  J2 24.1  J3 3.2  J4 0.0  J5 17.6  J6 0.0" in text
    assert "TCP at the end: X 500  Y 866  Z 725  Rx 0  Ry 45  Rz 60" in text
    # the speed it will run at, before the question: the driver's default scaling and its peaks
    assert ("  speed: velocity scaling 0.1 (the driver's default); at its fastest the TCP moves 250 mm/s, "
            "joint_1 12.0 deg/s (10 % of its limit)\nRun this planned motion") in text
    assert prompts[1] == "Run this planned motion on the robot? [y/N]: "
    assert backend.runs == [("trajectory", 1)]                 # the previewed one, not a new plan
    assert backend.sent == [] and backend.previews == []         # no move_to_pose goal at all
    assert "Reached X 500  Y 866  Z 725  Rx 0  Ry 45  Rz 60 (0.0 mm, 0.0 deg from the target)" in text
    assert term.defaults == BEHIND and term.default_type is MoveType.PTP
    assert [e.outcome for e in term.history] == ["reached"]


def test_plan_to_a_named_state_takes_the_plans_end_as_the_next_default():
    backend = PlanBackend()
    code, text, prompts, term = session(backend, ["plan home", "y", "quit"])
    assert backend.plans == [PlanRequest(state="home")]
    assert "Planning a collision-free motion: PLAN to the named state home" in text
    assert backend.runs == [("trajectory", 1)]
    assert term.defaults == HOME_POSE


def test_a_declined_plan_sends_nothing():
    backend = PlanBackend()
    code, text, _, term = session(backend, ["plan home", "n", "quit"])
    assert backend.runs == [] and "Not sent." in text
    assert [e.outcome for e in term.history] == ["not sent (not confirmed)"]
    assert term.defaults == HOME_POSE


def test_a_refused_plan_says_why_and_sends_nothing():
    why = ("goal refused: all 15 joint solutions of the goal pose are in collision; the nearest, (0.0, 65.0, "
           "-12.2, 0.0, 37.3, 0.0) deg: link_6 with object table (100.0 mm deep)")
    backend = PlanBackend(plan_refuse=why)
    code, text, prompts, term = session(backend, ["plan 1100 0 200 0 90 0", "quit"])
    assert "Refused, nothing was sent: " + why in text
    assert backend.runs == []
    assert len(prompts) == 2                      # no confirmation asked
    assert term.history[0].outcome == "refused: " + why


def test_a_driver_without_a_planner_refuses_in_words():
    term_backend = FakeBackend()                  # the base Backend.plan: no planner
    code, text, _, _ = session(term_backend, ["plan home", "quit"])
    assert "Refused, nothing was sent: this driver does not plan" in text
    assert term_backend.sent == []


def test_a_bad_plan_line_is_explained_and_asked_again():
    backend = PlanBackend()
    code, text, prompts, _ = session(backend, ["plan 500 866", "plan 500 866 725 0 45 60", "n", "quit"])
    assert "plan x y z rx ry rz, or plan NAME" in text and "got 2 value(s)" in text
    assert backend.plans == [PlanRequest(target=BEHIND)]


def test_no_plan_runs_while_motion_is_not_possible():
    backend = PlanBackend(motion_possible=False)
    code, text, prompts, term = session(backend, ["plan home", "quit"])
    assert "Not sent: motion is not possible now: the emergency stop is active" in text
    assert backend.runs == []
    assert len(prompts) == 2


def test_home_typed_at_the_confirmation_abandons_the_plan_and_moves_home():
    backend = PlanBackend()
    code, text, _, _ = session(backend, ["plan 500 866 725 0 45 60", "home", "y", "quit"])
    assert backend.runs == []
    assert backend.previews == [PoseRequest(MoveType.PTP, HOME_POSE)]


def test_ctrl_c_while_a_plan_runs_stops_it():
    backend = PlanBackend(interrupt_at=2)
    code, text, _, term = session(backend, ["plan home", "y", "quit"])
    assert "Ctrl-C: stopping the arm ..." in text
    assert backend.calls[0] == "cancel"
    assert term.history[-1].outcome.startswith("stopped at")


def test_one_shot_plans_preview_only_and_yes():
    import io
    backend = PlanBackend()
    out = io.StringIO()
    term = Terminal(backend, WS, out=out, input_fn=lambda p: "n", tty=False, poll_period=0.01)
    assert term.run_once(PlanRequest(state="home"), preview_only=True) == EXIT_OK
    assert backend.runs == [] and "planned (not run)" == term.history[-1].outcome
    term.assume_yes = True
    said = len(out.getvalue())
    assert term.run_once(PlanRequest(state="home")) == EXIT_OK
    assert backend.runs == [("trajectory", 2)]
    # --yes asks nothing, but says the speed before the arm moves
    text = out.getvalue()[said:]
    assert text.index("  speed: velocity scaling 0.1 (the driver's default); at its fastest the TCP moves 250 mm/s") \
        < text.index("Sent.")
    assert Terminal(PlanBackend(plan_unavailable=True), WS, out=out, input_fn=lambda p: "y", tty=False
                    ).run_once(PlanRequest(state="home")) == EXIT_NO_DRIVER
    assert Terminal(PlanBackend(plan_refuse="no path found"), WS, out=out, input_fn=lambda p: "y", tty=False
                    ).run_once(PlanRequest(state="home")) == EXIT_REFUSED


def test_a_plan_from_where_the_arm_is_runs_nothing():
    class There(PlanBackend):
        def plan(self, request):
            return PlanPreview(True, "", 0.0, 0.003, END, BEHIND, 1, "RRTConnect", token="one point")
    backend = There()
    code, text, prompts, term = session(backend, ["plan 500 866 725 0 45 60", "quit"])
    assert "Plan: the arm is at the goal already (planned in 3 ms); nothing to run." in text
    assert backend.runs == [] and len(prompts) == 2
    assert term.history[0].outcome == "already there"


def test_the_terminals_velocity_scaling_times_every_plan_that_gives_none():
    """--velocity-scaling S: each plan is asked at S (a line's own 'scaling' wins) and says so."""
    backend = PlanBackend()
    code, text, _, _ = session(backend, ["plan home", "n", "plan home scaling 1", "n", "quit"], velocity_scaling=0.5)
    assert backend.plans == [PlanRequest(state="home", velocity_scaling=0.5), PlanRequest(state="home", velocity_scaling=1.0)]
    assert "Planning a collision-free motion: PLAN to the named state home at velocity scaling 0.5" in text
    assert ("  speed: velocity scaling 0.5; at its fastest the TCP moves 1250 mm/s, joint_1 59.9 deg/s "
            "(50 % of its limit)") in text
    assert "  speed: velocity scaling 1; at its fastest the TCP moves 2500 mm/s" in text
    with pytest.raises(InputError, match="velocity_scaling: 2 is outside"):
        Terminal(backend, WS, velocity_scaling=2)


def test_a_driver_that_does_not_say_its_speed_is_named_so():
    class Mute(PlanBackend):
        def plan(self, request):
            return PlanPreview(True, "", 2.84, 0.213, END, BEHIND, 57, "RRTConnect", token="t")
    code, text, _, _ = session(Mute(), ["plan home", "n", "quit"])
    assert "  speed: not reported by the driver (velocity scaling the driver's default)" in text
