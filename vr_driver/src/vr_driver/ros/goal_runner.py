"""The goal skeleton the node's three action servers share (``move_to_pose``, ``joint_trajectory_action``,
``plan``): each keeps only what is its own -- validating a goal, executing it, building its result --
and hands the rest to one :class:`GoalRunner`:

- the ActionServer's goal and cancel callbacks (:meth:`GoalRunner.on_goal`, :meth:`GoalRunner.on_cancel`);
- an optional check at arrival (``check``): a goal it refuses (:class:`GoalRefused`) is rejected with
  the check's result and words, never accepted, and preempts nothing;
- the one-goal-at-a-time rule (``exclusive``): an exclusive goal preempts the running exclusive one at
  its arrival (its cancel event is set and :attr:`Goal.preempted` says why), so of goals arriving back
  to back the newest wins; a goal that is not exclusive runs beside the others and disturbs none;
- a thread per accepted goal with its cancel event (set by the client's cancel or by a preemption);
- the terminal state, set exactly once: a goal the execute function ends twice keeps its first end
  (the second is refused and logged), one it leaves without an end or whose execute raises ends
  ABORTED with the error in words (``internal_error``) and logged with its traceback.

A goal moves ACCEPTED -> ACTIVE -> one of SUCCEEDED / CANCELED / ABORTED, or is REJECTED at arrival.
No ROS here: the goal handle is anything with actionlib's ``ServerGoalHandle`` methods (``get_goal``,
``get_goal_id``, ``set_accepted``, ``set_rejected``, ``set_succeeded``, ``set_canceled``,
``set_aborted``, ``publish_feedback``) and the log is the ``vr_driver`` logger (the node sends it to
rosout), so the rules are tested in plain pytest with a fake handle in one thread
(``test/test_goal_runner.py``).
"""
from __future__ import annotations

import logging
import threading
import time
from typing import Any, Callable, Dict, Optional, Union

log = logging.getLogger(__name__)

ACCEPTED = "accepted"
ACTIVE = "active"
SUCCEEDED = "succeeded"
CANCELED = "canceled"
ABORTED = "aborted"
REJECTED = "rejected"
#: the states a goal ends in (at most one of them, once)
TERMINAL = (SUCCEEDED, CANCELED, ABORTED, REJECTED)


class GoalRefused(Exception):
    """Raised by a runner's ``check``: the goal is rejected with ``result`` and ``text`` (the reason)."""

    def __init__(self, result: Any, text: str) -> None:
        super().__init__(text)
        self.result = result
        self.text = text


class Goal:
    """One accepted goal as the execute function sees it: a goal handle that can end only once.

    ``set_succeeded`` / ``set_canceled`` / ``set_aborted`` and ``publish_feedback`` take the
    arguments of actionlib's ``ServerGoalHandle`` and pass them on to the handle; the first end is
    passed on and returns True, any later one is refused (logged as an error, False). Also (read
    only): ``state``, ACCEPTED, ACTIVE or the state it ended in; ``cancel``, the event set by the
    client's cancel or a preemption; ``preempted``, True once a newer exclusive goal arrived while
    this one ran (its cancel is then set); ``work``, what the runner's check returned for it (None
    without a check); ``ticket``, what the runner's ``ticket`` gave it at arrival (None otherwise);
    ``arrived``, the runner's clock when the goal arrived, before its check (the time a goal's
    figures count from)."""

    def __init__(self, runner_name: str, handle: Any, work: Any = None, ticket: Any = None,
                 arrived: float = 0.0) -> None:
        self.name = runner_name
        self.handle = handle
        self.arrived = arrived
        self.id: str = handle.get_goal_id().id
        self.work = work
        self.ticket = ticket
        self.cancel = threading.Event()
        self.preempted = False
        self.state = ACCEPTED
        self._lock = threading.Lock()

    # ------------------------------------------------------------------ what execute reads
    @property
    def ended(self) -> bool:
        return self.state in TERMINAL

    def get_goal(self) -> Any:
        return self.handle.get_goal()

    def get_goal_id(self) -> Any:
        return self.handle.get_goal_id()

    def publish_feedback(self, feedback: Any) -> None:
        self.handle.publish_feedback(feedback)

    # ------------------------------------------------------------------ the one end
    def set_succeeded(self, result: Any = None, text: str = "") -> bool:
        return self._end(SUCCEEDED, result, text)

    def set_canceled(self, result: Any = None, text: str = "") -> bool:
        return self._end(CANCELED, result, text)

    def set_aborted(self, result: Any = None, text: str = "") -> bool:
        return self._end(ABORTED, result, text)

    def _end(self, state: str, result: Any, text: str) -> bool:
        with self._lock:
            previous = self.state
            if previous not in TERMINAL:
                self.state = state
        if previous in TERMINAL:
            log.error("%s goal %s: %s refused, it ended %s already (%s)", self.name, self.id, state, previous,
                      text or "no text")
            return False
        getattr(self.handle, "set_" + state)(result, text)
        return True

    # ------------------------------------------------------------------ the runner's side
    def _activate(self) -> None:
        with self._lock:
            if self.state == ACCEPTED:
                self.state = ACTIVE

    def _preempt(self) -> None:
        self.preempted = True
        self.cancel.set()


