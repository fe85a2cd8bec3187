"""The goal runner of the node's action servers (vr_driver.ros.goal_runner), without ROS: a fake goal
handle records what the runner did with it, and the goals' "threads" are run by the test itself, one
after the other in this thread, so that every interleaving asked for is the one that happens. A goal
ends exactly once -- also when its execute raises, ends it twice or forgets to end it --, a cancel
before the start and during execution reaches execute, a second goal preempts the running one or
runs beside it by the server's rule, and a refused goal is never accepted and preempts nothing."""
from __future__ import annotations

import logging
import threading
from types import SimpleNamespace

import pytest

from vr_driver.ros.goal_runner import (ABORTED, ACTIVE, CANCELED, SUCCEEDED, Goal, GoalRefused, GoalRunner)

TERMINAL_CALLS = ("succeeded", "canceled", "aborted", "rejected")


class Handle:
    """An actionlib ServerGoalHandle as far as the runner uses it: records every call in order."""

    def __init__(self, goal_id, goal=None):
        self._id = SimpleNamespace(id=goal_id)
        self.goal = goal if goal is not None else SimpleNamespace(preview_only=False)
        self.calls = []

    def get_goal(self):
        return self.goal

    def get_goal_id(self):
        return self._id

    def set_accepted(self, text=""):
        self.calls.append(("accepted", None, text))

    def set_rejected(self, result=None, text=""):
        self.calls.append(("rejected", result, text))

    def set_succeeded(self, result=None, text=""):
        self.calls.append(("succeeded", result, text))

    def set_canceled(self, result=None, text=""):
        self.calls.append(("canceled", result, text))

    def set_aborted(self, result=None, text=""):
        self.calls.append(("aborted", result, text))

    def publish_feedback(self, feedback):
        self.calls.append(("feedback", feedback, ""))

    def ends(self):
        return [(how, result, text) for how, result, text in self.calls if how in TERMINAL_CALLS]


class Harness:
    """A runner whose goal threads wait in ``pending`` until the test runs them (:meth:`run`)."""

    def __init__(self, execute, **kw):
        self.pending = []
        self.threads = []
        self.runner = GoalRunner("test_action", execute, lambda text: {"error": text},
                                 spawn=self._spawn, **kw)

    def _spawn(self, run, name):
        self.pending.append(run)
        self.threads.append(name)

    def send(self, goal_id, goal=None):
        handle = Handle(goal_id, goal)
        self.runner.on_goal(handle)
        return handle

    def run(self):
        """Run the oldest goal's thread to its end (here, in this thread)."""
        self.pending.pop(0)()


def ok(goal):
    goal.set_succeeded({"ok": True}, "done")


# ---------------------------------------------------------------------- one end, always
def test_a_goal_runs_in_its_thread_and_ends_once():
    seen = []

    def execute(goal):
        seen.append((goal.state, goal.get_goal().preview_only, goal.cancel.is_set(), goal.preempted))
        goal.publish_feedback("half way")
        assert goal.set_succeeded({"ok": True}, "done") is True

    h = Harness(execute, thread_name="move")
    handle = h.send("goal-0123456789")
    assert handle.calls == [("accepted", None, "")] and h.runner.running() == 1
    assert h.threads == ["move-23456789"]
    h.run()
    assert seen == [(ACTIVE, False, False, False)]
    assert handle.calls[1:] == [("feedback", "half way", ""), ("succeeded", {"ok": True}, "done")]
    assert h.runner.running() == 0


def test_execute_raising_ends_the_goal_aborted_once_with_the_error_in_words(caplog):
    def execute(goal):
        goal.publish_feedback("started")
        raise KeyError("joint_7")

    h = Harness(execute)
    handle = h.send("g1")
    with caplog.at_level(logging.ERROR, logger="vr_driver.ros.goal_runner"):
        h.run()
    assert handle.ends() == [("aborted", {"error": "internal error: 'joint_7'"}, "internal error: 'joint_7'")]
    [record] = caplog.records
    assert "test_action: internal error: 'joint_7'" in record.getMessage() and record.exc_info is not None
    assert h.runner.running() == 0


def test_execute_that_ends_nothing_leaves_no_goal_hanging(caplog):
    h = Harness(lambda goal: None)
    handle = h.send("g1")
    with caplog.at_level(logging.ERROR, logger="vr_driver.ros.goal_runner"):
        h.run()
    text = "internal error: the goal ended without a result"
    assert handle.ends() == [("aborted", {"error": text}, text)]
    assert [r.getMessage() for r in caplog.records] == ["test_action: " + text]


