"""The messages between the driver and its planning process (vr_driver.driver.planning.plan_messages), the
same pattern as the bus process's: each goes over the wire and comes back equal; one that is
malformed, unknown, or meant for the other side is refused with an error that says what is wrong
(and the worker answers it with PlanFailed, changing nothing)."""
from __future__ import annotations

import pickle
from multiprocessing import Pipe

import pytest

from vr_driver.bus.messages import decode
from vr_driver.driver.planning.plan_messages import (FROM_WORKER, TO_WORKER, Configure, Log, Missing, Outcome, Plan,
                                            PlanFailed, PlanMessageError, Ready, SceneSnapshot, StartFailed, Stop,
                                            driver_end, worker_end)
from vr_driver.driver.planning.planning import SUCCESS, PlanGoal, PlanOutcome
from vr_driver.params import DriverParams

PARAMS = DriverParams.from_dict({"protocol": "v3"})
SCENE = SceneSnapshot((("table", "box", (1.0, 1.0, 0.1), (0.8, 0.0, -0.05), (0.0, 0.0, 0.0, 1.0)),), 0.01, True)
GOAL = PlanGoal(named="home")
START = (0.3, 0.5, -0.2, 0.0, 0.5, 0.0)
TO = [Configure(PARAMS), Plan(GOAL, START, 7, 25.0, SCENE), Plan(GOAL, START, None, 25.0, None), Stop()]
FROM = [Ready(), Missing("ompl", "ompl", "planning", "no ompl"), StartFailed("ParamError: model"),
        Outcome(PlanOutcome(SUCCESS, "planned", planning_time=0.5, profile={"tries": 1, "replans": []})),
        PlanFailed("ValueError: x"), Log(30, "a warning")]


@pytest.mark.parametrize("message", TO, ids=lambda m: type(m).__name__)
def test_every_message_to_the_worker_comes_back_equal(message):
    assert decode(message.encode(), TO_WORKER) == message


@pytest.mark.parametrize("message", FROM, ids=lambda m: type(m).__name__)
def test_every_message_from_the_worker_comes_back_equal(message):
    assert decode(message.encode(), FROM_WORKER) == message


@pytest.mark.parametrize("raw, words", [
    (("plan", GOAL, START, 7, 0.2), "planning message 'plan': 4 fields, expected 5"),
    (("plan", "home", START, 7, 0.2, None), "planning message 'plan': field 1 is str 'home', expected PlanGoal"),
    (("plan", GOAL, (0.3, float("nan")), 7, 0.2, None), "start joints (0.3, nan), expected finite numbers"),
    (("plan", GOAL, START, 7, 0.0, None), "cycle_rate 0.0, expected a positive number"),
    (("plan", GOAL, START, 7, 0.2, SceneSnapshot((("table", "box"),), 0.01, True)),
     "a scene object ('table', 'box'), expected (name, shape, size, position, quaternion)"),
    (("start", {"protocol": "v3"}), "field 1 is dict"),
    (("plan!",), "planning message 'plan!' unknown here (expected one of plan, start, stop)"),
    (["plan"], "is not a tagged tuple"),
])
def test_a_malformed_message_to_the_worker_is_refused_naming_what_is_wrong(raw, words):
    with pytest.raises(PlanMessageError) as err:
        decode(pickle.dumps(raw), TO_WORKER)
    assert words in str(err.value), str(err.value)


def test_a_channel_receives_only_its_sides_messages():
    ours, theirs = Pipe()
    node, worker = driver_end(ours), worker_end(theirs)
    node.send(Plan(GOAL, START, None, 25.0, None))
    assert worker.recv() == Plan(GOAL, START, None, 25.0, None)
    worker.send(Ready())
    assert node.recv() == Ready()
    node.send(Ready())                   # the worker's message, sent by the node
    with pytest.raises(PlanMessageError, match="'ready' unknown here"):
        worker.recv()
    with pytest.raises(PlanMessageError, match="does not load"):
        theirs.send_bytes(b"\x80\x05garbage")
        node.recv()


def test_the_scene_snapshot_rebuilds_its_objects_with_their_own_checks():
    assert SCENE.scene().names() == ["table"]
    with pytest.raises(Exception, match="size"):
        SceneSnapshot((("bad", "box", (-1.0, 1.0, 1.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)),), 0.0, True).scene()