def _thread(run: Callable[[], None], name: str) -> None:
    threading.Thread(target=run, name=name, daemon=True).start()


class GoalRunner:
    """The goal callbacks of one action server and the life of each goal (see the module text).

    ``name``: the action's name, in the log and the threads' names. ``execute(goal)``: runs one
    accepted :class:`Goal` in its own thread and ends it (``goal.set_succeeded`` etc.).
    ``internal_error(text)``: the action's result for a goal that ends ABORTED because of an error of
    the server's own (``text`` = "internal error: <the exception>"). ``check(msg)``: called with the
    goal message at arrival (in the ActionServer's thread, goals in the order they came); its value
    is the goal's ``work``; :class:`GoalRefused` rejects the goal. ``exclusive``: True, False or a
    function of the goal message: whether a goal takes part in the newest-wins rule. ``ticket(msg)``:
    called for each exclusive goal as it is accepted, in arrival order, under the runner's lock.
    ``spawn(run, thread_name)``: starts ``run`` (a daemon thread by default; a test runs it itself).
    ``clock``: what :attr:`Goal.arrived` is read from (the driver's clock; default time.monotonic)."""

    def __init__(self, name: str, execute: Callable[[Goal], None], internal_error: Callable[[str], Any], *,
                 check: Optional[Callable[[Any], Any]] = None,
                 exclusive: Union[bool, Callable[[Any], bool]] = False,
                 ticket: Optional[Callable[[Any], Any]] = None,
                 thread_name: str = "goal",
                 spawn: Callable[[Callable[[], None], str], None] = _thread,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.name = name
        self.clock = clock
        self.execute = execute
        self.internal_error = internal_error
        self.check = check
        if callable(exclusive):
            self.exclusive = exclusive
        else:
            rule = bool(exclusive)
            self.exclusive = lambda _msg: rule
        self.ticket = ticket
        self.thread_name = thread_name
        self.spawn = spawn
        self._lock = threading.Lock()
        self._goals: Dict[str, Goal] = {}          # goal id -> the goal, from arrival to its end
        self._current: Optional[Goal] = None        # the newest exclusive goal, while it runs

    # ------------------------------------------------------------------ ActionServer callbacks
    def on_goal(self, handle: Any) -> None:
        """ActionServer thread (goals arrive here in the order the server received them): check, then
        take the goal's ticket and preempt the running exclusive goal now -- the newest goal wins
        however long each takes to execute --, accept, and run the goal in its own thread."""
        arrived = self.clock()
        msg = handle.get_goal()
        work = None
        if self.check is not None:
            try:
                work = self.check(msg)
            except GoalRefused as exc:
                handle.set_rejected(exc.result, exc.text)
                return
            except Exception as exc:  # a goal is never left pending
                text = "internal error: %s" % exc
                log.error("%s: %s (goal refused)", self.name, text, exc_info=True)
                handle.set_rejected(self.internal_error(text), text)
                return
        exclusive = self.exclusive(msg)
        with self._lock:
            goal = Goal(self.name, handle, work, self.ticket(msg) if exclusive and self.ticket else None, arrived)
            self._goals[goal.id] = goal
            if exclusive:
                previous, self._current = self._current, goal
                if previous is not None:
                    previous._preempt()
        handle.set_accepted()
        self.spawn(lambda: self._run(goal), "%s-%s" % (self.thread_name, goal.id[-8:]))

    def on_cancel(self, handle: Any) -> None:
        """ActionServer thread: a client's cancel sets the goal's cancel event (execute decides what
        that means: stop the arm, stop planning; the goal ends when execute ends it). A goal that has
        ended already, or was never accepted, is left alone."""
        with self._lock:
            goal = self._goals.get(handle.get_goal_id().id)
        if goal is not None:
            goal.cancel.set()

    # ------------------------------------------------------------------ one goal
    def running(self) -> int:
        """How many accepted goals have not ended yet."""
        with self._lock:
            return len(self._goals)

    def _run(self, goal: Goal) -> None:
        """The goal's thread: execute it, and end it ABORTED if execute raised or left it unended."""
        goal._activate()
        try:
            self.execute(goal)
        except Exception as exc:  # never leave a goal hanging
            if goal.ended:
                log.error("%s goal %s: internal error after it ended %s: %s", self.name, goal.id, goal.state, exc,
                          exc_info=True)
            else:
                text = "internal error: %s" % exc
                log.error("%s: %s", self.name, text, exc_info=True)
                goal.set_aborted(self.internal_error(text), text)
        else:
            if not goal.ended:
                text = "internal error: the goal ended without a result"
                log.error("%s: %s", self.name, text)
                goal.set_aborted(self.internal_error(text), text)
        finally:
            with self._lock:
                self._goals.pop(goal.id, None)
                if self._current is goal:
                    self._current = None