def test_a_terminal_state_is_never_set_twice(caplog):
    answers = []

    def execute(goal):
        answers.append(goal.set_succeeded({"ok": True}))
        answers.append(goal.set_aborted({"ok": False}, "late failure"))
        answers.append(goal.set_canceled())
        assert goal.state == SUCCEEDED and goal.ended

    h = Harness(execute)
    handle = h.send("g1")
    with caplog.at_level(logging.ERROR, logger="vr_driver.ros.goal_runner"):
        h.run()
    assert answers == [True, False, False]
    assert handle.ends() == [("succeeded", {"ok": True}, "")]
    assert [r.getMessage() for r in caplog.records] == [
        "test_action goal g1: aborted refused, it ended succeeded already (late failure)",
        "test_action goal g1: canceled refused, it ended succeeded already (no text)"]


def test_execute_raising_after_the_goal_ended_keeps_that_end(caplog):
    def execute(goal):
        goal.set_canceled({"stopped": True}, "cancelled by the client")
        raise RuntimeError("drawing the path failed")

    h = Harness(execute)
    handle = h.send("g1")
    with caplog.at_level(logging.ERROR, logger="vr_driver.ros.goal_runner"):
        h.run()
    assert handle.ends() == [("canceled", {"stopped": True}, "cancelled by the client")]
    [record] = caplog.records
    assert record.getMessage() == ("test_action goal g1: internal error after it ended canceled: "
                                   "drawing the path failed")


# ---------------------------------------------------------------------- cancel
def test_a_cancel_before_the_goal_starts_reaches_its_execute():
    seen = []

    def execute(goal):
        seen.append((goal.cancel.is_set(), goal.preempted))
        goal.set_canceled({"stopped": True}, "cancelled before it ran")

    h = Harness(execute)
    handle = h.send("g1")
    h.runner.on_cancel(handle)                       # accepted, its thread not started yet
    h.run()
    assert seen == [(True, False)]                   # cancelled by the client, not preempted
    assert handle.ends() == [("canceled", {"stopped": True}, "cancelled before it ran")]


def test_a_cancel_during_execution_sets_the_goals_event_and_no_other():
    h = None
    seen = []

    def execute(goal):
        seen.append(goal.cancel.is_set())
        h.runner.on_cancel(Handle(goal.id))          # the ActionServer's cancel callback, mid-run
        seen.append((goal.cancel.is_set(), goal.preempted))
        goal.set_canceled({"at_rest": True}, "goal cancelled by the client")

    h = Harness(execute)
    first = h.send("g1")
    h.send("g2")
    h.run()
    assert seen == [False, (True, False)]
    assert first.ends() == [("canceled", {"at_rest": True}, "goal cancelled by the client")]
    seen.clear()
    h.run()                                          # the other goal saw no cancel
    assert seen[0] is False


def test_a_cancel_after_the_end_or_of_an_unknown_goal_changes_nothing():
    h = Harness(ok)
    handle = h.send("g1")
    h.run()
    h.runner.on_cancel(handle)
    h.runner.on_cancel(Handle("never-sent"))
    assert handle.ends() == [("succeeded", {"ok": True}, "done")] and h.runner.running() == 0


# ---------------------------------------------------------------------- one goal at a time, or side by side
def test_exclusive_a_second_goal_preempts_the_running_one_at_its_arrival():
    seen = {}

    def execute(goal):
        seen[goal.id] = (goal.cancel.is_set(), goal.preempted)
        if goal.cancel.is_set():
            goal.set_canceled()
        else:
            goal.set_succeeded()

    h = Harness(execute, exclusive=True)
    first = h.send("g1")
    second = h.send("g2")                            # g1 accepted, not run yet: preempted already
    third = h.send("g3")                             # back to back: the newest wins
    for _ in range(3):
        h.run()
    assert seen == {"g1": (True, True), "g2": (True, True), "g3": (False, False)}
    assert [e[0] for e in first.ends() + second.ends() + third.ends()] == [CANCELED, CANCELED, SUCCEEDED]
    later = h.send("g4")                             # the last one ended: nothing left to preempt
    h.run()
    assert later.ends()[0][0] == SUCCEEDED and seen["g4"] == (False, False)


def test_exclusive_a_goal_preempted_mid_run_knows_it_was_preempted():
    h = None
    seen = []

    def execute(goal):
        if goal.id == "g1":
            h.send("g2")                             # arrives while g1 runs
            seen.append((goal.cancel.is_set(), goal.preempted))
            goal.set_canceled(None, "preempted by a new goal")
        else:
            seen.append((goal.cancel.is_set(), goal.preempted))
            goal.set_succeeded()

    h = Harness(execute, exclusive=True)
    first = h.send("g1")
    h.run()
    h.run()
    assert seen == [(True, True), (False, False)]
    assert first.ends() == [("canceled", None, "preempted by a new goal")]


def test_not_exclusive_goals_run_side_by_side():
    h = Harness(lambda goal: goal.set_aborted() if goal.cancel.is_set() else goal.set_succeeded())
    handles = [h.send("g%d" % k) for k in range(3)]
    assert h.runner.running() == 3
    for _ in handles:
        h.run()
    assert [handle.ends()[0][0] for handle in handles] == [SUCCEEDED] * 3


def test_a_rule_per_goal_previews_run_beside_moves_and_tickets_go_to_moves_in_arrival_order():
    """move_to_pose's rule: a preview_only goal neither preempts a move nor is preempted by one; the
    moves take the core's ticket in the order they arrived."""
    tickets = iter(range(100, 200))
    seen = {}

    def execute(goal):
        seen[goal.id] = (goal.ticket, goal.cancel.is_set(), goal.preempted)
        goal.set_succeeded()

    h = Harness(execute, exclusive=lambda msg: not msg.preview_only, ticket=lambda msg: next(tickets))
    h.send("move1")
    h.send("preview1", SimpleNamespace(preview_only=True))
    h.send("move2")
    h.send("preview2", SimpleNamespace(preview_only=True))
    for _ in range(4):
        h.run()
    assert seen == {"move1": (100, True, True), "preview1": (None, False, False),
                    "move2": (101, False, False), "preview2": (None, False, False)}


# ---------------------------------------------------------------------- the check at arrival
def test_a_refused_goal_is_rejected_with_the_checks_result_and_preempts_nothing():
    seen = {}

    def check(msg):
        if msg.bad:
            raise GoalRefused({"error_code": -1}, "joint_7 is not a joint of this arm")
        return ("trajectory", msg.points)

    def execute(goal):
        seen[goal.id] = (goal.work, goal.cancel.is_set())
        goal.set_succeeded()

    h = Harness(execute, check=check, exclusive=True)
    good = h.send("g1", SimpleNamespace(bad=False, points=3))
    bad = h.send("g2", SimpleNamespace(bad=True, points=0))
    assert bad.calls == [("rejected", {"error_code": -1}, "joint_7 is not a joint of this arm")]
    assert len(h.pending) == 1 and h.runner.running() == 1
    h.run()
    assert seen == {"g1": (("trajectory", 3), False)}           # not preempted by the refused one
    assert good.ends() == [("succeeded", None, "")]


def test_a_check_that_fails_rejects_the_goal_in_words_instead_of_leaving_it_pending(caplog):
    def check(msg):
        raise ZeroDivisionError("float division by zero")

    h = Harness(ok, check=check)
    with caplog.at_level(logging.ERROR, logger="vr_driver.ros.goal_runner"):
        handle = h.send("g1")
    text = "internal error: float division by zero"
    assert handle.calls == [("rejected", {"error": text}, text)] and not h.pending
    assert caplog.records[0].getMessage() == "test_action: %s (goal refused)" % text


# ---------------------------------------------------------------------- the real thread
def test_by_default_each_goal_runs_in_a_daemon_thread_named_after_it():
    done = threading.Event()
    seen = []

    def execute(goal):
        thread = threading.current_thread()
        seen.append((thread.name, thread.daemon, thread is not threading.main_thread()))
        goal.set_succeeded()
        done.set()

    runner = GoalRunner("test_action", execute, lambda text: text, thread_name="plan")
    handle = Handle("goal-abcdefgh12345678")
    runner.on_goal(handle)
    assert done.wait(10.0)
    assert seen == [("plan-12345678", True, True)]
    assert handle.ends() == [("succeeded", None, "")]


@pytest.mark.parametrize("method, state", [("set_succeeded", SUCCEEDED), ("set_canceled", CANCELED),
                                           ("set_aborted", ABORTED)])
def test_each_end_reaches_the_handle_under_its_own_name(method, state):
    handle = Handle("g1")
    goal = Goal("test_action", handle)
    assert getattr(goal, method)({"r": 1}, "why") is True
    assert handle.calls == [(state, {"r": 1}, "why")] and goal.state == state
